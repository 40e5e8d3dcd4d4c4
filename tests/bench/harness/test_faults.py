"""Faults and absurd settings (issue 26): each class ends in one line and a non-zero exit, or in a correct recovery,
with the dataset unchanged and, after the fault, the next run giving the same rows and depth maps as a clean run.

* absurd settings: every key checked where the configuration is composed (bench.harness.validate), one line
  naming key, value and range; the app and a joblib multirun refuse them before any work;
* output faults: a file-size limit (RLIMIT_FSIZE: the same failed write as a full disk) while writing the store's
  HDF5 cell or the run's arrays.h5, SIGKILL mid-run, the output folder vanishing mid-run;
* the store as a trust boundary: truncated, wrong-type or foreign rows, truncated HDF5, external and soft links,
  virtual and externally stored datasets, arrays of the wrong shape, a cell linked out of the store: each
  computed again with a warning naming it, never served;
* the merge of a job CSV cut mid-row; error lines and failure reasons that name their file or cause; the code
  version from the import graph.

Small captures (16 frequencies, 2FSK d05): each in-process run takes 1-2 s, each subprocess 5-10 s on two loaded
cores; subprocesses run two at a time.
"""
from __future__ import annotations

import json
import logging
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from bench import cli
from bench.harness import validate
from bench.harness.app import CONFIG_DIR, run
from bench.harness.results import MEASURED_COLUMNS
from bench.harness.store import Store
from bench.report.merge import merge
from methods.domain.errors import DatasetError, UsageError

from hostile_tools import REPO, copy_capture, frame_file, one_error_line, tree_digest

VOLATILE = (*MEASURED_COLUMNS, "hostname", "cached")             # columns that differ between equal runs


def _overrides(root: Path, store: Path | None, *extra: str) -> list[str]:
    return ["dataset=maroon", f"dataset.root={root}", "method=2fsk", "freq=d05", "prior=none",
            f"store.dir={store if store is not None else 'null'}", *extra]


def _cfg(*overrides: str):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides))


def _stable(rows) -> pd.DataFrame:
    table = pd.DataFrame(rows) if not isinstance(rows, pd.DataFrame) else rows
    drop = [c for c in table.columns if c in VOLATILE or (c.startswith("t_") and c.endswith("_ms"))]
    return table.drop(columns=drop).sort_values(["object", "frame"]).reset_index(drop=True)


def _depth_pngs(out: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted((out / "depth").glob("*.png"))}


def _no_temp_files(*folders: Path) -> list[Path]:
    return [p for folder in folders if folder.exists() for p in folder.rglob("*.tmp")]


@pytest.fixture(scope="module")
def root(synth_capture, tmp_path_factory):
    """Two small captures (16 frequencies)."""
    root = tmp_path_factory.mktemp("faults_root")
    for name in ("01_plate", "03_sphere"):
        copy_capture(synth_capture(name, 30, frequency_points=16), root, name, "30")
    return root


@pytest.fixture(scope="module")
def dataset_digest(root):
    """The dataset's bytes before any fault (the last test compares)."""
    return tree_digest(root)


@pytest.fixture(scope="module")
def reference(root, dataset_digest, tmp_path_factory):
    """A clean run (rows, depth PNGs) and its filled store, to compare every recovery with."""
    base = tmp_path_factory.mktemp("faults_reference")
    rows = run(_cfg(*_overrides(root, base / "store")), base / "out")
    return {"rows": _stable(rows), "pngs": _depth_pngs(base / "out"), "store": base / "store", "out": base / "out"}


def _bench(args: list[str], cwd: Path, limit_bytes: int | None = None, **popen) -> subprocess.Popen:
    def limit():
        if limit_bytes is not None:
            resource.setrlimit(resource.RLIMIT_FSIZE, (limit_bytes, limit_bytes))
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    return subprocess.Popen([sys.executable, "-m", "bench", *args], cwd=cwd, env=env, preexec_fn=limit, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, **popen)


