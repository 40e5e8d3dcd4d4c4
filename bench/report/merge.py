"""After a multirun: merge the jobs' rows into the sweep root and write its table and plots (a Hydra callback).

Sweep root after `python -m bench -m experiment=table3`: `results.csv` (every job's rows), `table3.md`, `.csv`,
`.tex` and `table3_pairs.csv` (bench.report.tables: every pair of rows compared per capture),
`runtime_vs_error.png` (redrawn only when the table changed) and, with `report.depth_errors=true`,
`depth_errors/<object>_<distance>_<frame>.png` (bench.report.plots; off by default: the figures cost more than the
rest of the merge).
`python -m bench.report.merge ROOT [--table NAME]` does the same for a sweep that was interrupted before the end.

In a multirun the merge runs in a worker process that imports what the merge needs (pandas, SciPy's statistics,
matplotlib: ~0.8 s on a quiet 2-core machine, ~1.5 s on the H100 host) while the jobs run, then waits for the sweep
root on a pipe; the callback hands it over at the multirun's end and waits for it. On a host of several cores it is
a fresh interpreter started before Hydra (`SpawnedWorker`, `prestart_worker`, bench.prestart: `python -m
bench.report.merge --serve`), on fewer it is forked from the sweep's process when its first job ends (`Worker`:
started earlier, its imports would compete with composing the jobs for the two cores). Its errors are its own lines
on stderr and its exit code is the sweep's (as in one process).
"""
from __future__ import annotations

import atexit
import csv
import io
import json
import os
import signal
import subprocess
import sys
import threading
import traceback
from pathlib import Path
from typing import TYPE_CHECKING

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from bench import cli, warpstart
from bench.harness import stages
from bench.harness.results import finish_deferred, write_results
from methods.domain.errors import DatasetError

if TYPE_CHECKING:   # imported where used: the sweep's process loads this callback, and its jobs do not need pandas
    import pandas as pd


def job_files(root: Path, name: str) -> list[Path]:
    """`root/<job number>_*/name` in job order."""
    return sorted(root.glob(f"*/{name}"), key=lambda p: int(p.parent.name.split("_")[0]))


def read_job_rows(path: Path) -> pd.DataFrame:
    """A job's results.csv, every line whole: a line cut mid-row (a job killed while appending it, a full disk) or
    a row with another number of fields than the header is a DatasetError naming the file and line, never a row
    read with its last values missing or cut short."""
    data = path.read_bytes()
    try:
        text = data.decode("utf-8")
        lines = list(csv.reader(io.StringIO(text, newline="")))
    except (UnicodeDecodeError, csv.Error) as err:
        raise DatasetError(path, f"not a results table ({err})") from None
    if not lines:
        raise DatasetError(path, "is empty (the job wrote no row)")
    if not data.endswith(b"\n"):
        raise DatasetError(path, f"line {len(lines)} is cut mid-row (a job killed, or a disk full, while writing it): "
                                 "run the sweep again (the store keeps the finished cells) or delete that line")
    short = next((n for n, line in enumerate(lines[1:], 2) if len(line) != len(lines[0])), None)
    if short is not None:
        raise DatasetError(path, f"line {short} has {len(lines[short - 1])} fields, the header {len(lines[0])}")
    import pandas as pd

    return pd.read_csv(io.StringIO(text))


def merge(root: Path) -> pd.DataFrame:
    """Concatenate `root/*/results.csv` (job order) into `root/results.csv` (atomic); returns the rows."""
    import pandas as pd

    parts = job_files(root, "results.csv")
    if not parts:
        raise FileNotFoundError(f"{root}: no job wrote */results.csv")
    rows = pd.concat([read_job_rows(p) for p in parts], ignore_index=True)
    return write_results(root / "results.csv", rows.to_dict("records"))


