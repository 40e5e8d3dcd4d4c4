"""Streaming: frames per second through read, method and metrics over a capture's frame sequence.

`python -m bench.perf stream [--root DIR --capture OBJECT/DISTANCE] [--device cpu|cuda|warp-cpu]
[--method mm2fsk --freq d10 --prior realsense] [--passes N] [--no-metrics] [--out DIR]`

Each frame is read from disk (radar frame and the RealSense frame nearest in time, bench.maroon.reader; the mesh once),
reconstructed (`methods.reconstruct`) and scored against the ground truth at that frame's object pose (metrics;
the ground truth of a pose is built once and reused, as a sweep does). Two schedules over the same frames,
alternating pass by pass (`--passes` each, after one untimed warm-up pass):
* `serial`: read, then compute, frame after frame;
* `overlapped`: a reader thread reads frame i + 1 while frame i is computed (file reading, PNG decoding and
  unpickling release the GIL for much of their time, and the methods run in BLAS and Warp).
Reported per schedule: frames per second (median over passes, and the slowest pass), the median per-frame time
of each stage (read, method, metrics) and the method's own warm time. Without --root, a synthetic sequence is
generated once into outputs/perf/sequence (04_bottle at 30 cm, 10 radar frames 0.1 s apart, moving sideways at
5 cm/s, RealSense at 30 Hz). Writes OUT/perf_stream_<device>.csv (OUT = `--out`, default outputs/perf/).
"""
from __future__ import annotations

import dataclasses
import os
import statistics
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from bench import cli
from bench.maroon import reader as maroon
from bench.maroon import safe_io
from bench.perf.common import DEFAULT_OUT, add_device_option, add_out_option, write_rows
from bench.progress import each

SEQUENCE_ROOT = DEFAULT_OUT / "sequence"
SEQUENCE_CAPTURE = "04_bottle/30"
SEQUENCE = {"frames": 10, "motion": "lateral", "motion_speed_m_s": 0.05}


def default_sequence(root: Path = SEQUENCE_ROOT) -> Path:
    """The capture folder of the default synthetic sequence (generated on first use, cached by the generator)."""
    from bench.synth import SynthConfig, generate_capture

    obj, distance = SEQUENCE_CAPTURE.split("/")
    return generate_capture(root, obj, int(distance), dataclasses.replace(SynthConfig(), **SEQUENCE))


class FrameReader:
    """Reads frame after frame of one capture: radar + paired RealSense from disk, mesh and its poses once."""

    def __init__(self, capture_dir: Path, prior: str, metrics: bool):
        self.capture_dir = capture_dir
        self.parts = ("radar", "realsense") if prior == "realsense" else ("radar",)
        self.mesh = None
        if metrics:
            photogrammetry = capture_dir / "photogrammetry"
            with safe_io.use_root(capture_dir):
                self.mesh = maroon.read_mesh(maroon.find_mesh(photogrammetry))
        self.poses = capture_dir / "photogrammetry" / maroon.POSES_FOLDER

    def read(self, frame: int):
        """(capture of this frame, seconds spent reading it)."""
        start = time.perf_counter()
        capture = maroon.read_capture(self.capture_dir, frame=frame, parts=self.parts)
        if self.mesh is not None:
            capture.mesh = self.mesh
            if self.poses.is_dir():
                with safe_io.use_root(self.capture_dir):
                    capture.transforms["photogrammetry2radar"] = maroon.frame_pose(self.poses / f"{frame:06d}.json")
        return capture, time.perf_counter() - start


class Scorer:
    """Ground truth per (grid, object pose), built once and reused; metrics of a depth map against it."""

    def __init__(self):
        self.truths = {}

    def score(self, capture, depth_m) -> dict:
        from metrics.evaluate import evaluate, ground_truth
        from metrics.resample import resample_depth_m

        pose = capture.transforms["photogrammetry2radar"].tobytes()
        key = (capture.radar.grid, pose)
        if key not in self.truths:
            self.truths[key] = ground_truth(capture, capture.radar.grid)
        return evaluate(resample_depth_m(depth_m[0], depth_m[1], capture.radar.grid), self.truths[key])


def _compute(capture, args, scorer):
    """Method and metrics of one frame: (method s, metrics s, method's own warm ms, P_cm)."""
    from methods import reconstruct

    start = time.perf_counter()
    result = reconstruct(capture, args.method, args.freq, prior=args.prior, device=args.device)
    method_s = time.perf_counter() - start
    p_cm = float("nan")
    if scorer is not None:
        start = time.perf_counter()
        p_cm = scorer.score(capture, (result.depth_m, result.grid))["P_cm"]
        return method_s, time.perf_counter() - start, result.timings_ms["total"], p_cm
    return method_s, 0.0, result.timings_ms["total"], p_cm


