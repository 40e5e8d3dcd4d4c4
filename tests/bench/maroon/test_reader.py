"""The MAROON reader: round trip with the generator, safe unpickling, validation messages, read-only use."""
from __future__ import annotations

import hashlib
import io
import json
import pickle
import shutil
import stat
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from bench.maroon import reader as maroon
from bench.maroon.antennas import load_antenna_array, read_antenna_file
from bench.maroon.safe_pickle import load_pickled_dict
from methods.domain.capture import RadarGrid
from methods.domain.errors import DatasetError
from methods.domain.transforms import transform_between

CAPTURE = "01_plate/30"
RADAR = "radar_72.0_82.0_128"


@pytest.fixture
def capture_copy(synth_root, tmp_path) -> Path:
    """A private, writable copy of one synthetic capture inside its own dataset root."""
    dst = tmp_path / "root" / CAPTURE
    shutil.copytree(synth_root / CAPTURE, dst)
    return dst


def _tree_digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


# ----------------------------------------------------------------------------------------- round trip
def test_round_trip_matches_files(synth_root):
    capture = maroon.read_capture(synth_root / CAPTURE)
    frame_path = synth_root / CAPTURE / RADAR / "calibrated_data" / f"{capture.radar.index:06d}.npy"
    stored = np.load(frame_path, allow_pickle=True).item()  # trusted: our own generator wrote it
    assert capture.radar.signal.shape == (94, 94, 128) and capture.radar.signal.dtype == np.complex64
    np.testing.assert_array_equal(capture.radar.signal, stored["xr"][1:95, 1:95, :])
    np.testing.assert_array_equal(capture.radar.freqs_hz, stored["fvec"])
    calibration = json.loads((synth_root / CAPTURE / RADAR / "calibration.json").read_text())
    volume = calibration[f"{capture.radar.index:06d}"]["volume"]
    assert capture.radar.grid.size == tuple(volume["grid_size"])
    assert capture.radar.grid.bb_min_m == tuple(volume["bb_min"])
    depth_png = np.asarray(Image.open(capture.realsense.path))
    np.testing.assert_array_equal(capture.realsense.depth_mm, depth_png)
    assert capture.realsense.mask is not None and capture.realsense.mask.any()
    assert {"realsense2radar", "photogrammetry2radar"} <= set(capture.transforms)
    assert capture.mesh is not None and len(capture.mesh.triangles) > 0
    assert capture.object_name == "01_plate" and capture.distance_cm == 30
    assert capture.metadata.distance_m == pytest.approx(0.30)


def test_discovery_finds_every_capture(synth_root):
    found = {f"{p.parent.name}/{p.name}" for p in maroon.discover_captures(synth_root)}
    assert CAPTURE in found


# --------------------------------------------------------------------------------------- conventions
def test_antenna_layout_is_mirrored_and_sliced():
    file_tx = read_antenna_file(Path(maroon.__file__).parent / "qar50" / "Tx.dat")
    array = load_antenna_array()
    assert array.tx_m.shape == (94, 3) and array.rx_m.shape == (94, 3)
    np.testing.assert_allclose(array.tx_m[0], [-file_tx[1, 0], file_tx[1, 1], 0.0])   # row 1 of the file, x negated
    assert array.tx_m[0, 0] == pytest.approx(0.072)
    np.testing.assert_allclose(np.diff(array.rx_m[:47, 0]), -0.003)                  # mirrored: x decreases
    np.testing.assert_allclose(np.diff(array.tx_m[1:46, 1]), 0.003)


def test_default_grid_intrinsics_match_maroon():
    k = RadarGrid((-0.15, -0.15, 0.25), (0.15, 0.15, 0.40), (301, 301, 151)).intrinsics()
    assert k[0, 0] == pytest.approx(996.678, abs=1e-3) and k[0, 3] == pytest.approx(150.0)
    assert k[1, 1] == pytest.approx(-996.678, abs=1e-3) and k[1, 3] == pytest.approx(150.0)
    assert k[2, 2] == 1000.0


