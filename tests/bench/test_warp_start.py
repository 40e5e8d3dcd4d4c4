"""Warp started on a thread of its own while Hydra starts (bench.warpstart.start_early): only where this process
runs jobs on a Warp device, once whichever thread asks first (methods.backends.warp.runtime.init), and what the
process writes to stderr meanwhile is still written."""
from __future__ import annotations

import subprocess
import sys
import threading
import time

import pytest

from bench.warpstart import starts_early


@pytest.mark.parametrize("argv, early", [
    (["-m", "experiment=table3", "device=cuda", "store.dir=null"], True),
    (["-m", "experiment=table2", "device=cpu,cuda"], True),
    (["device=auto"], True),
    (["-m", "experiment=table3", "device=cuda", "hydra/launcher=basic"], True),
    (["-m", "experiment=table3"], False),                                 # the default device: cpu
    (["-m", "experiment=table3", "device=cpu"], False),
    (["-m", "experiment=table3", "device=cuda", "hydra/launcher=joblib"], False),   # jobs in other processes
    (["-m", "experiment=table3", "device=cuda", "hydra/launcher=slurm_gpu"], False),
    (["--cfg", "job", "device=cuda"], False),
    (["--shell-completion", "query=device=cu"], False),
    (["--info", "device=cuda"], False),
])
def test_warp_starts_early_only_where_this_process_runs_jobs_on_a_warp_device(argv, early):
    assert starts_early(argv) is early


def test_warp_is_started_once_whichever_thread_asks_first(monkeypatch):
    pytest.importorskip("warp")
    from methods.backends.warp import runtime

    calls = []

    def slow_init():
        calls.append(threading.current_thread().name)
        time.sleep(0.2)

    monkeypatch.setattr(runtime.wp, "init", slow_init)
    monkeypatch.setattr(runtime, "_started", [])
    early = threading.Thread(target=runtime.init, name="warp-start")
    early.start()
    time.sleep(0.05)
    runtime.init()                    # the first job's device check: waits for the early start, does not start again
    assert runtime._started == [True]
    early.join()
    assert calls == ["warp-start"]


def test_an_early_error_line_is_written_while_warp_starts(tmp_path):
    """A config mistake found while Warp starts (its native stderr held meanwhile) is still on stderr, as it is
    without the early start."""
    pytest.importorskip("warp")
    outputs = []
    for device in ("cuda", "cpu"):
        result = subprocess.run([sys.executable, "-m", "bench", "-m", "experiment=no_such_experiment",
                                 f"device={device}", f"hydra.sweep.dir={tmp_path / device}"],
                                capture_output=True, text=True, timeout=120)
        outputs.append((result.returncode, result.stderr))
    assert outputs[0] == outputs[1]
    assert outputs[0][0] != 0 and "no_such_experiment" in outputs[0][1]


def test_the_merges_fork_waits_for_warps_early_start(monkeypatch):
    """A sweep whose first job runs on the CPU does not wait for Warp's start; the merge's worker is forked only
    after it (a fork must not copy the starting thread's import locks or its held stderr)."""
    from bench import warpstart

    started, released = threading.Event(), threading.Event()

    def slow_start():
        started.set()
        released.wait(5)

    monkeypatch.setattr(warpstart, "_start_warp", slow_start)
    monkeypatch.setattr(warpstart, "_threads", [])
    warpstart.start_early(["-m", "device=cpu,cuda"])
    started.wait(5)
    waiting = threading.Thread(target=warpstart.wait)
    waiting.start()
    waiting.join(0.2)
    assert waiting.is_alive()             # still starting: the fork waits
    released.set()
    waiting.join(5)
    assert not waiting.is_alive()


def test_the_merge_waits_for_warps_start_before_it_forks(monkeypatch):
    from bench.report import merge

    calls = []
    monkeypatch.setattr(merge.warpstart, "wait", lambda: calls.append("wait for Warp's start"))
    monkeypatch.setattr(merge, "start_worker", lambda: calls.append("fork"))
    callback = merge.MergeResults()
    callback.on_multirun_start(None)
    callback.on_job_end(None, None)
    assert calls == ["wait for Warp's start", "fork"]
