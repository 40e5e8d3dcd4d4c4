"""Every command the README and the guide show, and a table of user mistakes, through the real entry points
(subprocesses).

* Commands: `DOC_RUNS` maps each command that README.md and the pages of docs/guide/ show (their ```bash blocks and
  the `python -m` / `bash run.sh` spans of their prose) to what this test runs for it;
  `test_doc_commands_are_all_covered` fails when the pages and the map drift apart. Cheap commands run for real on the `synth_root` fixture or on copies of
  committed files; long ones (the demo, sweeps, the full benchmarks) run with `--help`, Hydra sweeps are composed
  with `--cfg all` (every group and launcher resolved, nothing run). Each must exit 0 without a traceback.
* Mistakes: `MISTAKES` lists a command, the exit code and the one line it must print on stderr
  (`error: <what>: <what is wrong>`, bench.cli); nothing else may reach stderr.

The commands of a test module run two at a time (the machine has two cores; most of the time is imports).
"""
from __future__ import annotations

import hashlib
import re
import shlex
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from devices import cuda_seen

REPO = Path(__file__).resolve().parents[2]
PY = sys.executable
TIMEOUT_S = 300

STRESS_PRECISION = ["{py} -m bench.stress --precision-only --quick --out {tmp}/gpu",
                    "cp -r {repo}/results/stress {tmp}/report",
                    "{py} -m bench.stress --add-precision {tmp}/gpu/precision.csv --out {tmp}/report",
                    "test -s {tmp}/report/summary.md"]
# command shown in README.md or docs/guide/*.md -> the commands run for it, in order. {py}: this interpreter,
# {synth}: the synth_root fixture, {tmp}: an empty folder of this test, {repo}: the checkout.
REPORT_RUN = ["cp -r {repo}/results/table3 {tmp}/table3", "{py} -m bench.report {tmp}/table3 --out {tmp}/report.html",
              "test -s {tmp}/report.html"]
# one run, for real (one capture, 2FSK: seconds); the MM-2FSK run is test_app's
ONE_RUN = ["{py} -m bench dataset=maroon dataset.root={synth} dataset.captures=[01_plate/30] method=2fsk freq=d05 "
           "prior=none device=cpu store.dir=null hydra.run.dir={tmp}/run", "test -s {tmp}/run/results.csv"]
