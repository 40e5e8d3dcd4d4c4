"""Peak memory of sweep jobs: `python -m bench.perf memory --root DIR [--cells ...] [--grids ...]`.

Runs each cell as the job a sweep would run (`python -m bench cell=<cell> grid=<grid> dataset=maroon
dataset.root=DIR store.dir=null`, one process per job, all captures under DIR) and reads the job's peak resident
set size from the kernel (os.wait4's rusage: ru_maxrss of that process and the children it waited for), started
from a small interpreter (WAIT4). Beside
each it prints the model's peak and the memory the SLURM launcher asks for (`bench.harness.resources`), so the
model's error and margin are visible.
Writes OUT/perf_memory.csv (default outputs/perf/; docs/guide/slurm.md "Memory and time per job" quotes the figures).
"""
from __future__ import annotations

import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bench import cli
from bench.perf.common import DEFAULT_OUT, write_rows
from bench.progress import each

DEFAULT_CELLS = ("mm2fsk_d10", "2fsk_d05", "3fsk_d05_d10", "bp_d05", "bp_full")


# Started from a small interpreter: Linux counts the memory of the process a job was forked from into the job's
# ru_maxrss (the old address space's high-water mark at exec), so a job started by a large process (pytest with
# Open3D loaded: ~400 MiB) would report at least that.
WAIT4 = """import os, subprocess, sys
job = subprocess.Popen(sys.argv[1:], stdout=subprocess.DEVNULL)
_, status, usage = os.wait4(job.pid, 0)
print(usage.ru_maxrss, os.waitstatus_to_exitcode(status))"""


def job_peak_mib_measured(overrides: list[str]) -> tuple[float, float]:
    """(peak RSS in MiB, wall seconds) of one `python -m bench` job with these overrides, nothing kept from earlier
    runs (no store, `store.cache=null`: the ground truth is cast, Open3D imported, as in a job's first run)."""
    with tempfile.TemporaryDirectory() as tmp:
        start = time.perf_counter()
        proc = subprocess.run([sys.executable, "-c", WAIT4, sys.executable, "-m", "bench", *overrides,
                               "store.dir=null", "store.cache=null", f"hydra.run.dir={tmp}/run"],
                              capture_output=True, text=True)
        wall_s = time.perf_counter() - start
    maxrss_kib, code = map(int, proc.stdout.split()[-2:]) if proc.returncode == 0 else (0, proc.returncode)
    if code != 0:
        raise cli.UserError(" ".join(overrides), f"the job failed: {proc.stderr.strip()[-300:]}")
    return maxrss_kib / 1024, wall_s          # ru_maxrss: KiB on Linux


def main(argv=None) -> int:
    from hydra import compose, initialize_config_dir

    from bench.harness.app import CONFIG_DIR
    from bench.harness.resources import job_mem_gb, job_peak_mib
    from bench.maroon.reader import discover_captures

    parser = cli.ArgumentParser(prog="python -m bench.perf memory", description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, required=True, help="dataset root holding <object>/<distance> folders")
    parser.add_argument("--cells", nargs="*", default=list(DEFAULT_CELLS), help="cells (configs/cell/)")
    parser.add_argument("--grids", nargs="*", default=["cell"],
                        help="grids per cell: `cell` (the cell's own) and/or configs/grid names, e.g. bp_cpu")
    parser.add_argument("--frame", default=None, help="dataset.frame (e.g. all: every frame of a sequence)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT,
                        help="folder for the CSV (default: outputs/perf)")
    args = parser.parse_args(argv)
    root = cli.existing_path(args.root, "dir", "dataset root").absolute()
    out = cli.output_dir(args.out)
    runs = [(cell, grid) for cell in args.cells for grid in args.grids]
    rows = []
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        for cell, grid in each(runs, "jobs", unit="job"):
            overrides = [f"cell={cell}", "dataset=maroon", f"dataset.root={root}",
                         *([] if grid == "cell" else [f"grid={grid}"]),
                         *([] if args.frame is None else [f"dataset.frame={args.frame}"])]
            cfg = compose(config_name="config", overrides=overrides)
            frames = len(discover_captures(root))                   # captures (the model counts their frames)
            peak_mib, wall_s = job_peak_mib_measured(overrides)
            model_mib, request_gb = job_peak_mib(cfg, frames), job_mem_gb(cfg, frames)
            rows.append({"cell": cell, "grid": cfg.grid.name, "captures": frames, "peak_rss_mib": peak_mib,
                         "model_mib": model_mib, "request_gb": request_gb, "margin": request_gb * 1024 / peak_mib,
                         "wall_s": wall_s, "load_1min": os.getloadavg()[0], "hostname": socket.gethostname()})
            print(f"{cell:14s} {cfg.grid.name:12s} {frames} captures  peak {peak_mib:6.0f} MiB  model {model_mib:6.0f} "
                  f"MiB  asks {request_gb} GiB (x{request_gb * 1024 / peak_mib:.1f})  {wall_s:6.1f} s", flush=True)
    write_rows(rows, out / "perf_memory.csv")
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
