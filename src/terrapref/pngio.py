"""Image files: single-channel class-id PNGs and colour previews (Pillow, no matplotlib)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image

from terrapref.fileio import atomic_path
from terrapref.terrain import ClassTable


def write_png_atomic(path: str | Path, image: np.ndarray, compress_level: int = 6) -> None:
    """Write a PNG via a temporary file and rename, so a reader never sees half a file."""
    with atomic_path(path) as tmp:
        Image.fromarray(image).save(tmp, format="PNG", compress_level=compress_level)


def colorise(labels: np.ndarray, classes: ClassTable) -> np.ndarray:
    """RGB image (H, W, 3) uint8 of a class-id image (H, W)."""
    return classes.palette()[labels]


def read_label_png(path: str | Path) -> np.ndarray:
    """A single-channel 8-bit PNG as a (H, W) uint8 array."""
    with Image.open(path) as im:
        if im.mode != "L":
            raise ValueError(f"{path}: expected a single-channel 8-bit PNG, got mode {im.mode}")
        return np.asarray(im, dtype=np.uint8)
