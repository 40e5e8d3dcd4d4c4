"""What a job knows about its sweep: the number of jobs and whether its runtimes were measured alone."""
from __future__ import annotations

import pytest
from hydra.types import RunMode
from omegaconf import OmegaConf

from bench.harness.app import synthetic_asked
from bench.harness.sizing import JOBS_ENV, SweepSize, count_jobs, sweep_jobs, timing_mode

JOBLIB = "hydra_plugins.hydra_joblib_launcher.joblib_launcher.JoblibLauncher"
SLURM = "hydra_plugins.hydra_submitit_launcher.submitit_launcher.SlurmLauncher"
LOCAL = "hydra_plugins.hydra_submitit_launcher.submitit_launcher.LocalLauncher"
BASIC = "hydra._internal.core_plugins.basic_launcher.BasicLauncher"


def test_count_jobs_combines_config_params_and_command_line():
    assert count_jobs({"cell": "bp_d05,bp_d1,bp_d10"}, ["store.dir=x"]) == 3
    assert count_jobs({"freq": "d05,d1"}, ["method=2fsk,mm2fsk"]) == 4
    assert count_jobs({"freq": "d05,d1,d2"}, ["freq=d10"]) == 1                # the command line replaces a param
    assert count_jobs({}, []) == 1


@pytest.mark.parametrize("mode, launcher, jobs, expected", [
    (RunMode.RUN, {"_target_": JOBLIB, "n_jobs": 2}, None, "alone"),
    (RunMode.MULTIRUN, {"_target_": BASIC}, "13", "alone"),
    (RunMode.MULTIRUN, {"_target_": JOBLIB, "n_jobs": 2}, "13", "parallel"),
    (RunMode.MULTIRUN, {"_target_": JOBLIB, "n_jobs": 1}, "13", "alone"),
    (RunMode.MULTIRUN, {"_target_": JOBLIB, "n_jobs": 2}, "1", "alone"),        # a one-job sweep
    (RunMode.MULTIRUN, {"_target_": SLURM, "array_parallelism": 16}, "13", "parallel"),
    (RunMode.MULTIRUN, {"_target_": SLURM, "array_parallelism": 1}, "13", "alone"),
    (RunMode.MULTIRUN, {"_target_": LOCAL}, "13", "parallel"),
    (RunMode.MULTIRUN, {"_target_": "my.own.Launcher"}, None, "parallel"),      # unknown: assume contended
])
def test_timing_mode(monkeypatch, mode, launcher, jobs, expected):
    if jobs is None:
        monkeypatch.delenv(JOBS_ENV, raising=False)
    else:
        monkeypatch.setenv(JOBS_ENV, jobs)
    assert timing_mode(OmegaConf.create({"mode": mode, "launcher": launcher})) == expected


def test_joblib_with_every_core_is_parallel_on_a_multicore_machine(monkeypatch):
    monkeypatch.setattr("os.cpu_count", lambda: 2)
    monkeypatch.setenv(JOBS_ENV, "13")
    hydra_cfg = OmegaConf.create({"mode": RunMode.MULTIRUN, "launcher": {"_target_": JOBLIB, "n_jobs": -1}})
    assert timing_mode(hydra_cfg) == "parallel"
    monkeypatch.setattr("os.cpu_count", lambda: 1)
    assert timing_mode(hydra_cfg) == "alone"


@pytest.mark.parametrize("overrides, asked", [
    ([], True),                                                       # the default root of the default dataset
    (["method=2fsk"], True),
    (["dataset.root=/data/x"], False),                                # another root, synthetic not named
    (["dataset=synthetic", "dataset.root=/data/x"], True),
    (["dataset=maroon", "dataset.root=/data/x"], False),
    (["+dataset=synthetic", "++dataset.root=/data/x"], True),
])
def test_synthetic_data_is_generated_only_where_asked(overrides, asked):
    assert synthetic_asked(overrides) is asked


def test_an_uncountable_sweep_leaves_the_job_count_unknown(monkeypatch):
    monkeypatch.setenv(JOBS_ENV, "7")                                        # from an earlier sweep
    config = OmegaConf.create({"hydra": {"sweeper": {"params": {"cell": "glob(*)"}}, "overrides": {"task": []}}})
    SweepSize().on_multirun_start(config)
    assert sweep_jobs() is None
