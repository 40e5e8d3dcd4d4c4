"""What a job of `python -m bench` knows about its sweep: how many jobs it has, and whether it ran alone.

* `SweepSize` (a Hydra callback, configs/config.yaml `hydra.callbacks.size`) counts the multirun's jobs before
  they are launched and hands the number to them in the environment (`BENCH_SWEEP_JOBS`), for progress lines
  such as `[table3 5/13] bp_d05: 8 captures, 3 computed, 5 cached, 12.3 s`.
* `timing_mode` says how a job's runtimes were measured: 'alone' (no other job of the sweep ran at the same time:
  a single run, the basic launcher, joblib with one worker, a one-job sweep) or 'parallel' (jobs shared the
  machine: joblib with more than one worker, submitit_local, SLURM arrays with array_parallelism > 1, any other
  launcher). Results rows carry it in the column `timing`, with 'contended' for a row the app timed alone while
  other processes kept the cores busy during its call (`contended`: on Linux, the CPU time every other process
  used during the call, from /proc/stat minus our own, column `others_cores`, above half a core on average; a call
  shorter than 0.2 s is judged over the last 0.2 s of calls, `CpuClock`; elsewhere the 1-minute load average,
  column `load_1m`, above the number of cores).
"""
from __future__ import annotations

import collections
import dataclasses
import math
import os
import threading
import time

from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import HydraException
from hydra.experimental.callback import Callback
from hydra.types import RunMode
from omegaconf import DictConfig

JOBS_ENV = "BENCH_SWEEP_JOBS"


def count_jobs(params: dict, task_overrides: list[str]) -> int:
    """Number of jobs the basic sweeper makes of the config's sweeper params and the command-line overrides
    (later overrides of a key replace earlier ones; a sweep `a,b,c` counts 3)."""
    counts = {}
    for override in OverridesParser.create().parse_overrides([f"{k}={v}" for k, v in params.items()]
                                                             + list(task_overrides)):
        counts[override.get_key_element()] = (len(list(override.sweep_string_iterator()))
                                              if override.is_sweep_override() else 1)
    return math.prod(counts.values())


class SweepSize(Callback):
    """Before a multirun's jobs start: put their number into the environment the jobs inherit."""

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        try:
            os.environ[JOBS_ENV] = str(count_jobs(dict(config.hydra.sweeper.get("params") or {}),
                                                  list(config.hydra.overrides.task)))
        except HydraException:    # e.g. a glob sweep (needs the config loader): progress lines say '?'
            os.environ.pop(JOBS_ENV, None)


def sweep_jobs() -> int | None:
    """The current multirun's number of jobs (None when unknown)."""
    value = os.environ.get(JOBS_ENV, "")
    return int(value) if value.isdigit() else None


def machine_load() -> float:
    """The machine's 1-minute load average (runnable and waiting tasks, ours included); NaN where unknown."""
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


OTHERS_CORES_MAX = 0.5     # other processes' average CPU use (cores) during a call that still counts as alone


def busy_cpu_s() -> float:
    """CPU seconds every core has spent busy since boot (/proc/stat: all but idle and iowait); NaN off Linux.
    The difference over a call, minus the process's own CPU time, is what the rest of the machine used."""
    data = _proc_bytes("/proc/stat")
    try:
        fields = [int(v) for v in data.split(b"\n", 1)[0].split()[1:]]
    except (AttributeError, ValueError):         # unreadable (None): off Linux
        return float("nan")
    if len(fields) < 4:
        return float("nan")
    idle = fields[3] + (fields[4] if len(fields) > 4 else 0)
    return (sum(fields[:8]) - idle) / os.sysconf("SC_CLK_TCK")


def descendants() -> list[int]:
    """The process ids of this process's children, theirs, and so on (/proc/<pid>/task/<tid>/children; empty off
    Linux): the job's own helpers (a fork server, its pool workers, the merge's worker), whose CPU time is the job's
    own. This process's children are read from its Python threads' lists (`_own_threads`), its descendants' from
    every thread's."""
    found, todo = [], [(os.getpid(), _own_threads())]
    while todo:
        pid, tids = todo.pop()
        for tid in tids:
            try:
                new = [int(child) for child in _proc_bytes(f"/proc/{pid}/task/{tid}/children").split()]
            except (AttributeError, ValueError):     # gone (None) or unreadable
                continue
            found += new
            todo += [(child, _threads(child)) for child in new]
    return found


def _threads(pid: int) -> list[str]:
    try:
        return os.listdir(f"/proc/{pid}/task")
    except OSError:
        return []


def _own_threads() -> set[int]:
    """The threads of this process that can have started a child process: its Python threads (a fork, subprocess or
    multiprocessing start runs on one; the children of one that ended are the main thread's, Linux hands them to the
    thread group's leader). Not /proc/self/task, the list of every thread (the query pool's, CUDA's and BLAS's):
    listing it took 1.6 ms a sample on the H100 host, 0.36 s of Table III's main thread."""
    return {os.getpid(), *(thread.native_id for thread in threading.enumerate() if thread.native_id is not None)}


def _proc_bytes(path: str) -> bytes | None:
    """A /proc file's bytes (up to 64 KiB), or None where it cannot be read. Plain os.open/os.read: a sample reads one
    `children` file per thread of the process (30-40 on the H100 host: the query pool, Warp's, the writers') around
    every timed call, and Python's buffered text files cost three times as much (0.25 against 0.08 ms a sample for
    25 threads on the 2-core machine; 0.12 s of Table II's main thread on the H100 host)."""
    try:
        handle = os.open(path, os.O_RDONLY)
    except OSError:
        return None
    try:
        return os.read(handle, 65536)
    except OSError:
        return None
    finally:
        os.close(handle)


