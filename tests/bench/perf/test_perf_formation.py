"""bench.perf formation's parts on Warp-CPU at a tiny grid: the column kernel's rows carry its timings and its
errors against the fp32 separable kernel and the float64 sum, within the issue's 1e-4 at the default step."""
from __future__ import annotations

import numpy as np

from bench.maroon.antennas import load_antenna_array
from bench.perf import formation


def test_columns_rows_time_and_measure_every_variant():
    from methods.backends import backend_for

    rows = formation.columns_rows(backend_for("warp-cpu"), load_antenna_array(), 5, 6, 1, np.random.default_rng())
    assert [r["impl"] for r in rows] == ["default", "columns@0.001", "columns@0.0001", "columns@1e-05"]
    assert all(r["frame_median_ms"] > 0 for r in rows)
    default_step = rows[2]
    assert default_step["rel_l2_vs_f64_256_f0"] <= 1e-4 and default_step["max_mag_diff_f1"] <= 1e-4
    assert rows[1]["rho_step_mm"] > rows[2]["rho_step_mm"] > rows[3]["rho_step_mm"]


def test_scene_frames_differ_and_hold_the_scene():
    ant = load_antenna_array()
    rng = np.random.default_rng()
    a, b = (formation.scene_frame(ant, formation.D05_HZ, rng, n_points=20) for _ in range(2))
    assert a.shape == (94, 94, 2) and a.dtype == np.complex64 and not np.allclose(a, b)


def test_range_rows_time_both_tables_and_the_new_one_meets_the_issue():
    from methods.backends import backend_for

    rows = formation.range_rows(backend_for("cpu"), load_antenna_array(), 6, 8, 1, np.random.default_rng())
    new, old = rows
    assert new["impl"].endswith("(new)") and old["impl"].endswith("(old)")
    assert new["frame_median_ms"] > 0 and new["cpu_median_ms"] > 0 and "load_1min" in new
    assert new["rel_l2_vs_f64_256_f0"] <= 1e-4 and new["max_mag_diff_f1"] <= 1e-4
    assert old["rel_l2_vs_f64_256_f0"] > 2 * new["rel_l2_vs_f64_256_f0"]       # the earlier table, 4e-4
