"""MM-3FSK's frame graph (`warp_backend.frame_graph.FrameGraph` with a coarse pair: the RealSense prior, the coarse
pair's correlation, the median offset on the device, the three frequencies' slope depth, one copy back) against
MM-3FSK's host-driven passes (`methods.mm3fsk.mm3fsk_depth_m`) on the same backend and the same prior image, on
fresh random scenes with a miscalibrated camera (the prior off by up to 5 cm, beyond d10's 0.75 cm).

Tolerances: the device's median is within half a quantisation step (`MedianOffset.bound_m`, 3e-11 m) of
np.median's (tested alone below), but the corrections themselves are float32 phases (the device's atan2 and FMAs
against numpy's complex64 angle: an ulp of pi is 0.04 m/rad x 2.4e-7 rad = 1e-8 m), so offsets agree within
1e-7 m; the fine pass then correlates at points that differ by that much, so depths agree within 1e-6 m
(float32 phases of weak pixels move most), magnitudes within 1e-5 of the maximum, and the valid pixels differ
on at most 0.2 % (pixels at the filter threshold). On Warp-CPU the same launches run without a graph."""
from __future__ import annotations

import numpy as np
import pytest

from bench.synth.memory import (
    ANTENNAS,
    CAMERA,
    MAROON_FREQS_HZ,
    add_noise,
    plane_depth_frame,
    realsense2radar,
    simulate,
    square_grid,
)
from methods.ops.frequencies import config_indices

from devices import CUDA


def _scene(rng: np.random.Generator):
    """(signal d05_d10, freqs, depth frame, miscalibrated transform, grid, true plane (z0, sx, sy), prior error)."""
    freqs_hz = MAROON_FREQS_HZ[config_indices(MAROON_FREQS_HZ, "d05_d10")]
    z0, sx, sy = rng.uniform(0.28, 0.34), rng.uniform(-0.15, 0.15), rng.uniform(-0.15, 0.15)
    cam2radar = realsense2radar()
    rows, cols = np.mgrid[:CAMERA.height, :CAMERA.width]
    frame = plane_depth_frame(z0, sx, sy, cam2radar,
                              mask=(cols - 320) ** 2 + (rows - 240) ** 2 < rng.uniform(120, 200) ** 2)
    axis = np.arange(-0.03, 0.0301, 0.002)
    x, y = (a.ravel() for a in np.meshgrid(axis, axis))
    points = np.column_stack([x, y, z0 + sx * x + sy * y])
    amplitudes = rng.uniform(0.5, 1.5, len(points)) * np.exp(2j * np.pi * rng.random(len(points)))
    signal = add_noise(simulate(points, amplitudes, freqs_hz), rng.uniform(5, 20), seed=int(rng.integers(1 << 30)))
    error_m = rng.uniform(-0.05, 0.05)
    wrong = cam2radar.copy()
    wrong[2, 3] += error_m                        # a calibration error: the whole prior moves by ~error_m
    return signal, freqs_hz, frame, wrong, square_grid(0.04, 41), (z0, sx, sy), error_m


