"""Two-frequency depth at a device-resident prior (MM-2FSK without leaving the device), launching `fsk_kernels`:
covered pixels are compacted on the device (atomic slot counter; slots are per-point independent, so the order
does not change any value), correlated with the backend's default kernel on device-resident points, then
depth = prior - c angle(c2 conj c1) / (4 pi (f2 - f1)), magnitude = |(c1 + c2) / 2|, the max magnitude (atomic
max) and the filter threshold are applied on the device; one copy back of (depth, magnitude, prior)."""
from __future__ import annotations

from collections.abc import Callable

import numpy as np
import warp as wp

from methods.warp_backend import fsk_kernels as kernels
from methods.warp_backend.frames import C_M_PER_S, BufferPool
from methods.warp_backend.prior import DevicePrior


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
                  inputs=[nx, prior.zbuf, x_m, y_m, slot, points, pixel, maps], device=dev)
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
