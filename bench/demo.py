"""`python -m bench.demo [--root DIR] [--out DIR] [--store DIR] [--synth realistic|ideal] [--update-results [--results
DIR]]`:

1. Generates the embedded synthetic dataset (`--root`, default data/synthetic) in this process, one line per
   capture, before any sweep starts (cached: a re-run finds every capture up to date in milliseconds).
2. Runs the paper's experiments `table2` and `table3` as Hydra multiruns, exactly as `python -m bench -m
   experiment=NAME` would (the default launcher, inprocess): one job at a time, so every runtime in the tables is
   measured alone (rows get `timing=alone`; stored rows timed beside other jobs are re-measured). Finished cells
   come from the result store (`--store`), so a re-run computes only missing cells. Each job prints one progress
   line.
3. Prints Tables I-III and writes one HTML page, `<out>/report.html` (bench.report.html: every table with its spread
   across captures, a per-object view, the runtime plot, paper-style pictures for table3), and prints its path.
   Everything goes under `--out` (default outputs/demo): the sweep roots `<out>/table2|table3/` and Table I
   `<out>/table1.*`. Tracked files are left alone unless `--update-results` is given: then Table I and
   each sweep's tables, plots and per-capture rows (the regression baselines) are copied into `--results`
   (default results/), with `agreement.md`: the tables beside the paper's (bench.report.agreement, from the same rows).
"""
from __future__ import annotations

import argparse
import itertools
import shutil
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING

from bench import cli
from bench.harness import CONFIG_DIR
from bench.progress import Heartbeat, run_relayed

if TYPE_CHECKING:
    import pandas as pd
# pandas, OmegaConf and the report's tables are imported where they are used: the report's picture workers are
# spawned processes, which import this module again (as their __main__), and those imports cost each ~1 s of CPU.

EXPERIMENTS = ("table2", "table3")
# Runtimes: the median of the calls per capture that fit in 1.2 s, at most 3 (app._reconstruct's rule): 3 for a call
# up to 0.4 s (2FSK, 3FSK, MM-2FSK, the camera, where one busy moment of the machine is a large share of a call), 2 up
# to 0.6 s, one for a longer call (BP), as BP_max always was. Over the demo's cells the mean of 3-call medians was
# within 2 % of 5- and 7-call medians, one call up to 12 % off (docs/measurements/sweep.md, 2026-11-26 04:27); 5
# calls within 2 s cost ~25 s more on two cores.
TIMING = ("timing.repeat=3", "timing.budget_s=1.2")
REPORT_FILES = ("{table}.md", "{table}.csv", "{table}_pairs.csv", "{table}.tex", "runtime_vs_error.png")
# One job at a time: runtimes measured alone (docs/measurements/performance.md "The demo's cost"
# has the measured cost of this choice).
LAUNCHER = "inprocess"
QUIET = ("+hydra.job_logging.handlers.console.level=WARNING",   # per-capture lines stay in each job's app.log
         "hydra.hydra_logging.root.level=WARNING")             # no launcher chatter: the jobs print progress


class SweepFailed(Exception):
    """A sweep exited non-zero; the message is the reason it printed (its last `error:` line)."""


def demo_captures(distances_cm: list[int] | None) -> tuple[list[str], list[int]]:
    """(objects, distances in cm) of the demo: configs/dataset/synthetic.yaml's, the distances replaced when given."""
    from omegaconf import OmegaConf

    from bench.synth import CATALOGUE

    settings = OmegaConf.load(CONFIG_DIR / "dataset" / "synthetic.yaml").generate
    objects = list(CATALOGUE) if settings.objects is None else list(settings.objects)
    return objects, list(settings.distances) if distances_cm is None else list(distances_cm)


# Seconds per capture on two quiet cores (docs/measurements/performance.md, 2026-11-26 07:55: generator v9, BP's
# host search with its shortcuts, pictures drawn into pixels), for the estimate the demo prints before it starts;
# re-measure when they move.
GENERATE_S_PER_CAPTURE = 2.6
SWEEP_S_PER_CAPTURE = {"table2": 1.8, "table3": 16.5}
BP_MAX_S_PER_CAPTURE = 6.0           # table3's longest cell
REPORT_S_PER_CAPTURE = 0.6           # the report page, table3's pictures drawn anew (docs/measurements/sweep.md)


