"""`python -m bench`'s early start of Warp (its import, the CUDA driver and context: a fixed cost of every sweep on
a GPU, docs/measurements/sweep.md) on a thread of its own while Hydra starts, composes and launches, where the jobs
run in this process on a Warp device."""
from __future__ import annotations

import threading

IN_PROCESS_LAUNCHERS = ("inprocess", "basic")
_threads: list[threading.Thread] = []
NOT_RUNS = {"--cfg", "-c", "--info", "-i", "--help", "-h", "--hydra-help", "--shell-completion", "-sc"}


def jobs_in_this_process(argv: list[str]) -> bool:
    """Whether this command runs jobs in this process: a run or multirun (not --cfg, --info, --help or shell
    completion) that keeps the jobs here (no `hydra/launcher=` other than the in-process ones: joblib's or SLURM's
    jobs run in processes of their own)."""
    if any(arg.split("=", 1)[0] in NOT_RUNS for arg in argv):
        return False
    launchers = [arg.split("=", 1)[1] for arg in argv if arg.startswith("hydra/launcher=")]
    return all(launcher in IN_PROCESS_LAUNCHERS for launcher in launchers)


def starts_early(argv: list[str]) -> bool:
    """Whether this command runs jobs in this process on a Warp device: `jobs_in_this_process` and the command line
    asks for `device=cuda` or `auto` (alone or in a sweep list): a CUDA context here for jobs run elsewhere would only
    take GPU memory."""
    return jobs_in_this_process(argv) and any(
        arg.startswith("device=") and any(name in arg for name in ("cuda", "auto")) for arg in argv)


def _start_warp() -> None:
    try:
        from methods.backends.warp.runtime import init

        init()
    except Exception:   # noqa: BLE001 -- no Warp, no driver: the job's own start says so in one line
        pass


def start_early(argv: list[str]) -> None:
    """Warp's start (its import, the CUDA driver and context) on a thread of its own while Hydra starts and composes
    the jobs, where `starts_early`: the first job's device check (bench.harness.app, `resolve_device`) waits
    for it instead of starting it (methods.backends.warp.runtime.init holds a lock). Not a daemon: while Warp starts,
    what the process writes to its stderr is held and written after (runtime.init), so an early error line (a config
    mistake) is written before the process ends, not lost with the thread."""
    if starts_early(argv):
        _threads.append(threading.Thread(target=_start_warp, name="warp-start"))
        _threads[-1].start()


def wait() -> None:
    """Until Warp's early start (if any) has ended: before this process forks (the merge's worker,
    bench.report.merge), which must not copy a thread's half-taken import locks or the stderr it holds."""
    for thread in _threads:
        thread.join()
