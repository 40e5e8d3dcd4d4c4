"""Correlation benchmarks: `python -m bench.perf correlate [--device cpu|cuda] [--sizes paper|small] [--repeat N]
[--cpu-z N]
[--out DIR] [--no-frames]`;

Cases (paper sizes): MM-2FSK/2FSK (301x301 points on a curved surface, 2 frequencies), 3FSK (3 frequencies),
BP (301x301x201 voxels, 2 frequencies) and BP_max (128 frequencies). Each case is timed warm (one untimed run
first, so compilation is excluded), median of `--repeat` runs, beside a plain direct sum of ours timed in the same
run: on CUDA the plain Warp kernel (one sincos per antenna pair and frequency), on the CPU a plain numpy direct sum
over a subset of points, extrapolated per point. Volume cases on the CPU (and BP_max's plain kernel on CUDA) run on
`--cpu-z` z-planes and are scaled to all 201 planes; the printout marks scaled figures. On CUDA, median_ms is
the API call (uploads and the copy back included; the frame's inputs are cached on the device by content, so
repeated calls on one frame upload only the points) and kernel_ms the device time alone (inputs resident, output
left on the device), which is what the speedup over the plain kernel compares; the CUDA points and BP cases run
the tensor-core kernel ("tc"), and separable_kernel_ms times the fp32 separable kernel beside it. Accuracy is the
relative
error against the float64 reference on 64 random points of the case. Writes OUT/perf_<device>.csv, then the
whole-frame timings of every method (bench.perf.frames) to OUT/perf_frames_<device>.csv; OUT is `--out`, by
default outputs/perf/ (`--out results` refreshes the committed figures).
"""
from __future__ import annotations

import functools
import statistics
import time
from pathlib import Path

import numpy as np

from bench import cli
from bench.maroon.antennas import load_antenna_array
from bench.perf.common import DEFAULT_OUT, write_rows
from bench.perf.frames import run_frames
from bench.progress import each
from methods.backends import correlate, correlate_volume
from methods.domain.radar import MAROON_FREQS_HZ
from methods.ops.correlate import C_M_PER_S, correlate_reference

SIZES = {"paper": (301, 201), "small": (61, 21)}
CSV_COLUMNS = ["case", "device", "impl", "n_points", "n_freqs", "median_ms", "kernel_ms", "scaled", "direct_impl",
               "direct_ms", "speedup", "rel_err_vs_f64", "separable_kernel_ms"]


def median_ms(fn, repeat: int, sync=lambda: None) -> float:
    """Median wall time of `fn()` in ms after one warm-up call."""
    fn()
    sync()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        sync()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times)


def numpy_direct(signal, freqs_hz, tx_m, rx_m, points_m) -> np.ndarray:
    """Plain numpy direct sum (float32 phases, one cos/sin per pair and frequency), one point at a time."""
    sig = signal.astype(np.complex64) / (len(rx_m) * len(tx_m))
    k = (2 * np.pi * freqs_hz / C_M_PER_S).astype(np.float32)
    out = np.empty((len(freqs_hz), len(points_m)), dtype=np.complex64)
    for n, p in enumerate(points_m.astype(np.float32)):
        path = np.linalg.norm(p - rx_m.astype(np.float32), axis=1)[:, None] + \
            np.linalg.norm(p - tx_m.astype(np.float32), axis=1)[None, :]
        phase = path[:, :, None] * k
        out[:, n] = np.einsum("rtf,rtf->f", sig, np.cos(phase) + 1j * np.sin(phase))
    return out


def surface_points(n_xy: int) -> np.ndarray:
    """(n_xy^2, 3) points on a curved surface around z = 0.4 m, as a depth prior gives them."""
    x_m = np.linspace(-0.15, 0.15, n_xy)
    xx, yy = np.meshgrid(x_m, x_m[::-1])
    zz = 0.4 + 0.05 * np.sin(12 * xx) * np.cos(9 * yy)
    return np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])


