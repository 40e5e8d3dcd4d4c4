"""Orthographic triangle rasterisation onto an image grid with a nearest-z buffer, and convex-hull hole filling.

Coordinates are continuous pixel units: `u` = column, `v` = row, pixel centres at integers (so a radar pixel
(i, j) samples exactly the RadarGrid centre x_m[j], y_m[ny-1-i]; no half-voxel quirk of MAROON's K). Each pixel
centre inside a triangle (edges inclusive) gets the triangle's plane value there (= barycentric interpolation,
exact for an orthographic view); where several triangles cover a centre the smallest z (nearest to the radar) wins.

The rasteriser is a vectorised scanline: triangles are expanded into the pixel rows they cross, each row into
its covered columns, so the work grows with the number of covered pixels, not with triangle bounding boxes.
"""
from __future__ import annotations

import numpy as np
from scipy import ndimage
from scipy.spatial import Delaunay, QhullError

_EPS_PX = 1e-9   # inclusive edges: centres on a shared edge belong to both triangles (same z there)


def _expand(starts: np.ndarray, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For items with `counts[k]` consecutive integers from `starts[k]`: (item index, integer) per element."""
    item = np.repeat(np.arange(len(counts)), counts)
    first = np.cumsum(counts) - counts
    return item, starts[item] + (np.arange(len(item)) - first[item])


def rasterize_nearest_z(u: np.ndarray, v: np.ndarray, z: np.ndarray, triangles: np.ndarray,
                        shape: tuple[int, int]) -> np.ndarray:
    """Nearest-z image (rows, cols) float64 of a triangle mesh; NaN where no triangle covers a pixel centre.

    u, v, z: (V,) vertex columns, rows (pixel units) and depths; triangles: (T, 3) vertex indices.
    """
    n_rows, n_cols = shape
    tu = [u[triangles[:, k]] for k in range(3)]                               # per-vertex columns, rows, z
    tv = [v[triangles[:, k]] for k in range(3)]
    row_lo = np.ceil(np.minimum(np.minimum(tv[0], tv[1]), tv[2]) - _EPS_PX)
    row_hi = np.floor(np.maximum(np.maximum(tv[0], tv[1]), tv[2]) + _EPS_PX)
    keep = ((row_hi >= np.maximum(row_lo, 0)) & (row_lo <= n_rows - 1)
            & (np.maximum(np.maximum(tu[0], tu[1]), tu[2]) >= -_EPS_PX)
            & (np.minimum(np.minimum(tu[0], tu[1]), tu[2]) <= n_cols - 1 + _EPS_PX))
    tu, tv = [c[keep] for c in tu], [c[keep] for c in tv]
    tz = [z[triangles[keep, k]] for k in range(3)]
    row_lo = np.maximum(row_lo[keep], 0).astype(np.int64)
    row_hi = np.minimum(row_hi[keep], n_rows - 1).astype(np.int64)
    du1, du2 = tu[1] - tu[0], tu[2] - tu[0]
    dv1, dv2 = tv[1] - tv[0], tv[2] - tv[0]
    dz1, dz2 = tz[1] - tz[0], tz[2] - tz[0]
    area2 = du1 * dv2 - du2 * dv1
    with np.errstate(divide="ignore", invalid="ignore"):
        slope_u = (dz1 * dv2 - dz2 * dv1) / area2                             # dz/du of the triangle plane
        slope_v = (du1 * dz2 - du2 * dz1) / area2                             # dz/dv
    flat = np.abs(area2) <= 1e-12                                             # edge-on: covers no area
    row_hi[flat] = row_lo[flat] - 1

    tri, row = _expand(row_lo, row_hi - row_lo + 1)
    rowf = row.astype(np.float64)
    col_lo = np.full(len(tri), np.inf)
    col_hi = np.full(len(tri), -np.inf)
    for a, b in ((0, 1), (1, 2), (2, 0)):                                    # row line x each edge
        va, vb, ua, ub = tv[a][tri], tv[b][tri], tu[a][tri], tu[b][tri]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = (rowf - va) / (vb - va)
        crosses = (t >= -_EPS_PX) & (t <= 1 + _EPS_PX)                      # False for horizontal edges (NaN/inf)
        col = np.where(crosses, ua + t * (ub - ua), np.nan)
        np.fmin(col_lo, col, out=col_lo)
        np.fmax(col_hi, col, out=col_hi)
    first = np.maximum(np.ceil(col_lo - _EPS_PX), 0)
    last = np.minimum(np.floor(col_hi + _EPS_PX), n_cols - 1)
    has = last >= first                                                       # False for inf/NaN intervals
    tri, row = tri[has], row[has]
    seg, col = _expand(first[has].astype(np.int64), (last[has] - first[has]).astype(np.int64) + 1)
    tri, row = tri[seg], row[seg]
    depth = tz[0][tri] + slope_u[tri] * (col - tu[0][tri]) + slope_v[tri] * (row - tv[0][tri])

    zbuf = np.full(n_rows * n_cols, np.inf)
    np.minimum.at(zbuf, row * n_cols + col, depth)
    zbuf[np.isinf(zbuf)] = np.nan
    return zbuf.reshape(n_rows, n_cols)


def fill_convex_hull(image: np.ndarray) -> np.ndarray:
    """Fill the empty (NaN) pixels inside the convex hull of the covered ones by linear interpolation.

    Equivalent to the paper's Delaunay triangulation of all covered pixels: only its triangles over empty
    pixels matter, and those have vertices on the rim of the covered region (a Delaunay triangle with a vertex
    whose 8 neighbours are all covered has a circumradius < 0.8 px and covers no empty pixel centre), so the
    Delaunay triangulation of the rim pixels alone contains them. Pixels outside the hull stay NaN.
    """
    covered = np.isfinite(image)
    if covered.all() or not covered.any():
        return image.copy()
    rim = covered & ~ndimage.binary_erosion(covered, structure=np.ones((3, 3), bool), border_value=0)
    rows, cols = np.nonzero(rim)
    try:
        triangulation = Delaunay(np.column_stack([cols, rows]).astype(np.float64))
    except (QhullError, ValueError):          # fewer than 3 rim pixels, or all on one line: no area to fill
        return image.copy()
    fill = rasterize_nearest_z(cols.astype(np.float64), rows.astype(np.float64), image[rows, cols],
                               triangulation.simplices, image.shape)
    return np.where(covered, image, fill)


def _nearest_covered(covered: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per pixel of an (n, m) bool image, the index along axis 1 of the nearest covered pixel before it and after
    it in its row (-1 and m where there is none)."""
    index = np.arange(covered.shape[1])
    before = np.maximum.accumulate(np.where(covered, index, -1), axis=1)
    after = np.minimum.accumulate(np.where(covered, index, covered.shape[1])[:, ::-1], axis=1)[:, ::-1]
    return before, after


def _span_estimate(image: np.ndarray, covered: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(linear interpolation, span in pixels) along each row between the nearest covered pixels on either side;
    span 0 where a side has none."""
    before, after = _nearest_covered(covered)
    rows, cols = np.indices(image.shape)
    two_sided = (before >= 0) & (after < image.shape[1])
    lo = np.where(two_sided, before, 0)
    hi = np.where(two_sided, after, 0)
    span = np.where(two_sided, hi - lo, 0)
    z_lo, z_hi = image[rows, lo], image[rows, hi]
    with np.errstate(invalid="ignore", divide="ignore"):
        estimate = z_lo + (z_hi - z_lo) * ((cols - lo) / span)
    return np.where(two_sided, estimate, np.nan), span


def fill_scanline(image: np.ndarray) -> np.ndarray:
    """Fill each empty (NaN) pixel that has covered pixels on both sides in its row or in its column: the linear
    interpolation between the nearest covered pixels along the row (z_r, span s_r pixels) and along the column
    (z_c, s_c), combined with weights 1 / span, i.e. z = (z_r s_c + z_c s_r) / (s_r + s_c) (one of them alone
    where only one direction is two-sided). Pixels with neither keep NaN.

    The hull fill without a triangulation (setting `fill=scanline` of `methods.prior.priors`): every value is a fixed
    float64 expression of at most four covered pixels, so a kernel reproduces it (methods.backends.warp.kernels.prior);
    a plane is reproduced exactly, as by the Delaunay fill. It fills the holes and the gaps between objects the
    Delaunay fill fills, but not the concave notches of an outline that no row or column crosses twice.
    """
    covered = np.isfinite(image)
    if covered.all() or not covered.any():
        return image.copy()
    z_row, s_row = _span_estimate(image, covered)
    z_col, s_col = (a.T for a in _span_estimate(image.T, covered.T))
    with np.errstate(invalid="ignore", divide="ignore"):
        both = (z_row * s_col + z_col * s_row) / (s_row + s_col)
    fill = np.where(s_row > 0, np.where(s_col > 0, both, z_row), z_col)
    return np.where(covered, image, fill)
