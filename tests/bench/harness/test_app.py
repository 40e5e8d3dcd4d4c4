"""The run contract of `python -m bench` (DESIGN.md section 3) and the Hydra configs."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from PIL import Image

from bench.harness.app import CONFIG_DIR, run
from bench.harness.results import RESULT_COLUMNS
from bench.harness.sizing import contended

CONFIG_GROUPS = {group: sorted(p.stem for p in (CONFIG_DIR / group).glob("*.yaml"))
                 for group in ("dataset", "method", "freq", "prior", "grid")}


def _bench(*overrides: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *overrides], capture_output=True, text=True, timeout=300)


def test_run_writes_results_and_depth_images(synth_root, tmp_path):
    out = tmp_path / "run"
    result = _bench("dataset=maroon", f"dataset.root={synth_root}", "method=mm2fsk", "freq=d10",
                    "prior=realsense", "store.dir=null", f"hydra.run.dir={out}")
    assert result.returncode == 0, result.stderr
    table = pd.read_csv(out / "results.csv")
    assert list(table.columns[:len(RESULT_COLUMNS)]) == RESULT_COLUMNS
    assert {"t_prior_ms", "t_correlate_ms", "grid", "hostname", "code_version"} <= set(table.columns)
    assert not table.cached.any()
    assert sorted(table.object) == ["01_plate", "03_sphere"]
    plate = table.set_index("object").loc["01_plate"]
    assert plate.f_GHz == "72.0000 82.0000" and plate.device == "cpu" and plate.valid_px > 1000
    # a single run has the machine, unless other processes used the cores meanwhile (bench.harness.sizing)
    assert plate.timing == ("contended" if contended(plate.load_1m, plate.others_cores) else "alone")
    assert plate.cpu_ms > 0 and plate.call_ms >= plate.runtime_ms and plate.runtime_runs == 1
    assert plate.P_cm < 0.2 and plate.C_s_cm < 0.2                         # MM-2FSK d10 on a plate: ~mm
    depth = np.asarray(Image.open(out / "depth" / "01_plate_30_000000.png"))
    info = json.loads((out / "depth" / "01_plate_30_000000.json").read_text())
    assert depth.dtype == np.uint16 and depth.shape == (info["grid_size"][1], info["grid_size"][0])
    assert set(info) >= {"bb_min", "bb_max", "grid_size"}
    assert np.count_nonzero(depth) == plate.valid_px
    assert abs(np.median(depth[depth > 0]) - 300) <= 2                     # plate front at 30 cm


@pytest.mark.parametrize("overrides, message", [
    (["dataset=maroon"], "dataset.root' is required"),
    (["dataset=maroon", "dataset.root={missing}"], "{missing}: dataset root does not exist"),
    (["dataset.root={missing}"], "{missing}: dataset root does not exist"),     # synthetic config, other root
    (["dataset=maroon", "dataset.root={file}"], "{file}: dataset root is not a directory"),
    (["dataset=synthetic", "dataset.root={file}"], "{file}: dataset root is not a directory"),
    (["dataset=maroon", "dataset.root={synth_root}", "method=2fsk", "prior=realsense"], "use method='mm2fsk'"),
    # checked before any capture is generated (synthetic data asked for a missing root), by configuration name
    (["dataset=synthetic", "dataset.root={missing}", "method=3fsk", "freq=d10", "prior=none"],
     "3fsk needs a 3-frequency configuration, but freq='d10' selects 2 frequencies"),
])
def test_bad_settings_end_in_one_line_and_exit_2(synth_root, tmp_path, overrides, message):
    paths = {"missing": tmp_path / "data" / "nonexistent", "file": tmp_path / "file.txt", "synth_root": synth_root}
    paths["file"].write_text("not a dataset")
    result = _bench(*(o.format(**paths) for o in overrides), f"hydra.run.dir={tmp_path / 'run'}")
    assert result.returncode == 2 and message.format(**paths) in result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "data").exists()                  # a root nobody asked to generate is not created


@pytest.mark.parametrize("overrides, group", [(["-m", "experiment=tabel3"], "experiment"),
                                              (["cell=mm2fsk_d100"], "cell")])
def test_a_misspelt_experiment_or_cell_lists_the_options(tmp_path, overrides, group):
    result = _bench(*overrides, f"hydra.run.dir={tmp_path / 'run'}", f"hydra.sweep.dir={tmp_path / 'sweep'}")
    assert result.returncode != 0 and "Traceback" not in result.stderr
    assert f"Could not find '{group}/{overrides[-1].split('=')[1]}'" in result.stderr
    options = sorted(p.stem for p in (CONFIG_DIR / group).glob("*.yaml"))
    assert f"Available options in '{group}'" in result.stderr and all(f"\t{o}\n" in result.stderr for o in options)
    assert not (tmp_path / "run").exists() and not (tmp_path / "sweep").exists()       # nothing ran


@pytest.mark.parametrize("group", sorted(CONFIG_GROUPS))
def test_every_config_composes(group):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        for option in CONFIG_GROUPS[group]:
            cfg = compose(config_name="config", overrides=[f"{group}={option}"])
            assert cfg[group].name == option


def _experiment_cells(name: str) -> list[tuple[str, str, str, str]]:
    """(method, freq, prior, grid) of every job the experiment's sweep launches."""
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        params = compose(config_name="config", overrides=[f"experiment={name}"],
                         return_hydra_config=True).hydra.sweeper.params
        ((key, values),) = params.items()
        cells = []
        for value in values.split(","):
            cfg = compose(config_name="config", overrides=[f"experiment={name}", f"{key}={value}"])
            cells.append((cfg.method.name, cfg.freq.name, cfg.prior.name, cfg.grid.name))
    return cells