DOC_RUNS: dict[str, list[str]] = {
    "bash run.sh demo": ["bash run.sh demo --help"],
    "bash run.sh test": ["bash run.sh test --help"],
    "bash run.sh setup": ["bash run.sh setup"],
    "bash run.sh test -k reader": ["bash run.sh test -k reader --collect-only -q tests/bench/maroon/test_reader.py"],
    "bash run.sh demo --out /tmp/demo": ["bash run.sh demo --out {tmp}/demo --help"],
    ".venv/bin/python -m bench.demo": ["{py} -m bench.demo --help"],
    "python -m bench.demo [--out DIR] [--store DIR] [--distances CM ...] [--update-results]":
        ["{py} -m bench.demo --help"],
    "bash run.sh demo --update-results": ["bash run.sh demo --update-results --help"],
    "python -m bench": ["{py} -m bench --help"],
    # one run for real on one capture (MM-2FSK: seconds; without dataset.root it would generate data/synthetic)
    ".venv/bin/python -m bench method=mm2fsk freq=d10 prior=realsense":
        ["{py} -m bench dataset=maroon dataset.root={synth} dataset.captures=[01_plate/30] method=mm2fsk freq=d10 "
         "prior=realsense store.dir=null hydra.run.dir={tmp}/one", "test -s {tmp}/one/results.csv"],
    # sweeps take minutes: composed (experiment, cells, launcher) but not run
    ".venv/bin/python -m bench -m experiment=table2 hydra/launcher=local":
        ["{py} -m bench experiment=table2 hydra/launcher=local --cfg all"],
    ".venv/bin/python -m bench -m experiment=table3 hydra/launcher=local":
        ["{py} -m bench experiment=table3 hydra/launcher=local --cfg all"],
    ".venv/bin/python -m bench -m experiment=runtime": ["{py} -m bench experiment=runtime --cfg all"],
    ".venv/bin/python -m bench -m experiment=beyond hydra/launcher=local":
        ["{py} -m bench experiment=beyond hydra/launcher=local --cfg all"],
    # a method of one's own, for real on one capture (the worked example: no radar, seconds)
    ".venv/bin/python -m bench method=custom method._target_=examples.prior_only.PriorOnly prior=realsense freq=d10":
        ["{py} -m bench dataset=maroon dataset.root={synth} dataset.captures=[01_plate/30] method=custom "
         "method._target_=examples.prior_only.PriorOnly prior=realsense freq=d10 store.dir=null "
         "hydra.run.dir={tmp}/own", "test -s {tmp}/own/results.csv"],
    ".venv/bin/python -m bench -m experiment=table3 hydra/launcher=slurm_gpu hydra.launcher.partition=gpu device=cuda "
    "grid=paper": ["{py} -m bench experiment=table3 hydra/launcher=slurm_gpu hydra.launcher.partition=gpu "
                   "device=cuda grid=paper --cfg all"],
    ".venv/bin/python -m bench -m experiment=table3 hydra/launcher=slurm_cpu hydra.launcher.partition=cpu":
        ["{py} -m bench experiment=table3 hydra/launcher=slurm_cpu hydra.launcher.partition=cpu --cfg all"],
    # starting SLURM daemons is not a test's business: syntax only (test_slurm runs them, opt-in)
    "sudo bash scripts/slurm_single_node.sh start": ["bash -n {repo}/scripts/slurm_single_node.sh"],
    "sudo bash scripts/slurm_try.sh": ["bash -n {repo}/scripts/slurm_try.sh"],
    "sudo bash scripts/slurm_try.sh --accounting": ["bash -n {repo}/scripts/slurm_try.sh"],
    "sudo bash scripts/slurm_single_node.sh stop": ["bash -n {repo}/scripts/slurm_single_node.sh"],
    # the report for real on a copy of the committed table3 (no job folders: no pictures, seconds)
    ".venv/bin/python -m bench.report outputs/demo/table2 outputs/demo/table3 --out outputs/demo/report.html":
        REPORT_RUN,
    "python -m bench.report SWEEP_ROOT [SWEEP_ROOT ...]": REPORT_RUN,
    "python -m bench.report": ["{py} -m bench.report --help"],
    "python -m bench.report SWEEP_ROOT [SWEEP_ROOT ...] [--out FILE] [--no-pictures]": REPORT_RUN,
    "bash run.sh demo --distances 30 40 50": ["bash run.sh demo --distances 30 40 50 --help"],
    ".venv/bin/python -m bench -m experiment=table3 hydra/launcher=submitit_local":
        ["{py} -m bench experiment=table3 hydra/launcher=submitit_local --cfg all"],
    r"python -m bench -m experiment=table2\|table3\|runtime [hydra/launcher=local\|slurm_cpu\|slurm_gpu\|submitit_local]":
        ["{py} -m bench experiment=runtime hydra/launcher=submitit_local --cfg all"],
    ".venv/bin/python -m bench dataset=maroon dataset.root=data/synthetic dataset.captures=[01_plate/30] method=2fsk "
    "freq=d05 prior=none hydra.run.dir=outputs/one": ONE_RUN,
    r"python -m bench dataset.root=DIR method=bp\|2fsk\|3fsk\|mm2fsk freq=CONFIG "
    r"prior=none\|realsense\|photogrammetry [device=cpu\|cuda] hydra.run.dir=OUT":
        ONE_RUN,
    ".venv/bin/python -m bench profile=faithful dataset=maroon dataset.root=/data/maroon method=mm2fsk freq=d10 "
    "prior=realsense":      # for real on one capture with 2FSK (seconds); the faithful rows say so
        ["{py} -m bench profile=faithful dataset=maroon dataset.root={synth} dataset.captures=[01_plate/30] "
         "method=2fsk freq=d05 prior=none store.dir=null hydra.run.dir={tmp}/faithful",
         "grep -q ',faithful,' {tmp}/faithful/results.csv"],
    ".venv/bin/python -m bench dataset=maroon dataset.root=/data/maroon method=mm2fsk freq=d10 prior=realsense":
        ["{py} -m bench dataset=maroon dataset.root=/data/maroon method=mm2fsk freq=d10 prior=realsense --cfg job"],
    ".venv/bin/python -m bench.report.tables table1 [--csv FILE] [--latex FILE]":
        ["{py} -m bench.report.tables table1 --csv {tmp}/t1.csv --latex {tmp}/t1.tex", "test -s {tmp}/t1.tex"],
    ".venv/bin/python -m bench.report.tables table2|table3|runtime [--results DIR|CSV] [--csv FILE] [--latex FILE]":
        ["{py} -m bench.report.tables table2",
         "{py} -m bench.report.tables table3 --csv {tmp}/t3.csv --latex {tmp}/t3.tex",
         "{py} -m bench.report.tables runtime --results {repo}/results/table3/results.csv", "test -s {tmp}/t3.csv"],
    r"python -m bench.report.tables table1\|table2\|table3\|runtime [--results DIR] [--csv F] [--latex F]":
        ["{py} -m bench.report.tables table3 --results {repo}/results/table3"],
    "python -m bench.report.tables table3 | head -1": ["{py} -m bench.report.tables table3 | head -1"],
    "python -m bench.report.merge ROOT --table table3":      # a sweep root made of the committed table3 rows
        ["mkdir -p {tmp}/sweep/0_job", "cp {repo}/results/table3/results.csv {tmp}/sweep/0_job/",
         "{py} -m bench.report.merge {tmp}/sweep --table table3", "test -s {tmp}/sweep/table3.tex"],
    r"python -m bench.synth --out DIR [--preset realistic\|ideal] [--distances 30 40 50] [--objects ...] [--seed S]":
        ["{py} -m bench.synth --help"],     # generating takes ~15-60 s a capture; bench.synth runs in test_synth_*
    "python -m bench.synth": ["{py} -m bench.synth --help"],
    ".venv/bin/python -m bench.synth --out data/synthetic --preset realistic --distances 30": ["{py} -m bench.synth --help"],
    # the CUDA path's sums: tests/bench/synth/test_synth_warp.py (Warp-CPU here, CUDA on a GPU)
    ".venv/bin/python -m bench.synth --out data/synthetic_cuda --distances 30 --device cuda": ["{py} -m bench.synth --help"],
    # the agreement report generates the catalogue and runs 19 cells (~15 min): its options are checked only
    ".venv/bin/python -m bench.report.agreement": ["{py} -m bench.report.agreement --help"],
    ".venv/bin/python -m bench.report.agreement --ablation --no-tables": ["{py} -m bench.report.agreement --help"],
    ".venv/bin/python -m bench.report.agreement --from-results results --out /tmp/agreement":   # rows -> report, ~2 s
        ["{py} -m bench.report.agreement --from-results {repo}/results --out {tmp}/agreement",
         "test -s {tmp}/agreement/agreement.md"],
    r"python -m bench.report.agreement [--preset realistic\|ideal] [--objects ...] [--cells ...] [--ablation] [--out DIR]":
        ["{py} -m bench.report.agreement --help"],
    # the relations report reads 3,240 rows and pairs every relation per seed (~2 min): its options are checked only
    "python -m bench.report.catalogue results/catalogue": ["{py} -m bench.report.catalogue --help"],
    ".venv/bin/python -m bench.maroon.inspect_capture /data/maroon": ["{py} -m bench.maroon.inspect_capture {synth}"],
    "python -m bench.maroon.inspect_capture DIR": ["{py} -m bench.maroon.inspect_capture {synth}"],
    "python -m bench.maroon.inspect_capture": ["{py} -m bench.maroon.inspect_capture --help"],        # named in prose
    ".venv/bin/python -m bench.perf correlate [--device cpu|cuda] [--sizes paper|small]": ["{py} -m bench.perf correlate --help"],
    ".venv/bin/python -m bench.perf frames [--device cpu|cuda] [--scene masked|plate] [--root DIR]":
        ["{py} -m bench.perf frames --help"],          # minutes on the CPU; its parts run in test_perf_frames
    ".venv/bin/python -m bench.perf frames --device cuda --fill scanline delaunay":
        ["{py} -m bench.perf frames --help"],          # needs a GPU; its parts run in test_perf_frames
    ".venv/bin/python -m bench.perf fill --root data/synthetic":
        ["{py} -m bench.perf fill --help"],            # minutes on the CPU; its parts run in test_perf_fill
    "python -m bench.perf fill --root DIR": ["{py} -m bench.perf fill --help"],
    ".venv/bin/python -m bench.report.tables table2|table3|beyond|runtime [--results DIR|CSV] [--csv FILE] [--coverage-floor PCT]":
        ["{py} -m bench.report.tables table3 --coverage-floor 50 --csv {tmp}/t3f.csv", "test -s {tmp}/t3f_pairs.csv"],
    ".venv/bin/python -m bench.report SWEEP_ROOT [SWEEP_ROOT ...] [--out FILE] [--no-pictures]":
        ["{py} -m bench.report --help"],             # the report of a sweep runs in REPORT_RUN
    ".venv/bin/python -m bench.report.agreement --from-results DIR [--faithful-results DIR2] [--data ROOT] [--out DIR]":
        ["{py} -m bench.report.agreement --help"],
    # regenerating results/: the demo and the faithful sweeps take minutes to hours; their options are checked
    ".venv/bin/python -m bench.demo --update-results": ["{py} -m bench.demo --help"],
    ".venv/bin/python -m bench.synth --out data/full --catalogue full --distances 30":
        ["{py} -m bench.synth --help"],              # 27 captures take minutes; the catalogue's tests generate parts
    ".venv/bin/python -m bench -m threshold_db=10,14,20 method=mm2fsk freq=d10 prior=realsense":
        ["{py} -m bench threshold_db=10 method=mm2fsk freq=d10 prior=realsense --cfg job"],   # rows: test_identity
    "python -m bench.report.merge ROOT": ["{py} -m bench.report.merge --help"],   # merges run in test_sweep_report
    ".venv/bin/python -m bench -m experiment=table2 profile=faithful hydra/launcher=basic hydra.sweep.dir=outputs/faithful/table2":
        ["{py} -m bench experiment=table2 profile=faithful hydra/launcher=basic --cfg job"],
    ".venv/bin/python -m bench -m experiment=table3 profile=faithful hydra/launcher=basic hydra.sweep.dir=outputs/faithful/table3":
        ["{py} -m bench experiment=table3 profile=faithful hydra/launcher=basic --cfg job"],
    ".venv/bin/python -m bench.report.agreement --from-results results --faithful-results outputs/faithful --data data/synthetic --out results":
        ["{py} -m bench.report.agreement --help"],
    ".venv/bin/python -m bench.perf formation --device cuda --frames 8":
        ["{py} -m bench.perf formation --help"],       # needs a GPU; its parts run in test_perf_formation
    ".venv/bin/python -m bench.perf formation --device cpu --frames 3":
        ["{py} -m bench.perf formation --help"],       # minutes per BP_max frame; its parts run in test_perf_formation
    ".venv/bin/python -m bench.perf stream [--device cpu|cuda] [--root DIR --capture OBJECT/DISTANCE]":
        ["{py} -m bench.perf stream --help"],          # generates a 10-frame sequence; runs in test_perf_stream
    ".venv/bin/python -m bench.perf overhead --root data/synthetic [--device cpu|cuda] [--grid paper]":
        ["{py} -m bench.perf overhead --help"],        # a whole table3; runs in test_perf_overhead
    ".venv/bin/python -m bench.perf overhead --results-frames 100 1000":
        ["{py} -m bench.perf overhead --results-frames 3 20 --out {tmp}"],
    ".venv/bin/python -m bench.perf experiment table2 --root data/synthetic [--device cuda] [--repeat 2]":
        ["{py} -m bench.perf experiment --help"],      # whole sweeps; a small one runs in test_perf_experiment
    "python -m bench.perf experiment table2 --root data/synthetic [--device cuda]":
        ["{py} -m bench.perf experiment --help"],
    # frame sequences: generating 10 frames takes minutes; test_frames runs a 3-frame sequence for real
    ".venv/bin/python -m bench.synth --out data/sequence --objects 04_bottle --distances 30 --frames 10 "
    "--motion lateral": ["{py} -m bench.synth --help"],
    ".venv/bin/python -m bench dataset=maroon dataset.root=data/sequence dataset.frame=all method=mm2fsk freq=d10 "
    "prior=realsense": ["{py} -m bench dataset=maroon dataset.root=data/sequence dataset.frame=all method=mm2fsk "
                        "freq=d10 prior=realsense --cfg job"],
    ".venv/bin/python -m bench.perf sweep --root data/synthetic [--device cpu|cuda] [--bp-grid capture|small]":
        ["{py} -m bench.perf sweep --help"],
    ".venv/bin/python -m bench.perf correlate --device cuda --out results": ["{py} -m bench.perf correlate --help"],
    # minutes (BP on the paper grid); tests/bench/harness/test_slurm_resources.py measures a small cell through it
    ".venv/bin/python -m bench.perf memory --root data/synthetic --cells mm2fsk_d10 bp_d05 bp_full --grids cell bp_cpu":
        ["{py} -m bench.perf memory --help"],
    # new frames of every capture, minutes on the CPU; test_perf_skips_gpu runs its parts
    ".venv/bin/python -m bench.perf skips-gpu --root data/synthetic --device cuda":
        ["{py} -m bench.perf skips-gpu --help"],
    ".venv/bin/python -m bench.perf skips-gpu --root data/synthetic --device cpu --cases bp_d05,bp_full "
    "--variants auto": ["{py} -m bench.perf skips-gpu --help"],
    "python -m bench.perf": ["{py} -m bench.perf --help"],           # lists the benchmarks
    "python -m bench.perf <name>": ["{py} -m bench.perf --help"],
    r"python -m bench.perf correlate\|frames\|stream\|sweep\|overhead\|memory\|fill\|skips\|skips-gpu ... [--out DIR]":
        [f"{{py}} -m bench.perf {name} --help"
         for name in ("correlate", "frames", "stream", "sweep", "overhead", "memory", "fill", "skips", "skips-gpu")],
    "python -m bench.stress [--out DIR]": ["{py} -m bench.stress --help"],
    ".venv/bin/python -m bench.stress": ["{py} -m bench.stress --help"],
    ".venv/bin/python -m bench.stress --quick --out /tmp/stress": ["{py} -m bench.stress --help"],   # 30-40 s
    ".venv/bin/python -m bench.stress --out results/stress": ["{py} -m bench.stress --help"],
    # measured here on the CPU (quick sizes), merged into a copy of the committed report; the two commands in one
    "python -m bench.stress --precision-only --out /tmp/gpu": STRESS_PRECISION,
    ".venv/bin/python -m bench.stress --add-precision /tmp/gpu/precision.csv --out results/stress": STRESS_PRECISION,
    "python -m pytest -m cuda tests/methods/test_correlate.py tests/methods/test_methods_api.py tests/methods/backends/test_gpu_prior_depth.py":
        ["{py} -m pytest -m cuda --collect-only -q tests/methods/test_correlate.py tests/methods/test_methods_api.py "
         "tests/methods/backends/test_gpu_prior_depth.py"],
}