def report(root: Path, table: str | None, depth_errors: bool = False) -> pd.DataFrame:
    """Merge the rows; with a table name also write the table (md, csv with its pairs, tex) and the runtime plot,
    and with depth_errors the per-capture depth-error figures; returns the summary."""
    # here, not at the top: the sweep's own process loads the callback, and it needs neither matplotlib (~1 s) nor
    # the tables' SciPy statistics (~0.3 s) when the worker merges
    from bench.report import plots, tables

    rows = merge(root)
    if table is None:
        return tables.summarise(rows)
    summary, pairs = tables.summary_and_pairs(rows)     # scored once for both
    text = tables.caption(table, rows, summary=summary)
    (root / f"{table}.md").write_text(f"{text}\n\n{tables.summary_markdown(summary)}\n")
    tables.write_csv(summary, root / f"{table}.csv", pairs)
    (root / f"{table}.tex").write_text(tables.summary_latex(summary, text))
    runtime_plot(root, table, summary)
    if depth_errors:
        runs = [(tables.job_label(p.parent / "results.csv"), p) for p in job_files(root, "arrays.h5")]
        plots.depth_error_maps(runs, root / "depth_errors")
    return summary


def runtime_plot(root: Path, table: str, summary: pd.DataFrame) -> Path:
    """`root/runtime_vs_error.png` (bench.report.plots), redrawn only when the summary or the plotting code changed
    (bench.report.keyed)."""
    from bench.report import keyed, plots

    path = root / "runtime_vs_error.png"
    key = keyed.digest(summary.to_csv(), table, keyed.module_source(plots))
    keys = keyed.Keys(root)
    if not keys.fresh(path.name, key, [path]):
        plots.runtime_vs_error(summary, path, f"{table}: runtime against error")
        keys.record(path.name, key)
    return path


class Worker:
    """The merge's worker process (module doc): forked from this process, so it shares the modules this process has
    imported (NumPy, SciPy's spatial, h5py) and imports only the rest (pandas, SciPy's statistics, matplotlib); it reads
    one request from a pipe and exits with 0 (done, or no request: the multirun ended without a merge), 2 after a user
    error (its one `error:` line on stderr) or 1 after a bug (its traceback on stderr). It never runs this process's
    exit handlers (e.g. the stage clock's, bench.harness.stages): the waiting process counts the merge."""

    def __init__(self):
        read_fd, self._write_fd = os.pipe()
        try:
            self.pid = os.fork()
        except OSError:                      # no memory or process slots: the caller merges in this process
            os.close(read_fd)
            os.close(self._write_fd)
            raise
        if self.pid == 0:                    # the worker
            os.close(self._write_fd)
            _serve_and_exit(read_fd)
        os.close(read_fd)

    def hand_over(self, request: dict | None) -> int:
        """Send the request (None: nothing to merge) and wait for the worker's exit code."""
        try:
            if request is not None:
                os.write(self._write_fd, json.dumps(request).encode())
        except BrokenPipeError:              # it ended early (its error is on stderr); its exit code says
            pass
        finally:
            os.close(self._write_fd)
        return os.waitstatus_to_exitcode(os.waitpid(self.pid, 0)[1])


def _warm_up() -> None:
    """The merge's first-use costs, paid while the jobs run: its imports, pandas' LaTeX writer (jinja2 templates),
    matplotlib's Agg canvas, fonts and PNG writer (a throwaway plot): ~0.1 s less to wait for at the end."""
    import pandas as pd

    from bench.report import keyed, plots, tables  # noqa: F401

    pd.DataFrame({"a": [1.0]}).style.to_latex()
    one_row = pd.DataFrame({"method": ["m"], "row": ["r"], "runtime_ms": [1.0], "P_cm": [1.0], "captures": [1],
                            "failed": [0]})
    plots.runtime_vs_error(one_row, io.BytesIO(), "")


SERVE = "--serve"          # python -m bench.report.merge --serve: a SpawnedWorker
SPAWNED_NICENESS = 10      # a SpawnedWorker's priority below the jobs' (its imports, ~3 s of CPU on the H100 host,
                           # overlapped the first jobs of Table III, whose KD-tree queries run a thread per core)


