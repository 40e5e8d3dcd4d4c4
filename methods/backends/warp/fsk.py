"""Two-frequency depth at a device-resident prior (MM-2FSK without leaving the device), launching `fsk_kernels`:
covered pixels are compacted on the device (atomic slot counter; slots are per-point independent, so the order
does not change any value), correlated with the backend's default kernel on device-resident points, then
depth = prior - c angle(c2 conj c1) / (4 pi (f2 - f1)), magnitude = |(c1 + c2) / 2|, the max magnitude (atomic
max) and the filter threshold are applied on the device; one copy back of (depth, magnitude, prior)."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import warp as wp

from methods.backends.warp.frames import C_M_PER_S, BufferPool
from methods.backends.warp.kernels import fsk as kernels
from methods.backends.warp.prior import DevicePrior


def grid_arrays(buffers: BufferPool, grid) -> tuple[wp.array, wp.array]:
    """Device x of each column and y of each row (row 0 = +y), exactly `grid.pixel_xy_m()`'s values."""
    dev = buffers.wp_device
    return buffers.constant(("grid", grid), lambda: (
        wp.array(grid.x_m, dtype=wp.float64, device=dev),
        wp.array(np.ascontiguousarray(grid.y_m[::-1]), dtype=wp.float64, device=dev)))


def copy_back(buffers: BufferPool, arr: wp.array) -> np.ndarray:
    """Host copy of a float64 device array through a reused pinned staging buffer (one DMA, then a memcpy)."""
    if arr.device.is_cpu:
        return arr.numpy().copy()
    host = buffers.pinned(arr.shape, wp.float64)
    wp.copy(host, arr)
    wp.synchronize_device(arr.device)
    return host.numpy().copy()


