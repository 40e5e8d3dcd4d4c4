"""Command line: `python -m bench.synth --out DIR [--preset realistic|ideal] [--distances 30 40 50] [--objects ...]
[--catalogue demo|full] [--frames N] [--motion static|lateral|approach] [--motion-speed M_S]
[--snr-db X] [--seed S] [--no-clutter] [--force] [--device cpu|cuda]`. Prints one line per capture; bad arguments,
an output folder that cannot be written or a device this machine lacks give a one-line error and exit code 2
(bench.cli)."""
from __future__ import annotations

import argparse
import dataclasses
import sys
import time

from bench import cli
from bench.synth import workers
from bench.synth.config import DEFAULT_PRESET, DISTANCE_RANGE_CM, PRESETS, SynthConfig, preset
from bench.synth.generate import DEFAULT_DISTANCES_CM, CaptureResult, generate_catalogue
from bench.synth.motion import MOTIONS
from bench.synth.motion import validate as validate_motion
from bench.synth.scenes import CATALOGUES, FULL_CATALOGUE


def _parser() -> argparse.ArgumentParser:
    p = cli.ArgumentParser(prog="python -m bench.synth", description="Generate synthetic MAROON-format captures.")
    p.add_argument("--out", required=True, help="dataset root directory")
    p.add_argument("--preset", choices=list(PRESETS), default=DEFAULT_PRESET,
                   help="generator settings: realistic (the effects of real data) or ideal (exact physics)")
    p.add_argument("--distances", type=int, nargs="+", default=list(DEFAULT_DISTANCES_CM), help="centimetres")
    p.add_argument("--catalogue", choices=list(CATALOGUES), default="demo",
                   help="demo: the demo's 8 objects; full: every object of bench/synth/README.md's catalogue")
    p.add_argument("--objects", nargs="+", default=None,
                   help=f"subset of the full catalogue (instead of --catalogue): {' '.join(FULL_CATALOGUE)}")
    p.add_argument("--frames", type=cli.positive_int, default=SynthConfig.frames)
    p.add_argument("--motion", choices=list(MOTIONS), default=SynthConfig.motion,
                   help="trajectory of the object over the frames (bench/synth/motion.py)")
    p.add_argument("--motion-speed", type=float, default=SynthConfig.motion_speed_m_s, help="m/s")
    p.add_argument("--snr-db", type=float, default=None,
                   help=f"per-sample SNR where the preset's noise model is 'snr' (ideal: {SynthConfig.snr_db})")
    p.add_argument("--seed", type=int, default=SynthConfig.seed)
    p.add_argument("--no-clutter", action="store_true", help="raw frames without empty-room clutter")
    p.add_argument("--force", action="store_true", help="regenerate even when the cache is up to date")
    p.add_argument("--device", default="cpu",
                   help="where the radar sums run: cpu (NumPy, the default: the same files on every machine), cuda "
                        "(Warp on the GPU: frames within a stated tolerance, docs/guide/synth.md; recorded in the "
                        "manifest and part of the cache key), warp-cpu (the same kernels on the CPU) or auto "
                        "(cuda where a GPU is seen, else cpu)")
    return p


def main(argv: list[str] | None = None) -> int:
    parser = _parser()
    args = parser.parse_args(argv)
    workers.prestart()        # worker processes' imports, beside this process's start-up
    unknown = [o for o in (args.objects or []) if o not in FULL_CATALOGUE]
    if unknown:
        parser.error(f"unknown object(s) {', '.join(unknown)}; known: {', '.join(FULL_CATALOGUE)}")
    objects = args.objects or list(CATALOGUES[args.catalogue])
    lo, hi = DISTANCE_RANGE_CM
    bad = [d for d in args.distances if not lo <= d <= hi]
    if bad:
        parser.error(f"distances must be in {lo}..{hi} cm, got {', '.join(map(str, bad))}")
    snr = {} if args.snr_db is None else {"snr_db": args.snr_db}
    config = dataclasses.replace(preset(args.preset), frames=args.frames, motion=args.motion,
                                 motion_speed_m_s=args.motion_speed, seed=args.seed, clutter=not args.no_clutter,
                                 **snr)
    try:
        config.validate()
        validate_motion(config)
    except ValueError as err:
        parser.error(str(err))

    device = cli.resolve_device(args.device)
    from bench.progress import bar

    progress = bar(len(objects) * len(args.distances), "captures", unit="capture")

    def log(result: CaptureResult) -> None:
        progress.write(f"{result.status:9s} {result.path}  {result.seconds:6.2f} s", file=sys.stdout)
        progress.update()

    start = time.perf_counter()
    try:
        with progress:
            results = generate_catalogue(args.out, args.distances, objects, config, args.force, log, device=device)
    except OSError as err:
        raise cli.UserError(args.out, f"cannot write the dataset there ({err.strerror or err})") from None
    generated = sum(r.status == "generated" for r in results)
    print(f"{len(results)} captures ({generated} generated, {len(results) - generated} cached) "
          f"in {time.perf_counter() - start:.1f} s")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
