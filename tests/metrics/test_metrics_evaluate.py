"""The four metrics on known geometry: a plate against the same plate shifted by a known offset."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bench.maroon.antennas import load_antenna_array
from methods.domain.capture import Capture, Mesh, Metadata, RadarGrid
from metrics.evaluate import METRIC_COLUMNS, evaluate, ground_truth

GRID = RadarGrid((-0.15, -0.15, 0.2), (0.15, 0.15, 0.4), (301, 301, 201))
PLATE_Z_M = 0.30


def _plate_capture(mask_erosion: int = 20, tilt: float = 0.0) -> Capture:
    """A 10 cm square plate at z = 0.30 m (+ tilt * y), mesh given in a rotated/shifted photogrammetry frame."""
    corners = np.array([[-0.05, -0.05], [0.05, -0.05], [0.05, 0.05], [-0.05, 0.05]])
    radar_vertices = np.column_stack([corners, PLATE_Z_M + tilt * corners[:, 1]])
    angle = np.deg2rad(30.0)
    rotation = np.array([[np.cos(angle), 0, np.sin(angle)], [0, 1, 0], [-np.sin(angle), 0, np.cos(angle)]])
    photo2radar = np.eye(4)
    photo2radar[:3, :3], photo2radar[:3, 3] = rotation, [0.1, -0.2, 0.5]
    photo_vertices = (radar_vertices - photo2radar[:3, 3]) @ rotation     # inverse map into the photo frame
    metadata = Metadata(distance_m=0.3, mask_erosion=mask_erosion, mask_bb_m={"zmin": 0.2, "zmax": 0.7},
                        calibration=None, labels=(), raw={})
    return Capture(root=Path("/nowhere"), object_name="plate", distance_cm=30, metadata=metadata,
                   transforms={"photogrammetry2radar": photo2radar}, antennas=load_antenna_array(), radar_frames=[0],
                   mesh=Mesh(vertices=photo_vertices, triangles=np.array([[0, 1, 2], [0, 2, 3]]), path=Path("m.obj")))


@pytest.fixture(scope="module")
def plate_gt():
    return ground_truth(_plate_capture(), GRID)


def test_ground_truth_depth_is_the_plate(plate_gt):
    covered = np.isfinite(plate_gt.depth_m)
    assert covered.sum() == 101 * 101
    np.testing.assert_allclose(plate_gt.depth_m[covered], PLATE_Z_M, atol=1e-6)


@pytest.mark.parametrize("offset_m", [0.0, 0.0005, 0.003, 0.008])
def test_shifted_plate_gives_the_offset_in_every_metric(plate_gt, offset_m):
    depth = plate_gt.depth_m + offset_m
    result = evaluate(depth, plate_gt)
    for name in ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm"):
        assert result[name] == pytest.approx(offset_m * 100, abs=1e-4), name


def test_projective_error_ignores_gt_holes_by_default_but_faithful_counts_them(plate_gt):
    depth = plate_gt.depth_m.copy()
    rows, cols = np.nonzero(np.isfinite(depth))
    depth[rows.min() - 3:rows.min(), cols.min():cols.max() + 1] = PLATE_Z_M   # 3 radar rows above the plate
    sound = evaluate(depth, plate_gt)
    faithful = evaluate(depth, plate_gt, faithful=True)
    assert sound["P_cm"] == pytest.approx(0.0, abs=1e-6)
    n_plate, n_extra = 101 * 101, 3 * 101
    assert sound["off_px"] == n_extra and sound["P_px"] == n_plate     # the false positives are reported
    assert sound["off_pct"] == pytest.approx(100 * n_extra / (n_plate + n_extra))
    # each extra radar pixel has no ground truth: the reference counts |1000 z - 0| mm = 30 cm
    assert faithful["P_cm"] == pytest.approx(30.0 * n_extra / (n_plate + n_extra), rel=0.02)


def test_eroded_error_drops_the_silhouette(plate_gt):
    depth = plate_gt.depth_m.copy()
    rows, cols = np.nonzero(np.isfinite(depth))
    depth[rows, cols.min()] += 0.005                  # a bad left edge column
    result = evaluate(depth, plate_gt)
    assert result["P_cm"] == pytest.approx(0.5 / 101, rel=1e-3)
    assert result["P_e_cm"] == pytest.approx(0.0, abs=1e-9)     # k = round(20 / 4) = 5 erodes the edge away


def test_no_valid_pixel_gives_nan_metrics(plate_gt):
    result = evaluate(np.full(GRID.image_shape, np.nan), plate_gt)
    assert all(np.isnan(result[name]) for name in METRIC_COLUMNS) and result["failure"] == "no valid pixel"


def test_tilted_plate_matches_its_own_ground_truth():
    gt = ground_truth(_plate_capture(tilt=0.3), GRID)
    assert evaluate(gt.depth_m, gt)["P_cm"] == pytest.approx(0.0, abs=1e-6)
    assert evaluate(gt.depth_m, gt)["C_s_cm"] == pytest.approx(0.0, abs=1e-6)


def test_off_object_pixels_show_their_share_and_distance(plate_gt):
    depth = plate_gt.depth_m.copy()
    rows, cols = np.nonzero(np.isfinite(depth))
    block = (slice(rows.max() + 11, rows.max() + 21), slice(cols.min(), cols.min() + 10))   # 1 cm below the plate
    depth[block] = PLATE_Z_M + 0.05                                                       # and 5 cm behind it
    result = evaluate(depth, plate_gt)
    assert result["off_px"] == 100 and result["failure"] == ""
    assert result["off_pct"] == pytest.approx(100 * 100 / (101 * 101 + 100))
    # nearest plate point: the plate's bottom edge row, 1.0-1.9 cm away in y and 5 cm in z
    assert 5.0 < result["off_err_cm"] < np.hypot(5.0, 2.0)
    assert result["P_cm"] == pytest.approx(0.0, abs=1e-9)                   # P alone would not see them


def test_a_wrapped_result_inside_the_box_is_scored_not_dropped(plate_gt):
    wrapped = plate_gt.depth_m + 0.136                     # the d05 alias, 13.6 cm behind the plate (< zmax 0.70)
    result = evaluate(wrapped, plate_gt)
    assert result["failure"] == "" and result["P_cm"] == pytest.approx(13.6, abs=1e-6)


def test_a_result_outside_the_box_is_a_named_failure_not_silent_nan(plate_gt):
    result = evaluate(plate_gt.depth_m + 0.45, plate_gt)    # beyond mask_bb zmax = 0.70
    assert np.isnan(result["P_cm"]) and result["failure"] == "no radar point inside mask_bb"
    assert result["outside_bb_px"] == 101 * 101


def test_eroded_error_of_a_speckled_result_uses_the_object_silhouette(plate_gt):
    rng = np.random.default_rng(7)
    depth = plate_gt.depth_m + 0.002
    depth[rng.random(depth.shape) < 0.3] = np.nan          # 30 % holes: the result's own mask erodes to almost nothing
    result = evaluate(depth, plate_gt)
    eroded_plate_px = (101 - 4) ** 2                        # k = 5 px: 2 pixels off each side
    assert result["P_e_px"] > 0.5 * eroded_plate_px and result["P_e_px"] < result["P_px"]
    assert result["P_e_cm"] == pytest.approx(0.2, abs=1e-6)
    assert plate_gt.eroded_silhouette.sum() == eroded_plate_px


def test_the_erosion_kernel_is_the_same_width_in_millimetres_on_every_grid():
    fine = ground_truth(_plate_capture(), GRID)
    coarse = ground_truth(_plate_capture(), RadarGrid((-0.15, -0.15, 0.2), (0.15, 0.15, 0.4), (151, 151, 11)))
    def width_mm(gt, pitch_mm):
        return (gt.silhouette.sum(axis=1).max() - gt.eroded_silhouette.sum(axis=1).max()) * pitch_mm

    assert width_mm(fine, 1.0) == pytest.approx(width_mm(coarse, 2.0), abs=2.0)   # 4 mm either way, +- a pixel


def test_coverage_is_the_share_of_the_silhouette_the_points_cover(plate_gt):
    depth = plate_gt.depth_m.copy()
    rows, cols = np.nonzero(np.isfinite(depth))
    depth[:, cols.min() + 51:] = np.nan                                   # the right 50 of 101 columns missing
    result = evaluate(depth, plate_gt)
    assert result["silhouette_px"] == 101 * 101
    assert result["coverage_pct"] == pytest.approx(100 * 51 / 101)
    assert evaluate(plate_gt.depth_m, plate_gt)["coverage_pct"] == pytest.approx(100.0)
    assert evaluate(plate_gt.depth_m + 0.45, plate_gt)["coverage_pct"] == 0.0   # all of it beyond mask_bb


def test_off_share_counts_the_points_outside_mask_bb_too(plate_gt):
    depth = plate_gt.depth_m.copy()
    rows, cols = np.nonzero(np.isfinite(depth))
    block = (slice(rows.max() + 11, rows.max() + 21), slice(cols.min(), cols.min() + 10))   # 1 cm below the plate
    depth[block] = 0.75                                                   # and beyond mask_bb zmax = 0.70
    result = evaluate(depth, plate_gt)
    assert result["outside_bb_px"] == 100 and result["off_px"] == 0
    assert result["off_pct"] == pytest.approx(100 * 100 / (101 * 101 + 100))
    assert evaluate(plate_gt.depth_m + 0.45, plate_gt)["off_pct"] == 100.0       # every point outside mask_bb
