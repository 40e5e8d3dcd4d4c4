"""The full-catalogue evidence of issue #27 (results/catalogue/): the 27 objects at 30 cm, 128 frequencies, generator
seeds 0-2, every cell of Tables II and III and the depth camera alone under both metric profiles; seed 0 with each
camera effect off in turn (all objects; the radar frames are built once and shared, the camera does not touch them)
and each radar effect off in turn (the objects of --radar-objects). Built for the 16-core H100 machine: generation
and cells run as separate processes under one deadline, each writing its CSV as it goes.

    python scripts/catalogue_evidence.py orchestrate WORK EV DEADLINE_S [--max-procs 12] [--radar-objects ...]
    python scripts/catalogue_evidence.py collect EV results/catalogue      # the report's inputs from EV's CSVs
    python -m bench.report.catalogue results/catalogue                      # the report

`gen` and `cells` are the orchestrator's workers (`cells` runs on --device, default cuda or $DRV_DEVICE; DRV_QUICK=1
leaves the BP cells out, for a dry run on the CPU with --freqs 21 and a few --objects).
"""
from __future__ import annotations

import argparse
import dataclasses
import os
import re
import subprocess
import sys
import time
from pathlib import Path

import pandas as pd

TABLE2 = [f"mm2fsk_{f}@photogrammetry" for f in ("d05", "d1", "d2", "d4", "d8", "d10")]
TABLE3 = ["bp_full", "bp_d05", "bp_d1", "bp_d10", "2fsk_d05", "2fsk_d1", "2fsk_d10", "3fsk_d05_d10", "3fsk_d1_d10",
          "3fsk_d2_d10", "mm2fsk_d05", "mm2fsk_d1", "mm2fsk_d10", "prior_only_d10"]
# ordered so that the cells the relations need come first (a deadline cut leaves the rest)
MAIN_CELLS = ["mm2fsk_d10", "mm2fsk_d10@photogrammetry", "bp_full", "prior_only_d10", "2fsk_d05", "3fsk_d05_d10",
              "mm2fsk_d05", "mm2fsk_d1", "bp_d05", "bp_d1", "bp_d10", "mm2fsk_d05@photogrammetry",
              "mm2fsk_d1@photogrammetry", "mm2fsk_d2@photogrammetry", "mm2fsk_d4@photogrammetry",
              "mm2fsk_d8@photogrammetry", "2fsk_d1", "2fsk_d10", "3fsk_d1_d10", "3fsk_d2_d10"]
assert sorted(MAIN_CELLS) == sorted(TABLE2 + TABLE3)
CAMERA_EFFECTS = ["camera calibration residual", "camera materials", "camera edge pixels", "camera slant bias",
                  "camera depth scale", "camera calibration tail", "camera noise model", "camera minimum range",
                  "camera edge ramps", "camera contiguous holes", "camera IR multipath", "camera segmentation mask"]
CAMERA_CELLS = ["mm2fsk_d10", "prior_only_d10", "mm2fsk_d05", "mm2fsk_d1"]
RADAR_EFFECTS = ["second-order multipath", "transmission", "specular scattering", "radar materials", "scene clutter",
                 "mount", "ground-truth smoothing", "channel residual", "element pattern", "datasheet noise",
                 "ground-truth registration"]
RADAR_CELLS = ["bp_full", "mm2fsk_d10", "mm2fsk_d10@photogrammetry", "2fsk_d05", "3fsk_d05_d10", "mm2fsk_d05",
               "bp_d05"]


def slug(name: str) -> str:
    return re.sub(r"[^\w.-]+", "_", name).strip("_")


def ready(root: Path) -> Path:
    """The marker of a generated root (beside it: the generator refuses a root holding files it did not write)."""
    return root.with_name(root.name + ".ready")


def objects_of(args) -> list[str]:
    from bench.synth.scenes import FULL_CATALOGUE
    return args.objects or list(FULL_CATALOGUE)


def config_of(seed: int, freqs: int, change: dict | None = None):
    from bench.synth.config import preset
    return dataclasses.replace(preset("realistic"), seed=seed, frequency_points=freqs, **(change or {}))


def memoise_radar() -> None:
    """Camera variants leave the radar settings alone: one process builds each capture's radar frames once (a
    script run by path builds its captures in threads of this process: bench.synth.workers)."""
    from bench.synth import parts as gen
    memo, frames = {}, gen._radar_frames

    def memo_frames(scene, config, rng, device="cpu"):
        key = (scene.name, config.seed, config.frequency_points, device)
        if key not in memo:
            memo[key] = [(a.copy(), b.copy()) for a, b in frames(scene, config, rng, device)]
        yield from memo[key]
    gen._radar_frames = memo_frames


