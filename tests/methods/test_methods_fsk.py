"""2FSK, 3FSK and MM-2FSK on a flat plate: accuracy at high SNR and the unambiguous-range behaviour.

Scene: a 6 x 6 cm plate of point scatterers (1 mm spacing) facing the array at 0.30 m; pixels are evaluated
over the central 2 x 2 cm (1 mm pixels), away from the plate edges. Priors start 10 cm away (0.40 m), as in
the paper.
"""
from __future__ import annotations

import numpy as np
import pytest

from bench.synth.memory import ANTENNAS, TABLE1_FREQS_HZ, add_noise, make_capture, plate_points_m, simulate, square_grid
from methods import reconstruct
from methods.mm2fsk import reconstruct_mm2fsk
from methods.ops.frequencies import config_indices, max_unambiguous_depth_m

PLATE_Z_M = 0.30
GRID = square_grid(0.01, 21)


def plate_signal(freqs_hz, z_m=PLATE_Z_M, snr_db=None):
    points_m = plate_points_m(z_m)
    signal = simulate(points_m, np.ones(len(points_m)), freqs_hz)
    return signal if snr_db is None else add_noise(signal, snr_db)


@pytest.fixture(scope="module")
def plate():
    return make_capture(plate_signal(TABLE1_FREQS_HZ), TABLE1_FREQS_HZ, GRID)


def abs_error_m(rec, z_m=PLATE_Z_M):
    assert rec.valid.all()                     # a uniform plate: every pixel passes the -14 dB filter
    return np.abs(rec.depth_m - z_m)


def dd_max_m(config):
    f_lo, f_hi = TABLE1_FREQS_HZ[config_indices(TABLE1_FREQS_HZ, config)[[0, -1]]]
    return max_unambiguous_depth_m(f_hi - f_lo)


def test_2fsk_from_040_succeeds_at_d05_within_1mm(plate):
    assert dd_max_m("d05") > 0.10                           # 13.6 cm covers the 10 cm prior error
    rec = reconstruct(plate, "2fsk", "d05")
    assert abs_error_m(rec).max() < 1e-3                    # measured 0.6 mm
    assert abs(rec.extra["z1_m"] - PLATE_Z_M) < 5e-3        # pass 1 lands near the plate (measured +2 mm)


@pytest.mark.parametrize("config", ["d1", "d2", "d4", "d8", "d10"])
def test_2fsk_from_040_fails_beyond_its_unambiguous_range(plate, config):
    assert dd_max_m(config) < 0.10                          # 7.3 cm and less: the phase wraps
    assert np.median(abs_error_m(reconstruct(plate, "2fsk", config))) > 0.02   # measured 7.6-15 cm


def test_3fsk_d05_d10_succeeds_where_2fsk_d10_fails(plate):
    assert np.median(abs_error_m(reconstruct(plate, "2fsk", "d10"))) > 0.02
    rec = reconstruct(plate, "3fsk", "d05_d10")
    assert abs_error_m(rec).max() < 0.2e-3                  # measured 0.07 mm
    assert rec.extra["coarse_pair_hz"] == pytest.approx((81.45e9, 82e9), abs=0.01e9)


@pytest.mark.parametrize("config", ["d1_d10", "d2_d10"])
def test_3fsk_fails_when_its_coarse_pair_cannot_cover_the_prior_error(plate, config):
    assert np.median(abs_error_m(reconstruct(plate, "3fsk", config))) > 0.02    # paper Table III


def test_3fsk_fine_step_is_much_more_precise_than_2fsk_under_noise():
    capture = make_capture(plate_signal(TABLE1_FREQS_HZ, snr_db=10), TABLE1_FREQS_HZ, GRID)
    rms_2fsk = np.sqrt(np.mean(abs_error_m(reconstruct(capture, "2fsk", "d05")) ** 2))
    rms_3fsk = np.sqrt(np.mean(abs_error_m(reconstruct(capture, "3fsk", "d05_d10")) ** 2))
    assert rms_3fsk < rms_2fsk / 5                          # measured 0.14 mm vs 2.2 mm (ratio ~ 10 GHz / 0.55 GHz)


@pytest.mark.parametrize("config, offset_m, converges", [
    ("d2", +0.025, True), ("d2", -0.025, True), ("d2", +0.05, False), ("d2", -0.05, False),
    ("d10", +0.005, True), ("d10", -0.005, True), ("d10", +0.01, False), ("d10", -0.01, False),
])
def test_mm2fsk_converges_within_dd_max_and_fails_beyond(plate, config, offset_m, converges):
    indices = config_indices(TABLE1_FREQS_HZ, config)
    prior_m = np.full(GRID.image_shape, PLATE_Z_M + offset_m)
    rec = reconstruct_mm2fsk(plate.radar.signal[:, :, indices], TABLE1_FREQS_HZ[indices], ANTENNAS, GRID, prior_m)
    error_m = abs_error_m(rec)
    assert (abs(offset_m) < dd_max_m(config)) == converges
    if converges:   # near-field bias ~4.5% of the prior offset (round trip < 2 x depth change off-axis)
        assert error_m.max() < 0.06 * abs(offset_m) + 0.5e-3
    else:           # lands a whole number of ambiguity periods 2 dd_max away
        assert np.median(error_m) > dd_max_m(config)


@pytest.mark.parametrize("method, config", [("mm2fsk", "d05"), ("mm2fsk", "d10"), ("2fsk", "d05")])
def test_phase_sign_target_beyond_the_prior_comes_out_beyond_it(method, config):
    # a prior in front of the plate (well within the unambiguous range) must be corrected away from the array,
    # one behind it towards the array; a flipped phase sign would move both the wrong way
    plate_310 = make_capture(plate_signal(TABLE1_FREQS_HZ, z_m=0.31), TABLE1_FREQS_HZ, GRID)
    indices = config_indices(TABLE1_FREQS_HZ, config)
    offset_m = min(dd_max_m(config) / 2, 0.01)
    for prior in (0.31 - offset_m, 0.31 + offset_m):
        if method == "mm2fsk":
            rec = reconstruct_mm2fsk(plate_310.radar.signal[:, :, indices], TABLE1_FREQS_HZ[indices], ANTENNAS,
                                     GRID, np.full(GRID.image_shape, prior))
        else:
            rec = reconstruct(plate_310, method, config, prior=prior)
        assert np.sign(np.median(rec.depth_m) - prior) == np.sign(0.31 - prior)
        assert abs_error_m(rec, 0.31).max() < 0.06 * offset_m + 0.5e-3


def test_mm2fsk_correlates_only_pixels_with_a_prior(plate):
    indices = config_indices(TABLE1_FREQS_HZ, "d10")
    prior_m = np.full(GRID.image_shape, PLATE_Z_M + 0.002)
    prior_m[:, :5] = np.nan
    rec = reconstruct_mm2fsk(plate.radar.signal[:, :, indices], TABLE1_FREQS_HZ[indices], ANTENNAS, GRID, prior_m)
    assert rec.extra["prior_pixels"] == 21 * 16
    assert np.isnan(rec.depth_m[:, :5]).all() and np.isnan(rec.magnitude[:, :5]).all()
    assert np.abs(rec.depth_m[:, 5:] - PLATE_Z_M).max() < 0.5e-3
