"""The faithful profile's metrics pinned to numbers derived by hand from the reference's definitions
(MAROON_FORMAT.md 2.4, 4.2, 5.2-5.5; never from the reference's code), one test per quirk, on an 11 x 11 pixel
grid of 1 mm where every number can be followed on paper.

On this grid MAROON's K maps pixel centre x_j = -5 mm + j mm to u = (j + 0.5) * 10 / 11, so floor(u) = j for
j <= 4 and j - 1 for j >= 6 (the same for rows); it samples the ground truth of pixel (v, u) at
x = bx + (u + 0.5) (Bx - bx) / 10 with bx = -5.5 mm, Bx = +5.5 mm (hence "shifted": -4.95 mm at u = 0, +6.05 mm
at u = 10).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.distance import cdist

from bench.maroon.antennas import load_antenna_array
from bench.maroon.reader import read_metadata
from methods.domain.capture import Capture, Mesh, Metadata, RadarGrid
from methods.domain.lattice import triangulated_vertices
from metrics.evaluate import evaluate, ground_truth
from metrics.masks import reference_mask_bb_m

N = 11
PITCH_M = 0.001
GRID = RadarGrid((-0.005, -0.005, 0.2), (0.005, 0.005, 0.4), (N, N, 201))
PLATE_Z_M = 0.30


def _spec_sample_x_m(index: np.ndarray) -> np.ndarray:
    """MAROON's sample position of pixel column `index` (MAROON_FORMAT.md 2.4 and 4.2), metres."""
    half = PITCH_M / 2
    lo, hi = -0.005 - half, 0.005 + half
    return lo + (index + 0.5) * (hi - lo) / (N - 1)


def _capture(vertices_m: np.ndarray, triangles, mask_bb_m=None, mask_erosion: int = 0, raw=None) -> Capture:
    metadata = Metadata(distance_m=0.3, mask_erosion=mask_erosion,
                        mask_bb_m=mask_bb_m or {"zmin": 0.2, "zmax": 0.7}, calibration=None, labels=(),
                        raw=raw or {})
    return Capture(root=Path("/nowhere"), object_name="plate", distance_cm=30, metadata=metadata,
                   transforms={"photogrammetry2radar": np.eye(4)}, antennas=load_antenna_array(), radar_frames=[0],
                   mesh=Mesh(vertices=np.asarray(vertices_m, float), triangles=np.asarray(triangles), path=Path("m")))


def _plane(slope_x: float = 0.0, z0_m: float = PLATE_Z_M, half_m: float = 0.02, **kwargs) -> Capture:
    """A plane z = z0 + slope_x * x covering the whole grid (and beyond)."""
    corners = np.array([[-half_m, -half_m], [half_m, -half_m], [half_m, half_m], [-half_m, half_m]])
    vertices = np.column_stack([corners, z0_m + slope_x * corners[:, 0]])
    return _capture(vertices, [[0, 1, 2], [0, 2, 3]], **kwargs)


def _block(rows: slice, cols: slice, depth_m) -> np.ndarray:
    depth = np.full((N, N), np.nan)
    depth[rows, cols] = depth_m
    return depth


# ---------------------------------------------------------------------------------- GT sampling positions
def test_reference_ground_truth_is_sampled_at_the_shifted_positions():
    gt = ground_truth(_plane(slope_x=0.5), GRID)
    expected_row = PLATE_Z_M + 0.5 * _spec_sample_x_m(np.arange(N))
    np.testing.assert_allclose(gt.reference.depth_m, np.tile(expected_row, (N, 1)), atol=3e-7)   # float32 rays
    # the sound ground truth stays at the pixel centres; at u = 10 MAROON samples 6.05 mm instead of 5 mm
    assert gt.depth_m[0, 10] == pytest.approx(PLATE_Z_M + 0.5 * 0.005, abs=3e-7)   # float32 rays, as above
    assert gt.reference.depth_m[0, 10] - gt.depth_m[0, 10] == pytest.approx(0.5 * 0.00105, abs=3e-7)