EXIT_USER, EXIT_HYDRA, EXIT_PIPE = 2, 1, 141
NO_GPU = "device=cuda only fails where Warp sees no GPU"
# (id, command, exit code, the one stderr line; ending in a space: its beginning). {file}: a regular file,
# {missing}: a path that does not exist, {empty}: an empty folder, {tmp}: a fresh folder.
MISTAKES = [
    ("bench-cuda", "{py} -m bench device=cuda dataset=maroon dataset.root={empty} hydra.run.dir={tmp}/run",
     EXIT_USER, "error: device=cuda: Warp sees no CUDA device (use device=cpu or device=auto)"),
    ("bench-device", "{py} -m bench device=gpu dataset=maroon dataset.root={empty} hydra.run.dir={tmp}/run",
     EXIT_USER, "error: device=gpu: unknown device (choose from cpu, cuda, auto, warp-cpu)"),
    ("synth-cuda", "{py} -m bench.synth --out {tmp}/synth --device cuda",
     EXIT_USER, "error: --device cuda: Warp sees no CUDA device (use --device cpu or --device auto)"),
    ("bench-missing-root", "{py} -m bench dataset=maroon dataset.root={missing} hydra.run.dir={tmp}/run",
     EXIT_USER, "error: {missing}: "),
    ("bench-run-dir", "{py} -m bench hydra.run.dir={file}/run", EXIT_USER,
     "error: hydra.run.dir={file}/run: cannot create a directory there: {file} is a file"),
    ("bench-store", "{py} -m bench dataset=maroon dataset.root={empty} store.dir={file} hydra.run.dir={tmp}/run",
     EXIT_USER, "error: store.dir={file}: cannot create a directory there: {file} is a file"),
    ("bench-modes", "{py} -m bench -m experiment=table2 --cfg job", EXIT_USER,
     "error: python -m bench: --multirun and --cfg cannot be combined (use one of them)"),
    ("bench-flag", "{py} -m bench --bogus", EXIT_USER,
     "error: unrecognized arguments: --bogus (see python -m bench --help)"),
    ("tables-runtime", "{py} -m bench.report.tables runtime", EXIT_USER,
     "error: {repo}/results/runtime: no committed results for runtime: run `python -m bench -m experiment=runtime`"
     " and pass its sweep root with --results DIR"),
    ("tables-missing", "{py} -m bench.report.tables table3 --results {missing}", EXIT_USER,
     "error: {missing}: results path does not exist"),
    ("tables-not-csv", "{py} -m bench.report.tables table3 --results {repo}/results/table1.md", EXIT_USER,
     "error: {repo}/results/table1.md: not a results CSV: no column "),
    ("tables-empty", "{py} -m bench.report.tables table2 --results {empty}", EXIT_USER,
     "error: {empty}: no results.csv and no */results.csv"),
    ("tables-csv-dir", "{py} -m bench.report.tables table1 --csv {empty}", EXIT_USER,
     "error: {empty}: output file is a directory"),
    ("tables-name", "{py} -m bench.report.tables tabel3", EXIT_USER,
     "error: argument table: invalid choice: 'tabel3' (choose from 'table1', 'table2', 'table3', 'beyond', 'runtime') "
     "(see python -m bench.report.tables --help)"),
    ("sweep-missing", "{py} -m bench.report.merge {missing}", EXIT_USER, "error: {missing}: sweep root does not exist"),
    ("sweep-empty", "{py} -m bench.report.merge {empty}", EXIT_USER, "error: {empty}: no job wrote */results.csv"),
    ("inspect-missing", "{py} -m bench.maroon.inspect_capture {missing}", EXIT_USER, "error: {missing}: "),
    ("inspect-file", "{py} -m bench.maroon.inspect_capture {file}", EXIT_USER,
     "error: {file}: dataset root is not a directory"),
    ("inspect-args", "{py} -m bench.maroon.inspect_capture", EXIT_USER,
     "error: the following arguments are required: root (see python -m bench.maroon.inspect_capture --help)"),
    ("synth-object", "{py} -m bench.synth --out {tmp}/synth --objects nope", EXIT_USER,
     "error: unknown object(s) nope; known: "),
    ("synth-out", "{py} -m bench.synth --out {file}/synth --objects 01_plate", EXIT_USER,
     "error: {file}/synth: cannot write the dataset there (Not a directory)"),
    ("perf-cuda", "{py} -m bench.perf correlate --device cuda --out {tmp}/perf", EXIT_USER,
     "error: --device cuda: Warp sees no CUDA device (use --device cpu or --device auto)"),
    ("perf-repeat", "{py} -m bench.perf correlate --repeat 0", EXIT_USER,
     "error: argument --repeat: must be at least 1, got 0 (see python -m bench.perf correlate --help)"),
    ("perf-out", "{py} -m bench.perf correlate --sizes small --out {file}", EXIT_USER,
     "error: {file}: output directory is a file"),
    ("perf-frames-device", "{py} -m bench.perf frames --device gpu", EXIT_USER,
     "error: argument --device: invalid choice: 'gpu' (choose from 'cpu', 'cuda', 'auto', 'warp-cpu') "
     "(see python -m bench.perf frames --help)"),
    ("perf-frames-cuda", "{py} -m bench.perf frames --device cuda --out {tmp}/perf", EXIT_USER,
     "error: --device cuda: Warp sees no CUDA device (use --device cpu or --device auto)"),
    ("perf-sweep-args", "{py} -m bench.perf sweep", EXIT_USER,
     "error: the following arguments are required: --root (see python -m bench.perf sweep --help)"),
    ("perf-sweep-missing", "{py} -m bench.perf sweep --root {missing}", EXIT_USER,
     "error: {missing}: dataset root does not exist"),
    ("perf-sweep-empty", "{py} -m bench.perf sweep --root {empty} --out {tmp}/perf", EXIT_USER,
     "error: {empty}: no captures found (expected folders <object>/<distance_cm>/)"),
    ("stress-out", "{py} -m bench.stress --quick --out {file}", EXIT_USER, "error: {file}: output directory is a file"),
    ("stress-csv", "{py} -m bench.stress --add-precision {missing} --out {empty}", EXIT_USER,
     "error: {missing}: precision CSV does not exist"),
    ("stress-no-report", "{py} -m bench.stress --add-precision {file} --out {empty}", EXIT_USER,
     "error: {empty}: no stress report to merge into (missing precision.csv, "),
    ("stress-not-precision", "{py} -m bench.stress --add-precision {repo}/results/stress/wrapping.csv "
     "--out {repo}/results/stress", EXIT_USER, "error: {repo}/results/stress/wrapping.csv: not a precision CSV: "),
    ("stress-modes", "{py} -m bench.stress --precision-only --add-precision x.csv", EXIT_USER,
     "error: argument --add-precision: not allowed with argument --precision-only (see python -m bench.stress --help)"),
    ("demo-flag", "{py} -m bench.demo --bogus", EXIT_USER,
     "error: unrecognized arguments: --bogus (see python -m bench.demo --help)"),
    ("run-sh-job", "bash run.sh bogus", EXIT_USER,
     "error: bash run.sh: unknown job 'bogus' (usage: bash run.sh demo|test|setup [args...])"),
]
# Hydra's own config errors keep Hydra's wording (the options of the group, several lines) and exit 1.
# (test_app checks the options listed for a misspelt group.)
HYDRA_MISTAKES = [("bench-key", "{py} -m bench devcie=cpu", "Could not override 'devcie'")]


