"""BP's coarse-to-fine search on a Warp device end to end (methods.backends.warp.search) against the host-driven
search (methods.skips.bp_search.search_depth) over the same range-compressed values: same depths (to float32
rounding of the gather's sample positions), same skipped and cut pixels, same number of samples evaluated. The
device search is switched on for the test where it is off by default (Warp-CPU)."""
from __future__ import annotations

import numpy as np
import pytest

from bench.maroon.antennas import load_antenna_array
from methods.domain.radar import C_M_PER_S
from methods.skips import bp_search

from devices import CUDA

ANT = load_antenna_array()
FREQS_HZ = np.linspace(72e9, 82e9, 128)[40:72]       # 32 equidistant frequencies: the range-compressed path


def _searching(device):
    """The backend of `device` with its device search on (restored by the caller's fixture)."""
    from methods.backends import backend_for

    backend = backend_for(device)
    backend.device_search = True
    return backend


@pytest.fixture(autouse=True)
def _restore_device_search():
    from methods.backends import backend_for

    yield
    for device in ("warp-cpu",):
        backend = backend_for(device)
        backend.device_search = not backend.device.is_cpu


def _scene_frame(rng):
    n = 150
    pts = np.column_stack([rng.uniform(-0.05, 0.05, n), rng.uniform(-0.05, 0.05, n), np.zeros(n)])
    pts[:, 2] = 0.3 + 2.0 * (pts[:, 0] ** 2 + pts[:, 1] ** 2) + rng.uniform(-0.002, 0.002, n)
    k = 2 * np.pi * FREQS_HZ / C_M_PER_S
    d_rx = np.linalg.norm(pts[:, None] - ANT.rx_m[None], axis=2)
    d_tx = np.linalg.norm(pts[:, None] - ANT.tx_m[None], axis=2)
    amp = np.exp(2j * np.pi * rng.uniform(size=n))
    frame = np.stack([(amp[:, None] * np.exp(-1j * kf * d_rx)).T @ np.exp(-1j * kf * d_tx) for kf in k], axis=2)
    noise = rng.standard_normal(frame.shape) + 1j * rng.standard_normal(frame.shape)
    return (frame + 0.05 * np.abs(frame).mean() * noise).astype(np.complex64)


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
@pytest.mark.parametrize("threshold_db, z_edges, n_z", [(14.0, (True, False), 40), (None, (True, True), 40),
                                                        (None, (True, True), 4)])
def test_device_search_equals_the_host_search(device, threshold_db, z_edges, n_z):
    """40 depths: several refinement levels per pixel; 4 depths: the coarse step clipped to the last depth."""
    backend = _searching(device)
    rng = np.random.default_rng()
    signal = _scene_frame(rng)
    xx, yy = np.meshgrid(np.linspace(-0.06, 0.06, 9), np.linspace(0.06, -0.06, 7))
    x_m, y_m = xx.ravel(), yy.ravel()
    z_m = 0.26 + 0.0025 * np.arange(n_z)
    plan = bp_search.plan_search(FREQS_HZ, ANT, x_m, y_m, float(z_m[0]), 0.0025, 3.0, 0.02, 1.0)
    assert plan.step.max() > 1 and (n_z > 4 or plan.step.min() >= n_z - 1)
    host = bp_search.search_depth(backend.summed_at_points(signal, FREQS_HZ, ANT.tx_m, ANT.rx_m), x_m, y_m, z_m,
                                  plan, threshold_db, z_edges)
    got = bp_search.SearchResult(*backend.search_depth(signal, FREQS_HZ, ANT.tx_m, ANT.rx_m, x_m, y_m, z_m, plan,
                                                       threshold_db, z_edges))
    assert np.array_equal(np.isnan(got.depth_m), np.isnan(host.depth_m))
    valid = np.isfinite(host.depth_m)
    assert valid.sum() >= 8
    assert np.max(np.abs(got.depth_m[valid] - host.depth_m[valid])) <= 1e-6
    assert np.allclose(got.max_projection, host.max_projection, rtol=1e-4)
    assert got.n_evaluated == host.n_evaluated


def test_host_search_where_the_device_search_does_not_apply():
    from methods.backends import backend_for

    assert not backend_for("warp-cpu").device_search           # off by default on Warp-CPU (module doc)
    backend = _searching("warp-cpu")                             # two frequencies: no range compression
    signal = np.ones((94, 94, 2), dtype=np.complex64)
    plan = bp_search.SearchPlan.every_sample(3)
    assert backend.search_depth(signal, [81.45e9, 82e9], ANT.tx_m, ANT.rx_m, np.zeros(3), np.zeros(3),
                                np.array([0.3, 0.31]), plan, 14.0, (True, True)) is None


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_device_coarse_roi_equals_the_host_one(device):
    """bp_search.coarse_roi with the device's coarse pass (Backend.coarse_peaks) finds the host pass's ROI."""
    backend = _searching(device)
    rng = np.random.default_rng()
    xx, yy = np.meshgrid(np.linspace(-0.06, 0.06, 13), np.linspace(0.06, -0.06, 11))
    pixels = np.ones(xx.shape, dtype=bool)
    z_m = np.arange(0.24, 0.38, 0.0025)

    def plan_of(x_m, y_m):
        return bp_search.plan_search(FREQS_HZ, ANT, x_m, y_m, float(z_m[0]), 0.0025, 3.0, 0.02, 1.0)

    # fresh random scenes until the host's ROI cuts the depth range (most do; one that spans it all would make the
    # comparison below vacuous): the check is that the device finds the same ROI, not that every scene is cut
    for _ in range(20):
        signal = _scene_frame(rng)
        evaluate = backend.summed_at_points(signal, FREQS_HZ, ANT.tx_m, ANT.rx_m)
        host, n_host = bp_search.coarse_roi(evaluate, pixels, xx, yy, z_m, plan_of, 14.0, 3, 2, 3.0, 0.005)
        if host.pixels.sum() > 0 and host.z_max_m - host.z_min_m < z_m[-1] - z_m[0]:
            break
    else:
        pytest.fail("20 random scenes gave no ROI that cuts the depth range")

    def on_device(x_m, y_m, z_c, step):
        return backend.coarse_peaks(signal, FREQS_HZ, ANT.tx_m, ANT.rx_m, x_m, y_m, z_c, step)
    got, n_got = bp_search.coarse_roi(evaluate, pixels, xx, yy, z_m, plan_of, 14.0, 3, 2, 3.0, 0.005, on_device)
    assert n_got == n_host and np.array_equal(got.pixels, host.pixels)
    assert got.z_min_m == host.z_min_m and got.z_max_m == host.z_max_m