def cmd_gen(args) -> None:
    from bench.synth import generate_catalogue
    from bench.synth.config import EFFECTS
    objects = objects_of(args)
    if args.camera_variants:
        memoise_radar()
    t = time.perf_counter()
    generate_catalogue(args.root, [30], objects, config_of(args.seed, args.freqs))
    ready(Path(args.root)).touch()
    print(f"gen seed {args.seed} {len(objects)} objects {args.freqs} freqs: {time.perf_counter() - t:.0f} s",
          flush=True)
    if args.camera_variants:
        for name in CAMERA_EFFECTS:
            t = time.perf_counter()
            root = Path(args.camera_variants) / slug(name)
            generate_catalogue(root, [30], objects, config_of(args.seed, args.freqs, EFFECTS[name]))
            ready(root).touch()
            print(f"gen camera variant '{name}': {time.perf_counter() - t:.0f} s", flush=True)
    if args.radar_variants:
        for name in RADAR_EFFECTS:
            t = time.perf_counter()
            root = Path(args.radar_variants) / slug(name)
            generate_catalogue(root, [30], objects, config_of(args.seed, args.freqs, EFFECTS[name]))
            ready(root).touch()
            print(f"gen radar variant '{name}': {time.perf_counter() - t:.0f} s", flush=True)


def cmd_cells(args) -> None:
    from hydra import compose, initialize_config_dir

    from bench.harness.app import CONFIG_DIR, run
    from bench.report.agreement import cell_overrides
    objects, out = objects_of(args), Path(args.outcsv)
    frames = []
    for cell in args.cells:
        overrides = ["dataset=maroon", f"dataset.root={args.root}",
                     f"dataset.captures=[{','.join(o + '/30' for o in objects)}]",
                     f"store.dir={args.store or 'null'}", f"profile={args.profile}", f"device={args.device}",
                     *cell_overrides(cell)]
        with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
            cfg = compose(config_name="config", overrides=overrides)
        t = time.perf_counter()
        rows = pd.DataFrame(run(cfg, Path(args.runs) / out.stem / cell.replace("@", "_"), timing="parallel"))
        rows["cell"], rows["seed"], rows["variant"] = cell, args.seed, args.variant
        frames.append(rows)
        pd.concat(frames, ignore_index=True).to_csv(out, index=False)
        print(f"{out.stem} {cell}: {len(rows)} rows {time.perf_counter() - t:.1f} s", flush=True)
    if args.prior_errors:
        from bench.report.agreement import prior_errors
        errors = prior_errors(Path(args.root), objects)
        errors["seed"], errors["variant"] = args.seed, args.variant
        errors.to_csv(out.with_name(out.stem + "_prior_errors.csv"), index=False)


