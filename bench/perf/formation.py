"""Image formation by algorithm, runtime against error: `python -m bench.perf formation`.

`python -m bench.perf formation [--device cuda|warp-cpu|cpu] [--grid paper|small] [--frames N]
[--parts columns,search|range,bp2] [--out DIR]` times, on frames no cache has seen (scatterers on a random curved
surface at 0.3 m, every call a new scene), median and p90 over `--frames` frames after one untimed call (default
parts: columns,search on Warp devices, range,bp2 on the CPU):
* `columns`: BP d05 (81.45 / 82.0 GHz) over the whole grid, `volume_peak` with the tensor-core/default kernel
  (today's path) beside the column-separable kernel at three rho steps (term bounds 1e-3, 1e-4, 1e-5); and for
  two frames the error of each against the fp32 separable kernel over every voxel (relative L2, max |.|
  difference / max |.|), against the float64 direct sum at 256 random voxels, and the share of pixels within
  -14 dB whose depth is within 0.1 mm of the fp32 separable volume's;
* `search`: BP_max (128 frequencies) through `methods.bp.reconstruct_bp` with the device's default skips (coarse
  ROI, coarse-to-fine search), the search on the device (`device_search` on) beside the host-driven search (off),
  same frames, interleaved; the share of pixels valid in both maps within 0.1 mm and the samples evaluated;
* `range` (CPU): BP_max through `reconstruct_bp` with the CPU's default skips (coarse ROI, coarse-to-fine search on
  range-compressed profiles), `methods.backends.cpu_range` as it is (Q = 64 divided by sinc^2, points gathered in
  depth order) beside its earlier version (Q = 32 plain linear interpolation, the caller's order, chunks of 256
  points x 8 receivers), same frames interleaved: wall and CPU (process) time, the error
  of each table's values against the float64 direct sum at 256 random voxels, and for the first frame the share of
  pixels within -14 dB whose depth is within 0.1 mm of the same search on the per-frequency BLAS sum;
* `bp2` (CPU): BP d05 through `reconstruct_bp` with the CPU's default skips, wall and CPU time.
The CPU parts' rows carry the 1-minute load average. Writes OUT/perf_formation_<device>.csv (OUT = `--out`, default
outputs/perf/).
"""
from __future__ import annotations

import argparse
import dataclasses
import functools
import os
import time

import numpy as np

from bench.maroon.antennas import load_antenna_array
from bench.perf.common import DEFAULT_OUT, percentile, write_rows
from methods.bp import reconstruct_bp
from methods.domain.capture import RadarGrid
from methods.domain.radar import C_M_PER_S
from methods.ops.correlate import correlate_reference
from methods.skips import bp_search
from methods.skips import settings as skip_settings

ALL_FREQS_HZ = np.linspace(72e9, 82e9, 128)
D05_HZ = np.array([81.45e9, 82.0e9])
GRIDS = {"paper": (301, 201), "small": (31, 21)}
TERM_TOLS = (1e-3, 1e-4, 1e-5)
DEPTH_TOL_M = 1e-4
KEEP_DB = 14.0


def scene_frame(antennas, freqs_hz: np.ndarray, rng: np.random.Generator, n_points: int = 300) -> np.ndarray:
    """complex64 (94, 94, F): unit scatterers with random phases on a random curved surface near 0.3 m, plus
    -30 dB noise."""
    xy = rng.uniform(-0.12, 0.12, (n_points, 2))
    z = 0.3 + rng.uniform(0.3, 1.0) * (xy ** 2).sum(axis=1) + rng.uniform(-0.002, 0.002, n_points)
    pts = np.column_stack([xy, z])
    amp = np.exp(2j * np.pi * rng.uniform(size=n_points))
    d_rx = np.linalg.norm(pts[:, None] - antennas.rx_m[None], axis=2)
    d_tx = np.linalg.norm(pts[:, None] - antennas.tx_m[None], axis=2)
    k = 2 * np.pi * np.asarray(freqs_hz) / C_M_PER_S
    frame = np.stack([(amp[:, None] * np.exp(-1j * kf * d_rx)).T @ np.exp(-1j * kf * d_tx) for kf in k], axis=2)
    noise = rng.standard_normal(frame.shape) + 1j * rng.standard_normal(frame.shape)
    return (frame + 0.03 * np.abs(frame).mean() * noise).astype(np.complex64)


def timed_ms(fn, frames, sync) -> tuple[float, float]:
    """(median, p90) ms of fn(frame) over frames[1:] after an untimed fn(frames[0])."""
    fn(frames[0])
    sync()
    times = []
    for frame in frames[1:]:
        start = time.perf_counter()
        fn(frame)
        sync()
        times.append((time.perf_counter() - start) * 1e3)
    return percentile(times, 50), percentile(times, 90)


