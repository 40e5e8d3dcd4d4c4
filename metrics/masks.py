"""Masks of the metrics: `mask_bb` bounds in radar space, the object's silhouette and the P_e erosion (5.2, 5.4).

MAROON erodes with a k x k kernel of k = round(mask_erosion / 4) radar pixels on its 1 mm radar grid (the metadata
value is defined for the Kinect resolution); that is a kernel of k millimetres, converted here to the pixels of
whatever metric grid is used, so the same object is eroded by the same width on every grid.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage

from methods.domain.capture import Metadata

MAROON_RADAR_PITCH_MM = 1.0   # MAROON's radar image: 301 pixels over 0.30 m
_MIN_KEPT_PX = 10             # MAROON retries with a smaller kernel while the eroded mask keeps <= 10 pixels


def inside_mask_bb(points_m: np.ndarray, mask_bb_m: dict[str, float]) -> np.ndarray:
    """(N,) bool: points within every present bound of `mask_bb` (inclusive), radar space metres."""
    points_m = np.asarray(points_m)
    return inside_mask_bb_xyz(points_m[:, 0], points_m[:, 1], points_m[:, 2], mask_bb_m)


def inside_mask_bb_xyz(x_m, y_m, z_m, mask_bb_m: dict[str, float]) -> np.ndarray:
    """`inside_mask_bb` of coordinates given apart, each an array or scalar, the result of their broadcast shape
    (e.g. an image's columns (1, nx), rows (ny, 1) and depths (ny, nx): six passes over it, no (ny, nx, 3) array)."""
    keep = np.ones(np.broadcast_shapes(np.shape(x_m), np.shape(y_m), np.shape(z_m)), dtype=bool)
    for axis, values in (("x", x_m), ("y", y_m), ("z", z_m)):
        if f"{axis}min" in mask_bb_m:
            keep &= values >= mask_bb_m[f"{axis}min"]
        if f"{axis}max" in mask_bb_m:
            keep &= values <= mask_bb_m[f"{axis}max"]
    return keep


def reference_mask_bb_m(metadata: Metadata) -> dict[str, float]:
    """`mask_bb` as the reference viewer applies it (faithful profile): a legacy `mask_3d_threshold` sets zmax
    even where `mask_bb.zmax` is given too (the viewer migrates the threshold over it); read_metadata keeps the
    explicit `mask_bb.zmax`, the newer field, instead."""
    mask_bb_m = dict(metadata.mask_bb_m)
    if "mask_3d_threshold" in metadata.raw:            # validated by read_metadata
        mask_bb_m["zmax"] = float(metadata.raw["mask_3d_threshold"])
    return mask_bb_m


def radar_erosion_kernel_px(mask_erosion: int) -> int:
    """MAROON's radar kernel from metadata `mask_erosion`: Python's round(E / 4) (banker's: 10 -> 2, 20 -> 5)."""
    return int(round(mask_erosion / 4))


def erosion_kernel_mm(mask_erosion: int) -> float:
    """The P_e erosion width in millimetres: MAROON's radar kernel times its 1 mm radar pixel pitch."""
    return radar_erosion_kernel_px(mask_erosion) * MAROON_RADAR_PITCH_MM


def kernel_px_for_pitch(kernel_mm: float, pitch_mm: float) -> int:
    """A kernel of `kernel_mm` in pixels of `pitch_mm` (at least 1: no erosion)."""
    return max(1, int(round(kernel_mm / pitch_mm)))


def erode_mask(mask: np.ndarray, kernel_px: int) -> np.ndarray:
    """OpenCV-style erosion with a k x k rectangle (pixels beyond the border count as foreground).

    Like MAROON, the kernel shrinks by one while the result keeps <= 10 pixels; the loop always ends (at k = 1,
    the identity), also for masks that MAROON's retry loop never leaves.
    """
    mask = np.asarray(mask, dtype=bool)
    for k in range(int(kernel_px), 1, -1):
        eroded = _separable(ndimage.binary_erosion, mask, k, border_value=1)
        if eroded.sum() > _MIN_KEPT_PX:
            return eroded
    return mask.copy()


def _separable(operation, mask: np.ndarray, k: int, **kwargs) -> np.ndarray:
    """`operation` (binary erosion or dilation) with a k x k rectangle as a k x 1 then a 1 x k pass: the same
    result (a rectangle is the Minkowski sum of the two segments, origins included) in O(k) instead of O(k^2)
    per pixel (a 64-pixel kernel on a 1024 x 1024 grid: 0.06 s instead of 1.4 s)."""
    rows = operation(mask, structure=np.ones((k, 1), dtype=bool), **kwargs)
    return operation(rows, structure=np.ones((1, k), dtype=bool), **kwargs)


def close_mask(mask: np.ndarray, kernel_px: int) -> np.ndarray:
    """Morphological closing with a k x k rectangle: fills gaps narrower than k pixels, image border included."""
    mask = np.asarray(mask, dtype=bool)
    if kernel_px <= 1:
        return mask.copy()
    padded = np.pad(mask, kernel_px)
    dilated = _separable(ndimage.binary_dilation, padded, kernel_px)
    closed = _separable(ndimage.binary_erosion, dilated, kernel_px)      # = binary_closing with the k x k square
    return closed[kernel_px:-kernel_px, kernel_px:-kernel_px] | mask
