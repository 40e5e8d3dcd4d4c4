"""`python -m bench.perf experiment`: a whole sweep in a fresh process, its wall time split by stage."""
from __future__ import annotations

import pytest

from bench.perf.experiment import STAGES, measure


def test_an_experiment_is_timed_by_stage_cold_then_with_the_ground_truth_kept(synth_root):
    cold, kept = measure("table3", synth_root, "cpu", ["cell=2fsk_d05"], repeat=1)
    assert (cold["run"], kept["run"]) == ("cold", "kept") and cold["rows"] == kept["rows"] == 2
    for row in (cold, kept):
        spent = sum(row[f"{stage.replace(' ', '_')}_s"] for stage in STAGES)
        assert row["other_s"] == pytest.approx(row["wall_s"] - spent)
        assert row["methods_s"] >= row["method_runtime_s"] > 0 and row["metrics_s"] > 0
        assert row["composition_s"] > 0 and row["imports_s"] > 0 and row["reading_s"] > 0
    assert cold["ground_truth_s"] > 0 and kept["ground_truth_s"] > 0
