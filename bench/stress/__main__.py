"""`python -m bench.stress [--quick] [--out DIR]`: run every stress experiment, write CSVs, PNGs and summary.md into
OUT (default outputs/stress/; `--out results/stress` refreshes the committed report). The full report takes about
two minutes on two cores; `--quick` (for tests) seconds. `--precision-only` writes only OUT/precision.csv (e.g. on
a GPU machine); `--add-precision CSV` merges such rows into the report already in OUT."""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from bench import cli
from bench.stress import precision  # the other experiments import Open3D (via the generator): imported in run()

FULL = {"distances_m": (0.2, 0.3, 0.4, 0.5, 0.6), "grid_sizes": (11, 61, 151), "n_ref": 48,
        "snrs_db": tuple(range(-10, 45, 5)), "noise_configs": ("d05", "d10"),
        "realisations": {"point": 400, "plate": 60}, "knob_values": None, "repetitions": 3}
QUICK = {"distances_m": (0.2, 0.6), "grid_sizes": (11, 41), "n_ref": 16, "snrs_db": (-10, 0, 20, 40),
         "noise_configs": ("d05",), "realisations": {"point": 60, "plate": 8}, "knob_values": 3, "repetitions": 1}


def _knobs(n_values: int | None) -> dict:
    """The prior-degradation sweep; with n_values, the first, a middle and the last value of each knob."""
    from bench.stress import prior_degradation

    if n_values is None:
        return prior_degradation.KNOBS
    return {k: tuple(v[i] for i in np.unique(np.linspace(0, len(v) - 1, n_values).round().astype(int)))
            for k, v in prior_degradation.KNOBS.items()}


def run(out: Path, quick: bool, seed: int = 0, log=print) -> dict[str, list[dict]]:
    """Run all experiments, write OUT/<name>.csv, OUT/<name>.png and OUT/summary.md; return the rows."""
    from bench.progress import steps
    from bench.stress import hostile, noise, prior_degradation, wrapping
    from bench.synth import SynthConfig, generate_capture

    size = QUICK if quick else FULL
    out.mkdir(parents=True, exist_ok=True)
    results, seconds = {}, {}

    def step(name, compute):
        progress.set_postfix_str(name)
        start = time.perf_counter()
        results[name] = compute()
        seconds[name] = time.perf_counter() - start
        pd.DataFrame(results[name]).to_csv(out / f"{name}.csv", index=False, float_format="%.6g")
        progress.update()
        log(f"{name}: {len(results[name])} rows in {seconds[name]:.1f} s")    # above the bar (steps)

    with steps(7, "stress experiments", unit="experiment") as progress, tempfile.TemporaryDirectory() as tmp:
        step("precision", lambda: precision.precision_rows(size["distances_m"], size["grid_sizes"],
                                                           precision.available_devices(), size["n_ref"], seed))
        step("wrapping", lambda: wrapping.wrapping_rows(wrapping.offset_ratios(quick)))
        step("wrapping_boundaries", lambda: wrapping.boundaries(results["wrapping"]))
        step("noise", lambda: noise.noise_rows(size["snrs_db"], size["noise_configs"], size["realisations"], seed))
        step("prior_degradation", lambda: prior_degradation.degradation_rows(
            prior_degradation.build(), _knobs(size["knob_values"]), size["repetitions"], seed))
        step("prior_breaks", lambda: prior_degradation.break_points(results["prior_degradation"]))
        source = generate_capture(Path(tmp) / "source", "01_plate", 30, SynthConfig(frequency_points=16, seed=seed))
        step("hostile", lambda: hostile.hostile_rows(source, Path(tmp) / "work"))
    pd.DataFrame({"experiment": list(seconds), "seconds": list(seconds.values())}).to_csv(
        out / "timings.csv", index=False, float_format="%.1f")
    _report(out, results, seconds, quick)
    return results


def _report(out: Path, results: dict[str, list[dict]], seconds: dict[str, float], quick: bool) -> None:
    from bench.stress import plots
    from bench.stress.summary import write_summary

    for name, plot in (("precision", plots.plot_precision), ("wrapping", plots.plot_wrapping),
                       ("noise", plots.plot_noise), ("prior_degradation", plots.plot_prior)):
        plot(results[name], out / f"{name}.png")
    write_summary(results, seconds, quick, out / "summary.md")


REPORT_TABLES = ("precision", "wrapping", "wrapping_boundaries", "noise", "prior_degradation", "prior_breaks",
                 "hostile", "timings")


def add_precision_rows(out: Path, extra_csv: Path) -> None:
    """Merge precision rows measured on another machine (e.g. `--precision-only` on a GPU) into the full report
    in `out`, replacing rows of the same devices, and rewrite its plots and summary. A missing report or a CSV
    without precision rows is a UserError (one line, before anything is written)."""
    missing = [f"{name}.csv" for name in REPORT_TABLES if not (out / f"{name}.csv").is_file()]
    if missing:
        raise cli.UserError(out, f"no stress report to merge into (missing {', '.join(missing)}); write one with "
                                 f"`python -m bench.stress --out {out}` first")
    results = {name: pd.read_csv(out / f"{name}.csv").to_dict("records") for name in REPORT_TABLES[:-1]}
    try:
        extra = pd.read_csv(extra_csv)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as err:
        raise cli.UserError(extra_csv, f"not a precision CSV ({' '.join(str(err).split())})") from None
    absent = [c for c in pd.DataFrame(results["precision"]).columns if c not in extra]
    if absent:
        raise cli.UserError(extra_csv, f"not a precision CSV: no column {', '.join(absent)}")
    kept = pd.DataFrame(results["precision"])
    kept = kept[~kept.device.isin(extra.device.unique())]
    merged = pd.concat([kept, extra], ignore_index=True)
    merged.to_csv(out / "precision.csv", index=False, float_format="%.6g")
    results["precision"] = merged.to_dict("records")
    timings = pd.read_csv(out / "timings.csv")
    _report(out, results, dict(zip(timings.experiment, timings.seconds, strict=False)), quick=False)


DEFAULT_OUT = Path("outputs/stress")


def main(argv=None) -> int:
    parser = cli.ArgumentParser(prog="python -m bench.stress", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="report folder (default: outputs/stress; `--out results/stress` for the committed one)")
    parser.add_argument("--quick", action="store_true", help="small sweeps (seconds), for tests")
    parser.add_argument("--seed", type=int, default=0)
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument("--precision-only", action="store_true",
                      help="only the precision sweep on every device Warp sees (e.g. on a GPU machine without "
                           "Open3D); writes OUT/precision.csv")
    mode.add_argument("--add-precision", type=Path, metavar="CSV",
                      help="merge precision rows from another machine into the report in OUT")
    args = parser.parse_args(argv)
    start = time.perf_counter()
    if args.add_precision:
        add_precision_rows(cli.existing_path(args.out, "dir", "stress report folder"),
                           cli.existing_path(args.add_precision, "file", "precision CSV"))
    else:
        out = cli.output_dir(args.out)
        if args.precision_only:
            size = QUICK if args.quick else FULL
            rows = precision.precision_rows(size["distances_m"], size["grid_sizes"], precision.available_devices(),
                                            size["n_ref"], args.seed)
            pd.DataFrame(rows).to_csv(out / "precision.csv", index=False, float_format="%.6g")
        else:
            run(out, args.quick, args.seed)
    print(f"stress report written to {args.out} in {time.perf_counter() - start:.0f} s")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
