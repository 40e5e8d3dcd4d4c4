"""PNG/JPEG image I/O for depth images and masks (Pillow), bounded, with errors that name the file.

A dataset image is read through bench.maroon.safe_io (a regular file inside the dataset, within `image_bytes`); its
width and height are taken from the header and refused beyond `image_pixels` before any pixel is decoded
(Pillow's own decompression-bomb check, warning and error alike, ends in the same one-line DatasetError). The PNGs
a run writes are encoded here (`png_bytes`), not by Pillow.
"""
from __future__ import annotations

import io
import struct
import warnings
import zlib
from pathlib import Path

import numpy as np
from PIL import Image, UnidentifiedImageError

from bench.maroon import safe_io
from bench.maroon.limits import current_limits, too_large
from methods.domain.errors import DatasetError

_UINT16_MODES = {"I;16", "I;16B", "I;16L", "I"}


def _open(path: Path, formats: tuple[str, ...] = ("PNG",)) -> Image.Image:
    data = safe_io.read_bytes(path, "image")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            image = Image.open(io.BytesIO(data), formats=list(formats))
            width, height = image.size
            if width * height > current_limits().image_pixels:
                raise DatasetError(path, too_large(f"the image's pixel count ({width}x{height})", width * height,
                                                   "image_pixels"))
            image.load()
    except (Image.DecompressionBombError, Image.DecompressionBombWarning) as err:
        raise DatasetError(path, f"image refused as a decompression bomb ({err}); "
                                 f"at most {current_limits().image_pixels:,} pixels are read") from None
    except (UnidentifiedImageError, OSError, SyntaxError, ValueError, EOFError, MemoryError) as err:
        raise DatasetError(path, f"not a readable image ({err})") from None
    return image


def read_uint16_png(path: Path) -> np.ndarray:
    """A single-channel 16-bit PNG (e.g. depth in millimetres) as a (H, W) uint16 array."""
    image = _open(path)
    if image.mode not in _UINT16_MODES:
        raise DatasetError(path, f"expected a single-channel 16-bit image, found mode '{image.mode}'")
    values = np.asarray(image)
    if values.dtype != np.uint16:
        if values.min(initial=0) < 0 or values.max(initial=0) > 65535:
            raise DatasetError(path, "pixel values outside the uint16 range")
        values = values.astype(np.uint16)
    return values


def read_binary_mask(path: Path) -> np.ndarray:
    """A mask image as (H, W) bool: any channel value > 0 is foreground (MAROON_FORMAT.md 3.1)."""
    values = np.asarray(_open(path))
    return values.any(axis=2) if values.ndim == 3 else values > 0


PNG_COMPRESS_LEVEL = 1     # zlib level of the PNGs a run writes: half the encoding time of the default 6 (mostly
                           # empty depth maps grow ~1.4x); the pixels are the same
_PNG_COLOUR_TYPES = {2: 0, 3: 2}    # array dimensions -> PNG colour type: grey (H, W), RGB (H, W, 3)


def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


def png_bytes(values: np.ndarray) -> bytes:
    """A PNG of a (H, W) uint8 or uint16 grey image or an (H, W, 3) uint8 RGB image: its rows unfiltered (filter
    type 0) and deflated by zlib at PNG_COMPRESS_LEVEL in one IDAT chunk. Pillow filters every row adaptively (five
    filters tried a row, not configurable), which took 60 % of its encoding time for a run's mostly empty maps
    (301 x 301: 1.4 -> 0.5 ms grey 16-bit, 2.0 -> 0.8 ms RGB on the 2-core machine) for a few % smaller files; any
    PNG reader decodes the same pixels (tests/bench/harness/test_run_outputs.py reads them back with Pillow)."""
    colour = _PNG_COLOUR_TYPES.get(values.ndim)
    if colour is None or values.dtype not in (np.uint8, np.uint16) or (colour == 2 and (
            values.shape[2] != 3 or values.dtype != np.uint8)) or 0 in values.shape:
        raise ValueError(f"expected a (H, W) uint8/uint16 or (H, W, 3) uint8 array, got {values.dtype} {values.shape}")
    height, width = values.shape[:2]
    rows = np.zeros((height, 1 + values[0].nbytes), np.uint8)          # each row: filter type 0, then its pixels
    rows[:, 1:] = values.astype(values.dtype.newbyteorder(">"), copy=False).view(np.uint8).reshape(height, -1)
    header = struct.pack(">IIBBBBB", width, height, values.dtype.itemsize * 8, colour, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", header)
            + _png_chunk(b"IDAT", zlib.compress(rows.tobytes(), PNG_COMPRESS_LEVEL)) + _png_chunk(b"IEND", b""))

