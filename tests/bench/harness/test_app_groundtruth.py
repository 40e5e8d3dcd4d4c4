"""The ground truth of a capture (ray casting, silhouette, KD-tree) is built once and reused by every cell a
process runs, and every cell is scored on the capture's metric grid whatever grid it computed on."""
from __future__ import annotations

import numpy as np
from hydra import compose, initialize_config_dir

import bench.harness.app as app
from bench.harness import captures


def _cfg(synth_root, *overrides):
    with initialize_config_dir(config_dir=str(app.CONFIG_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=["dataset=maroon", f"dataset.root={synth_root}",
                                                      "dataset.captures=[01_plate/30]", "store.dir=null",
                                                      "store.cache=null", *overrides])


def test_ground_truth_is_built_once_per_capture_for_every_cell(synth_root, tmp_path, monkeypatch):
    calls = []
    real = captures.ground_truth_rasters_m
    monkeypatch.setattr(captures, "ground_truth_rasters_m",
                        lambda capture, grid: calls.append(capture.name) or real(capture, grid))
    monkeypatch.setattr(captures, "_GROUND_TRUTHS", type(captures._GROUND_TRUTHS)())  # none cached yet
    rows = [app.run(_cfg(synth_root, *cell), tmp_path / str(i))[0]
            for i, cell in enumerate([["cell=mm2fsk_d10"], ["cell=2fsk_d05"], ["cell=bp_d05", "grid=bp_cpu"]])]
    assert len(calls) == 1
    # BP computed on the reduced 51 x 51 grid (grid=bp_cpu: quick), scored like the others on the capture's
    # 301 x 301 grid: same GT points
    assert rows[2]["compute_grid_size"] == "51x51x21" and rows[0]["compute_grid_size"].startswith("301x301")
    assert len({row["C_g_px"] for row in rows}) == 1
    assert all(row["failure"] == "" for row in rows)
    assert np.isfinite([row["P_e_cm"] for row in rows]).all()
