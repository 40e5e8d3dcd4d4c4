"""The RealSense prior on a Warp device equals the CPU prior exactly: its hole filling
(`methods.backends.warp.hull_fill` against `raster.fill_convex_hull`, fresh random images with holes, notches and
several blobs) and its depth-jump rule (random steps in the depth image, rule on at several thresholds and off)."""
from __future__ import annotations

import numpy as np
import pytest

from bench.synth.memory import CAMERA, plane_depth_frame, realsense2radar, square_grid
from methods.prior.priors import realsense_prior_m
from methods.prior.raster import fill_convex_hull

from devices import CUDA

DEVICES = ["warp-cpu", CUDA]


def _blobs(rng: np.random.Generator, shape: tuple[int, int]) -> np.ndarray:
    """Depth image (m) of a few tilted discs with random dropouts; NaN = empty."""
    image = np.full(shape, np.nan)
    rows, cols = np.mgrid[:shape[0], :shape[1]]
    for _ in range(rng.integers(1, 5)):
        cy, cx = rng.uniform(0, shape[0]), rng.uniform(0, shape[1])
        radius = rng.uniform(3, min(shape) / 3)
        disc = (rows - cy) ** 2 + (cols - cx) ** 2 < radius ** 2
        image[disc] = 0.3 + 1e-3 * (rows[disc] - cy) + 1e-4 * rng.standard_normal(disc.sum())
    image[rng.random(shape) < rng.uniform(0, 0.1)] = np.nan
    return image


@pytest.mark.parametrize("device", DEVICES)
def test_device_hull_fill_equals_the_cpu_fill(device):
    import warp as wp

    from methods.backends.warp.frames import BufferPool
    from methods.backends.warp.hull_fill import FAR_M, fill_hull

    rng = np.random.default_rng()
    pool = BufferPool("cpu" if device == "warp-cpu" else "cuda:0")
    for shape in [(61, 73), (40, 40), (301, 301)]:
        image = _blobs(rng, shape)
        expected = fill_convex_hull(image)
        zbuf = wp.array(np.where(np.isfinite(image), image, FAR_M).ravel(), dtype=wp.float64, device=pool.wp_device)
        added = fill_hull(pool, zbuf, *shape)
        got = zbuf.numpy().reshape(shape)
        got[got >= FAR_M] = np.nan
        assert np.array_equal(np.isfinite(got), np.isfinite(expected)), shape
        assert added == int(np.isfinite(expected).sum() - np.isfinite(image).sum())
        # bit-equal on Warp-CPU; CUDA contracts the plane evaluation to FMAs (a few ulp of ~0.3 m)
        assert np.max(np.abs(got - expected), where=np.isfinite(expected), initial=0.0) < 1e-12, shape


@pytest.mark.parametrize("device", DEVICES)
def test_device_prior_drops_the_triangles_the_cpu_depth_jump_rule_drops(device):
    from methods.backends import backend_for
    from methods.backends.warp.prior import realsense_prior

    rng = np.random.default_rng()
    cam2radar = realsense2radar()
    rows, cols = np.mgrid[:CAMERA.height, :CAMERA.width]
    frame = plane_depth_frame(0.31, 0.2, -0.15, cam2radar, mask=(np.abs(cols - 320) < 200) & (np.abs(rows - 240) < 150))
    for _ in range(6):                          # raised blocks: 2-40 mm steps, some across the mask's edge
        r0, c0 = rng.integers(60, 400), rng.integers(60, 560)
        block = (rows >= r0) & (rows < r0 + rng.integers(10, 80)) & (cols >= c0) & (cols < c0 + rng.integers(10, 80))
        frame.depth_mm[block] -= np.uint16(rng.integers(2, 40))
    frame.depth_mm[rng.random(frame.depth_mm.shape) < 0.01] = 0
    grid = square_grid(0.15, 301)
    buffers = backend_for(device).buffers
    for max_jump_mm in (10.0, 3.0, None):
        expected = realsense_prior_m(frame, cam2radar, grid, max_jump_mm=max_jump_mm)
        got = realsense_prior(buffers, frame, cam2radar, grid, max_jump_mm=max_jump_mm)
        image = np.asarray(got)
        assert np.array_equal(np.isfinite(image), np.isfinite(expected)), max_jump_mm
        assert got.n_covered == np.isfinite(expected).sum()
        assert np.max(np.abs(image - expected), where=np.isfinite(expected), initial=0.0) < 1e-12, max_jump_mm


@pytest.mark.parametrize("device", DEVICES)
def test_device_scanline_fill_equals_the_cpu_fill(device):
    from methods.backends.warp import prior as device_prior
    from methods.backends.warp.frames import BufferPool
    from methods.domain.capture import RadarGrid
    from methods.prior.raster import fill_scanline

    rng = np.random.default_rng()
    pool = BufferPool("cpu" if device == "warp-cpu" else "cuda:0")
    for shape in [(61, 73), (40, 40), (301, 301)]:
        image = _blobs(rng, shape)
        expected = fill_scanline(image)
        grid = RadarGrid((-0.1, -0.1, 0.2), (0.1, 0.1, 0.4), (shape[1], shape[0], 3))
        zbuf, stats = device_prior.cleared_zbuffer(pool, grid)
        zbuf.assign(np.where(np.isfinite(image), image, device_prior.FAR_M).ravel())
        got = device_prior._scanline_finish(zbuf, stats, grid)
        image_m = got.host_m()
        assert np.array_equal(np.isfinite(image_m), np.isfinite(expected)), shape
        assert got.n_covered == np.isfinite(expected).sum()
        # bit-equal on Warp-CPU; CUDA may contract the interpolations to FMAs (a few ulp of ~0.3 m)
        assert np.max(np.abs(image_m - expected), where=np.isfinite(expected), initial=0.0) < 1e-12, shape


@pytest.mark.parametrize("device", DEVICES)
def test_device_realsense_prior_with_the_scanline_fill_equals_the_cpu_prior(device):
    from methods.backends import backend_for
    from methods.backends.warp.prior import realsense_prior

    rng = np.random.default_rng()
    cam2radar = realsense2radar()
    rows, cols = np.mgrid[:CAMERA.height, :CAMERA.width]
    frame = plane_depth_frame(0.31, 0.2, -0.15, cam2radar, mask=(cols - 320) ** 2 + (rows - 240) ** 2 < 180 ** 2)
    for _ in range(3):                                     # camera holes of 5-30 px radius
        r0, c0, radius = rng.integers(120, 360), rng.integers(160, 480), rng.integers(5, 30)
        frame.depth_mm[(rows - r0) ** 2 + (cols - c0) ** 2 < radius ** 2] = 0
    grid = square_grid(0.15, 301)
    expected = realsense_prior_m(frame, cam2radar, grid, fill="scanline")
    got = realsense_prior(backend_for(device).buffers, frame, cam2radar, grid, fill="scanline")
    image = np.asarray(got)
    assert np.array_equal(np.isfinite(image), np.isfinite(expected))
    assert got.n_covered == np.isfinite(expected).sum()
    assert np.max(np.abs(image - expected), where=np.isfinite(expected), initial=0.0) < 1e-12