def cmd_orchestrate(args) -> None:
    """Everything in priority order under one deadline; every process writes its CSV as it goes."""
    work, out, end = Path(args.work), Path(args.out), time.time() + args.deadline_s
    me = [sys.executable, __file__]
    obj = ["--objects", *args.objects] if args.objects else []
    procs: list[tuple[str, subprocess.Popen]] = []

    # a cells process is one thread of methods and metrics: BLAS/OpenMP pools in a dozen of them would contend
    threads = {"OMP_NUM_THREADS": "2", "OPENBLAS_NUM_THREADS": "2", "MKL_NUM_THREADS": "2"}

    def start(tag, argv):
        env = {**os.environ, "WARP_CACHE_PATH": f"/root/wpcache/{tag}"}   # one Warp cache per process
        if argv[0] == "cells":
            argv = [*argv, "--runs", str(work / "runs" / tag)]
            env.update(threads)
        log = open(out / f"{tag}.log", "w")
        extra = [] if "--objects" in argv else obj
        procs.append((tag, subprocess.Popen(me + argv + extra, stdout=log, stderr=subprocess.STDOUT, env=env)))
        print(f"{time.strftime('%X')} start {tag}", flush=True)

    seeds = [0, 1, 2]
    if os.environ.get("DRV_QUICK"):        # dry run on the CPU: no BP (seconds to minutes a frame there)
        for cells in (MAIN_CELLS, RADAR_CELLS):
            cells[:] = [c for c in cells if not c.startswith("bp_")]
    f = ["--freqs", str(args.freqs)]
    start("gen_s0", ["gen", "0", str(work / "data_s0"), *f, "--camera-variants", str(work / "cam")])
    for s in seeds[1:]:
        start(f"gen_s{s}", ["gen", str(s), str(work / f"data_s{s}"), *f])
    pending = {f"cells_s{s}_{p}": (ready(work / f"data_s{s}"),
                                   ["cells", str(s), p, str(work / f"data_s{s}"), str(out / f"rows_s{s}_{p}.csv"),
                                    "--store", str(work / f"store_s{s}_{p}"), "--variant", "all effects on",
                                    "--cells", *MAIN_CELLS] + (["--prior-errors"] if p == "sound" else []))
               for s in seeds for p in ("sound", "faithful")}
    for name in CAMERA_EFFECTS:
        for p in ("sound", "faithful"):
            pending[f"cam_{slug(name)}_{p}"] = (
                ready(work / "cam" / slug(name)),
                ["cells", "0", p, str(work / "cam" / slug(name)), str(out / "camera" / f"{slug(name)}_{p}.csv"),
                 "--store", str(work / f"store_cam_{p}"), "--variant", name, "--cells", *CAMERA_CELLS]
                + (["--prior-errors"] if p == "sound" else []))
    (out / "camera").mkdir(parents=True, exist_ok=True)
    (out / "radar").mkdir(parents=True, exist_ok=True)
    radar_started = False
    while time.time() < end:
        for tag, (marker, argv) in list(pending.items()):
            running = sum(p.poll() is None for _, p in procs)
            if marker.exists() and running < args.max_procs:
                start(tag, argv)
                del pending[tag]
        gens_done = all(p.poll() is not None for t, p in procs if t.startswith("gen_"))
        if gens_done and not radar_started and args.radar_objects:
            radar_started = True
            start("gen_radar", ["gen", "0", str(work / "radar_base"), *f, "--radar-variants", str(work / "radar"),
                                "--objects", *args.radar_objects])
            for name in ["all effects on", *RADAR_EFFECTS]:
                root = work / "radar_base" if name == "all effects on" else work / "radar" / slug(name)
                for p in ("sound", "faithful"):
                    pending[f"radar_{slug(name)}_{p}"] = (
                        ready(root), ["cells", "0", p, str(root), str(out / "radar" / f"{slug(name)}_{p}.csv"),
                                          "--store", str(work / f"store_radar_{p}"), "--variant", name,
                                          "--cells", *RADAR_CELLS, "--objects", *args.radar_objects])
        if not pending and all(p.poll() is not None for _, p in procs):
            break
        time.sleep(1)
    for tag, p in procs:
        if p.poll() is None:
            print(f"{time.strftime('%X')} deadline: stopping {tag}", flush=True)
            p.terminate()
    print(f"not started: {', '.join(pending) or 'none'}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser()
    sub = parser.add_subparsers(dest="cmd", required=True)
    g = sub.add_parser("gen")
    g.add_argument("seed", type=int)
    g.add_argument("root")
    g.add_argument("--freqs", type=int, default=128)
    g.add_argument("--camera-variants")
    g.add_argument("--radar-variants")
    c = sub.add_parser("cells")
    c.add_argument("seed", type=int)
    c.add_argument("profile")
    c.add_argument("root")
    c.add_argument("outcsv")
    c.add_argument("--cells", nargs="+", default=MAIN_CELLS)
    c.add_argument("--store")
    c.add_argument("--variant", default="all effects on")
    c.add_argument("--device", default=os.environ.get("DRV_DEVICE", "cuda"))
    c.add_argument("--prior-errors", action="store_true")
    c.add_argument("--runs", required=True, help="the runs' output folders (not under $OUT)")
    o = sub.add_parser("orchestrate")
    o.add_argument("work")
    o.add_argument("out")
    o.add_argument("deadline_s", type=float)
    o.add_argument("--freqs", type=int, default=128)
    o.add_argument("--max-procs", type=int, default=10)
    o.add_argument("--radar-objects", nargs="*", default=[])
    for p in (g, c, o):
        p.add_argument("--objects", nargs="+", default=None)
    k = sub.add_parser("collect")
    k.add_argument("ev", type=Path)
    k.add_argument("dest", type=Path)
    args = parser.parse_args()
    if args.cmd == "collect":
        return collect(args.ev, args.dest)
    {"gen": cmd_gen, "cells": cmd_cells, "orchestrate": cmd_orchestrate}[args.cmd](args)



KEEP = ["object", "distance", "frame", "method", "freq", "prior", "grid", "metrics", "cell", "seed", "variant",
        "C_g_cm", "C_s_cm", "P_cm", "P_e_cm", "coverage_pct", "off_pct", "failure", "valid_px", "runtime_ms",
        "device", "timing", "code_version"]


def collect(ev: Path, dest: Path) -> None:
    """The device batch's CSVs (`ev`) as the report's inputs (`dest`): rows, prior_errors, ablation."""
    def cat(paths):
        return pd.concat([pd.read_csv(p) for p in sorted(paths)], ignore_index=True)

    def kept(frame):
        return frame[[c for c in KEEP if c in frame]]
    dest.mkdir(parents=True, exist_ok=True)
    rows = kept(cat(ev.glob("rows_s*_*[dl].csv")))
    rows.to_csv(dest / "rows.csv", index=False, float_format="%.6g")
    cat(ev.glob("rows_s*_sound_prior_errors.csv")).to_csv(dest / "prior_errors.csv", index=False,
                                                           float_format="%.6g")
    parts = []
    for kind in ("camera", "radar"):
        files = [p for p in (ev / kind).glob("*.csv") if not p.stem.endswith("_prior_errors")]
        if files:
            parts.append(cat(files).assign(kind=kind))
    if parts:
        base = rows[(rows.seed == 0) & rows.cell.isin(CAMERA_CELLS)].assign(kind="camera")
        full = pd.concat([base, *parts], ignore_index=True)
        kept(full).drop(columns=["device", "timing", "code_version", "valid_px", "runtime_ms"]).assign(
            kind=full.kind).to_csv(dest / "ablation.csv", index=False, float_format="%.6g")
    errors = list((ev / "camera").glob("*_prior_errors.csv"))
    if errors:
        cat(errors).to_csv(dest / "ablation_prior_errors.csv", index=False, float_format="%.6g")


if __name__ == "__main__":
    main()