def columns_rows(backend, antennas, n_xy: int, n_z: int, n_frames: int, rng) -> list[dict]:
    """The `columns` part (module doc)."""
    import warp as wp

    from methods.backends.warp import columns

    x_m, y_m, z_m = np.linspace(-0.15, 0.15, n_xy), np.linspace(0.15, -0.15, n_xy), np.linspace(0.2, 0.4, n_z)
    dz_m = float(z_m[1] - z_m[0])
    frames = [scene_frame(antennas, D05_HZ, rng) for _ in range(n_frames + 1)]
    tx, rx = antennas.tx_m, antennas.rx_m

    def sync():
        wp.synchronize_device(backend.device)

    def peak(method, tol=None):
        def run(frame):
            backend.column_term_tol = tol or columns.TERM_TOL
            return backend.volume_peak(frame, D05_HZ, tx, rx, x_m, y_m, z_m, dz_m, method=method)
        return run

    rows = []
    variants = [("default", "auto", None)] + [("columns", "columns", tol) for tol in TERM_TOLS]
    for label, method, tol in variants:
        median, p90 = timed_ms(peak(method, tol), frames, sync)
        plan = columns.cached_plan(tx, D05_HZ, x_m, y_m, z_m, tol) if method == "columns" else None
        rows.append({"part": "columns", "impl": label if tol is None else f"columns@{tol:g}",
                     "kernel": backend._volume_kernel(D05_HZ, method), "term_tol": tol,
                     "rho_step_mm": None if plan is None else plan.rho_step_m * 1e3,
                     "n_rho": None if plan is None else plan.n_rho, "frame_median_ms": median, "frame_p90_ms": p90})
        print(rows[-1], flush=True)
    zz, yy, xx = np.meshgrid(z_m, y_m, x_m, indexing="ij")
    for i, frame in enumerate(frames[:2]):
        exact = backend.volume(frame, D05_HZ, tx, rx, x_m, y_m, z_m, kernel="separable").ravel()
        ref_depth, ref_proj = _peak_of(backend, exact, x_m, y_m, z_m, dz_m)
        kept = ref_proj >= ref_proj.max() * 10 ** (-KEEP_DB / 20)
        pick = rng.integers(0, exact.size, 256)
        ref64 = correlate_reference(frame, D05_HZ, tx, rx, np.column_stack([xx.ravel()[pick], yy.ravel()[pick],
                                                                            zz.ravel()[pick]]), sum_freqs=True)
        for row in rows:
            tol = row["term_tol"]
            backend.column_term_tol = tol or columns.TERM_TOL
            method = "columns" if tol is not None else "auto"
            vol = backend.volume(frame, D05_HZ, tx, rx, x_m, y_m, z_m, method=method).ravel()
            depth, _ = backend.volume_peak(frame, D05_HZ, tx, rx, x_m, y_m, z_m, dz_m, method=method)
            row[f"rel_l2_vs_fp32_f{i}"] = float(np.linalg.norm(vol - exact) / np.linalg.norm(exact))
            row[f"max_mag_diff_f{i}"] = float(np.max(np.abs(np.abs(vol) - np.abs(exact))) / np.abs(exact).max())
            row[f"rel_l2_vs_f64_256_f{i}"] = float(np.linalg.norm(vol[pick] - ref64) / np.linalg.norm(ref64))
            row[f"depth_within_0p1mm_pct_f{i}"] = 100.0 * float(np.mean(np.abs(depth[kept] - ref_depth[kept])
                                                                        <= DEPTH_TOL_M))
        print(f"fp32 separable vs float64 at 256 voxels, frame {i}: "
              f"{np.linalg.norm(exact[pick] - ref64) / np.linalg.norm(ref64):.2e}", flush=True)
    backend.column_term_tol = columns.TERM_TOL
    return rows


def _peak_of(backend, volume: np.ndarray, x_m, y_m, z_m, dz_m):
    """BP's (depth, max projection) of a host volume (z, y, x) flat, by the host's peak rule."""
    from methods.ops.depth_peak import peak_depth_m

    mag = np.abs(volume).reshape(len(z_m), len(y_m), len(x_m))
    return peak_depth_m(mag, float(z_m[0]), dz_m)


