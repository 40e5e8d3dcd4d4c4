"""The RealSense prior on a Warp device equals the CPU prior exactly: its hole filling
(`methods.warp_backend.hull_fill` against `raster.fill_convex_hull`, fresh random images with holes, notches and
several blobs) and its depth-jump rule (random steps in the depth image, rule on at several thresholds and off)."""
from __future__ import annotations

import numpy as np
import pytest

from devices import CUDA
from methods.prior import realsense_prior_m
from methods.raster import fill_convex_hull
from methods_scenes import CAMERA, plane_depth_frame, realsense2radar, square_grid

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

    from methods.warp_backend.frames import BufferPool
    from methods.warp_backend.hull_fill import FAR_M, fill_hull

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
    from methods.backend import backend_for
    from methods.warp_backend.prior import realsense_prior

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
