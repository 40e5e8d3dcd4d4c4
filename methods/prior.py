"""Per-pixel depth priors on the radar pixel grid for MM-2FSK (paper section II-B, eqs. 9-10).

RealSense prior: the valid (masked, nonzero) depth pixels are back-projected with the colour intrinsics
(X = (u - cx) Z / fx, Y = (v - cy) Z / fy, Z in mm; integer u = column, v = row, MAROON_FORMAT.md 3.2),
triangulated in 2-D, transformed with `realsense2radar` (mm -> m inside the matrix) and rasterised
orthographically onto the radar pixel centres with barycentric interpolation, keeping the nearest surface.

Triangulation: instead of a Delaunay triangulation of all valid pixels (about 4 s for 300k points here), the
image grid is triangulated directly (two triangles per valid 2x2 quad, one for a quad with three valid
corners; these are Delaunay triangles of the pixel lattice), and the empty radar pixels inside the convex hull
are then filled from a Delaunay triangulation of the rim of the covered radar region (`raster.fill_convex_hull`).
Over a hole both give planar triangles between rim samples, so the result is a linear interpolation across
the hole as in the paper, with rim samples on the radar grid instead of the camera grid.

Photogrammetry prior (paper Table II): the mesh vertices go through `photogrammetry2radar` and are rasterised
the same way (MAROON_FORMAT.md 4.2, 6.3 step 4), then holes are filled identically.
"""
from __future__ import annotations

import numpy as np

from bench.alignment import apply_transform
from bench.capture import DepthFrame, Mesh, RadarGrid
from methods.raster import fill_convex_hull, rasterize_nearest_z


def grid_triangles(valid: np.ndarray, quads: np.ndarray | None = None) -> np.ndarray:
    """(T, 3) flat pixel indices (row * W + col) of the lattice triangulation of the valid pixels (H, W).

    `quads` (H-1, W-1) bool optionally restricts it to the quads whose top-left corner is marked.
    """
    height, width = valid.shape
    idx = np.arange(height * width).reshape(height, width)
    p00, p01, p10, p11 = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    v00, v01, v10, v11 = valid[:-1, :-1], valid[:-1, 1:], valid[1:, :-1], valid[1:, 1:]
    if quads is not None:
        v00, v11 = v00 & quads, v11 & quads
    cases = (
        (v00 & v10 & v01, (p00, p10, p01)),           # upper-left half of a quad
        (v11 & v01 & v10, (p11, p01, p10)),           # lower-right half
        (v00 & v10 & v11 & ~v01, (p00, p10, p11)),    # three valid corners, top-right missing
        (v00 & v11 & v01 & ~v10, (p00, p11, p01)),    # three valid corners, bottom-left missing
    )
    return np.concatenate([np.column_stack([c[sel] for c in corners]) for sel, corners in cases])


def quads_around_centres(cols: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """(H-1, W-1) bool: lattice quads whose column and row ranges both contain an integer, i.e. that may cover
    a radar pixel centre. cols, rows: (H, W) radar pixel coordinates of the camera pixels, NaN where invalid.

    Camera pixels are smaller than radar pixels, so this drops most quads before any triangle is formed.
    """
    def spans_integer(a: np.ndarray) -> np.ndarray:
        lo = np.fmin(np.fmin(a[:-1, :-1], a[:-1, 1:]), np.fmin(a[1:, :-1], a[1:, 1:]))
        hi = np.fmax(np.fmax(a[:-1, :-1], a[:-1, 1:]), np.fmax(a[1:, :-1], a[1:, 1:]))
        return np.ceil(lo - 1e-9) <= np.floor(hi + 1e-9)

    return spans_integer(cols) & spans_integer(rows)


def backproject_mm(depth: DepthFrame) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame points (N, 3) in mm of the valid pixels and the (H, W) validity mask (paper eq. 9)."""
    valid = depth.depth_mm > 0
    if depth.mask is not None:
        valid &= depth.mask
    rows, cols = np.nonzero(valid)
    k = depth.intrinsics
    z_mm = depth.depth_mm[rows, cols] * (depth.depth_scale_m * 1000.0)
    points_mm = np.column_stack([(cols - k.cx) * z_mm / k.fx, (rows - k.cy) * z_mm / k.fy, z_mm])
    return points_mm, valid


def _to_radar_pixels(points_m: np.ndarray, grid: RadarGrid) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (column, row) of radar-space points on `grid`'s pixel centres, row 0 = +y."""
    (xmin, ymin, _), (xmax, ymax, _) = grid.bb_min_m, grid.bb_max_m
    nx, ny, _ = grid.size
    cols = (points_m[:, 0] - xmin) * ((nx - 1) / (xmax - xmin))
    rows = (ymax - points_m[:, 1]) * ((ny - 1) / (ymax - ymin))
    return cols, rows


def rasterize_prior(points_m: np.ndarray, triangles: np.ndarray, grid: RadarGrid,
                    fill_holes: bool = True) -> np.ndarray:
    """Nearest-surface radar depth (ny, nx) in metres of a radar-space mesh; NaN where it has no prior."""
    cols, rows = _to_radar_pixels(points_m, grid)
    prior_m = rasterize_nearest_z(cols, rows, points_m[:, 2], triangles, grid.image_shape)
    return fill_convex_hull(prior_m) if fill_holes else prior_m


def realsense_prior_m(depth: DepthFrame, realsense2radar: np.ndarray, grid: RadarGrid,
                      fill_holes: bool = True) -> np.ndarray:
    """Radar-grid depth prior (ny, nx) in metres from a RealSense depth frame; NaN = no prior."""
    points_mm, valid = backproject_mm(depth)
    points_m = apply_transform(realsense2radar, points_mm)
    cols, rows = _to_radar_pixels(points_m, grid)
    col_img, row_img = np.full(valid.shape, np.nan), np.full(valid.shape, np.nan)
    col_img[valid], row_img[valid] = cols, rows
    index = np.full(valid.shape, -1, dtype=np.int64)
    index[valid] = np.arange(len(points_mm))
    triangles = index.ravel()[grid_triangles(valid, quads_around_centres(col_img, row_img))]
    return rasterize_prior(points_m, triangles, grid, fill_holes)


def mesh_prior_m(mesh: Mesh, photogrammetry2radar: np.ndarray, grid: RadarGrid,
                 fill_holes: bool = True) -> np.ndarray:
    """Radar-grid depth prior (ny, nx) in metres from the photogrammetry mesh; NaN = no prior."""
    return rasterize_prior(apply_transform(photogrammetry2radar, mesh.vertices), mesh.triangles, grid, fill_holes)
