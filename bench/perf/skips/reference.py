"""Full-computation BP depth maps as float64 direct sums on a CUDA device (CuPy), the reference of
`python -m bench.perf skips` where the CPU takes too long for them (BP_max on the paper grid: ~20 min per
frame).

    python -m bench.perf skips-reference export --root DIR --out FRAMES.npz [--objects A/30 ...]   # here
    python -m bench.perf skips-reference compute FRAMES.npz --out BUNDLE.npz [--cells bp_d05 ...]  # on the GPU
    python -m bench.perf skips-reference split BUNDLE.npz --out DIR                                  # here

`export` writes each capture's radar frame, frequencies, antennas, metadata distance and mask_bb into one npz (no
dataset reader needed on the GPU machine, which has neither the data nor Open3D). `compute` forms, per depth plane
and frequency, the steering vectors a_r = exp(j k |p - rx_r|), b_t = exp(j k |p - tx_t|) in complex128, the pair
sum a^T S_f b / (n_rx n_tx) as one complex128 matrix product per plane, sums over frequencies, and extracts depth
and max projection exactly as `methods.bp.peak_depth_m` (argmax + parabola on dB), then the -14 dB filter
(`methods.ops.filtering`): the computation `roi=none` does on the CPU, in float64 (the CPU's float32 path agrees with
it to ~1e-5 relative, docs/measurements/gpu.md; measured: depth within 0.4 um on a small grid). `compute` writes one
bundle (the device machine returns few files); `split` turns it into `<object>_<distance>_<cell>_<grid>.npz` files with
`depth_m`, the folder `--reference` of `python -m bench.perf skips` reads.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from bench.progress import each
from methods.domain.radar import C_M_PER_S


def export_frames(root: Path, out: Path, objects: list[str] | None) -> None:
    """One npz with every capture's radar frame and what the reference needs (module doc)."""
    from bench.maroon import reader as maroon

    dirs = [root / o for o in objects] if objects else maroon.discover_captures(root)
    arrays, index = {}, []
    for i, capture_dir in enumerate(each(dirs, "captures", unit="capture")):
        capture = maroon.read_capture(capture_dir, parts=("radar",))
        arrays[f"signal_{i}"] = capture.radar.signal.astype(np.complex64)
        arrays[f"freqs_{i}"] = capture.radar.freqs_hz
        index.append({"object": capture.object_name, "distance": capture.distance_cm,
                      "distance_m": capture.metadata.distance_m, "mask_bb_m": capture.metadata.mask_bb_m})
        if i == 0:
            arrays["tx_m"], arrays["rx_m"] = capture.antennas.tx_m, capture.antennas.rx_m
    np.savez(out, index=json.dumps(index), **arrays)
    print(f"wrote {out} ({len(index)} captures)")


def volume_magnitude(xp, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m):
    """|V| (nz, ny*nx) float64 of the frequency-summed back-projection, y_m descending (row 0 = +y)."""
    sig = xp.asarray(signal, dtype=xp.complex128) / (len(rx_m) * len(tx_m))
    tx, rx = xp.asarray(tx_m), xp.asarray(rx_m)
    yy, xx = xp.meshgrid(xp.asarray(y_m), xp.asarray(x_m), indexing="ij")
    out = xp.empty((len(z_m), xx.size), dtype=xp.float64)
    for iz, z in enumerate(z_m):
        p = xp.stack([xx.ravel(), yy.ravel(), xp.full(xx.size, float(z))], axis=1)
        d_rx = xp.sqrt(((p[:, None, :] - rx[None]) ** 2).sum(-1))             # (N, R)
        d_tx = xp.sqrt(((p[:, None, :] - tx[None]) ** 2).sum(-1))             # (N, T)
        acc = xp.zeros(xx.size, dtype=xp.complex128)
        for f, freq in enumerate(freqs_hz):
            k = 2.0 * np.pi * float(freq) / C_M_PER_S
            acc += ((xp.exp(1j * k * d_rx) @ sig[:, :, f]) * xp.exp(1j * k * d_tx)).sum(axis=1)
        out[iz] = xp.abs(acc)
    return out