def _finish(proc: subprocess.Popen, timeout: float = 180) -> tuple[int, str]:
    try:
        _, stderr = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        pytest.fail("a run hung")
    return proc.returncode, stderr


# ---- absurd settings ----------------------------------------------------------------------------------------

ABSURD = {   # override(s) -> the start of the one line
    "grid_nxy_1e9": (["grid=coarse", "grid.override.nxy=1e9"],
                     "grid.override.nxy=1000000000.0: must be a whole number >= 2 and <= 1024"),
    "grid_nxy_fraction": (["grid=coarse", "grid.override.nxy=50.5"], "grid.override.nxy=50.5: must be a whole number"),
    "grid_nz_negative": (["grid=coarse", "grid.override.nz=-5"], "grid.override.nz=-5: must be a whole number >= 1"),
    "grid_xy_half_1e300": (["grid=coarse", "grid.override.xy_half_m=1e300"],
                           "grid.override.xy_half_m=1e+300: must be a number > 0 and <= 1"),
    "grid_xy_half_negative": (["grid=coarse", "grid.override.xy_half_m=-0.15"],
                              "grid.override.xy_half_m=-0.15: must be a number > 0"),
    "grid_z_half_zero": (["grid=coarse", "grid.override.z_half_m=0"], "grid.override.z_half_m=0: must be a number > 0"),
    "threshold_negative": (["threshold_db=-3"], "threshold_db=-3: must be a number >= 0 and <= 1529"),
    "threshold_nan": (["threshold_db=nan"], "threshold_db=nan: must be a number >= 0"),
    "threshold_text": (["threshold_db=loud"], "threshold_db=loud: must be a number"),
    "frame_text": (["dataset.frame=last"], "dataset.frame=last: must be an integer (-1 = the last frame), 'all'"),
    "captures_escape": (["dataset.captures=[../../etc]"], "dataset.captures=../../etc: must be a folder"),
    "frequencies_negative": (["freq.f_ghz=[-82.0,-81.45]"], "freq.f_ghz=-82.0: must be a number > 0"),
    "frequencies_repeated": (["freq.f_ghz=[82.0,82.0]"], "freq.f_ghz=[82.0, 82.0]: must be distinct frequencies"),
    "frequencies_empty": (["freq.f_ghz=[]"], "freq.f_ghz=[]: must be null (every frequency)"),
    "scalar_prior_negative": (["prior.scalar_m=-0.4"], "prior.scalar_m=-0.4: must be a number > 0 and <= 10"),
    "scalar_prior_text": (["prior.scalar_m=near"], "prior.scalar_m=near: must be a number"),
    "roi_step_zero": (["+roi=auto", "+roi.lattice_step_m=0"], "roi.lattice_step_m=0: must be a number > 0"),
    "roi_margin_nan": (["+roi=auto", "+roi.keep_margin_db=nan"], "roi.keep_margin_db=nan: must be a number >= 0"),
    "roi_switch_text": (["+roi=none", "+roi.fsk_keep=maybe"], "roi.fsk_keep=maybe: must be true or false"),
    "roi_unknown": (["+roi=none", "+roi.bogus=1"], "roi={'name': 'none', 'preset': 'none', 'bogus': 1}: unknown roi"),
    "profile_prior": (["profile.prior=fair"], "profile.prior=fair: must be sound or faithful"),
    "empty_filtered_text": (["dataset.empty_filtered=sometimes"], "dataset.empty_filtered=sometimes: must be true"),
    "workers_negative": (["evaluation.workers=-2"], "evaluation.workers=-2: must be a whole number >= 0"),
    "workers_text": (["evaluation.workers=many"], "evaluation.workers=many: must be a whole number"),
}


