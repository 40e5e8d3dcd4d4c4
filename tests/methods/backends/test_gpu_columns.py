"""The column-separable back-projection (methods.backends.warp.columns): the plan finds QAR50's columns and its
error bound holds; the volume is within 1e-4 (relative L2 and normalised magnitude) of the float64 direct sum on
fresh random frames, and BP depths on a scatterer scene agree with the float64 volume's within 0.1 mm."""
from __future__ import annotations

import numpy as np
import pytest

from bench.maroon.antennas import load_antenna_array
from methods.domain.radar import C_M_PER_S
from methods.ops.correlate import correlate_reference
from methods.ops.depth_peak import peak_depth_m

from devices import CUDA

ANT = load_antenna_array()


def _random_frame(rng, n_freqs):
    shape = (len(ANT.rx_m), len(ANT.tx_m), n_freqs)
    return (rng.standard_normal(shape) + 1j * rng.standard_normal(shape)).astype(np.complex64)


def _reference_volume(signal, freqs_hz, x_m, y_m, z_m):
    zz, yy, xx = np.meshgrid(z_m, y_m, x_m, indexing="ij")
    points_m = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])
    return correlate_reference(signal, freqs_hz, ANT.tx_m, ANT.rx_m, points_m, sum_freqs=True)


def test_plan_finds_the_qar50_columns_and_the_step_meets_its_bound():
    from methods.backends.warp import columns

    x_m, y_m, z_m = np.linspace(-0.15, 0.15, 31), np.linspace(0.15, -0.15, 31), np.linspace(0.2, 0.4, 21)
    plan = columns.plan(ANT.tx_m, np.array([81.45e9, 82e9]), x_m, y_m, z_m, term_tol=1e-4)
    assert np.allclose(np.sort(plan.cols_xz_m[:, 0]), [-0.0705, 0.0705]) and np.allclose(plan.cols_xz_m[:, 1], 0)
    assert list(np.diff(plan.col_start)) == [45, 45] and len(plan.small_tx) == 4
    assert np.isclose(plan.term_bound, 1e-4)
    finer = columns.plan(ANT.tx_m, np.array([81.45e9, 82e9]), x_m, y_m, z_m, term_tol=1e-6)
    assert finer.rho_step_m < plan.rho_step_m and finer.n_rho > plan.n_rho
    scattered = np.random.default_rng().uniform(-0.07, 0.07, (94, 3))
    assert columns.plan(scattered, np.array([81.45e9]), x_m, y_m, z_m) is None


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_columns_volume_matches_the_float64_sum(device):
    from methods.backends import backend_for

    backend = backend_for(device)
    rng = np.random.default_rng()
    n_freqs = int(rng.integers(1, 4))
    freqs_hz = np.sort(rng.uniform(72e9, 82e9, n_freqs))
    signal = _random_frame(rng, n_freqs)
    x_m, y_m = np.sort(rng.uniform(-0.15, 0.15, 5)), np.sort(rng.uniform(-0.15, 0.15, 4))[::-1]
    z_m = np.sort(rng.uniform(0.15, 0.6, 3))
    got = backend.volume(signal, freqs_hz, ANT.tx_m, ANT.rx_m, x_m, y_m, z_m, method="columns").ravel()
    ref = _reference_volume(signal, freqs_hz, x_m, y_m, z_m)
    assert np.linalg.norm(got - ref) / np.linalg.norm(ref) <= 1e-4
    assert np.max(np.abs(np.abs(got) - np.abs(ref))) / np.max(np.abs(ref)) <= 1e-4


def test_the_bound_holds_for_coarse_steps():
    """The stated per-term bound at a coarse step bounds the measured image error (and the error does grow)."""
    import warp as wp

    from methods.backends import backend_for
    from methods.backends.warp import columns

    backend = backend_for("warp-cpu")
    rng = np.random.default_rng()
    freqs_hz = np.array([77e9, 82e9])
    signal = _random_frame(rng, 2)
    x_m, y_m, z_m = np.linspace(-0.15, 0.15, 5), np.array([0.15, 0.02, -0.1]), np.array([0.2, 0.33])
    ref = _reference_volume(signal, freqs_hz, x_m, y_m, z_m)
    inputs = backend.frames.inputs(signal, freqs_hz, ANT.tx_m, ANT.rx_m)
    errors = []
    for tol in (1e-2, 1e-3):
        plan = columns.plan(ANT.tx_m, freqs_hz, x_m, y_m, z_m, term_tol=tol)
        out = wp.empty((1, ref.size), dtype=wp.vec2f, device="cpu")
        got = columns.make_volume_launch(inputs, backend.buffers, plan, x_m, y_m, z_m, out)().numpy()
        got = got.view(np.complex64)[0, :, 0]
        errors.append(np.linalg.norm(got - ref) / np.linalg.norm(ref))
        assert errors[-1] <= plan.term_bound
    assert errors[0] > errors[1]


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_columns_bp_depth_matches_the_float64_volume(device):
    """A random scatterer surface: depths of the pixels within -14 dB agree within 0.1 mm on >= 99.9 %."""
    from methods.backends import backend_for

    rng = np.random.default_rng()
    freqs_hz = np.array([81.45e9, 82e9])
    n = 150
    pts = np.column_stack([rng.uniform(-0.06, 0.06, n), rng.uniform(-0.06, 0.06, n), np.zeros(n)])
    pts[:, 2] = 0.3 + 2.0 * (pts[:, 0] ** 2 + pts[:, 1] ** 2) + rng.uniform(-0.002, 0.002, n)
    k = 2 * np.pi * freqs_hz / C_M_PER_S
    d_rx = np.linalg.norm(pts[:, None] - ANT.rx_m[None], axis=2)
    d_tx = np.linalg.norm(pts[:, None] - ANT.tx_m[None], axis=2)
    amp = np.exp(2j * np.pi * rng.uniform(size=n))
    signal = np.stack([(amp[:, None] * np.exp(-1j * kf * d_rx)).T @ np.exp(-1j * kf * d_tx) for kf in k], axis=2)
    x_m, y_m = np.linspace(-0.06, 0.06, 9), np.linspace(0.06, -0.06, 9)
    z_m = np.linspace(0.27, 0.35, 41)
    dz_m = z_m[1] - z_m[0]
    depth_m, max_proj = backend_for(device).volume_peak(signal.astype(np.complex64), freqs_hz, ANT.tx_m, ANT.rx_m,
                                                       x_m, y_m, z_m, dz_m, method="columns")
    ref = np.abs(_reference_volume(signal, freqs_hz, x_m, y_m, z_m).reshape(len(z_m), len(y_m), len(x_m)))
    ref_depth, ref_proj = peak_depth_m(ref, z_m[0], dz_m)
    kept = ref_proj >= ref_proj.max() * 10 ** (-14 / 20)
    assert kept.sum() >= 10
    assert np.mean(np.abs(depth_m[kept] - ref_depth[kept]) <= 1e-4) >= 0.999
    assert np.max(np.abs(max_proj - ref_proj)) <= 1e-4 * ref_proj.max()
