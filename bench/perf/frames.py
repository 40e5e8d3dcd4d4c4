"""Whole-frame timings of each method through `methods.reconstruct`: what a user pays for a frame it has not seen.

`python -m bench.perf frames [--device cpu|cuda|warp-cpu] [--scene masked|plate] [--root DIR] [--repeat N]
[--bp-nz N] [--fill delaunay|scanline ...] [--out DIR]` (also run by `python -m bench.perf correlate`).

Scenes, built in memory (no file I/O, no Open3D), at the paper's sizes (94x94x128 frame, 301x301 pixels, a
640x480 depth camera):
* `masked` (default): three catalogue-like objects cycled, each masked and partly visible: a tilted disc, a
  notched tilted plate and two plates 9 cm apart in depth, each depth image with two holes and 0.2 % dropouts,
  so MM-2FSK's prior needs its hull fill on every frame, as on every catalogue capture;
* `plate`: the old figure, a tilted plate 0.30-0.34 m whose every depth pixel is valid (its prior covers all
  301x301 pixels and never needs the hull fill);
* `--root DIR`: the captures of a dataset root (e.g. data/synthetic; radar and RealSense parts, read once).
Every call gets new data (`new` columns): the radar samples rotated by a random phase and the depth image moved
by 1 mm (new arrays, so no cache can hit), as a camera delivers frames; the `repeated` columns time the same
frame object again, interleaved call by call with the new ones. Median and 90th percentile of `--repeat` calls
after one untimed warm-up per scene (compilation): `total` is the methods' own warm time (`timings_ms['total']`),
`wall` the whole `reconstruct` call; per-stage medians of the new frames. Cases with a sensor prior run once per
`--fill` (the prior's hole fill, methods.prior.priors; default: the default fill). BP runs on 301x301 pixels with
`--bp-nz` depth samples (201 = the paper's grid; fewer on the CPU, scaled to 201). Writes
OUT/perf_frames_<device>.csv, OUT being `--out` (default outputs/perf/; `--out results` for the committed figures).
"""
from __future__ import annotations

import dataclasses
import os
import statistics
import time
from pathlib import Path

import numpy as np

from bench import cli
from bench.maroon.antennas import load_antenna_array
from bench.perf.common import DEFAULT_OUT, add_device_option, percentile, write_rows
from bench.progress import each
from bench.synth.memory import CAMERA, make_capture
from methods import reconstruct
from methods.domain.capture import Capture, DepthFrame, RadarGrid
from methods.domain.radar import MAROON_FREQS_HZ
from methods.method import SENSOR_PRIORS
from methods.ops.correlate import C_M_PER_S
from methods.prior.priors import DEFAULT_FILL, FILLS

CASES = (("mm2fsk", "d10", "realsense"), ("mm3fsk", "d05_d10", "realsense"), ("2fsk", "d05", "none"),
         ("3fsk", "d05_d10", "none"), ("bp", "d05", "none"), ("bp", "full", "none"))
GRID = RadarGrid((-0.15, -0.15, 0.22), (0.15, 0.15, 0.42), (301, 301, 201))
REALSENSE2RADAR = np.diag([1e-3, -1e-3, 1e-3, 1.0])     # camera at the radar origin, y down, millimetres
SCATTERER_PITCH_M = 0.005


@dataclasses.dataclass(frozen=True)
class Piece:
    """A planar surface z = z0 + tilt_x x + tilt_y y (radar space, m) inside a footprint(x, y) -> bool."""

    z0_m: float
    tilt_x: float
    tilt_y: float
    footprint: object

    def z_m(self, x_m, y_m):
        return self.z0_m + self.tilt_x * x_m + self.tilt_y * y_m


def _inside(x_m, y_m, x0, x1, y0, y1):
    return (x_m >= x0) & (x_m <= x1) & (y_m >= y0) & (y_m <= y1)


MASKED_OBJECTS = {         # catalogue-like: masked, partly visible, each with its own outline
    "disc": (Piece(0.30, 0.15, 0.0, lambda x, y: (x - 0.01) ** 2 + y ** 2 <= 0.05 ** 2),),
    "notched_plate": (Piece(0.32, 0.0, 0.1, lambda x, y: _inside(x, y, -0.06, 0.06, -0.05, 0.05)
                            & ~_inside(x, y, 0.01, 0.07, 0.0, 0.06)),),
    "two_objects": (Piece(0.255, 0.0, 0.0, lambda x, y: _inside(x, y, -0.08, -0.01, -0.045, 0.045)),
                    Piece(0.345, 0.0, 0.0, lambda x, y: _inside(x, y, 0.015, 0.075, -0.045, 0.045))),
}