def test_transform_lookup_rule():
    a2r = np.diag([2.0, 2.0, 2.0, 1.0])
    a2r[:3, 3] = [1, 2, 3]
    b2r = np.eye(4)
    b2r[:3, 3] = [0, 0, 1]
    transforms = {"a2radar": a2r, "b2radar": b2r}
    np.testing.assert_allclose(transform_between(transforms, "a", "radar"), a2r)
    np.testing.assert_allclose(transform_between(transforms, "radar", "a"), np.linalg.inv(a2r))
    np.testing.assert_allclose(transform_between(transforms, "a", "b"), np.linalg.inv(b2r) @ a2r)
    with pytest.raises(KeyError, match="c2radar"):
        transform_between(transforms, "c", "radar")


# ------------------------------------------------------------------------------------- safe unpickling
def _npy_with_payload(path: Path, payload: bytes) -> None:
    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "|O", "fortran_order": False, "shape": ()})
    path.write_bytes(header.getvalue() + payload)     # the header writer emits the magic string too


class _Exploit:
    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return (open, (str(self.marker), "w"))


def test_malicious_pickle_is_refused_and_not_executed(tmp_path):
    marker = tmp_path / "pwned"
    path = tmp_path / "000000.npy"
    _npy_with_payload(path, pickle.dumps({"xr": _Exploit(marker)}, protocol=4))
    with pytest.raises(DatasetError, match="refused to load .(io|builtins).open.") as info:
        load_pickled_dict(path)
    assert str(path) in str(info.value)
    assert not marker.exists()


def test_numpy1_module_names_are_admitted(tmp_path):
    frame = {"xr": np.ones((2, 2, 2), np.complex64), "fvec": np.array([72e9, 82e9])}
    payload = pickle.dumps(frame, protocol=3).replace(b"numpy._core.", b"numpy.core.")  # as numpy 1.x wrote
    assert b"numpy.core.multiarray" in payload
    _npy_with_payload(tmp_path / "f.npy", payload)
    np.testing.assert_array_equal(load_pickled_dict(tmp_path / "f.npy")["xr"], frame["xr"])


def test_object_arrays_inside_the_dict_are_refused(tmp_path):
    _npy_with_payload(tmp_path / "f.npy", pickle.dumps({"xr": np.array([1, "a"], dtype=object)}, protocol=4))
    with pytest.raises(DatasetError, match="object array"):
        load_pickled_dict(tmp_path / "f.npy")


# ------------------------------------------------------------------------------------ malformed input
def _frame_path(capture_dir: Path) -> Path:
    return capture_dir / RADAR / "calibrated_data" / "000000.npy"


def _edit_frame(**changes):
    """Replace frame entries by functions of the original frame."""
    def edit(capture_dir: Path):
        path = _frame_path(capture_dir)
        frame = np.load(path, allow_pickle=True).item()       # trusted: our own generator wrote it
        frame.update({key: change(frame) for key, change in changes.items()})
        np.save(path, frame)
    return edit


def _with_nan_at_used_element(frame: dict) -> np.ndarray:
    xr = frame["xr"].copy()
    xr[50, 40, 7] = np.nan        # inside the 94x94 imaging array (row 0 and 95 are sliced away)
    return xr


def _edit_json(relative: str, change):
    def edit(capture_dir: Path):
        path = capture_dir / relative
        data = json.loads(path.read_text())
        change(data)
        path.write_text(json.dumps(data))
    return edit


def _write(relative: str, content: bytes):
    def edit(capture_dir: Path):
        (capture_dir / relative).write_bytes(content)
    return edit


def _remove(relative: str):
    def edit(capture_dir: Path):
        target = capture_dir / relative
        shutil.rmtree(target) if target.is_dir() else target.unlink()
    return edit


