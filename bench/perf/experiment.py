"""A whole experiment as a user runs it, its wall time beside its methods' and metrics' time, split by stage.

`python -m bench.perf experiment NAME --root DIR [--device cpu|cuda] [--grid G] [--cells CELL ...] [--repeat N]
[--set KEY=VALUE ...] [--no-store] [--launcher L] [--out DIR]` runs `python -m bench -m experiment=NAME
hydra/launcher=L dataset=maroon dataset.root=DIR device=D` (L: inprocess, the default, or basic, Hydra's: one job
at a time, as the demo runs it) in a fresh process with the stage clock on (bench.harness.stages): seconds in
composing the jobs' configurations, the in-process launcher's per-job set-up (`launch`), imports, reading captures,
the ground truth, the methods (`methods.reconstruct` calls: prior, warm-up, method), the metrics, the output files
(on the main thread: what it waited for; `outputs (background)` is the writer thread's, the output process's and
the scoring workers' time, overlapped; with scoring workers, bench.harness.workers, the metrics are theirs,
overlapped), the merge (tables and plots), and `other` (Hydra's start and its first composition, the jobs' own
set-up, the basic launcher's per-job set-up, and the interpreter's start and end outside the stage clock, printed
apart).
Runs: `cold`, a store that keeps nothing yet (the ground truth is cast from the meshes), then `--repeat` runs
`kept` on the store it left with its cells removed (every cell computes again; the ground truth kept by content
is read back, as a second experiment on the same captures finds it). `--no-store` runs as `store.dir=null` does
(the command of the issue's end-to-end figures): `cold` with an empty `store.cache`, `kept` with the ground truths
and meshes the cold run kept there. The ratio printed is wall / (methods + metrics, the workers' scoring
included); the targets (issue 29) are 1.3. `--set KEY=VALUE ...` passes further overrides to every run (e.g.
`evaluation.workers=0`). Writes OUT/perf_experiment_<name>_<device>.csv (OUT = `--out`, default outputs/perf/), one
row per run, with the machine's load.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd

from bench import cli
from bench.harness.stages import ENV
from bench.perf.common import add_out_option, write_rows

STAGES = ("composition", "launch", "imports", "reading", "ground truth", "methods", "metrics", "outputs", "merge")


def run_once(name: str, root: Path, device: str, extra: list[str], store: Path, work: Path, no_store: bool = False,
             launcher: str = "inprocess") -> dict:
    """One `python -m bench -m experiment=NAME` in a fresh process: wall seconds, seconds per stage, the summed
    warm method runtimes of its rows and the load before it. `no_store`: `store.dir=null`, `store` as the cache."""
    stages_file, sweep = work / "stages.json", work / "sweep"
    shutil.rmtree(sweep, ignore_errors=True)
    kept = ["store.dir=null", f"store.cache={store}"] if no_store else [f"store.dir={store}"]
    command = [sys.executable, "-m", "bench", "-m", f"experiment={name}", f"hydra/launcher={launcher}",
               "dataset=maroon", f"dataset.root={root}", f"device={device}", *kept, f"hydra.sweep.dir={sweep}", *extra]
    load_1m = os.getloadavg()[0]
    started = time.perf_counter()
    result = subprocess.run(command, env={**os.environ, ENV: str(stages_file)}, capture_output=True, text=True)
    wall_s = time.perf_counter() - started
    if result.returncode != 0:
        raise cli.UserError(f"experiment={name}", f"the sweep failed: {result.stderr.strip().splitlines()[-1:]}")
    spent = json.loads(stages_file.read_text())
    rows = pd.read_csv(sweep / "results.csv")
    row = {"experiment": name, "device": device, "launcher": launcher, "rows": len(rows), "wall_s": wall_s,
           "load_1m_before": load_1m,
           **{f"{stage.replace(' ', '_')}_s": spent["stages_s"].get(stage, 0.0) for stage in STAGES}}
    row["outputs_background_s"] = spent["background_s"].get("outputs", 0.0)
    row["metrics_workers_s"] = spent["background_s"].get("metrics", 0.0)
    row["other_s"] = wall_s - sum(spent["stages_s"].get(stage, 0.0) for stage in STAGES)
    row["outside_s"] = wall_s - spent["process_s"]     # the interpreter's start and end, outside the stage clock
    row["method_runtime_s"] = float(rows.runtime_ms.sum()) / 1e3
    row["methods_metrics_s"] = row["methods_s"] + row["metrics_s"] + row["metrics_workers_s"]
    row["ratio"] = wall_s / row["methods_metrics_s"]
    return row


def _print(row: dict, label: str) -> None:
    stages = "  ".join(f"{stage} {row[stage.replace(' ', '_') + '_s']:.2f}" for stage in STAGES)
    print(f"{label:5s} wall {row['wall_s']:6.1f} s = {row['ratio']:.2f} x methods+metrics "
          f"{row['methods_metrics_s']:.2f} s (methods' own runtimes {row['method_runtime_s']:.2f} s) | {stages}  "
          f"other {row['other_s']:.2f} (of it before and after the app {row['outside_s']:.2f})  "
          f"[outputs on their thread {row['outputs_background_s']:.2f}, "
          f"scoring in workers {row['metrics_workers_s']:.2f}]  "
          f"load {row['load_1m_before']:.1f}", flush=True)


def measure(name: str, root: Path, device: str, extra: list[str], repeat: int, no_store: bool = False,
            launcher: str = "inprocess") -> list[dict]:
    """The cold run, then `repeat` runs with the ground truth kept (module doc)."""
    rows = []
    with tempfile.TemporaryDirectory(prefix="perf_experiment-") as work:
        store = Path(work) / "store"
        for i in range(repeat + 1):
            shutil.rmtree(store / "cells", ignore_errors=True)
            label = "cold" if i == 0 else "kept"
            rows.append({"run": label, "store": "off" if no_store else "on",
                         **run_once(name, root, device, extra, store, Path(work), no_store, launcher)})
            _print(rows[-1], label)
    return rows


def main(argv=None) -> int:
    parser = cli.ArgumentParser(prog="python -m bench.perf experiment", description=__doc__.splitlines()[0])
    parser.add_argument("name", help="experiment (configs/experiment/: table2, table3, beyond, runtime)")
    parser.add_argument("--root", type=Path, required=True, help="dataset root (e.g. data/synthetic)")
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda", "auto"])
    parser.add_argument("--grid", default=None, help="grid config for every cell (e.g. bp_cpu on a small CPU)")
    parser.add_argument("--cells", nargs="+", default=None, help="only these cells of the experiment")
    parser.add_argument("--repeat", type=cli.positive_int, default=1, help="runs with the ground truth kept")
    parser.add_argument("--set", nargs="+", default=[], metavar="KEY=VALUE", help="further overrides of every run")
    parser.add_argument("--no-store", action="store_true",
                        help="run with store.dir=null, the ground truth kept in a store.cache of the runs")
    parser.add_argument("--launcher", default="inprocess", choices=["inprocess", "basic"],
                        help="inprocess (the default launcher) or basic (Hydra's): jobs one at a time in the process")
    add_out_option(parser)
    args = parser.parse_args(argv)
    root = cli.existing_path(args.root, "dir", "--root").resolve()
    device = cli.resolve_device(args.device)
    out = cli.output_dir(args.out)
    extra = ([f"grid={args.grid}"] if args.grid else []) + ([f"cell={','.join(args.cells)}"] if args.cells else [])
    extra += args.set
    rows = measure(args.name, root, device, extra, args.repeat, args.no_store, args.launcher)
    write_rows(rows, out / f"perf_experiment_{args.name}_{device}.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
