"""`python -m bench ...`: the Hydra app (see bench/harness/app.py).

Before Hydra starts, its command line is checked with Hydra's own parser made one-line (an unknown flag, or two
of -m/--cfg/--info/--run/--shell-completion, which Hydra reports with a usage dump or a traceback), and an
explicit `hydra.run.dir=` (with -m: `hydra.sweep.dir=`) that cannot be created ends in one line (Hydra would print
a traceback). A closed stdout (`python -m bench ... | head -1`) or Ctrl-C end quietly (bench.cli). Hydra's own
messages for config mistakes (an unknown option of a group, with the list of options) are left as Hydra words them.

Where the jobs run here on a Warp device, Warp starts on a thread of its own while Hydra starts (bench.warpstart);
on a host of several cores, the merge's worker and the output process start before Hydra too (bench.prestart).
At its exit the process skips the interpreter's teardown of its modules and objects (`QuickExit`).
"""
import atexit
import logging
import os
import sys

from bench import cli, prestart, warpstart
from bench.harness import stages


class QuickExit:
    """The process's end without the interpreter's teardown: freeing every module and object of SciPy, pandas,
    h5py, Hydra and Warp took 0.3 s on two loaded cores after the last exit handler (docs/measurements/sweep.md).
    `run` records the exit code; `end`, registered before any other exit handler and so run after all of them (after
    the interpreter has joined every thread: the jobs' writers, the output process's manager; and after logging's,
    multiprocessing's, Warp's and the stage clock's handlers), flushes stdout and stderr and ends the process with
    that code."""

    def __init__(self):
        self.code = 1                   # an exception that escapes: Python's own exit code after its traceback

    def run(self, main) -> None:
        try:
            main()
        except SystemExit as done:
            self.code = done.code if isinstance(done.code, int) else 0 if done.code is None else 1
            raise

    def end(self) -> None:
        logging.shutdown()               # registered before this (imported first): its files flushed and closed
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):    # a closed pipe or stream: nothing more to say
                pass
        os._exit(self.code)

PROG = "python -m bench"


def check_command_line(argv: list[str]) -> bool:
    """UserError (or a one-line argparse error) for what Hydra would refuse with a usage dump or a traceback;
    returns whether it is a multirun (-m)."""
    from hydra._internal.utils import get_args_parser

    parser = get_args_parser()
    parser.prog = PROG
    parser.error = lambda message: cli.fail(f"{message} (see {PROG} --help)")   # one line, as cli.ArgumentParser
    args = parser.parse_args(argv)
    modes = [flag for flag, on in (("--run", args.run), ("--multirun", args.multirun), ("--cfg", args.cfg),
                                   ("--info", args.info is not None), ("--shell-completion", args.shell_completion))
             if on]
    if len(modes) > 1:
        raise cli.UserError(PROG, f"{' and '.join(modes)} cannot be combined (use one of them)")
    key = "hydra.sweep.dir=" if args.multirun else "hydra.run.dir="
    for override in args.overrides:
        if override.startswith(key) and "${" not in override:
            cli.check_creatable_dir(override[len(key):], override)
    return bool(args.multirun)


def skip_mode_probe() -> None:
    """Hydra composes the whole configuration once only to read `hydra.mode` (`Hydra.get_mode`) before it composes it
    again to run. With -m the mode is MULTIRUN whatever that probe finds (hydra/_internal/utils.py `_run_app`; no
    config here sets hydra.mode), so a multirun skips it: one composition less (0.1-0.2 s)."""
    from hydra._internal.hydra import Hydra

    Hydra.get_mode = lambda self, config_name, overrides: None


def _main() -> None:
    stages.start_from_environment()    # python -m bench.perf experiment: seconds per stage, imports included
    logging.raiseExceptions = False    # a log line to a closed stdout is dropped, not a '--- Logging error ---' dump
    multirun = check_command_line(sys.argv[1:])
    if multirun:
        skip_mode_probe()
    warpstart.start_early(sys.argv[1:])
    prestart.start(sys.argv[1:], multirun)
    from bench.harness.app import main

    main()


quick_exit = QuickExit()
atexit.register(quick_exit.end)         # first registered, last run (atexit runs its handlers in reverse)
quick_exit.run(lambda: cli.run_guarded(_main))
