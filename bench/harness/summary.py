"""What a multirun says at its end (Hydra callbacks, configs/config.yaml `hydra.callbacks`): one line with the
paths of its table and rows, and a warning when two jobs gave rows of one identity (bench.harness.identity), which
a table would merge into one row. While the merge runs (tables, plots), a heartbeat line every 30 s.

`SweepSummary` is listed before the merge callback and `MergeClock` after it: Hydra calls `on_multirun_end` in
reverse order, so the clock starts before the merge and the summary comes after it.
"""
from __future__ import annotations

import csv
import sys
from pathlib import Path

import yaml
from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from bench.harness import stages
from bench.harness.identity import ROW_IDENTITY
from bench.progress import Heartbeat

_merging: list[Heartbeat] = []


def _job_identities(root: Path) -> dict[str, set[tuple]]:
    """Job folder name -> the identities of its rows (the values as written; read without pandas, which the sweep's
    process does not import otherwise)."""
    jobs = {}
    for path in sorted(root.glob("*/results.csv")):
        with path.open(newline="") as handle:
            rows = csv.DictReader(handle)
            columns = [c for c in ROW_IDENTITY if c in (rows.fieldnames or [])]
            jobs[path.parent.name] = {tuple(row[c] or "" for c in columns) for row in rows}
    return jobs


def _overrides(job_dir: Path) -> set[str]:
    path = job_dir / ".hydra" / "overrides.yaml"
    return set(yaml.safe_load(path.read_text()) or []) if path.is_file() else set()


def colliding_jobs(root: Path) -> list[str]:
    """One sentence per pair of jobs of the sweep root whose rows share an identity, naming the settings they
    differ in (which are then not part of `params`)."""
    jobs = _job_identities(root)
    names, found = sorted(jobs), []
    for i, first in enumerate(names):
        for second in names[i + 1:]:
            if jobs[first] & jobs[second]:
                differ = sorted(_overrides(root / first) ^ _overrides(root / second))
                found.append(f"jobs {first} and {second} gave rows of one identity (object, distance, frame, "
                             f"method, freq, prior, grid, params, device, metrics); they differ in "
                             f"{', '.join(differ) or 'nothing on their command lines'}, which is not part of a "
                             f"row's params: a table shows them as one row")
    return found


def summary_line(root: Path, table: str | None) -> str:
    """`sweep finished: table <root>/table3.md, rows <root>/results.csv; one HTML page: python -m bench.report
    <root>`."""
    if not (root / "results.csv").is_file():
        return f"sweep finished without merged rows: see its jobs' logs, {root}/*/app.log"
    table_text = f"table {root / f'{table}.md'}, " if table and (root / f"{table}.md").is_file() else ""
    return (f"sweep finished: {table_text}rows {root / 'results.csv'}; one HTML page: "
            f"python -m bench.report {root}")


class MergeClock(Callback):
    """Before the merge callback's work: the merge stage's clock and a heartbeat line while it runs."""

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        stages.begin("merge")
        _merging.append(Heartbeat(lambda: f"merging the sweep's rows into {config.hydra.sweep.dir}"))
        _merging[-1].__enter__()


class SweepSummary(Callback):
    """After the merge: warnings for colliding jobs, then the line with the table's and rows' paths."""

    def on_multirun_end(self, config: DictConfig, **kwargs) -> None:
        while _merging:
            _merging.pop().__exit__(None, None, None)
        stages.end()
        root = Path(config.hydra.sweep.dir)
        for warning in colliding_jobs(root):     # (the jobs' logging is closed by now)
            print(f"warning: {warning}", file=sys.stderr, flush=True)
        print(summary_line(root, config.report.get("table")), flush=True)
