"""What a sweep pays per cell outside the methods: reading, ground truth, metrics, store and output files.

`python -m bench.perf overhead --root DIR [--cells CELL ...] [--captures OBJECT/DISTANCE ...] [--device cpu|cuda]
[--grid NAME] [--store] [--out DIR]` runs the cells (default: those of configs/experiment/table3.yaml) one after
the other in one process through `bench.harness.app.run`, as the basic launcher runs a sweep's jobs (Hydra's per-job
set-up is not included: `python -m bench.perf experiment` times whole sweeps). The app's stages are timed where it
calls them: reading captures (`reader.read_capture`: each capture is read once per frame and parts, then served
from bench.harness.captures' cache), the ground truth (its ray casts, its rasters kept in the store, its masks:
once per capture, grid and object pose), the store's file list and digests, `methods.reconstruct` (its wall time
and its own warm `total`), resampling and metrics, the store's reads and writes of finished cells (`store`), and
the output files (depth PNG + JSON + preview, arrays.h5, results.csv; written in line here, not on the app's
background thread, so that each second has one stage).
`other` is the cell's wall time minus all of these. Without --store the result store is off (every cell
computes). One row per cell and a `total` row: OUT/perf_overhead_<device>.csv (OUT = `--out`, default
outputs/perf/). `--results-frames N [N ...]` times instead what results.csv costs over a sequence of N frames,
appended per frame (what the app does) beside rewritten per frame (what it did): OUT/perf_results_csv.csv.
"""
from __future__ import annotations

import collections
import contextlib
import os
import tempfile
import time
from pathlib import Path

from bench import cli
from bench.perf.common import add_device_option, add_out_option, write_rows
from bench.perf.sweep import table3_cells
from bench.progress import each

STAGES = ("read", "ground_truth", "store_key", "store", "method", "metrics", "outputs")


class _InlineWriter:
    """bench.harness.results.BackgroundWriter's interface, writing at once on the caller's thread."""

    def submit(self, function, *args) -> None:
        function(*args)

    def close(self) -> None:
        pass


@contextlib.contextmanager
def timed_stages(spent: dict):
    """Wrap the functions the app calls with timers adding seconds to `spent[stage]`; restore them afterwards."""
    import methods
    from bench.harness import app, captures, store, workers
    from bench.maroon import reader

    targets = [(reader, "read_capture", "read"), (captures, "ground_truth_rasters_m", "ground_truth"),
               (captures, "ground_truth_from_rasters", "ground_truth"), (captures, "load_kept", "ground_truth"),
               (app, "capture_files", "store_key"), (store.Store, "capture_digest", "store_key"),
               (store.Store, "get", "store"), (store.Store, "put", "store"), (store.Store, "copy_arrays", "outputs"),
               (methods, "reconstruct", "method"), (workers, "resample_depth_m", "metrics"),
               (workers, "evaluate", "metrics"), (workers, "resample_nearest", "metrics"),
               (app, "write_depth", "outputs"), (app, "write_arrays", "outputs"), (app.ResultsCsv, "add", "outputs")]
    originals = [(owner, name, getattr(owner, name)) for owner, name, _ in targets]

    def wrap(function, stage):
        def timed(*args, **kwargs):
            start = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                spent[stage] += time.perf_counter() - start
        return timed

    for (owner, name, stage), (_, _, function) in zip(targets, originals, strict=False):
        setattr(owner, name, wrap(function, stage))
    writer = app.BackgroundWriter
    app.BackgroundWriter = _InlineWriter
    try:
        yield
    finally:
        app.BackgroundWriter = writer
        for owner, name, function in originals:
            setattr(owner, name, function)


def measure(root: Path, cells: list[str], captures: list[str] | None, device: str, grid: str | None,
            use_store: bool, work: Path) -> list[dict]:
    """One row per cell: wall seconds, seconds per stage (module doc), captures, summed warm method time."""
    from hydra import compose, initialize_config_dir

    from bench.harness.app import CONFIG_DIR, run

    rows = []
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        for name in each(cells, "cells", unit="cell"):
            overrides = [f"cell={name}", "dataset=maroon", f"dataset.root={root}", f"device={device}",
                         f"store.dir={work / 'store' if use_store else 'null'}",
                         "evaluation.workers=0"]        # every stage in this thread, timed where it runs
            if captures:
                overrides.append(f"dataset.captures=[{','.join(captures)}]")
            if grid:
                overrides.append(f"grid={grid}")
            cfg = compose(config_name="config", overrides=overrides)
            spent = collections.defaultdict(float)
            with timed_stages(spent):
                start = time.perf_counter()
                results = run(cfg, work / name)
                wall_s = time.perf_counter() - start
            row = {"cell": name, "device": device, "frames": len(results), "wall_s": wall_s,
                   **{f"{stage}_s": spent[stage] for stage in STAGES},
                   "method_warm_s": sum(r["runtime_ms"] for r in results) / 1e3}
            row["other_s"] = wall_s - sum(spent[stage] for stage in STAGES)
            row["outside_method_s"] = wall_s - spent["method"]
            rows.append(row)
            print(f"{name:14s} {len(results)} frames  wall {wall_s:7.2f} s  method {spent['method']:7.2f} s  "
                  + "  ".join(f"{stage} {spent[stage]:.2f}" for stage in STAGES if stage != "method")
                  + f"  other {row['other_s']:.2f}", flush=True)
    total = {"cell": "total", "device": device, "frames": sum(r["frames"] for r in rows)}
    total.update({key: sum(r[key] for r in rows) for key in rows[0] if key.endswith("_s")})
    total["load_1min"] = os.getloadavg()[0]
    print(f"total: {total['wall_s']:.1f} s for {len(rows)} cells, {total['outside_method_s']:.2f} s outside the "
          f"methods ({total['outside_method_s'] / len(rows):.3f} s per cell)  load {total['load_1min']:.1f}")
    return rows + [total]


