"""`python -m bench.demo [--root DIR] [--out DIR] [--store DIR] [--results DIR]`: the README's main job.

Runs the paper's experiments `table2` and `table3` on the embedded synthetic dataset (generated on first use) as
Hydra multiruns with the local parallel launcher, exactly as `python -m bench -m experiment=NAME
hydra/launcher=local` would; finished cells come from the result store, so a re-run computes only missing cells.
Prints Tables I-III, and copies each sweep root's tables and plots (plus its per-capture rows, the regression
baseline) into `--results/<table>/` and Table I into `--results/table1.*`.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

from bench import tables
from bench.cli import run_guarded

EXPERIMENTS = ("table2", "table3")
REPORT_FILES = ("{table}.md", "{table}.csv", "{table}.tex", "runtime_vs_error.png")


def sweep(experiment: str, root: Path, out: Path, store: Path) -> pd.DataFrame:
    """One multirun into `out/<experiment>`; returns its merged rows."""
    command = [sys.executable, "-m", "bench", "-m", f"experiment={experiment}", "hydra/launcher=local",
               f"dataset.root={root}", f"store.dir={store}", f"hydra.sweep.dir={out / experiment}"]
    print(f"\n$ {' '.join(command[1:])}", flush=True)
    shutil.rmtree(out / experiment, ignore_errors=True)    # the store keeps the finished cells
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return pd.read_csv(out / experiment / "results.csv")


def publish(sweep_root: Path, rows: pd.DataFrame, table: str, results: Path) -> None:
    """Copy the sweep's table files, plots and rows (without the volatile `cached` flag) to `results/<table>/`."""
    target = results / table
    shutil.rmtree(target, ignore_errors=True)
    target.mkdir(parents=True)
    for name in REPORT_FILES:
        shutil.copy2(sweep_root / name.format(table=table), target)
    shutil.copytree(sweep_root / "depth_errors", target / "depth_errors")
    rows.drop(columns="cached").to_csv(target / "results.csv", index=False)


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.demo", description=__doc__)
    parser.add_argument("--root", type=Path, default=Path("data/synthetic"), help="synthetic dataset root")
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"), help="sweep roots go here")
    parser.add_argument("--store", type=Path, default=Path("outputs/store"), help="result store (cache)")
    parser.add_argument("--results", type=Path, default=tables.RESULTS_DIR, help="committed outputs")
    args = parser.parse_args()
    root, out, store = args.root.resolve(), args.out.resolve(), args.store.resolve()
    started = time.perf_counter()
    table1 = tables.table1()
    args.results.mkdir(parents=True, exist_ok=True)
    table1.to_csv(args.results / "table1.csv", index=False, float_format="%.4f")
    (args.results / "table1.md").write_text(tables.to_markdown(table1) + "\n")
    texts = [f"Table I: frequency configurations\n\n{tables.to_markdown(table1)}"]
    for experiment in EXPERIMENTS:
        try:
            rows = sweep(experiment, root, out, store)
        except subprocess.CalledProcessError as err:   # the sweep printed its own error on stderr
            print(f"error: the {experiment} sweep failed (exit {err.returncode}); its jobs are under "
                  f"{out / experiment}", file=sys.stderr)
            return 1
        publish(out / experiment, rows, experiment, args.results)
        texts.append((out / experiment / f"{experiment}.md").read_text())
        print(f"{experiment}: {len(rows)} rows, {int((~rows.cached).sum())} computed, {int(rows.cached.sum())} "
              f"from the store", flush=True)
    print("\n\n".join(["", *texts]))
    print(f"sweep roots under {out}; tables and plots copied to {args.results}; "
          f"{time.perf_counter() - started:.0f} s in all")
    return 0


if __name__ == "__main__":
    run_guarded(main)
