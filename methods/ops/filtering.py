"""Depth filtering shared by all methods (paper section III-B): keep pixels whose magnitude is within
`threshold_db` of the image maximum (default 14 dB, MAROON_FORMAT.md section 7); the rest become NaN.
A pixel of zero magnitude has no phase and no peak, so it is never kept (an all-zero frame gives no depth)."""
from __future__ import annotations

import numpy as np

DEFAULT_THRESHOLD_DB = 14.0


def keep_mask(magnitude: np.ndarray, threshold_db: float | None = DEFAULT_THRESHOLD_DB) -> np.ndarray:
    """True where `magnitude` (linear, NaN = not evaluated) > 0 and >= max * 10^(-threshold_db/20).

    `threshold_db=None` keeps every evaluated pixel of nonzero magnitude. The threshold is in dB below the maximum
    (positive).
    """
    magnitude = np.asarray(magnitude)
    if threshold_db is not None and threshold_db >= 0 and magnitude.size and magnitude.dtype.kind == "f":
        # one NaN-skipping pass for the maximum, one comparison: a finite positive floor keeps exactly the finite
        # positive pixels at or above it (the general rule below makes ~7 passes: 0.39 against 0.1 ms for BP's
        # 301x301 maps on the H100's host)
        peak = np.fmax.reduce(magnitude, axis=None)
        floor = peak * 10.0 ** (-threshold_db / 20.0)
        if np.isfinite(peak) and floor > 0:
            with np.errstate(invalid="ignore"):
                return magnitude >= floor
    finite = np.isfinite(magnitude) & (magnitude > 0)
    if threshold_db is None or not finite.any():
        return finite
    if threshold_db < 0:
        raise ValueError(f"threshold_db is dB below the maximum and must be >= 0, got {threshold_db}")
    floor = np.max(magnitude[finite]) * 10.0 ** (-threshold_db / 20.0)
    with np.errstate(invalid="ignore"):
        return finite & (magnitude >= floor)


def filter_depth(depth_m: np.ndarray, magnitude: np.ndarray,
                 threshold_db: float | None = DEFAULT_THRESHOLD_DB) -> np.ndarray:
    """Copy of `depth_m` with pixels below the magnitude threshold (or not evaluated) set to NaN."""
    return np.where(keep_mask(magnitude, threshold_db), depth_m, np.nan)
