"""The paper's four metrics for one reconstruction against the capture's ground truth (MAROON_FORMAT.md 5), with
the pixel counts behind each and the false positives the paper's P cannot see.

Sound definitions (the default), all on one metric grid per capture (the capture's calibration grid; a depth map
computed on another grid is resampled first, metrics.resample):
* radar points: pixels with a valid depth that are vertices of the grid triangulation (threshold 1 cm) and lie
  inside `mask_bb`, at the exact pixel-centre coordinates `(grid_x[j], grid_y[ny-1-i], depth)`;
* ground truth: the mesh in radar space rasterised onto the same pixel centres (nearest surface), triangulated the
  same way and restricted to `mask_bb`;
* the object's silhouette: ground-truth pixels inside `mask_bb`, closed with the erosion kernel (fills gaps
  narrower than it); the eroded silhouette: the silhouette eroded by MAROON's kernel converted to millimetres
  (metrics.masks) - the same region for every method, whatever its own validity mask looks like;
* C_s = Chamfer(radar -> GT), C_g = Chamfer(GT -> radar) with KD-trees (on a CUDA sweep by brute force on the GPU);
* P = mean |D_radar - D_gt| over radar points on the silhouette with ground truth; P_e the same on the eroded
  silhouette;
* off = share (%) of the triangulated radar points off the silhouette or outside mask_bb (false positives: the
  paper's P never sees them), off_err the mean distance of those inside mask_bb to the nearest ground-truth point;
* coverage = share (%) of the silhouette's pixels that hold a radar point the profile scores: how much of the
  object the method returned (bench.report.scoring turns it into the success rule's floor).
`faithful=True` reproduces the reference code's C_g, C_s, P and P_e instead (docs/guide/metrics.md "The faithful
profile"):
* ground truth sampled at MAROON's shifted positions K^-1 (u + 0.5, v + 0.5) (up to one pixel off the pixel
  centres at the far edges), triangulated with the reference's quad rule, restricted to mask_bb for C_g / C_s;
* radar points triangulated with the reference's quad rule (methods.domain.lattice 'maroon': three-valid quads
  decided by the image's corner pixels), kept where the depth is valid and inside mask_bb (the source mask);
* P: every such point maps to GT pixel floor(K p) (two columns share a GT column); it counts only where the radar's
  source mask is set at that destination pixel; there e = 1000 z - D_gt mm with D_gt the splat of the triangulated
  GT vertices (holes: 0, i.e. an error of 1000 z mm); points projecting outside the image count with error 0;
* P_e: the same with the radar's validity mask eroded by round(mask_erosion / 4) pixels (source and destination
  mask), the triangulation left as it was before the erosion.
Values in centimetres; a metric is NaN (never a made-up number) when no point is left to compare, and `failure`
then names the reason: a row with a failure is counted as a failed capture by the tables, never dropped.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from methods.domain.capture import Capture, RadarGrid
from methods.domain.lattice import triangulated_vertices
from methods.domain.transforms import apply_transform
from metrics.chamfer import PointSet, nearest_both_ways_m, nearest_distances_m
from metrics.groundtruth import rasterise_depth_m
from metrics.masks import (
    MAROON_RADAR_PITCH_MM,
    close_mask,
    erode_mask,
    erosion_kernel_mm,
    inside_mask_bb,
    inside_mask_bb_xyz,
    kernel_px_for_pitch,
    radar_erosion_kernel_px,
    reference_mask_bb_m,
)

TRIANGULATION_THRESHOLD_M = 0.01
METRIC_COLUMNS = ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm")
COUNT_COLUMNS = ("C_g_px", "C_s_px", "P_px", "P_e_px", "off_px", "outside_bb_px", "silhouette_px")
SCORE_COLUMNS = (*METRIC_COLUMNS, "coverage_pct", "off_pct", "off_err_cm", *COUNT_COLUMNS, "failure")


@dataclass
class ReferenceGroundTruth:
    """The reference code's ground truth (faithful profile): samples at MAROON's shifted positions."""

    depth_m: np.ndarray           # (ny, nx) at K^-1 (u + 0.5, v + 0.5), NaN = no surface
    points: PointSet              # its triangulated vertices ('maroon' quad rule) inside mask_bb, metres
    splat_mm: np.ndarray          # (ny, nx) the triangulated vertices splatted at floor(K p), mm; 0 = hole
    mask_bb_m: dict[str, float]   # with the viewer's legacy precedence (metrics.masks.reference_mask_bb_m)


@dataclass
class GroundTruth:
    """Ground truth of one capture on its metric grid; build once per capture, evaluate every method against it."""

    grid: RadarGrid
    depth_m: np.ndarray           # (ny, nx) at the pixel centres, NaN = no surface
    points: PointSet              # triangulated GT points inside mask_bb, metres
    silhouette: np.ndarray        # (ny, nx) bool: the object (GT inside mask_bb), closed
    eroded_silhouette: np.ndarray  # (ny, nx) bool: the silhouette eroded by the P_e kernel
    mask_bb_m: dict[str, float]
    mask_erosion: int
    reference: ReferenceGroundTruth


def _pixel_points_m(grid: RadarGrid, depth_m: np.ndarray) -> np.ndarray:
    x_m, y_m = grid.pixel_xy_m()
    return np.stack([x_m, y_m, depth_m], axis=-1)


@functools.lru_cache(maxsize=16)
def _pixel_axes_m(grid: RadarGrid) -> tuple[np.ndarray, np.ndarray]:
    """x (m) of every pixel column and y (m) of every row (row 0 = +y): `grid.pixel_xy_m()`'s values without its
    two (ny, nx) arrays, kept per grid (read-only: shared by every evaluation on it)."""
    x_m, y_m = grid.x_m, grid.y_m[::-1].copy()
    x_m.flags.writeable = y_m.flags.writeable = False
    return x_m, y_m


def maroon_sample_xy_m(grid: RadarGrid) -> tuple[np.ndarray, np.ndarray]:
    """(x, y) in metres, each (ny, nx), where MAROON samples pixel (v, u): K^-1 (u + 0.5, v + 0.5) with its
    orthographic K (MAROON_FORMAT.md 2.4, 4.2): -0.15 m at u = 0 but +0.151 m at u = 300 on the default grid."""
    k = grid.intrinsics()
    ny, nx = grid.image_shape
    u, v = np.meshgrid(np.arange(nx) + 0.5, np.arange(ny) + 0.5)
    return (u - k[0, 3]) / k[0, 0], (v - k[1, 3]) / k[1, 1]


def _floor_pixels(grid: RadarGrid, x_m: np.ndarray, y_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """MAROON's pixel of radar-space points: (u, v) = floor(K p) (no clipping)."""
    k = grid.intrinsics()
    return (np.floor(k[0, 0] * x_m + k[0, 3]).astype(np.int64), np.floor(k[1, 1] * y_m + k[1, 3]).astype(np.int64))


