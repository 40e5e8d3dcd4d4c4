"""Captures scored in worker processes (bench.harness.workers): the same rows, depth files, arrays and store cells as
scored in the main thread, their runtimes labelled as taken beside other work; a run whose last files are deferred."""
from __future__ import annotations

import json
import logging
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from bench.harness import CONFIG_DIR, app, workers
from bench.harness.app import run
from bench.harness.results import MEASURED_COLUMNS, finish_deferred

from hostile_tools import copy_capture

VOLATILE = (*MEASURED_COLUMNS, "hostname")


@pytest.fixture(scope="module")
def root(synth_capture, tmp_path_factory):
    """Two small captures (16 frequencies)."""
    root = tmp_path_factory.mktemp("workers_root")
    for name in ("01_plate", "03_sphere"):
        copy_capture(synth_capture(name, 30, frequency_points=16), root, name, "30")
    return root


def _run(root: Path, out: Path, store: Path | None, n_workers: int, defer: bool = False) -> list[dict]:
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", overrides=[
            "dataset=maroon", f"dataset.root={root}", "method=2fsk", "freq=d05", "prior=none",
            f"store.dir={store if store is not None else 'null'}", f"evaluation.workers={n_workers}"])
    return run(cfg, out, defer_outputs=defer)


def _stable(table: pd.DataFrame) -> pd.DataFrame:
    return table.drop(columns=[c for c in table.columns if c in VOLATILE or (c.startswith("t_") and c.endswith("_ms"))])


def _files(out: Path) -> dict[str, bytes]:
    return {str(p.relative_to(out)): p.read_bytes() for p in sorted(out.rglob("*"))
            if p.is_file() and p.suffix in (".png", ".json")}


def _arrays(path: Path) -> dict[str, np.ndarray]:
    with h5py.File(path) as h5:
        return {f"{group}/{name}": h5[group][name][()] for group in h5 for name in h5[group]}


@pytest.mark.parametrize("with_store", [True, False])
def test_rows_and_files_scored_by_workers_are_those_scored_in_the_main_thread(root, tmp_path, with_store):
    stores = {n: (tmp_path / f"store{n}" if with_store else None) for n in (0, 1)}
    rows = {n: _run(root, tmp_path / f"out{n}", stores[n], n) for n in (0, 1)}
    assert [r["object"] for r in rows[1]] == [r["object"] for r in rows[0]] == ["01_plate", "03_sphere"]
    pd.testing.assert_frame_equal(_stable(pd.DataFrame(rows[1])), _stable(pd.DataFrame(rows[0])))
    tables = {n: pd.read_csv(tmp_path / f"out{n}" / "results.csv") for n in (0, 1)}
    assert list(tables[1].columns) == list(tables[0].columns)                       # the same column order
    pd.testing.assert_frame_equal(_stable(tables[1]), _stable(tables[0]))
    assert _files(tmp_path / "out1") == _files(tmp_path / "out0")                   # depth PNGs, JSON, previews
    arrays = {n: _arrays(tmp_path / f"out{n}" / "arrays.h5") for n in (0, 1)}
    assert arrays[1].keys() == arrays[0].keys() and len(arrays[0]) == 6
    for name, values in arrays[0].items():
        np.testing.assert_array_equal(arrays[1][name], values)
    if with_store:                   # the cells a worker wrote serve the next run as the main thread's do
        cells = {n: sorted((stores[n] / "cells").glob("*.json")) for n in (0, 1)}
        assert len(cells[1]) == len(cells[0]) == 2
        for a, b in zip(cells[0], cells[1], strict=True):
            assert _stable(pd.DataFrame([json.loads(b.read_text())])).equals(
                _stable(pd.DataFrame([json.loads(a.read_text())])))
        again = _run(root, tmp_path / "again", stores[1], 1)
        assert all(r["cached"] for r in again)
    # the workers share the host with the timed calls: never a runtime measured alone
    assert {r["timing"] for r in rows[1]} == {"parallel"} and {r["timing"] for r in rows[0]} <= {"alone", "contended"}


@pytest.mark.parametrize(("cores", "expected"), [(16, workers.MAX_AUTO_WORKERS), (5, 3), (2, 0), (1, 0)])
def test_pool_sizes(monkeypatch, cores, expected):
    monkeypatch.setattr(workers, "usable_cores", lambda: cores)
    assert workers.pool_size("auto", "cuda") == expected
    assert workers.pool_size("auto", "cpu") == 0
    assert workers.pool_size("auto", "cuda", shared=True) == 0          # jobs side by side: their cores
    assert workers.pool_size(3, "cpu") == 3
    process = workers.output_process()
    assert (process is not None) == (cores >= workers.OUTPUT_PROCESS_MIN_CORES)
    assert workers.output_process(shared=True) is None