def peak_depth(xp, magnitude, z_first_m: float, dz_m: float):
    """`methods.bp.peak_depth_m` on any array module: (depth_m, max projection) of |V| profiles (K, N)."""
    n_z = magnitude.shape[0]
    k_best = xp.argmax(magnitude, axis=0)

    def pick(k):
        return xp.take_along_axis(magnitude, xp.clip(k, 0, n_z - 1)[None], axis=0)[0]

    tiny = np.finfo(np.float32).tiny
    db = [20.0 * xp.log10(xp.maximum(pick(k_best + s), tiny)) for s in (-1, 0, 1)]
    curvature = db[0] - 2.0 * db[1] + db[2]
    safe = xp.where(curvature < 0, curvature, -1.0)
    offset = xp.where(curvature < 0, 0.5 * (db[0] - db[2]) / safe, 0.0)
    return z_first_m + (k_best + offset) * dz_m, pick(k_best)


def write_references(frames: Path, bundle: Path, cells: list[str], grid_name: str, threshold_db: float) -> None:
    """Compute the reference depth maps of every BP cell of every capture in `frames` into one npz `bundle`."""
    import cupy as cp

    from bench.perf.skips.cpu import CELLS, GRIDS
    from methods.ops.filtering import filter_depth
    from methods.ops.frequencies import config_indices

    data = np.load(frames)
    index = json.loads(str(data["index"]))
    tx_m, rx_m = data["tx_m"], data["rx_m"]
    g = GRIDS[grid_name]
    maps = {}
    for i, info in enumerate(each(index, "captures", unit="capture")):
        signal, freqs_hz = data[f"signal_{i}"], data[f"freqs_{i}"]
        centre = info["distance_m"]
        x_m = np.linspace(-g["xy_half_m"], g["xy_half_m"], g["nxy"])
        z_m = np.linspace(centre - g["z_half_m"], centre + g["z_half_m"], g["nz"])
        for cell in cells:
            method, freq, _ = CELLS[cell]
            if method != "bp":
                continue
            idx = np.arange(len(freqs_hz)) if freq is None else config_indices(freqs_hz, freq)
            mag = volume_magnitude(cp, signal[:, :, idx], freqs_hz[idx], tx_m, rx_m, x_m, x_m[::-1], z_m)
            depth, peak = peak_depth(cp, mag, float(z_m[0]), float(z_m[1] - z_m[0]))
            depth_m = filter_depth(cp.asnumpy(depth).reshape(g["nxy"], g["nxy"]),
                                   cp.asnumpy(peak).reshape(g["nxy"], g["nxy"]), threshold_db)
            key = f"{info['object']}_{info['distance']}_{cell}_{grid_name}"
            maps[key] = depth_m
            print(f"{key}: {int(np.isfinite(depth_m).sum())} valid", flush=True)
    np.savez_compressed(bundle, **maps)


def split_bundle(bundle: Path, out_dir: Path) -> None:
    """One `<key>.npz` (depth_m) per map of a bundle."""
    out_dir.mkdir(parents=True, exist_ok=True)
    with np.load(bundle) as data:
        for key in data.files:
            np.savez_compressed(out_dir / f"{key}.npz", depth_m=data[key], source="cuda float64 direct sum (cupy)")
            print(out_dir / f"{key}.npz")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    ex = sub.add_parser("export")
    ex.add_argument("--root", required=True)
    ex.add_argument("--out", required=True)
    ex.add_argument("--objects", nargs="*", default=None)
    co = sub.add_parser("compute")
    co.add_argument("frames")
    co.add_argument("--out", required=True)
    co.add_argument("--cells", nargs="*", default=["bp_d05", "bp_d1", "bp_d10", "bp_full"])
    co.add_argument("--grid", default="paper")
    co.add_argument("--threshold-db", type=float, default=14.0)
    sp = sub.add_parser("split")
    sp.add_argument("bundle")
    sp.add_argument("--out", required=True)
    args = parser.parse_args(argv)
    if args.command == "export":
        export_frames(Path(args.root), Path(args.out), args.objects)
    elif args.command == "compute":
        write_references(Path(args.frames), Path(args.out), args.cells, args.grid, args.threshold_db)
    else:
        split_bundle(Path(args.bundle), Path(args.out))


if __name__ == "__main__":
    main()
