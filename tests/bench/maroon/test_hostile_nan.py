"""No NaN metric without a reason: the issue's 'silent NaN' inputs (a frame near float32's maximum, two
frequencies 1 Hz apart, a mask_bb that excludes every point, a 2x2x1 grid, a 1e300 scale in a transform, a mesh
with huge coordinates or 1e6 degenerate faces) and variations end in one DatasetError naming the file, or in a
results row whose `failure` column says why each NaN metric is NaN - through `bench.harness.app.run`, as `python -m
bench`
computes rows."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from bench.harness.app import CONFIG_DIR, run
from methods.domain.errors import DatasetError
from metrics.evaluate import METRIC_COLUMNS

from hostile_tools import RADAR, bounded, copy_capture, frame_file, tree_digest


@pytest.fixture(scope="module")
def source_capture(synth_capture):
    return synth_capture("01_plate", 30, frequency_points=16)


def _frame(change):
    def edit(capture: Path):
        path = frame_file(capture)
        frame = np.load(path, allow_pickle=True).item()          # trusted: the generator wrote it
        change(frame)
        np.save(path, frame, allow_pickle=True)
    return edit


def _json(relative: str, change):
    def edit(capture: Path):
        data = json.loads((capture / relative).read_text())
        change(data)
        (capture / relative).write_text(json.dumps(data))
    return edit


def _near_float32_max(frame):
    frame["xr"] = (frame["xr"] / np.abs(frame["xr"]).max() * 3.0e38).astype(np.complex64)


def _one_hz_pair(frame):
    frame["fvec"] = frame["fvec"].copy()
    frame["fvec"][-2] = frame["fvec"][-1] - 1.0                   # d05 picks exactly these two


def _two_frequencies_one_hz(frame):
    frame["xr"], frame["fvec"] = frame["xr"][:, :, 8:10].copy(), np.array([76e9, 76e9 + 1.0])


def _scaled(key, factor):
    def change(data):
        matrix = np.array(data[key], dtype=float).reshape(4, 4)
        matrix[:3, :3] *= factor
        data[key] = matrix.tolist()
    return change


def _mesh(text_from_vertices):
    def edit(capture: Path):
        (capture / "photogrammetry" / "mesh_masked_smoothed.obj").write_bytes(text_from_vertices(capture))
    return edit


def _huge_coordinates(capture: Path) -> bytes:
    lines = (capture / "photogrammetry" / "mesh_masked_smoothed.obj").read_text().splitlines()
    return "\n".join("v " + " ".join(str(float(v) * 1e30) for v in line.split()[1:]) if line.startswith("v ")
                     else line for line in lines).encode() + b"\n"


def _volume(**changes):
    def change(data):
        data["000000"]["volume"].update(changes)
    return change


ERRORS = {       # case: (edit, file that the one error line names, what it says)
    "frame_near_float32_max": (_frame(_near_float32_max), "000000.npy", "signal_abs"),
    "adjacent_frequencies_1_hz": (_frame(_one_hz_pair), "000000.npy", "1 Hz apart"),
    "two_frequencies_1_hz": (_frame(_two_frequencies_one_hz), "000000.npy", "1 Hz apart"),
    "transform_scale_1e300": (_json("alignment.json", _scaled("photogrammetry2radar", 1e300)), "alignment.json",
                              "scales lengths"),
    "realsense_scale_1e-300": (_json("alignment.json", _scaled("realsense2radar", 1e-300)), "alignment.json",
                               "scales lengths"),
    "mesh_huge_coordinates": (_mesh(_huge_coordinates), "mesh_masked_smoothed.obj", "coordinates reach"),
    "mesh_1e6_degenerate_faces": (_mesh(lambda c: b"v 0 0 0.3\nv 0.01 0 0.3\nv 0 0.01 0.3\n" + b"f 1 1 1\n" * 10 ** 6),
                                  "mesh_masked_smoothed.obj", "degenerate"),
    "grid_1_um_pixels": (_json(f"{RADAR}/calibration.json", _volume(bb_min=[-1e-7, -1e-7, 0.2],
                                                                     bb_max=[1e-7, 1e-7, 0.4])),
                         "calibration.json", "below"),
}


def _compose(root: Path, method: str, prior: str):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=["dataset=maroon", f"dataset.root={root}", f"method={method}",
                                                        "freq=d05", f"prior={prior}", "store.dir=null"])


@pytest.mark.parametrize("case", sorted(ERRORS))
def test_silent_nan_inputs_now_end_in_one_error(source_capture, tmp_path, case):
    edit, name, message = ERRORS[case]
    capture = copy_capture(source_capture, tmp_path / "root")
    edit(capture)
    before = tree_digest(tmp_path / "root")
    with pytest.raises(DatasetError) as info, bounded(seconds=60):
        run(_compose(tmp_path / "root", "mm2fsk", "realsense"), tmp_path / "out")
    assert info.value.path.name == name and message in info.value.problem, str(info.value)
    assert tree_digest(tmp_path / "root") == before


# a method that skips pixels outside mask_bb (methods.skips.roi) ends all-invalid and gives its own reason instead
MASK_BB_REASONS = ("inside mask_bb", "mask_bb", "no pixel has a nonzero magnitude")
ROWS = {         # case: (edit, method, prior, what the failure column must say: one of these)
    "mask_bb_excludes_every_point": (_json("metadata.json", lambda d: d.update(mask_bb={"zmin": 0.6, "zmax": 0.7})),
                                     "mm2fsk", "realsense", MASK_BB_REASONS),
    "mask_bb_excludes_every_point_2fsk": (_json("metadata.json", lambda d: d.update(mask_bb={"xmin": 0.149})),
                                          "2fsk", "none", MASK_BB_REASONS),
    "grid_2x2x1": (_json(f"{RADAR}/calibration.json", _volume(grid_size=[2, 2, 1], bb_max=[0.15, 0.15, 0.2],
                                                              bb_min=[-0.15, -0.15, 0.2])),
                   "2fsk", "none", "triangulated"),
    "grid_2x2x1_mm2fsk": (_json(f"{RADAR}/calibration.json", _volume(grid_size=[2, 2, 1], bb_max=[0.15, 0.15, 0.2],
                                                                     bb_min=[-0.15, -0.15, 0.2])),
                          "mm2fsk", "realsense", "covers no radar pixel"),
    "prior_5_m_to_the_side": (_json("alignment.json", lambda d: d["realsense2radar"][0].__setitem__(3, 5.0)),
                              "mm2fsk", "realsense", "covers no radar pixel"),
    "mesh_5_m_to_the_side": (_json("alignment.json", lambda d: d["photogrammetry2radar"][0].__setitem__(3, 5.0)),
                             "mm2fsk", "realsense", "no point to compare"),
    "all_zero_frame": (_frame(lambda f: f.update(xr=np.zeros_like(f["xr"]))), "2fsk", "none", "has no signal"),
    "mask_bb_beside_the_grid": (_json("metadata.json", lambda d: d.__setitem__("mask_bb", {"xmin": 5.0, "xmax": 6.0})),
                                "2fsk", "none", "metadata.json (xmax 6, xmin 5 m) excludes every pixel of the grid"),
}


@pytest.mark.parametrize("case", sorted(ROWS))
def test_every_nan_metric_has_a_reason_in_its_row(source_capture, tmp_path, case):
    edit, method, prior, reason = ROWS[case]
    capture = copy_capture(source_capture, tmp_path / "root")
    edit(capture)
    with bounded(seconds=90):
        (row,) = run(_compose(tmp_path / "root", method, prior), tmp_path / "out")
    nan = [name for name in METRIC_COLUMNS if not math.isfinite(row[name])]
    assert nan, row                                  # each case leaves something not comparable
    reasons = (reason,) if isinstance(reason, str) else reason
    assert any(text in row["failure"] for text in reasons), row["failure"]
    assert row["failure"] in (tmp_path / "out" / "results.csv").read_text()
