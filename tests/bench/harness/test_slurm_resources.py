"""Memory per SLURM job from its cell (bench.harness.resources): the model against a real job's measured peak, how
the launcher's `mem_gb` setting is read, and what the SLURM preset hands to sbatch."""
from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest
from hydra import compose, initialize_config_dir

from bench.harness import captures
from bench.harness import resources as slurm_resources
from bench.harness.app import CONFIG_DIR
from bench.harness.resources import job_mem_gb, job_peak_mib
from bench.perf.memory import job_peak_mib_measured


def _cfg(*overrides: str):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides))


def test_frames_held_bound_is_the_apps():
    assert slurm_resources.KEPT_MIB == captures.KEPT_MIB
    assert captures.Kept().limit_bytes == captures.KEPT_MIB * 2**20


@pytest.mark.parametrize("cell", [["cell=mm2fsk_d10"], ["cell=bp_d05", "grid=bp_cpu"]], ids=["mm2fsk", "bp_small"])
def test_model_covers_the_measured_peak_of_a_small_cell(synth_root, cell):
    overrides = [*cell, "dataset=maroon", f"dataset.root={synth_root}"]
    peak_mib, _ = job_peak_mib_measured(overrides)
    model_mib = job_peak_mib(_cfg(*overrides), captures=2)
    assert model_mib >= peak_mib, (model_mib, peak_mib)            # the fit itself stays above what was measured
    # ... and is a fit, not a blanket figure: within twice the peak, which moves with the machine's state (the same
    # job at the same commit on the development machine: 350-354 MiB in full test runs on 2026-11-25, 246-251 MiB
    # on 2026-11-26, cause not found), so 1.5x failed on a machine where the job needed less
    assert model_mib <= 2.0 * peak_mib, (model_mib, peak_mib)
    assert job_mem_gb(_cfg(*overrides), captures=2) * 1024 >= slurm_resources.MARGIN * peak_mib


def test_model_grows_with_what_a_job_holds():
    small, paper = _cfg("cell=bp_d05", "grid=bp_cpu"), _cfg("cell=bp_d05")
    assert job_peak_mib(paper, 8) > job_peak_mib(small, 8)                          # voxels of the compute grid
    assert job_peak_mib(_cfg("cell=bp_full"), 8) >= job_peak_mib(paper, 8)         # many frequencies
    fsk = _cfg("cell=mm2fsk_d10")
    assert job_peak_mib(fsk, 8) > job_peak_mib(fsk, 1)
    assert job_peak_mib(fsk, 100) > job_peak_mib(fsk, 16)                  # more captures kept in memory ...
    assert job_peak_mib(fsk, 1000) == job_peak_mib(fsk, 10_000)            # ... up to the caches' bound
    assert job_peak_mib(_cfg("cell=mm2fsk_d10", "dataset.frame=all"), 1) == job_peak_mib(fsk, 100)


def test_mem_gb_setting():
    cfg = _cfg("cell=mm2fsk_d10")
    assert job_mem_gb(cfg, 8, 12) == 12                         # a number: asked for as it is
    assert job_mem_gb(cfg, 8, None) is None                     # null: none asked (mem_per_cpu, cluster default)
    assert job_mem_gb(cfg, 8, 0) == job_mem_gb(cfg, 8) >= slurm_resources.MIN_GB
    assert job_mem_gb(_cfg("cell=mm2fsk_d10", "device=cuda"), 8) == job_mem_gb(cfg, 8) + slurm_resources.CUDA_HOST_GB


def test_launcher_asks_sbatch_for_the_cells_memory(synth_root, tmp_path):
    """The SLURM preset end to end up to sbatch (a stand-in that only answers with a job id): each job's submission
    script asks for its cell's memory, 2 GB more with a GPU. Every SLURM command the launcher touches is a fake
    (the session's PATH has none: tests/conftest.py)."""
    fake = tmp_path / "bin"
    fake.mkdir()
    (fake / "sbatch").write_text('#!/bin/sh\necho "Submitted batch job $$"\n')
    (fake / "squeue").write_text("#!/bin/sh\necho 1\n")          # jobs stay listed: the launcher waits for them
    (fake / "sinfo").write_text("#!/bin/sh\necho 16\n")         # CPUs of a node: cpus_per_task is not clipped
    for name in ("srun", "scancel"):                             # looked for before submitting; never run here
        (fake / name).write_text("#!/bin/sh\nexit 0\n")
    for tool in fake.iterdir():
        tool.chmod(0o755)
    env = {**os.environ, "PATH": f"{fake}:{os.environ['PATH']}", "BENCH_SLURM_LOCAL_PATHS": "1"}
    sweep = tmp_path / "sweep"
    proc = subprocess.Popen([sys.executable, "-m", "bench", "-m", "cell=mm2fsk_d10", "device=cpu,cuda",
                             "dataset=maroon", f"dataset.root={synth_root}", "hydra/launcher=slurm_cpu",
                             f"store.dir={tmp_path / 'store'}",
                             f"hydra.sweep.dir={sweep}"], env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    try:
        deadline = time.monotonic() + 180
        while len(scripts := sorted(sweep.glob(".submitit/*/*_submission.sh"))) < 2 and time.monotonic() < deadline:
            assert proc.poll() is None, proc.stderr.read().decode()
            time.sleep(0.5)
        time.sleep(0.5)                                            # the second script fully written
        asked = sorted(next(line for line in s.read_text().splitlines() if line.startswith("#SBATCH --mem="))
                       for s in scripts)
    finally:
        proc.kill()
        proc.wait()
    cpu = job_mem_gb(_cfg("cell=mm2fsk_d10"), 2)
    assert asked == sorted([f"#SBATCH --mem={cpu}GB", f"#SBATCH --mem={cpu + slurm_resources.CUDA_HOST_GB}GB"])
