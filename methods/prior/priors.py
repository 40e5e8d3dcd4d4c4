"""Per-pixel depth priors on the radar pixel grid for MM-2FSK (paper section II-B, eqs. 9-10).

RealSense prior: the valid (masked, nonzero) depth pixels are back-projected with the colour intrinsics
(X = (u - cx) Z / fx, Y = (v - cy) Z / fy, Z in mm; integer u = column, v = row, MAROON_FORMAT.md 3.2),
triangulated on the image lattice, transformed with `realsense2radar` (mm -> m inside the matrix) and rasterised
orthographically onto the radar pixel centres with barycentric interpolation, keeping the nearest surface.

Triangulation: the image lattice (MAROON's quad split, methods.domain.lattice) instead of a Delaunay triangulation
of all valid pixels (about 4 s for 300k points here). Depth-jump rule (default, as MAROON's viewer does): a
triangle is dropped when a checked edge joins camera depths more than `max_jump_mm` (10 mm) apart: a triangle
across a depth discontinuity (an object's edge in front of the background, or a held object in front of the
hand) is no surface, and rasterising it would invent depths between the two. `max_jump_mm=None` keeps them.
Holes (setting `fill`): 'delaunay' fills the empty radar pixels inside the convex hull of the covered ones from a
Delaunay triangulation of the rim of the covered region (`raster.fill_convex_hull`), the same planar interpolation
across a hole as the paper's Delaunay of all pixels; 'scanline' interpolates linearly along each empty pixel's row
and column between the nearest covered pixels (`raster.fill_scanline`): no triangulation, so a GPU kernel computes
it exactly (Qhull's tie-breaks between cocircular lattice points set the Delaunay fill's values, and Qhull runs on
the host only). Both reproduce a plane exactly; docs/measurements/prior.md "Hole fill" gives their measured cost
and error.

`faithful=True` builds the prior as the reference code does (the faithful profile): it samples pixel (v, u) at
MAROON's shifted position K^-1 (u + 0.5, v + 0.5) instead of the pixel centre (up to one pixel off at the far
edges; metrics.evaluate.maroon_sample_xy_m), triangulates with its quad rule (the three-valid-quad quirk,
methods.domain.lattice 'maroon') and fills holes by a Delaunay triangulation of all covered pixels' integer
(column, row) positions re-rasterised (scipy's Qhull, as the reference uses). Pixels it leaves uncovered stay NaN
(the reference starts them at z = 0).

Photogrammetry prior (paper Table II): the mesh vertices go through `photogrammetry2radar` and are rasterised
the same way (MAROON_FORMAT.md 4.2, 6.3 step 4), then holes are filled identically. GPU mirror:
methods/warp_backend (the same depth-jump rule per lattice triangle, in camera millimetres).
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import Delaunay, QhullError

from methods.domain.capture import DepthFrame, Mesh, RadarGrid
from methods.domain.errors import UsageError
from methods.domain.lattice import lattice_triangles
from methods.domain.transforms import apply_transform
from methods.prior.raster import fill_convex_hull, fill_scanline, rasterize_nearest_z

DEFAULT_MAX_JUMP_MM = 10.0   # MAROON's triangulation threshold in optical spaces (MAROON_FORMAT.md 3.2, 5.2)
FILLS = {"delaunay": fill_convex_hull, "scanline": fill_scanline}   # hole-fill rules (module doc)
# measured: same metrics as delaunay on the catalogue, no host Qhull (docs/measurements/prior.md)
DEFAULT_FILL = "scanline"


def check_fill(fill: str) -> str:
    """`fill` if it names a hole-fill rule, else UsageError listing them."""
    if fill not in FILLS:
        raise UsageError(f"unknown prior fill {fill!r}; choose one of {', '.join(FILLS)}")
    return fill


def grid_triangles(depth_mm: np.ndarray, valid: np.ndarray, quads: np.ndarray | None = None,
                   max_jump_mm: float | None = DEFAULT_MAX_JUMP_MM, rule: str = "sound") -> np.ndarray:
    """(T, 3) flat pixel indices (row * W + col) of the lattice triangles of a depth image (H, W) in mm.

    valid: (H, W) pixels with a depth; quads: optional (H-1, W-1) bool of the quads to consider (top-left corner);
    max_jump_mm: the depth-jump rule (None = off); rule: three-valid quads, 'sound' or 'maroon'
    (methods.domain.lattice). For a GPU mirror: a quad with four valid corners gives (p00, p10, p01) when
    |z00 - z10| and |z10 - z01| are <= max_jump_mm and (p11, p01, p10) when |z11 - z01| and |z01 - z10| are; one
    with three valid corners gives their triangle when all three of its jumps are (rule 'sound').
    """
    return lattice_triangles(depth_mm, max_jump_mm, rule, quads=quads, valid=valid)


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


def _to_radar_pixels(points_m: np.ndarray, grid: RadarGrid, faithful: bool = False
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Continuous (column, row) of radar-space points, integers at the sample positions, row 0 = +y: the pixel
    centres, or with `faithful` MAROON's K^-1 (u + 0.5, v + 0.5) (K of MAROON_FORMAT.md 2.4)."""
    if faithful:
        k = grid.intrinsics()
        return k[0, 0] * points_m[:, 0] + k[0, 3] - 0.5, k[1, 1] * points_m[:, 1] + k[1, 3] - 0.5
    (xmin, ymin, _), (xmax, ymax, _) = grid.bb_min_m, grid.bb_max_m
    nx, ny, _ = grid.size
    cols = (points_m[:, 0] - xmin) * ((nx - 1) / (xmax - xmin))
    rows = (ymax - points_m[:, 1]) * ((ny - 1) / (ymax - ymin))
    return cols, rows