def _reference_ground_truth(depth_m: np.ndarray, grid: RadarGrid, mask_bb_m: dict[str, float]
                            ) -> ReferenceGroundTruth:
    x_m, y_m = maroon_sample_xy_m(grid)
    used = triangulated_vertices(depth_m, TRIANGULATION_THRESHOLD_M, rule="maroon")
    points_m = np.column_stack([x_m[used], y_m[used], depth_m[used]])
    ny, nx = grid.image_shape
    splat_mm = np.zeros((ny, nx))
    u, v = _floor_pixels(grid, points_m[:, 0], points_m[:, 1])
    inside = (u >= 0) & (u < nx) & (v >= 0) & (v < ny)
    splat_mm[v[inside], u[inside]] = 1000.0 * points_m[inside, 2]
    return ReferenceGroundTruth(depth_m=depth_m, points=PointSet(points_m[inside_mask_bb(points_m, mask_bb_m)]),
                                splat_mm=splat_mm, mask_bb_m=mask_bb_m)


def pixel_pitch_mm(grid: RadarGrid) -> float:
    """The finer of the two lateral pixel pitches of `grid` in millimetres."""
    pitches = [(hi - lo) / (n - 1) for lo, hi, n in zip(grid.bb_min_m[:2], grid.bb_max_m[:2], grid.size[:2],
                                                        strict=False) if n > 1]
    return 1000.0 * min(pitches) if pitches else MAROON_RADAR_PITCH_MM


