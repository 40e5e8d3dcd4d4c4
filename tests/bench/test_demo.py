"""The main job (bench.demo): outputs under --out, tracked results/ only with --update-results, a failing sweep
ends in its own reason. The sweeps themselves are tested in test_app.py; here they are replaced by a stand-in."""
from __future__ import annotations

import sys

import pandas as pd
import pytest

from bench import demo


def _fake_sweep(experiment, root, out, store, synth="realistic", distances_cm=None, depth_errors=False):
    """What a finished sweep leaves in its root (bench.report.merge), in miniature."""
    folder = out / experiment
    folder.mkdir(parents=True)
    for name in demo.REPORT_FILES:
        (folder / name.format(table=experiment)).write_text(f"{experiment}\n")
    if depth_errors:
        (folder / "depth_errors").mkdir()
        (folder / "depth_errors" / "01_plate_30_000000.png").write_bytes(b"png")
    rows = pd.DataFrame({"object": ["01_plate"], "distance": [30], "frame": [0], "method": ["mm2fsk"], "freq": ["d10"],
                         "prior": ["photogrammetry" if experiment == "table2" else "realsense"],
                         "grid": ["from_capture"],
                         **{m: [0.1] for m in ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm")}, "timing": ["alone"],
                         "cached": [False]})
    rows.to_csv(folder / "results.csv", index=False)
    return rows


def _small_capture(root, synth, distances_cm=None):
    """The one capture the fake sweeps' rows name, small (16 frequencies): the agreement report measures it."""
    from bench.synth import SynthConfig, generate_capture

    generate_capture(root, "01_plate", 30, SynthConfig(frequency_points=16))


def _main(monkeypatch, tmp_path, *args):
    monkeypatch.setattr(demo, "generate_dataset", _small_capture)
    monkeypatch.setattr(demo, "sweep", _fake_sweep)
    monkeypatch.setattr(demo, "report_page", lambda out: out / "report.html")      # tested in test_report.py
    monkeypatch.setattr(sys, "argv", ["bench.demo", "--root", str(tmp_path / "data"), "--out", str(tmp_path / "out"),
                                      "--store", str(tmp_path / "store"), "--results", str(tmp_path / "results"),
                                      *args])
    return demo.main()


def test_outputs_stay_under_out(monkeypatch, tmp_path):
    assert _main(monkeypatch, tmp_path) == 0
    assert not (tmp_path / "results").exists()
    assert {p.name for p in (tmp_path / "out").iterdir()} == {"table1.csv", "table1.md", "table2", "table3"}


def test_the_preset_and_distances_reach_generation_and_every_sweep(monkeypatch, tmp_path):
    seen = []
    monkeypatch.setattr(demo, "generate_dataset", lambda root, synth, distances_cm: seen.append(("data", synth,
                                                                                                 distances_cm)))
    monkeypatch.setattr(demo, "sweep", lambda *a, synth, distances_cm, depth_errors: (
        seen.append((a[0], synth, distances_cm, depth_errors)), _fake_sweep(*a))[1])
    monkeypatch.setattr(demo, "report_page", lambda out: out / "report.html")
    monkeypatch.setattr(sys, "argv", ["bench.demo", "--root", str(tmp_path / "data"), "--out", str(tmp_path / "out"),
                                      "--store", str(tmp_path / "store"), "--synth", "ideal", "--distances", "30",
                                      "45"])
    assert demo.main() == 0
    # the depth-error figures only where --update-results publishes them (the report's panels show table3's)
    assert seen == [("data", "ideal", [30, 45]), ("table2", "ideal", [30, 45], False),
                    ("table3", "ideal", [30, 45], False)]
    objects, distances = demo.demo_captures([30, 45])
    assert distances == [30, 45] and "01_plate" in objects
    assert demo.demo_captures(None)[1] == [30]                  # configs/dataset/synthetic.yaml


def test_update_results_copies_tables_plots_and_baselines(monkeypatch, tmp_path):
    assert _main(monkeypatch, tmp_path, "--update-results") == 0
    results = tmp_path / "results"
    assert {p.name for p in results.iterdir()} == {"table1.csv", "table1.md", "table2", "table3", "agreement.md"}
    assert (results / "table3" / "runtime_vs_error.png").is_file()
    report = (results / "agreement.md").read_text()
    assert "| MM-2FSK Δ10.0 | 0/1 | 0.10 | 0.82 |" in report                        # from the sweep rows
    assert "## Placement against" in report and "| 01_plate | 30." in report       # measured on the capture
    assert (results / "table3" / "depth_errors" / "01_plate_30_000000.png").is_file()
    baseline = pd.read_csv(results / "table2" / "results.csv")
    assert "cached" not in baseline and list(baseline.timing) == ["alone"]


def test_a_failing_sweep_ends_in_its_own_reason(tmp_path, capsys):
    root = tmp_path / "not_a_folder"
    root.write_text("")
    with pytest.raises(demo.SweepFailed, match=f"the table2 sweep failed \\(exit 2\\): {root}: dataset root is "
                                               "not a directory; job logs: "):
        demo.sweep("table2", root, tmp_path / "out", tmp_path / "store")
    assert f"error: {root}: dataset root is not a directory" in capsys.readouterr().err   # passed through


def test_the_reason_of_a_hydra_error_is_its_headline_or_exception():
    hint = "Set the environment variable HYDRA_FULL_ERROR=1 for a complete stack trace."
    assert demo._reason(["Could not override 'x'.", "To append use +x=1", "", hint]) == "Could not override 'x'."
    traceback = ["Error executing job with overrides: ['cell=bp_d05']", "Traceback (most recent call last):",
                 '  File "bench/harness/app.py", line 1, in main', "RuntimeError: out of memory", "", hint]
    assert demo._reason(traceback) == "RuntimeError: out of memory"
    assert demo._reason(["warning: slow", "error: data/x: no captures found"]) == "data/x: no captures found"


def test_the_demo_says_up_front_how_long_it_takes_and_which_step_is_long(tmp_path):
    from bench.demo import demo_captures, plan

    objects, _ = demo_captures([30])
    missing = plan(tmp_path / "none", tmp_path / "store", [30])
    assert f"generating {len(objects)} of {len(objects)} captures" in missing and "min on two quiet cores" in missing
    assert "the long step is table3's BP_max" in missing and "reused" not in missing
    (tmp_path / "store" / "cells").mkdir(parents=True)
    (tmp_path / "store" / "cells" / "x.json").write_text("{}")
    assert "are reused" in plan(tmp_path / "none", tmp_path / "store", [30])


def test_importing_the_demo_is_light_for_the_report_s_spawned_workers():
    """Each picture worker of the report is a spawned process that imports the demo again as its __main__: the
    demo's own imports stay out of that (pandas, SciPy and the report's tables cost ~1 s of CPU per worker)."""
    import subprocess
    from pathlib import Path

    heavy = ("pandas", "scipy", "bench.report.tables", "bench.report.agreement", "omegaconf", "matplotlib")
    code = f"import sys, bench.demo; print([m for m in {heavy!r} if m in sys.modules])"
    found = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120,
                           cwd=Path(demo.__file__).resolve().parents[1])
    assert found.returncode == 0, found.stderr[-2000:]
    assert found.stdout.strip() == "[]"
