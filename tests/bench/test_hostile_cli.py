"""The hostile kinds through the real entry points, as a user runs them: `python -m bench` and `python -m
bench.maroon.inspect_capture` in subprocesses capped at 3 GiB of address space and 90 s each. Every case ends in
exactly one line
`error: <the file>: <what is wrong>` and exit 2 (inspect: one `!!` problem line naming the file, exit 1), the
dataset stays byte-identical and nothing is executed; valid data beside hostile names still gives its row, and
a forged generator manifest makes nothing be written.

The commands run two at a time (the machine has 2 cores; each is mostly interpreter start-up) in one module
fixture; the tests then read their results."""
from __future__ import annotations

import json
import os
import shutil
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

from bench.stress import hostile_inputs as hi

from hostile_tools import (
    RADAR,
    copy_capture,
    frame_file,
    one_error_line,
    replace_with_fifo,
    replace_with_link,
    run_capped,
    tree_digest,
)

MARKER = "hostile_cli_pickle_ran"


def _write(relative: str, data):
    return lambda capture: (capture / relative).write_bytes(data() if callable(data) else data)


def _json(relative: str, change):
    def edit(capture: Path):
        data = json.loads((capture / relative).read_text())
        change(data)
        (capture / relative).write_text(json.dumps(data))
    return edit


FRAME = f"{RADAR}/calibrated_data/000000.npy"
CASES = {       # case: (edit of the capture copy, the file the error names)
    "billion_laughs": (_write(FRAME, lambda: hi.npy_pickle(hi.billion_laughs_pickle())), FRAME),
    "void_scalar": (_write(FRAME, hi.void_scalar_frame), FRAME),
    "zero_stride": (_write(FRAME, hi.zero_stride_frame), FRAME),
    "deep_pickle": (_write(FRAME, lambda: hi.npy_pickle(hi.deep_list_pickle(100_000))), FRAME),
    "os_system": (lambda c: frame_file(c).write_bytes(hi.os_system_frame(str(c.parents[1] / MARKER))), FRAME),
    "frame_dev_zero": (lambda c: replace_with_link(frame_file(c), "/dev/zero"), FRAME),
    "metadata_fifo": (lambda c: replace_with_fifo(c / "metadata.json"), "metadata.json"),
    "metadata_deep_json": (_write("metadata.json", b"[" * 100_000 + b"]" * 100_000), "metadata.json"),
    "metadata_5000_digits": (_write("metadata.json", hi.json_cases()["json_int_5000_digits"]), "metadata.json"),
    "mask_erosion_4000": (_json("metadata.json", lambda d: d.update(mask_erosion=4000)), "metadata.json"),
    "grid_1_6e9_pixels": (_json(f"{RADAR}/calibration.json",
                                lambda d: d["000000"]["volume"].update(grid_size=[40000, 40000, 1])),
                          f"{RADAR}/calibration.json"),
    "grid_bb_max_string": (_json(f"{RADAR}/calibration.json",
                                 lambda d: d["000000"]["volume"].update(bb_max=["0.15", 0.15, 0.4])),
                           f"{RADAR}/calibration.json"),
    "depth_png_bomb": (_write("realsense/depth/000000.png", lambda: hi.png_declaring(20000, 20000)),
                       "realsense/depth/000000.png"),
    "mask_png_bomb": (_write("realsense/mask/000000.png", lambda: hi.png_declaring(30000, 30000, 8)),
                      "realsense/mask/000000.png"),
    "alignment_scale_1e300": (_json("alignment.json", lambda d: d.update(
        photogrammetry2radar=np.diag([1e300, 1e300, 1e300, 1.0]).tolist())), "alignment.json"),
}
# a representative subset, one command each (every case also runs through inspect, and in-process in the other
# test_hostile_* files): a pickle, a FIFO that would hang, a size declared by JSON, an image bomb
BENCH_CASES = ("billion_laughs", "metadata_fifo", "grid_1_6e9_pixels", "depth_png_bomb")


def _bench(root: Path, out: Path) -> list[str]:
    return ["-m", "bench", "dataset=maroon", f"dataset.root={root}", "method=mm2fsk", "freq=d05", "prior=realsense",
            "store.dir=null", f"hydra.run.dir={out}"]


