"""Back-projection: point target and plate positions, BP_max, the parabola refinement, and the prior band."""
from __future__ import annotations

import numpy as np
import pytest
from precision import parabola_depth_bound_m

from bench.synth.memory import MAROON_FREQS_HZ, TABLE1_FREQS_HZ, make_capture, plate_points_m, simulate
from methods import reconstruct
from methods.bp import peak_depth_m
from methods.domain.capture import RadarGrid

TARGET_M = np.array([0.012, 0.020, 0.311])          # +x, +y, between two z samples
GRID = RadarGrid((-0.03, -0.03, 0.26), (0.03, 0.03, 0.36), (31, 31, 51))     # 2 mm pixels and z steps
TARGET_PIXEL = (5, 21)                              # row 0 = +0.03 m: row 5 = +0.02 m; column 21 = +0.012 m


@pytest.fixture(scope="module")
def point_capture():
    return make_capture(simulate(TARGET_M[None], np.ones(1), TABLE1_FREQS_HZ), TABLE1_FREQS_HZ, GRID)


def peak_pixel(rec):
    return np.unravel_index(np.nanargmax(rec.magnitude), rec.magnitude.shape)


@pytest.mark.parametrize("config", ["d05", "d10", "d05_d10"])
def test_point_target_at_its_pixel_and_depth(point_capture, config):
    rec = reconstruct(point_capture, "bp", config)
    assert peak_pixel(rec) == TARGET_PIXEL
    assert rec.depth_m[TARGET_PIXEL] == pytest.approx(TARGET_M[2], abs=0.5e-3)   # measured < 0.1 mm
    assert rec.valid.sum() < 100                    # the -14 dB filter keeps only the focal spot


def test_bp_max_point_target_and_plate():
    # all 128 frequencies; small grids around the targets keep the 128-frequency sums cheap on the CPU
    point = make_capture(simulate(TARGET_M[None], np.ones(1), MAROON_FREQS_HZ), MAROON_FREQS_HZ,
                         RadarGrid((0.006, 0.014, 0.29), (0.018, 0.026, 0.33), (7, 7, 21)))
    rec = reconstruct(point, "bp", "full")
    assert len(rec.freqs_hz) == 128 and peak_pixel(rec) == (3, 3)
    assert rec.depth_m[3, 3] == pytest.approx(TARGET_M[2], abs=0.2e-3)
    # Two-frequency BP has no range resolution (c / 2 delta_f = 27 cm at d05); on an extended plate its
    # maximum lies off the plate (paper Table III, BP d05 vs BP_max). The full band resolves the plate; its peak
    # sits slightly in front of an extended plate (measured 0.5 / 1.1 / 1.6 mm for 2 / 4 / 8 cm plates).
    points_m = plate_points_m(0.30, half_size_m=0.01)
    plate = make_capture(simulate(points_m, np.ones(len(points_m)), MAROON_FREQS_HZ), MAROON_FREQS_HZ,
                         RadarGrid((-0.002, -0.002, 0.27), (0.002, 0.002, 0.33), (3, 3, 31)))
    rec = reconstruct(plate, "bp", "full")
    assert rec.valid.all()
    assert np.abs(rec.depth_m - 0.30).max() < 1e-3


def test_parabola_on_db_values_with_clipped_ends_and_flat_guard():
    z_first_m, dz_m = 0.25, 0.002
    k = np.arange(10.0)
    true_peak = 4.3
    db = -((k - true_peak) ** 2)                                  # a parabola in dB: exact refinement
    magnitude = 10 ** (db / 20)
    profiles = np.stack([magnitude, magnitude[::-1], np.ones(10), 10 ** (-k / 20)], axis=1)   # (10, 4)
    depth_m, peak = peak_depth_m(profiles, z_first_m, dz_m)
    assert depth_m[0] == pytest.approx(z_first_m + true_peak * dz_m, abs=1e-12)
    assert depth_m[1] == pytest.approx(z_first_m + (9 - true_peak) * dz_m, abs=1e-12)
    assert depth_m[2] == z_first_m                                 # flat: argmax 0, no offset, no NaN
    assert depth_m[3] == pytest.approx(z_first_m - dz_m / 2)       # maximum at the first sample: -dz/2
    assert peak.tolist() == pytest.approx([profiles.max(axis=0)][0].tolist())


def test_search_band_around_a_scalar_or_per_pixel_prior_finds_the_same_depth(point_capture):
    full = reconstruct(point_capture, "bp", "d05")
    banded = reconstruct(point_capture, "bp", "d05", prior=0.32, band_m=0.02)
    # the band evaluates fewer depths per pixel, so float32 sums in another order: the parabola's bound, not 1e-6 m
    bound_m = parabola_depth_bound_m(point_capture.radar.signal[:, :, [5, 6]], TABLE1_FREQS_HZ[[5, 6]], GRID)
    assert banded.depth_m[TARGET_PIXEL] == pytest.approx(full.depth_m[TARGET_PIXEL], abs=bound_m[TARGET_PIXEL])
    prior_m = np.full(GRID.image_shape, np.nan)
    prior_m[2:9, 18:25] = 0.305                                    # a per-pixel prior around the target only
    per_pixel = reconstruct_with_prior_image(point_capture, prior_m)
    assert np.isnan(per_pixel.depth_m[~np.isfinite(prior_m)]).all()
    assert peak_pixel(per_pixel) == TARGET_PIXEL
    assert per_pixel.depth_m[TARGET_PIXEL] == pytest.approx(TARGET_M[2], abs=0.5e-3)
    with pytest.raises(ValueError, match="no z sample"):
        reconstruct(point_capture, "bp", "d05", prior=0.5, band_m=0.01)


def reconstruct_with_prior_image(capture, prior_m):
    from methods.bp import reconstruct_bp
    signal = capture.radar.signal[:, :, [5, 6]]                    # d05 of TABLE1_FREQS_HZ
    return reconstruct_bp(signal, TABLE1_FREQS_HZ[[5, 6]], capture.antennas, GRID, prior_m=prior_m, band_m=0.02)
