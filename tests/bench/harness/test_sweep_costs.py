"""A sweep's fixed and per-capture costs paid once (issue 29): each job composed once, the ground truth kept by
content in the store and read back bit for bit, outputs written on a background thread, the stage clock."""
from __future__ import annotations

import os
import pickle
import subprocess
import sys
import time

import numpy as np
import pytest
from hydra import compose, initialize_config_dir

from bench.harness import CONFIG_DIR, app, captures, sizing, stages
from bench.harness.results import BackgroundWriter
from bench.maroon import reader


class _Loader:
    def __init__(self):
        self.calls = []

    def load_sweep_config(self, master_config, sweep_overrides):
        self.calls.append(tuple(sweep_overrides))
        return {"composed": tuple(sweep_overrides), "n": len(self.calls)}


def test_the_launcher_gets_the_configuration_the_check_composed_once():
    # imported here: Hydra's plugin scan (other tests) imports the module anew, and pickling needs the current class
    from hydra_plugins.mm2fsk_bench.sweeper import _ComposedOnce

    loader = _Loader()
    once = _ComposedOnce(loader)
    once.keep({}, ["freq=d05"])
    first = once.load_sweep_config({}, ["freq=d05"])
    assert loader.calls == [("freq=d05",)] and first == {"composed": ("freq=d05",), "n": 1}
    assert once.load_sweep_config({}, ["freq=d05"])["n"] == 2          # handed over once: the launcher edits it
    once.keep({}, ["freq=d1"])
    assert pickle.loads(pickle.dumps(once))._kept == {}                 # other processes compose their own


def _cfg(synth_root, store, *overrides):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=["dataset=maroon", f"dataset.root={synth_root}",
                                                      "dataset.captures=[01_plate/30]", f"store.dir={store}",
                                                      *overrides])


def test_kept_ground_truth_scores_like_a_fresh_one_without_reading_the_mesh(synth_root, tmp_path, monkeypatch):
    """A second process on the same captures (emptied memory caches) reads the kept rasters: no ray cast, no mesh
    read for a RealSense cell, and every score equal to the run without a store."""
    casts, parts = [], []
    real_cast, real_read = captures.ground_truth_rasters_m, reader.read_capture
    monkeypatch.setattr(captures, "ground_truth_rasters_m", lambda c, g: casts.append(c.name) or real_cast(c, g))
    monkeypatch.setattr(reader, "read_capture", lambda *a, **k: parts.append(k["parts"]) or real_read(*a, **k))

    def fresh_process():
        monkeypatch.setattr(captures, "_CAPTURES", type(captures._CAPTURES)())
        monkeypatch.setattr(captures, "_GROUND_TRUTHS", type(captures._GROUND_TRUTHS)())

    fresh_process()
    (plain,) = app.run(_cfg(synth_root, "null", "cell=mm2fsk_d10", "store.cache=null"), tmp_path / "plain")
    fresh_process()
    app.run(_cfg(synth_root, tmp_path / "store", "cell=2fsk_d05"), tmp_path / "first")
    assert len(casts) == 2 and len(list((tmp_path / "store" / "ground_truth").glob("*.h5"))) == 1
    fresh_process()
    parts.clear()
    (kept,) = app.run(_cfg(synth_root, tmp_path / "store", "cell=mm2fsk_d10"), tmp_path / "kept")
    assert len(casts) == 2 and parts == [("radar", "realsense")]            # no cast, no mesh
    for column in ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm", "off_pct", "C_g_px", "C_s_px", "P_px", "P_e_px"):
        assert kept[column] == plain[column] or (np.isnan(kept[column]) and np.isnan(plain[column])), column


def test_a_failed_background_write_fails_the_run():
    writer = BackgroundWriter()
    written = []
    writer.submit(written.append, 1)

    def fail():
        raise OSError(28, "No space left on device", "/out/arrays.h5")

    writer.submit(fail)
    with pytest.raises(OSError, match="No space left"):
        writer.close()
    assert written == [1]


