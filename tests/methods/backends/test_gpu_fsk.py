"""2FSK and 3FSK on the device pipeline (`methods.backends.warp.fsk`: points made on the device, the strongest
pixel by a reduction, depth and filter kernels, one copy back) against the same backend's host-driven passes
(today's computation), on fresh random scenes: the same pixels valid but for at most 0.2 % (pixels at the filter
threshold), depths within 10 um (the device's float32 atan2 and FMAs move z1 by ~1e-8 m; a weak pixel's phase
moves more), the same reference pixel, and the ROI's depth interval applied."""
from __future__ import annotations

import numpy as np
import pytest

from bench.synth.memory import ANTENNAS, MAROON_FREQS_HZ, add_noise, simulate, square_grid
from methods.ops.frequencies import config_indices

from devices import CUDA

DEVICES = ["warp-cpu", CUDA]


def _scene(rng: np.random.Generator, freq: str):
    """A tilted plate of random scatterers at a random depth, noisy, and a 41 x 41 grid of 2 mm pixels."""
    indices = config_indices(MAROON_FREQS_HZ, freq)
    axis = np.arange(-0.03, 0.0301, 0.002)
    x, y = (a.ravel() for a in np.meshgrid(axis, axis))
    z0, tilt = rng.uniform(0.33, 0.45), rng.uniform(-0.1, 0.1, 2)
    points = np.column_stack([x, y, z0 + tilt[0] * x + tilt[1] * y])
    amplitudes = rng.uniform(0.5, 1.5, len(points)) * np.exp(2j * np.pi * rng.random(len(points)))
    signal = add_noise(simulate(points, amplitudes, MAROON_FREQS_HZ[indices]), rng.uniform(0, 20),
                       seed=int(rng.integers(1 << 30)))
    return signal, MAROON_FREQS_HZ[indices], square_grid(0.04, 41)


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("method, freq", [("2fsk", "d05"), ("3fsk", "d05_d10")])
def test_device_fsk_equals_the_host_driven_passes(device, method, freq, monkeypatch):
    from methods.backends import backend_for
    from methods.fsk import reconstruct_2fsk
    from methods.fsk3 import reconstruct_3fsk
    from methods.skips.roi import Roi, full_roi

    backend = backend_for(device)
    rng = np.random.default_rng()
    run = reconstruct_2fsk if method == "2fsk" else reconstruct_3fsk
    for _ in range(2):
        signal, freqs_hz, grid = _scene(rng, freq)
        pixels = full_roi(grid).pixels.copy()
        pixels[:, :5] = False                                          # a region of interest with a cut
        roi = Roi(pixels, 0.30, np.inf, ("test",))
        assert backend.device_fsk
        got = run(signal, freqs_hz, ANTENNAS, grid, backend=backend, roi=roi)
        with monkeypatch.context() as m:
            m.setattr(type(backend), "device_fsk", False)
            expected = run(signal, freqs_hz, ANTENNAS, grid, backend=backend, roi=roi)
        valid, reference = np.isfinite(got.depth_m), np.isfinite(expected.depth_m)
        assert valid.sum() > 100 and np.mean(valid != reference) <= 0.002
        assert not valid[:, :5].any() and np.all(got.depth_m[valid] >= 0.30)
        assert np.max(np.abs(got.depth_m - expected.depth_m)[valid & reference]) < 1e-5
        assert got.extra["reference_pixel"] == expected.extra["reference_pixel"]
        assert got.extra["z1_m"] == pytest.approx(expected.extra["z1_m"], abs=1e-7)
        if method == "3fsk":
            coarse = np.isfinite(expected.extra["coarse_depth_m"])
            assert np.array_equal(np.isfinite(got.extra["coarse_depth_m"]), coarse)