def ground_truth_rasters_m(capture: Capture, grid: RadarGrid) -> tuple[np.ndarray, np.ndarray]:
    """The capture's photogrammetry mesh (through `photogrammetry2radar`) rasterised onto `grid`: depth (m, NaN =
    no surface) at the pixel centres and at MAROON's sample positions (the faithful profile's); the costly part of
    `ground_truth`, which a caller may keep (bench.harness.captures)."""
    if capture.mesh is None:
        raise ValueError(f"{capture.path}: no photogrammetry mesh, metrics need ground truth")
    if "photogrammetry2radar" not in capture.transforms:
        raise ValueError(f"{capture.path}: alignment has no 'photogrammetry2radar' transform")
    vertices_m = apply_transform(capture.transforms["photogrammetry2radar"], capture.mesh.vertices)
    depth_m = rasterise_depth_m(vertices_m, capture.mesh.triangles, grid)
    reference_depth_m = rasterise_depth_m(vertices_m, capture.mesh.triangles, grid, xy_m=maroon_sample_xy_m(grid))
    return depth_m, reference_depth_m


def ground_truth(capture: Capture, grid: RadarGrid) -> GroundTruth:
    """Rasterise the capture's photogrammetry mesh (through `photogrammetry2radar`) onto `grid`."""
    return ground_truth_from_rasters(*ground_truth_rasters_m(capture, grid), grid, capture.metadata)


def ground_truth_from_rasters(depth_m: np.ndarray, reference_depth_m: np.ndarray, grid: RadarGrid, metadata
                              ) -> GroundTruth:
    """The ground truth from `ground_truth_rasters_m`'s two depth maps and the capture's metadata (mask_bb,
    erosion): points, silhouettes and masks."""
    mask_bb_m = metadata.mask_bb_m
    points_m = _pixel_points_m(grid, np.nan_to_num(depth_m))
    on_object = np.isfinite(depth_m) & inside_mask_bb(points_m.reshape(-1, 3), mask_bb_m).reshape(depth_m.shape)
    used = triangulated_vertices(depth_m, TRIANGULATION_THRESHOLD_M) & on_object
    kernel_px = kernel_px_for_pitch(erosion_kernel_mm(metadata.mask_erosion), pixel_pitch_mm(grid))
    silhouette = close_mask(on_object, kernel_px)
    reference = _reference_ground_truth(reference_depth_m, grid, reference_mask_bb_m(metadata))
    return GroundTruth(grid=grid, depth_m=depth_m, points=PointSet(points_m[used]), silhouette=silhouette,
                       eroded_silhouette=erode_mask(silhouette, kernel_px), mask_bb_m=mask_bb_m,
                       mask_erosion=metadata.mask_erosion,
                       reference=reference)


def ground_truth_arrays(gt: GroundTruth) -> dict[str, np.ndarray]:
    """What `ground_truth_from_rasters` computed (rasters, points, silhouettes, the reference's splat), by name: kept
    on disk (bench.harness.captures), `ground_truth_from_arrays` gives the same ground truth back without
    computing it again."""
    return {"depth_m": gt.depth_m, "reference_depth_m": gt.reference.depth_m, "points_m": gt.points.points_m,
            "silhouette": gt.silhouette, "eroded_silhouette": gt.eroded_silhouette,
            "reference_points_m": gt.reference.points.points_m, "reference_splat_mm": gt.reference.splat_mm}


def ground_truth_from_arrays(arrays: dict[str, np.ndarray], grid: RadarGrid, metadata) -> GroundTruth:
    """The ground truth of `ground_truth_arrays`' arrays (checked by the caller) with the capture's metadata."""
    reference = ReferenceGroundTruth(depth_m=arrays["reference_depth_m"], points=PointSet(arrays["reference_points_m"]),
                                     splat_mm=arrays["reference_splat_mm"], mask_bb_m=reference_mask_bb_m(metadata))
    return GroundTruth(grid=grid, depth_m=arrays["depth_m"], points=PointSet(arrays["points_m"]),
                       silhouette=arrays["silhouette"], eroded_silhouette=arrays["eroded_silhouette"],
                       mask_bb_m=metadata.mask_bb_m, mask_erosion=metadata.mask_erosion, reference=reference)


