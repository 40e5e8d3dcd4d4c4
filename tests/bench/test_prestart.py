"""`python -m bench`'s helper processes started before Hydra on a host of several cores (bench.prestart): the merge's
worker as a fresh interpreter (bench.report.merge.SpawnedWorker) and the output process; the same rows and files as
without them."""
from __future__ import annotations

import os
import subprocess
import sys
import time

import pandas as pd
import pytest

from bench import prestart
from bench.harness import workers
from bench.harness.results import MEASURED_COLUMNS
from bench.report import merge


@pytest.mark.parametrize("argv, cores, started", [
    (["-m", "experiment=table2", "device=cuda"], 16, ["merge worker", "fork server"]),
    (["-m", "experiment=table3", "hydra/launcher=basic"], 4, ["merge worker", "fork server"]),
    (["method=bp", "freq=d10"], 16, ["fork server"]),                          # one run: no merge
    (["-m", "experiment=table2", "evaluation.workers=3"], 16, ["merge worker", "fork server"]),   # scoring workers'
    (["-m", "experiment=table2"], 2, []),                                      # two cores: as before
    (["-m", "experiment=table2", "hydra/launcher=local"], 16, []),             # jobs in other processes
    (["-m", "experiment=table2", "hydra/launcher=slurm_gpu"], 16, []),
    (["--cfg", "job", "-m", "experiment=table2"], 16, []),
    (["--info", "defaults"], 16, []),
])
def test_helpers_start_before_hydra_only_where_this_process_runs_jobs_on_several_cores(monkeypatch, argv, cores,
                                                                                        started):
    calls = []
    monkeypatch.setattr(prestart, "usable_cores", lambda: cores)
    monkeypatch.setattr(merge, "prestart_worker", lambda: calls.append("merge worker"))
    monkeypatch.setattr(prestart, "start_fork_server", lambda: calls.append("fork server"))
    prestart.start(argv, "-m" in argv)
    assert calls == started


def test_the_fork_server_started_early_is_the_one_the_workers_use():
    """The pool of bench.harness.workers forks its processes from the server started before Hydra, which has
    imported what they need (its preload)."""
    from multiprocessing import forkserver

    prestart.start_fork_server()
    server = forkserver._forkserver._forkserver_pid
    assert server is not None
    assert forkserver._forkserver._preload_modules == workers.PRELOAD
    started = workers.pool(1).submit(os.getppid).result(timeout=60)
    assert started == server and forkserver._forkserver._forkserver_pid == server


def _job_rows(root, rows_text):
    (root / "0_job").mkdir(parents=True)
    (root / "0_job" / "results.csv").write_text(rows_text)


def test_a_spawned_worker_merges_what_it_is_handed_and_relays_a_user_error(tmp_path, capfd):
    header = ("object,distance,frame,method,freq,prior,f_GHz,C_g_cm,C_s_cm,P_cm,P_e_cm,valid_px,runtime_ms,device,"
              "timing,label,grid,params,metrics,failure\n")
    row = "01_plate,30,0,mm2fsk,d10,none,80.0 82.0,0.1,0.2,0.3,0.3,100,50.0,cpu,alone,MM-2FSK,from_capture,,sound,"
    _job_rows(tmp_path / "sweep", f"{header}{row}\n")
    merge.finish_worker(merge.SpawnedWorker(), tmp_path / "sweep", None, False)
    merged = (tmp_path / "sweep" / "results.csv").read_text()
    assert merged.splitlines()[0].startswith("object,distance,frame,method,freq,prior") and "01_plate" in merged
    _job_rows(tmp_path / "cut", header + row[:20])                 # a row cut by a killed job
    with pytest.raises(SystemExit) as exited:
        merge.finish_worker(merge.SpawnedWorker(), tmp_path / "cut", None, False)
    assert exited.value.code == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "cut mid-row" in err[0]
    idle = merge.SpawnedWorker()
    if hasattr(os, "getpriority"):                       # its imports yield to the jobs
        assert os.getpriority(os.PRIO_PROCESS, idle._process.pid) == merge.spawned_niceness(
            os.getpriority(os.PRIO_PROCESS, 0))
    assert idle.hand_over(None) == 0                     # a multirun that ends without a merge: it just exits


