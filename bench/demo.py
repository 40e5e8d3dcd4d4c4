"""`python -m bench.demo [--root DIR] [--out DIR]`: the main job on the embedded synthetic dataset.

Generates (or reuses) the synthetic catalogue, prints what the reader finds in every capture, then runs each
method on every capture through the same code path as `python -m bench` and prints the mean metrics and
runtimes per run. Each run's results.csv and depth images land in `--out/<run>/`.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd
from hydra import compose, initialize_config_dir

from bench import inspect as inspect_cli
from bench import maroon
from bench.app import CONFIG_DIR, run
from bench.cli import run_guarded

RUNS = {  # run name -> Hydra overrides (the paper's comparisons at a size that suits a 2-core CPU)
    "mm2fsk_d10_realsense": ["method=mm2fsk", "freq=d10", "prior=realsense"],
    "mm2fsk_d10_photogrammetry": ["method=mm2fsk", "freq=d10", "prior=photogrammetry"],
    "mm2fsk_d05_realsense": ["method=mm2fsk", "freq=d05", "prior=realsense"],
    "2fsk_d05": ["method=2fsk", "freq=d05", "prior=none"],
    "2fsk_d1": ["method=2fsk", "freq=d1", "prior=none"],
    "3fsk_d05_d10": ["method=3fsk", "freq=d05_d10", "prior=none"],
    "bp_d05_coarse": ["method=bp", "freq=d05", "prior=none", "grid=coarse"],
}
SUMMARY_COLUMNS = ["C_g_cm", "C_s_cm", "P_cm", "P_e_cm", "valid_px", "runtime_ms"]


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.demo", description=__doc__)
    parser.add_argument("--root", type=Path, default=Path("data/synthetic"), help="synthetic dataset root")
    parser.add_argument("--out", type=Path, default=Path("outputs/demo"), help="where each run writes its files")
    parser.add_argument("--runs", nargs="*", choices=sorted(RUNS), default=list(RUNS), help="subset of runs")
    args = parser.parse_args()
    root, out = args.root.resolve(), args.out.resolve()
    summaries = []
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        for i, name in enumerate(args.runs):
            cfg = compose(config_name="config", overrides=[f"dataset.root={root}", *RUNS[name]])
            rows = run(cfg, out / name)
            if i == 0:   # the dataset exists now: show what the reader finds, as `python -m bench.inspect` does
                print(f"\n== captures in {root}")
                for capture_dir in maroon.discover_captures(root):
                    found, problems = inspect_cli.inspect_capture(capture_dir)
                    print(f"{capture_dir.parent.name}/{capture_dir.name}  {'PROBLEMS' if problems else 'ok'}")
                    for line in found + [f"!! {p}" for p in problems]:
                        print(f"  {line}")
                print()
            table = pd.DataFrame(rows)
            summaries.append({"run": name, "captures": len(table), **table[SUMMARY_COLUMNS].mean().to_dict()})
            print(f"{name}: {len(table)} captures, mean P {summaries[-1]['P_cm']:.2f} cm, "
                  f"mean runtime {summaries[-1]['runtime_ms']:.0f} ms", flush=True)
    summary = pd.DataFrame(summaries)
    print(f"\n== mean over captures (centimetres; runtime_ms per frame on the CPU); files under {out}")
    print(summary.to_string(index=False, float_format=lambda v: f"{v:.2f}"))
    return 0


if __name__ == "__main__":
    run_guarded(main)
