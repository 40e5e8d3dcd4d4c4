"""MM-2FSK on the GPU: the depth prior rasterised with Warp, then correlation, depth and filter on the device.

Used by `methods.api.reconstruct` for method="mm2fsk" on device="cuda" (the functions also run on "warp-cpu",
which the tests use as a reference for the kernels without a GPU). The CPU prior (`methods.prior`) is the
specification; this path reproduces it step by step in float64:

* `_camera_quads_kernel`: one thread per 2x2 quad of the depth image. Its four corners are back-projected with the
  intrinsics (paper eq. 9, same float64 expressions as `prior.backproject_mm`), mapped with realsense2radar
  (`apply_transform`'s order of operations) onto continuous radar pixel coordinates, and the quad's triangles are
  formed exactly as `prior.grid_triangles` does (2 triangles, or 1 for three valid corners). The quad culling of
  `prior.quads_around_centres` is not needed: it only drops triangles that cover no pixel centre.
* `_raster_tri`: the scanline rasteriser of `raster.rasterize_nearest_z` for one triangle (same row range, edge
  crossings, inclusive 1e-9 px epsilon, plane evaluation), nearest z kept with a float64 `atomic_min` z-buffer.
  Camera pixels are smaller than radar pixels, so a triangle covers 0-2 centres and the loops stay short.
* Hull fill (`raster.fill_convex_hull`): the device counts the covered pixels, each row's first/last covered
  column, and, exactly in integer arithmetic, the lattice points of the convex hull of the covered pixels (row r of
  the hull spans the extreme interpolations between the covered rows i <= r <= j; `_hull_rows_kernel`). The fill
  can add pixels only if the hull holds more lattice points than are covered (it fills exactly those inside the
  hull); only then is the z-buffer copied back, filled with the CPU function itself (exact; ~5-10 ms for a masked
  object with holes or notches) and uploaded again. One 8-byte copy back decides. A prior with nothing to fill (e.g. a surface that covers the whole radar grid) never leaves the GPU.
* MM-2FSK: covered pixels are compacted on the device (atomic slot counter; slots are per-point independent, so the
  order does not change any value), correlated with the backend's default kernel on device-resident points, then
  depth = prior - c angle(c2 conj c1) / (4 pi (f2 - f1)), magnitude = |(c1 + c2) / 2|, the max magnitude
  (atomic max) and the filter threshold are applied on the device; one copy back of (depth, magnitude, prior).
"""
from __future__ import annotations

import time

import numpy as np
import warp as wp

from bench.alignment import apply_transform
from bench.capture import DepthFrame, Mesh, RadarGrid
from methods import backend_warp
from methods.correlate import C_M_PER_S, _check_inputs
from methods.filtering import DEFAULT_THRESHOLD_DB
from methods.reconstruction import Reconstruction
from methods.timing import StageTimer

_FAR = wp.constant(wp.float64(1.0e300))          # z-buffer value of an uncovered pixel
_EPS = wp.constant(wp.float64(1e-9))            # raster._EPS_PX
vec9d = wp.types.vector(length=9, dtype=wp.float64)   # fx, fy, cx, cy, mm per depth unit, xmin, ymax, px/m x, y
FAR_M = 1.0e300


@wp.func
def _edge_span(rowf: wp.float64, ua: wp.float64, va: wp.float64, ub: wp.float64, vb: wp.float64,
               lo: wp.float64, hi: wp.float64):
    """Column where the row line crosses edge a-b (t in [-eps, 1 + eps]) merged into [lo, hi]."""
    if vb != va:                                 # horizontal edges never cross (inf/NaN t on the CPU)
        t = (rowf - va) / (vb - va)
        if t >= -_EPS and t <= wp.float64(1.0) + _EPS:
            col = ua + t * (ub - ua)
            lo = wp.min(lo, col)
            hi = wp.max(hi, col)
    return lo, hi