DOC_PAGES = [REPO / "README.md", *sorted((REPO / "docs" / "guide").glob("*.md"))]


def doc_commands(text: str) -> set[str]:
    """The commands a page shows: lines of its ```bash blocks (comments dropped) and the inline code spans of
    its prose that start with `python -m`, `.venv/bin/python -m` or `bash run.sh`, whitespace collapsed."""
    commands = set()
    for block in re.findall(r"```bash\n(.*?)```", text, re.S):
        for line in block.splitlines():
            command = re.split(r"\s#\s", line.strip())[0].strip()
            if command and not command.startswith("#"):
                commands.add(" ".join(command.split()))
    prose = re.sub(r"```.*?```", "", text, flags=re.S)
    for span in re.findall(r"`([^`]+)`", prose):
        span = " ".join(span.split())
        if re.match(r"(\.venv/bin/)?python -m |bash run\.sh", span):
            commands.add(span)
    return commands


def _setup_done() -> bool:
    """`bash run.sh` would skip its set-up (else it installs: not something a test does)."""
    stamp = REPO / ".venv" / f".installed-{hashlib.sha256((REPO / 'pyproject.toml').read_bytes()).hexdigest()[:16]}"
    libusb = subprocess.run("ldconfig -p | grep -q libusb-1.0.so.0", shell=True).returncode == 0
    return stamp.is_file() and libusb


