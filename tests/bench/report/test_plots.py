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


def test_depth_error_maps_drawn_by_forked_workers_are_the_figures_drawn_here(tmp_path, monkeypatch):
    """Three captures drawn by two forked workers, then one after another in this process (workers=1; and where
    other threads run, which must not fork): byte-identical files, and a second call redraws nothing."""
    import threading

    from bench.report import plots

    rng = np.random.default_rng(5)
    runs = []
    for name in ("a", "b"):
        for stem in ("01_plate_30_000000", "03_sphere_30_000000", "05_steps_30_000000"):
            depth = 0.3 + 0.01 * rng.standard_normal((5, 6))
            arrays = {"depth_m": depth, "magnitude": depth, "gt_depth_m": depth + 0.01}
            write_arrays(tmp_path / f"{name}.h5", stem, arrays,
                         {"bb_min_m": [-0.1, -0.1, 0.2], "bb_max_m": [0.1, 0.1, 0.4], "grid_size": [6, 5, 3]})
        runs.append((name, tmp_path / f"{name}.h5"))
    monkeypatch.setattr(threading, "active_count", lambda: 1)     # as in the merge's worker: forks
    forked = depth_error_maps(runs, tmp_path / "forked", workers=2)
    here = depth_error_maps(runs, tmp_path / "here", workers=1)
    monkeypatch.setattr(threading, "active_count", lambda: 2)     # another thread: drawn here, not forked
    threaded = depth_error_maps(runs, tmp_path / "threaded", workers=2)
    assert len(forked) == 3
    for a, b, c in zip(forked, here, threaded, strict=True):
        assert a.read_bytes() == b.read_bytes() == c.read_bytes()
    drawn = []
    monkeypatch.setattr(plots, "_depth_error_map", lambda *args: drawn.append(args))
    depth_error_maps(runs, tmp_path / "forked", workers=2)
    assert drawn == []                                               # unchanged: nothing redrawn