def depth_at_prior(buffers: BufferPool, correlate_points: Callable, signal, freqs_hz, grid, prior: DevicePrior,
                   keep_ratio: float, timer) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(depth_m, magnitude, prior_m), each (ny, nx) float64 NaN where not covered/kept, for a two-frequency frame.

    `correlate_points(points)` returns the device phasors (2, N) of device points (N,) vec3d; `keep_ratio` is the
    linear filter floor relative to the maximum magnitude (0: keep every nonzero one)."""
    dev = prior.zbuf.device
    ny, nx = grid.image_shape
    n = prior.n_covered
    peak = buffers.get("fsk.peak", 1, wp.float32)
    maps = buffers.get("fsk.maps", (3, ny * nx), wp.float64)
    with timer.stage("correlate"):
        points = buffers.get("fsk.points", ny * nx, wp.vec3d)
        pixel = buffers.get("fsk.pixel", ny * nx, wp.int32)
        slot = buffers.get("fsk.slot", 1, wp.int32)
        x_m, y_m = grid_arrays(buffers, grid)
        slot.zero_()
        peak.zero_()
        wp.launch(kernels.compact_covered_pixels, dim=ny * nx,
                  inputs=[nx, prior.zbuf, x_m, y_m, slot, points, pixel, maps, 0,
                          buffers.get("fsk.no_roi", 1, wp.uint8)], device=dev)
        phasors = correlate_points(points[:n]) if n else None
        wp.synchronize_device(dev)
    with timer.stage("depth"):
        if n:
            m_per_rad = C_M_PER_S / (4.0 * np.pi * (freqs_hz[1] - freqs_hz[0]))
            wp.launch(kernels.fsk_depth_at_prior, dim=n, inputs=[phasors, pixel, float(m_per_rad), maps, peak],
                      device=dev)
        wp.synchronize_device(dev)
    with timer.stage("filter"):
        if n:
            wp.launch(kernels.magnitude_filter, dim=n, inputs=[pixel, float(keep_ratio), peak, maps], device=dev)
        host = copy_back(buffers, maps).reshape(3, ny, nx)
    return host[0], host[1], host[2]


def _pixel_list(buffers: BufferPool, grid, pixels: np.ndarray) -> tuple[wp.array, int]:
    """Device flat indices (row-major, as boolean indexing orders them) of the True pixels, kept per mask."""
    flat = np.flatnonzero(pixels).astype(np.int32)
    return buffers.constant(("pixels", grid, flat.tobytes()),
                            lambda: wp.array(flat, dtype=wp.int32, device=buffers.wp_device)), len(flat)


def _copy_back_with(buffers: BufferPool, maps: wp.array, scalars: wp.array) -> tuple[np.ndarray, np.ndarray]:
    """Host copies of float64 `maps` and a few `scalars` after one synchronisation."""
    if maps.device.is_cpu:
        return maps.numpy().copy(), scalars.numpy().copy()
    host = buffers.pinned(maps.shape, wp.float64)
    small = buffers.pinned(scalars.shape, wp.float64, name="pinned.scalars")
    wp.copy(host, maps)
    wp.copy(small, scalars)
    wp.synchronize_device(maps.device)
    return host.numpy().copy(), small.numpy().copy()


def _first_pass(buffers: BufferPool, correlate: Callable, pixel: wp.array, n: int, grid, prior_m: float,
                m_per_rad: float):
    """2FSK pass 1 at the scalar prior over the listed pixels, then every point refocused at the common guess z1
    of the strongest pixel (all on the device): (points (n,) vec3d at z1, scalars (z1, reference pixel))."""
    dev = buffers.wp_device
    nx = grid.image_shape[1]
    x_m, y_m = grid_arrays(buffers, grid)
    points = buffers.get("fsk.scalar_points", n, wp.vec3d)
    scalars = buffers.get("fsk.scalars", 2, wp.float64)
    peak = buffers.get("fsk.first_peak", 1, wp.float32)
    ref = buffers.get("fsk.ref", 1, wp.int32)
    peak.zero_()
    ref.fill_(2147483647)
    wp.launch(kernels.points_at_depth, dim=n, inputs=[pixel, nx, x_m, y_m, float(prior_m), points], device=dev)
    ph = correlate(points)
    wp.launch(kernels.first_magnitude_peak, dim=n, inputs=[ph, peak], device=dev)
    wp.launch(kernels.first_argmax, dim=n, inputs=[ph, peak, ref], device=dev)
    wp.launch(kernels.refocus_points, dim=n, inputs=[ph, ref, float(prior_m), float(m_per_rad), points, scalars],
              device=dev)
    return points, scalars


def two_pass(buffers: BufferPool, correlate: Callable, grid, pixels: np.ndarray, freqs_hz, prior_m: float,
             keep_ratio: float, first_only: bool, timer) -> tuple[np.ndarray, np.ndarray, dict]:
    """2FSK (methods.fsk.reconstruct_2fsk without skips) over the True `pixels` (ny, nx) on the device:
    (depth_m, magnitude) (ny, nx), NaN where not evaluated or filtered, and the details (reference pixel, z1);
    `correlate(freqs_index, points)` returns the device phasors (2, n). One copy back."""
    dev = buffers.wp_device
    ny, nx = grid.image_shape
    pixel, n = _pixel_list(buffers, grid, pixels)
    m_per_rad = C_M_PER_S / (4.0 * np.pi * (freqs_hz[1] - freqs_hz[0]))
    maps = buffers.get("fsk.maps2", (2, ny * nx), wp.float64)
    peak = buffers.get("fsk.peak", 1, wp.float32)
    with timer.stage("correlate"):
        maps.fill_(float("nan"))
        points, scalars = _first_pass(buffers, correlate, pixel, n, grid, prior_m, m_per_rad)
        ph = correlate(points)
        wp.synchronize_device(dev)
    with timer.stage("depth"):
        peak.zero_()
        wp.launch(kernels.pair_depth, dim=n, inputs=[ph, pixel, float(m_per_rad), int(first_only), points, maps,
                                                     peak], device=dev)
        wp.synchronize_device(dev)
    with timer.stage("filter"):
        wp.launch(kernels.magnitude_filter, dim=n, inputs=[pixel, float(keep_ratio), peak, maps], device=dev)
        host, (z1_m, ref) = _copy_back_with(buffers, maps, scalars)
    host = host.reshape(2, ny, nx)
    return host[0], host[1], {"reference_pixel": int(ref), "z1_m": float(z1_m)}


def three_fsk(buffers: BufferPool, correlate_coarse: Callable, correlate_all: Callable, grid, pixels: np.ndarray,
              freqs_hz, coarse_hz, prior_m: float, keep_ratio: float, timer
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
    """3FSK (methods.fsk3.reconstruct_3fsk without skips) over the True `pixels` on the device: the coarse pair's
    two passes (`correlate_coarse(points)` -> (2, n)), every point moved to its coarse depth, the three frequencies
    (`correlate_all(points)` -> (3, n)) and the least-squares slope: (depth_m, magnitude, coarse_depth_m) (ny, nx)
    and the details. One copy back."""
    dev = buffers.wp_device
    ny, nx = grid.image_shape
    pixel, n = _pixel_list(buffers, grid, pixels)
    m_per_rad = C_M_PER_S / (4.0 * np.pi * (coarse_hz[1] - coarse_hz[0]))
    offsets_hz = np.asarray(freqs_hz, dtype=np.float64) - freqs_hz[-1]
    centred_hz = offsets_hz - offsets_hz.mean()
    maps = buffers.get("fsk.maps3", (3, ny * nx), wp.float64)
    peak = buffers.get("fsk.peak", 1, wp.float32)
    with timer.stage("correlate"):
        maps.fill_(float("nan"))
        points, scalars = _first_pass(buffers, correlate_coarse, pixel, n, grid, prior_m, m_per_rad)
        ph = correlate_coarse(points)
        wp.launch(kernels.coarse_points, dim=n, inputs=[ph, pixel, float(m_per_rad), points, maps], device=dev)
        ph = correlate_all(points)
        wp.synchronize_device(dev)
    with timer.stage("depth"):
        peak.zero_()
        wp.launch(kernels.slope_depth, dim=n,
                  inputs=[ph, pixel, wp.vec3d(*(centred_hz / (centred_hz @ centred_hz))),
                          float(C_M_PER_S / (4.0 * np.pi)), points, maps, peak], device=dev)
        wp.synchronize_device(dev)
    with timer.stage("filter"):
        wp.launch(kernels.magnitude_filter, dim=n, inputs=[pixel, float(keep_ratio), peak, maps], device=dev)
        host, (z1_m, ref) = _copy_back_with(buffers, maps, scalars)
    host = host.reshape(3, ny, nx)
    return host[0], host[1], host[2], {"reference_pixel": int(ref), "z1_m": float(z1_m)}