def _plate_z_m(x_m: np.ndarray, y_m: np.ndarray) -> np.ndarray:
    return 0.32 + 0.1 * y_m


def _signal(antennas, points_m: np.ndarray) -> np.ndarray:
    """Frame (94, 94, 128) complex64 of unit point scatterers at points_m (K, 3): float64 phasors, stepped from
    one frequency to the next by a complex multiply (the frequencies are equidistant), summed in complex64."""
    d_rx = np.linalg.norm(points_m[:, None, :] - antennas.rx_m[None], axis=2)        # (K, 94)
    d_tx = np.linalg.norm(points_m[:, None, :] - antennas.tx_m[None], axis=2)
    k = 2 * np.pi * MAROON_FREQS_HZ / C_M_PER_S
    dk = k[1] - k[0]
    signal = np.empty((len(antennas.rx_m), len(antennas.tx_m), len(MAROON_FREQS_HZ)), dtype=np.complex64)
    rx, tx = np.exp(-1j * k[0] * d_rx), np.exp(-1j * k[0] * d_tx)
    step_rx, step_tx = np.exp(-1j * dk * d_rx), np.exp(-1j * dk * d_tx)
    for f in range(len(k)):
        signal[:, :, f] = rx.T.astype(np.complex64) @ tx.astype(np.complex64)
        rx *= step_rx
        tx *= step_tx
    return signal


def _plate_signal(antennas, n_side: int = 21) -> np.ndarray:
    """Frame of point scatterers on the tilted plate, float64 phases, complex64 (94, 94, 128)."""
    axis = np.linspace(-0.06, 0.06, n_side)
    x_m, y_m = (a.ravel() for a in np.meshgrid(axis, axis))
    return _signal(antennas, np.column_stack([x_m, y_m, _plate_z_m(x_m, y_m)]))


def _full_depth_frame() -> tuple[DepthFrame, np.ndarray]:
    """640x480 depth of the plate from a camera at the radar origin (y down), every pixel valid."""
    k = CAMERA
    u, v = np.meshgrid(np.arange(k.width), np.arange(k.height))
    # camera y is down: a ray (u, v) hits z = 0.32 + 0.1 * y_radar with y_radar = -(v - cy) z / fy
    z_m = 0.32 / (1.0 + 0.1 * (v - k.cy) / k.fy)
    depth = DepthFrame(index=0, depth_mm=np.rint(z_m * 1000).astype(np.uint16), mask=np.ones(z_m.shape, bool),
                       intrinsics=k, depth_scale_m=0.001, path=Path("memory"))
    return depth, REALSENSE2RADAR


def _masked_depth_frame(pieces, rng: np.random.Generator) -> DepthFrame:
    """640x480 depth (mm) and mask of the nearest piece along each camera ray; two 8 mm holes per object and
    0.2 % dropouts, as a stereo camera leaves them (so the prior's hull fill has work on every frame)."""
    k = CAMERA
    u, v = np.meshgrid(np.arange(k.width, dtype=float), np.arange(k.height, dtype=float))
    ray_x, ray_y = (u - k.cx) / k.fx, -(v - k.cy) / k.fy          # radar-space x / z and y / z of each ray
    z_m = np.full(u.shape, np.inf)
    for piece in pieces:                                           # z = z0 + a x + b y on the ray (x, y) = z (rx, ry)
        hit = piece.z0_m / (1.0 - piece.tilt_x * ray_x - piece.tilt_y * ray_y)
        seen = piece.footprint(hit * ray_x, hit * ray_y) & (hit > 0) & (hit < z_m)
        z_m[seen] = hit[seen]
    mask = np.isfinite(z_m)
    depth_mm = np.where(mask, np.rint(np.where(mask, z_m, 0) * 1000), 0)
    rows, cols = np.nonzero(mask)
    for centre in rng.choice(len(rows), size=2, replace=False):   # holes inside the object (radius 8 mm)
        radius_px = 8.0 * k.fx / (1000 * z_m[rows[centre], cols[centre]])
        depth_mm[(v - rows[centre]) ** 2 + (u - cols[centre]) ** 2 <= radius_px ** 2] = 0
    depth_mm[rng.random(u.shape) < 0.002] = 0
    return DepthFrame(index=0, depth_mm=depth_mm.astype(np.uint16), mask=mask, intrinsics=k, depth_scale_m=0.001,
                      path=Path("memory"))