def plan(root: Path, store: Path, distances_cm: list[int] | None) -> str:
    """What the demo will do and about how long it takes on two quiet cores, the long step named; captures on
    disk and cells in the store are not counted again."""
    objects, distances = demo_captures(distances_cm)
    n = len(objects) * len(distances)
    missing = sum(not (root / o / str(d)).is_dir() for o in objects for d in distances)
    stored = store.is_dir() and any((store / "cells").glob("*.json"))
    sweeps_s = {name: n * s for name, s in SWEEP_S_PER_CAPTURE.items()}
    total_s = missing * GENERATE_S_PER_CAPTURE + sum(sweeps_s.values()) + n * REPORT_S_PER_CAPTURE
    steps = [f"generating {missing} of {n} captures ~{missing * GENERATE_S_PER_CAPTURE:.0f} s" if missing
             else f"the {n} captures are on disk"]
    steps += [f"{name} ~{seconds:.0f} s" for name, seconds in sweeps_s.items()]
    steps.append(f"the report ~{n * REPORT_S_PER_CAPTURE:.0f} s")
    text = (f"demo: about {total_s / 60:.0f} min on two quiet cores ({', '.join(steps)}); the long step is "
            f"table3's BP_max (~{n * BP_MAX_S_PER_CAPTURE:.0f} s, one back-projection over 128 frequencies per "
            f"capture)")
    if stored:
        text += f"; cells already in {store} are reused, so this run may take much less"
    return text


def generate_dataset(root: Path, synth: str = "realistic", distances_cm: list[int] | None = None) -> None:
    """The synthetic captures configs/dataset/synthetic.yaml asks for (at `distances_cm` when given), generated
    here with the preset `synth` (configs/synth/) before any sweep starts."""
    from bench.synth import generate_catalogue
    from bench.synth.config import preset
    from bench.synth.ownership import ForeignRootError

    objects, distances = demo_captures(distances_cm)
    total, done = len(objects) * len(distances), itertools.count(1)
    print(f"synthetic dataset {root}: {total} captures, preset {synth}", flush=True)

    def log(result) -> None:
        print(f"[data {next(done)}/{total}] {result.path.parent.name}/{result.path.name}: {result.status}, "
              f"{result.seconds:.1f} s", flush=True)

    started = time.perf_counter()
    try:
        with Heartbeat(lambda: f"generating synthetic captures, {time.perf_counter() - started:.0f} s"):
            generate_catalogue(root, distances, objects, preset(synth), log=log,
                               on_wait=lambda: print(f"waiting for another process generating into {root}",
                                                     flush=True))
    except ForeignRootError:
        print(f"{root} holds data the generator did not write: using it as it is", flush=True)


def _reason(stderr_tail: list[str]) -> str:
    """The failing sweep's own explanation: its last `error:` line (bench.harness.app), else the headline of Hydra's
    last
    message (the exception line of a traceback), without Hydra's HYDRA_FULL_ERROR hint."""
    errors = [line for line in stderr_tail if line.startswith("error:")]
    if errors:
        return errors[-1].removeprefix("error:").strip()
    paragraphs = [block.strip().splitlines() for block in "\n".join(stderr_tail).split("\n\n")
                  if block.strip() and not block.strip().startswith("Set the environment variable HYDRA_FULL_ERROR")]
    if not paragraphs:
        return "no message"
    last = paragraphs[-1]
    return last[-1] if any(line.startswith("Traceback") for line in last) else last[0]


def sweep(experiment: str, root: Path, out: Path, store: Path, synth: str = "realistic",
          distances_cm: list[int] | None = None, depth_errors: bool = False) -> pd.DataFrame:
    """One multirun into `out/<experiment>`; returns its merged rows. Job lines go to stdout as they finish;
    stderr is passed through and its tail kept, so a failure ends in the job's own reason (SweepFailed).
    `distances_cm`: only the demo's captures at these distances (default: the dataset config's); `depth_errors`:
    the sweep root also gets depth_errors/<capture>.png (what --update-results publishes)."""
    import pandas as pd

    objects, distances = demo_captures(distances_cm)
    captures = ",".join(f"{name}/{distance}" for name in objects for distance in distances)
    command = [sys.executable, "-m", "bench", "-m", f"experiment={experiment}", f"hydra/launcher={LAUNCHER}",
               "dataset=synthetic", f"dataset.root={root}", f"synth={synth}", f"store.dir={store}",
               f"dataset.captures=[{captures}]", f"dataset.generate.distances=[{','.join(map(str, distances))}]",
               f"hydra.sweep.dir={out / experiment}",
               f"report.depth_errors={str(depth_errors).lower()}",
               *TIMING,
               *QUIET]
    print(f"\n$ python {' '.join(command[1:-len(QUIET)])}", flush=True)
    shutil.rmtree(out / experiment, ignore_errors=True)    # the store keeps the finished cells
    returncode, tail = run_relayed(command)     # on a terminal, with the jobs' progress bars (bench.progress)
    if returncode != 0:
        raise SweepFailed(f"the {experiment} sweep failed (exit {returncode}): {_reason(tail)}"
                          f"; job logs: {out / experiment}/*/app.log")
    return pd.read_csv(out / experiment / "results.csv")


