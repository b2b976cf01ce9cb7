"""Terrain classes as data: ids, names, colours and the default preference profile."""

from terrapref.terrain.classes import UNKNOWN, ClassTable, TerrainClass, default_classes, load_classes
from terrapref.terrain.profile import PreferenceProfile

__all__ = ["UNKNOWN", "ClassTable", "TerrainClass", "PreferenceProfile", "default_classes", "load_classes"]
