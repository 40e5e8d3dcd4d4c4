"""PNG/JPEG image I/O for depth images and masks (Pillow), with errors that name the file."""
from __future__ import annotations

from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from bench.errors import DatasetError

_UINT16_MODES = {"I;16", "I;16B", "I;16L", "I"}


def _open(path: Path) -> Image.Image:
    try:
        image = Image.open(path)
        image.load()
    except FileNotFoundError:
        raise DatasetError(path, "file is missing") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError) as err:
        raise DatasetError(path, f"not a readable image ({err})") from None
    return image


def read_uint16_png(path: Path) -> np.ndarray:
    """A single-channel 16-bit PNG (e.g. depth in millimetres) as a (H, W) uint16 array."""
    image = _open(path)
    if image.mode not in _UINT16_MODES:
        raise DatasetError(path, f"expected a single-channel 16-bit image, found mode '{image.mode}'")
    values = np.asarray(image)
    if values.dtype != np.uint16:
        if values.min() < 0 or values.max() > 65535:
            raise DatasetError(path, "pixel values outside the uint16 range")
        values = values.astype(np.uint16)
    return values


def read_binary_mask(path: Path) -> np.ndarray:
    """A mask image as (H, W) bool: any channel value > 0 is foreground (MAROON_FORMAT.md 3.1)."""
    values = np.asarray(_open(path))
    return values.any(axis=2) if values.ndim == 3 else values > 0


def write_uint16_png(path: Path, values: np.ndarray) -> None:
    """Write a (H, W) uint16 array as a 16-bit PNG."""
    if values.dtype != np.uint16 or values.ndim != 2:
        raise ValueError(f"expected a 2-D uint16 array, got {values.dtype} {values.shape}")
    Image.fromarray(values).save(path)
