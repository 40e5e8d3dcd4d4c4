"""Every method is scored on one metric grid: resampling a coarse depth map keeps planes exact, steps sharp and
footprints in place, so a coarse and a fine reconstruction of the same plate score alike."""
from __future__ import annotations

import numpy as np
import pytest
from test_metrics_evaluate import GRID, PLATE_Z_M, _plate_capture

from methods.domain.capture import RadarGrid
from metrics.evaluate import evaluate, ground_truth
from metrics.resample import resample_depth_m, resample_nearest

COARSE = RadarGrid((-0.15, -0.15, 0.2), (0.15, 0.15, 0.4), (51, 51, 21))       # bp_cpu: 6 mm pixels


def _sample(grid: RadarGrid, depth_of_xy):
    x_m, y_m = grid.pixel_xy_m()
    return depth_of_xy(x_m, y_m)


def test_a_tilted_plane_is_resampled_exactly_inside_its_footprint():
    plane = lambda x, y: np.where(np.hypot(x, y) < 0.08, 0.3 + 0.1 * x - 0.05 * y, np.nan)   # noqa: E731
    fine = resample_depth_m(_sample(COARSE, plane), COARSE, GRID)
    x_m, y_m = GRID.pixel_xy_m()
    interior = np.hypot(x_m, y_m) < 0.07
    np.testing.assert_allclose(fine[interior], (0.3 + 0.1 * x_m - 0.05 * y_m)[interior], atol=1e-12)
    # the footprint of the coarse disc is kept (nearest pixel at the rim), not shrunk by half a coarse pixel
    coarse_area_m2 = np.isfinite(_sample(COARSE, plane)).sum() * 0.006 ** 2
    assert np.isfinite(fine).sum() * 0.001 ** 2 == pytest.approx(coarse_area_m2, rel=0.05)


def test_a_depth_step_is_not_smeared_into_a_ramp():
    step = lambda x, y: np.where(x < 0.0, 0.30, 0.33)      # noqa: E731  3 cm step, beyond the 1 cm surface jump
    fine = resample_depth_m(_sample(COARSE, step), COARSE, GRID)
    assert set(np.unique(np.round(fine, 6))) == {0.30, 0.33}


def test_same_grid_is_the_identity_and_outside_is_invalid():
    depth = np.random.default_rng(1).uniform(0.2, 0.4, GRID.image_shape)
    np.testing.assert_array_equal(resample_depth_m(depth, GRID, GRID), depth)
    half = RadarGrid((-0.05, -0.05, 0.2), (0.05, 0.05, 0.4), (11, 11, 3))
    out = resample_depth_m(np.full(half.image_shape, 0.3), half, GRID)
    x_m, y_m = GRID.pixel_xy_m()
    assert np.isnan(out[(np.abs(x_m) > 0.056) | (np.abs(y_m) > 0.056)]).all()
    assert np.isfinite(out[(np.abs(x_m) < 0.054) & (np.abs(y_m) < 0.054)]).all()
    assert resample_nearest(np.ones(half.image_shape), half, GRID)[150, 150] == 1.0


def test_a_coarse_and_a_fine_plate_give_comparable_chamfer_distances():
    gt = ground_truth(_plate_capture(), GRID)
    plate = lambda x, y: np.where((np.abs(x) <= 0.05) & (np.abs(y) <= 0.05), PLATE_Z_M + 0.002, np.nan)   # noqa: E731
    fine_scores = evaluate(_sample(GRID, plate), gt)
    coarse_scores = evaluate(resample_depth_m(_sample(COARSE, plate), COARSE, GRID), gt)
    assert fine_scores["C_g_cm"] == pytest.approx(0.2, abs=2e-3)
    # scored natively against the same GT points, the 6 mm grid's C_g is 0.31 cm (GT up to 4 mm off a radar point)
    for name in ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm"):
        assert coarse_scores[name] == pytest.approx(fine_scores[name], abs=0.03), name
