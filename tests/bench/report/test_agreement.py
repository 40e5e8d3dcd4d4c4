"""bench.report.agreement from finished sweeps' rows: cell names, like-with-like means, both metric profiles, the
paper's relations paired per capture, the prior's cost, the depth camera alone, and the CLI's one-line error. Rows
are made by hand (the sweeps are tested in test_app.py)."""
from __future__ import annotations

import subprocess
import sys

import pandas as pd
import pytest

from bench.report import agreement

METRICS = ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm")


def _rows(cells: dict[tuple[str, str], float], distance: int = 30, profile: str = "sound",
          captures=("01_plate", "03_sphere")) -> pd.DataFrame:
    """Per (method, freq) one row per capture with every metric equal to the given value (cm); MM-2FSK on the
    RealSense prior, Table II's rows get theirs from the caller."""
    return pd.DataFrame([{"object": capture, "distance": distance, "frame": 0, "method": m, "freq": f,
                          "prior": "realsense" if m in ("mm2fsk", "prior_only") else "none", "grid": "g",
                          "metrics": profile, "failure": "", **{k: value for k in METRICS}}
                         for (m, f), value in cells.items() for capture in captures])


def test_rows_of_the_two_sweeps_become_the_papers_cells_at_30_cm_only():
    table2 = _rows({("mm2fsk", "d10"): 0.19})
    table3 = pd.concat([_rows({("bp", "full"): 0.5, ("3fsk", "d05_d10"): 2.0}), _rows({("bp", "full"): 9.0}, 40)])
    rows = agreement.cells_of_sweeps(table2, table3)
    assert sorted(set(rows.cell)) == ["3fsk_d05_d10", "bp_full", "mm2fsk_d10@photogrammetry"]   # no 40 cm row
    assert agreement.cells_of_sweeps(None, None).empty


def test_cell_names_split_and_the_geometry_fixed_cells_are_the_scalar_prior_ones_that_cannot_reach_30_cm():
    assert agreement.split_cell("prior_only_d10") == ("prior_only", "d10", "")
    assert agreement.split_cell("3fsk_d05_d10") == ("3fsk", "d05_d10", "")
    assert agreement.split_cell("mm2fsk_d1@photogrammetry") == ("mm2fsk", "d1", "photogrammetry")
    fixed = [c for c in agreement.PAPER_TABLE3 if agreement.geometry_fixed(c)]
    assert fixed == ["2fsk_d1", "2fsk_d10", "3fsk_d1_d10", "3fsk_d2_d10"]    # Δ0.5's window [26.4, 53.6] cm holds 30


def test_report_compares_like_with_like_both_profiles_relations_first(tmp_path):
    # MM-2FSK d10 RealSense 1.36 cm (the paper's P), photogrammetry 0.19 (the paper's): cost 7.16 as the paper's
    table2 = _rows({("mm2fsk", "d10"): 0.19}).assign(prior="photogrammetry")
    table3 = _rows({("bp", "full"): 2.0, ("mm2fsk", "d10"): 1.36, ("2fsk", "d05"): 2.0, ("mm2fsk", "d05"): 3.0,
                    ("2fsk", "d10"): 10.0, ("prior_only", "d10"): 1.0})
    table3.loc[(table3.method == "bp") & (table3.object == "03_sphere"), METRICS] = 4.0
    failed = (table3.method == "mm2fsk") & (table3.freq == "d05") & (table3.object == "03_sphere")
    table3.loc[failed, ["P_cm", "P_e_cm", "failure"]] = [float("nan"), float("nan"), "no radar point inside mask_bb"]
    faithful3 = table3.assign(metrics="faithful")
    faithful3.loc[faithful3.method == "bp", METRICS] = 1.0                   # the faithful profile: BP_max better
    text = agreement.write_from_sweeps(table2, table3, tmp_path / "agreement.md", "realistic",
                                       faithful=(None, faithful3)).read_text()
    assert text.index("stated relations") < text.index("## Table II") < text.index("Within a factor 2")
    # BP_max's P over 01_plate alone, the capture every Table III cell reconstructed (its 4.0 on 03 left out)
    assert ("BP_max < MM-2FSK Δ10.0 on P (paper 0.94 vs 1.36 cm): sound: reversed (2.00 vs 1.36 cm; BP_max "
            "better in 0 of 1 captures, p n/a); faithful: holds (1.00 vs 1.36 cm; BP_max better in 1 of 1 captures, "
            "p n/a)") in text
    assert "| BP_max | 0/2 / 0/2 | 2.00 | 1.00 | 0.82 |" in text             # both profiles on 01_plate alone
    assert "| MM-2FSK Δ0.5 | 1/2 / 1/2 |" in text and "| 2FSK Δ10.0 § |" in text
    assert "| Prior only (no radar) | 0/2 / 0/2 | 1.00 | 1.00 | – |" in text
    assert ("MM-2FSK Δ10.0: the RealSense prior costs on P, Table III / Table II > 1 (paper x7.16): sound: holds "
            "(x7.16; the ground-truth prior better in 2 of 2 captures, p 0.5)") in text
    assert "sound: P: MM-2FSK Δ10.0 1.36 cm against the camera's 1.00 cm (1.36x)" in text
    assert "sound: P within 2x in" in text and "1 geometry-fixed cells §, 4 values, left out" in text
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
