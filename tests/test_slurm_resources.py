"""Memory per SLURM job from its cell (bench.slurm_resources): the model against a real job's measured peak, and
how the launcher's `mem_gb` setting is read."""
from __future__ import annotations

import pytest
from hydra import compose, initialize_config_dir

from bench import app, slurm_resources
from bench.app import CONFIG_DIR
from bench.perf_memory import job_peak_mib_measured
from bench.slurm_resources import job_mem_gb, job_peak_mib


def _cfg(*overrides: str):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides))


def test_frames_held_bound_is_the_apps():
    assert slurm_resources.CAPTURES_KEPT == app.CAPTURES_KEPT == app.GROUND_TRUTHS_KEPT


@pytest.mark.parametrize("cell", [["cell=mm2fsk_d10"], ["cell=bp_d05", "grid=bp_cpu"]], ids=["mm2fsk", "bp_small"])
def test_model_covers_the_measured_peak_of_a_small_cell(synth_root, cell):
    overrides = [*cell, "dataset=maroon", f"dataset.root={synth_root}"]
    peak_mib, _ = job_peak_mib_measured(overrides)
    model_mib = job_peak_mib(_cfg(*overrides), captures=2)
    assert model_mib >= peak_mib, (model_mib, peak_mib)            # the fit itself stays above what was measured
    assert model_mib <= 1.5 * peak_mib, (model_mib, peak_mib)      # ... and is a fit, not a blanket figure
    assert job_mem_gb(_cfg(*overrides), captures=2) * 1024 >= slurm_resources.MARGIN * peak_mib


def test_model_grows_with_what_a_job_holds():
    small, paper = _cfg("cell=bp_d05", "grid=bp_cpu"), _cfg("cell=bp_d05")
    assert job_peak_mib(paper, 8) > job_peak_mib(small, 8)                          # voxels of the compute grid
    assert job_peak_mib(_cfg("cell=bp_full"), 8) >= job_peak_mib(paper, 8)         # many frequencies
    fsk = _cfg("cell=mm2fsk_d10")
    assert job_peak_mib(fsk, 8) > job_peak_mib(fsk, 1)
    assert job_peak_mib(fsk, 100) == job_peak_mib(fsk, slurm_resources.CAPTURES_KEPT)   # the app's caches are bounded
    assert job_peak_mib(_cfg("cell=mm2fsk_d10", "dataset.frame=all"), 1) == job_peak_mib(fsk, 100)


def test_mem_gb_setting():
    cfg = _cfg("cell=mm2fsk_d10")
    assert job_mem_gb(cfg, 8, 12) == 12                         # a number: asked for as it is
    assert job_mem_gb(cfg, 8, None) is None                     # null: none asked (mem_per_cpu, cluster default)
    assert job_mem_gb(cfg, 8, 0) == job_mem_gb(cfg, 8) >= slurm_resources.MIN_GB
    assert job_mem_gb(_cfg("cell=mm2fsk_d10", "device=cuda"), 8) == job_mem_gb(cfg, 8) + slurm_resources.CUDA_HOST_GB