def _run(commands: list[str], paths: dict[str, Path]) -> tuple[int, str, str, str]:
    """Run commands in order in the checkout, up to the first failure: (exit code, stdout, stderr, command)."""
    for template in commands:
        command = template.format(py=shlex.quote(PY), **{k: shlex.quote(str(v)) for k, v in paths.items()})
        done = subprocess.run(command, shell=True, cwd=REPO, capture_output=True, text=True, timeout=TIMEOUT_S)
        if done.returncode != 0:
            break
    return done.returncode, done.stdout, done.stderr, command


def _selected(request, argname: str) -> set[str]:
    """The parameters of this module's selected tests (so that `-k` runs only what it selects)."""
    return {item.callspec.params[argname] for item in request.session.items
            if item.module is request.module and hasattr(item, "callspec") and argname in item.callspec.params}


def _paths(base: Path, synth_root: Path) -> dict[str, Path]:
    base.mkdir(parents=True)
    (base / "empty").mkdir()
    (base / "tmp").mkdir()
    (base / "file.txt").write_text("not what was asked for\n")
    return {"synth": synth_root, "repo": REPO, "tmp": base / "tmp", "empty": base / "empty",
            "file": base / "file.txt", "missing": base / "does" / "not" / "exist"}


def _run_all(jobs: dict[str, list[str]], base: Path, request) -> dict[str, tuple]:
    """Each distinct list of commands once, in its own folders, two at a time:
    name -> ((exit code, stdout, stderr, command), paths). The synth_root fixture is built only when needed."""
    distinct = sorted({tuple(commands) for commands in jobs.values()})
    needs_synth = any("{synth}" in command for commands in distinct for command in commands)
    synth_root = request.getfixturevalue("synth_root") if needs_synth else base / "no-synth-root"
    paths = {commands: _paths(base / str(i), synth_root) for i, commands in enumerate(distinct)}
    with ThreadPoolExecutor(max_workers=2) as pool:
        futures = {commands: pool.submit(_run, list(commands), paths[commands]) for commands in distinct}
        done = {commands: (future.result(), paths[commands]) for commands, future in futures.items()}
    return {name: done[tuple(commands)] for name, commands in jobs.items()}