def test_a_row_timed_on_a_busy_machine_is_marked_contended(synth_root, tmp_path, monkeypatch):
    monkeypatch.setattr(app, "machine_load", lambda: 1e3)
    ticks = iter(range(0, 10**9, 1000))                  # the rest of the machine: 1000 CPU seconds per look
    monkeypatch.setattr(sizing, "busy_cpu_s", lambda: float(next(ticks)))
    monkeypatch.setattr(sizing, "CLOCK", sizing.CpuClock())
    (row,) = app.run(_cfg(synth_root, "null", "cell=2fsk_d05", "timing.repeat=3"), tmp_path / "busy")
    assert row["timing"] == "contended" and row["load_1m"] == 1e3 and row["others_cores"] > 1
    assert 1 <= row["runtime_runs"] <= 3 and row["cpu_ms"] > 0
    assert app._reusable("contended", "alone")                       # still busy: re-measuring would not help
    monkeypatch.setattr(app, "machine_load", lambda: 0.0)
    assert not app._reusable("contended", "alone") and not app._reusable("parallel", "alone")
    assert app._reusable("alone", "alone") and app._reusable("parallel", "parallel")


def test_the_jobs_own_output_process_does_not_make_its_rows_contended(synth_root, tmp_path, monkeypatch):
    """The rest of the machine's CPU over a timed call, less the job's own child processes (its output writer, the
    fork server that starts it, as its writer thread was), decides `contended`: here all of it was a child's."""
    monkeypatch.setattr(app, "machine_load", lambda: 0.0)
    machine = iter(range(0, 10**9, 1000))                # 1000 CPU seconds per look, all of them the helper's
    helper = iter(range(0, 10**9, 1000))
    monkeypatch.setattr(sizing, "busy_cpu_s", lambda: float(next(machine)))
    monkeypatch.setattr(sizing, "processes_cpu_s", lambda pids: float(next(helper)) if pids == [4242] else 0.0)
    monkeypatch.setattr(sizing, "descendants", lambda: [4242])
    monkeypatch.setattr(sizing, "CLOCK", sizing.CpuClock())
    (row,) = app.run(_cfg(synth_root, "null", "cell=2fsk_d05", "timing.repeat=1"), tmp_path / "own")
    assert row["timing"] == "alone" and row["others_cores"] < 0.5


