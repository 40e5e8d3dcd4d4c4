"""Writers for the files of one MAROON-format capture directory (MAROON_FORMAT.md sections 1-4)."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
from PIL import Image

from bench.synth.camera import photogrammetry
from bench.synth.config import F_HIGH_GHZ, F_LOW_GHZ
from bench.synth.meshes import indexed
from methods.domain.capture import RadarGrid
from methods.domain.radar import radar_folder_name as maroon_radar_folder

RADAR_HALF_WIDTH_M = 0.15
RADAR_HALF_DEPTH_M = 0.10
RADAR_GRID_SIZE = (301, 301, 201)


def radar_folder_name(frequency_points: int) -> str:
    """MAROON's radar folder for a sweep of `frequency_points` over the band, e.g. radar_72.0_82.0_128."""
    return maroon_radar_folder(F_LOW_GHZ, F_HIGH_GHZ, frequency_points)


def frame_name(index: int) -> str:
    return f"{index:06d}"


def _write_json(path: Path, payload: dict, sort_keys: bool = False) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(payload, indent=2, sort_keys=sort_keys))


def radar_grid(distance_m: float) -> RadarGrid:
    """The capture's 301x301x201 voxel grid: +-0.15 m laterally, distance +-0.10 m in z, float32-rounded."""
    r32 = lambda v: float(np.float32(v))  # noqa: E731 - the real files hold float32-rounded values
    bb_min = (r32(-RADAR_HALF_WIDTH_M), r32(-RADAR_HALF_WIDTH_M), r32(distance_m - RADAR_HALF_DEPTH_M))
    bb_max = (r32(RADAR_HALF_WIDTH_M), r32(RADAR_HALF_WIDTH_M), r32(distance_m + RADAR_HALF_DEPTH_M))
    return RadarGrid(bb_min, bb_max, RADAR_GRID_SIZE)


def maroon_default_mask_bb(distance_m: float) -> dict[str, float]:
    """What MAROON's viewer writes into metadata.json (MAROON_FORMAT.md 1.2): zmax 0.70 m, zmin 0.26 m at 30 cm.

    Not tighter: a result that wraps to an alias behind the object must stay inside the box and be scored as
    wrong, not removed before it is measured.
    """
    return {"zmin": 0.26, "zmax": 0.7} if distance_m == 0.3 else {"zmax": 0.7}


def write_metadata(capture_dir: Path, distance_m: float, label: str) -> None:
    _write_json(capture_dir / "metadata.json", {
        "calibration": "01_registration_coarse", "calibration_fine": "01_registration_fine",
        "distance_meters": distance_m, "mask_erosion": 20, "labels": [label],
        "mask_bb": maroon_default_mask_bb(distance_m),
        "empty_measurement": "01_empty"})


def write_alignment(capture_dir: Path, transforms: dict[str, np.ndarray]) -> None:
    """alignment.json: 4x4 row-major nested lists, p_dst = M @ [p_src; 1]."""
    _write_json(capture_dir / "alignment.json", {k: np.asarray(m, float).tolist() for k, m in transforms.items()})


def write_radar_calibration(capture_dir: Path, grid: RadarGrid, frames: int, frequency_points: int) -> None:
    entry = {"volume": {"bb_min": list(grid.bb_min_m), "bb_max": list(grid.bb_max_m), "grid_size": list(grid.size)},
             "amplitude": {"amplitude_filter_threshold_dB": 14, "amplitude_filter_kernel_size": 1},
             "depth": {"intrinsics": grid.intrinsics().tolist()}}
    payload = {frame_name(i): entry for i in range(frames)}
    payload.update({"frequency_low_ghz": int(F_LOW_GHZ), "frequency_high_ghz": int(F_HIGH_GHZ),
                    "frequency_points": int(frequency_points)})
    _write_json(capture_dir / radar_folder_name(frequency_points) / "calibration.json", payload, sort_keys=True)


def write_radar_frame(capture_dir: Path, index: int, raw: np.ndarray, emptyfiltered: np.ndarray,
                      freqs_hz: np.ndarray, frames: int, timestamp_us: int) -> None:
    """calibrated_data/NNNNNN.npy and NNNNNN_emptyfiltered.npy as pickled dicts (like the originals)."""
    folder = capture_dir / radar_folder_name(len(freqs_hz)) / "calibrated_data"
    folder.mkdir(parents=True, exist_ok=True)
    for suffix, xr in (("", raw), ("_emptyfiltered", emptyfiltered)):
        np.save(folder / f"{frame_name(index)}{suffix}.npy",
                {"xr": xr.astype(np.complex64), "fvec": np.asarray(freqs_hz, np.float64),
                 "number_of_measurements": int(frames), "timestamp_us": np.array([timestamp_us], np.int64)})


def write_realsense_frame(capture_dir: Path, index: int, depth_mm: np.ndarray, mask: np.ndarray,
                          rgb: np.ndarray) -> None:
    folder = capture_dir / "realsense"
    for sub in ("rgb", "depth", "mask"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    Image.fromarray(rgb).save(folder / "rgb" / f"{frame_name(index)}.jpg", quality=92)
    Image.fromarray(depth_mm.astype(np.uint16)).save(folder / "depth" / f"{frame_name(index)}.png")
    Image.fromarray(mask.astype(np.uint8)).save(folder / "mask" / f"{frame_name(index)}.png")


def write_realsense_meta(capture_dir: Path, camera_intrinsics: dict, timestamps_ns: list[int]) -> None:
    folder = capture_dir / "realsense"
    _write_json(folder / "calibration.json", {"capture": {"scale": 0.001}, "rgb": dict(camera_intrinsics),
                                              "depth": dict(camera_intrinsics)})
    lines = ["filename absolute_system[ns]"] + [f"{frame_name(i)} {t}" for i, t in enumerate(timestamps_ns)]
    (folder / "timestamps.txt").write_text("\n".join(lines) + "\n")


def write_mesh_obj(path: Path, tris_m: np.ndarray) -> None:
    """Plain OBJ (v / f lines, 1-based) of a triangle soup, corners merged."""
    vertices, triangles = indexed(tris_m)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w") as fh:
        fh.write("# synthetic ground truth, metres, photogrammetry frame\n")
        # one format operation per block: the text np.savetxt writes, 3-5x faster on the refined meshes
        fh.write(("v %.7f %.7f %.7f\n" * len(vertices)) % tuple(vertices.ravel()))
        fh.write(("f %d %d %d\n" * len(triangles)) % tuple((triangles + 1).ravel().tolist()))
    if path.name == photogrammetry.GT_MESH_NAME:        # the rest of what MAROON's loader opens beside it
        photogrammetry.write_loader_files(path.parent, vertices, triangles)