def _scatterers_m(pieces) -> np.ndarray:
    """Points on a 5 mm lattice over the visible part of the pieces (nearest to the array), radar space."""
    axis = np.arange(-0.15, 0.15 + 1e-9, SCATTERER_PITCH_M)
    x_m, y_m = (a.ravel() for a in np.meshgrid(axis, axis))
    z_m = np.full(x_m.shape, np.inf)
    for piece in pieces:
        z = piece.z_m(x_m, y_m)
        seen = piece.footprint(x_m, y_m) & (z < z_m)
        z_m[seen] = z[seen]
    keep = np.isfinite(z_m)
    return np.column_stack([x_m[keep], y_m[keep], z_m[keep]])


def _capture(name: str, signal: np.ndarray, depth: DepthFrame, grid: RadarGrid = GRID) -> Capture:
    return make_capture(signal, MAROON_FREQS_HZ, grid, realsense=depth, transforms={"realsense2radar": REALSENSE2RADAR},
                        name=name, distance_cm=32, mask_erosion=20)


def frame_capture() -> Capture:
    """The `plate` scene: a 94x94x128 frame, 301x301x201 grid, 640x480 prior whose every pixel is valid."""
    depth, _ = _full_depth_frame()
    return _capture("tilted_plate", _plate_signal(load_antenna_array()), depth)


def masked_captures(seed: int = 0) -> list[Capture]:
    """The `masked` scene: one in-memory capture per catalogue-like object (module doc)."""
    rng = np.random.default_rng(seed)
    antennas = load_antenna_array()
    return [_capture(name, _signal(antennas, _scatterers_m(pieces)), _masked_depth_frame(pieces, rng))
            for name, pieces in MASKED_OBJECTS.items()]


def root_captures(root: Path) -> list[Capture]:
    """Every capture of a dataset root, radar and RealSense parts (read once, before any timing)."""
    from bench.maroon.reader import discover_captures, read_capture

    return [read_capture(path, parts=("radar", "realsense")) for path in discover_captures(root)]


def new_frame(capture: Capture, rng: np.random.Generator) -> Capture:
    """The same scene as a new frame: radar samples rotated by a random phase, depth moved by +-1 mm (new arrays)."""
    radar = capture.radar
    phasor = np.complex64(np.exp(1j * rng.uniform(0, 2 * np.pi)))
    fresh = dataclasses.replace(capture, radar=dataclasses.replace(radar, signal=radar.signal * phasor))
    if capture.realsense is not None:
        depth = capture.realsense
        step = np.uint16(1)
        moved = np.where(depth.depth_mm > 0, depth.depth_mm + step if rng.random() < 0.5 else depth.depth_mm - step,
                         0).astype(np.uint16)
        fresh.realsense = dataclasses.replace(depth, depth_mm=moved,
                                              mask=None if depth.mask is None else depth.mask.copy())
    return fresh


