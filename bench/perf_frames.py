"""Whole-frame timings of each method through `methods.reconstruct`, at the paper's sizes.

`python -m bench.perf_frames [--device cpu|cuda] [--repeat N] [--bp-nz N] [--out DIR]` (also run by
`python -m bench.perf`). The frame is built in memory (no file I/O, no Open3D): a tilted plate 0.30-0.34 m seen by
a 640x480 depth camera whose every pixel is valid, so MM-2FSK's prior covers all 301x301 radar pixels (the worst
case of the CPU target <= 0.3 s).
BP runs on 301x301 pixels with `--bp-nz` depth samples (201 = the paper's grid; fewer on the CPU, scaled).
Medians of `--repeat` warm runs, with the per-stage times the methods report. Writes
OUT/perf_frames_<device>.csv, OUT being `--out` (default outputs/perf/; `--out results` for the committed figures).
"""
from __future__ import annotations

import csv
import statistics
from pathlib import Path

import numpy as np

from bench import cli
from bench.antennas import load_antenna_array
from bench.capture import CameraIntrinsics, Capture, DepthFrame, Metadata, RadarFrame, RadarGrid
from methods import reconstruct
from methods.correlate import C_M_PER_S

FREQS_HZ = np.linspace(72e9, 82e9, 128)
DEFAULT_OUT = Path("outputs/perf")      # the benchmarks' CSVs (bench.perf, .perf_frames, .perf_sweep); not tracked
CASES = (("mm2fsk", "d10", "realsense"), ("2fsk", "d05", "none"), ("3fsk", "d05_d10", "none"),
         ("bp", "d05", "none"), ("bp", "full", "none"))


def _plate_z_m(x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    return 0.32 + 0.1 * y_m


def _plate_signal(antennas, n_side: int = 21) -> np.ndarray:
    """Frame of point scatterers on the tilted plate, float64 phases, complex64 (94, 94, 128)."""
    axis = np.linspace(-0.06, 0.06, n_side)
    x_m, y_m = (a.ravel() for a in np.meshgrid(axis, axis))
    points_m = np.column_stack([x_m, y_m, _plate_z_m(x_m, y_m)])
    d_rx = np.linalg.norm(points_m[:, None, :] - antennas.rx_m[None], axis=2)        # (K, 94)
    d_tx = np.linalg.norm(points_m[:, None, :] - antennas.tx_m[None], axis=2)
    k = 2 * np.pi * FREQS_HZ / C_M_PER_S
    signal = np.empty((len(antennas.rx_m), len(antennas.tx_m), len(FREQS_HZ)), dtype=np.complex64)
    for f, kf in enumerate(k):
        signal[:, :, f] = np.exp(-1j * kf * d_rx).T @ np.exp(-1j * kf * d_tx)
    return signal


def _full_depth_frame() -> tuple[DepthFrame, np.ndarray]:
    """640x480 depth of the plate from a camera at the radar origin (y down), every pixel valid."""
    k = CameraIntrinsics(fx=615.0, fy=615.0, cx=320.0, cy=240.0, width=640, height=480)
    u, v = np.meshgrid(np.arange(k.width), np.arange(k.height))
    # camera y is down: a ray (u, v) hits z = 0.32 + 0.1 * y_radar with y_radar = -(v - cy) z / fy
    z_m = 0.32 / (1.0 + 0.1 * (v - k.cy) / k.fy)
    depth = DepthFrame(index=0, depth_mm=np.rint(z_m * 1000).astype(np.uint16), mask=np.ones(z_m.shape, bool),
                       intrinsics=k, depth_scale_m=0.001, path=Path("memory"))
    realsense2radar = np.diag([1e-3, -1e-3, 1e-3, 1.0])
    return depth, realsense2radar


def frame_capture() -> Capture:
    """An in-memory capture at the paper's sizes: 94x94x128 frame, 301x301x201 grid, 640x480 prior."""
    antennas = load_antenna_array()
    grid = RadarGrid((-0.15, -0.15, 0.22), (0.15, 0.15, 0.42), (301, 301, 201))
    radar = RadarFrame(index=0, signal=_plate_signal(antennas), freqs_hz=FREQS_HZ, timestamp_s=None, grid=grid,
                       path=Path("memory"))
    depth, realsense2radar = _full_depth_frame()
    metadata = Metadata(distance_m=0.32, mask_erosion=20, mask_bb_m={}, calibration=None, labels=(), raw={})
    return Capture(root=Path("memory"), object_name="tilted_plate", distance_cm=32, metadata=metadata,
                   transforms={"realsense2radar": realsense2radar}, antennas=antennas, radar_frames=[0],
                   radar=radar, realsense=depth)


def run_frames(device: str, repeat: int, bp_nz: int) -> list[dict]:
    capture = frame_capture()
    rows = []
    for method, freq, prior in CASES:
        grid = capture.radar.grid
        if method == "bp" and bp_nz < grid.size[2]:
            step = grid.size[2] // bp_nz
            z_m = grid.z_m[::step][:bp_nz]
            grid = RadarGrid((grid.bb_min_m[0], grid.bb_min_m[1], z_m[0]),
                             (grid.bb_max_m[0], grid.bb_max_m[1], z_m[-1]), (grid.size[0], grid.size[1], len(z_m)))
        scale = capture.radar.grid.size[2] / grid.size[2] if method == "bp" else 1.0
        runs = []                    # timings only: holding every result would time fresh host pages, not a frame
        for _ in range(repeat + 1):
            last = reconstruct(capture, method, freq, prior=prior, device=device, grid=grid)
            runs.append(last.timings_ms)
        stages = sorted({s for r in runs for s in r})
        row = {"method": method, "freq": freq, "prior": prior, "device": device,
               "pixels": grid.size[0] * grid.size[1], "nz": grid.size[2] if method == "bp" else 1,
               "scaled_to_nz": f"x{scale:.0f}" if scale > 1 else "",
               "valid_px": int(last.valid.sum())}
        row.update({f"{s}_ms": statistics.median(r.get(s, 0.0) for r in runs[1:]) * scale for s in stages})
        rows.append(row)
        detail = "  ".join(f"{s} {row[f'{s}_ms']:.1f}" for s in stages if s != "total")
        print(f"frame {method:6s} {freq:8s} {prior:9s} total {row['total_ms']:10.1f} ms {row['scaled_to_nz']:5s}"
              f" ({detail})", flush=True)
    return rows


def write_rows(rows: list[dict], path: Path, columns: list[str] | None = None, digits: int = 4) -> None:
    """Write benchmark rows as CSV, floats to `digits` significant digits."""
    columns = columns or list(dict.fromkeys(k for r in rows for k in r))
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        writer.writerows({k: (f"{v:.{digits}g}" if isinstance(v, float) else v) for k, v in r.items()} for r in rows)
    print(f"wrote {path}")


def main(argv=None) -> int:
    parser = cli.ArgumentParser(prog="python -m bench.perf_frames", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda", "auto"])
    parser.add_argument("--repeat", type=cli.positive_int, default=5)
    parser.add_argument("--bp-nz", type=cli.positive_int, default=None,
                        help="BP depth samples run (default: 201 on CUDA, 2 on CPU)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="folder for the CSV (default: outputs/perf; `--out results` for the committed figures)")
    args = parser.parse_args(argv)
    device = cli.resolve_device(args.device)
    out = cli.output_dir(args.out)
    bp_nz = args.bp_nz or (201 if device == "cuda" else 2)
    write_rows(run_frames(device, args.repeat, bp_nz), out / f"perf_frames_{device}.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