@wp.func
def _raster_tri(u0: wp.float64, v0: wp.float64, z0: wp.float64, u1: wp.float64, v1: wp.float64, z1: wp.float64,
                u2: wp.float64, v2: wp.float64, z2: wp.float64, n_rows: int, n_cols: int,
                zbuf: wp.array(dtype=wp.float64)):
    """One triangle of `raster.rasterize_nearest_z` into the nearest-z buffer (row-major n_rows x n_cols)."""
    row_lo = wp.ceil(wp.min(wp.min(v0, v1), v2) - _EPS)
    row_hi = wp.floor(wp.max(wp.max(v0, v1), v2) + _EPS)
    last_row = wp.float64(n_rows - 1)
    last_col = wp.float64(n_cols - 1)
    if row_hi < wp.max(row_lo, wp.float64(0.0)) or row_lo > last_row:
        return
    if wp.max(wp.max(u0, u1), u2) < -_EPS or wp.min(wp.min(u0, u1), u2) > last_col + _EPS:
        return
    du1 = u1 - u0
    du2 = u2 - u0
    dv1 = v1 - v0
    dv2 = v2 - v0
    dz1 = z1 - z0
    dz2 = z2 - z0
    area2 = du1 * dv2 - du2 * dv1
    if wp.abs(area2) <= wp.float64(1e-12):
        return
    slope_u = (dz1 * dv2 - dz2 * dv1) / area2
    slope_v = (du1 * dz2 - du2 * dz1) / area2
    r_first = wp.int32(wp.max(row_lo, wp.float64(0.0)))
    r_last = wp.int32(wp.min(row_hi, last_row))
    for row in range(r_first, r_last + 1):
        rowf = wp.float64(row)
        lo = _FAR
        hi = -_FAR
        lo, hi = _edge_span(rowf, u0, v0, u1, v1, lo, hi)
        lo, hi = _edge_span(rowf, u1, v1, u2, v2, lo, hi)
        lo, hi = _edge_span(rowf, u2, v2, u0, v0, lo, hi)
        if hi >= lo:
            first = wp.max(wp.ceil(lo - _EPS), wp.float64(0.0))
            last = wp.min(wp.floor(hi + _EPS), last_col)
            if last >= first:
                for col in range(wp.int32(first), wp.int32(last) + 1):
                    depth = z0 + slope_u * (wp.float64(col) - u0) + slope_v * (rowf - v0)
                    wp.atomic_min(zbuf, row * n_cols + col, depth)


@wp.func
def _corner(depth: wp.array2d(dtype=wp.uint16), mask: wp.array2d(dtype=wp.uint8), use_mask: int, r: int, c: int,
            cam: vec9d, xf: wp.mat44d):
    """(u, v, z, valid) of camera pixel (r, c): radar column, row and depth; valid 1 or 0."""
    d = depth[r, c]
    if d == wp.uint16(0):
        return wp.vec4d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0), wp.float64(0.0))
    if use_mask != 0 and mask[r, c] == wp.uint8(0):
        return wp.vec4d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0), wp.float64(0.0))
    z_mm = wp.float64(d) * cam[4]
    x_mm = (wp.float64(c) - cam[2]) * z_mm / cam[0]
    y_mm = (wp.float64(r) - cam[3]) * z_mm / cam[1]
    px = xf[0, 0] * x_mm + xf[0, 1] * y_mm + xf[0, 2] * z_mm
    px += xf[0, 3]
    py = xf[1, 0] * x_mm + xf[1, 1] * y_mm + xf[1, 2] * z_mm
    py += xf[1, 3]
    pz = xf[2, 0] * x_mm + xf[2, 1] * y_mm + xf[2, 2] * z_mm
    pz += xf[2, 3]
    return wp.vec4d((px - cam[5]) * cam[7], (cam[6] - py) * cam[8], pz, wp.float64(1.0))


@wp.func
def _tri(a: wp.vec4d, b: wp.vec4d, c: wp.vec4d, n_rows: int, n_cols: int, zbuf: wp.array(dtype=wp.float64)):
    _raster_tri(a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2], n_rows, n_cols, zbuf)


@wp.kernel(enable_backward=False)
def _camera_quads_kernel(depth: wp.array2d(dtype=wp.uint16), mask: wp.array2d(dtype=wp.uint8), use_mask: int,
                         cam: vec9d, xf: wp.mat44d, n_rows: int, n_cols: int,
                         zbuf: wp.array(dtype=wp.float64)):
    """One 2x2 quad of the depth image: its triangles (cases of `prior.grid_triangles`) into the z-buffer."""
    q = wp.tid()
    w1 = depth.shape[1] - 1
    r = q // w1
    c = q % w1
    p00 = _corner(depth, mask, use_mask, r, c, cam, xf)
    p01 = _corner(depth, mask, use_mask, r, c + 1, cam, xf)
    p10 = _corner(depth, mask, use_mask, r + 1, c, cam, xf)
    p11 = _corner(depth, mask, use_mask, r + 1, c + 1, cam, xf)
    v00 = p00[3] > wp.float64(0.5)
    v01 = p01[3] > wp.float64(0.5)
    v10 = p10[3] > wp.float64(0.5)
    v11 = p11[3] > wp.float64(0.5)
    if v00 and v10 and v01:
        _tri(p00, p10, p01, n_rows, n_cols, zbuf)
    if v11 and v01 and v10:
        _tri(p11, p01, p10, n_rows, n_cols, zbuf)
    if v00 and v10 and v11 and not v01:
        _tri(p00, p10, p11, n_rows, n_cols, zbuf)
    if v00 and v11 and v01 and not v10:
        _tri(p00, p11, p01, n_rows, n_cols, zbuf)