def publish(sweep_root: Path, rows: pd.DataFrame, table: str, results: Path) -> None:
    """Copy the sweep's table files, plots and rows (without the volatile `cached` flag) to `results/<table>/`."""
    target = results / table
    shutil.rmtree(target, ignore_errors=True)
    target.mkdir(parents=True)
    for name in REPORT_FILES:
        shutil.copy2(sweep_root / name.format(table=table), target)
    shutil.copytree(sweep_root / "depth_errors", target / "depth_errors")
    # the paper-style figures (bench.report.html), not the PLY
    pictures = sweep_root / "pictures" / "point_clouds"
    for picture in sorted(pictures.glob("*.png")) if pictures.is_dir() else []:
        (target / "point_clouds").mkdir(exist_ok=True)
        shutil.copy2(picture, target / "point_clouds")
    rows.drop(columns="cached").to_csv(target / "results.csv", index=False)


def report_page(out: Path) -> Path:
    """`out/report.html` (bench.report.html) over the demo's sweep roots; pictures for table3, which holds every method
    (about 1 s of CPU per capture, drawn by one spawned process per core)."""
    from bench.report import html

    return html.write_report([out / name for name in EXPERIMENTS], out / "report.html",
                               pictures=[out / "table3"])


def write_table1(folder: Path) -> str:
    """Table I as `folder/table1.csv` and `.md`; returns its Markdown."""
    from bench.report import tables

    table1 = tables.table1()
    folder.mkdir(parents=True, exist_ok=True)
    table1.to_csv(folder / "table1.csv", index=False, float_format="%.4f")
    (folder / "table1.md").write_text(tables.to_markdown(table1) + "\n")
    return tables.to_markdown(table1)


def main() -> int:
    import pandas as pd

    from bench.report import agreement, tables

    parser = cli.ArgumentParser(prog="python -m bench.demo", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--root", type=Path, default=Path("data/synthetic"), help="synthetic dataset root")
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"), help="sweep roots and Table I go here")
    parser.add_argument("--store", type=Path, default=Path("outputs/store"), help="result store (cache)")
    parser.add_argument("--synth", choices=["realistic", "ideal"], default="realistic",
                        help="generator preset of the synthetic captures (configs/synth/)")
    parser.add_argument("--distances", type=cli.positive_int, nargs="+", metavar="CM",
                        help="object distances in cm (e.g. --distances 30 40 50; default: configs/dataset/"
                             "synthetic.yaml, 30)")
    parser.add_argument("--update-results", action="store_true",
                        help="also copy the tables, plots and baselines into --results (tracked files)")
    parser.add_argument("--results", type=Path, default=tables.RESULTS_DIR,
                        help="where --update-results copies to (default: the committed results/)")
    args = parser.parse_args()
    root, out, store = args.root.resolve(), cli.output_dir(args.out).resolve(), args.store.resolve()
    started = time.perf_counter()
    print(plan(root, store, args.distances), flush=True)
    generate_dataset(root, synth=args.synth, distances_cm=args.distances)
    texts = [f"Table I: frequency configurations\n\n{write_table1(out)}"]
    for experiment in EXPERIMENTS:
        sweep_started = time.perf_counter()
        try:
            rows = sweep(experiment, root, out, store, synth=args.synth, distances_cm=args.distances,
                         depth_errors=args.update_results)
        except SweepFailed as err:
            print(f"error: {err}", file=sys.stderr)
            return 1
        texts.append((out / experiment / f"{experiment}.md").read_text())
        print(f"{experiment}: {len(rows)} rows, {int((~rows.cached).sum())} computed, {int(rows.cached.sum())} "
              f"from the store, {time.perf_counter() - sweep_started:.0f} s", flush=True)
    print("\n\n".join(["", *texts]))
    with Heartbeat(lambda: f"drawing the report's tables and pictures, {time.perf_counter() - report_started:.0f} s"):
        report_started = time.perf_counter()
        page = report_page(out)                 # before publishing: it draws the pictures that results/ keeps
    if args.update_results:
        write_table1(args.results)
        for experiment in EXPERIMENTS:
            publish(out / experiment, pd.read_csv(out / experiment / "results.csv"), experiment, args.results)
        # the paper-agreement report from these very rows (no second sweep; bench.report.agreement)
        agreement.write_from_sweeps(*(pd.read_csv(out / e / "results.csv") for e in EXPERIMENTS),
                                    args.results / "agreement.md", args.synth, root)
    print(f"\nreport (tables, spread, per object, pictures; open in a browser): {page}")
    copied = f"; tables, plots and baselines copied to {args.results}" if args.update_results else ""
    print(f"outputs under {out}{copied}; {time.perf_counter() - started:.0f} s in all")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