def test_faithful_chamfer_uses_the_shifted_ground_truth_points():
    gt = ground_truth(_plane(slope_x=0.5), GRID)
    xs = -0.005 + PITCH_M * np.arange(N)
    radar = np.tile(PLATE_Z_M + 0.5 * xs, (N, 1))            # the plane, exactly, at the pixel centres
    u = np.arange(N)
    gx, gy = np.meshgrid(_spec_sample_x_m(u), -_spec_sample_x_m(u))   # rows run along -y, same formula
    gt_points = np.column_stack([gx.ravel(), gy.ravel(), (PLATE_Z_M + 0.5 * gx).ravel()])
    rx, ry = np.meshgrid(xs, xs[::-1])
    radar_points = np.column_stack([rx.ravel(), ry.ravel(), radar.ravel()])
    distances = cdist(radar_points, gt_points)
    faithful = evaluate(radar, gt, faithful=True)
    # Open3D casts the rays in float32: 0.1 um
    assert faithful["C_s_cm"] == pytest.approx(100 * distances.min(axis=1).mean(), abs=1e-5)
    assert faithful["C_g_cm"] == pytest.approx(100 * distances.min(axis=0).mean(), abs=1e-5)
    assert faithful["C_s_px"] == N * N and faithful["C_g_px"] == N * N
    assert evaluate(radar, gt)["C_s_cm"] == pytest.approx(0.0, abs=1e-5)    # sound: the same points exactly
    assert faithful["C_s_cm"] > 0.01


# ---------------------------------------------------------------------------------- projective conditions
def test_faithful_p_counts_a_point_only_where_the_radar_mask_is_set_at_its_destination():
    gt = ground_truth(_plane(), GRID)
    rows = cols = np.arange(6, 10)
    depth_m = PLATE_Z_M + 0.001 * (rows[:, None] + 10 * cols[None, :])       # every pixel its own error
    radar = _block(slice(6, 10), slice(6, 10), depth_m)
    result = evaluate(radar, gt, faithful=True)
    # pixel (i, j) with i, j >= 6 lands on (i - 1, j - 1): inside the radar's mask only for i, j in 7..9
    counted = depth_m[1:, 1:]
    assert result["P_px"] == 9
    assert result["P_cm"] == pytest.approx(100 * np.mean(counted - PLATE_Z_M), rel=1e-9)


def test_faithful_p_counts_ground_truth_holes_with_the_full_depth():
    # ground truth on x < -0.4 mm: MAROON samples columns 0..4 there (column 4 at -0.55 mm, column 5 at +0.55 mm)
    plate = _capture(np.array([[-0.02, -0.02, PLATE_Z_M], [-0.0004, -0.02, PLATE_Z_M], [-0.0004, 0.02, PLATE_Z_M],
                               [-0.02, 0.02, PLATE_Z_M]]), [[0, 1, 2], [0, 2, 3]])
    gt = ground_truth(plate, GRID)
    assert np.isfinite(gt.reference.depth_m[:, :5]).all() and np.isnan(gt.reference.depth_m[:, 5:]).all()
    radar = _block(slice(0, N), slice(2, 5), PLATE_Z_M + 0.002)             # 11 x 3 on the plate: error 2 mm
    radar[:, 6:8] = PLATE_Z_M                                                 # off the plate, column 5 empty
    result = evaluate(radar, gt, faithful=True)
    # columns 2..4 land on themselves (33 points, 2 mm); column 7 lands on GT column 6, a hole: |1000 z - 0| =
    # 300 mm each (11 points); column 6 lands on column 5, where the radar has no depth: not counted
    assert result["P_px"] == 44
    assert result["P_cm"] == pytest.approx((33 * 0.2 + 11 * 30.0) / 44, rel=1e-9)
    assert evaluate(radar, gt)["P_cm"] == pytest.approx(0.2, rel=1e-6)      # sound: holes are not compared