def test_experiments_sweep_the_papers_cells():
    two = ["d05", "d1", "d2", "d4", "d8", "d10"]
    assert _experiment_cells("table2") == [("mm2fsk", f, "photogrammetry", "from_capture") for f in two]
    table3 = _experiment_cells("table3")
    assert table3 == ([("bp", f, "none", "paper") for f in ("full", "d05", "d1", "d10")]
                      + [("2fsk", f, "none", "from_capture") for f in ("d05", "d1", "d10")]
                      + [("3fsk", f, "none", "from_capture") for f in ("d05_d10", "d1_d10", "d2_d10")]
                      + [("mm2fsk", f, "realsense", "from_capture") for f in ("d05", "d1", "d10")]
                      + [("prior_only", "d10", "realsense", "from_capture")])       # the depth camera alone
    runtime = _experiment_cells("runtime")
    assert set(table3) < set(runtime) and len(runtime) == len(set(runtime)) == 7 + 6 + 3 + 6 + 3 + 1
    beyond = _experiment_cells("beyond")        # Table III (its prior-only baseline last) and MM-3FSK x 3
    assert beyond == table3[:-1] + [("mm3fsk", f, "realsense", "from_capture")
                                    for f in ("d05_d10", "d1_d10", "d2_d10")] + table3[-1:]


def test_cells_and_experiments_compose():
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        for cell in sorted(p.stem for p in (CONFIG_DIR / "cell").glob("*.yaml")):
            cfg = compose(config_name="config", overrides=[f"cell={cell}"])
            assert cell == f"{cfg.method.name}_{cfg.freq.name}"
        paper = compose(config_name="config", overrides=["cell=bp_full", "grid=paper"])   # command line wins
        assert paper.grid.name == "paper"
        for launcher in ("local", "slurm"):
            cfg = compose(config_name="config", overrides=[f"hydra/launcher={launcher}"], return_hydra_config=True)
            assert cfg.hydra.launcher._target_.endswith(("JoblibLauncher", "SlurmLauncher"))


def _sweep(tmp_path, synth_root, launcher: str, freqs: str) -> pd.DataFrame:
    root = tmp_path / "sweep"
    result = _bench("-m", "experiment=table2", f"hydra.sweeper.params.freq='{freqs}'", f"hydra/launcher={launcher}",
                    "dataset=maroon", f"dataset.root={synth_root}", "dataset.captures=[01_plate/30]",
                    f"store.dir={tmp_path / 'store'}", f"hydra.sweep.dir={root}", "report.depth_errors=true")
    assert result.returncode == 0, result.stderr
    if launcher != "submitit_local":                                    # submitit keeps job output in its logs
        jobs = len(freqs.split(","))
        for num, freq in enumerate(freqs.split(","), 1):                 # one progress line per finished job
            assert f"[table2 {num}/{jobs}] mm2fsk_{freq}_photogrammetry: 1 capture, " in result.stdout
    return root


def test_joblib_sweep_merges_rows_and_writes_table_and_plots(synth_root, tmp_path):
    root = _sweep(tmp_path, synth_root, "local", "d8,d10")
    merged = pd.read_csv(root / "results.csv")
    assert sorted(merged.freq) == ["d10", "d8"] and not merged.cached.any()
    assert merged.P_cm.max() < 0.2                                       # MM-2FSK, ground-truth prior, plate
    assert "MM-2FSK Δ10.0" in (root / "table2.md").read_text()
    assert (root / "runtime_vs_error.png").stat().st_size > 0
    assert (root / "depth_errors" / "01_plate_30_000000.png").stat().st_size > 0
    assert (merged.timing == "parallel").all()                           # two jobs shared the machine
    again = pd.read_csv(_sweep(tmp_path, synth_root, "local", "d8,d10") / "results.csv")
    assert again.cached.all()                                            # the re-run computes nothing


