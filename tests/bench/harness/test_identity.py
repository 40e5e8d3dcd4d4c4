"""A swept setting that changes a result is part of a row's identity (issue 28 item 1): the `params` column, job
lines and a warning when two jobs give rows of one identity; the sweep ends in one line naming its table."""
from __future__ import annotations

import os
import subprocess
import sys

import h5py
import numpy as np
import pandas as pd
import pytest

from bench.harness.identity import params_string
from bench.harness.summary import colliding_jobs, summary_line

METHOD = '''
import numpy as np
from methods import Method, Reconstruction


class PriorBias(Method):
    """The RealSense prior moved back by `offset_mm`: each offset a different depth map."""

    name = "prior_bias"
    label = "Prior bias"
    priors = ("realsense",)
    params = {"offset_mm": 0.0}

    def run(self, frame, prior, backend, timer):
        with timer.stage("depth"):
            depth_m = np.where(frame.roi.pixels, prior.host_m() + self.values["offset_mm"] / 1000.0, np.nan)
        return Reconstruction(depth_m=depth_m, magnitude=np.where(np.isfinite(depth_m), 1.0, np.nan),
                              freqs_hz=np.asarray(frame.freqs_hz), timings_ms=timer.finish(), grid=frame.grid,
                              method=self.name)
'''


@pytest.mark.parametrize("overrides, expected", [
    ([], ""),
    (["method=mm2fsk", "freq=d10", "prior=realsense", "cell=bp_d10", "+experiment=table3", "dataset.root=/x",
      "store.dir=null", "hydra/launcher=basic", "device=cpu", "timing.repeat=5", "method._target_=a.B"], ""),
    (["+method.params.offset_mm=2.0"], "offset_mm=2"),                       # 2 and 2.0: one text
    (["threshold_db=10", "prior.fill=scanline", "roi=none", "freq.f_ghz=[72,82]", "profile=faithful"],
     "freq.f_ghz=[72,82] prior.fill=scanline profile=faithful roi=none threshold_db=10"),   # sorted by key
    (["threshold_db=10", "threshold_db=20"], "threshold_db=20"),             # the last override of a key wins
    (["prior.max_jump_mm=null", "+method.params.flag=true"], "flag=true prior.max_jump_mm=null"),
])
def test_params_hold_the_overrides_that_change_a_result(overrides, expected):
    assert params_string(overrides) == expected


def test_a_parameter_sweep_gives_three_distinct_rows(synth_root, tmp_path):
    """`+method.params.offset_mm=0,2,5` on a method outside the repository: three jobs named by their parameter,
    three rows told apart by `params`, depths 2 and 5 mm apart, and one closing line naming the rows."""
    (tmp_path / "mypkg").mkdir()
    (tmp_path / "mypkg" / "prior_bias.py").write_text(METHOD)
    sweep = tmp_path / "sweep"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(tmp_path), os.environ.get("PYTHONPATH", "")])}
    result = subprocess.run([sys.executable, "-m", "bench", "-m", "method=custom",
                             "method._target_=mypkg.prior_bias.PriorBias", "+method.params.offset_mm=0,2,5",
                             "prior=realsense", "freq=d10", "dataset=maroon", f"dataset.root={synth_root}",
                             "dataset.captures=[01_plate/30]", "store.dir=null", "hydra/launcher=basic",
                             f"hydra.sweep.dir={sweep}"], capture_output=True, text=True, timeout=600, env=env)
    assert result.returncode == 0, result.stderr
    for num, offset in enumerate((0, 2, 5), 1):
        assert f"[sweep {num}/3] custom_d10_realsense offset_mm={offset}: 1 capture, 1 computed" in result.stdout
    assert f"sweep finished: rows {sweep / 'results.csv'}" in result.stdout
    assert "warning:" not in result.stderr
    rows = pd.read_csv(sweep / "results.csv", keep_default_na=False)
    assert list(rows.params) == ["offset_mm=0", "offset_mm=2", "offset_mm=5"]
    assert len(rows.drop_duplicates(["object", "method", "freq", "prior", "grid", "params"])) == 3
    assert rows.valid_px.nunique() == 1
    depths_m = []                                  # each job's own depth map: the offsets, not one run three times
    for job in sorted(sweep.glob("*_custom_*")):
        with h5py.File(job / "arrays.h5", "r") as h5:
            depths_m.append(h5["01_plate_30_000000/depth_m"][()])
    assert np.nanmax(np.abs(depths_m[2] - depths_m[1] - 0.003)) < 1e-9
    assert np.nanmax(np.abs(depths_m[1] - depths_m[0] - 0.002)) < 1e-9


def _job(root, name: str, params: str, overrides: list[str]) -> None:
    (root / name / ".hydra").mkdir(parents=True)
    pd.DataFrame([{"object": "01_plate", "distance": 30, "frame": 0, "method": "mm2fsk", "freq": "d10",
                   "prior": "realsense", "grid": "from_capture", "params": params, "device": "cpu",
                   "metrics": "sound"}]).to_csv(root / name / "results.csv", index=False)
    (root / name / ".hydra" / "overrides.yaml").write_text("".join(f"- {o}\n" for o in overrides))


def test_jobs_whose_rows_share_an_identity_are_named_with_what_they_differ_in(tmp_path):
    _job(tmp_path, "0_a", "", ["synth=ideal", "freq=d10"])
    _job(tmp_path, "1_b", "", ["synth=realistic", "freq=d10"])
    _job(tmp_path, "2_c", "threshold_db=10", ["synth=ideal", "freq=d10", "threshold_db=10"])
    (warning,) = colliding_jobs(tmp_path)
    assert "jobs 0_a and 1_b" in warning and "synth=ideal, synth=realistic" in warning


def test_the_closing_line_names_the_table_when_there_is_one(tmp_path):
    assert summary_line(tmp_path, "table3").startswith("sweep finished without merged rows")
    (tmp_path / "results.csv").write_text("object\n")
    assert summary_line(tmp_path, "table3").startswith(f"sweep finished: rows {tmp_path / 'results.csv'}")
    (tmp_path / "table3.md").write_text("table")
    assert f"table {tmp_path / 'table3.md'}, rows" in summary_line(tmp_path, "table3")
