"""Sensing: a pinhole camera over flat ground and its segmentation renderer."""

from terrapref.camera.pinhole import CameraConfig, PinholeCamera
from terrapref.camera.render import PixelSet, SegmentationRenderer, SegmentationView, as_view, flat_of

__all__ = ["CameraConfig", "PinholeCamera", "PixelSet", "SegmentationRenderer", "SegmentationView", "as_view", "flat_of"]
