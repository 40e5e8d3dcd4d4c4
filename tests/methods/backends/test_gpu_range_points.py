"""The range-compressed gather at arbitrary points (BP_max's coarse-to-fine search on Warp devices): within the
stated range-compression bound of the float64 sum on fresh random frames, and equal to the range-compressed volume
at the same voxels (same profiles when the points span the same box), so a search finds the volume's values."""
from __future__ import annotations

import numpy as np
import pytest

from bench.maroon.antennas import load_antenna_array
from methods.domain.radar import MAROON_FREQS_HZ
from methods.ops.correlate import correlate_reference
from methods.ops.range_compression import RANGE_REL_TOL

from devices import CUDA

ANT = load_antenna_array()


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_range_gather_at_points_matches_the_float64_sum_and_the_volume(device):
    from methods.backends import backend_for

    backend = backend_for(device)
    rng = np.random.default_rng()
    n_freqs = int(rng.integers(16, 40))
    start = int(rng.integers(0, 128 - n_freqs))
    freqs_hz = MAROON_FREQS_HZ[start:start + n_freqs]
    signal = (rng.standard_normal((94, 94, n_freqs)) + 1j * rng.standard_normal((94, 94, n_freqs))).astype(np.complex64)
    points_m = np.column_stack([rng.uniform(-0.15, 0.15, 7), rng.uniform(-0.15, 0.15, 7), rng.uniform(0.2, 0.6, 7)])
    got = backend.correlate_summed(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m)
    ref = correlate_reference(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, sum_freqs=True)
    assert np.isfinite(got).all() and np.linalg.norm(got - ref) / np.linalg.norm(ref) < RANGE_REL_TOL

    x_m, y_m, z_m = np.sort(rng.uniform(-0.15, 0.15, 3)), np.sort(rng.uniform(-0.15, 0.15, 2)), [0.27, 0.31]
    volume = backend.volume(signal, freqs_hz, ANT.tx_m, ANT.rx_m, x_m, y_m, z_m, method="range")
    zz, yy, xx = np.meshgrid(z_m, y_m, x_m, indexing="ij")
    at_voxels = backend.correlate_summed(signal, freqs_hz, ANT.tx_m, ANT.rx_m,
                                         np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()]))
    assert np.array_equal(at_voxels, volume.ravel())


@pytest.mark.parametrize("device", ["cpu", "warp-cpu", CUDA])
def test_summed_at_points_is_correlate_summed_on_one_frame(device):
    from methods.backends import backend_for

    backend = backend_for(device)
    rng = np.random.default_rng()
    for freqs_hz in (MAROON_FREQS_HZ[[3, 90]], MAROON_FREQS_HZ[::6]):          # two frequencies; many (range on Warp)
        signal = (rng.standard_normal((94, 94, len(freqs_hz)))
                  + 1j * rng.standard_normal((94, 94, len(freqs_hz)))).astype(np.complex64)
        evaluate = backend.summed_at_points(signal, freqs_hz, ANT.tx_m, ANT.rx_m)
        for n in (5, 9):
            points_m = np.column_stack([rng.uniform(-0.1, 0.1, n), rng.uniform(-0.1, 0.1, n),
                                        rng.uniform(0.25, 0.4, n)])
            expected = backend.correlate_summed(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m)
            assert np.array_equal(evaluate(points_m), expected)
