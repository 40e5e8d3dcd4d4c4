"""The entry point `methods.reconstruct`: the full MM-2FSK path from a depth image, parameters, and clear errors
for invalid combinations."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.synth.memory import (
    TABLE1_FREQS_HZ,
    make_capture,
    plane_depth_frame,
    plate_points_m,
    realsense2radar,
    simulate,
    square_grid,
)
from methods import reconstruct

from devices import CUDA

GRID = square_grid(0.02, 41)
SLOPE_X = 0.05                                          # plate z = 0.30 + 0.05 x (3 degrees)


@pytest.fixture(scope="module")
def tilted_plate():
    points_m = plate_points_m(0.30)
    points_m[:, 2] += SLOPE_X * points_m[:, 0]
    cam2radar = realsense2radar()
    return make_capture(simulate(points_m, np.ones(len(points_m)), TABLE1_FREQS_HZ), TABLE1_FREQS_HZ, GRID,
                        realsense=plane_depth_frame(0.30, SLOPE_X, 0.0, cam2radar),
                        transforms={"realsense2radar": cam2radar})


@pytest.mark.parametrize("config", ["d05", "d10"])
def test_mm2fsk_from_a_realsense_depth_image(tilted_plate, config):
    rec = reconstruct(tilted_plate, "mm2fsk", config, prior="realsense")
    x_m, _ = GRID.pixel_xy_m()
    error_m = np.abs(rec.depth_m - (0.30 + SLOPE_X * x_m))
    assert rec.valid.sum() > 0.9 * rec.valid.size
    assert np.nanmax(error_m) < 1e-3                    # measured 0.5 mm
    assert rec.method == "mm2fsk" and rec.extra["prior_pixels"] == GRID.image_shape[0] * GRID.image_shape[1]
    assert {"prior", "correlate", "depth", "filter", "total"} <= set(rec.timings_ms)
    assert rec.timings_ms["total"] >= rec.timings_ms["prior"] + rec.timings_ms["correlate"]


def test_frequencies_by_name_or_by_target_list_and_scalar_prior_parameter(tilted_plate):
    by_name = reconstruct(tilted_plate, "2fsk", "d05")
    by_list = reconstruct(tilted_plate, "2fsk", [81.45, 82.0])
    assert np.array_equal(by_name.freqs_hz, by_list.freqs_hz)
    assert np.array_equal(by_name.depth_m, by_list.depth_m, equal_nan=True)
    assert reconstruct(tilted_plate, "2fsk", "d05", scalar_prior_m=0.35).extra["prior_m"] == 0.35
    assert reconstruct(tilted_plate, "2fsk", "d05", prior="0.33").extra["prior_m"] == 0.33
    few_pixels = square_grid(0.002, 3, 0.29, 0.31, 11)                             # grid override
    every = reconstruct(tilted_plate, "bp", None, grid=few_pixels, threshold_db=None)  # None = all frequencies
    assert len(every.freqs_hz) == len(TABLE1_FREQS_HZ) and every.depth_m.shape == (3, 3) and every.valid.all()


@pytest.mark.parametrize("method, freq, prior, params, message", [
    ("sar", "d05", "none", {}, "unknown method 'sar'"),
    ("2fsk", "d3", "none", {}, "unknown frequency configuration 'd3'"),
    ("2fsk", "d05_d10", "none", {}, "2fsk needs a 2-frequency configuration"),
    ("3fsk", "d05", "none", {}, "3fsk needs a 3-frequency configuration"),
    ("mm2fsk", "full", "realsense", {}, "mm2fsk needs a 2-frequency configuration"),
    ("mm2fsk", "d05", "none", {}, "mm2fsk needs a per-pixel prior"),
    ("mm2fsk", "d05", 0.3, {}, "mm2fsk needs a per-pixel prior"),
    ("2fsk", "d05", "realsense", {}, "use method='mm2fsk'"),
    ("2fsk", "d05", "lidar", {}, "prior must be 'none', 'realsense', 'photogrammetry'"),
    ("2fsk", "d05", -0.4, {}, "in front of the array"),
    ("2fsk", "d05", "none", {"band_m": 0.01}, "unknown parameter"),
    ("bp", "d05", "none", {"band_m": 0.01}, "give a prior as well"),
    ("mm2fsk", "d05", "photogrammetry", {}, "has none"),
])
def test_invalid_combinations_raise_clear_errors(tilted_plate, method, freq, prior, params, message):
    with pytest.raises(ValueError, match=message):
        reconstruct(tilted_plate, method, freq, prior=prior, **params)


def test_missing_parts_of_the_capture_are_named(tilted_plate):
    no_realsense = dataclasses.replace(tilted_plate, realsense=None, notes=["realsense/depth/000000.png missing"])
    with pytest.raises(ValueError, match=r"has none \(realsense/depth/000000.png missing\)"):
        reconstruct(no_realsense, "mm2fsk", "d05", prior="realsense")
    no_transform = dataclasses.replace(tilted_plate, transforms={})
    with pytest.raises(ValueError, match="no 'realsense2radar' transform"):
        reconstruct(no_transform, "mm2fsk", "d05", prior="realsense")
    with pytest.raises(ValueError, match="no radar frame"):
        reconstruct(dataclasses.replace(tilted_plate, radar=None), "2fsk", "d05")


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
@pytest.mark.parametrize("method, config, prior", [("mm2fsk", "d10", "realsense"), ("3fsk", "d05_d10", "none"),
                                                   ("bp", "d05", "none")])
def test_warp_devices_give_the_cpu_result(tilted_plate, device, method, config, prior):
    grid = square_grid(0.003, 7, 0.29, 0.31, 11)          # few pixels: Warp on the CPU runs on one thread
    on_cpu = reconstruct(tilted_plate, method, config, prior=prior, grid=grid)
    on_device = reconstruct(tilted_plate, method, config, prior=prior, grid=grid, device=device)
    assert on_device.device == device
    np.testing.assert_allclose(on_device.depth_m, on_cpu.depth_m, rtol=0, atol=2e-6)


def test_warm_up_runs_once_per_backend_and_frequency_count(tilted_plate, monkeypatch):
    from methods.backends import backend_for
    backend = backend_for("warp-cpu")
    calls, correlate = [], backend.correlate

    def counting(signal, freqs_hz, tx_m, rx_m, points_m, **kwargs):
        if np.array_equal(points_m, [[0.0, 0.0, 0.3]]):          # the warm-up's tiny problem
            calls.append(len(freqs_hz))
        return correlate(signal, freqs_hz, tx_m, rx_m, points_m, **kwargs)
    monkeypatch.setattr(backend, "warmed", set())
    monkeypatch.setattr(backend, "correlate", counting)
    grid = square_grid(0.003, 7, 0.29, 0.31, 11)
    for _ in range(3):
        reconstruct(tilted_plate, "3fsk", "d05_d10", prior=0.3, grid=grid, device="warp-cpu")
    assert calls == [3]                                 # the later calls skip the warm-up
    reconstruct(tilted_plate, "2fsk", "d05", prior=0.3, grid=grid, device="warp-cpu")
    assert calls == [3, 2]                              # another frequency count: its own warm-up
    assert backend.warmed == {(3, False, False), (2, False, False)}


def _with_nan_sample(capture):
    signal = capture.radar.signal.copy()
    signal[3, 5, -1] = np.nan
    return dataclasses.replace(capture, radar=dataclasses.replace(capture.radar, signal=signal))


def test_a_frame_with_nan_samples_is_refused_naming_the_capture(tilted_plate):
    for method, freq in (("bp", None), ("2fsk", "d05")):
        with pytest.raises(ValueError, match=f"capture {tilted_plate.name} has NaN or Inf samples"):
            reconstruct(_with_nan_sample(tilted_plate), method, freq, grid=square_grid(0.003, 3, 0.29, 0.31, 5))


@pytest.mark.parametrize("checked", [False, True])
def test_a_backend_that_checks_samples_on_its_device_replaces_the_host_check(tilted_plate, monkeypatch, checked):
    """Where the backend says it checks a frame's samples when it uploads them (`checks_samples`), the host skips its
    sum; a frame the method never uploaded (`samples_checked` False) is still checked on the host after the run, and
    the backend's NonFiniteSignal becomes the same one-line error naming the capture."""
    from methods import api
    from methods.backends import backend_for
    from methods.domain.errors import NonFiniteSignal

    backend, host_checks = backend_for("cpu"), []
    check_signal = api._check_signal
    monkeypatch.setattr(api, "_check_signal", lambda capture, signal: host_checks.append(1) or check_signal(
        capture, signal))
    monkeypatch.setattr(backend, "checks_samples", lambda signal: True, raising=False)
    monkeypatch.setattr(backend, "samples_checked", lambda signal: checked, raising=False)
    grid = square_grid(0.003, 3, 0.29, 0.31, 5)
    reconstruct(tilted_plate, "bp", None, grid=grid)
    assert host_checks == ([] if checked else [1])
    if not checked:                                   # never uploaded: the host's check after the run refuses it
        with pytest.raises(ValueError, match=f"capture {tilted_plate.name} has NaN or Inf samples"):
            reconstruct(_with_nan_sample(tilted_plate), "bp", None, grid=grid)
        return

    def refuse(*args, **kwargs):
        raise NonFiniteSignal("the radar frame has NaN or Inf samples")
    monkeypatch.setattr(backend, "volume_peak", refuse)
    monkeypatch.setattr(backend, "correlate", refuse)
    with pytest.raises(ValueError, match=f"^the radar frame of capture {tilted_plate.name} has NaN or Inf samples$"):
        reconstruct(tilted_plate, "bp", None, grid=grid, roi="none")