def test_no_worker_processes_where_the_machine_cannot_make_a_pool(monkeypatch, caplog):
    """No semaphores (no writable /dev/shm): the output process is not started, a warning says so, and the job's
    writer thread does its work."""
    def no_shm(*args, **kwargs):
        raise OSError(38, "Function not implemented")

    monkeypatch.setattr(workers, "ProcessPoolExecutor", no_shm)
    monkeypatch.setattr(workers, "_POOLS", {})
    monkeypatch.setattr(workers, "usable_cores", lambda: 16)
    with caplog.at_level(logging.WARNING, logger="bench"):
        assert workers.output_process() is None
    assert any("no worker processes" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("with_store", [True, False])
def test_files_written_by_the_output_process_are_the_writer_threads(root, tmp_path, monkeypatch, with_store):
    """Without scoring workers, a host of OUTPUT_PROCESS_MIN_CORES cores writes each capture's depth files, cell and
    compressed arrays (into arrays.h5; a stored cell's arrays copied there too) in one process instead of the writer
    thread: the same rows, files, arrays and cells, and the rows timed as before (alone, or contended on a busy
    machine)."""
    rows, stores, handed = {}, {}, []
    monkeypatch.setattr(workers, "OUTPUT_PROCESS_MIN_CORES", 1)
    process = workers.output_process()
    submit = process.submit
    monkeypatch.setattr(process, "submit", lambda fn, *args: handed.append((fn.__name__, args[-1] is not None)) or
                        submit(fn, *args))
    for name, min_cores in (("thread", 10**6), ("process", 1)):
        monkeypatch.setattr(workers, "OUTPUT_PROCESS_MIN_CORES", min_cores)
        stores[name] = tmp_path / f"store_{name}" if with_store else None
        rows[name] = _run(root, tmp_path / name, stores[name], 0)
    pd.testing.assert_frame_equal(_stable(pd.DataFrame(rows["process"])), _stable(pd.DataFrame(rows["thread"])))
    tables = {name: pd.read_csv(tmp_path / name / "results.csv") for name in rows}
    pd.testing.assert_frame_equal(_stable(tables["process"]), _stable(tables["thread"]))
    assert _files(tmp_path / "process") == _files(tmp_path / "thread") and _files(tmp_path / "thread")
    arrays = {name: _arrays(tmp_path / name / "arrays.h5") for name in rows}
    assert arrays["process"].keys() == arrays["thread"].keys() and len(arrays["thread"]) == 6
    for name, values in arrays["thread"].items():
        np.testing.assert_array_equal(arrays["process"][name], values)
    if with_store:                   # the cells the process wrote serve the next run
        assert len(list((stores["process"] / "cells").glob("*.h5"))) == 2
        # a row timed `contended` (a busy test machine) would be measured again when the machine is quiet
        # (app._reusable): not what this test is about
        monkeypatch.setattr(app, "_reusable", lambda stored_timing, timing: True)
        assert all(r["cached"] for r in _run(root, tmp_path / "again", stores["process"], 0))
        assert _arrays(tmp_path / "again" / "arrays.h5").keys() == arrays["thread"].keys()
        for name, values in arrays["thread"].items():            # copied from the store by the process
            np.testing.assert_array_equal(_arrays(tmp_path / "again" / "arrays.h5")[name], values)
    assert {r["timing"] for r in rows["process"]} <= {"alone", "contended"}
    # the process wrote both captures' files and their arrays into arrays.h5 (its one writer), and copied the stored
    # cells' arrays of the cached run
    assert handed == [("write", True)] * 2 + [("copy_stored", True)] * 2 * with_store


def test_a_run_that_defers_its_files_is_complete_once_they_are_finished(root, tmp_path):
    reference = _stable(pd.DataFrame(_run(root, tmp_path / "reference", None, 0)))
    rows = _run(root, tmp_path / "deferred", None, 1, defer=True)
    assert [r["object"] for r in rows] == ["01_plate", "03_sphere"]     # known when the run returns
    finish_deferred()
    pd.testing.assert_frame_equal(_stable(pd.DataFrame(rows)), reference)
    pd.testing.assert_frame_equal(_stable(pd.read_csv(tmp_path / "deferred" / "results.csv")),
                                  _stable(pd.read_csv(tmp_path / "reference" / "results.csv")))


def test_a_later_run_computes_only_after_the_files_an_earlier_run_deferred(root, tmp_path, monkeypatch):
    from bench.harness import app

    gate, waiting, computed_after_gate = threading.Event(), threading.Event(), []
    write, compute, finish = app._write_outputs, app._computed_row, app.outputs.finish_deferred

    def held_write(out_dir, *args, **kwargs):               # the first run's files wait for the gate
        if out_dir.name == "first":
            assert gate.wait(60)
        return write(out_dir, *args, **kwargs)

    def noted_compute(*args, **kwargs):
        computed_after_gate.append(gate.is_set())
        return compute(*args, **kwargs)

    def noted_finish():
        waiting.set()
        finish()

    def release():                                          # the gate opens once the second run waits
        if waiting.wait(60):
            time.sleep(0.2)
            gate.set()

    monkeypatch.setattr(app, "_write_outputs", held_write)
    first = _run(root, tmp_path / "first", None, 1, defer=True)
    monkeypatch.setattr(app, "_computed_row", noted_compute)
    monkeypatch.setattr(app.outputs, "finish_deferred", noted_finish)
    threading.Thread(target=release, daemon=True).start()
    try:
        _run(root, tmp_path / "second", None, 0)
    finally:
        gate.set()
        finish()
    assert computed_after_gate == [True, True]
    assert all("P_cm" in row for row in first) and len(pd.read_csv(tmp_path / "first" / "results.csv")) == 2


def test_a_deferred_run_logs_into_its_own_file_and_leaves_it_closed(root, tmp_path):
    """The writer's lines after the run returned go to the run's log file, which Hydra has closed by then (the next
    job's logging replaces it); once the writer is done the file is closed again, not left open by the reopening."""
    import logging

    from bench.harness import app

    handler = logging.FileHandler(tmp_path / "app.log")
    handler.setLevel(logging.INFO)
    level = app.log.level
    app.log.addHandler(handler)
    app.log.setLevel(logging.INFO)
    try:
        _run(root, tmp_path / "deferred", None, 1, defer=True)
        app.log.removeHandler(handler)
        handler.close()                                    # as Hydra's next job configures logging
        finish_deferred()
    finally:
        app.log.removeHandler(handler)
        app.log.setLevel(level)
    assert handler.stream is None                          # closed again after the writer's reopening lines
    assert (tmp_path / "app.log").read_text().count(": computed,") == 2