def grid(n_xy: int, n_z: int):
    return np.linspace(-0.15, 0.15, n_xy), np.linspace(0.15, -0.15, n_xy), np.linspace(0.2, 0.6, n_z)


def accuracy(signal, freqs_hz, ant, points_m, values, rng) -> float:
    pick = rng.choice(len(points_m), size=min(64, len(points_m)), replace=False)
    ref = correlate_reference(signal, freqs_hz, ant.tx_m, ant.rx_m, points_m[pick], sum_freqs=values.ndim == 1)
    got = values[..., pick]
    return float(np.linalg.norm(got - ref) / np.linalg.norm(ref))


def run_cases(device: str, sizes: str, repeat: int, cpu_z: int) -> list[dict]:
    rng = np.random.default_rng(0)
    ant = load_antenna_array()
    n_xy, n_z = SIZES[sizes]
    rows = []
    cases = [("mm2fsk_2fsk", [120, 127], "points"), ("3fsk", [0, 64, 127], "points"),
             ("bp", [120, 127], "volume"), ("bp_max", list(range(128)), "volume")]
    for name, idx, kind in each(cases, "correlation cases", unit="case"):
        freqs_hz = MAROON_FREQS_HZ[idx]
        signal = rng.standard_normal((94, 94, len(idx))) + 1j * rng.standard_normal((94, 94, len(idx)))
        row = {"case": name, "device": device, "n_freqs": len(idx)}
        if kind == "points":
            points_m = surface_points(n_xy)
            fast = functools.partial(correlate, signal, freqs_hz, ant.tx_m, ant.rx_m, points_m, device=device)
            row.update(impl="tc" if device == "cuda" else "separable", n_points=len(points_m),
                       median_ms=median_ms(fast, repeat), scaled="")
            row["rel_err_vs_f64"] = accuracy(signal, freqs_hz, ant, points_m, fast(), rng)
            row["kernel_ms"] = kernel_ms(device, signal, freqs_hz, ant, row["impl"], repeat, points_m=points_m)
            row["separable_kernel_ms"] = kernel_ms(device, signal, freqs_hz, ant, "separable", repeat,
                                                   points_m=points_m)
            row.update(direct_of_points(device, signal, freqs_hz, ant, points_m, repeat))
        else:
            x_m, y_m, z_m = grid(n_xy, n_z)
            z_run = z_m if device == "cuda" else z_m[:: max(1, len(z_m) // cpu_z)][:cpu_z]
            scale = len(z_m) / len(z_run)
            vol = functools.partial(correlate_volume, signal, freqs_hz, ant.tx_m, ant.rx_m, x_m, y_m, z_run,
                                    device=device)
            impl = "range" if (device != "cpu" and len(idx) >= 16) else ("tc" if device == "cuda" else "separable")
            row.update(impl=impl, n_points=len(x_m) * len(y_m) * len(z_m),
                       median_ms=median_ms(vol, repeat) * scale, scaled=f"x{scale:.0f}" if scale > 1 else "")
            zz, yy, xx = np.meshgrid(z_run, y_m, x_m, indexing="ij")
            points_m = np.column_stack([xx.ravel(), yy.ravel(), zz.ravel()])
            row["rel_err_vs_f64"] = accuracy(signal, freqs_hz, ant, points_m, vol().ravel(), rng)
            row["kernel_ms"] = kernel_ms(device, signal, freqs_hz, ant, impl, repeat, grid_m=(x_m, y_m, z_run))
            row["kernel_ms"] = row["kernel_ms"] * scale if row["kernel_ms"] else ""
            if impl == "tc":
                row["separable_kernel_ms"] = kernel_ms(device, signal, freqs_hz, ant, "separable", repeat,
                                                       grid_m=(x_m, y_m, z_run))
            row.update(direct_of_volume(device, signal, freqs_hz, ant, x_m, y_m, z_m, repeat))
        row["speedup"] = row["direct_ms"] / (row["kernel_ms"] or row["median_ms"])
        rows.append(row)
        kernel = f"kernel {row['kernel_ms']:9.3f} ms" if row["kernel_ms"] else ""
        print(f"{name:12s} {row['impl']:9s} API {row['median_ms']:10.2f} ms {kernel} {row['scaled']:5s} "
              f"direct {row['direct_ms']:11.2f} ms ({row['direct_impl']})  x{row['speedup']:.1f}  "
              f"rel_err {row['rel_err_vs_f64']:.1e}", flush=True)
    return rows


def kernel_ms(device, signal, freqs_hz, ant, impl, repeat, points_m=None, grid_m=None):
    """CUDA only: device time of our kernel(s) with inputs already uploaded and output left on the device."""
    if device != "cuda":
        return ""
    import warp as wp

    from methods.backends import backend_for
    run = backend_for(device).make_launch(signal, freqs_hz, ant.tx_m, ant.rx_m, kernel=impl, points_m=points_m,
                                          grid_m=grid_m)
    first = median_ms(run, 1, sync=wp.synchronize)
    batch = 1 if first > 5.0 else 20          # short kernels: launches queued back to back, one sync per batch

    def many():
        for _ in range(batch):
            run()
    return median_ms(many, repeat, sync=wp.synchronize) / batch


def direct_of_points(device, signal, freqs_hz, ant, points_m, repeat) -> dict:
    if device == "cuda":
        return {"direct_impl": "warp plain kernel",
                "direct_ms": kernel_ms(device, signal, freqs_hz, ant, "direct", repeat, points_m=points_m)}
    subset = points_m[:: max(1, len(points_m) // 200)]
    ms = median_ms(lambda: numpy_direct(signal, freqs_hz, ant.tx_m, ant.rx_m, subset), 1)
    return {"direct_impl": f"numpy plain, {len(subset)} points extrapolated",
            "direct_ms": ms * len(points_m) / len(subset)}


def direct_of_volume(device, signal, freqs_hz, ant, x_m, y_m, z_m, repeat) -> dict:
    if device == "cuda":
        z_run = z_m if len(freqs_hz) <= 3 else z_m[len(z_m) // 2: len(z_m) // 2 + 1]
        scale = len(z_m) / len(z_run)
        label = "warp plain kernel" + (f", {len(z_run)} z-plane x{scale:.0f}" if scale > 1 else "")
        ms = kernel_ms(device, signal, freqs_hz, ant, "direct", 1 if scale > 1 else repeat, grid_m=(x_m, y_m, z_run))
        return {"direct_impl": label, "direct_ms": ms * scale}
    n_points = len(x_m) * len(y_m) * len(z_m)
    subset = surface_points(len(x_m))[:: max(1, len(x_m) ** 2 // (200 if len(freqs_hz) <= 3 else 20))]
    ms = median_ms(lambda: numpy_direct(signal, freqs_hz, ant.tx_m, ant.rx_m, subset), 1)
    return {"direct_impl": f"numpy plain, {len(subset)} points extrapolated", "direct_ms": ms * n_points / len(subset)}


def main(argv=None) -> int:
    parser = cli.ArgumentParser(prog="python -m bench.perf correlate", description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cpu", choices=["cpu", "cuda", "auto"])
    parser.add_argument("--sizes", default="paper", choices=sorted(SIZES))
    parser.add_argument("--repeat", type=cli.positive_int, default=5)
    parser.add_argument("--cpu-z", type=cli.positive_int, default=2,
                        help="z-planes run for CPU volume cases (scaled to all)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="folder for the CSVs (default: outputs/perf; `--out results` for the committed figures)")
    parser.add_argument("--no-frames", action="store_true", help="skip the whole-frame timings (bench.perf.frames)")
    args = parser.parse_args(argv)
    device = cli.resolve_device(args.device)
    out = cli.output_dir(args.out)
    rows = run_cases(device, args.sizes, args.repeat, args.cpu_z)
    write_rows(rows, out / f"perf_{device}.csv", columns=CSV_COLUMNS, digits=6)
    if not args.no_frames:
        bp_nz = 201 if device == "cuda" else args.cpu_z
        write_rows(run_frames(device, args.repeat, bp_nz), out / f"perf_frames_{device}.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
