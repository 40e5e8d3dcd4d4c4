"""The prior's hole fill, runtime against error: MM-2FSK with the RealSense prior built with each fill rule
(`prior.fill`: delaunay | scanline, methods.prior.priors) on the same captures and frames.

`python -m bench.perf fill [--root DIR] [--freqs d10 d1 d05] [--device cpu|cuda|warp-cpu] [--repeat N] [--out DIR]`

Per fill and frequency configuration: the metrics C_g, C_s, P, P_e (cm, mean over the captures, sound
definitions, metrics.evaluate) and how many captures succeeded; per fill the prior's build time (median over
captures of the median of `--repeat` builds, on `--device`) and the pixels it fills. Per configuration, how the
two fills' results differ on the same frame: prior pixels filled by one and not the other, the largest prior
difference where both have one, and the share of depth pixels valid in both maps within 0.1 mm, with the pixels
valid in only one. Writes OUT/perf_fill.csv (OUT: `--out`, default outputs/perf).
"""
from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np

from bench import cli
from bench.perf.common import DEFAULT_OUT, add_device_option, write_rows
from bench.progress import each
from methods import reconstruct
from methods.api import prior_image_m
from methods.prior.priors import FILLS

METRICS = ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm")
AGREE_M = 1e-4


def _captures(root: Path) -> list:
    from bench.maroon.reader import discover_captures, read_capture

    return [read_capture(path, parts=("radar", "realsense", "mesh")) for path in discover_captures(root)]


def _prior_ms(capture, fill: str, device: str, repeat: int) -> tuple[float, np.ndarray]:
    """Median build time (ms, result on the host) of the capture's RealSense prior, and the prior (ny, nx)."""
    grid = capture.radar.grid
    times = []
    for _ in range(repeat + 1):                       # the first build compiles / touches pages: not timed
        start = time.perf_counter()
        image = np.asarray(prior_image_m(capture, "realsense", grid, device, keep_on_device=True, fill=fill))
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times[1:]), image


def compare_fills(captures, freqs: list[str], device: str, repeat: int) -> list[dict]:
    """One row per (fill, configuration) with its metrics and prior cost, and one per configuration comparing the
    two fills (module doc)."""
    from metrics.evaluate import evaluate, ground_truth

    truths = [ground_truth(c, c.radar.grid) for c in captures]
    priors = {fill: [_prior_ms(c, fill, device, repeat) for c in captures] for fill in FILLS}
    depths, rows = {}, []
    for fill in FILLS:
        filled_px = [int(np.isfinite(p).sum()) for _, p in priors[fill]]
        for freq in each(freqs, f"prior fill {fill}", unit="config"):
            scores, runtimes = [], []
            for capture, truth in zip(captures, truths, strict=False):
                rec = reconstruct(capture, "mm2fsk", freq, prior="realsense", device=device,
                                  prior_options={"fill": fill})
                depths[fill, freq, capture.name] = rec.depth_m
                scores.append(evaluate(rec.depth_m, truth))
                runtimes.append(rec.timings_ms["total"])
            ok = [s for s in scores if not s["failure"]]
            row = {"fill": fill, "freq": freq, "device": device, "captures": len(captures), "ok": len(ok),
                   "prior_ms_median": statistics.median(ms for ms, _ in priors[fill]),
                   "runtime_ms_median": statistics.median(runtimes), "prior_px_median": statistics.median(filled_px)}
            row.update({m: float(np.mean([s[m] for s in ok])) if ok else float("nan") for m in METRICS})
            rows.append(row)
            print(f"{fill:9s} {freq:4s} ok {len(ok)}/{len(captures)}  " + "  ".join(
                f"{m[:-3]} {row[m]:.3f}" for m in METRICS) + f"  prior {row['prior_ms_median']:.2f} ms  total "
                f"{row['runtime_ms_median']:.2f} ms ({device})", flush=True)
    first, second = FILLS
    for freq in freqs:
        only_px, max_prior_m, agree, only_valid = 0, 0.0, [], 0
        for k, capture in enumerate(captures):
            a, b = priors[first][k][1], priors[second][k][1]
            only_px += int((np.isfinite(a) != np.isfinite(b)).sum())
            both = np.isfinite(a) & np.isfinite(b)
            max_prior_m = max(max_prior_m, float(np.max(np.abs(a - b), where=both, initial=0.0)))
            da, db = depths[first, freq, capture.name], depths[second, freq, capture.name]
            valid = np.isfinite(da) & np.isfinite(db)
            agree.append(float(np.mean(np.abs(da - db)[valid] <= AGREE_M)) if valid.any() else 1.0)
            only_valid += int((np.isfinite(da) != np.isfinite(db)).sum())
        row = {"fill": f"{first} vs {second}", "freq": freq, "device": device, "captures": len(captures),
               "prior_px_in_one_only": only_px, "prior_max_diff_mm": max_prior_m * 1e3,
               "depth_agree_0.1mm_pct_worst": 100.0 * min(agree), "depth_valid_in_one_only_px": only_valid}
        rows.append(row)
        print(f"{first} vs {second} {freq}: prior pixels in one only {only_px}, prior max diff "
              f"{row['prior_max_diff_mm']:.3f} mm; depth within 0.1 mm {row['depth_agree_0.1mm_pct_worst']:.2f} % "
              f"(worst capture), valid in one only {only_valid} px", flush=True)
    return rows


def main(argv=None) -> int:
    parser = cli.ArgumentParser(prog="python -m bench.perf fill", description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=Path("data/synthetic"), help="dataset root (default: %(default)s)")
    parser.add_argument("--freqs", nargs="+", default=["d10", "d1", "d05"])
    add_device_option(parser)
    parser.add_argument("--repeat", type=cli.positive_int, default=3, help="prior builds timed per capture")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="folder for perf_fill.csv")
    args = parser.parse_args(argv)
    root = cli.existing_path(args.root, "dir", "--root")
    device = cli.resolve_device(args.device)
    rows = compare_fills(_captures(root), args.freqs, device, args.repeat)
    write_rows(rows, cli.output_dir(args.out) / "perf_fill.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