def delaunay_fill(image: np.ndarray) -> np.ndarray:
    """The reference's hole filling: Delaunay triangulation of the covered pixels' integer (column, row)
    positions (row-major order), re-rasterised with their depths; outside the hull NaN."""
    rows, cols = np.nonzero(np.isfinite(image))
    try:
        simplices = Delaunay(np.column_stack([cols, rows]).astype(np.float64)).simplices
    except (QhullError, ValueError):          # fewer than 3 pixels, or all on one line: nothing to fill
        return image.copy()
    filled = rasterize_nearest_z(cols.astype(np.float64), rows.astype(np.float64), image[rows, cols], simplices,
                                 image.shape)
    return np.where(np.isfinite(image), image, filled)


def rasterize_prior(points_m: np.ndarray, triangles: np.ndarray, grid: RadarGrid,
                    fill_holes: bool = True, faithful: bool = False, fill: str = DEFAULT_FILL) -> np.ndarray:
    """Nearest-surface radar depth (ny, nx) in metres of a radar-space mesh; NaN where it has no prior.
    fill: the hole-fill rule (module doc; `faithful` always takes the reference's Delaunay of all pixels)."""
    check_fill(fill)
    cols, rows = _to_radar_pixels(points_m, grid, faithful)
    prior_m = rasterize_nearest_z(cols, rows, points_m[:, 2], triangles, grid.image_shape)
    if not fill_holes:
        return prior_m
    return delaunay_fill(prior_m) if faithful else FILLS[fill](prior_m)


def _bounding_box(valid: np.ndarray) -> tuple[slice, slice]:
    """Rows and columns of an (H, W) bool image's bounding box of True pixels (empty slices when none)."""
    rows, cols = np.flatnonzero(valid.any(axis=1)), np.flatnonzero(valid.any(axis=0))
    if not len(rows):
        return slice(0, 0), slice(0, 0)
    return slice(rows[0], rows[-1] + 1), slice(cols[0], cols[-1] + 1)


def realsense_prior_m(depth: DepthFrame, realsense2radar: np.ndarray, grid: RadarGrid,
                      fill_holes: bool = True, max_jump_mm: float | None = DEFAULT_MAX_JUMP_MM,
                      faithful: bool = False, fill: str = DEFAULT_FILL) -> np.ndarray:
    """Radar-grid depth prior (ny, nx) in metres from a RealSense depth frame; NaN = no prior.

    max_jump_mm: the depth-jump rule (module doc; None = off); faithful: the reference's construction; fill: the
    hole-fill rule ('delaunay' | 'scanline', module doc)."""
    points_mm, valid = backproject_mm(depth)
    points_m = apply_transform(realsense2radar, points_mm)
    cols, rows = _to_radar_pixels(points_m, grid, faithful)
    if not faithful:   # the 'sound' rule sees each quad's own corners only: the valid pixels' bounding box suffices
        valid = valid[_bounding_box(valid)]      # (masked objects: 3-10x fewer pixels; same triangles, same order)
    col_img, row_img = np.full(valid.shape, np.nan), np.full(valid.shape, np.nan)
    col_img[valid], row_img[valid] = cols, rows
    z_mm = np.zeros(valid.shape)
    z_mm[valid] = points_mm[:, 2]
    index = np.full(valid.shape, -1, dtype=np.int64)
    index[valid] = np.arange(len(points_mm))
    lattice = grid_triangles(z_mm, valid, quads_around_centres(col_img, row_img), max_jump_mm,
                             "maroon" if faithful else "sound")
    return rasterize_prior(points_m, index.ravel()[lattice], grid, fill_holes, faithful, fill)


def mesh_prior_m(mesh: Mesh, photogrammetry2radar: np.ndarray, grid: RadarGrid,
                 fill_holes: bool = True, faithful: bool = False, fill: str = DEFAULT_FILL) -> np.ndarray:
    """Radar-grid depth prior (ny, nx) in metres from the photogrammetry mesh; NaN = no prior (fill as
    `realsense_prior_m`)."""
    return rasterize_prior(apply_transform(photogrammetry2radar, mesh.vertices), mesh.triangles, grid, fill_holes,
                           faithful, fill)
