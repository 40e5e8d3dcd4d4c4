"""New-frame latency with the default skips against the full computation: `python -m bench.perf skips-gpu`.

`python -m bench.perf skips-gpu --root DIR [--device cuda|cpu|warp-cpu] [--repeat N] [--cases a,b]
[--variants auto,none|auto|none] [--out DIR]`
reads every capture under DIR (radar + RealSense: no Open3D) and times, for each case (BP_max, BP d05, MM-2FSK d10
with the RealSense prior, 2FSK d05, 3FSK d05_d10; the capture's own grid, i.e. the paper's 301 x 301 x 201), the
whole `methods.reconstruct` call (result back on the host) with `roi=auto` (the default skips) and `roi=none`
(today's full computation), interleaved in one process. Every timed call gets a frame the process has not seen:
the radar samples rotated by a random phase (|signal| and every depth unchanged) and the depth image shifted by
1 mm (every valid pixel + 1 unit), so no content cache can hit. One untimed call per case and capture comes first
(compilation; there both variants see the same frame, for the agreement). Printed and written per case and
variant: median and 90th percentile over all frames (ms), the median of each stage, and for `auto` the share of the
pixels valid in either map whose depths agree within 0.1 mm (`agreement`; worst capture). Writes
OUT/perf_skips_gpu_<device>.csv (OUT = `--out`, default outputs/perf/).
"""
from __future__ import annotations

import dataclasses
import statistics
import time
from pathlib import Path

import numpy as np

from bench import cli
from bench.maroon.reader import discover_captures, read_capture
from bench.perf.common import DEFAULT_OUT, percentile, write_rows
from bench.progress import each
from methods import reconstruct
from methods.domain.capture import Capture

# label -> (method, frequency configuration (None = all), prior)
CASES = {"bp_full": ("bp", None, "none"), "bp_d05": ("bp", "d05", "none"),
         "mm2fsk_d10": ("mm2fsk", "d10", "realsense"), "2fsk_d05": ("2fsk", "d05", "none"),
         "3fsk_d05_d10": ("3fsk", "d05_d10", "none")}
VARIANTS = ("auto", "none")
DEPTH_TOL_M = 1e-4          # 0.1 mm


def new_frame(capture: Capture, rng: np.random.Generator, shift_units: int) -> Capture:
    """A copy of the capture that no cache has seen: radar samples x exp(j phi), depth image + shift_units."""
    phase = np.complex64(np.exp(1j * rng.uniform(0, 2 * np.pi)))
    radar = dataclasses.replace(capture.radar, signal=capture.radar.signal * phase)
    realsense = capture.realsense
    if realsense is not None:
        depth = realsense.depth_mm.astype(np.int32)
        depth[depth > 0] += shift_units
        realsense = dataclasses.replace(realsense, depth_mm=np.clip(depth, 0, 65535).astype(np.uint16))
    return dataclasses.replace(capture, radar=radar, realsense=realsense)


def agreement(ref_m: np.ndarray, depth_m: np.ndarray) -> float:
    """Share (%) of the pixels valid in either map whose depths agree within 0.1 mm, a pixel valid in one map only
    counting as not (issue 30's reading, as `agree_either_pct` of bench.perf skips); 100 when none is valid."""
    valid_ref, valid = np.isfinite(ref_m), np.isfinite(depth_m)
    either = int((valid_ref | valid).sum())
    if not either:
        return 100.0
    both = valid_ref & valid
    return 100.0 * int((np.abs(ref_m[both] - depth_m[both]) <= DEPTH_TOL_M).sum()) / either


