"""The file system as an attacker shapes it: FIFOs (which would block forever), devices (`/dev/zero` never ends),
sockets, folders where files belong, symbolic links out of the dataset or in a loop, and folder names with a
newline, bytes that are not UTF-8 or superscript digits, and a forged generator manifest. Each ends in one
DatasetError naming the path (or a
warning and a skip, for names), under a time cap (a FIFO that blocks fails the test instead of hanging it); valid
data - links inside the dataset, a capture folder linked from another disk, accented names - still reads."""
from __future__ import annotations

import dataclasses
import json
import logging
import os
import socket
from pathlib import Path

import pytest

from bench.harness.store import Store, capture_files
from bench.maroon import reader as maroon
from bench.synth import SynthConfig, generate_capture
from bench.synth.ownership import ForeignRootError
from methods.domain.errors import DatasetError

from hostile_tools import RADAR, bounded, copy_capture, frame_file, replace_with_fifo, replace_with_link, tree_digest

FILES = {"metadata": "metadata.json", "alignment": "alignment.json", "calibration": f"{RADAR}/calibration.json",
         "frame": f"{RADAR}/calibrated_data/000000.npy", "depth": "realsense/depth/000000.png",
         "mask": "realsense/mask/000000.png", "realsense_calibration": "realsense/calibration.json",
         "mesh": "photogrammetry/mesh_masked_smoothed.obj"}


@pytest.fixture(scope="module")
def source_capture(synth_capture):
    return synth_capture("01_plate", 30, frequency_points=16)


@pytest.fixture
def capture(source_capture, tmp_path) -> Path:
    return copy_capture(source_capture, tmp_path / "root")


def _bind_socket(path: Path) -> None:
    path.unlink()
    cwd = os.getcwd()
    os.chdir(path.parent)                        # a relative name: socket paths are limited to 108 bytes
    try:
        with socket.socket(socket.AF_UNIX) as sock:
            sock.bind(path.name)
    finally:
        os.chdir(cwd)


def _directory(path: Path) -> None:
    path.unlink()
    path.mkdir()


KINDS = {
    "fifo": (replace_with_fifo, "is a FIFO"),
    "dev_zero": (lambda p: replace_with_link(p, "/dev/zero"), "outside the dataset root"),
    "dev_null": (lambda p: replace_with_link(p, "/dev/null"), "outside the dataset root"),
    "outside_root": (lambda p: replace_with_link(p, "/etc/hostname"),
                     "outside the dataset root"),
    "socket": (_bind_socket, "is a socket"),
    "directory": (_directory, "is a directory"),
    "link_loop": (lambda p: replace_with_link(p, p.name), "Too many levels of symbolic links"),
}


@pytest.mark.parametrize("kind", sorted(KINDS))
@pytest.mark.parametrize("which", sorted(FILES))
def test_a_dataset_file_that_is_no_regular_file_inside_the_dataset_is_refused(capture, which, kind):
    path = capture / FILES[which]
    make, message = KINDS[kind]
    make(path)
    before = tree_digest(capture.parent.parent)
    with pytest.raises(DatasetError) as info, bounded(seconds=20):
        maroon.read_capture(capture)
    assert info.value.path == path and message in info.value.problem, str(info.value)
    assert tree_digest(capture.parent.parent) == before


def test_a_fifo_is_refused_by_the_store_too(capture, tmp_path):
    replace_with_fifo(frame_file(capture))
    with pytest.raises(DatasetError, match="is a FIFO"), bounded(seconds=20):
        Store(tmp_path / "store").capture_digest(capture_files(capture, -1, ("radar", "mesh"), False))


def test_a_link_to_a_huge_file_outside_is_refused_before_hashing(capture, tmp_path):
    """The store hashes what the reader would read: never a file outside the dataset (here a sparse 64 GiB one)."""
    huge = tmp_path / "huge.npy"
    with open(huge, "wb") as handle:
        handle.truncate(64 << 30)
    replace_with_link(frame_file(capture), huge)
    with pytest.raises(DatasetError, match="outside the dataset root"), bounded(seconds=20):
        capture_files(capture, -1, ("radar",), False)


def test_a_regular_file_beyond_its_size_limit_is_refused_unread(capture):
    path = capture / "metadata.json"
    with open(path, "r+b") as handle:
        handle.truncate(1 << 40)                                   # sparse: a 1 TiB metadata.json
    with pytest.raises(DatasetError, match="json_bytes"), bounded(seconds=20):
        maroon.read_capture(capture)


def test_links_inside_the_dataset_are_followed(capture):
    root = capture.parent.parent
    shared = root / "shared"
    shared.mkdir()
    for name in ("metadata.json", "alignment.json"):
        (capture / name).rename(shared / name)
        (capture / name).symlink_to(Path("../../shared") / name)
    with bounded():
        read = maroon.read_capture(capture)
    assert read.radar is not None and read.mesh is not None


