"""MM-3FSK (methods/mm3fsk.py) on a plate seen by a depth camera with a calibration error: it succeeds where
MM-2FSK d10 wraps, up to the coarse pair's unambiguous range, and fails beyond it.

Scene: the plate of tests/methods/test_methods_fsk.py at 0.30 m; the depth frame is rendered with the true camera pose,
the capture's realsense2radar is off by `error_m` along z (a calibration error), so the prior is off by it too."""
from __future__ import annotations

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
from methods.ops.frequencies import config_indices, max_unambiguous_depth_m

from devices import CUDA

PLATE_Z_M = 0.30
GRID = square_grid(0.01, 21)


@pytest.fixture(scope="module")
def plate_signal():
    points_m = plate_points_m(PLATE_Z_M)
    return simulate(points_m, np.ones(len(points_m)), TABLE1_FREQS_HZ)


def _miscalibrated(signal, error_m: float):
    cam2radar = realsense2radar()
    wrong = cam2radar.copy()
    wrong[2, 3] += error_m
    return make_capture(signal, TABLE1_FREQS_HZ, GRID, realsense=plane_depth_frame(PLATE_Z_M, 0.0, 0.0, cam2radar),
                        transforms={"realsense2radar": wrong})


def _coarse_range_m(config: str) -> float:
    f_lo, f_mid, f_hi = TABLE1_FREQS_HZ[config_indices(TABLE1_FREQS_HZ, config)]
    return max_unambiguous_depth_m(min(f_mid - f_lo, f_hi - f_mid))


@pytest.mark.parametrize("config, error_m", [("d05_d10", 0.02), ("d05_d10", -0.05), ("d05_d10", 0.12),
                                             ("d1_d10", 0.06), ("d2_d10", -0.03)])
def test_mm3fsk_succeeds_where_mm2fsk_d10_wraps(plate_signal, config, error_m):
    capture = _miscalibrated(plate_signal, error_m)
    assert abs(error_m) < _coarse_range_m(config)
    fine_range_m = max_unambiguous_depth_m(10e9)                        # 0.75 cm: d10's
    mm2 = reconstruct(capture, "mm2fsk", "d10", prior="realsense")
    assert np.nanmedian(np.abs(mm2.extra["prior_depth_m"] - PLATE_Z_M)) == pytest.approx(abs(error_m), rel=0.05)
    assert np.nanmedian(np.abs(mm2.depth_m - PLATE_Z_M)) > fine_range_m  # wrapped: whole periods away
    mm3 = reconstruct(capture, "mm3fsk", config, prior="realsense")
    assert mm3.valid.sum() > 0.9 * mm3.valid.size
    assert np.nanmax(np.abs(mm3.depth_m - PLATE_Z_M)) < 0.5e-3        # d10's precision


@pytest.mark.parametrize("config, error_m", [("d05_d10", 0.16), ("d2_d10", 0.05)])
def test_mm3fsk_wraps_beyond_the_coarse_pairs_range(plate_signal, config, error_m):
    assert abs(error_m) > _coarse_range_m(config)
    mm3 = reconstruct(_miscalibrated(plate_signal, error_m), "mm3fsk", config, prior="realsense")
    assert np.nanmedian(np.abs(mm3.depth_m - PLATE_Z_M)) > max_unambiguous_depth_m(10e9)


@pytest.mark.parametrize("device", ["cpu", CUDA])
def test_mm3fsk_noisy_coarse_corrections_do_not_reach_the_fine_step(plate_signal, device):
    # at 0 dB SNR each pixel's 0.55 GHz correction is off by millimetres to centimetres; the one median offset is
    # not (measured: offset -4.70 cm for a -5 cm error, every depth within 0.8 mm). On CUDA the whole call runs as
    # one frame graph (prior, both passes, the median on the device: methods.backends.warp.frame_graph)
    from bench.synth.memory import add_noise
    mm3 = reconstruct(_miscalibrated(add_noise(plate_signal, 0.0), -0.05), "mm3fsk", "d05_d10", prior="realsense",
                      device=device)
    assert mm3.extra["prior_offset_m"] == pytest.approx(-0.05, abs=5e-3)
    assert np.nanmax(np.abs(mm3.depth_m - PLATE_Z_M)) < 1.5e-3 and mm3.valid.sum() > 0.9 * mm3.valid.size
