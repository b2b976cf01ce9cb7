"""Image files: single-channel class-id PNGs and colour previews (Pillow, no matplotlib)."""

from __future__ import annotations

import math
import warnings
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


def depth_to_millimetres(depth: np.ndarray) -> np.ndarray:
    """A depth image (H, W) float32 [m, NaN where nothing is seen] as REP 118's 16UC1 (H, W)
    uint16 millimetres, 0 where nothing is seen (and beyond 65.534 m)."""
    mm = np.rint(depth * np.float32(1000.0))  # NaN and infinities stay so, and fail both tests below
    return np.where((mm > 0) & (mm <= 65534), mm, 0).astype(np.uint16)


def millimetres_to_depth(mm: np.ndarray) -> np.ndarray:
    """REP 118's 16UC1 depth (H, W) [mm, 0 where nothing is seen] as float32 metres, NaN where nothing is seen."""
    return np.where(mm > 0, mm.astype(np.float32) / np.float32(1000.0), np.float32(np.nan)).astype(np.float32)


def _open_png(path: str | Path) -> Image.Image:
    """``path`` opened, refused (a ValueError) where its pixels are more than a decompression
    bomb's (Pillow's limit: a camera's image is far smaller), before they are decoded."""
    with warnings.catch_warnings():
        warnings.simplefilter("error", Image.DecompressionBombWarning)
        try:
            return Image.open(path)
        except (Image.DecompressionBombError, Image.DecompressionBombWarning) as exc:
            raise ValueError(f"{path}: {exc}") from None


def read_depth_png(path: str | Path) -> np.ndarray:
    """A 16-bit single-channel PNG of millimetres (0: no return; :func:`depth_to_millimetres`'s)
    as a depth image (H, W) float32 [m, NaN where nothing is seen]."""
    with _open_png(path) as im:
        if im.mode not in ("I;16", "I;16B", "I;16L"):
            raise ValueError(f"{path}: expected a single-channel 16-bit PNG, got mode {im.mode}")
        return millimetres_to_depth(np.asarray(im, dtype=np.uint16))


def depth_preview(depth: np.ndarray, height_px: int) -> np.ndarray:
    """A picture (height_px, W, 3) uint8 of a depth image: near light, far dark (by the square
    root of the depth over its farthest return, so the near ground's shape shows), nothing seen
    in grey blue; the rows below the image, to ``height_px``, white."""
    seen = np.isfinite(depth)
    far = float(depth[seen].max()) if seen.any() else 1.0
    shade = np.where(seen, 235.0 - 200.0 * np.sqrt(np.maximum(np.nan_to_num(depth, nan=0.0), 0.0) / far), 0.0).astype(np.uint8)
    rgb = np.repeat(shade[:, :, None], 3, axis=2)
    rgb[~seen] = (150, 170, 200)
    out = np.full((height_px, depth.shape[1], 3), 255, dtype=np.uint8)
    out[: depth.shape[0]] = rgb
    return out


DEPTH_KEY_WIDTH_PX = 120


def depth_key(depth: np.ndarray, height_px: int) -> np.ndarray:
    """The scale beside :func:`depth_preview`'s picture (height_px, DEPTH_KEY_WIDTH_PX, 3) uint8:
    its shades from near to its farthest return with their depths [m], and nothing seen's colour."""
    from PIL import ImageDraw

    seen = np.isfinite(depth)
    far = float(depth[seen].max()) if seen.any() else 1.0
    band = Image.new("RGB", (DEPTH_KEY_WIDTH_PX, height_px), (245, 245, 245))
    draw = ImageDraw.Draw(band)
    draw.text((10, 6), "depth [m]", fill=(20, 20, 20))
    top, bar = 24, max(20, min(height_px - 60, 260))
    for i in range(bar):  # the shades as the preview draws them: by the square root of depth over the farthest
        shade = int(235.0 - 200.0 * i / (bar - 1))
        draw.line((10, top + i, 24, top + i), fill=(shade, shade, shade))
    draw.rectangle((10, top, 24, top + bar - 1), outline=(60, 60, 60))
    ticks = [d for d in (0.0, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0) if d < 0.85 * far] + [far]
    for d in ticks:
        y = top + round((bar - 1) * math.sqrt(d / far))
        draw.line((24, y, 28, y), fill=(60, 60, 60))
        draw.text((32, y - 5), f"{d:.3g}", fill=(20, 20, 20))
    y = top + bar + 12
    draw.rectangle((10, y, 24, y + 14), fill=(150, 170, 200), outline=(60, 60, 60))
    draw.text((32, y + 1), "nothing seen", fill=(20, 20, 20))
    return np.asarray(band)


LEGEND_WIDTH_PX = 170


def preview_with_legend(labels: np.ndarray, classes: ClassTable) -> np.ndarray:
    """The colour preview (H, W, 3) of a class-id image with a legend band to its right: the
    image's pixels are :func:`colorise`'s, the band names each class's colour and unknown (255)."""
    from PIL import ImageDraw

    rgb = colorise(labels, classes)
    h = rgb.shape[0]
    band = Image.new("RGB", (LEGEND_WIDTH_PX, h), (245, 245, 245))
    draw = ImageDraw.Draw(band)
    palette = classes.palette()
    entries = [(c.name + (" (lethal)" if c.name in classes.lethal else ""), tuple(int(v) for v in c.color)) for c in classes.classes]
    entries.append(("unknown: sky, far, off map", tuple(int(v) for v in palette[255])))
    for i, (name, colour) in enumerate(entries):
        y = 10 + 20 * i
        draw.rectangle((10, y, 24, y + 14), fill=colour, outline=(60, 60, 60))
        draw.text((32, y + 1), name, fill=(20, 20, 20))
    return np.concatenate([rgb, np.asarray(band)], axis=1)


def read_label_png(path: str | Path) -> np.ndarray:
    """A single-channel 8-bit PNG as a (H, W) uint8 array."""
    with _open_png(path) as im:
        if im.mode != "L":
            raise ValueError(f"{path}: expected a single-channel 8-bit PNG, got mode {im.mode}")
        return np.asarray(im, dtype=np.uint8)
