"""Image files: single-channel class-id PNGs and colour previews (Pillow, no matplotlib)."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from PIL import Image

from terrapref.terrain import ClassTable


def write_png_atomic(path: str | Path, image: np.ndarray, compress_level: int = 6) -> None:
    """Write a PNG via a temporary file and rename, so a reader never sees half a file."""
    path = Path(path)
    if path.is_dir():
        raise IsADirectoryError(21, "is a directory, expected a file name", str(path))
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            Image.fromarray(image).save(fh, format="PNG", compress_level=compress_level)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def colorise(labels: np.ndarray, classes: ClassTable) -> np.ndarray:
    """RGB image (H, W, 3) uint8 of a class-id image (H, W)."""
    return classes.palette()[labels]


def read_label_png(path: str | Path) -> np.ndarray:
    """A single-channel 8-bit PNG as a (H, W) uint8 array."""
    with Image.open(path) as im:
        if im.mode != "L":
            raise ValueError(f"{path}: expected a single-channel 8-bit PNG, got mode {im.mode}")
        return np.asarray(im, dtype=np.uint8)