def test_faithful_p_e_erodes_the_radar_mask_not_the_silhouette():
    gt = ground_truth(_plane(mask_erosion=12), GRID)                       # radar kernel round(12 / 4) = 3
    radar = _block(slice(1, 10), slice(1, 10), PLATE_Z_M + 0.001)           # 9 x 9, rows/cols 1..9
    radar[2:9, 2:9] += 0.001                                                # its 7 x 7 interior 1 mm farther
    faithful, sound = evaluate(radar, gt, faithful=True), evaluate(radar, gt)
    # P: all 81 points; each lands on a pixel of the block (rows/cols 1..8), where the radar mask is set
    assert faithful["P_px"] == 81
    assert faithful["P_cm"] == pytest.approx((49 * 0.2 + 32 * 0.1) / 81, rel=1e-9)
    # P_e: the 3 x 3 erosion keeps the 7 x 7 interior (49 > 10 pixels: no retry); its points land on rows/cols
    # 2..7, inside the eroded mask
    assert faithful["P_e_px"] == 49
    assert faithful["P_e_cm"] == pytest.approx(0.2, rel=1e-9)
    # the sound P_e erodes the object's silhouette (here the whole image), so every point stays
    assert sound["P_e_px"] == 81


# ---------------------------------------------------------------------------------- quad triangulation
def test_three_valid_quads_follow_the_image_corner_in_the_faithful_rule():
    depth = _block(slice(4, 6), slice(4, 6), PLATE_Z_M)
    for missing, survives_faithful in (((4, 4), True), ((4, 5), False), ((5, 4), False), ((5, 5), False)):
        quad = depth.copy()
        quad[missing] = np.nan                    # image pixel (0, 0) is invalid: MAROON takes p00 as missing
        sound, faithful = (triangulated_vertices(quad, 0.01, rule) for rule in ("sound", "maroon"))
        assert sound.sum() == 3, missing
        assert faithful.sum() == (3 if survives_faithful else 0), missing
    # with the image's (0, 0) valid and (0, 1) invalid, MAROON takes p01 as the missing corner everywhere
    quad = depth.copy()
    quad[0, 0] = PLATE_Z_M
    quad[4, 5] = np.nan
    assert triangulated_vertices(quad, 0.01, "maroon").sum() == 3
    quad[4, 5], quad[4, 4] = PLATE_Z_M, np.nan
    assert triangulated_vertices(quad, 0.01, "maroon").sum() == 0


def test_three_valid_quad_rule_changes_the_faithful_point_count():
    gt = ground_truth(_plane(), GRID)
    radar = _block(slice(3, 8), slice(3, 8), PLATE_Z_M)                     # 5 x 5: every pixel in a full quad
    radar[8, 1] = radar[8, 2] = radar[9, 1] = PLATE_Z_M                      # an L whose quad misses p11
    radar[8, 9] = radar[9, 8] = radar[9, 9] = PLATE_Z_M                      # an L whose quad misses p00
    sound, faithful = evaluate(radar, gt), evaluate(radar, gt, faithful=True)
    assert sound["C_s_px"] == 25 + 3 + 3
    assert faithful["C_s_px"] == 25 + 3                                      # image pixel (0, 0) is invalid


# ---------------------------------------------------------------------------------- legacy metadata
def test_legacy_threshold_wins_only_in_the_faithful_profile(tmp_path):
    capture_dir = tmp_path / "01_plate" / "30"
    capture_dir.mkdir(parents=True)
    (capture_dir / "metadata.json").write_text(json.dumps(
        {"distance_meters": 0.3, "mask_erosion": 0, "mask_bb": {"zmax": 0.5}, "mask_3d_threshold": 0.305}))
    metadata = read_metadata(capture_dir)
    assert metadata.mask_bb_m["zmax"] == 0.5
    assert reference_mask_bb_m(metadata)["zmax"] == 0.305
    gt = ground_truth(_plane(mask_bb_m=dict(metadata.mask_bb_m), raw=metadata.raw), GRID)
    radar = _block(slice(0, N), slice(0, N), PLATE_Z_M)
    radar[:, 6:] = 0.31                                       # beyond the legacy threshold, before zmax
    sound, faithful = evaluate(radar, gt), evaluate(radar, gt, faithful=True)
    assert sound["C_s_px"] == N * N
    assert faithful["C_s_px"] == N * 6                        # columns 6..10 are outside the reference's box
