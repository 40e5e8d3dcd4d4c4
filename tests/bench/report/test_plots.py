"""Plots: the Pareto front is the non-dominated set; figures are written for every capture."""
from __future__ import annotations

import numpy as np
import pandas as pd

from bench.harness.store import write_arrays
from bench.report.plots import depth_error_maps, pareto_front, runtime_vs_error


def test_pareto_front_keeps_exactly_the_non_dominated_points():
    runtime_ms = np.array([1.0, 2.0, 3.0, 10.0, 2.0])
    error_cm = np.array([5.0, 1.0, 2.0, 0.5, 1.0])      # 3 ms / 2 cm is beaten by 2 ms / 1 cm; ties both kept
    assert pareto_front(runtime_ms, error_cm).tolist() == [True, True, False, True, True]


def test_plots_are_written(tmp_path):
    summary = pd.DataFrame({"row": ["a", "b", "c"], "method": ["bp", "mm2fsk", "2fsk"],
                            "runtime_ms": [100.0, 1.0, 5.0], "P_cm": [0.5, 1.0, 3.0], "comparable": [True, True, False],
                            "ok": [2, 2, 1], "captures": [2, 2, 2]})
    assert runtime_vs_error(summary, tmp_path / "r.png", "t").stat().st_size > 0
    untimed = summary.assign(runtime_ms=float("nan"))              # a parallel sweep: no runtime measured alone
    assert runtime_vs_error(untimed, tmp_path / "u.png", "t").stat().st_size > 0
    depth = np.full((5, 6), 0.30)
    for name in ("a", "b"):
        write_arrays(tmp_path / f"{name}.h5", "01_plate_30_000000",
                     {"depth_m": depth, "magnitude": depth, "gt_depth_m": depth + 0.01},
                     {"bb_min_m": [-0.1, -0.1, 0.2], "bb_max_m": [0.1, 0.1, 0.4], "grid_size": [6, 5, 3]})
    (path,) = depth_error_maps([("a", tmp_path / "a.h5"), ("b", tmp_path / "b.h5")], tmp_path / "maps")
    assert path.name == "01_plate_30_000000.png" and path.stat().st_size > 0
