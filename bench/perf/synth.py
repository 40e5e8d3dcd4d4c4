"""Synthetic capture generation, by stage, with the radar echo from frequency nodes and computed at every frequency.

`python -m bench.perf synth [--objects NAME ...] [--distance CM] [--preset realistic|ideal] [--paths nodes direct]
[--device cpu|cuda] [--out DIR]` builds each capture (`bench.synth.parts.build_capture`, into a temporary
folder, no cache) once per path: `nodes` is the generator as it is (each block of scatterers at a few node
frequencies, interpolated: bench.synth.radar.frequency_nodes), `direct` computes every frequency (what generator
version 7 did, per-frequency products); `--device` is where the radar sums run (as `python -m bench.synth
--device`), on either path. Stages are timed where the generator calls them, wall and process CPU seconds (all
threads): the surface samples (ray casting), the radar echo (`simulate_frame`, multipath, wall), the depth camera,
the ground-truth mesh, writing files; `other` is the rest (scene, noise, sums). With both paths, each capture's radar
frames are compared (same seeds, so the same noise): the largest difference over the peak, and the rms difference
against the thermal noise of the frames in dB. Writes OUT/perf_synth.csv (OUT: `--out`, default outputs/perf).

`--workers N [N ...]` times instead what a user waits for: `generate_catalogue` of the objects at the distance into
a fresh root, building N capture parts at once (default: as many as the generator builds, `capture_workers()`), in
worker processes or threads (`--builders`; default as the generator chooses: bench.synth.workers), wall and CPU
seconds of this process (not its worker processes): OUT/perf_synth_catalogue.csv.
"""
from __future__ import annotations

import argparse
import collections
import contextlib
import tempfile
import time
from pathlib import Path

import numpy as np

from bench import cli
from bench.perf.common import DEFAULT_OUT, write_rows
from bench.progress import each

STAGES = ("samples", "radar_echo", "camera", "ground_truth", "write")
PATHS = ("nodes", "direct")


@contextlib.contextmanager
def timed_stages(spent: dict):
    """Wrap the functions the generator calls with timers adding [wall, cpu] seconds to `spent[stage]`."""
    from bench.synth import writer
    from bench.synth.camera import depth as depth_camera
    from bench.synth.camera import photogrammetry
    from bench.synth.radar import multipath
    from bench.synth.radar import scene as radar_scene

    targets = [(radar_scene, "visible_samples", "samples"), (radar_scene, "back_wall_samples", "samples"),
               (radar_scene, "simulate_frame", "radar_echo"), (multipath, "simulate_pairs", "radar_echo"),
               (multipath, "bounce_pairs", "samples"), (radar_scene, "wall_frame", "radar_echo"),
               (radar_scene, "clutter_frame", "radar_echo"), (depth_camera, "render", "camera"),
               (photogrammetry, "smoothed_mesh", "ground_truth")]
    targets += [(writer, name, "write") for name in dir(writer) if name.startswith("write_")]
    originals = [(owner, name, getattr(owner, name)) for owner, name, _ in targets]

    def wrap(function, stage):
        def timed(*args, **kwargs):
            wall, cpu = time.perf_counter(), time.process_time()
            try:
                return function(*args, **kwargs)
            finally:
                spent[stage][0] += time.perf_counter() - wall
                spent[stage][1] += time.process_time() - cpu
        return timed

    for (owner, name, stage), (_, _, function) in zip(targets, originals, strict=True):
        setattr(owner, name, wrap(function, stage))
    try:
        yield
    finally:
        for owner, name, function in originals:
            setattr(owner, name, function)


@contextlib.contextmanager
def radar_path(path: str):
    """`nodes`: the generator as configured; `direct`: every frequency computed (no node interpolation)."""
    from bench.synth.radar import frequency_nodes

    share = frequency_nodes.MAX_NODE_SHARE
    frequency_nodes.MAX_NODE_SHARE = share if path == "nodes" else 0.0
    try:
        yield
    finally:
        frequency_nodes.MAX_NODE_SHARE = share


def build(object_name: str, distance_cm: int, config, path: str, work: Path, device: str = "cpu") -> dict:
    """Build one capture on `path` into `work`; its row: wall and CPU seconds in all and per stage."""
    from bench.synth.parts import build_capture

    spent = collections.defaultdict(lambda: [0.0, 0.0])
    target = work / path / object_name
    with radar_path(path), timed_stages(spent):
        wall, cpu = time.perf_counter(), time.process_time()
        build_capture(target, object_name, distance_cm, config, device)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    row = {"path": path, "device": device, "capture": f"{object_name}/{distance_cm}", "wall_s": wall, "cpu_s": cpu}
    for stage in STAGES:
        row[f"{stage}_wall_s"], row[f"{stage}_cpu_s"] = spent[stage]
    row["other_s"] = wall - sum(spent[s][0] for s in STAGES)
    return row


def frame_difference(nodes_dir: Path, direct_dir: Path, config) -> dict:
    """Largest |nodes - direct| over the peak |direct|, and rms(nodes - direct) over the frames' thermal noise
    (dB), over every radar frame file of one capture."""
    from bench.synth.radar.model import thermal_noise_sigma

    worst, squares, count, peak = 0.0, 0.0, 0, 0.0
    for direct_file in sorted(direct_dir.rglob("calibrated_data/*.npy")):
        a = np.load(nodes_dir / direct_file.relative_to(direct_dir), allow_pickle=True).item()["xr"]
        b = np.load(direct_file, allow_pickle=True).item()["xr"]      # our own files, just written
        worst, peak = max(worst, float(np.abs(a - b).max())), max(peak, float(np.abs(b).max()))
        squares, count = squares + float(np.sum(np.abs(a - b) ** 2)), count + a.size
    noise = (np.sqrt(2.0) * thermal_noise_sigma(config) * config.amplitude_scale if config.noise_model == "datasheet"
             else float("nan"))
    rms = np.sqrt(squares / max(count, 1))
    return {"max_diff_over_peak": worst / peak if peak else float("nan"),
            "rms_diff_over_noise_db": 20.0 * np.log10(rms / noise) if rms > 0 and noise > 0 else float("nan")}


