"""Frames per second of the table3 experiment: every table3 cell on every capture of a dataset root.

`python -m bench.perf sweep --root DIR [--device cpu|cuda] [--repeat N] [--bp-grid capture|small] [--out DIR]`
reads every capture under DIR once (radar + RealSense parts: no Open3D), then times `methods.reconstruct` for
each cell of configs/experiment/table3.yaml (method, frequencies and prior from configs/cell, /freq, /prior) on
the capture's own grid (the paper's 301x301 pixels, 301x301x201 voxels for BP; `--bp-grid small` runs BP on
configs/grid/bp_cpu.yaml instead). One untimed pass over all cells and captures comes first (compilation, caches);
each frame's time is the median of `--repeat` wall-clock calls (ms, the whole `reconstruct` call, as a sweep pays).

Shared stage: the MM-2FSK cells of one capture use the same RealSense prior; the `mm2fsk shared` row builds it
once per capture (`methods.api.prior_image_m`) and runs the three cells on it (`methods.mm2fsk.reconstruct_mm2fsk`),
timed as one frame group, and checks that the depth maps equal those of `reconstruct`.
Writes OUT/perf_sweep_<device>.csv (OUT = `--out`, default outputs/perf/; `--out results` for the committed
figures): one row per cell, the shared MM-2FSK group, and the table3 totals.
"""
from __future__ import annotations

import functools
import statistics
import time
from pathlib import Path

import numpy as np
from omegaconf import OmegaConf

from bench import cli
from bench.harness.app import CONFIG_DIR
from bench.harness.grids import grid_for
from bench.maroon.reader import discover_captures, read_capture
from bench.perf.common import DEFAULT_OUT, write_rows
from bench.progress import each
from methods import reconstruct
from methods.api import frequency_indices, prior_image_m
from methods.backends import backend_for
from methods.domain.capture import Capture, RadarGrid
from methods.mm2fsk import reconstruct_mm2fsk
from methods.registry import BUILTIN


