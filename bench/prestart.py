"""`python -m bench`'s helper processes, started before Hydra on a host of MIN_CORES cores or more where the jobs run
in this process (bench.warpstart.jobs_in_this_process): the merge's worker of a multirun (bench.report.merge
`prestart_worker`) and the fork server of the job's worker processes (the output process, or the scoring workers:
bench.harness.workers), a fresh interpreter that imports what a worker needs (~1 s on the H100 host). Started with
the first job instead, the fork server's imports made the first capture's hand-over wait 0.3-0.7 s for them, and
the merge's worker, forked after the first job, imported pandas and matplotlib while the last jobs ran, in a short
sweep not always done by its end (docs/measurements/sweep.md). Neither is a fork of this process. On fewer cores
they start as before (no output process there, the merge's worker after the first job): there they would take one of
the two cores from Hydra's start and the first job.
"""
from __future__ import annotations

from bench import warpstart
from methods.domain.host import usable_cores

MIN_CORES = 4     # as the output process's (bench.harness.workers) and the composition workers' (hydra_plugins)


def start_fork_server() -> None:
    """The workers' fork server, with the imports bench.harness.workers.pool gives it, started now; the pools and
    their processes start with the first job as before, forked from it. Only the server: where the command then ends
    before its first job (a config mistake), the server sees this process gone and exits without forking anything,
    where a pool's worker forked for this process would fail on the pool's semaphores after it ended, a traceback on
    the command's stderr."""
    import multiprocessing
    from multiprocessing import forkserver

    from bench.harness import workers

    try:
        multiprocessing.get_context("forkserver").set_forkserver_preload(workers.PRELOAD)   # as workers.pool does
        forkserver.ensure_running()
    except (ValueError, OSError):      # no fork server here (Windows), or no process to start: as on few cores
        pass


def start(argv: list[str], multirun: bool) -> None:
    """The helpers this command's jobs will use (module doc), started now."""
    if not warpstart.jobs_in_this_process(argv) or usable_cores() < MIN_CORES:
        return
    from bench.report import merge

    if multirun:
        merge.prestart_worker()
    start_fork_server()