def _mean_abs_cm(depth_m: np.ndarray, gt_depth_m: np.ndarray, compared: np.ndarray) -> float:
    if not compared.any():
        return float("nan")
    return float(np.mean(np.abs(depth_m[compared] - gt_depth_m[compared])) * 100.0)


def reference_projective(depth_m: np.ndarray, used: np.ndarray, source_mask: np.ndarray, gt: GroundTruth
                         ) -> tuple[float, int]:
    """The reference code's projective error (cm) and its number of counted points.

    Points: `used & source_mask` at the exact pixel centres; each maps to pixel floor(K p). Outside the image it
    counts with error 0; inside it counts only where `source_mask` is set at that pixel, with
    e = 1000 z - splat (mm, splat 0 at GT holes)."""
    selected = used & source_mask
    x_m, y_m = gt.grid.pixel_xy_m()
    u, v = _floor_pixels(gt.grid, x_m[selected], y_m[selected])
    ny, nx = gt.grid.image_shape
    inside = (u >= 0) & (u < nx) & (v >= 0) & (v < ny)
    counted = ~inside
    counted[inside] = source_mask[v[inside], u[inside]]
    errors_mm = np.zeros(u.size)                                # outside the image: 0, counted (reference bug)
    errors_mm[inside] = depth_m[selected][inside] * 1000.0 - gt.reference.splat_mm[v[inside], u[inside]]
    if not counted.any():
        return float("nan"), 0
    return float(np.mean(np.abs(errors_mm[counted])) / 10.0), int(counted.sum())


def _chamfers_cm(radar_points_m: np.ndarray, off: np.ndarray, gt_points: PointSet, sound_points: PointSet,
                 device: str = "cpu") -> tuple[float, float, float]:
    """C_g and C_s (cm: `gt_points` to `radar_points_m` and back) and off_err (cm: the radar points flagged `off`,
    off the object, to the sound ground truth's points). Where both go to the same points (the sound profile) the
    off points' distances are picked from C_s's query, not queried again: the same numbers, since a point's nearest
    distance does not depend on the other points of its query. `device`: the sweep's (metrics.chamfer.on_gpu)."""
    off_points_m = radar_points_m[off]
    if not len(radar_points_m) or not len(gt_points.points_m):
        c_g_cm = c_s_cm = float("nan")
        to_gt_m = None
    else:
        to_gt_m, to_radar_m = nearest_both_ways_m(radar_points_m, gt_points, device)
        c_g_cm, c_s_cm = float(np.mean(to_radar_m)) * 100.0, float(np.mean(to_gt_m)) * 100.0
    if not len(off_points_m) or not len(sound_points.points_m):
        off_err_cm = float("nan")
    elif gt_points is sound_points and to_gt_m is not None:
        off_err_cm = float(np.mean(to_gt_m[off])) * 100.0
    else:
        off_err_cm = float(np.mean(nearest_distances_m(off_points_m, sound_points, device))) * 100.0
    return c_g_cm, c_s_cm, off_err_cm