def run_cases(captures: list[Capture], cases: list[str], device: str, repeat: int, seed: int = 0,
              variants: tuple[str, ...] = VARIANTS) -> list[dict]:
    """Rows per case and variant: new-frame wall time median/p90, stage medians, agreement of auto with none (when
    both run; `variants` ("auto",) times the default skips alone, e.g. where the full computation takes minutes)."""
    rng = np.random.default_rng(seed)
    rows = []
    both = set(variants) == set(VARIANTS)
    for label in each(cases, "cases", unit="case"):
        method, freq, prior = CASES[label]
        times = {v: [] for v in variants}
        stages = {v: [] for v in variants}
        agree, roi_px = [], []
        # untimed: compilation, first uploads, and the agreement on one frame (alone: the first capture only)
        for cap in captures if both else captures[:1]:
            frame = new_frame(cap, rng, 1)
            results = {v: reconstruct(frame, method, freq, prior=prior, device=device, roi=v) for v in variants}
            if both:
                agree.append(agreement(results["none"].depth_m, results["auto"].depth_m))
            if "auto" in results:
                roi_px.append(int(results["auto"].extra.get("roi_px", -1) or -1))
        per_capture = {cap.name: [] for cap in captures}
        for run in range(repeat):
            for cap in captures:
                for variant in (variants if run % 2 == 0 else variants[::-1]):
                    frame = new_frame(cap, rng, 1 + run % 2)
                    t0 = time.perf_counter()
                    rec = reconstruct(frame, method, freq, prior=prior, device=device, roi=variant)
                    times[variant].append(1e3 * (time.perf_counter() - t0))
                    stages[variant].append(rec.timings_ms)
                    if variant == variants[0]:
                        per_capture[cap.name].append(times[variant][-1])
        if not both:                    # per object, as the CPU figures are reported
            for name, ms in per_capture.items():
                print(f"{label:13s} {variants[0]:5s} {name:24s} median {statistics.median(ms):10.1f} ms", flush=True)
        for variant in variants:
            names = sorted({s for t in stages[variant] for s in t})
            row = {"case": label, "variant": variant, "device": device, "captures": len(captures),
                   "frames": len(times[variant]), "median_ms": statistics.median(times[variant]),
                   "p90_ms": percentile(times[variant], 90),
                   "agree_min_pct": min(agree) if agree and variant == "auto" else (100.0 if both else float("nan")),
                   "roi_px_median": statistics.median(roi_px) if roi_px and variant == "auto" else ""}
            row.update({f"{s}_ms": statistics.median(t.get(s, 0.0) for t in stages[variant]) for s in names})
            rows.append(row)
            detail = "  ".join(f"{s} {row[f'{s}_ms']:.2f}" for s in names if s != "total")
            print(f"{label:13s} {variant:5s} median {row['median_ms']:9.2f} ms  p90 {row['p90_ms']:9.2f} ms  "
                  f"agree {row['agree_min_pct']:6.2f} %  ({detail})", flush=True)
    return rows


def main(argv=None) -> int:
    parser = cli.ArgumentParser(prog="python -m bench.perf skips-gpu", description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, required=True, help="dataset root holding <object>/<distance> folders")
    parser.add_argument("--device", default="cuda", choices=["cpu", "cuda", "warp-cpu", "auto"])
    parser.add_argument("--repeat", type=cli.positive_int, default=3, help="timed new frames per capture and variant")
    parser.add_argument("--cases", default=",".join(CASES), help=f"comma-separated subset of {', '.join(CASES)}")
    parser.add_argument("--variants", default="auto,none", choices=["auto,none", "auto", "none"],
                        help="auto,none (default: both, interleaved, with their agreement) or one alone")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="folder for the CSV (default: outputs/perf)")
    args = parser.parse_args(argv)
    cases = [c for c in args.cases.split(",") if c]
    unknown = sorted(set(cases) - set(CASES))
    if unknown:
        cli.fail(f"--cases: unknown case(s) {', '.join(unknown)}; choose from {', '.join(CASES)}")
    root = cli.existing_path(args.root, "dir", "dataset root")
    device = cli.resolve_device(args.device)
    out = cli.output_dir(args.out)
    captures = [read_capture(d, parts=("radar", "realsense")) for d in discover_captures(root)]
    rows = run_cases(captures, cases, device, args.repeat, variants=tuple(args.variants.split(",")))
    write_rows(rows, out / f"perf_skips_gpu_{device}.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
