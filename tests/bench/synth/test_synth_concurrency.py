"""Synthetic generation shared by concurrent jobs: one writer per root, captures complete and identical, no
temp folders left, stale leftovers of a crashed run harmless, foreign data never written (bench.synth.ownership)."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

from bench.maroon.reader import discover_captures
from bench.synth import SynthConfig, generate_catalogue
from bench.synth.ownership import ForeignRootError

OBJECTS = ["01_plate", "03_sphere"]
FAST = SynthConfig(frequency_points=16)
# A worker: import everything, say so, wait for the common start signal, then generate and report the statuses.
WORKER = """
import json, sys
from bench.synth import SynthConfig, generate_catalogue
print("ready", flush=True)
sys.stdin.readline()
results = generate_catalogue(sys.argv[1], [30], sys.argv[2:], SynthConfig(frequency_points=16))
print(json.dumps([r.status for r in results]), flush=True)
"""


def _capture_files(root):
    """{relative path: bytes} of every file inside the capture folders."""
    return {p.relative_to(root).as_posix(): p.read_bytes() for p in root.glob("*/30/**/*") if p.is_file()}


def _hidden_folders(root):
    return [p for p in root.rglob(".*") if p.is_dir()]


def _dead_pid() -> int:
    return int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                              text=True, check=True).stdout)


def test_concurrent_processes_on_an_empty_root_generate_each_capture_once(tmp_path):
    root = tmp_path / "missing" / "synthetic"
    workers = [subprocess.Popen([sys.executable, "-c", WORKER, str(root), *OBJECTS], stdin=subprocess.PIPE,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for _ in range(3)]
    for worker in workers:                               # all imported: start them together
        assert worker.stdout.readline().strip() == "ready", worker.stderr.read()
    for worker in workers:
        worker.stdin.write("\n")
        worker.stdin.flush()
    outputs = [worker.communicate(timeout=300) for worker in workers]
    assert [w.returncode for w in workers] == [0, 0, 0], [err for _, err in outputs]
    statuses = [status for out, _ in outputs for status in json.loads(out)]
    assert sorted(statuses) == ["cached"] * 4 + ["generated"] * 2           # each capture generated exactly once

    reference = tmp_path / "reference"
    generate_catalogue(reference, [30], OBJECTS, FAST)
    files = _capture_files(root)
    assert len(files) > 10 and files == _capture_files(reference)          # complete and identical
    assert _hidden_folders(root) == []                                       # no temp folders left
    manifest = json.loads((root / "synth_manifest.json").read_text())["captures"]
    assert sorted(manifest) == ["01_plate/30", "03_sphere/30"]


def test_captures_built_at_once_are_the_files_built_one_at_a_time(tmp_path, monkeypatch):
    """generate_catalogue builds several captures at once (threads): each capture's files are byte for byte those
    of a run that builds one at a time, and the manifest records every capture."""
    from bench.synth import workers

    monkeypatch.setattr(workers, "capture_workers", lambda: 2)
    concurrent = generate_catalogue(tmp_path / "at_once", [30], OBJECTS, FAST)
    monkeypatch.setattr(workers, "capture_workers", lambda: 1)
    generate_catalogue(tmp_path / "one_by_one", [30], OBJECTS, FAST)
    assert [r.status for r in concurrent] == ["generated"] * 2
    files = _capture_files(tmp_path / "at_once")
    assert len(files) > 10 and files == _capture_files(tmp_path / "one_by_one")
    manifest = json.loads((tmp_path / "at_once" / "synth_manifest.json").read_text())["captures"]
    assert sorted(manifest) == [f"{o}/30" for o in OBJECTS]


def test_stale_temp_folder_of_a_dead_process_does_not_break_a_run(tmp_path):
    root = tmp_path / "synthetic"
    stale = root / "01_plate" / f".30.tmp-{_dead_pid()}-0123abcd"      # a first run that crashed mid-capture
    (stale / "realsense").mkdir(parents=True)
    (stale / "metadata.json").write_text("{")
    results = generate_catalogue(root, [30], ["01_plate"], FAST)           # no manifest yet: still the generator's
    assert [r.status for r in results] == ["generated"]
    assert not stale.exists() and _hidden_folders(root) == []
    assert discover_captures(root) == [root / "01_plate" / "30"]
    assert [r.status for r in generate_catalogue(root, [30], ["01_plate"], FAST)] == ["cached"]


def test_a_root_with_other_data_is_refused_and_left_untouched(tmp_path):
    root = tmp_path / "maroon"
    (root / "01_plate" / "30").mkdir(parents=True)
    (root / "01_plate" / "30" / "metadata.json").write_text("{}")
    before = sorted(root.rglob("*"))
    with pytest.raises(ForeignRootError, match="generator did not write"):
        generate_catalogue(root, [30], ["01_plate"], FAST)
    assert sorted(root.rglob("*")) == before                                  # not even a lock file


def test_a_manifest_naming_existing_captures_never_lets_them_be_overwritten(tmp_path):
    """A manifest that lists the real captures by name (with a stale hash) grants no right to replace them: only a
    capture byte for byte as the generator recorded it is regenerated."""
    root = tmp_path / "root"
    generate_catalogue(root, [30], ["01_plate"], FAST)
    manifest_path = root / "synth_manifest.json"
    manifest = json.loads(manifest_path.read_text())
    manifest["captures"]["01_plate/30"]["hash"] = "stale"
    manifest_path.write_text(json.dumps(manifest))
    assert generate_catalogue(root, [30], ["01_plate"], FAST)[0].status == "generated"   # ours: replaced

    manifest = json.loads(manifest_path.read_text())
    manifest["captures"]["01_plate/30"]["hash"] = "stale"
    manifest_path.write_text(json.dumps(manifest))
    metadata = root / "01_plate" / "30" / "metadata.json"
    metadata.write_text(metadata.read_text().replace("metal plate", "someone's plate"))    # no longer the generator's
    before = _capture_files(root)
    with pytest.raises(ForeignRootError, match="not byte for byte"):
        generate_catalogue(root, [30], ["01_plate"], FAST)
    assert _capture_files(root) == before
    del manifest["captures"]["01_plate/30"]["content"]                  # an entry without the content digest
    manifest_path.write_text(json.dumps(manifest))
    with pytest.raises(ForeignRootError, match="not overwriting"):
        generate_catalogue(root, [30], ["01_plate"], FAST)
    assert _capture_files(root) == before


def test_a_claimed_manifest_is_whole_the_moment_it_exists(tmp_path, monkeypatch):
    """claim() makes the manifest appear already written: a second process that looks right after the name
    appears (here: inside the link call) finds a manifest it can verify, never an empty file (the race a
    fresh-clone CI run once hit with three generators starting together)."""
    import os

    from bench.synth import ownership

    root = tmp_path / "synthetic"
    seen = []
    real_link = os.link

    def link_then_look(source, target, *args, **kwargs):
        real_link(source, target, *args, **kwargs)
        ownership.verify_manifest(root)                      # what a concurrent claimant's `exclusive` does first
        seen.append(json.loads((root / ownership.MANIFEST_NAME).read_text()))

    monkeypatch.setattr(ownership.os, "link", link_then_look)
    ownership.claim(root)
    assert seen == [{"captures": {}}]
    assert sorted(p.name for p in root.iterdir()) == [ownership.MANIFEST_NAME]    # the temp file is gone


def test_a_file_system_without_hard_links_still_claims_the_root(tmp_path, monkeypatch):
    from bench.synth import ownership

    def no_links(*args, **kwargs):
        raise PermissionError(1, "Operation not permitted")

    monkeypatch.setattr(ownership.os, "link", no_links)
    root = tmp_path / "synthetic"
    ownership.claim(root)
    ownership.verify_manifest(root)
    assert sorted(p.name for p in root.iterdir()) == [ownership.MANIFEST_NAME]
