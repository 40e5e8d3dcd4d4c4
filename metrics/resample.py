"""Depth maps onto the metric grid: every method is scored on one pixel grid per capture, whatever it computed on.

Rule (`resample_depth_m`): a metric pixel centre takes the bilinear interpolation of the four surrounding computed
pixels when all four are valid and within the triangulation threshold (1 cm) of each other, i.e. lie on one surface
as the metrics' grid triangulation defines it; otherwise the depth of the nearest computed pixel (NaN if that one
is invalid), so a computed pixel keeps its footprint and a depth step is not smeared into a ramp. Metric pixels
more than half a computed pixel outside the computed grid are invalid.
"""
from __future__ import annotations

import numpy as np

from methods.domain.capture import RadarGrid

SURFACE_JUMP_M = 0.01     # = metrics.evaluate.TRIANGULATION_THRESHOLD_M: one surface for the triangulation


def same_pixels(a: RadarGrid, b: RadarGrid) -> bool:
    """True when both grids have the same pixel centres in x and y (depth sampling may differ)."""
    return (a.size[:2] == b.size[:2] and np.allclose(a.bb_min_m[:2], b.bb_min_m[:2], rtol=0, atol=1e-9)
            and np.allclose(a.bb_max_m[:2], b.bb_max_m[:2], rtol=0, atol=1e-9))


def _fractional_index(coords_m: np.ndarray, axis_m: np.ndarray) -> np.ndarray:
    """Position of `coords_m` in units of the (uniform) `axis_m` spacing, 0 at axis_m[0]."""
    if axis_m.size == 1:
        return np.zeros_like(coords_m)
    return (coords_m - axis_m[0]) / (axis_m[1] - axis_m[0])


def _positions(src: RadarGrid, dst: RadarGrid) -> tuple[np.ndarray, np.ndarray]:
    """Fractional (column, row) of every `dst` pixel centre in `src`: columns along +x, rows along -y."""
    return _fractional_index(dst.x_m, src.x_m), _fractional_index(dst.y_m[::-1], src.y_m[::-1])


def _inside(f: np.ndarray, n: int) -> np.ndarray:
    """Positions within half a pixel of a source axis of `n` pixels."""
    return (f >= -0.5) & (f <= n - 0.5)


def _nearest(values: np.ndarray, fx: np.ndarray, fy: np.ndarray) -> np.ndarray:
    """Nearest-pixel lookup; NaN more than half a pixel outside the source image."""
    ny, nx = values.shape
    near_c, near_r = np.clip(np.rint(fx), 0, nx - 1).astype(int), np.clip(np.rint(fy), 0, ny - 1).astype(int)
    out = values[np.ix_(near_r, near_c)].astype(np.float64)
    out[~_inside(fy, ny), :] = np.nan
    out[:, ~_inside(fx, nx)] = np.nan
    return out


def resample_nearest(values: np.ndarray, src: RadarGrid, dst: RadarGrid) -> np.ndarray:
    """(ny, nx) of `dst` from an image on `src` by nearest pixel (e.g. a magnitude map); NaN outside `src`."""
    values = np.asarray(values)
    return values.astype(np.float64) if same_pixels(src, dst) else _nearest(values, *_positions(src, dst))


def resample_depth_m(depth_m: np.ndarray, src: RadarGrid, dst: RadarGrid) -> np.ndarray:
    """(ny, nx) depth of `dst` (metres, NaN = invalid) from a depth map on `src` by the module's rule."""
    depth_m = np.asarray(depth_m, dtype=np.float64)
    if same_pixels(src, dst):
        return depth_m.copy()
    fx, fy = _positions(src, dst)
    ny, nx = src.image_shape
    nearest = _nearest(depth_m, fx, fy)
    c0 = np.clip(np.floor(fx), 0, max(nx - 2, 0)).astype(int)
    r0 = np.clip(np.floor(fy), 0, max(ny - 2, 0)).astype(int)
    c1, r1 = np.minimum(c0 + 1, nx - 1), np.minimum(r0 + 1, ny - 1)
    wx, wy = np.clip(fx - c0, 0.0, 1.0)[None, :], np.clip(fy - r0, 0.0, 1.0)[:, None]
    z00, z01 = depth_m[np.ix_(r0, c0)], depth_m[np.ix_(r0, c1)]
    z10, z11 = depth_m[np.ix_(r1, c0)], depth_m[np.ix_(r1, c1)]
    corners = np.stack([z00, z01, z10, z11])
    with np.errstate(invalid="ignore"):
        one_surface = np.all(np.isfinite(corners), axis=0) & (np.ptp(corners, axis=0) <= SURFACE_JUMP_M)
    bilinear = (z00 * (1 - wx) + z01 * wx) * (1 - wy) + (z10 * (1 - wx) + z11 * wx) * wy
    inside = _inside(fy, ny)[:, None] & _inside(fx, nx)[None, :]
    return np.where(one_surface & inside, bilinear, nearest)
