"""Masks of the MAROON metrics: `mask_bb` bounds in radar space and the P_e mask erosion (5.2, 5.4)."""
from __future__ import annotations

import numpy as np
from scipy import ndimage

_MIN_KEPT_PX = 10   # MAROON retries with a smaller kernel while the eroded mask keeps <= 10 pixels


def inside_mask_bb(points_m: np.ndarray, mask_bb_m: dict[str, float]) -> np.ndarray:
    """(N,) bool: points within every present bound of `mask_bb` (inclusive), radar space metres."""
    points_m = np.asarray(points_m)
    keep = np.ones(len(points_m), dtype=bool)
    for axis, column in (("x", 0), ("y", 1), ("z", 2)):
        if f"{axis}min" in mask_bb_m:
            keep &= points_m[:, column] >= mask_bb_m[f"{axis}min"]
        if f"{axis}max" in mask_bb_m:
            keep &= points_m[:, column] <= mask_bb_m[f"{axis}max"]
    return keep


def radar_erosion_kernel_px(mask_erosion: int) -> int:
    """Radar kernel size from metadata `mask_erosion`: Python's round(E / 4) (banker's: 10 -> 2, 20 -> 5)."""
    return int(round(mask_erosion / 4))


def erode_mask(mask: np.ndarray, kernel_px: int) -> np.ndarray:
    """OpenCV-style erosion with a k x k rectangle (pixels beyond the border count as foreground).

    Like MAROON, the kernel shrinks by one while the result keeps <= 10 pixels; the loop always ends (at k = 1,
    the identity), also for masks that MAROON's retry loop never leaves.
    """
    mask = np.asarray(mask, dtype=bool)
    for k in range(int(kernel_px), 1, -1):
        eroded = ndimage.binary_erosion(mask, structure=np.ones((k, k), dtype=bool), border_value=1)
        if eroded.sum() > _MIN_KEPT_PX:
            return eroded
    return mask.copy()