@pytest.mark.skipif(not os.path.isdir("/proc/self"), reason="reads /proc")
def test_a_child_processes_cpu_time_is_read_from_proc():
    busy = subprocess.Popen([sys.executable, "-c", "import sys, time\nt = time.process_time()\n"
                             "while time.process_time() - t < 0.3: pass\nsys.stdin.read()"], stdin=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 30
        while sizing.processes_cpu_s([busy.pid]) < 0.25 and time.monotonic() < deadline:
            time.sleep(0.05)
        used_s = sizing.processes_cpu_s([busy.pid])
        assert 0.25 <= used_s < 5.0          # the child spins 0.3 s of CPU; /proc counts 10 ms ticks (0.29 seen)
        assert sizing.processes_cpu_s([busy.pid, 2**22 + 7]) == used_s       # a pid that is gone counts 0
        assert busy.pid in sizing.descendants()
    finally:
        busy.communicate(b"")
    assert sizing.processes_cpu_s([]) == 0.0


@pytest.mark.skipif(not os.path.isfile("/proc/stat"), reason="reads /proc")
def test_the_machines_busy_time_is_proc_stats_first_line():
    """busy_cpu_s reads /proc/stat with plain os.read (bench.harness.sizing._proc_bytes): the same seconds as its
    first line read as text, taken just before and after; a file that cannot be read is None."""
    def from_text() -> float:
        with open("/proc/stat") as stat:
            fields = [int(v) for v in stat.readline().split()[1:]]
        return (sum(fields[:8]) - fields[3] - fields[4]) / os.sysconf("SC_CLK_TCK")

    before = from_text()
    busy_s = sizing.busy_cpu_s()
    assert before <= busy_s <= from_text()
    assert sizing._proc_bytes("/proc/no_such_file") is None


def _parent_pid(pid: str) -> int | None:
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return int(stat.read().rpartition(")")[2].split()[1])
    except (OSError, ValueError, IndexError):
        return None


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="reads /proc")
def test_descendants_are_children_and_their_children():
    """A fork server's pool workers are the job's grandchildren: both generations count as its own."""
    child = subprocess.Popen([sys.executable, "-c", "import subprocess, sys\n"
                              "subprocess.run([sys.executable, '-c', 'import sys; sys.stdin.read()'])"],
                             stdin=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 30
        while not (grandchildren := [int(p) for p in os.listdir("/proc") if p.isdigit()
                                     and _parent_pid(p) == child.pid]):
            assert time.monotonic() < deadline
            time.sleep(0.05)
        found = sizing.descendants()
        assert child.pid in found and set(grandchildren) <= set(found)
    finally:
        child.communicate(b"")


@pytest.mark.skipif(not os.path.isdir("/proc/self/task"), reason="reads /proc")
def test_children_started_on_other_threads_are_descendants_while_and_after_those_run():
    """This process's children are read from its Python threads (sizing._own_threads, not every thread's list): one
    started by a thread that still runs, and one whose thread has ended (Linux hands it to the main thread), are
    both found, as /proc/self/task's every thread finds them."""
    import threading

    def every_threads_children() -> set[int]:
        return {int(child) for tid in os.listdir("/proc/self/task")
                for child in (sizing._proc_bytes(f"/proc/self/task/{tid}/children") or b"").split()}

    children, release = [], threading.Event()

    def start_child(wait: bool) -> None:
        children.append(subprocess.Popen([sys.executable, "-c", "import sys; sys.stdin.read()"],
                                         stdin=subprocess.PIPE))
        if wait:
            release.wait()

    running = threading.Thread(target=start_child, args=(True,))
    ended = threading.Thread(target=start_child, args=(False,))
    try:
        running.start()
        ended.start()
        ended.join()
        deadline = time.monotonic() + 30
        while len(children) < 2:
            assert time.monotonic() < deadline
            time.sleep(0.01)
        pids = {child.pid for child in children}
        assert pids <= every_threads_children()
        assert pids <= set(sizing.descendants())
    finally:
        release.set()
        running.join()
        for child in children:
            child.communicate(b"")


def test_stage_seconds_go_to_the_innermost_open_stage(monkeypatch):
    clock = iter([0.0, 1.0, 3.0, 6.0, 6.0, 10.0])
    monkeypatch.setattr(stages, "_on", True)
    monkeypatch.setattr(stages, "_seconds", type(stages._seconds)())
    monkeypatch.setattr(stages, "_clock", lambda: next(clock))
    with stages.stage("reading"):           # 0 .. 1 reading, 1 .. 3 imports, 3 .. 6 reading again
        with stages.stage("imports"):
            pass
    with stages.stage("methods"):           # 6 .. 10
        pass
    assert dict(stages._seconds) == {"reading": 4.0, "imports": 2.0, "methods": 4.0}


def test_a_job_records_its_seconds_per_frame_for_the_next_estimate(synth_root, tmp_path):
    from bench.harness.durations import Durations, configuration_id

    cfg = _cfg(synth_root, tmp_path / "store", "cell=2fsk_d05")
    app.run(cfg, tmp_path / "a")
    method = app._method(cfg)
    cell = app._cell(cfg, "cpu", method)
    seconds = Durations(tmp_path / "store").seconds(configuration_id(cell))
    assert seconds is not None and seconds > 0
    assert configuration_id({**cell, "code": "other"}) == configuration_id(cell)      # survives a code change
    assert configuration_id({**cell, "threshold_db": 3.0}) != configuration_id(cell)


def test_a_kept_mesh_is_read_back_as_parsed(synth_root, tmp_path, monkeypatch):
    """The photogrammetry prior's mesh: parsed by Open3D once, then read from the store; same scores."""
    parsed = []
    real = reader.read_mesh
    monkeypatch.setattr(reader, "read_mesh", lambda path: parsed.append(path) or real(path))
    rows = []
    for name in ("first", "again"):
        monkeypatch.setattr(captures, "_CAPTURES", type(captures._CAPTURES)())
        monkeypatch.setattr(captures, "_GROUND_TRUTHS", type(captures._GROUND_TRUTHS)())
        rows += app.run(_cfg(synth_root, tmp_path / "store", "method=mm2fsk", "freq=d05", "prior=photogrammetry"),
                        tmp_path / name)
        for cell in (tmp_path / "store" / "cells").glob("*"):          # the second run computes again
            cell.unlink()
    assert len(parsed) == 1 and len(list((tmp_path / "store" / "meshes").glob("*.h5"))) == 1
    first, again = rows
    for column in ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm", "valid_px"):
        assert first[column] == again[column], column


@pytest.mark.parametrize("experiment", ["table2", "table3", "beyond", "runtime"])
def test_no_experiment_sets_hydra_mode_so_a_multirun_may_skip_hydras_mode_probe(experiment):
    """bench.__main__.skip_mode_probe: with -m Hydra runs a multirun whatever the probe finds, unless a config said
    RUN (then it only warns): skipping the probe's composition changes nothing while no config sets the mode."""
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", overrides=[f"experiment={experiment}"], return_hydra_config=True)
    assert cfg.hydra.mode is None


def _job_rows(root, rows_text):
    (root / "0_job").mkdir(parents=True)
    (root / "0_job" / "results.csv").write_text(rows_text)


def test_the_merge_worker_merges_what_it_is_handed_and_relays_a_user_error(tmp_path, capfd):
    from bench.report import merge

    header = ("object,distance,frame,method,freq,prior,f_GHz,C_g_cm,C_s_cm,P_cm,P_e_cm,valid_px,runtime_ms,device,"
              "timing,label,grid,params,metrics,failure\n")
    row = "01_plate,30,0,mm2fsk,d10,none,80.0 82.0,0.1,0.2,0.3,0.3,100,50.0,cpu,alone,MM-2FSK,from_capture,,sound,"
    _job_rows(tmp_path / "sweep", f"{header}{row}\n")
    merge.finish_worker(merge.start_worker(), tmp_path / "sweep", None, False)
    merged = (tmp_path / "sweep" / "results.csv").read_text()
    assert merged.splitlines()[0].startswith("object,distance,frame,method,freq,prior") and "01_plate" in merged
    _job_rows(tmp_path / "cut", header + row[:20])                 # a row cut by a killed job
    with pytest.raises(SystemExit) as exited:
        merge.finish_worker(merge.start_worker(), tmp_path / "cut", None, False)
    assert exited.value.code == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and "cut mid-row" in err[0]
    assert merge.start_worker().hand_over(None) == 0     # a multirun that ends without a merge: it just exits


def test_the_merge_worker_starts_after_the_first_job_and_only_in_the_sweeps_process(monkeypatch):
    from bench.report import merge

    started = []
    monkeypatch.setattr(merge, "start_worker", lambda: started.append(1) or "worker")
    callback = merge.MergeResults()
    callback.on_job_end(None, None)                      # no multirun started here (a joblib or SLURM job's copy)
    assert started == []
    callback.on_multirun_start(None)
    assert started == []                                 # not while the jobs are composed
    callback.on_job_end(None, None)
    callback.on_job_end(None, None)
    assert started == [1] and callback._worker == "worker"
    remote = merge.MergeResults()
    remote.on_multirun_start(None)
    remote._sweep_pid += 1                                # the callback as copied into another process
    remote.on_job_end(None, None)
    assert started == [1]


def test_a_pickled_copy_or_another_thread_never_forks_and_a_failed_fork_merges_here(monkeypatch):
    import threading

    from bench.report import merge

    started = []
    monkeypatch.setattr(merge, "start_worker", lambda: started.append(1) or "worker")
    callback = merge.MergeResults()
    callback.on_multirun_start(None)
    copy = pickle.loads(pickle.dumps(callback))          # what joblib and SLURM send to their workers
    copy.on_job_end(None, None)
    thread = threading.Thread(target=callback.on_job_end, args=(None, None))   # a threading launcher's job
    thread.start()
    thread.join()
    assert started == [] and callback._worker is None
    monkeypatch.undo()

    def no_fork():
        raise OSError(12, "Cannot allocate memory")
    monkeypatch.setattr(merge.os, "fork", no_fork)
    descriptors = set(os.listdir("/proc/self/fd"))
    assert merge.start_worker() is None                   # the merge then runs in this process
    assert set(os.listdir("/proc/self/fd")) == descriptors   # the pipe's two ends closed


class _FailingLoader(_Loader):
    def load_sweep_config(self, master_config, sweep_overrides):
        if "freq=typo" in sweep_overrides:
            raise ValueError("no freq 'typo'")
        return super().load_sweep_config(master_config, sweep_overrides)


def test_a_batch_is_composed_by_forked_workers_and_a_failure_is_composed_again_here(monkeypatch):
    from hydra_plugins.mm2fsk_bench import sweeper

    monkeypatch.setattr(sweeper, "usable_cores", lambda: 4)
    loader = _Loader()
    once = sweeper._ComposedOnce(loader)
    batch = [["freq=d05"], ["freq=d1"], ["freq=d2"], ["freq=d4"]]
    once.keep_all({}, batch)
    assert loader.calls == []                                            # composed in the workers
    assert [once.load_sweep_config({}, o)["composed"] for o in batch] == [tuple(o) for o in batch]
    failing = _FailingLoader()
    once = sweeper._ComposedOnce(failing)
    with pytest.raises(ValueError, match="typo"):                        # here, as Hydra would report it
        once.keep_all({}, [["freq=d05"], ["freq=typo"]])
    assert failing.calls == [("freq=d05",)]


def test_configurations_composed_by_the_workers_equal_those_composed_here():
    from hydra._internal.hydra import Hydra
    from hydra._internal.utils import create_config_search_path
    from hydra.core.global_hydra import GlobalHydra
    from hydra.types import RunMode
    from omegaconf import OmegaConf

    from hydra_plugins.mm2fsk_bench import sweeper

    try:                        # Hydra's global state, as `python -m bench` sets it up: cleared for the next tests
        loader = Hydra.create_main_hydra2(task_name="app", config_search_path=create_config_search_path(
            str(CONFIG_DIR))).config_loader
        master = loader.load_configuration("config", ["experiment=table3", "dataset=maroon", "dataset.root=/x"],
                                           RunMode.MULTIRUN)
        batch = [["cell=bp_d05"], ["cell=mm2fsk_d10"], ["cell=prior_only_d10"]]
        forked = sweeper._compose_in_workers(loader, master, batch, 2)
        here = [loader.load_sweep_config(master, o) for o in batch]
    finally:
        GlobalHydra.instance().clear()
    assert forked is not None and [OmegaConf.to_yaml(c) for c in forked] == [OmegaConf.to_yaml(c) for c in here]


def test_the_ground_truths_key_is_worked_out_once_per_capture_held_in_memory(synth_root, tmp_path, monkeypatch):
    """Later cells of a process on a capture frame it holds find its ground truth's disk key in memory: the files
    it names (the capture's metadata parsed anew, ~3 ms a row) are listed once; a fresh process lists them again."""
    listed = []
    real = reader.files_read
    monkeypatch.setattr(reader, "files_read", lambda *a, **k: listed.append(a[2]) or real(*a, **k))
    monkeypatch.setattr(captures, "_CAPTURES", type(captures._CAPTURES)())
    monkeypatch.setattr(captures, "_GROUND_TRUTHS", type(captures._GROUND_TRUTHS)())
    rows = [app.run(_cfg(synth_root, "null", cell, f"store.cache={tmp_path / 'kept'}"), tmp_path / cell)[0]
            for cell in ("cell=2fsk_d05", "cell=mm2fsk_d10", "cell=2fsk_d10")]
    assert listed.count(("mesh",)) == 1
    assert len({row["C_g_px"] for row in rows}) == 1                     # one ground truth for the three cells
    monkeypatch.setattr(captures, "_CAPTURES", type(captures._CAPTURES)())
    app.run(_cfg(synth_root, "null", "cell=2fsk_d05", f"store.cache={tmp_path / 'kept'}"), tmp_path / "again")
    assert listed.count(("mesh",)) == 2


def _clock_of(ticks_s: list[tuple[float, float, float]]) -> sizing.CpuClock:
    """A clock whose samples are (wall s, the machine's busy CPU s, the job's own CPU s), one per look."""
    looks = iter(ticks_s)
    return sizing.CpuClock(read=lambda: sizing.CpuSample(*next(looks), helpers_s={}))


def test_a_short_calls_rest_of_the_machine_is_judged_over_enough_clock_ticks():
    """/proc/stat counts 10 ms ticks: two ticks of another process's housekeeping inside a 30 ms call read as 0.67
    core over the call alone (contended); over the last 0.2 s of calls, as the clock judges a short call, 0.1 core.
    A process that keeps a core busy is still seen (1 core), and a long call is judged over itself."""
    clock = _clock_of([(0.0, 0.0, 0.0), (0.03, 0.03, 0.03),                  # calls of 30 ms every 50 ms
                       (0.05, 0.05, 0.05), (0.08, 0.08, 0.08),
                       (0.10, 0.10, 0.10), (0.13, 0.13, 0.13),
                       (0.15, 0.15, 0.15), (0.18, 0.18, 0.18),
                       (0.20, 0.20, 0.20), (0.23, 0.25, 0.23)])              # two foreign ticks in the last call
    samples = [clock.sample() for _ in range(10)]
    over_the_call = (0.25 - 0.20 - (0.23 - 0.20)) / 0.03
    assert sizing.contended(0.0, over_the_call)                            # the old rule: 0.67 core
    assert clock.others_cores(samples[-2], samples[-1]) == pytest.approx(0.02 / 0.2)
    assert not sizing.contended(0.0, clock.others_cores(samples[-2], samples[-1]))
    busy = _clock_of([(t, 2.0 * t, t) for t in np.arange(0.0, 0.26, 0.05)] + [(0.28, 0.56, 0.28)])
    samples = [busy.sample() for _ in range(7)]                            # another process on one core all along
    assert sizing.contended(0.0, busy.others_cores(samples[-2], samples[-1]))
    long = _clock_of([(0.0, 0.0, 0.0), (1.0, 1.0, 0.0), (1.5, 1.5, 0.5)])  # busy before the call, not during it
    samples = [long.sample() for _ in range(3)]
    assert long.others_cores(samples[-2], samples[-1]) == 0.0
    first = _clock_of([(0.0, 0.0, 0.0), (0.01, 0.02, 0.0)])                # a first call of 10 ms: unknown
    assert np.isnan(first.others_cores(first.sample(), first.sample()))


def test_the_job_s_own_helpers_are_counted_by_process_across_a_widened_window():
    """A helper born between two samples counts from nothing (its whole CPU time is the job's), one gone counts 0."""
    looks = iter([sizing.CpuSample(0.0, 0.0, 0.0, {7: 5.0, 8: 1.0}), sizing.CpuSample(0.3, 5.6, 0.1, {7: 5.2, 9: 0.3})])
    clock = sizing.CpuClock(read=lambda: next(looks))
    start, end = clock.sample(), clock.sample()
    assert clock.others_cores(start, end) == pytest.approx((5.6 - 0.1 - 0.2 - 0.3) / 0.3)
