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
        assert row["launch_s"] > 0 and 0 < row["outside_s"] < row["other_s"]   # the launcher's per-job set-up
    assert cold["ground_truth_s"] > 0 and kept["ground_truth_s"] > 0


def test_without_a_store_the_kept_run_reads_the_ground_truth_the_cold_run_kept(synth_root, monkeypatch):
    import bench.perf.experiment as experiment

    commands = []
    real = experiment.subprocess.run
    monkeypatch.setattr(experiment.subprocess, "run", lambda command, **kw: commands.append(command) or
                        real(command, **kw))
    cold, kept = measure("table3", synth_root, "cpu", ["cell=mm2fsk_d10"], repeat=1, no_store=True)
    assert (cold["store"], kept["store"]) == ("off", "off") and cold["rows"] == kept["rows"] == 2
    caches = [[arg for arg in command if arg.startswith("store.cache=")] for command in commands]
    assert all("store.dir=null" in command for command in commands) and len(caches) == 2
    assert caches[0] == caches[1] and len(caches[0]) == 1             # the kept run reads what the cold run kept