def run_pass(reader: FrameReader, frames: list[int], args, scorer, overlapped: bool) -> dict:
    """One pass over `frames`: wall seconds and per-frame stage times (s)."""
    stages = {"read": [], "method": [], "metrics": [], "warm_ms": []}
    start = time.perf_counter()
    if overlapped:
        with ThreadPoolExecutor(1) as pool:
            pending = pool.submit(reader.read, frames[0])
            for i in range(len(frames)):
                capture, read_s = pending.result()
                if i + 1 < len(frames):
                    pending = pool.submit(reader.read, frames[i + 1])
                _record(stages, read_s, _compute(capture, args, scorer))
    else:
        for frame in frames:
            capture, read_s = reader.read(frame)
            _record(stages, read_s, _compute(capture, args, scorer))
    return {"wall_s": time.perf_counter() - start, **stages}


def _record(stages: dict, read_s: float, computed: tuple) -> None:
    method_s, metrics_s, warm_ms, p_cm = computed
    stages["read"].append(read_s)
    stages["method"].append(method_s)
    stages["metrics"].append(metrics_s)
    stages["warm_ms"].append(warm_ms)
    stages.setdefault("P_cm", []).append(p_cm)


def stream(capture_dir: Path, args) -> list[dict]:
    """Rows of the two schedules (module doc)."""
    reader = FrameReader(capture_dir, args.prior, not args.no_metrics)
    radar_dir = maroon.find_radar_folder(capture_dir)
    frames = maroon.list_radar_frames(radar_dir)
    scorer = None if args.no_metrics else Scorer()
    run_pass(reader, frames, args, scorer, overlapped=False)              # warm-up: compilation, ground truths
    passes = {"serial": [], "overlapped": []}
    for _, schedule in each([(i, s) for i in range(args.passes) for s in passes], "passes", unit="pass"):
        passes[schedule].append(run_pass(reader, frames, args, scorer, overlapped=schedule == "overlapped"))
    rows = []
    for schedule, runs in passes.items():
        fps = [len(frames) / run["wall_s"] for run in runs]
        per_frame = {stage: statistics.median(v for run in runs for v in run[stage])
                     for stage in ("read", "method", "metrics")}
        row = {"capture": f"{capture_dir.parent.name}/{capture_dir.name}", "frames": len(frames),
               "method": args.method, "freq": args.freq, "prior": args.prior, "device": args.device,
               "schedule": schedule, "passes": len(runs), "fps_median": statistics.median(fps), "fps_min": min(fps),
               "frame_ms_median": 1e3 / statistics.median(fps),
               **{f"{stage}_ms": 1e3 * value for stage, value in per_frame.items()},
               "method_warm_ms": statistics.median(v for run in runs for v in run["warm_ms"]),
               "P_cm_mean": statistics.fmean(v for v in runs[-1]["P_cm"]) if scorer else float("nan"),
               "load_1min": os.getloadavg()[0]}
        rows.append(row)
        print(f"stream {schedule:10s} {row['fps_median']:6.2f} frames/s (slowest pass {row['fps_min']:.2f}; per "
              f"frame: read {row['read_ms']:.1f} ms, method {row['method_ms']:.1f} ms, metrics "
              f"{row['metrics_ms']:.1f} ms)  load {row['load_1min']:.1f}", flush=True)
    return rows


def main(argv=None) -> int:
    parser = cli.ArgumentParser(prog="python -m bench.perf stream", description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, default=None, help="dataset root (default: the synthetic sequence)")
    parser.add_argument("--capture", default=None, help="OBJECT/DISTANCE under --root")
    add_device_option(parser)
    parser.add_argument("--method", default="mm2fsk")
    parser.add_argument("--freq", default="d10")
    parser.add_argument("--prior", default="realsense")
    parser.add_argument("--passes", type=cli.positive_int, default=3)
    parser.add_argument("--no-metrics", action="store_true", help="read and method only (no Open3D needed)")
    add_out_option(parser)
    args = parser.parse_args(argv)
    args.device = cli.resolve_device(args.device)
    out = cli.output_dir(args.out)
    if args.root is None:
        capture_dir = default_sequence()
    else:
        if args.capture is None:
            raise cli.UserError("--capture", "give the capture (OBJECT/DISTANCE) to stream with --root")
        capture_dir = cli.existing_path(args.root / args.capture, "dir", "--root/--capture")
    write_rows(stream(capture_dir, args), out / f"perf_stream_{args.device}.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
