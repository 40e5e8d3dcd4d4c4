"""Every skip accounted for in runtime against error: `python -m bench.perf skips [options]`.

For every capture of a dataset (default: the synthetic catalogue at 30 cm) and every cell (method x frequency
configuration x prior), each skip of `methods.skips.settings` runs off and on beside the full computation (`roi=none`),
interleaved in one process (repeat-th run of each in turn), warm (one untimed run first). Printed and written per
variant: median time, speed-up over the full computation, the pixels evaluated, the change of the depth map (the
share of the pixels valid in both that agree within 0.1 mm, valid pixels gained and lost) and of each metric
(C_g, C_s, P, P_e on the capture's metric grid after resampling, metrics.evaluate), and whether the variant meets
the rule for being on by default: depth within 0.1 mm on >= 99 % of the pixels valid in both, every metric within
1 % (relative; within 0.001 cm where the full value is below 0.1 cm). `agree_either_pct` counts the pixels valid in
either map, a pixel valid in one only as not within 0.1 mm (issue 30's reading of "the pixels that pass -14 dB":
a pixel the skip loses or gains is a depth it got wrong).

Variants: `alone` (each skip alone; `auto` and `all` together), or `--mode leave-one-out` (the default skips with
one flipped: `auto-X` without a default skip X, `auto+X` with a skip X that is off by default; attributes each
skip's share where a variant alone is too slow, e.g. BP_max on the paper grid on the CPU). Full computations that are
too slow here can be read from `--reference DIR`
(`<object>_<distance>_<cell>_<grid>.npz` holding `depth_m` on the compute grid: e.g. from `--make-reference`, the
float64 direct sum on a CUDA device through CuPy); the full computation is then timed on `--full-planes` depth
planes of the grid and scaled to all (marked in `full_timing`).
"""
from __future__ import annotations

import csv
import dataclasses
import functools
import statistics
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from methods.domain.capture import RadarGrid
from methods.skips.settings import ALL, NONE, SkipSettings, default_for

DEPTH_TOL_M = 1e-4              # 0.1 mm
AGREE_SHARE = 0.99              # of the pixels valid in both
METRIC_REL_TOL = 0.01           # 1 %
METRIC_ABS_FLOOR_CM = 1e-3      # metrics below 0.1 cm compare absolutely (a relative 1 % of ~0 is noise)
METRICS = ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm")
GRIDS = {"paper": {"xy_half_m": 0.15, "nxy": 301, "z_half_m": 0.10, "nz": 201},
         "coarse": {"xy_half_m": 0.15, "nxy": 151, "z_half_m": 0.10, "nz": 101},
         "bp_cpu": {"xy_half_m": 0.15, "nxy": 51, "z_half_m": 0.10, "nz": 21},
         "from_capture": None}
# label -> (method, frequency configuration (None = all), prior)
CELLS = {"bp_d05": ("bp", "d05", "none"), "bp_d1": ("bp", "d1", "none"), "bp_d10": ("bp", "d10", "none"),
         "bp_full": ("bp", None, "none"), "2fsk_d05": ("2fsk", "d05", "none"), "3fsk_d05_d10": ("3fsk", "d05_d10",
                                                                                                "none"),
         "mm2fsk_d10": ("mm2fsk", "d10", "photogrammetry")}
APPLIES = {"bp": ("mask_bb", "mask_bb_depth", "coarse_roi", "bp_coarse_to_fine", "bp_range_cpu"),
           "2fsk": ("mask_bb", "mask_bb_depth", "fsk_keep"), "3fsk": ("mask_bb", "mask_bb_depth", "fsk_keep"),
           "mm2fsk": ("mask_bb", "mask_bb_depth")}
CSV_COLUMNS = ["object", "distance", "cell", "grid", "variant", "median_ms", "full_ms", "full_timing", "speedup",
               "roi_px", "evaluated", "valid_full", "valid_skip", "valid_both", "agree_0p1mm_pct", "agree_either_pct",
               "max_diff_mm",
               *[f"{m}_full" for m in METRICS], *[f"{m}_skip" for m in METRICS], *[f"{m}_rel_pct" for m in METRICS],
               "meets_rule", "reference", "device", "hostname"]


@dataclass
class Comparison:
    """Depth and metric change of one variant against the full computation."""

    valid_full: int
    valid_skip: int
    valid_both: int
    agree_pct: float
    agree_either_pct: float          # of the pixels valid in either map; valid in one only: not within
    max_diff_mm: float
    metrics_full: dict
    metrics_skip: dict
    rel_pct: dict
    meets_rule: bool


def applicable(method: str, n_freqs: int) -> tuple[str, ...]:
    """Skips that change anything for this method and frequency count (range compression: many frequencies)."""
    names = APPLIES[method]
    return tuple(n for n in names if n != "bp_range_cpu" or n_freqs >= 16)


