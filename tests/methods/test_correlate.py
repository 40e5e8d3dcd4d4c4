"""Every correlation backend against the float64 direct sum, on fresh random inputs and the real QAR50 layout.

Tolerances (relative error ||out - ref|| / ||ref||): float32 separable paths 1e-4 (measured ~4e-6); the CUDA
tensor-core kernel (fp16 operands, fp32 accumulation) 1e-3 (measured ~3e-4); the plain float32 direct kernel 1e-3
(measured ~9e-5: its phases of ~1e3 rad carry float32 rounding); range compression RANGE_REL_TOL = 1e-2
(measured ~1e-3).
"""
from __future__ import annotations

import numpy as np
import pytest

from bench.maroon.antennas import load_antenna_array
from methods.backends import correlate, correlate_volume, resolve_device
from methods.domain.radar import MAROON_FREQS_HZ
from methods.ops.correlate import C_M_PER_S, correlate_reference
from methods.ops.range_compression import RANGE_REL_TOL

from devices import CUDA

ANT = load_antenna_array()


DEVICES = ["cpu", "warp-cpu", CUDA]


TOL = {"cpu": 1e-4, "warp-cpu": 1e-4, "cuda": 1e-3}     # cuda: the tensor-core kernel, fp16 operands


def rel_err(out, ref) -> float:
    return float(np.linalg.norm(out - ref) / np.linalg.norm(ref))


def random_problem(rng, n_points: int, n_freqs: int):
    """Random complex frame, random frequency subset, random points in x, y in +-0.15 m, z in 0.2-0.6 m."""
    freqs_hz = np.sort(rng.choice(MAROON_FREQS_HZ, n_freqs, replace=False))
    signal = rng.standard_normal((94, 94, n_freqs)) + 1j * rng.standard_normal((94, 94, n_freqs))
    points_m = np.column_stack([rng.uniform(-0.15, 0.15, n_points), rng.uniform(-0.15, 0.15, n_points),
                                rng.uniform(0.2, 0.6, n_points)])
    return signal, freqs_hz, points_m


def point_target_frame(target_m, freqs_hz):
    """Analytic frame of one point scatterer: S[r, t, f] = exp(-j 2 pi f (|p - rx| + |p - tx|) / c)."""
    path_m = (np.linalg.norm(target_m - ANT.rx_m, axis=1)[:, None]
              + np.linalg.norm(target_m - ANT.tx_m, axis=1)[None, :])
    return np.exp(-2j * np.pi * freqs_hz[None, None, :] * path_m[:, :, None] / C_M_PER_S)


@pytest.mark.parametrize("device", DEVICES)
def test_correlate_matches_float64_reference(device):
    rng = np.random.default_rng()
    n_points = 4000 if device == "cpu" else 40
    signal, freqs_hz, points_m = random_problem(rng, n_points, int(rng.integers(1, 4)))
    out = correlate(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, device=device)
    ref = correlate_reference(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m[:200])
    assert out.dtype == np.complex64 and out.shape == (len(freqs_hz), n_points)
    assert rel_err(out[:, :200], ref) < TOL[device]


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
@pytest.mark.parametrize("kernel", ["tc", "separable"])
def test_warp_kernels_match_reference(device, kernel):
    """Each Warp kernel by name on both Warp devices (the tensor-core kernel runs its scalar tile path on the CPU)."""
    from methods.backends import backend_for
    rng = np.random.default_rng()
    signal, freqs_hz, points_m = random_problem(rng, 70, int(rng.integers(1, 4)))
    out = backend_for(device).correlate(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, kernel=kernel)
    ref = correlate_reference(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m)
    assert rel_err(out, ref) < (1e-3 if kernel == "tc" else 1e-4)


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_frame_cache_sees_in_place_changes_and_outputs_are_not_shared(device):
    rng = np.random.default_rng()
    signal, freqs_hz, points_m = random_problem(rng, 20, 2)
    first = correlate(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, device=device)
    kept = first.copy()
    signal[3, 5, 1] += 10.0                                   # same array object, new content
    second = correlate(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, device=device)
    assert np.array_equal(first, kept)                        # the first result was not overwritten
    ref = correlate_reference(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m)
    assert rel_err(second, ref) < TOL[device]