def test_clean_timings_never_reuse_a_parallel_row(synth_root, tmp_path, monkeypatch):
    """A contended runtime from the store is re-measured by a run that needs clean timings; the clean row is kept.
    In-process with a fixed code version: other work in this tree must not change the store keys meanwhile."""
    monkeypatch.setattr("bench.harness.app.code_version", lambda: "0.1.0+fixed")
    monkeypatch.setattr("bench.harness.app.machine_load", lambda: 0.0)      # a quiet machine: 'alone' stays
    monkeypatch.setattr("bench.harness.sizing.busy_cpu_s", lambda: 0.0)     # no other process on the cores
    overrides = ["dataset=maroon", f"dataset.root={synth_root}", "dataset.captures=[01_plate/30]", "method=2fsk",
                 "freq=d05", "prior=none", f"store.dir={tmp_path / 'store'}"]
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", overrides=overrides)
    (first,) = run(cfg, tmp_path / "a", timing="parallel")
    (alone,) = run(cfg, tmp_path / "b", timing="alone")
    (reused,) = run(cfg, tmp_path / "c", timing="parallel")
    (again,) = run(cfg, tmp_path / "d", timing="alone")
    assert (first["timing"], first["cached"]) == ("parallel", False)
    assert (alone["timing"], alone["cached"]) == ("alone", False)            # re-measured, not reused
    assert (reused["timing"], reused["cached"]) == ("alone", True)           # the clean row serves later runs
    assert (again["timing"], again["cached"]) == ("alone", True)
    assert reused["runtime_ms"] == alone["runtime_ms"] != first["runtime_ms"]


@pytest.mark.slow
def test_submitit_local_sweep(synth_root, tmp_path):
    merged = pd.read_csv(_sweep(tmp_path, synth_root, "submitit_local", "d10") / "results.csv")
    assert list(merged.freq) == ["d10"] and merged.P_cm[0] < 0.2


@pytest.mark.parametrize("dataset", [[], ["dataset=synthetic"]], ids=["default", "synthetic asked"])
def test_a_foreign_dataset_root_is_never_written(synth_root, tmp_path, dataset):
    """`dataset.root=DIR` with the synthetic dataset config must not generate into a real dataset, even when
    synthetic data is asked for: it is read as it is."""
    root = tmp_path / "maroon"
    shutil.copytree(synth_root / "01_plate", root / "01_plate")      # captures, but no generator manifest
    before = sorted(p.relative_to(root) for p in root.rglob("*"))
    result = _bench(*dataset, f"dataset.root={root}", "method=2fsk", "freq=d05", "prior=none", "store.dir=null",
                    f"hydra.run.dir={tmp_path / 'run'}")
    assert result.returncode == 0, result.stderr
    assert sorted(p.relative_to(root) for p in root.rglob("*")) == before


def test_concurrent_runs_on_a_missing_synthetic_root_share_one_generation(tmp_path):
    """Two runs start at once on a missing root (with a crashed run's temp folder): both succeed on one dataset."""
    root = tmp_path / "synthetic"
    dead_pid = int(subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                                  text=True).stdout)
    (root / "01_plate" / f".30.tmp-{dead_pid}-0123abcd").mkdir(parents=True)
    runs = [subprocess.Popen([sys.executable, "-m", "bench", "dataset=synthetic", f"dataset.root={root}",
                              "dataset.generate.objects=[01_plate]", "synth=ideal", "method=2fsk", "freq=d05",
                              "prior=none",
                              "store.dir=null", f"hydra.run.dir={tmp_path / f'run{i}'}"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for i in range(2)]
    outputs = [run.communicate(timeout=600) for run in runs]
    assert [run.returncode for run in runs] == [0, 0], [err for _, err in outputs]
    logs = [(tmp_path / f"run{i}" / "app.log").read_text() for i in range(2)]
    assert sorted("01_plate/30: generated" in text for text in logs) == [False, True]     # generated once
    assert [p.name for p in root.rglob(".*") if p.is_dir()] == []                      # no temp folder left
    for i in range(2):
        assert pd.read_csv(tmp_path / f"run{i}" / "results.csv").valid_px[0] > 1000
