"""The sweep's merge: the depth-error figures are optional and never change the table."""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd

from bench.harness.store import write_arrays
from bench.report.merge import report

REPO = Path(__file__).resolve().parents[3]


def _sweep_root(root: Path) -> Path:
    """Two jobs made of the committed table3 rows (split by method), each with one capture's arrays."""
    rows = pd.read_csv(REPO / "results" / "table3" / "results.csv")
    depth = np.full((5, 6), 0.30)
    for num, (method, part) in enumerate(rows.groupby("method", sort=True)):
        job = root / f"{num}_{method}"
        job.mkdir(parents=True)
        part.to_csv(job / "results.csv", index=False)
        write_arrays(job / "arrays.h5", "01_plate_30_000000",
                     {"depth_m": depth, "magnitude": depth, "gt_depth_m": depth + 0.01},
                     {"bb_min_m": [-0.1, -0.1, 0.2], "bb_max_m": [0.1, 0.1, 0.4], "grid_size": [6, 5, 3]})
    return root


def test_depth_error_figures_are_optional_and_leave_the_table_as_it_is(tmp_path):
    plain, drawn = _sweep_root(tmp_path / "plain"), tmp_path / "drawn"
    shutil.copytree(plain, drawn)
    report(plain, "table3")                                              # the sweep's default
    report(drawn, "table3", depth_errors=True)
    assert not (plain / "depth_errors").exists()
    assert (drawn / "depth_errors" / "01_plate_30_000000.png").stat().st_size > 0
    for name in ("table3.md", "table3.csv", "table3.tex", "results.csv"):
        assert (plain / name).read_bytes() == (drawn / name).read_bytes(), name
