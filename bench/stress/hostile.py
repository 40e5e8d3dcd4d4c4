"""Degenerate and hostile input: each case must end in a clear error or an explicit all-invalid result.

A case mutates a private copy of one synthetic capture (or the capture once loaded), then runs the whole chain
read -> MM-2FSK (d05, RealSense prior, a coarse 61 x 61 grid) -> ground truth -> metrics. Outcomes:
* "error": DatasetError (its message names the file) or ValueError (a clear sentence), no traceback;
* "all-invalid": every depth NaN, `invalid_reason` set, metrics NaN because nothing is comparable;
* "nothing-comparable": valid pixels but none a vertex of a metric triangle (e.g. a one-pixel object): NaN
  metrics by the documented rule;
* "valid": finite metrics; "partial-nan" (some metric NaN with comparable points) and "crash" (any other
  exception) are defects. Every run also records RuntimeWarnings and whether the dataset files changed.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import traceback
import warnings
from collections.abc import Callable
from pathlib import Path

import numpy as np

from bench.maroon import reader
from bench.stress import hostile_inputs
from methods import reconstruct
from methods.domain.capture import Capture
from methods.domain.errors import DatasetError
from methods.mm2fsk import reconstruct_mm2fsk
from methods.ops.frequencies import config_indices
from metrics.evaluate import METRIC_COLUMNS, evaluate, ground_truth

PWNED = "hostile_pickle_ran"            # a file the malicious pickles would create if they were executed


class _Executes:
    """Pickles as a call of os.system: what an attacker would put into a frame file."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def frame_path(capture_dir: Path) -> Path:
    """The capture's radar frame file (the generator writes one frame)."""
    return next(capture_dir.glob("radar_*/calibrated_data/000000.npy"))


def _rewrite_frame(capture_dir: Path, change: Callable[[dict], dict]) -> None:
    path = frame_path(capture_dir)
    frame = np.load(path, allow_pickle=True).item()     # trusted: the generator wrote it
    np.save(path, change(frame), allow_pickle=True)


def _save_object(capture_dir: Path, obj) -> None:
    holder = np.empty((), dtype=object)
    holder[()] = obj
    np.save(frame_path(capture_dir), holder, allow_pickle=True)


def _with_nan(xr: np.ndarray) -> np.ndarray:
    """Copy of a frame with one NaN sample on a used antenna pair at the highest frequency (used by d05)."""
    xr = xr.copy()
    xr[10, 10, -1] = np.nan
    return xr


def _truncate(path: Path) -> None:
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])


def _blank_mask(capture_dir: Path) -> None:
    from PIL import Image
    path = capture_dir / "realsense" / "mask" / "000000.png"
    Image.fromarray(np.zeros_like(np.asarray(Image.open(path)))).save(path)


FILE_CASES: dict[str, Callable[[Path], None]] = {
    "all_zero_frame": lambda d: _rewrite_frame(d, lambda f: {**f, "xr": np.zeros_like(f["xr"])}),
    "nan_in_xr": lambda d: _rewrite_frame(d, lambda f: {**f, "xr": _with_nan(f["xr"])}),
    "inf_in_xr": lambda d: _rewrite_frame(d, lambda f: {**f, "xr": f["xr"] * np.inf}),
    "fvec_in_ghz": lambda d: _rewrite_frame(d, lambda f: {**f, "fvec": f["fvec"] / 1e9}),
    "xr_fvec_mismatch": lambda d: _rewrite_frame(d, lambda f: {**f, "xr": f["xr"][:, :, :-1]}),
    "xr_wrong_antennas": lambda d: _rewrite_frame(d, lambda f: {**f, "xr": f["xr"][:50]}),
    "xr_real_valued": lambda d: _rewrite_frame(d, lambda f: {**f, "xr": np.abs(f["xr"])}),
    "pickle_os_system": lambda d: _save_object(d, {"xr": _Executes(d.parent.parent / PWNED)}),
    "pickle_top_level_call": lambda d: _save_object(d, _Executes(d.parent.parent / PWNED)),
    "pickle_object_array": lambda d: _save_object(d, {"xr": np.array([1, "a"], dtype=object)}),
    "pickle_not_a_dict": lambda d: _save_object(d, [1, 2, 3]),
    "frame_truncated": lambda d: _truncate(frame_path(d)),
    "frame_empty_file": lambda d: frame_path(d).write_bytes(b""),
    "frame_missing": lambda d: [p.unlink() for p in frame_path(d).parent.glob("*.npy")],
    "metadata_missing": lambda d: (d / "metadata.json").unlink(),
    "metadata_truncated": lambda d: _truncate(d / "metadata.json"),
    "alignment_missing": lambda d: (d / "alignment.json").unlink(),
    "radar_calibration_truncated": lambda d: _truncate(next(d.glob("radar_*/calibration.json"))),
    "depth_png_truncated": lambda d: _truncate(d / "realsense" / "depth" / "000000.png"),
    "depth_png_missing": lambda d: (d / "realsense" / "depth" / "000000.png").unlink(),
    "empty_mask": _blank_mask,
    "mesh_truncated": lambda d: _truncate(d / "photogrammetry" / "mesh_masked_smoothed.obj"),
    "mesh_missing": lambda d: shutil.rmtree(d / "photogrammetry"),
}