def variants(method: str, n_freqs: int, mode: str) -> list[tuple[str, SkipSettings]]:
    """(name, settings) of the variants measured beside the full computation."""
    names = applicable(method, n_freqs)
    auto = default_for(method, n_freqs)
    if mode == "alone":
        out = [(n, ALL.only(n)) for n in names]
    else:                            # the default with one skip flipped: off where it is on, on where it is off
        out = [(f"auto{'-' if getattr(auto, n) else '+'}{n}", dataclasses.replace(auto, **{n: not getattr(auto, n)}))
               for n in names]
    return out + [("auto", auto), ("all", ALL)]


def compare(full_m: np.ndarray, skip_m: np.ndarray, scores_full: dict, scores_skip: dict) -> Comparison:
    """Depth maps (metric grid, metres, NaN = invalid) and their scores -> the change (module doc)."""
    valid_full, valid_skip = np.isfinite(full_m), np.isfinite(skip_m)
    both = valid_full & valid_skip
    diff = np.abs(full_m[both] - skip_m[both])
    agree = 100.0 * float(np.mean(diff <= DEPTH_TOL_M)) if both.any() else float("nan")
    either = int((valid_full | valid_skip).sum())
    agree_either = 100.0 * int((diff <= DEPTH_TOL_M).sum()) / either if either else float("nan")
    rel = {}
    for m in METRICS:
        a, b = float(scores_full[m]), float(scores_skip[m])
        if not (np.isfinite(a) and np.isfinite(b)):
            rel[m] = 0.0 if (np.isnan(a) and np.isnan(b)) else float("inf")
        elif abs(a) < 0.1:
            rel[m] = 0.0 if abs(b - a) <= METRIC_ABS_FLOOR_CM else 100.0 * abs(b - a) / max(abs(a), 1e-12)
        else:
            rel[m] = 100.0 * abs(b - a) / abs(a)
    meets = (not both.any() or agree >= 100.0 * AGREE_SHARE) and all(v <= 100.0 * METRIC_REL_TOL for v in rel.values())
    return Comparison(int(valid_full.sum()), int(valid_skip.sum()), int(both.sum()), agree, agree_either,
                      float(diff.max() * 1e3) if both.any() else float("nan"),
                      {m: scores_full[m] for m in METRICS}, {m: scores_skip[m] for m in METRICS}, rel, bool(meets))


def compute_grid(capture, grid_name: str) -> RadarGrid:
    from bench.harness.grids import grid_for
    return grid_for(capture, GRIDS[grid_name])


def _planes_grid(grid: RadarGrid, n_planes: int) -> RadarGrid:
    """The grid's pixels with `n_planes` of its depth samples (evenly spaced, same step) around its centre."""
    z_m = grid.z_m
    mid = len(z_m) // 2
    z_run = z_m[mid - n_planes // 2: mid - n_planes // 2 + n_planes]
    return RadarGrid((grid.bb_min_m[0], grid.bb_min_m[1], float(z_run[0])),
                     (grid.bb_max_m[0], grid.bb_max_m[1], float(z_run[-1])), (grid.size[0], grid.size[1], len(z_run)))


def _timed(fn) -> tuple[float, object]:
    start = time.perf_counter()
    out = fn()
    return 1e3 * (time.perf_counter() - start), out


def reference_path(ref_dir: Path | None, capture, cell: str, grid_name: str) -> Path | None:
    if ref_dir is None:
        return None
    return Path(ref_dir) / f"{capture.object_name}_{capture.distance_cm}_{cell}_{grid_name}.npz"


def measure_cell(capture, gt, cell: str, grid_name: str, device: str, repeat: int, mode: str,
                 ref_dir: Path | None, full_planes: int, only: list[str] | None = None, log=print) -> list[dict]:
    """Rows (CSV_COLUMNS) for one capture and cell: the full computation and every variant, interleaved."""
    import socket

    from methods import reconstruct
    from methods.api import frequency_indices
    from metrics.evaluate import evaluate
    from metrics.resample import resample_depth_m

    method, freq, prior = CELLS[cell]
    grid = compute_grid(capture, grid_name)
    n_freqs = len(frequency_indices(capture.radar.freqs_hz, freq))
    runs = [(n, v) for n, v in variants(method, n_freqs, mode) if not only or n in only]
    ref_file = reference_path(ref_dir, capture, cell, grid_name)
    full_depth = np.load(ref_file)["depth_m"] if ref_file is not None and ref_file.exists() else None
    full_grid = grid if full_depth is None else _planes_grid(grid, full_planes)

    def run(settings: SkipSettings, on_grid: RadarGrid):
        return reconstruct(capture, method, freq, prior=prior, device=device, grid=on_grid, roi=settings)

    # warm-up (compilation, the per-configuration search plan), then interleaved timed runs
    run(NONE, _planes_grid(grid, 2))
    times = {name: [] for name, _ in [("full", NONE), *runs]}
    results = {}
    for _ in range(repeat):
        ms, rec = _timed(lambda: run(NONE, full_grid))
        times["full"].append(ms)
        results.setdefault("full", rec)
        for name, settings in runs:
            ms, rec = _timed(functools.partial(run, settings, grid))
            times[name].append(ms)
            results.setdefault(name, rec)
    full_ms = statistics.median(times["full"]) * (grid.size[2] / full_grid.size[2])
    scale = grid.size[2] / full_grid.size[2]
    full_timing = "measured" if full_grid is grid else f"{full_grid.size[2]} planes x{scale:.1f}"
    if full_depth is None:
        full_depth = results["full"].depth_m
        if ref_file is not None:
            ref_file.parent.mkdir(parents=True, exist_ok=True)
            np.savez_compressed(ref_file, depth_m=full_depth, source="cpu roi=none")
    metric_grid = capture.radar.grid
    full_metric = resample_depth_m(full_depth, grid, metric_grid)
    scores_full = evaluate(full_metric, gt)
    rows = []
    for name, _ in runs:
        rec = results[name]
        skip_metric = resample_depth_m(rec.depth_m, rec.grid, metric_grid)
        c = compare(full_metric, skip_metric, scores_full, evaluate(skip_metric, gt))
        median_ms = statistics.median(times[name])
        row = {"object": capture.object_name, "distance": capture.distance_cm, "cell": cell, "grid": grid_name,
               "variant": name, "median_ms": median_ms, "full_ms": full_ms, "full_timing": full_timing,
               "speedup": full_ms / median_ms, "roi_px": rec.extra.get("roi_px"),
               "evaluated": rec.extra.get("evaluated_voxels", rec.extra.get("roi_px")),
               "valid_full": c.valid_full, "valid_skip": c.valid_skip, "valid_both": c.valid_both,
               "agree_0p1mm_pct": c.agree_pct, "agree_either_pct": c.agree_either_pct, "max_diff_mm": c.max_diff_mm,
               **{f"{m}_full": c.metrics_full[m] for m in METRICS}, **{f"{m}_skip": c.metrics_skip[m] for m in METRICS},
               **{f"{m}_rel_pct": c.rel_pct[m] for m in METRICS}, "meets_rule": c.meets_rule,
               "reference": "file" if ref_file is not None and ref_file.exists() else "computed",
               "device": device, "hostname": socket.gethostname()}
        rows.append(row)
        log(f"{capture.object_name:16s} {cell:13s} {name:20s} {median_ms:10.0f} ms  full {full_ms:10.0f} ms "
            f"x{row['speedup']:6.1f}  agree {c.agree_pct:7.3f} % of {c.valid_both:6d} ({c.agree_either_pct:7.3f} % of "
            f"either)  valid {c.valid_full}->"
            f"{c.valid_skip}  metrics max {max(c.rel_pct.values()):6.2f} %  {'ok' if c.meets_rule else 'NO'}")
    return rows


def write_csv(rows: list[dict], path: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=CSV_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: (f"{v:.5g}" if isinstance(v, float) else v) for k, v in r.items()})
    print(f"wrote {path}")