def search_rows(backend, antennas, n_xy: int, n_z: int, n_frames: int, rng) -> list[dict]:
    """The `search` part (module doc)."""
    import warp as wp

    grid = RadarGrid((-0.15, -0.15, 0.2), (0.15, 0.15, 0.4), (n_xy, n_xy, n_z))
    # the device search has the rules without the host's shortcuts (bp_search: local maxima, pixel lattice, local
    # depth windows; the coarse ROI's two passes): compare like with like
    skips = dataclasses.replace(skip_settings.default_for("bp", len(ALL_FREQS_HZ), backend.dense_beats_search),
                                search_local_max=False, search_lattice_step_m=0.0, search_local_z=False,
                                roi_prepass_margin_db=-1.0)
    frames = [scene_frame(antennas, ALL_FREQS_HZ, rng) for _ in range(n_frames + 1)]
    results: dict = {True: [], False: []}
    times: dict = {True: [], False: []}
    search_ms: dict = {True: [], False: []}
    spent = []

    def timing(fn):
        def run(*args, **kwargs):
            start = time.perf_counter()
            out = fn(*args, **kwargs)
            wp.synchronize_device(backend.device)
            spent.append((time.perf_counter() - start) * 1e3)
            return out
        return run
    default_on, device_search, host_search = backend.device_search, backend.search_depth, bp_search.search_depth
    backend.search_depth, bp_search.search_depth = timing(device_search), timing(host_search)
    try:
        for i, frame in enumerate(frames):
            for on in (True, False):
                backend.device_search = on
                spent.clear()
                start = time.perf_counter()
                rec = reconstruct_bp(frame, ALL_FREQS_HZ, antennas, grid, backend=backend, skips=skips)
                wp.synchronize_device(backend.device)
                if i > 0:
                    times[on].append((time.perf_counter() - start) * 1e3)
                    search_ms[on].append(sum(spent))
                results[on].append(rec)
    finally:
        backend.device_search = default_on
        del backend.search_depth
        bp_search.search_depth = host_search
    both = [np.isfinite(a.depth_m) & np.isfinite(b.depth_m) for a, b in zip(results[True], results[False],
                                                                            strict=True)]
    agree = [100.0 * float(np.mean(np.abs(a.depth_m[m] - b.depth_m[m]) <= DEPTH_TOL_M)) if m.any() else 100.0
             for a, b, m in zip(results[True], results[False], both, strict=True)]
    rows = []
    for on in (True, False):
        rows.append({"part": "search", "impl": "device search" if on else "host search",
                     "frame_median_ms": percentile(times[on], 50), "frame_p90_ms": percentile(times[on], 90),
                     "evaluated_median": float(np.median([r.extra.get("evaluated_voxels", 0) for r in results[on]])),
                     "valid_px_median": float(np.median([np.isfinite(r.depth_m).sum() for r in results[on]])),
                     "search_median_ms": percentile(search_ms[on], 50),
                     "agree_within_0p1mm_pct_min": min(agree)})
        for stage in results[on][-1].timings_ms:
            rows[-1][f"stage_{stage}_ms"] = float(np.median([r.timings_ms.get(stage, np.nan)
                                                             for r in results[on][1:]]))
        print(rows[-1], flush=True)
    return rows


def _timed_bp(frame, freqs_hz, antennas, grid, backend, skips) -> tuple:
    """(reconstruction, wall ms, CPU ms) of one `reconstruct_bp` call."""
    start, cpu = time.perf_counter(), time.process_time()
    rec = reconstruct_bp(frame, freqs_hz, antennas, grid, backend=backend, skips=skips)
    return rec, (time.perf_counter() - start) * 1e3, (time.process_time() - cpu) * 1e3


def _timing_row(part: str, impl: str, walls: list[float], cpus: list[float]) -> dict:
    return {"part": part, "impl": impl, "frame_median_ms": percentile(walls, 50), "frame_p90_ms": percentile(walls, 90),
            "cpu_median_ms": percentile(cpus, 50), "cpu_p90_ms": percentile(cpus, 90),
            "load_1min": os.getloadavg()[0]}