def test_a_capture_folder_linked_from_another_disk_reads(source_capture, tmp_path):
    """The dataset root of a capture is its grandparent as given and as resolved: a linked capture folder reads."""
    elsewhere = copy_capture(source_capture, tmp_path / "other_disk")
    (tmp_path / "root" / "01_plate").mkdir(parents=True)
    (tmp_path / "root" / "01_plate" / "30").symlink_to(elsewhere)
    with bounded():
        read = maroon.read_capture(tmp_path / "root" / "01_plate" / "30")
    assert read.radar is not None and read.realsense is not None


# ------------------------------------------------------------------------------------------------- names
def test_a_superscript_digit_is_no_distance_folder(source_capture, tmp_path, caplog):
    copy_capture(source_capture, tmp_path / "root", distance="3\u00b3")
    copy_capture(source_capture, tmp_path / "root", distance="30")
    with caplog.at_level(logging.WARNING, logger="bench"):
        found = maroon.discover_captures(tmp_path / "root")
    assert [p.name for p in found] == ["30"]
    assert "not a distance folder" in caplog.text and "3\u00b3" in caplog.text
    with pytest.raises(DatasetError, match="ASCII digits"):
        maroon.read_capture(tmp_path / "root" / "01_plate" / "3\u00b3")


@pytest.mark.parametrize("name, problem", [("01\nplate", "control characters"),
                                           (os.fsdecode(b"01_pl\xffte"), "not valid UTF-8")])
def test_unrepresentable_object_names_are_skipped_with_a_warning(source_capture, tmp_path, caplog, name, problem):
    copy_capture(source_capture, tmp_path / "root", object_name=name)
    copy_capture(source_capture, tmp_path / "root", object_name="02_ok")
    with caplog.at_level(logging.WARNING, logger="bench"):
        found = maroon.discover_captures(tmp_path / "root")
    assert [p.parent.name for p in found] == ["02_ok"] and problem in caplog.text
    warning = [r.getMessage() for r in caplog.records if problem in r.getMessage()]
    assert len(warning) == 1 and "\n" not in warning[0]
    with pytest.raises(DatasetError) as info:
        maroon.read_capture(tmp_path / "root" / name / "30")
    assert problem in info.value.problem and "\n" not in str(info.value)
    str(info.value).encode("utf-8")                                  # printable on any UTF-8 terminal


def test_every_skipped_folder_is_counted_when_nothing_is_left(source_capture, tmp_path):
    copy_capture(source_capture, tmp_path / "root", object_name="01\nplate")
    with pytest.raises(DatasetError, match="1 folder"):
        maroon.discover_captures(tmp_path / "root")


def test_accented_and_wide_names_are_valid_data(source_capture, tmp_path):
    copy_capture(source_capture, tmp_path / "root", object_name="01_w\u00fcrfel_\u7acb\u65b9")
    (found,) = maroon.discover_captures(tmp_path / "root")
    assert maroon.read_capture(found, parts=()).object_name == "01_w\u00fcrfel_\u7acb\u65b9"


# ------------------------------------------------------------------------------- forged generator manifest
def _forged_root(source_capture, tmp_path, manifest: dict) -> Path:
    root = tmp_path / "real_dataset"
    copy_capture(source_capture, root)
    (root / "synth_manifest.json").write_text(json.dumps(manifest))
    return root


@pytest.mark.parametrize("manifest, extra, message", [
    ({"captures": {}}, None, "does not list"),                              # the forged manifest
    ({"captures": {"01_plate/30": {"hash": "x"}}}, "README.txt", "did not write"),
    ({"captures": []}, None, "lists no captures"),
    ({"captures": {}}, ".synth.lock->/etc/hostname", "synth.lock"),          # its lock forged as a link
])
def test_a_forged_manifest_grants_no_write(source_capture, tmp_path, manifest, extra, message):
    root = _forged_root(source_capture, tmp_path, manifest)
    if extra == "README.txt":
        (root / "README.txt").write_text("the real dataset")
    elif extra:
        (root / ".synth.lock").symlink_to("/etc/hostname")
    before = tree_digest(root)
    with pytest.raises(ForeignRootError, match=message), bounded(seconds=60):
        generate_capture(root, "03_sphere", 30, dataclasses.replace(SynthConfig(), frequency_points=16))
    assert tree_digest(root) == before                                      # not even a lock file


def test_a_manifest_linked_from_outside_is_not_trusted(source_capture, tmp_path):
    root = _forged_root(source_capture, tmp_path, {"captures": {"01_plate/30": {}}})
    outside = tmp_path / "manifest.json"
    (root / "synth_manifest.json").rename(outside)
    (root / "synth_manifest.json").symlink_to(outside)
    before = tree_digest(root)
    with pytest.raises(ForeignRootError, match="outside the dataset root"), bounded(seconds=60):
        generate_capture(root, "01_plate", 30, dataclasses.replace(SynthConfig(), frequency_points=16), force=True)
    assert tree_digest(root) == before