@wp.kernel(enable_backward=False)
def _mesh_kernel(verts: wp.array(dtype=wp.vec3d), tris: wp.array(dtype=wp.vec3i), n_rows: int, n_cols: int,
                 zbuf: wp.array(dtype=wp.float64)):
    """One mesh triangle (vertices as radar column, row, z) into the z-buffer."""
    t = tris[wp.tid()]
    a = verts[t[0]]
    b = verts[t[1]]
    c = verts[t[2]]
    _raster_tri(a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2], n_rows, n_cols, zbuf)


@wp.kernel(enable_backward=False)
def _clear_kernel(n_rows: int, zbuf: wp.array(dtype=wp.float64), stats: wp.array(dtype=wp.int32)):
    """z-buffer = _FAR (1e300, no prior); stats = [covered, hull lattice points, (first col, last col) per row,
    (hull first col, hull last col) per row]."""
    p = wp.tid()
    zbuf[p] = _FAR
    if p < n_rows:
        stats[2 + 2 * p] = 2147483647
        stats[3 + 2 * p] = -1
        stats[2 + 2 * n_rows + 2 * p] = 2147483647
        stats[3 + 2 * n_rows + 2 * p] = -1
    if p == 0:
        stats[0] = 0
        stats[1] = 0


@wp.kernel(enable_backward=False)
def _span_kernel(n_cols: int, zbuf: wp.array(dtype=wp.float64), stats: wp.array(dtype=wp.int32)):
    """Covered-pixel count and each row's first and last covered column (input of the hull test)."""
    p = wp.tid()
    if zbuf[p] < _FAR:
        r = p // n_cols
        c = p % n_cols
        wp.atomic_add(stats, 0, 1)
        wp.atomic_min(stats, 2 + 2 * r, c)
        wp.atomic_max(stats, 3 + 2 * r, c)


