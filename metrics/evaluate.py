"""The paper's four metrics for one reconstruction against the capture's ground truth (MAROON_FORMAT.md 5).

Sound definitions (the default):
* radar points: pixels with a valid depth that are vertices of the grid triangulation (threshold 1 cm) and lie
  inside `mask_bb`, at the exact pixel-centre coordinates `(grid_x[j], grid_y[ny-1-i], depth)`;
* ground truth: the mesh in radar space rasterised onto the same pixel centres (nearest surface), triangulated the
  same way and restricted to `mask_bb`;
* C_s = Chamfer(radar -> GT), C_g = Chamfer(GT -> radar) with KD-trees;
* P = mean |D_radar - D_gt| over radar points whose pixel has ground truth (GT holes are not errors);
* P_e = P with the radar mask eroded by round(mask_erosion / 4) pixels (after triangulation).
`faithful=True` reproduces the reference code instead: GT sampled at MAROON's half-voxel-shifted positions,
radar points mapped to GT pixels by `floor(K p)` (two columns share a GT column), GT holes counted as errors of
1000 z mm, points projecting outside the image counted as 0 error, three-valid quads not triangulated.
All values in centimetres; NaN (never a made-up number) when no point is left to compare.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bench.alignment import apply_transform
from bench.capture import Capture, RadarGrid
from metrics.chamfer import PointSet, one_sided_chamfer_m
from metrics.groundtruth import rasterise_depth_m
from metrics.masks import erode_mask, inside_mask_bb, radar_erosion_kernel_px
from metrics.triangulation import triangulated_vertices

TRIANGULATION_THRESHOLD_M = 0.01
METRIC_COLUMNS = ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm")


@dataclass
class GroundTruth:
    """Ground truth of one capture on one pixel grid; build once, evaluate every method against it."""

    grid: RadarGrid
    depth_m: np.ndarray          # (ny, nx) at the pixel centres, NaN = no surface
    points: PointSet             # triangulated GT points inside mask_bb, metres
    mask_bb_m: dict[str, float]
    mask_erosion: int
    faithful_depth_m: np.ndarray  # (ny, nx) at MAROON's sample positions K^-1 (u + 0.5, v + 0.5)


def _pixel_points_m(grid: RadarGrid, depth_m: np.ndarray, x_m: np.ndarray | None = None,
                    y_m: np.ndarray | None = None) -> np.ndarray:
    if x_m is None:
        x_m, y_m = grid.pixel_xy_m()
    return np.stack([x_m, y_m, depth_m], axis=-1)


def _maroon_sample_xy_m(grid: RadarGrid) -> tuple[np.ndarray, np.ndarray]:
    k = grid.intrinsics()
    ny, nx = grid.image_shape
    u, v = np.meshgrid(np.arange(nx) + 0.5, np.arange(ny) + 0.5)
    return (u - k[0, 3]) / k[0, 0], (v - k[1, 3]) / k[1, 1]


def ground_truth(capture: Capture, grid: RadarGrid) -> GroundTruth:
    """Rasterise the capture's photogrammetry mesh (through `photogrammetry2radar`) onto `grid`."""
    if capture.mesh is None:
        raise ValueError(f"{capture.path}: no photogrammetry mesh, metrics need ground truth")
    if "photogrammetry2radar" not in capture.transforms:
        raise ValueError(f"{capture.path}: alignment has no 'photogrammetry2radar' transform")
    vertices_m = apply_transform(capture.transforms["photogrammetry2radar"], capture.mesh.vertices)
    depth_m = rasterise_depth_m(vertices_m, capture.mesh.triangles, grid)
    sx_m, sy_m = _maroon_sample_xy_m(grid)
    faithful_depth_m = rasterise_depth_m(vertices_m, capture.mesh.triangles, grid, xy_m=(sx_m, sy_m))
    used = triangulated_vertices(depth_m, TRIANGULATION_THRESHOLD_M)
    points_m = _pixel_points_m(grid, depth_m)[used]
    points_m = points_m[inside_mask_bb(points_m, capture.metadata.mask_bb_m)]
    return GroundTruth(grid=grid, depth_m=depth_m, points=PointSet(points_m), mask_bb_m=capture.metadata.mask_bb_m,
                       mask_erosion=capture.metadata.mask_erosion, faithful_depth_m=faithful_depth_m)


def _projective_cm(depth_m: np.ndarray, selected: np.ndarray, gt: GroundTruth, faithful: bool) -> float:
    if not faithful:
        compared = selected & np.isfinite(gt.depth_m)
        if not compared.any():
            return float("nan")
        return float(np.mean(np.abs(depth_m[compared] - gt.depth_m[compared])) * 100.0)
    if not selected.any():
        return float("nan")
    k = gt.grid.intrinsics()
    x_m, y_m = gt.grid.pixel_xy_m()
    u = np.floor(k[0, 0] * x_m[selected] + k[0, 3]).astype(int)
    v = np.floor(k[1, 1] * y_m[selected] + k[1, 3]).astype(int)
    ny, nx = gt.grid.image_shape
    inside = (u >= 0) & (u < nx) & (v >= 0) & (v < ny)
    errors_mm = np.zeros(u.size)                                # outside the image: 0, counted (reference bug)
    gt_mm = np.nan_to_num(gt.faithful_depth_m[v[inside], u[inside]] * 1000.0)   # holes: 0 mm (reference bug)
    errors_mm[inside] = depth_m[selected][inside] * 1000.0 - gt_mm
    return float(np.mean(np.abs(errors_mm)) / 10.0)


def evaluate(depth_m: np.ndarray, gt: GroundTruth, faithful: bool = False) -> dict[str, float]:
    """C_g, C_s, P and P_e in centimetres for a depth map (metres, NaN = invalid) on `gt.grid`."""
    depth_m = np.asarray(depth_m, dtype=np.float64)
    if depth_m.shape != gt.grid.image_shape:
        raise ValueError(f"depth map {depth_m.shape} does not match the ground-truth grid {gt.grid.image_shape}")
    used = triangulated_vertices(depth_m, TRIANGULATION_THRESHOLD_M, three_valid_quads=not faithful)
    points_m = _pixel_points_m(gt.grid, np.nan_to_num(depth_m))
    selected = used.copy()
    selected[used] = inside_mask_bb(points_m[used], gt.mask_bb_m)
    radar_points_m = points_m[selected]
    eroded = selected & erode_mask(np.isfinite(depth_m), radar_erosion_kernel_px(gt.mask_erosion))
    return {
        "C_g_cm": one_sided_chamfer_m(gt.points.points_m, PointSet(radar_points_m)) * 100.0,
        "C_s_cm": one_sided_chamfer_m(radar_points_m, gt.points) * 100.0,
        "P_cm": _projective_cm(depth_m, selected, gt, faithful),
        "P_e_cm": _projective_cm(depth_m, eroded, gt, faithful),
    }