@pytest.mark.parametrize("device", [CUDA])
def test_cuda_checks_the_samples_it_uploads(tilted_plate, monkeypatch, device):
    """On CUDA a frame the cache checks (`FrameCache.CHECK_BYTES`, lowered here to this small frame) is checked on
    the device: a NaN sample is refused with the host's message, a finite frame gives the host-checked result."""
    from methods.backends import backend_for
    from methods.backends.warp.frames import FrameCache

    grid = square_grid(0.003, 5, 0.29, 0.31, 11)
    host_checked = reconstruct(tilted_plate, "bp", None, grid=grid, device=device)
    monkeypatch.setattr(FrameCache, "CHECK_BYTES", 0)
    backend = backend_for(device)
    assert backend.checks_samples(tilted_plate.radar.signal)
    device_checked = reconstruct(tilted_plate, "bp", None, grid=grid, device=device)
    assert backend.samples_checked(tilted_plate.radar.signal)
    assert np.array_equal(device_checked.depth_m, host_checked.depth_m, equal_nan=True)
    nan_frame = _with_nan_sample(tilted_plate)
    with pytest.raises(ValueError, match=f"^the radar frame of capture {tilted_plate.name} has NaN or Inf samples$"):
        reconstruct(nan_frame, "bp", None, grid=grid, device=device)
    assert not backend.samples_checked(nan_frame.radar.signal)