def range_rows(backend, antennas, n_xy: int, n_z: int, n_frames: int, rng) -> list[dict]:
    """The `range` part (module doc)."""
    from methods.backends import cpu_range

    grid = RadarGrid((-0.15, -0.15, 0.2), (0.15, 0.15, 0.4), (n_xy, n_xy, n_z))
    skips = skip_settings.default_for("bp", len(ALL_FREQS_HZ), backend.dense_beats_search)
    frames = [scene_frame(antennas, ALL_FREQS_HZ, rng) for _ in range(n_frames + 1)]
    new = {name: getattr(cpu_range, name) for name in ("range_table", "DEPTH_ORDER", "CHUNK_POINTS", "RX_BLOCK")}
    variants = {"Q64 / sinc^2, depth order (new)": new,
                "Q32 linear, search order (old)": dict(
                    range_table=functools.partial(new["range_table"], oversampling=32, deconvolve=False),
                    DEPTH_ORDER=False, CHUNK_POINTS=256, RX_BLOCK=8)}
    tables = {name: v["range_table"] for name, v in variants.items()}
    runs: dict = {name: {"wall": [], "cpu": [], "rec": []} for name in tables}
    try:
        for i, frame in enumerate(frames):
            for name, variant in variants.items():
                for attr, value in variant.items():
                    setattr(cpu_range, attr, value)
                rec, wall, cpu = _timed_bp(frame, ALL_FREQS_HZ, antennas, grid, backend, skips)
                if i > 0:
                    runs[name]["wall"].append(wall)
                    runs[name]["cpu"].append(cpu)
                runs[name]["rec"].append(rec)
    finally:
        for attr, value in new.items():
            setattr(cpu_range, attr, value)
    exact_skips = dataclasses.replace(skips, bp_range_cpu=False)
    exact = reconstruct_bp(frames[0], ALL_FREQS_HZ, antennas, grid, backend=backend, skips=exact_skips)
    zz, yy, xx = np.meshgrid(grid.z_m, grid.y_m, grid.x_m, indexing="ij")
    pick = rng.integers(0, xx.size, 256)
    points = np.column_stack([xx.ravel()[pick], yy.ravel()[pick], zz.ravel()[pick]])
    ref64 = [correlate_reference(f, ALL_FREQS_HZ, antennas.tx_m, antennas.rx_m, points, sum_freqs=True)
             for f in frames[:2]]
    rows = []
    for name, table in tables.items():
        row = _timing_row("range", name, runs[name]["wall"], runs[name]["cpu"])
        for i, ref in enumerate(ref64):
            got = cpu_range.correlate_range_cpu(
                table(frames[i], ALL_FREQS_HZ, *cpu_range.path_bounds_m(antennas.tx_m, antennas.rx_m, points)),
                antennas.tx_m, antennas.rx_m, points)
            row[f"rel_l2_vs_f64_256_f{i}"] = float(np.linalg.norm(got - ref) / np.linalg.norm(ref))
            row[f"max_mag_diff_f{i}"] = float(np.max(np.abs(np.abs(got) - np.abs(ref))) / np.abs(ref).max())
        rec = runs[name]["rec"][0]
        kept = np.isfinite(exact.depth_m) & (exact.magnitude >= np.nanmax(exact.magnitude) * 10 ** (-KEEP_DB / 20))
        row["depth_within_0p1mm_of_blas_pct_f0"] = 100.0 * float(np.mean(np.abs(rec.depth_m[kept] - exact.depth_m[kept])
                                                                        <= DEPTH_TOL_M))
        row["evaluated_median"] = float(np.median([r.extra.get("evaluated_voxels", 0) for r in runs[name]["rec"]]))
        rows.append(row)
        print(rows[-1], flush=True)
    return rows


def bp2_rows(backend, antennas, n_xy: int, n_z: int, n_frames: int, rng) -> list[dict]:
    """The `bp2` part (module doc)."""
    grid = RadarGrid((-0.15, -0.15, 0.2), (0.15, 0.15, 0.4), (n_xy, n_xy, n_z))
    skips = skip_settings.default_for("bp", len(D05_HZ), backend.dense_beats_search)
    walls, cpus = [], []
    for i, frame in enumerate(scene_frame(antennas, D05_HZ, rng) for _ in range(n_frames + 1)):
        _, wall, cpu = _timed_bp(frame, D05_HZ, antennas, grid, backend, skips)
        if i > 0:
            walls.append(wall)
            cpus.append(cpu)
    rows = [_timing_row("bp2", "BP d05, default skips", walls, cpus)]
    print(rows[-1], flush=True)
    return rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.perf formation", description=__doc__.split("\n")[0])
    parser.add_argument("--device", default="cuda", choices=["cuda", "warp-cpu", "cpu"])
    parser.add_argument("--grid", default="paper", choices=list(GRIDS))
    parser.add_argument("--frames", type=int, default=8)
    parser.add_argument("--parts", default=None, help="default: columns,search (Warp devices), range,bp2 (cpu)")
    parser.add_argument("--out", type=lambda s: __import__("pathlib").Path(s), default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    from methods.backends import backend_for

    backend = backend_for(args.device)
    antennas = load_antenna_array()
    rng = np.random.default_rng(2026)
    n_xy, n_z = GRIDS[args.grid]
    rows = []
    parts = (args.parts or ("range,bp2" if args.device == "cpu" else "columns,search")).split(",")
    print(f"uptime: load {os.getloadavg()}", flush=True)
    if "columns" in parts:
        rows += columns_rows(backend, antennas, n_xy, n_z, args.frames, rng)
    if "search" in parts:
        rows += search_rows(backend, antennas, n_xy, n_z, args.frames, rng)
    if "range" in parts:
        rows += range_rows(backend, antennas, n_xy, n_z, args.frames, rng)
    if "bp2" in parts:
        rows += bp2_rows(backend, antennas, n_xy, n_z, args.frames, rng)
    for row in rows:
        row.update(device=backend.name, grid=args.grid)
    write_rows(rows, args.out / f"perf_formation_{backend.name}.csv")
    return 0