def processes_cpu_s(pids) -> float:
    """CPU seconds (user + system) the processes `pids` have used so far (/proc/<pid>/stat); a process that is gone
    or unreadable counts 0 (off Linux every one does)."""
    total_ticks = 0
    for pid in pids:
        try:
            fields = _proc_bytes(f"/proc/{pid}/stat").rpartition(b")")[2].split()   # after the command name, which
            total_ticks += int(fields[11]) + int(fields[12])      # may hold spaces; utime, stime: fields 14 and 15
        except (AttributeError, ValueError, IndexError):          # gone (None) or unreadable
            continue
    return total_ticks / os.sysconf("SC_CLK_TCK") if total_ticks else 0.0


MIN_WINDOW_S = 0.2    # /proc/stat counts 10 ms clock ticks: one stray tick is 0.05 core over 0.2 s, 0.3 over 30 ms
MAX_WINDOW_S = 1.0    # the furthest back a short call's window reaches


@dataclasses.dataclass(frozen=True)
class CpuSample:
    """What the machine and the job had used at one moment: wall clock (s), the machine's busy CPU seconds
    (`busy_cpu_s`), this process's CPU seconds and its descendants' by process id."""

    wall_s: float
    busy_s: float
    own_s: float
    helpers_s: dict[int, float]


class CpuClock:
    """Samples taken around the job's timed calls, and the cores the rest of the machine used over a call
    (`others_cores`). A call shorter than MIN_WINDOW_S is judged over the last MIN_WINDOW_S or more ending with it
    (from an earlier call's sample, at most MAX_WINDOW_S back): /proc/stat's 10 ms ticks make a 23-40 ms window read
    one tick of any process as ~0.3 core, so that calls of the camera-only cell on an idle host read 0.63-0.69 and
    were marked contended. Other jobs that take the cores run for seconds, not for one call's 30 ms: a longer window
    still sees them. The job's own CPU (its threads, its child processes: the output process, the fork server that
    starts it) is not the rest of the machine's."""

    def __init__(self, read=None):
        self.read = read or self._read
        self.samples: collections.deque[CpuSample] = collections.deque(maxlen=256)

    @staticmethod
    def _read() -> CpuSample:
        helpers = descendants()
        return CpuSample(time.perf_counter(), busy_cpu_s(), time.process_time(),
                         {pid: processes_cpu_s([pid]) for pid in helpers})

    def sample(self) -> CpuSample:
        taken = self.read()
        self.samples.append(taken)
        return taken

    def others_cores(self, start: CpuSample, end: CpuSample) -> float:
        """The rest of the machine's average CPU use (cores) over the call from `start` to `end` (both `sample`s),
        widened for a short call (class doc); NaN where unknown (off Linux, a window under 20 ms)."""
        if end.wall_s - start.wall_s < MIN_WINDOW_S:
            earlier = [s for s in self.samples if end.wall_s - MAX_WINDOW_S <= s.wall_s <= start.wall_s]
            widened = [s for s in earlier if s.wall_s <= end.wall_s - MIN_WINDOW_S]
            start = widened[-1] if widened else (earlier[0] if earlier else start)
        window_s = end.wall_s - start.wall_s
        own_s = end.own_s - start.own_s + sum(cpu_s - start.helpers_s.get(pid, 0.0)
                                              for pid, cpu_s in end.helpers_s.items())
        others_s = end.busy_s - start.busy_s - own_s
        if window_s < 0.02 or not math.isfinite(others_s):
            return float("nan")
        return max(0.0, others_s) / window_s


CLOCK = CpuClock()


def contended(load_1m: float, others_cores: float = float("nan")) -> bool:
    """Whether a runtime had to share the cores: other processes used more than OTHERS_CORES_MAX cores on average
    during the call (`others_cores`, where measured); else, by the 1-minute load average, more runnable tasks
    than cores (the load counts our own threads too, so it only catches heavy contention)."""
    if math.isfinite(others_cores):
        return others_cores > OTHERS_CORES_MAX
    return load_1m > (os.cpu_count() or 1)


def runs_jobs_here(launcher: DictConfig) -> bool:
    """Whether a launcher (its Hydra config) runs a multirun's jobs one after another in the sweep's process:
    Hydra's basic launcher and ours (hydra_plugins/mm2fsk_bench/inprocess.py)."""
    return str(launcher.get("_target_", "")).endswith(("BasicLauncher", "InProcessLauncher"))


def timing_mode(hydra_cfg: DictConfig) -> str:
    """'alone' or 'parallel' for the job whose Hydra config (HydraConfig.get()) this is (module docstring)."""
    if hydra_cfg.mode != RunMode.MULTIRUN or sweep_jobs() == 1:
        return "alone"
    launcher = hydra_cfg.launcher
    target = str(launcher.get("_target_", ""))
    if runs_jobs_here(launcher):
        return "alone"
    if target.endswith("JoblibLauncher"):
        n_jobs = int(launcher.n_jobs)                         # joblib: -1 = every core, -2 = all but one, ...
        workers = n_jobs if n_jobs > 0 else (os.cpu_count() or 1) + 1 + n_jobs
        return "alone" if workers <= 1 else "parallel"
    if target.endswith("SlurmLauncher") and launcher.get("array_parallelism") == 1:
        return "alone"
    return "parallel"
