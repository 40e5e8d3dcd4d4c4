"""The run contract of `python -m bench` (DESIGN.md section 3) and the Hydra configs."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hydra import compose, initialize_config_dir
from PIL import Image

from bench.app import CONFIG_DIR
from bench.results import RESULT_COLUMNS

CONFIG_GROUPS = {group: sorted(p.stem for p in (CONFIG_DIR / group).glob("*.yaml"))
                 for group in ("dataset", "method", "freq", "prior", "grid")}


def _bench(*overrides: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "bench", *overrides], capture_output=True, text=True, timeout=300)


def test_run_writes_results_and_depth_images(synth_root, tmp_path):
    out = tmp_path / "run"
    result = _bench("dataset=maroon", f"dataset.root={synth_root}", "method=mm2fsk", "freq=d10",
                    "prior=realsense", f"hydra.run.dir={out}")
    assert result.returncode == 0, result.stderr
    table = pd.read_csv(out / "results.csv")
    assert list(table.columns[:len(RESULT_COLUMNS)]) == RESULT_COLUMNS
    assert {"t_prior_ms", "t_correlate_ms"} <= set(table.columns)
    assert sorted(table.object) == ["01_plate", "03_sphere"]
    plate = table.set_index("object").loc["01_plate"]
    assert plate.f_GHz == "72.0000 82.0000" and plate.device == "cpu" and plate.valid_px > 1000
    assert plate.P_cm < 0.2 and plate.C_s_cm < 0.2                         # MM-2FSK d10 on a plate: ~mm
    depth = np.asarray(Image.open(out / "depth" / "01_plate_30_000000.png"))
    info = json.loads((out / "depth" / "01_plate_30_000000.json").read_text())
    assert depth.dtype == np.uint16 and depth.shape == (info["grid_size"][1], info["grid_size"][0])
    assert set(info) >= {"bb_min", "bb_max", "grid_size"}
    assert np.count_nonzero(depth) == plate.valid_px
    assert abs(np.median(depth[depth > 0]) - 300) <= 2                     # plate front at 30 cm


@pytest.mark.parametrize("overrides, message", [
    (["dataset=maroon"], "dataset.root' is required"),
    (["dataset=maroon", "dataset.root=/does/not/exist"], "dataset root is not a directory"),
    (["method=2fsk", "prior=realsense"], "use method='mm2fsk'"),
])
def test_bad_settings_end_in_one_line_and_exit_2(synth_root, tmp_path, overrides, message):
    if overrides == ["method=2fsk", "prior=realsense"]:
        overrides = ["dataset=maroon", f"dataset.root={synth_root}", *overrides]
    result = _bench(*overrides, f"hydra.run.dir={tmp_path / 'run'}")
    assert result.returncode == 2 and message in result.stderr
    assert "Traceback" not in result.stderr


@pytest.mark.parametrize("group", sorted(CONFIG_GROUPS))
def test_every_config_composes(group):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        for option in CONFIG_GROUPS[group]:
            cfg = compose(config_name="config", overrides=[f"{group}={option}"])
            assert cfg[group].name == option