def catalogue(objects: list[str], distance_cm: int, config, workers: int, work: Path, device: str = "cpu",
              builders: str = "default") -> dict:
    """Wall and CPU seconds of generate_catalogue into a fresh root, `workers` capture parts at once, in worker
    processes or threads (`builders`; "default": as the generator chooses, bench.synth.workers)."""
    from bench.synth import generate
    from bench.synth import workers as pool

    defaults = pool.capture_workers, pool.capture_processes
    pool.capture_workers = lambda: workers
    if builders != "default":
        pool.capture_processes = lambda: builders == "processes"
    used = "processes" if pool.capture_processes() else "threads"
    try:
        wall, cpu = time.perf_counter(), time.process_time()
        generate.generate_catalogue(Path(tempfile.mkdtemp(prefix=f"workers{workers}-", dir=work)), [distance_cm],
                                    objects, config, device=device)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    finally:
        pool.capture_workers, pool.capture_processes = defaults
    print(f"generate_catalogue ({device}, {used}): {len(objects)} captures, {workers} parts at once: {wall:.1f} s "
          f"wall, {cpu:.1f} s CPU in this process")
    return {"device": device, "builders": used, "captures": len(objects), "workers": workers, "wall_s": wall,
            "cpu_s": cpu}


def _print(rows: list[dict]) -> None:
    """Per capture its wall seconds and, below them, its process CPU seconds (all threads), in all and per stage."""
    stages = ["", *(f"{s}_" for s in STAGES)]
    print(f"{'path':7s} {'capture':22s} {'':4s} " + " ".join(f"{(s or 'all_')[:-1]:>12s}" for s in stages)
          + f" {'other':>12s}   (seconds)")
    for row in rows:
        extra = (f"  diff/peak {row['max_diff_over_peak']:.1e}, rms diff/noise {row['rms_diff_over_noise_db']:.0f} dB"
                 if "max_diff_over_peak" in row else "")
        wall = " ".join(f"{row[f'{s}wall_s']:12.2f}" for s in stages) + f" {row['other_s']:12.2f}"
        cpu = " ".join(f"{row[f'{s}cpu_s']:12.2f}" for s in stages)
        print(f"{row['path']:7s} {row['capture']:22s} wall {wall}{extra}")
        print(f"{'':7s} {'':22s} cpu  {cpu}")


def main(argv: list[str] | None = None) -> int:
    from bench.synth.config import PRESETS, preset
    from bench.synth.scenes import CATALOGUE

    parser = cli.ArgumentParser(prog="python -m bench.perf synth", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--objects", nargs="+", default=list(CATALOGUE), help="catalogue objects (default: all)")
    parser.add_argument("--distance", type=int, default=30, help="centimetres (default: %(default)s)")
    parser.add_argument("--preset", choices=list(PRESETS), default="realistic")
    parser.add_argument("--paths", nargs="+", choices=PATHS, default=list(PATHS), help="radar paths to time")
    parser.add_argument("--workers", type=cli.positive_int, nargs="*", default=None,
                        help="time generate_catalogue building this many captures at once (none given: the default)")
    parser.add_argument("--builders", choices=["default", "processes", "threads"], default="default",
                        help="with --workers: build in worker processes or threads (default: as the generator does)")
    parser.add_argument("--device", default="cpu", help="where the radar sums run: cpu (NumPy) or cuda (Warp)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="folder for the CSV")
    args = parser.parse_args(argv)
    device = cli.resolve_device(args.device)
    unknown = [o for o in args.objects if o not in CATALOGUE]
    if unknown:
        parser.error(f"unknown object(s) {', '.join(unknown)}; known: {', '.join(CATALOGUE)}")
    config = preset(args.preset)
    import open3d  # noqa: F401  - imported before timing (the generator's ray casting imports it on first use)

    if args.workers is not None:
        from bench.synth.workers import capture_workers

        with tempfile.TemporaryDirectory(prefix="perf-synth-") as tmp:
            rows = [catalogue(args.objects, args.distance, config, n, Path(tmp), device, args.builders)
                    for n in args.workers or [capture_workers()]]
        write_rows(rows, args.out / "perf_synth_catalogue.csv")
        return 0
    rows = []
    with tempfile.TemporaryDirectory(prefix="perf-synth-") as tmp:
        work = Path(tmp)
        for path in args.paths:
            captures = [build(o, args.distance, config, path, work, device)
                        for o in each(args.objects, path, unit="capture")]
            total = {"path": path, "device": device, "capture": f"total ({len(captures)})"}
            total.update({k: sum(r[k] for r in captures) for k in captures[0] if k.endswith("_s")})
            rows += captures + [total]
        if set(PATHS) <= set(args.paths):
            for row in rows:
                if row["path"] == "nodes" and not row["capture"].startswith("total"):
                    name = row["capture"].split("/")[0]
                    row.update(frame_difference(work / "nodes" / name, work / "direct" / name, config))
    _print(rows)
    write_rows(rows, args.out / "perf_synth.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
