"""Sensing: a pinhole camera over flat ground and its segmentation renderer."""

from terrapref.camera.pinhole import CameraConfig, PinholeCamera
from terrapref.camera.render import SegmentationRenderer

__all__ = ["CameraConfig", "PinholeCamera", "SegmentationRenderer"]
