"""`python -m bench`'s helper processes, started before Hydra on a host of MIN_CORES cores or more where the jobs run
in this process (bench.warpstart.jobs_in_this_process): the merge's worker of a multirun (bench.report.merge
`prestart_worker`) and the output process (bench.harness.workers `output_process`: its fork server, a fresh
interpreter, imports what a worker needs, ~1 s on the H100 host). Started with the first job instead, the output
process's start made the first capture's hand-over wait 0.3-0.6 s for those imports, and the merge's worker, forked
after the first job, imported pandas and matplotlib while the last jobs ran, in a short sweep not always done by
its end (docs/measurements/sweep.md). Both are fresh interpreters, not forks of this process. On fewer cores they
start as before (the output process not at all, the merge's worker after the first job): there they would take one
of the two cores from Hydra's start and the first job.
"""
from __future__ import annotations

from bench import warpstart
from methods.domain.host import usable_cores

MIN_CORES = 4     # as the output process's (bench.harness.workers) and the composition workers' (hydra_plugins)


def output_process_wanted(argv: list[str]) -> bool:
    """Whether the jobs write their files through the output process: no `evaluation.workers` on the command line
    but 0 (scoring workers write them instead; a value set in a config file only shows once composed: the process
    then waits unused, as it does for the rest of a sweep whose jobs got workers)."""
    values = [arg.split("=", 1)[1] for arg in argv if arg.lstrip("+~").startswith("evaluation.workers=")]
    return all(value == "0" for value in values)


def start(argv: list[str], multirun: bool) -> None:
    """The helpers this command's jobs will use (module doc), started now."""
    if not warpstart.jobs_in_this_process(argv) or usable_cores() < MIN_CORES:
        return
    from bench.harness import workers
    from bench.report import merge

    if multirun:
        merge.prestart_worker()
    if output_process_wanted(argv):
        workers.output_process()
