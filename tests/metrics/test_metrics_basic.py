"""Metrics on analytic geometry: Chamfer between shifted planes, mask_bb bounds, erosion of known masks."""
from __future__ import annotations

import numpy as np
import pytest

from metrics.chamfer import PointSet, nearest_distances_m, one_sided_chamfer_m
from metrics.masks import erode_mask, inside_mask_bb, radar_erosion_kernel_px


def _plane_points(z_m: float, spacing_m: float = 1e-3, half_m: float = 0.05) -> np.ndarray:
    axis = np.arange(-half_m, half_m + spacing_m / 2, spacing_m)
    x, y = np.meshgrid(axis, axis)
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z_m)])


@pytest.mark.parametrize("offset_m", [0.0, 0.0007, 0.004, 0.02])
def test_chamfer_of_shifted_plane_is_the_offset(offset_m):
    gt = PointSet(_plane_points(0.30))
    shifted = _plane_points(0.30 + offset_m)
    assert one_sided_chamfer_m(shifted, gt) == pytest.approx(offset_m, abs=1e-12)


def test_chamfer_is_one_sided():
    small = _plane_points(0.30, half_m=0.01)
    large = _plane_points(0.30, half_m=0.05)
    assert one_sided_chamfer_m(small, PointSet(large)) == pytest.approx(0.0, abs=1e-12)
    assert one_sided_chamfer_m(large, PointSet(small)) > 0.01


def test_kd_tree_matches_brute_force_on_random_points():
    rng = np.random.default_rng()
    src, dst = rng.uniform(-0.1, 0.1, (500, 3)), rng.uniform(-0.1, 0.1, (700, 3))
    brute = np.min(np.linalg.norm(src[:, None, :] - dst[None, :, :], axis=2), axis=1)
    np.testing.assert_allclose(nearest_distances_m(src, PointSet(dst)), brute, rtol=1e-12)


def test_empty_sets_give_nan_not_a_number_that_looks_valid():
    assert np.isnan(one_sided_chamfer_m(np.zeros((0, 3)), PointSet(_plane_points(0.3))))


def test_mask_bb_is_inclusive_and_only_uses_present_bounds():
    points = np.array([[0, 0, 0.26], [0, 0, 0.2599], [5, -5, 0.7], [0, 0, 0.7001]])
    np.testing.assert_array_equal(inside_mask_bb(points, {"zmin": 0.26, "zmax": 0.7}), [True, False, True, False])


@pytest.mark.parametrize(("erosion", "kernel"), [(10, 2), (20, 5), (30, 8), (2, 0), (6, 2)])
def test_radar_kernel_uses_bankers_rounding(erosion, kernel):
    assert radar_erosion_kernel_px(erosion) == kernel


@pytest.mark.parametrize(("kernel", "kept_side"), [(5, 16), (3, 18), (4, 17), (1, 20)])
def test_erosion_of_a_square_removes_the_known_border(kernel, kept_side):
    mask = np.zeros((40, 40), dtype=bool)
    mask[10:30, 10:30] = True
    eroded = erode_mask(mask, kernel)
    assert eroded.sum() == kept_side ** 2
    assert eroded[10:30, 10:30].sum() == kept_side ** 2      # only pixels of the square remain


def test_erosion_shrinks_kernel_instead_of_emptying_a_small_mask():
    mask = np.zeros((20, 20), dtype=bool)
    mask[5:10, 5:10] = True                                  # 25 px: k = 5 leaves 1 px, k = 3 leaves 9, k = 2 16
    assert erode_mask(mask, 5).sum() == 16
    full = np.ones((8, 8), dtype=bool)                       # no background pixel: nothing to erode
    assert erode_mask(full, 5).sum() == 64