def _radar_points(depth_m: np.ndarray, used: np.ndarray, grid: RadarGrid, mask_bb_m: dict[str, float]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(valid depths, the source mask: valid and inside `mask_bb`, the radar points (m): pixels `used` and in the
    source mask, in row-major order). A pixel's point is (x_m[j], y_m[i], depth) (`_pixel_points_m`): bounds are
    tested per column, row and depth, the points gathered for the selected pixels only, without the (ny, nx, 3)
    array (the same booleans and coordinates; invalid depths fail every z bound but are no sources anyway)."""
    valid = np.isfinite(depth_m) & (depth_m != 0)
    x_m, y_m = _pixel_axes_m(grid)
    with np.errstate(invalid="ignore"):
        source_mask = valid & inside_mask_bb_xyz(x_m[None, :], y_m[:, None], depth_m, mask_bb_m)
    rows, columns = np.nonzero(used & source_mask)
    return valid, source_mask, np.column_stack([x_m[columns], y_m[rows], depth_m[rows, columns]])


def _failure(depth_m: np.ndarray, used: np.ndarray, selected: np.ndarray, scores: dict) -> str:
    """Why a metric is NaN ('' when all four are numbers)."""
    if not np.isfinite(depth_m).any():
        return "no valid pixel"
    if not used.any():
        return "no triangulated pixel"
    if not selected.any():
        return "no radar point inside mask_bb"
    missing = [name for name in METRIC_COLUMNS if not np.isfinite(scores[name])]
    return f"{', '.join(missing)}: no point to compare" if missing else ""


def evaluate(depth_m: np.ndarray, gt: GroundTruth, faithful: bool = False, device: str = "cpu"
             ) -> dict[str, float | int | str]:
    """Metrics (cm), off-object share (%), pixel counts and `failure` for a depth map (metres, NaN = invalid) on
    `gt.grid`; the keys are SCORE_COLUMNS. `device`: the sweep's; "cuda" finds the Chamfer distances' nearest
    points on the GPU (metrics.chamfer.on_gpu: the same numbers)."""
    depth_m = np.asarray(depth_m, dtype=np.float64)
    if depth_m.shape != gt.grid.image_shape:
        raise ValueError(f"depth map {depth_m.shape} does not match the ground-truth grid {gt.grid.image_shape}")
    used = triangulated_vertices(depth_m, TRIANGULATION_THRESHOLD_M, rule="maroon" if faithful else "sound")
    valid, source_mask, radar_points_m = _radar_points(depth_m, used, gt.grid,
                                                       gt.reference.mask_bb_m if faithful else gt.mask_bb_m)
    selected = used & source_mask
    has_gt = np.isfinite(gt.depth_m)
    off = selected & ~gt.silhouette
    gt_points = gt.reference.points if faithful else gt.points
    if faithful:
        eroded_mask = source_mask & erode_mask(valid, radar_erosion_kernel_px(gt.mask_erosion))
        p_cm, p_px = reference_projective(depth_m, used, source_mask, gt)
        p_e_cm, p_e_px = reference_projective(depth_m, used, eroded_mask, gt)
    else:
        on, on_eroded = selected & gt.silhouette & has_gt, selected & gt.eroded_silhouette & has_gt
        p_px, p_e_px = int(on.sum()), int(on_eroded.sum())
        p_cm, p_e_cm = _mean_abs_cm(depth_m, gt.depth_m, on), _mean_abs_cm(depth_m, gt.depth_m, on_eroded)
    outside = used & ~selected
    counted = selected.sum() + outside.sum()
    silhouette_px = int(gt.silhouette.sum())
    c_g_cm, c_s_cm, off_err_cm = _chamfers_cm(radar_points_m, off[selected], gt_points, gt.points, device)
    scores = {
        "C_g_cm": c_g_cm,
        "C_s_cm": c_s_cm,
        "P_cm": p_cm, "P_e_cm": p_e_cm,
        "coverage_pct": 100.0 * (selected & gt.silhouette).sum() / silhouette_px if silhouette_px else float("nan"),
        "off_pct": 100.0 * (off.sum() + outside.sum()) / counted if counted else float("nan"),
        "off_err_cm": off_err_cm,
        "C_g_px": len(gt_points.points_m), "C_s_px": len(radar_points_m), "P_px": p_px, "P_e_px": p_e_px,
        "off_px": int(off.sum()), "outside_bb_px": int(outside.sum()), "silhouette_px": silhouette_px,
    }
    scores["failure"] = _failure(depth_m, used, selected, scores)
    return scores


def no_ground_truth_scores(reason: str) -> dict[str, float | int | str]:
    """SCORE_COLUMNS of a capture that cannot be evaluated (e.g. no mesh): NaN metrics, zero counts, `reason`."""
    scores = {name: float("nan") for name in (*METRIC_COLUMNS, "coverage_pct", "off_pct", "off_err_cm")}
    scores.update(dict.fromkeys(COUNT_COLUMNS, 0), failure=reason)
    return scores