def _edit_json(relative: str, change: Callable[[dict], None]) -> Callable[[Path], None]:
    def edit(capture_dir: Path) -> None:
        path = next(capture_dir.glob(relative))
        data = json.loads(path.read_text())
        change(data)
        path.write_text(json.dumps(data))
    return edit


def _write(relative: str, build: Callable[[], bytes]) -> Callable[[Path], None]:
    return lambda capture_dir: next(capture_dir.glob(relative)).write_bytes(build())


# issue 18's kinds, built by bench.stress.hostile_inputs (the file-system kinds - FIFOs, devices, links - are in
# tests/bench/maroon/test_hostile_fs.py: this in-process chain reads every dataset file to check it is unchanged)
FILE_CASES.update({
    "pickle_billion_laughs": _write("radar_*/calibrated_data/000000.npy",
                                    lambda: hostile_inputs.npy_pickle(hostile_inputs.billion_laughs_pickle())),
    "pickle_deep_nesting": _write("radar_*/calibrated_data/000000.npy",
                                  lambda: hostile_inputs.npy_pickle(hostile_inputs.deep_list_pickle(100_000))),
    "pickle_void_scalar": _write("radar_*/calibrated_data/000000.npy", hostile_inputs.void_scalar_frame),
    "pickle_zero_stride": _write("radar_*/calibrated_data/000000.npy", hostile_inputs.zero_stride_frame),
    "pickle_subarray_dtype": _write("radar_*/calibrated_data/000000.npy", hostile_inputs.subarray_dtype_frame),
    "json_deep_nesting": _write("metadata.json", lambda: b"[" * 100_000 + b"]" * 100_000),
    "json_5000_digit_int": _write("metadata.json", lambda: hostile_inputs.json_cases()["json_int_5000_digits"]),
    "grid_bb_max_string": _edit_json("radar_*/calibration.json",
                                     lambda d: d["000000"]["volume"].update(bb_max=["0.15", 0.15, 0.4])),
    "grid_1_6e9_pixels": _edit_json("radar_*/calibration.json",
                                    lambda d: d["000000"]["volume"].update(grid_size=[40000, 40000, 1])),
    "mask_erosion_4000": _edit_json("metadata.json", lambda d: d.update(mask_erosion=4000)),
    "depth_png_bomb": _write("realsense/depth/000000.png", lambda: hostile_inputs.png_declaring(20000, 20000)),
    "transform_scale_1e300": _edit_json("alignment.json", lambda d: d.update(
        photogrammetry2radar=np.diag([1e300, 1e300, 1e300, 1.0]).tolist())),
})


def _shift_prior_out(capture: Capture) -> Capture:
    moved = capture.transforms["realsense2radar"].copy()
    moved[0, 3] += 5.0                                   # 5 m to the side: no radar pixel under the object
    return dataclasses.replace(capture, transforms={**capture.transforms, "realsense2radar": moved})


def _with_radar(capture: Capture, **changes) -> Capture:
    return dataclasses.replace(capture, radar=dataclasses.replace(capture.radar, **changes))


MEMORY_CASES: dict[str, Callable[[Capture], Capture]] = {
    "memory_nan_signal": lambda c: _with_radar(c, signal=_with_nan(c.radar.signal)),
    "memory_freqs_in_ghz": lambda c: _with_radar(c, freqs_hz=c.radar.freqs_hz / 1e9),
    "memory_prior_outside_grid": _shift_prior_out,
}