def _truncate(relative_fn):
    def edit(capture_dir: Path):
        path = relative_fn(capture_dir)
        data = path.read_bytes()
        path.write_bytes(data[: len(data) // 2])
    return edit


def _set_volume(key, value):
    def change(data):
        data["000000"]["volume"][key] = value
    return change


def _image(relative: str, array: np.ndarray):
    def edit(capture_dir: Path):
        Image.fromarray(array).save(capture_dir / relative)
    return edit


MALFORMED = {
    "metadata missing": (_remove("metadata.json"), "metadata.json", "file is missing"),
    "metadata bad json": (_write("metadata.json", b"{not json"), "metadata.json", "invalid JSON"),
    "metadata distance in cm": (_edit_json("metadata.json", lambda d: d.update(distance_meters=30)),
                                "metadata.json", "in metres"),
    "mask_bb inverted": (_edit_json("metadata.json", lambda d: d.update(mask_bb={"zmin": 0.5, "zmax": 0.2})),
                         "metadata.json", "zmin"),
    "alignment missing": (_remove("alignment.json"), "alignment.json", "missing"),
    "alignment not 4x4": (_edit_json("alignment.json", lambda d: d.update(realsense2radar=[[1, 0], [0, 1]])),
                          "alignment.json", "not a 4x4"),
    "alignment bad bottom row": (_edit_json("alignment.json", lambda d: d.update(
        realsense2radar=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]])), "alignment.json", "bottom row"),
    "radar folder missing": (_remove(RADAR), "30", "no radar folder"),
    "no frames": (_remove(f"{RADAR}/calibrated_data"), "calibrated_data", "missing"),
    "grid size negative": (_edit_json(f"{RADAR}/calibration.json", _set_volume("grid_size", [301, -1, 201])),
                           "calibration.json", "grid_size"),
    "grid inverted": (_edit_json(f"{RADAR}/calibration.json", _set_volume("bb_max", [-0.2, 0.15, 0.4])),
                      "calibration.json", "range"),
    "grid behind array": (_edit_json(f"{RADAR}/calibration.json", _set_volume("bb_min", [-0.15, -0.15, -0.1])),
                          "calibration.json", "z > 0"),
    "xr wrong shape": (_edit_frame(xr=lambda f: f["xr"][:95, :95]), "000000.npy", "(96, 96, F)"),
    "xr real": (_edit_frame(xr=lambda f: f["xr"].real.copy()), "000000.npy", "complex"),
    "xr nan": (_edit_frame(xr=_with_nan_at_used_element), "000000.npy", "NaN or Inf"),
    "fvec in GHz": (_edit_frame(fvec=lambda f: f["fvec"] / 1e9), "000000.npy", "looks like GHz"),
    "fvec length": (_edit_frame(fvec=lambda f: f["fvec"][:-1]), "000000.npy", "frequencies"),
    "fvec not increasing": (_edit_frame(fvec=lambda f: f["fvec"][::-1].copy()), "000000.npy", "increasing"),
    "frame not a dict": (lambda c: np.save(_frame_path(c), np.zeros(3)), "000000.npy", "pickled dict"),
    "frame without xr": (lambda c: np.save(_frame_path(c), {"fvec": np.zeros(3)}), "000000.npy", "no 'xr'"),
    "frame truncated": (_truncate(_frame_path), "000000.npy", "pickle"),
    "depth 8-bit": (_image("realsense/depth/000000.png", np.zeros((480, 640), np.uint8)), "000000.png", "16-bit"),
    "depth wrong size": (_image("realsense/depth/000000.png", np.zeros((240, 320), np.uint16)), "000000.png",
                         "calibration.json"),
    "depth not an image": (_write("realsense/depth/000000.png", b"garbage"), "000000.png", "readable image"),
    "mask wrong size": (_image("realsense/mask/000000.png", np.zeros((10, 10), np.uint8)), "000000.png", "mask is"),
    "realsense calibration no fx": (_edit_json("realsense/calibration.json", lambda d: d["rgb"].pop("fx")),
                                    "calibration.json", "fx"),
    "mesh empty": (_write("photogrammetry/mesh_masked_smoothed.obj", b"# nothing\n"), "mesh_masked_smoothed.obj",
                   "no vertices"),
    "mesh bad indices": (_write("photogrammetry/mesh_masked_smoothed.obj", b"v 0 0 0\nv 1 0 0\nf 1 2 9\n"),
                         "mesh_masked_smoothed.obj", ""),
}


