"""Shared fixtures: small synthetic MAROON-format captures built once per test session.

* `synth_root`: a dataset root holding `01_plate/30` and `03_sphere/30` generated with the default
  `SynthConfig` (the `ideal` preset: 128 frequencies, clutter, noise; about 10 s on 2 cores, once per session).
* `results_root`: the same captures with the preset of the committed results (`realistic`; ~30 s, regression only).
* `synth_capture(object_name, distance_cm, **config_overrides) -> Path`: one custom capture, cached per
  configuration for the whole session (e.g. `frequency_points=16` for a fast capture, `depth_noise=False`).

Every test runs with SLURM's commands off PATH (tests/support/no_slurm.py), also where SLURM is installed, so a
test that touches one without faking it fails everywhere, not only on machines without SLURM; the opt-in
real-cluster test (BENCH_SLURM_TRY=1, tests/bench/harness/test_slurm.py) keeps them.
"""
from __future__ import annotations

import dataclasses
import os
import shutil
import tempfile
from pathlib import Path

import pytest
from no_slurm import path_without_slurm

_SHADOW_PATH = Path(tempfile.mkdtemp(prefix="bench-no-slurm-"))
_CACHE_HOME = Path(tempfile.mkdtemp(prefix="bench-cache-"))


def pytest_configure(config):
    # every cache of the package (bench.cachedir: the code version, kept ground truths, the generator's fits) in a
    # folder of this session, never the user's ~/.cache; subprocesses inherit it
    os.environ["XDG_CACHE_HOME"] = str(_CACHE_HOME)
    if os.environ.get("BENCH_SLURM_TRY") != "1":
        os.environ["PATH"] = path_without_slurm(os.environ.get("PATH", ""), _SHADOW_PATH)


def pytest_unconfigure(config):
    shutil.rmtree(_SHADOW_PATH, ignore_errors=True)
    shutil.rmtree(_CACHE_HOME, ignore_errors=True)

SYNTH_FIXTURE_CAPTURES = (("01_plate", 30), ("03_sphere", 30))


@pytest.fixture(scope="session")
def synth_root(tmp_path_factory):
    """Dataset root with the default-config captures listed in SYNTH_FIXTURE_CAPTURES."""
    from bench.synth import generate_capture  # imported here: the GPU machine runs tests without Open3D

    root = tmp_path_factory.mktemp("synth_default")
    for object_name, distance_cm in SYNTH_FIXTURE_CAPTURES:
        generate_capture(root, object_name, distance_cm)
    return root


@pytest.fixture(scope="session")
def results_root(tmp_path_factory):
    """Dataset root with SYNTH_FIXTURE_CAPTURES generated with the preset of the committed results (the demo's
    default, bench.synth.config.DEFAULT_PRESET): what tests/test_regression.py compares with results/."""
    from bench.synth import generate_capture
    from bench.synth.config import DEFAULT_PRESET, preset

    root = tmp_path_factory.mktemp("synth_results")
    for object_name, distance_cm in SYNTH_FIXTURE_CAPTURES:
        generate_capture(root, object_name, distance_cm, preset(DEFAULT_PRESET))
    return root


@pytest.fixture(scope="session")
def synth_capture(tmp_path_factory):
    """Factory: path of a capture generated with `SynthConfig(**config_overrides)`, one root per configuration."""
    from bench.synth import SynthConfig, generate_capture
    from bench.synth.config import capture_hash

    base = tmp_path_factory.mktemp("synth_custom")

    def make(object_name: str = "01_plate", distance_cm: int = 30, **config_overrides):
        config = dataclasses.replace(SynthConfig(), **config_overrides)
        root = base / capture_hash(config, object_name, distance_cm)
        return generate_capture(root, object_name, distance_cm, config)

    return make