@pytest.mark.parametrize("case", sorted(ABSURD))
def test_an_absurd_setting_is_one_line_naming_key_value_and_range(tmp_path, case):
    overrides, expected = ABSURD[case]
    cfg = _cfg(*_overrides(tmp_path, None, *overrides))
    with pytest.raises(cli.UserError) as caught:
        validate.check(cfg)
    assert str(caught.value).startswith(expected), str(caught.value)
    assert "\n" not in str(caught.value)


def test_every_shipped_cell_and_experiment_passes_the_checks(tmp_path):
    """The checks refuse nothing the configs ship (so the cases above fail for their value, not for the rule)."""
    cells = sorted(p.stem for p in (CONFIG_DIR / "cell").glob("*.yaml"))
    for cell in cells:
        validate.check(_cfg(*_overrides(tmp_path, None, f"cell={cell}")))
    for grid in ("bp_cpu", "coarse", "paper", "from_capture"):
        validate.check(_cfg(*_overrides(tmp_path, None, f"grid={grid}", "method=bp")))
    for roi in ("all", "auto", "none"):
        validate.check(_cfg(*_overrides(tmp_path, None, f"+roi={roi}", "dataset.frame=all", "profile=faithful")))


def test_a_grid_larger_than_the_machines_memory_is_refused(tmp_path, monkeypatch):
    cfg = _cfg(*_overrides(tmp_path, None, "method=bp", "grid=paper"))
    validate.check(cfg)                                                      # fits any machine running the tests
    pages = {"SC_PHYS_PAGES": (256 << 20) // 4096, "SC_PAGE_SIZE": 4096}     # a machine of 256 MiB
    monkeypatch.setattr(validate.os, "sysconf", lambda name: pages[name])
    with pytest.raises(cli.UserError, match=r"^grid=paper: bp on its 301 x 301 x 201 grid needs about 0\.\d GiB .* "
                                            r"this machine has 0\.2 GiB: use a smaller grid"):
        validate.check(cfg)
    validate.check(cfg, memory=False)                                        # the SLURM launcher's check


@pytest.mark.parametrize("n_jobs, ok", [(1, True), (2, True), (-1, True), (0, False), (-10_000, False),
                                        (1.5, False), ("two", False)])
def test_joblib_n_jobs(n_jobs, ok):
    launcher = OmegaConf.create({"_target_": "hydra_plugins.hydra_joblib_launcher.joblib_launcher.JoblibLauncher",
                                 "n_jobs": n_jobs})
    if ok:
        validate.check_launcher(launcher)
    else:
        with pytest.raises(cli.UserError, match=rf"^hydra.launcher.n_jobs={n_jobs}: must be a whole number"):
            validate.check_launcher(launcher)


def test_the_app_and_a_multirun_refuse_absurd_settings_before_any_work(root, tmp_path):
    before = tree_digest(root)
    runs = {"app": ["grid=coarse", "grid.override.nxy=1e9", f"hydra.run.dir={tmp_path / 'out'}"],
            "joblib": ["-m", "hydra/launcher=local", "hydra.launcher.n_jobs=0",
                       f"hydra.sweep.dir={tmp_path / 'sweep'}"]}
    procs = {name: _bench([*args[:1], *_overrides(root, tmp_path / "store", *args[1:])] if args[0] == "-m" else
                          _overrides(root, tmp_path / "store", *args), tmp_path) for name, args in runs.items()}
    results = {name: _finish(proc) for name, proc in procs.items()}
    assert results["app"][0] == 2 and one_error_line(results["app"][1]) == \
        "error: grid.override.nxy=1000000000.0: must be a whole number >= 2 and <= 1024"
    assert results["joblib"][0] == 2 and one_error_line(results["joblib"][1]).startswith(
        "error: hydra.launcher.n_jobs=0: must be a whole number >= 1, or -1")
    assert not (tmp_path / "store").exists() and tree_digest(root) == before
    assert sorted(p.name for p in (tmp_path / "out").iterdir()) == [".hydra", "app.log"]    # Hydra's, before main


# ---- output faults ------------------------------------------------------------------------------------------


def test_a_file_size_limit_is_one_line_no_crash_and_the_next_run_is_identical(root, reference, tmp_path):
    """RLIMIT_FSIZE makes a write fail as a full disk does (EFBIG instead of ENOSPC: the same OSError path). One
    limit below the store's HDF5 cell (the store's write fails), one above every store file but below the run's
    arrays.h5 of two captures (its append fails). Before, h5py ended in a traceback and a SIGSEGV."""
    before = tree_digest(root)
    cell_bytes = sorted(p.stat().st_size for p in (reference["store"] / "cells").glob("*.h5"))
    arrays_bytes = (reference["out"] / "arrays.h5").stat().st_size
    limits = {"store_cell": cell_bytes[0] // 2, "arrays_h5": max(cell_bytes[-1] + 1, arrays_bytes - 1)}
    assert limits["arrays_h5"] < arrays_bytes
    procs = {name: _bench(_overrides(root, tmp_path / name / "store", f"hydra.run.dir={tmp_path / name / 'out'}"),
                          tmp_path, limit_bytes=limit) for name, limit in limits.items()}
    for name, proc in procs.items():
        code, stderr = _finish(proc)
        line = one_error_line(stderr)                    # one line, no traceback; exit 2, not -11 (SIGSEGV)
        assert code == 2 and "cannot write (File too large)" in line, (name, code, stderr)
        wrote = "store/cells/" if name == "store_cell" else "out/arrays.h5"
        assert f"{tmp_path / name}/{wrote}" in line, line
        assert _no_temp_files(tmp_path / name) == []
        assert not (tmp_path / name / "out" / "arrays.h5").exists()     # a partial file is never left behind
        store = Store(tmp_path / name / "store")
        assert all(store.get(p.stem) is not None for p in (tmp_path / name / "store" / "cells").glob("*.json"))
        rows = run(_cfg(*_overrides(root, tmp_path / name / "store")), tmp_path / name / "again")
        pd.testing.assert_frame_equal(_stable(rows), reference["rows"])
        assert _depth_pngs(tmp_path / name / "again") == reference["pngs"]
    assert tree_digest(root) == before


def test_sigkill_mid_run_then_the_next_run_is_identical(root, reference, tmp_path):
    store = tmp_path / "store"
    proc = _bench(_overrides(root, store, f"hydra.run.dir={tmp_path / 'out'}"), tmp_path)
    deadline = time.monotonic() + 120
    while not list((store / "cells").glob("*.json")) and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.communicate()
    assert Store(store).get(next((store / "cells").glob("*.json")).stem) is not None    # a finished cell is whole
    rows = run(_cfg(*_overrides(root, store)), tmp_path / "again")
    pd.testing.assert_frame_equal(_stable(rows), reference["rows"])
    assert _depth_pngs(tmp_path / "again") == reference["pngs"]


def test_an_output_folder_vanishing_mid_run_is_one_line_and_the_next_run_is_identical(root, reference, tmp_path,
                                                                                        monkeypatch):
    from bench.harness import app

    out = tmp_path / "out"
    written = []

    def write_then_vanish(out_dir, stem, depth_m, grid):
        written.append(stem)
        if len(written) == 2:                    # another process removed the run folder after the first capture
            shutil.rmtree(out)
        return real_write_depth(out_dir, stem, depth_m, grid)

    real_write_depth = app.write_depth
    monkeypatch.setattr(app, "write_depth", write_then_vanish)
    with pytest.raises(OSError) as caught:
        run(_cfg(*_overrides(root, tmp_path / "store")), out)
    line = cli.error_line(caught.value)
    assert line.startswith(f"{out}/") and "\n" not in line, line
    monkeypatch.undo()
    rows = run(_cfg(*_overrides(root, tmp_path / "store")), tmp_path / "again")
    pd.testing.assert_frame_equal(_stable(rows), reference["rows"])


# ---- the store as a trust boundary --------------------------------------------------------------------------


def _plate_cell(store: Path) -> str:
    (key,) = [p.stem for p in (store / "cells").glob("*.json") if json.loads(p.read_text())["object"] == "01_plate"]
    return key


def _secret(tmp_path: Path) -> Path:
    """A file outside the store whose data a planted cell would serve."""
    path = tmp_path / "secret.h5"
    with h5py.File(path, "w") as h5:
        for name in ("depth_m", "magnitude", "gt_depth_m"):
            h5[name] = np.full((301, 301), 0.123)
    return path


def _rewrite_h5(path: Path, change) -> None:
    """Rewrite the cell's HDF5 file with `change(h5)` applied (its datasets and attributes kept otherwise)."""
    with h5py.File(path, "a") as h5:
        change(h5)


def _replace_dataset(name: str, make):
    def change(h5):
        del h5[name]
        make(h5, name)
    return change


def _virtual(secret: Path):
    def make(h5, name):
        layout = h5py.VirtualLayout(shape=(301, 301), dtype="f8")
        layout[:] = h5py.VirtualSource(str(secret), name, shape=(301, 301))
        h5.create_virtual_dataset(name, layout)
    return make


CORRUPT = {   # case -> (what to do to the cell (json path, h5 path, tmp_path), words of the warning)
    "row_truncated": (lambda j, h, t: j.write_bytes(j.read_bytes()[:40]), "invalid JSON"),
    "row_wrong_type": (lambda j, h, t: j.write_text("[1, 2, 3]"), "a row must be a JSON object, found list"),
    "row_field_wrong_type": (lambda j, h, t: j.write_text(json.dumps({**json.loads(j.read_text()), "valid_px": "12"})),
                             "field 'valid_px' must be int"),
    "row_of_another_cell": (lambda j, h, t: j.write_text(json.dumps({**json.loads(j.read_text()), "key": "0" * 64})),
                            "holds the row of another cell"),
    "row_linked_out_of_the_store": (lambda j, h, t: (shutil.copy(j, t / "row.json"), j.unlink(),
                                                     j.symlink_to(t / "row.json")), "outside the dataset root"),
    "h5_truncated": (lambda j, h, t: h.write_bytes(h.read_bytes()[:1000]), "unreadable HDF5"),
    "h5_missing": (lambda j, h, t: h.unlink(), "file is missing"),
    "h5_external_link": (lambda j, h, t: _rewrite_h5(h, _replace_dataset(
        "depth_m", lambda h5, n: h5.__setitem__(n, h5py.ExternalLink(str(_secret(t)), n)))), "is a ExternalLink"),
    "h5_soft_link": (lambda j, h, t: _rewrite_h5(h, _replace_dataset(
        "depth_m", lambda h5, n: h5.__setitem__(n, h5py.SoftLink("/magnitude")))), "is a SoftLink"),
    "h5_virtual_dataset": (lambda j, h, t: _rewrite_h5(h, _replace_dataset("depth_m", _virtual(_secret(t)))),
                           "is a virtual dataset"),
    "h5_external_storage": (lambda j, h, t: _rewrite_h5(h, _replace_dataset("depth_m", lambda h5, n: (
        (t / "raw.bin").write_bytes(np.full(301 * 301, 0.123).tobytes()),
        h5.create_dataset(n, shape=(301, 301), dtype="f8", external=[(str(t / "raw.bin"), 0, 301 * 301 * 8)])))),
        "is a externally stored dataset"),
    "h5_wrong_shape": (lambda j, h, t: _rewrite_h5(h, _replace_dataset(
        "depth_m", lambda h5, n: h5.create_dataset(n, data=np.zeros((3, 3))))), "must be a float array of the grid's"),
    "h5_wrong_type": (lambda j, h, t: _rewrite_h5(h, _replace_dataset(
        "depth_m", lambda h5, n: h5.create_dataset(n, data=np.zeros((301, 301), dtype=np.int64)))),
        "must be a float array"),
    "h5_grid_attributes": (lambda j, h, t: _rewrite_h5(h, lambda h5: h5.attrs.__setitem__("grid_size", [0, 1, 2])),
                           "its grid attributes"),
}


@pytest.mark.parametrize("case", sorted(CORRUPT))
def test_a_corrupt_store_cell_is_computed_again_with_a_warning_naming_it(root, reference, tmp_path, caplog, case):
    corrupt, words = CORRUPT[case]
    store = tmp_path / "store"
    shutil.copytree(reference["store"], store, symlinks=True)
    key = _plate_cell(store)
    corrupt(store / "cells" / f"{key}.json", store / "cells" / f"{key}.h5", tmp_path)
    with caplog.at_level(logging.WARNING, logger="bench"):
        rows = run(_cfg(*_overrides(root, store)), tmp_path / "out")
    warnings = [r.getMessage() for r in caplog.records if "store cell" in r.getMessage()]
    assert len(warnings) == 1 and key in warnings[0] and words in warnings[0], warnings
    assert {row["object"]: row["cached"] for row in rows} == {"01_plate": False, "03_sphere": True}
    pd.testing.assert_frame_equal(_stable(rows), reference["rows"])
    assert _depth_pngs(tmp_path / "out") == reference["pngs"]                # nothing of the planted file served
    assert Store(store).get(key) is not None                                 # the cell is whole again


def test_a_forged_digest_cache_entry_is_hashed_again(root, reference, tmp_path):
    store = tmp_path / "store"
    shutil.copytree(reference["store"], store)
    for entry in (store / "digests").iterdir():
        entry.write_text("not a digest")
    rows = run(_cfg(*_overrides(root, store)), tmp_path / "out")
    assert all(row["cached"] for row in rows)                                # the same digests, found again
    pd.testing.assert_frame_equal(_stable(rows), reference["rows"])


# ---- the merge, error lines that name the file, failure reasons -----------------------------------------------


def test_a_job_csv_cut_mid_row_is_one_line_at_merge_and_merges_once_whole(reference, tmp_path):
    whole = (reference["out"] / "results.csv").read_bytes()
    for job in ("0_2fsk_d05_none", "1_2fsk_d05_none"):
        (tmp_path / job).mkdir()
        (tmp_path / job / "results.csv").write_bytes(whole)
    cut = tmp_path / "1_2fsk_d05_none" / "results.csv"
    cut.write_bytes(whole[:-25])
    with pytest.raises(DatasetError, match=r"line 3 is cut mid-row"):
        merge(tmp_path)
    proc = subprocess.run([sys.executable, "-m", "bench.report.merge", str(tmp_path)], capture_output=True,
                          text=True, cwd=REPO, timeout=120)
    assert proc.returncode == 2 and one_error_line(proc.stderr).startswith(f"error: {cut}: line 3 is cut mid-row")
    assert not (tmp_path / "results.csv").exists()
    cut.write_bytes(whole.replace(b"\n", b",extra\n", 1)[: len(whole)] + b"\n")   # a row of another width
    with pytest.raises(DatasetError, match=r"line \d has \d+ fields, the header \d+"):
        merge(tmp_path)
    cut.write_bytes(whole)                                                    # the job run again
    merged = merge(tmp_path)
    assert len(merged) == 2 * len(reference["rows"])


def test_two_targets_on_one_frame_frequency_name_the_frame_file(root, tmp_path):
    with pytest.raises(UsageError) as caught:
        run(_cfg(*_overrides(root, None, "freq.f_ghz=[81.9,82.0]")), tmp_path / "out")
    message = cli.error_line(caught.value)
    assert message.startswith(str(frame_file(root / "01_plate" / "30"))) and "same frame frequency" in message
    with pytest.raises(UsageError, match=r"000000\.npy: target frequency 90 GHz lies outside the frame's band"):
        run(_cfg(*_overrides(root, None, "freq.f_ghz=[81.45,90.0]")), tmp_path / "out2")


def test_inspect_names_the_file_of_a_5000_digit_count(root, tmp_path):
    from bench.maroon.inspect_capture import inspect_capture

    capture = copy_capture(root / "01_plate" / "30", tmp_path / "root")
    frame = np.load(frame_file(capture), allow_pickle=True).item()     # trusted: the generator wrote it
    frame["number_of_measurements"] = 10 ** 5000
    np.save(frame_file(capture), frame, allow_pickle=True)
    _, problems = inspect_capture(capture)
    assert f"{frame_file(capture)}: number_of_measurements must be 0..1,000,000,000, found an integer of about " \
           "5000 digits" in problems


# ---- the code version ---------------------------------------------------------------------------------------


def test_the_code_version_follows_the_import_graph_of_the_compute_path(tmp_path):
    import grimp

    from bench.harness.codeversion import compute_modules

    modules = compute_modules()
    for needed in ("bench.harness.app", "bench.harness.grids", "bench.harness.store", "bench.maroon.reader",
                   "methods.bp", "methods.mm2fsk", "methods.backends.cpu", "metrics.evaluate"):
        assert needed in modules, needed
    assert not [name for name in modules if name.startswith(("bench.report", "bench.perf", "tests"))]
    # import-linter's graph (grimp, a test dependency): every module it finds upstream is covered
    graph = grimp.build_graph("bench", "methods", "metrics", cache_dir=None)
    assert graph.find_upstream_modules("bench.harness.app") <= set(modules)
    assert "methods.bp" not in graph.find_upstream_modules("bench.harness.app")   # named in registry.BUILTIN only
    tree = {"bench/__init__.py": "", "bench/harness/__init__.py": "", "methods/__init__.py": "",
            "bench/harness/app.py": "from . import grids\ndef f():\n    import methods.lazy\n",
            "bench/harness/grids.py": "from ..other import thing\nTABLE = {'bp': 'methods.named.Class'}\n",
            "bench/other.py": "thing = 1\n", "methods/lazy.py": "", "methods/named.py": "", "methods/unused.py": ""}
    for name, text in tree.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(text)
    assert sorted(compute_modules(root=tmp_path)) == ["bench", "bench.harness", "bench.harness.app",
                                                      "bench.harness.grids", "bench.other", "methods", "methods.lazy",
                                                      "methods.named"]


def test_the_cached_code_version_is_the_computed_one_and_any_source_edit_computes_it_again(tmp_path, monkeypatch):
    from bench.harness import codeversion

    tree = {"bench/__init__.py": "", "bench/harness/__init__.py": "", "bench/harness/app.py": "from . import grids\n",
            "bench/harness/grids.py": "X = 1\n", "bench/report.py": "", "methods/__init__.py": ""}
    root = tmp_path / "tree"
    for name, text in tree.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)
    cache = tmp_path / "cache" / "code_version.json"
    computed = []
    real = codeversion._compute_version
    monkeypatch.setattr(codeversion, "_compute_version", lambda root: computed.append(1) or real(root))
    first = codeversion.cached_version(root, cache)
    assert first == real(root) and codeversion.cached_version(root, cache) == first and len(computed) == 1
    (root / "bench/report.py").write_text("# outside the compute path: same version, but followed again\n")
    assert codeversion.cached_version(root, cache) == first and len(computed) == 2
    (root / "bench/harness/grids.py").write_text("X = 2\n")
    second = codeversion.cached_version(root, cache)
    assert second != first and second == real(root) and len(computed) == 3
    (root / "bench/harness/new.py").write_text("")            # a new file: a new key, even if nothing imports it
    assert codeversion.cached_version(root, cache) == second and len(computed) == 4
    cache.write_text("{not json")                                 # a damaged cache: computed again, rewritten
    assert codeversion.cached_version(root, cache) == second and len(computed) == 5
    assert codeversion.cached_version(root, cache) == second and len(computed) == 5
    unwritable = tmp_path / "file"
    unwritable.write_text("")
    assert codeversion.cached_version(root, unwritable / "code_version.json") == second     # no cache: computed


def test_a_checkout_that_was_never_installed_still_has_a_code_version(monkeypatch, tmp_path):
    """Sources on PYTHONPATH without the package's metadata (a clone used in place): the version pyproject.toml
    declares, or 0+unknown; never a PackageNotFoundError traceback out of a sweep."""
    from importlib.metadata import PackageNotFoundError

    from bench.harness import codeversion

    def not_installed(name):
        raise PackageNotFoundError(name)

    monkeypatch.setattr(codeversion, "version", not_installed)
    (tmp_path / "pyproject.toml").write_text('[project]\nname = "mm2fsk-bench"\nversion = "9.8.7"\n')
    assert codeversion.package_version(tmp_path) == "9.8.7"
    assert codeversion.package_version(tmp_path / "nowhere") == "0+unknown"
    import tomllib

    declared = tomllib.loads((codeversion.PACKAGE_ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert codeversion.package_version() == declared                 # this checkout's pyproject.toml
    assert codeversion.sources_key(tmp_path)                        # the cache key is made without the metadata


def test_the_code_versions_cache_file_without_a_home_or_with_a_relative_cache_home(monkeypatch, tmp_path):
    from pathlib import Path

    from bench.harness import codeversion

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert codeversion.default_cache_file() == tmp_path / "mm2fsk-bench" / "code_version.json"
    monkeypatch.setenv("XDG_CACHE_HOME", "relative/cache")               # ignored: it would follow the cwd
    monkeypatch.setattr(Path, "home", classmethod(lambda cls: tmp_path / "home"))
    assert codeversion.default_cache_file() == tmp_path / "home" / ".cache" / "mm2fsk-bench" / "code_version.json"

    def no_home(cls):
        raise RuntimeError("Could not determine home directory.")
    monkeypatch.setattr(Path, "home", classmethod(no_home))
    assert codeversion.default_cache_file() is None                    # a container without HOME: no cache
    assert codeversion.cached_version() == codeversion._compute_version(codeversion.PACKAGE_ROOT)


def test_an_arrays_h5_cut_by_a_killed_run_is_written_anew(tmp_path, caplog):
    from bench.harness.store import write_arrays

    path = tmp_path / "arrays.h5"
    values = {"depth_m": np.full((5, 4), 0.3), "magnitude": np.ones((5, 4)), "gt_depth_m": np.zeros((5, 4))}
    for group in ("a", "b"):
        write_arrays(path, group, values)
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])            # killed while writing
    with caplog.at_level(logging.WARNING, logger="bench"):
        write_arrays(path, "c", values)
    assert any(f"{path} is not a readable HDF5 file" in r.getMessage() for r in caplog.records)
    with h5py.File(path, "r") as h5:
        assert list(h5) == ["c"] and (h5["c/depth_m"][()] == 0.3).all()


def test_a_depth_window_reaching_behind_the_radar_is_one_line_naming_the_capture(root, tmp_path):
    cfg = _cfg(*_overrides(root, None, "grid=coarse", "grid.override.z_half_m=0.5"))
    validate.check(cfg)                                   # within range; too deep only for a capture at 30 cm
    with pytest.raises(cli.UserError, match=r"^grid.override.z_half_m=0.5: must be below the distance of capture "
                                            r"01_plate/30 \(0.3 m\): the depth window would reach behind the radar"):
        run(cfg, tmp_path / "out")


def test_the_dataset_is_unchanged_by_every_fault_above(root, dataset_digest):
    assert tree_digest(root) == dataset_digest