@pytest.mark.parametrize("case", sorted(MALFORMED))
def test_malformed_input_gives_clear_error(capture_copy, case):
    edit, file_part, message = MALFORMED[case]
    edit(capture_copy)
    with pytest.raises(DatasetError) as info:
        maroon.read_capture(capture_copy)
    assert file_part in str(info.value.path) and message in info.value.problem, str(info.value)


def test_missing_optional_parts_are_noted_not_fatal(capture_copy):
    shutil.rmtree(capture_copy / "realsense")
    shutil.rmtree(capture_copy / "photogrammetry")
    capture = maroon.read_capture(capture_copy)
    assert capture.realsense is None and capture.mesh is None and capture.radar is not None
    assert any("realsense" in note for note in capture.notes) and any("photogrammetry" in n for n in capture.notes)


def test_alignment_fallback_to_registration_folder(capture_copy):
    metadata = json.loads((capture_copy / "metadata.json").read_text())
    fallback = capture_copy.parent.parent / "00_registration" / metadata["calibration"]
    fallback.mkdir(parents=True)
    shutil.move(capture_copy / "alignment.json", fallback / "alignment.json")
    capture = maroon.read_capture(capture_copy, parts=())
    assert "realsense2radar" in capture.transforms
    assert any("fallback" in note for note in capture.notes)
    assert [p.name for p in maroon.discover_captures(capture_copy.parent.parent)] == ["30"]


def test_96_and_94_frames_read_the_same(capture_copy):
    before = maroon.read_capture(capture_copy, parts=("radar",)).radar.signal
    _edit_frame(xr=lambda f: f["xr"][1:95, 1:95].copy())(capture_copy)
    np.testing.assert_array_equal(maroon.read_capture(capture_copy, parts=("radar",)).radar.signal, before)


# ---------------------------------------------------------------------------------- command line, read-only
def _run_inspect(root: Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench.maroon.inspect_capture", str(root)], capture_output=True,
                          text=True,
                          timeout=120)


def test_inspect_reports_problem_without_traceback(capture_copy):
    _edit_frame(fvec=lambda f: f["fvec"] / 1e9)(capture_copy)
    result = _run_inspect(capture_copy.parent.parent)
    assert result.returncode == 1
    assert "looks like GHz" in result.stdout and "000000.npy" in result.stdout
    assert "Traceback" not in result.stdout + result.stderr


def test_inspect_on_missing_root_exits_cleanly(tmp_path):
    result = _run_inspect(tmp_path / "nope")
    assert result.returncode == 2 and "dataset root is not a directory" in result.stderr
    assert "Traceback" not in result.stderr


def test_read_only_dataset_stays_byte_identical(capture_copy):
    root = capture_copy.parent.parent
    before, paths_before = _tree_digest(root), sorted(root.rglob("*"))
    for path in [root, *root.rglob("*")]:
        path.chmod(path.stat().st_mode & ~(stat.S_IWUSR | stat.S_IWGRP | stat.S_IWOTH))
    try:
        capture = maroon.read_capture(capture_copy)
        assert capture.radar is not None and capture.realsense is not None and capture.mesh is not None
        result = _run_inspect(root)
        assert result.returncode == 0, result.stdout + result.stderr
    finally:
        for path in [root, *root.rglob("*")]:
            path.chmod(path.stat().st_mode | stat.S_IWUSR)
    assert _tree_digest(root) == before          # (as root, permissions alone would not stop a write)
    assert sorted(root.rglob("*")) == paths_before
