"""The terrain world: a class raster painted from a scenario's shapes."""

from terrapref.world.raster import WorldMap, rasterise

__all__ = ["WorldMap", "rasterise"]
