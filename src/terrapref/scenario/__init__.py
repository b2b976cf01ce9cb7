"""Scenario files (``terrapref-scenario/1``): typed model, shapes, loading and validation."""

from terrapref.scenario.catalog import packaged_scenarios, resolve_scenario
from terrapref.scenario.loader import FORMAT, MAX_YAW_DEG, load_scenario, parse_scenario
from terrapref.scenario.model import AVOID, BEST, Scenario, TerrainPatch, Zone
from terrapref.scenario.shapes import Circle, Polygon, Rectangle, Shape

__all__ = [
    "AVOID",
    "BEST",
    "FORMAT",
    "MAX_YAW_DEG",
    "Circle",
    "Polygon",
    "Rectangle",
    "Scenario",
    "Shape",
    "TerrainPatch",
    "Zone",
    "load_scenario",
    "packaged_scenarios",
    "parse_scenario",
    "resolve_scenario",
]
