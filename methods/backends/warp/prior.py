"""The depth prior rasterised on a Warp device (launching `prior_kernels`): the CPU prior (`methods.prior.priors`) is
the
specification, reproduced step by step in float64.

Hull fill (`raster.fill_convex_hull`): the device counts the covered pixels, each row's first/last covered column,
and, exactly in integer arithmetic, the lattice points of the convex hull of the covered pixels. The fill can add
pixels only if the hull holds more lattice points than are covered (it fills exactly those inside the hull); only
then does `hull_fill.fill_hull` run: the rim pixels are found on the device, their indices (not the z-buffer) come
to the host for scipy's Delaunay triangulation, and its triangles are rasterised into the empty pixels on the
device (exact). One 8-byte copy back decides. A prior with nothing to fill (e.g. a surface that covers the whole
radar grid) never leaves the GPU.

Scanline fill (prior fill 'scanline', `raster.fill_scanline`): one kernel over the pixels after the coverage
kernel, no host work; the prior never leaves the GPU (one 8-byte copy back of the pixel counts).
"""
from __future__ import annotations

import numpy as np
import warp as wp

from methods.backends.warp.frames import BufferPool
from methods.backends.warp.hull_fill import fill_hull
from methods.backends.warp.kernels import prior as kernels
from methods.domain.capture import DepthFrame, Mesh, RadarGrid
from methods.domain.transforms import apply_transform
from methods.prior.image import Prior
from methods.prior.priors import DEFAULT_FILL, DEFAULT_MAX_JUMP_MM, check_fill

FAR_M = 1.0e300                  # z-buffer value of an uncovered pixel (prior_kernels.FAR)


class DevicePrior(Prior):
    """A radar-grid prior (ny, nx) held on a Warp device (z-buffer, 1e300 = no prior) and its covered-pixel count.

    `host_m()` (and `np.asarray(prior)`) copies it back as the CPU functions return it (NaN = no prior)."""

    device_resident = True

    def __init__(self, zbuf: wp.array, grid: RadarGrid, n_covered: int, filled: bool):
        self.zbuf, self.grid, self.n_covered, self.filled = zbuf, grid, n_covered, filled
        self.shape = grid.image_shape

    def host_m(self) -> np.ndarray:
        z = self.zbuf.numpy().reshape(self.shape).copy()
        z[z >= FAR_M] = np.nan
        return z


class DeferredPrior(Prior):
    """A RealSense prior with the scanline fill not built yet: MM-2FSK builds it inside its frame's CUDA graph
    (`frame_graph`, `WarpBackend.depth_at_prior`); any other use builds it step by step first (`materialise`)."""

    device_resident = True

    def __init__(self, buffers: BufferPool, depth: DepthFrame, realsense2radar: np.ndarray, grid: RadarGrid,
                 max_jump_mm: float | None):
        self.buffers, self.depth, self.realsense2radar, self.grid = buffers, depth, realsense2radar, grid
        self.max_jump_mm, self.shape = max_jump_mm, grid.image_shape
        self._built: DevicePrior | None = None
        self._host: np.ndarray | None = None
        self._n: int | None = None

    @property
    def pending(self) -> bool:
        """Neither built step by step nor computed by a frame graph yet."""
        return self._built is None and self._n is None

    @property
    def takes_roi(self) -> bool:
        """The frame graph restricts the correlated pixels to a region of interest itself."""
        return self.pending

    def resolve(self, host_m: np.ndarray, n_covered: int, n_used: int) -> None:
        """Record what the frame graph computed: the prior (ny, nx) on the host, its covered pixels and those
        correlated (inside the region of interest)."""
        self._host, self._n, self.n_used = host_m, n_covered, n_used

    def materialise(self) -> DevicePrior:
        """The prior built on the device step by step (`realsense_prior`, fill 'scanline')."""
        if self._built is None:
            self._built = realsense_prior(self.buffers, self.depth, self.realsense2radar, self.grid,
                                          max_jump_mm=self.max_jump_mm, fill="scanline")
        return self._built

    @property
    def n_covered(self) -> int:
        return self._n if self._n is not None else self.materialise().n_covered

    @property
    def zbuf(self) -> wp.array:
        return self.materialise().zbuf

    def host_m(self) -> np.ndarray:
        return self._host if self._host is not None else self.materialise().host_m()


def pixel_scale(grid: RadarGrid) -> tuple[float, float, float, float]:
    """(xmin, ymax, columns per metre, rows per metre), as `prior._to_radar_pixels`."""
    (xmin, ymin, _), (xmax, ymax, _) = grid.bb_min_m, grid.bb_max_m
    nx, ny, _ = grid.size
    return xmin, ymax, (nx - 1) / (xmax - xmin), (ny - 1) / (ymax - ymin)


def coverage(zbuf, stats, ny: int, nx: int, hull: bool = True) -> tuple[int, int]:
    """(covered pixels, lattice points of their convex hull (0 unless `hull`)) of a cleared-then-rasterised
    z-buffer: one 8-byte copy back."""
    dev = zbuf.device
    wp.launch(kernels.covered_spans, dim=ny * nx, inputs=[ny, nx, zbuf, stats], device=dev)
    if hull:
        wp.launch(kernels.hull_rows, dim=(ny, ny), inputs=[ny, stats], device=dev)
        wp.launch(kernels.hull_lattice_count, dim=ny, inputs=[ny, stats], device=dev)
    n_covered, n_hull = (int(v) for v in stats[:2].numpy())
    return n_covered, n_hull


