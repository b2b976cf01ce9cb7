"""Sensing: a pinhole camera over flat ground and its segmentation renderer."""

from terrapref.camera.pinhole import CameraConfig, PinholeCamera
from terrapref.camera.render import SegmentationRenderer, SegmentationView, as_view

__all__ = ["CameraConfig", "PinholeCamera", "SegmentationRenderer", "SegmentationView", "as_view"]
