"""bench.perf.sweep: the table3 cell list and a tiny-grid CPU sweep on the synthetic fixture captures."""
from __future__ import annotations

from bench.perf.sweep import run_sweep, table3_cells

TINY_IMAGE = {"xy_half_m": 0.15, "nxy": 15, "z_half_m": 0.10, "nz": 3}
TINY_BP = {"xy_half_m": 0.15, "nxy": 9, "z_half_m": 0.10, "nz": 3}


def test_table3_cells_match_the_paper():
    cells = {c["cell"]: (c["method"], c["f_ghz"], c["prior"]) for c in table3_cells()}
    assert list(cells) == ["bp_full", "bp_d05", "bp_d1", "bp_d10", "2fsk_d05", "2fsk_d1", "2fsk_d10",
                           "3fsk_d05_d10", "3fsk_d1_d10", "3fsk_d2_d10", "mm2fsk_d05", "mm2fsk_d1", "mm2fsk_d10",
                           "prior_only_d10"]
    assert cells["bp_full"] == ("bp", None, "none")
    assert cells["2fsk_d1"] == ("2fsk", [80.98, 82.0], "none")
    assert cells["3fsk_d2_d10"] == ("3fsk", [72.0, 79.95, 82.0], "none")
    assert cells["mm2fsk_d10"] == ("mm2fsk", [72.0, 82.0], "realsense")
    assert cells["prior_only_d10"] == ("examples.prior_only.PriorOnly", [72.0, 82.0], "realsense")


def test_sweep_rows_on_a_tiny_grid(synth_root):
    rows = {r["cell"]: r for r in run_sweep(synth_root, "cpu", 1, bp_override=TINY_BP, image_override=TINY_IMAGE)}
    assert len(rows) == 14 + 3
    assert all(r["fps"] > 0 and r["captures"] == 2 for r in rows.values())
    assert rows["table3"]["frames"] == 28 and rows["table3_shared_prior"]["frames"] == 28
    assert rows["mm2fsk_shared"]["max_depth_diff_m"] == 0.0       # same prior, same depth maps
    total_ms = sum(rows[c["cell"]]["ms_per_frame"] for c in table3_cells()) * 2
    assert abs(rows["table3"]["ms_per_frame"] * 28 - total_ms) < 1e-6 * total_ms