def results_csv_cost(frame_counts: list[int], work: Path, columns: int = 45) -> list[dict]:
    """results.csv over a sequence of N frames, the way the app writes it (one row appended per finished frame,
    `bench.harness.results.ResultsCsv`) beside the old way (the whole table rewritten after every frame,
    `bench.harness.results.write_results`), interleaved N by N: total seconds and the last frame's milliseconds."""
    import numpy as np

    from bench.harness.results import ResultsCsv, write_results

    rng = np.random.default_rng(0)
    names = ["object", "distance", "frame", "method", "failure"] + [f"value_{i}_cm" for i in range(columns - 5)]
    rows = []
    for n in frame_counts:
        frames = [dict(zip(names, ["04_bottle", 30, i, "mm2fsk", ""] + list(rng.random(columns - 5)), strict=False))
                  for i in range(n)]
        timings = {}
        for scheme in ("append", "rewrite"):
            path, spent, last_s = work / f"{scheme}_{n}.csv", 0.0, 0.0
            writer = ResultsCsv(path)
            for i in range(n):
                start = time.perf_counter()
                if scheme == "append":
                    writer.add(frames[i])
                else:
                    write_results(path, frames[:i + 1])
                last_s = time.perf_counter() - start
                spent += last_s
            timings[scheme] = (spent, last_s)
        rows.append({"frames": n, "append_s": timings["append"][0], "rewrite_s": timings["rewrite"][0],
                     "append_last_ms": timings["append"][1] * 1e3, "rewrite_last_ms": timings["rewrite"][1] * 1e3,
                     "load_1min": os.getloadavg()[0]})
        print(f"results.csv over {n:5d} frames: appended {timings['append'][0]:6.2f} s (last frame "
              f"{timings['append'][1] * 1e3:5.2f} ms), rewritten {timings['rewrite'][0]:6.2f} s (last frame "
              f"{timings['rewrite'][1] * 1e3:6.2f} ms)  load {rows[-1]['load_1min']:.1f}", flush=True)
    return rows


def main(argv=None) -> int:
    parser = cli.ArgumentParser(prog="python -m bench.perf overhead", description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=None, help="dataset root (e.g. data/synthetic)")
    parser.add_argument("--cells", nargs="+", default=None, help="default: the table3 cells")
    parser.add_argument("--captures", nargs="+", default=None, help="OBJECT/DISTANCE (default: all)")
    add_device_option(parser)
    parser.add_argument("--grid", default=None, help="grid config for every cell (e.g. paper, bp_cpu)")
    parser.add_argument("--store", action="store_true", help="use a fresh result store (default: none)")
    add_out_option(parser)
    parser.add_argument("--results-frames", type=int, nargs="+", default=None, metavar="N",
                        help="instead: results.csv written over N frames, appended beside rewritten "
                             "(OUT/perf_results_csv.csv)")
    args = parser.parse_args(argv)
    out = cli.output_dir(args.out)
    if args.results_frames:
        if min(args.results_frames) < 1:
            cli.fail(f"--results-frames {min(args.results_frames)}: give frame counts >= 1")
        with tempfile.TemporaryDirectory(prefix="perf_results_csv-") as work:
            write_rows(results_csv_cost(args.results_frames, Path(work)), out / "perf_results_csv.csv")
        return 0
    if args.root is None:
        cli.fail("--root: give the dataset root (e.g. data/synthetic)")
    device = cli.resolve_device(args.device)
    root = cli.existing_path(args.root, "dir", "--root").resolve()
    cells = args.cells or [cell["cell"] for cell in table3_cells()]
    with tempfile.TemporaryDirectory(prefix="perf_overhead-") as work:
        rows = measure(root, cells, args.captures, device, args.grid, args.store, Path(work))
    write_rows(rows, out / f"perf_overhead_{device}.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