@pytest.mark.parametrize("device", [CUDA])
@pytest.mark.parametrize("method, config, prior", [("mm2fsk", "d10", "realsense"), ("mm3fsk", "d05_d10", "realsense"),
                                                   ("2fsk", "d05", "none"), ("3fsk", "d05_d10", "none")])
def test_cuda_frame_graphs_check_the_samples_they_gather(tilted_plate, monkeypatch, device, method, config, prior):
    """The frame graphs of MM-2FSK, MM-3FSK, 2FSK and 3FSK gather the used frequencies' samples from the frame and
    check them on the device: the host neither takes nor checks them for a finite frame, and a NaN at a used
    frequency is refused with the host's message."""
    from methods import api
    from methods.ops.frequencies import config_indices

    host_checks, check_signal = [], api._check_signal
    monkeypatch.setattr(api, "_check_signal", lambda capture, signal: host_checks.append(1) or check_signal(
        capture, signal))
    grid = square_grid(0.003, 7, 0.29, 0.31, 11)
    on_device = reconstruct(tilted_plate, method, config, prior=prior, grid=grid, device=device)
    assert host_checks == [] and on_device.valid.any()
    signal = tilted_plate.radar.signal.copy()
    signal[3, 5, config_indices(tilted_plate.radar.freqs_hz, config)[-1]] = np.nan
    nan_frame = dataclasses.replace(tilted_plate, radar=dataclasses.replace(tilted_plate.radar, signal=signal))
    with pytest.raises(ValueError, match=f"^the radar frame of capture {tilted_plate.name} has NaN or Inf samples$"):
        reconstruct(nan_frame, method, config, prior=prior, grid=grid, device=device)


def test_any_valid_is_whether_some_depth_is_finite():
    """The API's test for an all-invalid result (a sparse sample first, then a full pass) against its definition on
    random maps with few finite depths, off the sample's stride and on it, NaN and Inf."""
    from methods.api import _any_valid

    rng = np.random.default_rng()
    for _ in range(200):
        depth_m = np.full(rng.integers(1, 60, size=2), np.nan)
        depth_m[rng.random(depth_m.shape) < rng.choice([0.0, 0.01, 0.3])] = 0.3
        depth_m[rng.random(depth_m.shape) < 0.05] = rng.choice([np.inf, -np.inf])
        assert _any_valid(depth_m) == bool(np.isfinite(depth_m).any())