@pytest.fixture(scope="module")
def doc_results(request, tmp_path_factory):
    wanted = _selected(request, "command") & set(DOC_RUNS)
    if not _setup_done():
        wanted = {c for c in wanted if not c.startswith("bash run.sh")}
    return _run_all({c: DOC_RUNS[c] for c in wanted}, tmp_path_factory.mktemp("docs"), request)


@pytest.fixture(scope="module")
def mistake_results(request, tmp_path_factory):
    wanted = _selected(request, "name")
    rows = {name: [command] for name, command, *_ in MISTAKES + HYDRA_MISTAKES if name in wanted}
    return _run_all(rows, tmp_path_factory.mktemp("mistakes"), request)


def test_doc_commands_are_all_covered():
    assert len(DOC_PAGES) > 5, "docs/guide/ has no pages"
    shown = {command for page in DOC_PAGES for command in doc_commands(page.read_text(encoding="utf-8"))}
    unrun, stale = sorted(shown - set(DOC_RUNS)), sorted(set(DOC_RUNS) - shown)
    assert not unrun, f"commands of README.md and docs/guide/ this test does not run (add them to DOC_RUNS): {unrun}"
    assert not stale, f"DOC_RUNS entries no page shows any more: {stale}"


@pytest.mark.parametrize("command", sorted(DOC_RUNS))
def test_doc_command_runs(command, doc_results):
    if command not in doc_results:
        pytest.skip("bash run.sh would install its set-up first")
    (code, stdout, stderr, ran), _ = doc_results[command]
    assert code == 0, f"{ran}\n{stdout[-2000:]}\n{stderr[-2000:]}"
    assert "Traceback" not in stderr, stderr