def coarse_grid(capture: Capture):
    """The capture's grid with 61 x 61 pixels (fast; the same bounds)."""
    grid = capture.radar.grid
    return dataclasses.replace(grid, size=(61, 61, grid.size[2]))


def _metrics(capture: Capture, depth_m: np.ndarray, grid) -> dict:
    return evaluate(depth_m, ground_truth(capture, grid))


def _outcome(valid_px: int, metrics: dict) -> str:
    values = np.array([metrics[k] for k in METRIC_COLUMNS])
    if valid_px == 0:
        return "all-invalid" if np.isnan(values).all() else "partial-nan"
    if np.isfinite(values).all():
        return "valid"
    return "nothing-comparable" if np.isnan(values).all() else "partial-nan"


def _chain(capture_dir: Path, change: Callable[[Capture], Capture] | None) -> dict:
    capture = reader.read_capture(capture_dir)
    if change is not None:
        capture = change(capture)
    grid = coarse_grid(capture)
    rec = reconstruct(capture, "mm2fsk", "d05", prior="realsense", grid=grid)
    metrics = _metrics(capture, rec.depth_m, grid)
    return {"valid_px": int(rec.valid.sum()), "invalid_reason": rec.invalid_reason or "", **metrics,
            "outcome": _outcome(int(rec.valid.sum()), metrics)}


def _one_pixel_object(capture_dir: Path) -> dict:
    """MM-2FSK with a prior on exactly one radar pixel (an object one pixel wide)."""
    capture = reader.read_capture(capture_dir)
    grid = coarse_grid(capture)
    prior_m = np.full(grid.image_shape, np.nan)
    prior_m[30, 30] = capture.metadata.distance_m
    used = config_indices(capture.radar.freqs_hz, "d05")
    rec = reconstruct_mm2fsk(capture.radar.signal[:, :, used], capture.radar.freqs_hz[used], capture.antennas,
                             grid, prior_m)
    metrics = _metrics(capture, rec.depth_m, grid)
    return {"valid_px": int(rec.valid.sum()), "invalid_reason": "", **metrics,
            "outcome": _outcome(int(rec.valid.sum()), metrics)}


def _digest(root: Path) -> str:
    sha = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.is_file()):
        sha.update(str(path.relative_to(root)).encode() + path.read_bytes())
    return sha.hexdigest()


def run_case(name: str, source_capture: Path, work_dir: Path) -> dict:
    """Copy `source_capture` under `work_dir`, apply case `name`, run the chain; one result row."""
    capture_dir = work_dir / name / source_capture.parent.name / source_capture.name
    shutil.rmtree(work_dir / name, ignore_errors=True)
    shutil.copytree(source_capture, capture_dir)
    if name in FILE_CASES:
        FILE_CASES[name](capture_dir)
    before = _digest(work_dir / name)
    row = {"case": name, "outcome": "", "message": "", "valid_px": 0, "invalid_reason": "",
           **dict.fromkeys(METRIC_COLUMNS, np.nan)}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        try:
            if name == "one_pixel_object":
                row.update(_one_pixel_object(capture_dir))
            else:
                row.update(_chain(capture_dir, MEMORY_CASES.get(name)))
        except (DatasetError, ValueError) as err:
            row.update(outcome="error", message=f"{type(err).__name__}: {err}")
        except Exception as err:                                    # noqa: BLE001 - a crash is what we record
            row.update(outcome="crash", message="".join(traceback.format_exception_only(err)).strip())
    row["runtime_warnings"] = sum(issubclass(w.category, RuntimeWarning) for w in caught)
    row["dataset_unchanged"] = _digest(work_dir / name) == before
    row["pickle_executed"] = (work_dir / name / PWNED).exists()
    return row


CASES = tuple(FILE_CASES) + tuple(MEMORY_CASES) + ("one_pixel_object",)


def hostile_rows(source_capture: Path, work_dir: Path, cases=CASES) -> list[dict]:
    """One row per hostile case (see the module doc); paths in messages start at WORK/ (reproducible CSV)."""
    rows = [run_case(name, Path(source_capture), Path(work_dir)) for name in cases]
    return [{**row, "message": row["message"].replace(str(work_dir), "WORK")} for row in rows]
