"""Shared fixtures: small synthetic MAROON-format captures built once per test session.

* `synth_root`: a dataset root holding `01_plate/30` and `03_sphere/30` generated with the default
  `SynthConfig` (the `ideal` preset: 128 frequencies, clutter, noise; about 10 s on 2 cores, once per session).
* `results_root`: the same captures with the preset of the committed results (`realistic`; ~30 s, regression only).
* `synth_capture(object_name, distance_cm, **config_overrides) -> Path`: one custom capture, cached per
  configuration for the whole session (e.g. `frequency_points=16` for a fast capture, `depth_noise=False`).
"""
from __future__ import annotations

import dataclasses

import pytest

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