@pytest.mark.parametrize("name", [m[0] for m in MISTAKES])
def test_mistake_ends_in_one_line(name, mistake_results):
    _, _, expected_code, expected = next(m for m in MISTAKES if m[0] == name)
    if "cuda" in name and cuda_seen():
        pytest.skip(NO_GPU)
    if name == "tables-runtime" and (REPO / "results" / "runtime").exists():
        pytest.skip("results/runtime is committed")
    (code, _, stderr, ran), paths = mistake_results[name]
    expected = expected.format(**{k: str(v) for k, v in paths.items()})
    lines = stderr.splitlines()
    assert code == expected_code, f"{ran}: exit {code}\n{stderr}"
    assert len(lines) == 1 and lines[0].startswith("error: "), f"{ran}: not one line:\n{stderr}"
    if expected.endswith(" "):
        assert lines[0].startswith(expected), f"{ran}:\n{lines[0]}\nexpected to begin with: {expected}"
    else:
        assert lines[0] == expected, f"{ran}:\n{lines[0]}\nexpected: {expected}"


@pytest.mark.parametrize("name", [m[0] for m in HYDRA_MISTAKES])
def test_hydra_config_mistake_lists_without_traceback(name, mistake_results):
    expected = next(m[2] for m in HYDRA_MISTAKES if m[0] == name)
    (code, _, stderr, ran), _ = mistake_results[name]
    assert code == EXIT_HYDRA and expected in stderr and "Traceback" not in stderr, f"{ran}:\n{stderr}"