def spawned_niceness(own: int) -> int:
    """A SpawnedWorker's niceness for a sweep's process of niceness `own`: SPAWNED_NICENESS more, at most 19."""
    return min(19, own + SPAWNED_NICENESS)


class SpawnedWorker:
    """The merge's worker as a fresh interpreter (`python -m bench.report.merge --serve`; module doc), with `Worker`'s
    protocol: the request on its stdin (EOF without one: it just exits), its exit code. Started before Hydra on a host
    of several cores (bench.prestart), so the sweep's process, which holds a CUDA context and many threads by the
    first job's end, is not forked for it. One never handed a request is ended with this process (`_end_unused`):
    started for a command that then failed before its multirun, it would hold stderr until its imports were done."""

    def __init__(self):
        environment = {name: value for name, value in os.environ.items() if name != stages.ENV}
        self._process = subprocess.Popen([sys.executable, "-m", "bench.report.merge", SERVE], stdin=subprocess.PIPE,
                                         stdout=subprocess.DEVNULL, env=environment)
        self.handed = False
        try:         # its imports yield to the jobs where the cores are taken (the metrics' query pool uses them all)
            os.setpriority(os.PRIO_PROCESS, self._process.pid, spawned_niceness(os.getpriority(os.PRIO_PROCESS, 0)))
        except (AttributeError, OSError):           # no priorities here, or not allowed: as it is
            pass

    def hand_over(self, request: dict | None) -> int:
        """Send the request (None: nothing to merge) and wait for the worker's exit code."""
        self.handed = True
        try:
            if request is not None:
                self._process.stdin.write(json.dumps(request).encode())
            self._process.stdin.close()
        except BrokenPipeError:              # it ended early (its error is on stderr); its exit code says
            pass
        return self._process.wait()

    def stop(self) -> None:
        if not self.handed:
            self._process.kill()
            self._process.wait()


_spawned: list[SpawnedWorker] = []        # started by prestart_worker, in start order
_waiting: list[SpawnedWorker] = []        # of those, the one no multirun has taken yet


def prestart_worker() -> None:
    """Start the merge's worker now (`SpawnedWorker`) for the multirun this process is about to run: its callback
    takes it when the multirun starts (`MergeResults`). Where it cannot start, the callback forks one as on few
    cores."""
    if not sys.executable:                 # an embedding interpreter that cannot start another
        return
    try:
        worker = SpawnedWorker()
    except OSError:
        return
    if not _spawned:
        atexit.register(_end_unused)
    _spawned.append(worker)
    _waiting.append(worker)


def _end_unused() -> None:
    for worker in _spawned:
        worker.stop()


def _serve_and_exit(read_fd: int) -> None:
    """The worker's whole life (`_serve`), then its exit: 0, 2 after a user error, `cli.EXIT_INTERRUPTED` after
    Ctrl-C, 1 after a bug (its traceback on stderr)."""
    code = 1
    try:
        code = _serve(read_fd)
    except KeyboardInterrupt:
        code = cli.EXIT_INTERRUPTED
    except BaseException:            # noqa: BLE001 -- a bug: its traceback, exit 1
        traceback.print_exc()
    finally:
        sys.stderr.flush()
        os._exit(code)     # without tearing down pandas, SciPy and matplotlib (~0.2 s the sweep would wait)