@pytest.fixture(scope="module")
def runs(synth_capture, tmp_path_factory):
    """Build every case; run `python -m bench` per BENCH_CASES case, one `python -m bench.maroon.inspect_capture` over
    a root
    holding all cases, and `python -m bench` over a root where valid data sits beside unrepresentable names."""
    source = synth_capture("01_plate", 30, frequency_points=16)
    base = tmp_path_factory.mktemp("hostile_cli")
    jobs, roots = {}, {}
    inspect_root = base / "inspect_root"
    for number, (case, (edit, _)) in enumerate(sorted(CASES.items()), start=1):
        edit(copy_capture(source, inspect_root, object_name=f"{number:02d}_{case}"))
        if case in BENCH_CASES:
            roots[case] = base / case
            edit(copy_capture(source, roots[case]))
            jobs[case] = _bench(roots[case], base / "out" / case)
    jobs["inspect"] = ["-m", "bench.maroon.inspect_capture", str(inspect_root)]
    roots["inspect"] = inspect_root
    names = base / "names_root"
    copy_capture(source, names, object_name="01\nplate")
    copy_capture(source, names, object_name=os.fsdecode(b"02_pl\xffte"))
    copy_capture(source, names, distance="3\u00b3")
    copy_capture(source, names, object_name="04_w\u00fcrfel")
    jobs["names"], roots["names"] = _bench(names, base / "out" / "names"), names
    forged = base / "forged_root"                                    # a dataset with a forged generator manifest
    copy_capture(source, forged)
    (forged / "synth_manifest.json").write_text(json.dumps({"captures": {}}))
    jobs["forged"] = ["dataset=synthetic" if arg == "dataset=maroon" else arg
                      for arg in _bench(forged, base / "out" / "forged")]
    roots["forged"] = forged
    before = {name: tree_digest(root) for name, root in roots.items()}
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = dict(zip(jobs, pool.map(run_capped, jobs.values()), strict=False))
    after = {name: tree_digest(root) for name, root in roots.items()}
    yield {"results": results, "roots": roots, "before": before, "after": after, "base": base}
    shutil.rmtree(base, ignore_errors=True)


@pytest.mark.parametrize("case", BENCH_CASES)
def test_bench_ends_in_one_error_line_naming_the_file(runs, case):
    result = runs["results"][case]
    line = one_error_line(result.stderr)
    expected = runs["roots"][case] / "01_plate" / "30" / CASES[case][1]
    assert result.returncode == 2 and line.startswith(f"error: {expected}: "), result.stderr
    assert "Traceback" not in result.stdout + result.stderr
    assert runs["after"][case] == runs["before"][case]               # byte-identical, nothing added


def test_inspect_names_each_hostile_file_once_and_survives_all(runs):
    result = runs["results"]["inspect"]
    assert result.returncode == 1, result.stdout + result.stderr     # no signal (the void scalar crashed it)
    assert "Traceback" not in result.stdout + result.stderr and result.stderr.strip() == ""
    blocks = _blocks(result.stdout)
    assert len(blocks) == len(CASES), result.stdout
    for number, (case, (_, relative)) in enumerate(sorted(CASES.items()), start=1):
        problems = [line for line in blocks[f"{number:02d}_{case}/30"] if line.startswith("  !! ")]
        expected = runs["roots"]["inspect"] / f"{number:02d}_{case}" / "30" / relative
        assert len(problems) == 1 and problems[0].startswith(f"  !! {expected}: "), (case, problems)
    assert f"{len(CASES)} capture(s), 0 ok, {len(CASES)} with problems" in result.stdout
    assert runs["after"]["inspect"] == runs["before"]["inspect"]
    assert not list(runs["base"].rglob(MARKER))                        # the os.system pickle never ran


def _blocks(stdout: str) -> dict[str, list[str]]:
    blocks, current = {}, None
    for line in stdout.splitlines():
        if not line.startswith(" ") and line.endswith(("PROBLEMS", "ok")) and "capture(s)" not in line:
            current = line.split()[0]
            blocks[current] = []
        elif current is not None and line.startswith(" "):
            blocks[current].append(line)
    return blocks


def test_valid_data_beside_unrepresentable_names_still_gives_its_row(runs):
    result = runs["results"]["names"]
    assert result.returncode == 0, result.stderr
    rows = (runs["base"] / "out" / "names" / "results.csv").read_text().splitlines()
    assert len(rows) == 2 and rows[1].startswith("04_w\u00fcrfel,30,"), rows
    output = result.stdout + result.stderr
    for skipped in ("01\\nplate: skipped", "02_pl\\xffte: skipped", "3\u00b3: skipped"):
        assert skipped in output, output
    assert runs["after"]["names"] == runs["before"]["names"]


def test_a_forged_manifest_makes_python_m_bench_read_not_write(runs):
    """`dataset=synthetic dataset.root=<a dataset holding a forged synth_manifest.json>`: nothing is generated (the
    issue saw 25 paths changed), the capture there is read as it is."""
    result = runs["results"]["forged"]
    assert result.returncode == 0, result.stderr
    assert "generating nothing" in result.stdout + result.stderr
    assert len((runs["base"] / "out" / "forged" / "results.csv").read_text().splitlines()) == 2
    assert runs["after"]["forged"] == runs["before"]["forged"]