def _frame(signal, freqs_hz, grid, roi):
    from methods.method import Frame
    from methods.skips.settings import NONE

    return Frame(signal, freqs_hz, ANTENNAS, grid, roi, NONE)


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
@pytest.mark.parametrize("cut", [False, True])
def test_mm3fsk_graph_equals_the_host_driven_passes(device, cut):
    from methods.backends import backend_for
    from methods.backends.warp.prior import DeferredPrior
    from methods.mm3fsk import MM3FSK
    from methods.ops.timing import StageTimer
    from methods.prior.image import HostPrior
    from methods.skips.roi import Roi, full_roi

    backend = backend_for(device)
    rng = np.random.default_rng()
    for _ in range(2):
        signal, freqs_hz, depth, wrong, grid, (z0, sx, sy), error_m = _scene(rng)
        roi = full_roi(grid)
        if cut:
            pixels = roi.pixels.copy()
            pixels[:, :6] = False
            roi = Roi(pixels, z0 - 0.02, np.inf, ("test",))
        prior = DeferredPrior(backend.buffers, depth, wrong, grid, 10.0)
        got = MM3FSK().run(_frame(signal, freqs_hz, grid, roi), prior, backend, StageTimer())
        assert not prior.pending                        # the graph ran (not the host path)
        prior_m = got.extra["prior_depth_m"]
        want = MM3FSK().run(_frame(signal, freqs_hz, grid, roi), HostPrior(prior_m, grid), backend, StageTimer())
        assert got.extra["prior_pixels"] == want.extra["prior_pixels"] > 300
        assert got.extra["prior_offset_m"] == pytest.approx(want.extra["prior_offset_m"], abs=1e-7)
        valid, reference = np.isfinite(got.depth_m), np.isfinite(want.depth_m)
        assert valid.sum() > 200 and np.mean(valid != reference) <= 0.002
        assert np.max(np.abs(got.depth_m - want.depth_m)[valid & reference]) < 1e-6
        assert np.array_equal(np.isfinite(got.magnitude), np.isfinite(want.magnitude))
        scale = np.nanmax(want.magnitude)                # float32 sums: magnitudes agree to ~1e-6 of the maximum
        difference = np.abs(got.magnitude - want.magnitude)
        assert np.max(difference, where=np.isfinite(want.magnitude), initial=0) < 1e-5 * scale
        if cut:
            assert not valid[:, :6].any() and np.all(got.depth_m[valid] >= z0 - 0.02)
        # physics: the offset undoes the camera's error, and the depth has d10's precision
        assert got.extra["prior_offset_m"] == pytest.approx(error_m, abs=0.01)
        x_m, y_m = grid.pixel_xy_m()
        true_m = z0 + sx * x_m + sy * y_m
        assert np.median(np.abs(got.depth_m - true_m)[valid]) < 1e-3


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_median_offset_is_np_median_of_the_kept_corrections(device):
    """Random corrections (with ties) and magnitudes, odd and even kept counts, none kept, no threshold: the
    device's offset is np.median of the corrections whose magnitude passes the filter (0 when none does), within
    half a quantisation step, and only the first count[0] points move."""
    import warp as wp

    from methods.backends import backend_for
    from methods.backends.warp.frame_graph import MedianOffset

    dev = backend_for(device).device
    rng = np.random.default_rng()
    m_per_rad = 0.0434                                            # d05_d10's coarse pair: 0.55 GHz
    assert MedianOffset(dev, 1, m_per_rad).bound_m < 1e-10
    for n_used, keep_ratio, zero in [(1, 0.2, False), (2, 0.2, False), (257, 0.2, False), (1000, 0.5, False),
                                     (999, 0.0, False), (300, 0.2, True)]:
        n = n_used + 37                                           # slots past the count stay untouched
        correction = rng.uniform(-np.pi, np.pi, n) * m_per_rad
        correction[rng.random(n) < 0.2] = correction[0]         # ties
        magnitude = rng.random(n).astype(np.float32)
        if zero:
            magnitude[:] = 0
        peak = float(magnitude[:n_used].max())
        kept = (magnitude[:n_used] > 0) & (magnitude[:n_used] >= peak * keep_ratio)
        want = float(np.median(correction[:n_used][kept])) if kept.any() else 0.0
        median = MedianOffset(dev, n, m_per_rad)
        points = wp.array(np.column_stack([np.zeros((n, 2)), np.full(n, 0.3)]), dtype=wp.vec3d, device=dev)
        median.enqueue(wp.array([n_used], dtype=wp.int32, device=dev), wp.array(correction, dtype=wp.float64,
                                                                                 device=dev),
                       wp.array(magnitude, dtype=wp.float32, device=dev), keep_ratio,
                       wp.array([peak], dtype=wp.float32, device=dev), points)
        got = float(median.offset.numpy()[0])
        assert got == pytest.approx(want, abs=median.bound_m * 1.01)
        z = points.numpy()[:, 2]
        assert np.allclose(z[:n_used], 0.3 - got, rtol=0, atol=1e-15) and np.all(z[n_used:] == 0.3)