def main(argv=None) -> int:
    from bench import cli
    from bench.perf.common import DEFAULT_OUT

    parser = cli.ArgumentParser(prog="python -m bench.perf skips", description=__doc__.splitlines()[0])
    parser.add_argument("--root", default="data/synthetic", help="dataset root (default: the synthetic catalogue)")
    parser.add_argument("--objects", nargs="*", default=None, help="object/distance captures (default: all)")
    parser.add_argument("--cells", nargs="*", default=list(CELLS), choices=list(CELLS))
    parser.add_argument("--grid", default="paper", choices=list(GRIDS))
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda", "auto"])
    parser.add_argument("--repeat", type=cli.positive_int, default=1)
    parser.add_argument("--mode", default="alone", choices=["alone", "leave-one-out"])
    parser.add_argument("--reference", default=None, help="folder of full-computation depth maps (read, or written)")
    parser.add_argument("--full-planes", type=cli.positive_int, default=10,
                        help="depth planes the full computation is timed on when its depth map is read")
    parser.add_argument("--variants", nargs="*", default=None,
                        help="run only these variants (e.g. auto all, or all-bp_range_cpu in leave-one-out mode)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT / "perf_skips.csv", help="CSV written")
    args = parser.parse_args(argv)
    from bench.maroon import reader
    from bench.progress import steps
    from metrics.evaluate import ground_truth

    root = cli.existing_path(args.root, "dir", "dataset root")
    device = cli.resolve_device(args.device)
    out = cli.output_file(args.out)
    dirs = ([cli.existing_path(root / o, "dir", "capture") for o in args.objects] if args.objects
            else reader.discover_captures(root))
    rows: list[dict] = []
    with steps(len(dirs) * len(args.cells), "captures x cells", unit="cell") as progress:
        for capture_dir in dirs:
            capture = reader.read_capture(capture_dir, parts=("radar", "mesh"))
            gt = ground_truth(capture, capture.radar.grid)
            for cell in args.cells:
                rows += measure_cell(capture, gt, cell, args.grid, device, args.repeat, args.mode,
                                     None if args.reference is None else Path(args.reference), args.full_planes,
                                     args.variants)
                write_csv(rows, out)
                progress.update()
    return 0


if __name__ == "__main__":
    from bench import cli
    cli.run_guarded(main)