def test_a_held_frame_is_found_by_identity_and_only_within_its_block(monkeypatch):
    from methods.backends.warp import frames

    rng = np.random.default_rng()
    signal, freqs_hz, _ = random_problem(rng, 1, 2)
    signal = signal.astype(np.complex64)
    cache = frames.FrameCache("cpu")
    compared = []
    equal = frames._equal
    monkeypatch.setattr(frames, "_equal", lambda a, b: compared.append(a.size) or equal(a, b))
    cache.inputs(signal, freqs_hz, ANT.tx_m, ANT.rx_m)             # cached by content before the block
    with cache.held(signal):
        first = cache.inputs(signal, freqs_hz, ANT.tx_m, ANT.rx_m)
        compared.clear()
        assert cache.inputs(signal, freqs_hz, ANT.tx_m, ANT.rx_m) is first
        assert signal.size not in compared                          # the frame itself not compared again
        other = cache.inputs(signal, freqs_hz[::-1].copy(), ANT.tx_m, ANT.rx_m)
        assert other is not first                                   # the small arrays are still compared
        copy = cache.inputs(signal.copy(), freqs_hz, ANT.tx_m, ANT.rx_m)
        assert copy is first                                        # another object: found by content
    signal[0, 0, 0] += 1.0                                          # outside the block: content decides again
    assert cache.inputs(signal, freqs_hz, ANT.tx_m, ANT.rx_m) is not first


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_plain_direct_kernel_matches_reference(device):
    from methods.backends import backend_for
    rng = np.random.default_rng()
    signal, freqs_hz, points_m = random_problem(rng, 30, 2)
    out = backend_for(device).correlate(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, kernel="direct")
    assert rel_err(out, correlate_reference(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m)) < 1e-3


@pytest.mark.parametrize("device", DEVICES)
def test_sum_freqs_is_sum_of_per_frequency_output(device):
    rng = np.random.default_rng()
    signal, freqs_hz, points_m = random_problem(rng, 50, 3)
    per_freq = correlate(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, device=device)
    summed = correlate(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, sum_freqs=True, device=device)
    assert summed.shape == (50,)
    assert rel_err(summed, per_freq.sum(axis=0)) < 1e-5


@pytest.mark.parametrize("device", DEVICES)
def test_volume_equals_correlate_on_flattened_grid(device):
    rng = np.random.default_rng()
    signal, freqs_hz, _ = random_problem(rng, 0, 2)
    x_m = np.sort(rng.uniform(-0.15, 0.15, 5))
    y_m = np.sort(rng.uniform(-0.15, 0.15, 4))[::-1]          # descending: row 0 = +y
    z_m = np.sort(rng.uniform(0.2, 0.6, 3))
    vol = correlate_volume(signal, freqs_hz, ANT.tx_m, ANT.rx_m, x_m, y_m, z_m, device=device, method="direct")
    zz, yy, xx = np.meshgrid(z_m, y_m, x_m, indexing="ij")
    points_m = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])
    flat = correlate(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, sum_freqs=True, device="cpu")
    assert vol.shape == (3, 4, 5) and vol.dtype == np.complex64
    assert rel_err(vol.ravel(), flat) < TOL[device]


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_range_compressed_volume_within_stated_bound(device):
    rng = np.random.default_rng()
    n_freqs = int(rng.integers(16, 48))
    start = int(rng.integers(0, 128 - n_freqs))
    freqs_hz = MAROON_FREQS_HZ[start:start + n_freqs]
    signal = rng.standard_normal((94, 94, n_freqs)) + 1j * rng.standard_normal((94, 94, n_freqs))
    x_m, y_m, z_m = rng.uniform(-0.15, 0.15, 4), rng.uniform(-0.15, 0.15, 3), rng.uniform(0.2, 0.6, 2)
    fast = correlate_volume(signal, freqs_hz, ANT.tx_m, ANT.rx_m, x_m, y_m, z_m, device=device, method="range")
    zz, yy, xx = np.meshgrid(z_m, y_m, x_m, indexing="ij")
    points_m = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])
    ref = correlate_reference(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, sum_freqs=True)
    assert rel_err(fast.ravel(), ref) < RANGE_REL_TOL