def test_benchmarks_write_under_outputs_by_default():
    """The tracked results/ is written only when a command is told to (`--out results...`): every benchmark's
    default folder is the common one, under outputs/."""
    import importlib

    from bench.perf import common
    from bench.perf.__main__ import COMMANDS
    from bench.stress import __main__ as stress

    assert common.DEFAULT_OUT.parts[0] == "outputs" and stress.DEFAULT_OUT.parts[0] == "outputs"
    for module, _ in COMMANDS.values():
        module = importlib.import_module(f"bench.perf.{module}")
        assert getattr(module, "DEFAULT_OUT", common.DEFAULT_OUT) == common.DEFAULT_OUT, module.__name__


@pytest.mark.parametrize("argv", [["bench.report.tables", "table3"], ["bench", "--help"],
                                  ["bench", "dataset=maroon", "dataset.root={synth}", "dataset.captures=[01_plate/30]",
                                   "method=2fsk", "freq=d05", "prior=none", "store.dir=null", "hydra.run.dir={tmp}"]],
                         ids=["tables", "bench-help", "bench-run"])
def test_closed_stdout_ends_quietly(argv, request, tmp_path):
    """`... | head -1`: stdout's reader is gone before the first write (for a run: its log lines and its progress
    line, inside Hydra's job); exit 141 (as SIGPIPE), nothing on stderr."""
    if any("{synth}" in arg for arg in argv):
        paths = {"synth": request.getfixturevalue("synth_root"), "tmp": tmp_path / "run"}
        argv = [arg.format(**paths) for arg in argv]
    proc = subprocess.Popen([PY, "-m", *argv], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    proc.stdout.close()                  # the reader exits at once (before the command has imported anything)
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=TIMEOUT_S) == EXIT_PIPE, stderr
    assert stderr == ""