def table3_cells() -> list[dict]:
    """The table3 cells in sweep order, each composed by Hydra as the sweep composes it: name, method, f_ghz
    (None = all), prior, scalar_prior_m (m), grid (name)."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        sweep = compose(config_name="config", overrides=["experiment=table3"], return_hydra_config=True)
        names = str(sweep.hydra.sweeper.params.cell).split(",")
        cells = []
        for name in names:
            cfg = compose(config_name="config", overrides=[f"cell={name}"])
            # a method outside the package is named by its class path (configs/method/custom.yaml's _target_)
            method = cfg.method.name if cfg.method.name in BUILTIN else cfg.method._target_
            cells.append({"cell": name, "method": method,
                          "f_ghz": None if cfg.freq.f_ghz is None else list(cfg.freq.f_ghz),
                          "prior": cfg.prior.name, "scalar_prior_m": float(cfg.prior.scalar_m),
                          "grid": cfg.grid.name})
    return cells


def _grid_override(name: str) -> dict:
    """The `override` of grid config `name` (configs/grid/), composed by Hydra."""
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return OmegaConf.to_container(compose(config_name="config", overrides=[f"grid={name}"]).grid.override)


def _grid(capture: Capture, method: str, bp_override: dict | None, image_override: dict | None) -> RadarGrid:
    return grid_for(capture, bp_override if method == "bp" else image_override)


def _wall_ms(fn) -> tuple[float, object]:
    t0 = time.perf_counter()
    out = fn()
    return 1e3 * (time.perf_counter() - t0), out


def _cell_call(capture: Capture, cell: dict, device: str, grid: RadarGrid):
    return reconstruct(capture, cell["method"], cell["f_ghz"], prior=cell["prior"], device=device, grid=grid,
                       scalar_prior_m=cell["scalar_prior_m"])


def _shared_mm2fsk(capture: Capture, cells: list[dict], device: str, grid: RadarGrid) -> list:
    """The MM-2FSK cells of one capture on one prior image (built once): their Reconstructions."""
    prior = prior_image_m(capture, cells[0]["prior"], grid, device, keep_on_device=True)
    frame = capture.radar
    results = []
    for cell in cells:
        idx = frequency_indices(frame.freqs_hz, cell["f_ghz"])
        results.append(reconstruct_mm2fsk(np.ascontiguousarray(frame.signal[:, :, idx]), frame.freqs_hz[idx],
                                          capture.antennas, grid, prior, backend=backend_for(device)))
    return results


def run_sweep(root: Path, device: str, repeat: int, bp_override: dict | None = None,
              image_override: dict | None = None) -> list[dict]:
    """Rows of frames per second per cell, for the shared MM-2FSK group and for table3 (all cells x captures)."""
    captures = [read_capture(d, parts=("radar", "realsense")) for d in discover_captures(root)]
    cells = table3_cells()
    mm_cells = [c for c in cells if c["method"] == "mm2fsk"]
    rows, reference = [], {}
    for cell in each(cells, "warm-up", unit="cell"):  # untimed pass: compilation, device caches, reference maps
        for cap in captures:
            rec = _cell_call(cap, cell, device, _grid(cap, cell["method"], bp_override, image_override))
            if cell["method"] == "mm2fsk":
                reference[cap.name, cell["cell"]] = rec.depth_m
    for cell in each(cells, "timing", unit="cell"):
        per_frame, method_ms, valid = [], [], 0
        for cap in captures:
            grid = _grid(cap, cell["method"], bp_override, image_override)
            runs = [_wall_ms(functools.partial(_cell_call, cap, cell, device, grid)) for _ in range(repeat)]
            per_frame.append(statistics.median(ms for ms, _ in runs))
            method_ms.append(statistics.median(rec.timings_ms["total"] for _, rec in runs))
            valid += int(runs[-1][1].valid.sum())
        rows.append(_row(cell["cell"], cell["method"], device, len(captures), per_frame, method_ms,
                         valid_px=valid // len(captures)))
    if mm_cells:
        per_group, max_diff = [], 0.0
        for cap in each(captures, "shared MM-2FSK prior", unit="capture"):
            grid = _grid(cap, "mm2fsk", bp_override, image_override)
            runs = [_wall_ms(functools.partial(_shared_mm2fsk, cap, mm_cells, device, grid))
                    for _ in range(repeat + 1)][1:]
            per_group.append(statistics.median(ms for ms, _ in runs))
            for cell, rec in zip(mm_cells, runs[-1][1], strict=False):
                ref = reference[cap.name, cell["cell"]]
                both = np.isfinite(ref) & np.isfinite(rec.depth_m)
                if not np.array_equal(np.isfinite(ref), np.isfinite(rec.depth_m)):
                    raise AssertionError(f"{cap.name} {cell['cell']}: shared prior changed the valid pixels")
                max_diff = max(max_diff, float(np.abs(ref[both] - rec.depth_m[both]).max(initial=0.0)))
        per_frame = [ms / len(mm_cells) for ms in per_group]
        rows.append(_row("mm2fsk_shared", "mm2fsk", device, len(captures), per_frame, per_frame,
                         max_depth_diff_m=max_diff))
    rows.append(_total("table3", rows[:len(cells)], device))
    if mm_cells:
        shared = [r for r in rows[:len(cells)] if r["method"] != "mm2fsk"] + [rows[len(cells)]] * len(mm_cells)
        rows.append(_total("table3_shared_prior", shared, device))
    return rows


def _row(name: str, method: str, device: str, n_captures: int, per_frame_ms: list[float],
         method_ms: list[float], **extra) -> dict:
    ms = statistics.fmean(per_frame_ms)
    row = {"cell": name, "method": method, "device": device, "captures": n_captures, "frames": n_captures,
           "ms_per_frame": ms, "method_ms_per_frame": statistics.fmean(method_ms), "fps": 1e3 / ms}
    row.update(extra)
    print(f"{name:22s} {ms:10.2f} ms/frame  {1e3 / ms:9.2f} fps", flush=True)
    return row


def _total(name: str, rows: list[dict], device: str) -> dict:
    """All cells x captures: frames over the summed time (ms = mean time per frame)."""
    frames = sum(r["frames"] for r in rows)
    total_ms = sum(r["ms_per_frame"] * r["frames"] for r in rows)
    method_ms = sum(r["method_ms_per_frame"] * r["frames"] for r in rows)
    print(f"{name:22s} {frames} frames in {total_ms / 1e3:.3f} s: {1e3 * frames / total_ms:.2f} fps", flush=True)
    return {"cell": name, "method": "all", "device": device, "captures": rows[0]["captures"], "frames": frames,
            "ms_per_frame": total_ms / frames, "method_ms_per_frame": method_ms / frames,
            "fps": 1e3 * frames / total_ms}


def main(argv=None) -> int:
    parser = cli.ArgumentParser(prog="python -m bench.perf sweep", description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, required=True, help="dataset root holding <object>/<distance> folders")
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda", "auto"])
    parser.add_argument("--repeat", type=cli.positive_int, default=3, help="timed calls per cell and capture (median)")
    parser.add_argument("--bp-grid", default="capture", choices=["capture", "small"],
                        help="BP grid: the capture's own (paper, 301x301x201) or configs/grid/bp_cpu.yaml")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="folder for the CSV (default: outputs/perf; `--out results` for the committed figures)")
    args = parser.parse_args(argv)
    root = cli.existing_path(args.root, "dir", "dataset root")
    device = cli.resolve_device(args.device)
    out = cli.output_dir(args.out)
    bp_override = _grid_override("bp_cpu") if args.bp_grid == "small" else None
    rows = run_sweep(root, device, args.repeat, bp_override)
    write_rows(rows, out / f"perf_sweep_{device}.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