def test_auto_method_uses_range_compression_only_where_it_applies():
    from methods.ops.range_compression import worth_it
    assert worth_it(MAROON_FREQS_HZ)
    assert not worth_it(MAROON_FREQS_HZ[[0, 127]])      # 2 frequencies: direct
    assert not worth_it(MAROON_FREQS_HZ[::16] + np.r_[0, 1e6, 0, 0, 0, 0, 0, 0])  # off-grid


@pytest.mark.parametrize("device", DEVICES)
def test_point_target_peaks_at_its_position(device):
    rng = np.random.default_rng()
    freqs_hz = MAROON_FREQS_HZ[::8] if device == "cpu" else MAROON_FREQS_HZ[::16]
    x_m = np.linspace(-0.1, 0.1, 21)
    y_m = np.linspace(0.1, -0.1, 21)
    z_m = np.linspace(0.25, 0.45, 21)
    target_m = np.array([rng.choice(x_m[3:-3]), rng.choice(y_m[3:-3]), rng.choice(z_m[3:-3])])
    frame = point_target_frame(target_m, freqs_hz)
    if device == "warp-cpu":       # single-threaded: scan a cross through the target only
        x_m = x_m[np.abs(x_m - target_m[0]) < 0.03]
        y_m = y_m[np.abs(y_m - target_m[1]) < 0.03]
    vol = np.abs(correlate_volume(frame, freqs_hz, ANT.tx_m, ANT.rx_m, x_m, y_m, z_m, device=device))
    iz, iy, ix = np.unravel_index(np.argmax(vol), vol.shape)
    assert np.allclose([x_m[ix], y_m[iy], z_m[iz]], target_m)
    assert vol.max() == pytest.approx(len(freqs_hz), rel=2e-2)     # coherent: |sum over f of 1|


def test_bad_inputs_raise_clear_errors():
    with pytest.raises(ValueError, match="signal must have shape"):
        correlate(np.zeros((94, 94, 2)), MAROON_FREQS_HZ[:3], ANT.tx_m, ANT.rx_m, np.zeros((1, 3)))
    with pytest.raises(ValueError, match="device must be one of"):
        resolve_device("gpu")


@pytest.mark.parametrize("n_threads", [1, 2, 3, 16])
def test_cpu_chunks_cover_every_point_once_in_balanced_blocks(n_threads):
    import math

    from methods.backends.cpu import CHUNK_POINTS, chunk_starts

    for n_points in (0, 1, 5, 2047, 2048, 4097, 13680, 90601):
        starts = chunk_starts(n_points, n_threads)
        covered = np.concatenate([np.arange(s, min(s + starts.step, n_points)) for s in starts] or [[]])
        np.testing.assert_array_equal(covered, np.arange(n_points))
        assert starts.step <= max(CHUNK_POINTS, 1)
        # the slowest thread does at most one chunk more than an even share
        assert math.ceil(len(starts) / n_threads) * starts.step <= n_points / n_threads + starts.step


def test_cpu_small_batches_on_the_calling_thread_give_the_pools_values():
    # a batch under MIN_PARALLEL_POINTS runs on the calling thread with single-threaded BLAS: the values of the same
    # points inside a batch the worker threads share (float32 products: the same within 1e-6)
    from methods.backends.cpu import MIN_PARALLEL_POINTS, correlate_numpy

    rng = np.random.default_rng()
    signal, freqs_hz, points_m = random_problem(rng, 4 * MIN_PARALLEL_POINTS, 2)
    pooled = correlate_numpy(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m)
    small = correlate_numpy(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m[:MIN_PARALLEL_POINTS // 3])
    assert rel_err(small, pooled[:, :MIN_PARALLEL_POINTS // 3]) < 1e-6


def test_cpu_correlation_threads_follow_the_process_affinity_unless_set(monkeypatch):
    from methods.backends import cpu
    from methods.domain import host

    monkeypatch.delenv("CORRELATE_THREADS", raising=False)
    monkeypatch.setattr(host.os, "sched_getaffinity", lambda pid: {1, 4}, raising=False)
    monkeypatch.setattr(host.os, "cpu_count", lambda: 224)       # the host's cores, not the container's
    assert cpu.correlation_threads() == 2
    monkeypatch.setenv("CORRELATE_THREADS", "3")
    assert cpu.correlation_threads() == 3