def _scanline_finish(zbuf, stats, grid) -> DevicePrior:
    """Coverage, then `raster.fill_scanline` into a new buffer on the device; one 8-byte copy back."""
    ny, nx = grid.image_shape
    dev = zbuf.device
    filled = wp.empty(ny * nx, dtype=wp.float64, device=dev)
    wp.launch(kernels.covered_spans, dim=ny * nx, inputs=[ny, nx, zbuf, stats], device=dev)
    wp.launch(kernels.scanline_fill, dim=ny * nx, inputs=[ny, nx, zbuf, stats, filled], device=dev)
    n_covered, n_filled = (int(v) for v in stats[:2].numpy())
    return DevicePrior(filled, grid, n_covered + n_filled, n_filled > 0)


def _finish(buffers: BufferPool, zbuf, stats, grid, fill_holes: bool, fill: str = DEFAULT_FILL) -> DevicePrior:
    if fill_holes and check_fill(fill) == "scanline":
        return _scanline_finish(zbuf, stats, grid)
    ny, nx = grid.image_shape
    n_covered, n_hull = coverage(zbuf, stats, ny, nx, hull=fill_holes)
    filled = False
    if fill_holes and 0 < n_covered < ny * nx and n_hull > n_covered:
        n_covered += fill_hull(buffers, zbuf, ny, nx)
        filled = True
    return DevicePrior(zbuf, grid, n_covered, filled)


def upload(buffers: BufferPool, name: str, host: np.ndarray, dtype) -> wp.array:
    """`host` in the pool's device buffer `name`: on CUDA through a reused pinned staging buffer (an asynchronous
    DMA; the previous frame's copy finished at its copy back), on Warp-CPU a copy."""
    target = buffers.get(name, host.shape, dtype)
    if target.device.is_cpu:
        target.assign(host)
        return target
    staging = buffers.pinned(host.shape, dtype, name=name + ".pinned")
    np.copyto(staging.numpy(), host, casting="unsafe")
    wp.copy(target, staging)
    return target


def cleared_zbuffer(buffers: BufferPool, grid: RadarGrid):
    """A new z-buffer of `grid` (no prior anywhere) and the pool's cleared coverage statistics."""
    dev = buffers.wp_device
    ny, nx = grid.image_shape
    zbuf = wp.empty(ny * nx, dtype=wp.float64, device=dev)       # owned by the DevicePrior
    stats = buffers.get("prior.stats", 2 + 4 * ny + 2 * nx, wp.int32)
    wp.launch(kernels.clear_zbuffer, dim=ny * nx, inputs=[ny, zbuf, stats], device=dev)
    return zbuf, stats


def realsense_prior(buffers: BufferPool, depth: DepthFrame, realsense2radar: np.ndarray, grid: RadarGrid,
                    fill_holes: bool = True, max_jump_mm: float | None = DEFAULT_MAX_JUMP_MM,
                    fill: str = DEFAULT_FILL) -> DevicePrior:
    """`prior.realsense_prior_m` on the pool's Warp device (max_jump_mm: the depth-jump rule, None = off; fill:
    the hole-fill rule)."""
    zbuf, stats = cleared_zbuffer(buffers, grid)
    dev = buffers.wp_device
    height, width = depth.depth_mm.shape
    d_img = upload(buffers, "prior.depth", np.asarray(depth.depth_mm, dtype=np.uint16), wp.uint16)
    if depth.mask is None:
        m_img = buffers.get("prior.no_mask", (1, 1), wp.uint8)
    else:
        mask = np.asarray(depth.mask)
        m_img = upload(buffers, "prior.mask", mask.view(np.uint8) if mask.dtype == np.bool_ else mask != 0, wp.uint8)
    k = depth.intrinsics
    cam = kernels.vec9d(k.fx, k.fy, k.cx, k.cy, depth.depth_scale_m * 1000.0, *pixel_scale(grid))
    ny, nx = grid.image_shape
    xf = wp.mat44d(*np.asarray(realsense2radar, dtype=np.float64).ravel())
    wp.launch(kernels.raster_camera_quads, dim=(height - 1) * (width - 1),
              inputs=[d_img, m_img, int(depth.mask is not None), cam, xf,
                      wp.float64(-1.0 if max_jump_mm is None else max_jump_mm), ny, nx, zbuf], device=dev)
    return _finish(buffers, zbuf, stats, grid, fill_holes, fill)


def mesh_prior(buffers: BufferPool, mesh: Mesh, photogrammetry2radar: np.ndarray, grid: RadarGrid,
               fill_holes: bool = True, fill: str = DEFAULT_FILL) -> DevicePrior:
    """`prior.mesh_prior_m` on the pool's Warp device (vertices transformed on the host)."""
    zbuf, stats = cleared_zbuffer(buffers, grid)
    dev = buffers.wp_device
    points_m = apply_transform(photogrammetry2radar, mesh.vertices)
    xmin, ymax, sx, sy = pixel_scale(grid)
    verts = np.column_stack([(points_m[:, 0] - xmin) * sx, (ymax - points_m[:, 1]) * sy, points_m[:, 2]])
    tris = np.ascontiguousarray(mesh.triangles, dtype=np.int32)
    ny, nx = grid.image_shape
    if len(tris):
        wp.launch(kernels.raster_mesh_triangles, dim=len(tris),
                  inputs=[wp.array(verts, dtype=wp.vec3d, device=dev), wp.array(tris, dtype=wp.vec3i, device=dev),
                          ny, nx, zbuf], device=dev)
    return _finish(buffers, zbuf, stats, grid, fill_holes, fill)
