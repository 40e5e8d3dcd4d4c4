"""bench.report.agreement from finished sweeps' rows: cell names, ratios to the paper, the paper's pairs, the prior's
cost,
and the CLI's one-line error. Rows are made by hand (the sweeps are tested in test_app.py)."""
from __future__ import annotations

import subprocess
import sys

import pandas as pd
import pytest

from bench.report import agreement

METRICS = ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm")


def _rows(cells: dict[tuple[str, str], float], distance: int = 30) -> pd.DataFrame:
    """One capture per (method, freq) with every metric equal to the given value (cm)."""
    return pd.DataFrame([{"object": "01_plate", "distance": distance, "method": m, "freq": f,
                          **{k: value for k in METRICS}} for (m, f), value in cells.items()])


def test_rows_of_the_two_sweeps_become_the_papers_cells_at_30_cm_only():
    table2 = _rows({("mm2fsk", "d10"): 0.19})
    table3 = pd.concat([_rows({("bp", "full"): 0.5, ("3fsk", "d05_d10"): 2.0}), _rows({("bp", "full"): 9.0}, 40)])
    rows = agreement.cells_of_sweeps(table2, table3)
    assert sorted(rows.cell) == ["3fsk_d05_d10", "bp_full", "mm2fsk_d10@photogrammetry"]   # the 40 cm row left out
    assert agreement.cells_of_sweeps(None, None).empty


def test_report_ratios_pairs_and_the_prior_cost(tmp_path):
    # MM-2FSK d10 RealSense 1.36 cm (the paper's P), photogrammetry 0.19 (the paper's): cost 7.16 as the paper's
    table2 = _rows({("mm2fsk", "d10"): 0.19})
    table3 = _rows({("bp", "full"): 2.0, ("mm2fsk", "d10"): 1.36, ("2fsk", "d05"): 2.0, ("mm2fsk", "d05"): 3.0})
    path = agreement.write_from_sweeps(table2, table3, tmp_path / "agreement.md", "realistic")
    text = path.read_text()
    assert "| BP_max | 1/1 | 2.00 | 0.82 | 2.44 |" in text                # C_g 2.00 / 0.82
    assert "* BP_max C_g x2.44" in text and "* MM-2FSK Δ10.0 P x" not in text
    assert "BP_max < MM-2FSK Δ10.0 on P (paper): FAILS (2.00 vs 1.36 cm)" in text
    assert "2FSK Δ0.5 < MM-2FSK Δ0.5 on P (paper): holds (2.00 vs 3.00 cm)" in text
    cost = [line for line in text.splitlines() if line.startswith("| MM-2FSK Δ10.0 | ")][-1].split(" | ")
    assert cost[5:7] == ["7.16", "7.16"]                                  # P syn, P paper
    assert agreement.write_from_sweeps(None, _rows({("bp", "full"): 1.0}, 40), tmp_path / "none.md", "x") is None


def test_from_results_of_a_missing_folder_is_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "bench.report.agreement", "--from-results", str(tmp_path / "nope"),
                           "--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [
        f"error: {tmp_path / 'nope'}: --from-results does not exist"]


def test_prior_errors_measure_the_realsense_prior_against_the_ground_truth(synth_capture):
    """Exact camera: no pixel beyond MM-2FSK Δ10's ~7.5 mm; a camera reading 4 % far (12 mm at 30 cm): all of them."""
    exact = synth_capture("01_plate", 30, frequency_points=16)
    far = synth_capture("01_plate", 30, frequency_points=16, depth_scale_error=0.04)
    for capture, share in ((exact, 0.0), (far, 1.0)):
        line = agreement.prior_errors(capture.parent.parent, ["01_plate"]).iloc[0]
        column = next(c for c in line.index if c.startswith("share beyond"))
        assert line["pixels"] > 1000 and line[column] == pytest.approx(share, abs=0.02)
    assert 10.0 < line["median error mm"] < 13.0


def test_variants_table_shows_what_a_camera_error_costs_mm2fsk(tmp_path):
    """The ablation's machinery on one capture: a camera reading 4 % far (12 mm at 30 cm, beyond Δ10's 7.5 mm)
    raises MM-2FSK Δ10's P with the RealSense prior and leaves the photogrammetry prior's alone."""
    from bench.synth.config import preset

    variants = {"all effects on": {}, "far camera": {"depth_scale_error": 0.04}}
    table = agreement.variants_table(preset("realistic"), variants, "camera", ["01_plate"],
                                     list(agreement.CAMERA_BOUNDS_CELLS), None, tmp_path).set_index("camera")
    assert list(table.index) == list(variants)
    camera, truth = "MM-2FSK Δ10.0", "MM-2FSK Δ10.0 (photogrammetry)"
    assert table.loc["far camera", truth] == table.loc["all effects on", truth]
    assert table.loc["far camera", camera] > table.loc["all effects on", camera] + 0.3
    assert table.loc["far camera", "prior cost d10"] > 2.0
    assert (tmp_path / "ablation" / "far_camera" / "01_plate" / "30").is_dir()


def test_the_paper_row_of_the_ablation_holds_its_p_and_prior_cost():
    line = agreement.paper_row(["mm2fsk_d10", "mm2fsk_d10@photogrammetry", "2fsk_d05"], "effect")
    assert line["MM-2FSK Δ10.0"] == 1.36 and line["MM-2FSK Δ10.0 (photogrammetry)"] == 0.19
    assert line["2FSK Δ0.5"] == 2.55 and line["prior cost d10"] == pytest.approx(7.16, abs=0.01)
    assert "prior cost d10" not in agreement.paper_row(["2fsk_d05"], "effect")