def _bp_grid(grid: RadarGrid, bp_nz: int) -> RadarGrid:
    if bp_nz >= grid.size[2]:
        return grid
    z_m = grid.z_m[::grid.size[2] // bp_nz][:bp_nz]
    return RadarGrid((grid.bb_min_m[0], grid.bb_min_m[1], z_m[0]), (grid.bb_max_m[0], grid.bb_max_m[1], z_m[-1]),
                     (grid.size[0], grid.size[1], len(z_m)))


def time_case(captures: list[Capture], method: str, freq: str, prior: str, device: str, repeat: int, bp_nz: int,
              seed: int = 0, fill: str = DEFAULT_FILL) -> dict:
    """Median / p90 of `repeat` new-frame and repeated-frame calls (interleaved), captures cycled; stage medians.
    `fill`: the sensor prior's hole fill."""
    rng = np.random.default_rng(seed)
    options = {"fill": fill} if prior in SENSOR_PRIORS else {}
    grids = [_bp_grid(c.radar.grid, bp_nz) if method == "bp" else c.radar.grid for c in captures]
    scale = captures[0].radar.grid.size[2] / grids[0].size[2] if method == "bp" else 1.0
    # warm-up: compilation, first-touch pages
    for capture, grid in zip(captures, grids, strict=False):
        reconstruct(capture, method, freq, prior=prior, device=device, grid=grid, prior_options=options)
    runs = {"new": [], "repeated": []}
    valid = []
    for i in range(repeat):
        j = i % len(captures)
        for mode in ("new", "repeated"):
            capture = new_frame(captures[j], rng) if mode == "new" else captures[j]
            start = time.perf_counter()
            result = reconstruct(capture, method, freq, prior=prior, device=device, grid=grids[j],
                                 prior_options=options)
            wall_ms = (time.perf_counter() - start) * 1e3
            runs[mode].append({**result.timings_ms, "wall": wall_ms})
            if mode == "new":
                valid.append(int(result.valid.sum()))
            del result, capture                 # holding results would time fresh host pages, not a frame
    row = {"method": method, "freq": freq, "prior": prior, "fill": options.get("fill", ""), "device": device,
           "scene": "+".join(dict.fromkeys(c.object_name for c in captures)), "calls": repeat,
           "pixels": grids[0].size[0] * grids[0].size[1], "nz": grids[0].size[2] if method == "bp" else 1,
           "scaled_to_nz": f"x{scale:.0f}" if scale > 1 else "", "valid_px": int(statistics.median(valid))}
    for mode in ("new", "repeated"):
        for what in ("total", "wall"):
            values = [r[what] * scale for r in runs[mode]]
            row[f"{mode}_{what}_median_ms"] = statistics.median(values)
            row[f"{mode}_{what}_p90_ms"] = percentile(values, 90)
    stages = sorted({s for r in runs["new"] for s in r} - {"total", "wall"})
    row.update({f"new_{s}_ms": statistics.median(r.get(s, 0.0) for r in runs["new"]) * scale for s in stages})
    row["load_1min"] = os.getloadavg()[0]
    detail = "  ".join(f"{s} {row[f'new_{s}_ms']:.1f}" for s in stages)
    print(f"frame {method:6s} {freq:8s} {prior:9s} {row['fill']:8s} new {row['new_total_median_ms']:9.1f} ms (p90 "
          f"{row['new_total_p90_ms']:9.1f})  repeated {row['repeated_total_median_ms']:9.1f} ms "
          f"{row['scaled_to_nz']:5s} ({detail})  load {row['load_1min']:.1f}", flush=True)
    return row


def scene_captures(scene: str, root: Path | None = None) -> list[Capture]:
    """The captures a scene cycles through (module doc)."""
    if root is not None:
        return root_captures(root)
    return masked_captures() if scene == "masked" else [frame_capture()]


def run_frames(device: str, repeat: int, bp_nz: int, scene: str = "masked", root: Path | None = None,
               cases=CASES, fills=(DEFAULT_FILL,)) -> list[dict]:
    """One row per case (method, freq, prior) and, with a sensor prior, per fill of new-frame and repeated-frame
    timings on `scene`'s captures."""
    captures = scene_captures(scene, root)
    todo = [(*case, fill) for case in cases for fill in (fills if case[2] in SENSOR_PRIORS else fills[:1])]
    return [time_case(captures, method, freq, prior, device, repeat, bp_nz, fill=fill)
            for method, freq, prior, fill in each(todo, "frame cases", unit="case")]


def _case(text: str) -> tuple[str, str, str]:
    parts = text.split(":")
    if len(parts) != 3:
        raise cli.UserError(f"--cases {text}", "a case is METHOD:FREQ:PRIOR, e.g. mm2fsk:d10:realsense")
    return tuple(parts)


def main(argv=None) -> int:
    parser = cli.ArgumentParser(prog="python -m bench.perf frames", description=__doc__.splitlines()[0])
    add_device_option(parser)
    parser.add_argument("--scene", default="masked", choices=["masked", "plate"],
                        help="in-memory frames (module doc): catalogue-like masked objects, or the full plate")
    parser.add_argument("--root", type=Path, default=None,
                        help="time the captures of this dataset root instead (e.g. data/synthetic)")
    parser.add_argument("--cases", nargs="+", default=None, metavar="METHOD:FREQ:PRIOR",
                        help="default: " + " ".join(":".join(c) for c in CASES))
    parser.add_argument("--repeat", type=cli.positive_int, default=9)
    parser.add_argument("--bp-nz", type=cli.positive_int, default=None,
                        help="BP depth samples run (default: 201 on CUDA, 2 on CPU)")
    parser.add_argument("--fill", nargs="+", default=[DEFAULT_FILL], choices=list(FILLS),
                        help="the sensor prior's hole fill(s) (default: %(default)s)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="folder for the CSV (default: outputs/perf; `--out results` for the committed figures)")
    args = parser.parse_args(argv)
    device = cli.resolve_device(args.device)
    out = cli.output_dir(args.out)
    bp_nz = args.bp_nz or (201 if device == "cuda" else 2)
    root = None if args.root is None else cli.existing_path(args.root, "dir", "--root")
    cases = CASES if args.cases is None else [_case(text) for text in args.cases]
    write_rows(run_frames(device, args.repeat, bp_nz, args.scene, root, cases, tuple(args.fill)),
               out / f"perf_frames_{device}.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