def test_a_multirun_takes_the_worker_started_before_hydra_and_forks_none(monkeypatch):
    forked = []
    monkeypatch.setattr(merge, "start_worker", lambda: forked.append(1) or "forked")
    monkeypatch.setattr(merge, "_waiting", ["spawned"])
    callback = merge.MergeResults()
    callback.on_multirun_start(None)
    callback.on_job_end(None, None)
    assert callback._worker == "spawned" and forked == [] and merge._waiting == []
    later = merge.MergeResults()                          # a second multirun of the process: none left, it forks
    later.on_multirun_start(None)
    later.on_job_end(None, None)
    assert later._worker == "forked"


def test_a_spawned_worker_never_handed_a_sweep_ends_with_the_process(monkeypatch):
    """A command that fails before its multirun (a config mistake) must not leave the worker importing for a second
    with the command's stderr open: it is ended at exit."""
    monkeypatch.setattr(merge, "_spawned", [])
    monkeypatch.setattr(merge, "_waiting", [])
    monkeypatch.setattr(merge.atexit, "register", lambda handler: None)
    merge.prestart_worker()
    merge.prestart_worker()
    handed = merge._waiting.pop()
    assert handed.hand_over(None) == 0
    started = time.perf_counter()
    merge._end_unused()
    assert time.perf_counter() - started < 5
    unused = merge._waiting[0]._process
    assert unused.returncode is not None and unused.returncode < 0          # killed, not left to finish


_FAKE_CORES = ("import runpy, sys\nimport methods.domain.host as host\nhost.usable_cores = lambda: {cores}\n"
               "sys.argv = ['bench', *sys.argv[1:]]\nrunpy.run_module('bench', run_name='__main__', alter_sys=True)\n")


def _sweep(tmp_path, synth_root, cores: int):
    root = tmp_path / f"cores{cores}"
    result = subprocess.run([sys.executable, "-c", _FAKE_CORES.format(cores=cores), "-m", "experiment=table2",
                             "hydra.sweeper.params.freq='d8,d10'", "dataset=maroon", f"dataset.root={synth_root}",
                             "dataset.captures=[01_plate/30]", "store.dir=null", f"store.cache={tmp_path / 'cache'}",
                             f"hydra.sweep.dir={root}"], capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    return root


def test_a_sweep_with_its_helpers_started_before_hydra_gives_the_same_rows_and_files(synth_root, tmp_path):
    """16 cores (faked: the merge's worker spawned before Hydra, the output process, the composition workers) and 2
    (none of them): the same rows, tables' rows and depth files."""
    outcomes = {}
    for cores in (16, 2):
        root = _sweep(tmp_path, synth_root, cores)
        rows = pd.read_csv(root / "results.csv")
        table = pd.read_csv(root / "table2.csv")
        outcomes[cores] = (rows.drop(columns=[*MEASURED_COLUMNS, "hostname", *(c for c in rows if c.startswith("t_"))]),
                           table.drop(columns=[c for c in table if "runtime" in c]),
                           {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.glob("*/depth/*"))})
        assert (root / "runtime_vs_error.png").is_file() and (root / "table2.md").is_file()
    pd.testing.assert_frame_equal(outcomes[16][0], outcomes[2][0])
    pd.testing.assert_frame_equal(outcomes[16][1], outcomes[2][1])
    assert outcomes[16][2] == outcomes[2][2] and len(outcomes[2][2]) >= 4


def test_a_config_mistake_reads_the_same_with_the_helpers_started(tmp_path):
    """A command that fails before its first job (an experiment that does not exist) after the helpers started:
    the same exit code and stderr as without them (no traceback of a helper left behind)."""
    outcomes = {}
    for cores in (16, 2):
        result = subprocess.run([sys.executable, "-c", _FAKE_CORES.format(cores=cores), "-m",
                                 "experiment=no_such_experiment", f"hydra.sweep.dir={tmp_path / str(cores)}"],
                                capture_output=True, text=True, timeout=120)
        outcomes[cores] = (result.returncode, result.stderr)
    assert outcomes[16] == outcomes[2] and outcomes[2][0] != 0
    assert "Traceback" not in outcomes[16][1]