@wp.kernel(enable_backward=False)
def _hull_rows_kernel(n_rows: int, stats: wp.array(dtype=wp.int32)):
    """Row r of the convex hull of the covered pixels, exactly in integers: its lattice columns are
    [ceil(min L), floor(max R)] over all pairs of covered rows i <= r <= j, L (R) the linear interpolation at row r
    between rows i and j's first (last) covered columns. Thread (r, i) takes every j >= r."""
    r, i = wp.tid()
    if i > r or stats[3 + 2 * i] < 0:
        return
    xl_i = stats[2 + 2 * i]
    xr_i = stats[3 + 2 * i]
    lo = int(2147483647)
    hi = int(-1)
    if i == r:
        lo = xl_i
        hi = xr_i
    for j in range(r + 1, n_rows):
        if stats[3 + 2 * j] >= 0:
            den = j - i
            t = r - i
            num_l = xl_i * den + (stats[2 + 2 * j] - xl_i) * t        # >= 0: columns are >= 0
            num_r = xr_i * den + (stats[3 + 2 * j] - xr_i) * t
            lo = wp.min(lo, (num_l + den - 1) // den)
            hi = wp.max(hi, num_r // den)
    if hi >= 0:
        wp.atomic_min(stats, 2 + 2 * n_rows + 2 * r, lo)
        wp.atomic_max(stats, 3 + 2 * n_rows + 2 * r, hi)


@wp.kernel(enable_backward=False)
def _hull_count_kernel(n_rows: int, stats: wp.array(dtype=wp.int32)):
    """stats[1] = lattice points inside or on the convex hull of the covered pixels."""
    r = wp.tid()
    lo = stats[2 + 2 * n_rows + 2 * r]
    hi = stats[3 + 2 * n_rows + 2 * r]
    if hi >= lo:
        wp.atomic_add(stats, 1, hi - lo + 1)


@wp.kernel(enable_backward=False)
def _compact_kernel(n_cols: int, zbuf: wp.array(dtype=wp.float64), x_m: wp.array(dtype=wp.float64),
                    y_m: wp.array(dtype=wp.float64), slot: wp.array(dtype=wp.int32),
                    points: wp.array(dtype=wp.vec3d), pixel: wp.array(dtype=wp.int32),
                    maps: wp.array2d(dtype=wp.float64)):
    """maps = (depth NaN, magnitude NaN, prior or NaN); covered pixels -> next slot of (x, y, prior) points."""
    p = wp.tid()
    z = zbuf[p]
    nan = wp.float64(wp.nan)
    maps[0, p] = nan
    maps[1, p] = nan
    if z < _FAR:
        maps[2, p] = z
        i = wp.atomic_add(slot, 0, 1)
        points[i] = wp.vec3d(x_m[p % n_cols], y_m[p // n_cols], z)
        pixel[i] = p
    else:
        maps[2, p] = nan


@wp.kernel(enable_backward=False)
def _fsk_depth_kernel(ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32), m_per_rad: wp.float64,
                      maps: wp.array2d(dtype=wp.float64), peak: wp.array(dtype=wp.float32)):
    """depth = prior - c angle(c2 conj c1) / (4 pi (f2 - f1)); magnitude = |(c1 + c2) / 2| (float32 as numpy)."""
    i = wp.tid()
    p = pixel[i]
    c1 = ph[0, i]
    c2 = ph[1, i]
    re = c2[0] * c1[0] + c2[1] * c1[1]
    im = c2[1] * c1[0] - c2[0] * c1[1]
    maps[0, p] = maps[2, p] - m_per_rad * wp.float64(wp.atan2(im, re))
    mean = (c1 + c2) * wp.float32(0.5)
    mag = wp.length(mean)
    maps[1, p] = wp.float64(mag)
    wp.atomic_max(peak, 0, mag)


@wp.kernel(enable_backward=False)
def _filter_kernel(pixel: wp.array(dtype=wp.int32), keep_ratio: wp.float64, peak: wp.array(dtype=wp.float32),
                   maps: wp.array2d(dtype=wp.float64)):
    """`filtering.keep_mask`: depth NaN where magnitude is 0 or < max * keep_ratio (10^(-threshold_db / 20), 0 for
    no threshold)."""
    p = pixel[wp.tid()]
    mag = maps[1, p]
    if mag <= wp.float64(0.0) or mag < wp.float64(peak[0]) * keep_ratio:
        maps[0, p] = wp.float64(wp.nan)


PROFILE: list | None = None     # diagnostics: set to [] to record (step, time) with a device sync after each step


def _mark(dev, name: str) -> None:
    if PROFILE is not None:
        wp.synchronize_device(dev)
        PROFILE.append((name, time.perf_counter()))


def load(device: str = "cuda") -> None:
    """Compile/load this module's kernels (the API's warm-up calls it, so timed runs exclude compilation)."""
    wp.load_module(module=__name__, device=backend_warp._wp_device(device))


def _buffer(name, shape, dtype, dev):
    """The backend's reusable device buffers, under names of this module's own."""
    return backend_warp._buffer(f"prior.{name}", shape, dtype, dev)


_grids: dict = {}


def _grid_arrays(grid: RadarGrid, dev: str):
    """Device x of each column and y of each row (row 0 = +y), exactly `grid.pixel_xy_m()`'s values."""
    key = (grid, dev)
    if key not in _grids:
        _grids[key] = (wp.array(grid.x_m, dtype=wp.float64, device=dev),
                       wp.array(np.ascontiguousarray(grid.y_m[::-1]), dtype=wp.float64, device=dev))
    return _grids[key]


def _pixel_scale(grid: RadarGrid) -> tuple[float, float, float, float]:
    """(xmin, ymax, columns per metre, rows per metre), as `prior._to_radar_pixels`."""
    (xmin, ymin, _), (xmax, ymax, _) = grid.bb_min_m, grid.bb_max_m
    nx, ny, _ = grid.size
    return xmin, ymax, (nx - 1) / (xmax - xmin), (ny - 1) / (ymax - ymin)


class DevicePrior:
    """A radar-grid prior (ny, nx) held on a Warp device (z-buffer, 1e300 = no prior) and its covered-pixel count.

    `np.asarray(prior)` copies it back as the CPU functions return it (NaN = no prior).
    """

    def __init__(self, zbuf: wp.array, grid: RadarGrid, n_covered: int, filled: bool):
        self.zbuf, self.grid, self.n_covered, self.filled = zbuf, grid, n_covered, filled
        self.shape = grid.image_shape
        self.device = zbuf.device.alias           # "cpu" or "cuda:0"

    def __array__(self, dtype=None, copy=None):
        z = self.zbuf.numpy().reshape(self.shape).copy()
        z[z >= FAR_M] = np.nan
        return z if dtype is None else z.astype(dtype)


def _coverage(zbuf, stats, ny: int, nx: int, dev: str, hull: bool = True) -> tuple[int, int]:
    """(covered pixels, lattice points of their convex hull (0 unless `hull`)) of a cleared-then-rasterised
    z-buffer: one 8-byte copy back."""
    wp.launch(_span_kernel, dim=ny * nx, inputs=[nx, zbuf, stats], device=dev)
    if hull:
        wp.launch(_hull_rows_kernel, dim=(ny, ny), inputs=[ny, stats], device=dev)
        wp.launch(_hull_count_kernel, dim=ny, inputs=[ny, stats], device=dev)
    n_covered, n_hull = (int(v) for v in stats[:2].numpy())
    return n_covered, n_hull


def _finish_prior(zbuf, stats, grid, dev, fill_holes: bool) -> DevicePrior:
    ny, nx = grid.image_shape
    n_covered, n_hull = _coverage(zbuf, stats, ny, nx, dev, hull=fill_holes)
    _mark(dev, "spans + hull count + copy back")
    filled = False
    if fill_holes and 0 < n_covered < ny * nx and n_hull > n_covered:
        from methods.raster import fill_convex_hull
        image = zbuf.numpy().reshape(ny, nx).copy()
        image[image >= FAR_M] = np.nan
        image = fill_convex_hull(image)
        covered = np.isfinite(image)
        n_covered, filled = int(covered.sum()), True
        zbuf.assign(np.where(covered, image, FAR_M).ravel())
    _mark(dev, "fill")
    return DevicePrior(zbuf, grid, n_covered, filled)


def _start(grid: RadarGrid, device: str):
    dev = backend_warp._wp_device(device)
    ny, nx = grid.image_shape
    zbuf = wp.empty(ny * nx, dtype=wp.float64, device=dev)       # owned by the DevicePrior
    stats = _buffer("stats", 2 + 4 * ny, wp.int32, dev)
    wp.launch(_clear_kernel, dim=ny * nx, inputs=[ny, zbuf, stats], device=dev)
    return dev, zbuf, stats


def realsense_prior_device(depth: DepthFrame, realsense2radar: np.ndarray, grid: RadarGrid,
                           fill_holes: bool = True, device: str = "cuda") -> DevicePrior:
    """`prior.realsense_prior_m` on a Warp device."""
    _mark(backend_warp._wp_device(device), "start")
    dev, zbuf, stats = _start(grid, device)
    height, width = depth.depth_mm.shape
    d_img = wp.array(np.ascontiguousarray(depth.depth_mm, dtype=np.uint16), dtype=wp.uint16, device=dev)
    if depth.mask is None:
        m_img = _buffer("no_mask", (1, 1), wp.uint8, dev)
    else:
        mask = np.ascontiguousarray(depth.mask)
        mask = mask.view(np.uint8) if mask.dtype == np.bool_ else (mask != 0).view(np.uint8)
        m_img = wp.array(mask, dtype=wp.uint8, device=dev)
    k = depth.intrinsics
    cam = vec9d(k.fx, k.fy, k.cx, k.cy, depth.depth_scale_m * 1000.0, *_pixel_scale(grid))
    ny, nx = grid.image_shape
    xf = wp.mat44d(*np.asarray(realsense2radar, dtype=np.float64).ravel())
    _mark(dev, "clear + uploads")
    wp.launch(_camera_quads_kernel, dim=(height - 1) * (width - 1),
              inputs=[d_img, m_img, int(depth.mask is not None), cam, xf, ny, nx, zbuf], device=dev)
    _mark(dev, "raster")
    return _finish_prior(zbuf, stats, grid, dev, fill_holes)


def mesh_prior_device(mesh: Mesh, photogrammetry2radar: np.ndarray, grid: RadarGrid, fill_holes: bool = True,
                      device: str = "cuda") -> DevicePrior:
    """`prior.mesh_prior_m` on a Warp device (vertices transformed on the host)."""
    dev, zbuf, stats = _start(grid, device)
    points_m = apply_transform(photogrammetry2radar, mesh.vertices)
    xmin, ymax, sx, sy = _pixel_scale(grid)
    verts = np.column_stack([(points_m[:, 0] - xmin) * sx, (ymax - points_m[:, 1]) * sy, points_m[:, 2]])
    tris = np.ascontiguousarray(mesh.triangles, dtype=np.int32)
    ny, nx = grid.image_shape
    if len(tris):
        wp.launch(_mesh_kernel, dim=len(tris), inputs=[wp.array(verts, dtype=wp.vec3d, device=dev),
                                                       wp.array(tris, dtype=wp.vec3i, device=dev), ny, nx, zbuf],
                  device=dev)
    return _finish_prior(zbuf, stats, grid, dev, fill_holes)


_pinned: dict = {}


def _copy_back(arr: wp.array, dev: str) -> np.ndarray:
    """Host copy of a float64 device array through a reused pinned staging buffer (one DMA, then a memcpy)."""
    if dev == "cpu":
        return arr.numpy().copy()
    if arr.shape not in _pinned:
        _pinned.clear()
        _pinned[arr.shape] = wp.empty(arr.shape, dtype=wp.float64, device="cpu", pinned=True)
    host = _pinned[arr.shape]
    wp.copy(host, arr)
    wp.synchronize_device(dev)
    return host.numpy().copy()


def _sync(dev) -> None:
    wp.synchronize_device(dev)


def reconstruct_mm2fsk_device(signal: np.ndarray, freqs_hz: np.ndarray, antennas, grid: RadarGrid,
                              prior: DevicePrior, *, threshold_db: float | None = DEFAULT_THRESHOLD_DB,
                              timer: StageTimer | None = None) -> Reconstruction:
    """`mm2fsk.reconstruct_mm2fsk` with a DevicePrior: everything on the device, one copy back of the maps."""
    if threshold_db is not None and threshold_db < 0:
        raise ValueError(f"threshold_db is dB below the maximum and must be >= 0, got {threshold_db}")
    timer = timer or StageTimer()
    dev = prior.device
    ny, nx = grid.image_shape
    n = prior.n_covered
    signal, freqs_hz, tx_m, rx_m = _check_inputs(signal, freqs_hz, antennas.tx_m, antennas.rx_m)
    device = "warp-cpu" if dev == "cpu" else "cuda"
    peak = _buffer("peak", 1, wp.float32, dev)
    maps = _buffer("maps", (3, ny * nx), wp.float64, dev)
    _mark(dev, "mm2fsk start")
    with timer.stage("correlate"):
        points = _buffer("points", ny * nx, wp.vec3d, dev)
        pixel = _buffer("pixel", ny * nx, wp.int32, dev)
        slot = _buffer("slot", 1, wp.int32, dev)
        x_m, y_m = _grid_arrays(grid, dev)
        slot.zero_()
        peak.zero_()
        wp.launch(_compact_kernel, dim=ny * nx, inputs=[nx, prior.zbuf, x_m, y_m, slot, points, pixel, maps],
                  device=dev)
        _mark(dev, "compact")
        phasors = None
        if n:
            run = backend_warp.make_launch(signal, freqs_hz, tx_m, rx_m, device=device,
                                           kernel=backend_warp.default_kernel(device), points_m=points[:n],
                                           reuse=True)
            _mark(dev, "make_launch (frame cache)")
            phasors = run()
        _sync(dev)
        _mark(dev, "correlate kernels")
    with timer.stage("depth"):
        if n:
            m_per_rad = C_M_PER_S / (4.0 * np.pi * (freqs_hz[1] - freqs_hz[0]))
            wp.launch(_fsk_depth_kernel, dim=n, inputs=[phasors, pixel, float(m_per_rad), maps, peak], device=dev)
        _sync(dev)
        _mark(dev, "depth kernel")
    with timer.stage("filter"):
        if n:
            keep_ratio = 0.0 if threshold_db is None else float(10.0 ** (-threshold_db / 20.0))
            wp.launch(_filter_kernel, dim=n, inputs=[pixel, keep_ratio, peak, maps],
                      device=dev)
        _mark(dev, "filter kernel")
        host = _copy_back(maps, dev).reshape(3, ny, nx)
        _mark(dev, "copy back")
    depth_m, magnitude, prior_m = host
    return Reconstruction(depth_m=depth_m, magnitude=magnitude, freqs_hz=np.asarray(freqs_hz),
                          timings_ms=timer.finish(), grid=grid, method="mm2fsk",
                          extra={"prior_depth_m": prior_m, "prior_pixels": n})