def _serve(read_fd: int) -> int:
    """The worker's side: the merge's imports, then the request from the pipe."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)                      # its stdout is the sweep's: the merge itself prints nothing
    _warm_up()
    with os.fdopen(read_fd, "rb") as pipe:
        request = pipe.read()
    if not request.strip():
        return 0
    work = json.loads(request)
    try:
        report(Path(work["root"]), work["table"], bool(work["depth_errors"]))
    except Exception as err:   # noqa: BLE001 -- a file or disk problem in one line (bench.cli); bugs re-raised
        message = cli.error_line(err)
        if message is None:
            raise
        print(f"error: {' '.join(message.split())}", file=sys.stderr)
        return cli.EXIT_USER_ERROR
    return 0


def start_worker() -> Worker | None:
    """The merge's worker, or None where processes cannot fork or the fork fails (the merge then runs in this
    process)."""
    if not hasattr(os, "fork"):
        return None
    try:
        return Worker()
    except OSError:
        return None


def finish_worker(worker: Worker | SpawnedWorker, root: Path, table: str | None, depth_errors: bool) -> None:
    """Hand the sweep to the worker and wait: its exit code 2 (one `error:` line of its own on stderr) ends this
    process with 2 too; any other failure is raised."""
    # resolved here: the worker was forked inside a job, whose working directory Hydra may have changed
    code = worker.hand_over({"root": str(root.resolve()), "table": table, "depth_errors": depth_errors})
    if code == cli.EXIT_USER_ERROR:
        sys.exit(code)
    if code == cli.EXIT_INTERRUPTED:
        raise KeyboardInterrupt
    if code < 0:
        raise RuntimeError(f"the merge of {root} was killed by signal {signal.Signals(-code).name}")
    if code != 0:
        raise RuntimeError(f"the merge of {root} failed (exit code {code}; its error above)")


class MergeResults(Callback):
    """Hydra callback (configs/config.yaml `hydra.callbacks.merge`): `report` at the end of every multirun, in the
    worker (module doc): the one started before Hydra where there is one (`prestart_worker`, on several cores), else
    one forked when the multirun's first job ends in this process: not before, where its imports would compete with
    composing the jobs and the first job's own imports on two cores (measured on 2 loaded cores: composition 0.5 ->
    1.9 s), and not where the jobs run in other processes (joblib, SLURM), which merge here, in this process."""

    def __init__(self):
        self._worker: Worker | SpawnedWorker | None = None
        self._sweep_pid: int | None = None

    def on_multirun_start(self, config: DictConfig, **kwargs) -> None:
        self._sweep_pid = os.getpid()
        if _waiting:                     # started before Hydra (prestart_worker): no fork after the first job
            self._worker = _waiting.pop()

    def __getstate__(self) -> dict:
        """Copies sent to other processes (joblib, SLURM) never fork a worker: they carry no sweep process id."""
        return {"_worker": None, "_sweep_pid": None}

    def on_job_end(self, config: DictConfig, job_return, **kwargs) -> None:
        # only the sweep's own process, from its main thread (a threading launcher's jobs must not fork mid-job)
        if (self._worker is None and self._sweep_pid == os.getpid()
                and threading.current_thread() is threading.main_thread()):
            with stages.stage("outputs"):
                finish_deferred()        # no writer thread mid-write while the process forks
                warpstart.wait()         # nor Warp's start (a first job on the CPU did not wait for it)
            self._worker = start_worker()

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        with stages.stage("outputs"):
            finish_deferred()            # the last job's files (bench.harness.app: a basic launcher's jobs)
        root, table = Path(config.hydra.sweep.dir), config.report.table
        depth_errors = config.report.get("depth_errors", False)
        worker, self._worker = self._worker, None
        if worker is not None:
            finish_worker(worker, root, table, depth_errors)
            return
        try:
            report(root, table, depth_errors)
        except Exception as err:   # noqa: BLE001 -- a file or disk problem in one line (bench.cli); bugs re-raised
            message = cli.error_line(err)
            if message is None:
                raise
            cli.fail(message)


def main() -> int:
    from bench.report import tables

    parser = cli.ArgumentParser(prog="python -m bench.report.merge", description=__doc__)
    parser.add_argument("root", type=Path, help="sweep root (holding <job>/results.csv)")
    parser.add_argument("--table", choices=sorted(tables.TITLES))
    parser.add_argument("--depth-errors", action="store_true",
                        help="also draw depth_errors/<capture>.png (needs --table)")
    args = parser.parse_args()
    root = cli.existing_path(args.root, "dir", "sweep root")
    print(tables.summary_markdown(report(root, args.table, args.depth_errors)))
    return 0


if __name__ == "__main__":
    if sys.argv[1:] == [SERVE]:
        _serve_and_exit(sys.stdin.fileno())
    cli.run_guarded(main)
