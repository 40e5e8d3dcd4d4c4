"""Table I from the frequency grid matches the paper; the Hydra frequency configs match the methods' table;
Tables II and III compare every row on the same captures, count failures beside the rows and carry their
uncertainty."""
from __future__ import annotations

import os

import numpy as np
import pandas as pd
import pytest

from bench.report.tables import table1
from methods.ops.frequencies import CONFIGS_GHZ

PAPER_TABLE1 = {  # config: (f1_GHz, f2_GHz, dd_max_cm), paper Table I
    "d05": (81.45, 82.00, 13.60), "d1": (80.98, 82.00, 7.32), "d2": (79.95, 82.00, 3.66),
    "d4": (77.91, 82.00, 1.83), "d8": (73.97, 82.00, 0.93), "d10": (72.00, 82.00, 0.75),
}


def test_table1_matches_the_paper_to_two_decimals():
    table = table1().set_index("config")
    assert list(table.columns) == ["delta_f_GHz", "f1_GHz", "f2_GHz", "dd_max_cm"]
    for name, (f1, f2, dd_max) in PAPER_TABLE1.items():
        assert round(table.loc[name, "f1_GHz"], 2) == pytest.approx(f1)
        assert round(table.loc[name, "f2_GHz"], 2) == pytest.approx(f2)
        assert round(table.loc[name, "dd_max_cm"], 2) == pytest.approx(dd_max)


@pytest.mark.parametrize("name", sorted(CONFIGS_GHZ))
def test_frequency_configs_take_their_targets_from_the_one_table(name):
    from hydra import compose, initialize_config_dir

    from bench.harness.app import CONFIG_DIR

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", overrides=[f"freq={name}"])
    expected = CONFIGS_GHZ[name]
    assert cfg.freq.name == name
    assert (None if cfg.freq.f_ghz is None else list(cfg.freq.f_ghz)) == (None if expected is None else list(expected))
    assert "f_ghz: ${freq_ghz:" in (CONFIG_DIR / "freq" / f"{name}.yaml").read_text()   # not a second copy


def _rows(cells, captures=("01_plate", "03_sphere")):
    """Result rows with C_g, C_s, P_e = the given per-cell value on every capture, P = value + capture index."""
    return pd.DataFrame([{"object": obj, "distance": 30, "frame": 0, "method": m, "freq": f, "prior": p,
                          "grid": "g", "device": "cpu", "runtime_ms": 1.0, "timing": "alone", "C_g_cm": v,
                          "C_s_cm": v, "P_cm": v + i, "P_e_cm": v, "off_pct": 0.0, "off_err_cm": float("nan"),
                          "off_px": 0, "failure": ""}
                         for m, f, p, v in cells for i, obj in enumerate(captures)])


def test_row_labels_follow_the_paper():
    from bench.report.tables import row_label

    assert [row_label("bp", "full"), row_label("bp", "d05"), row_label("mm2fsk", "d10"),
            row_label("3fsk", "d1_d10")] == ["BP_max", "BP Δ0.5", "MM-2FSK Δ10.0", "3FSK(Δ1.0, Δ10.0)"]


def test_summary_averages_over_captures_orders_like_the_paper_and_marks_the_best():
    from bench.report.tables import summarise, summary_latex, summary_markdown

    rows = _rows([("mm2fsk", "d10", "realsense", 0.5), ("bp", "d05", "none", 0.7), ("bp", "full", "none", 0.1),
                  ("2fsk", "d05", "none", 2.0)])
    summary = summarise(rows)
    assert list(summary.row) == ["BP_max", "BP Δ0.5", "2FSK Δ0.5", "MM-2FSK Δ10.0"]
    assert summary.set_index("row").loc["BP Δ0.5", "P_cm"] == pytest.approx(1.2)   # mean of 0.7 and 1.7
    assert (summary.captures == 2).all() and (summary.failed == 0).all() and (summary.P_cm_n == 2).all()
    markdown = summary_markdown(summary)
    assert "| MM-2FSK Δ10.0 | 0/2 | **0.50** [0.50, 0.50] | **0.50** [0.50, 0.50] | **1.00** [0.50, 1.50] |" in markdown
    assert r"\textbf{0.50}" in summary_latex(summary, "caption")          # BP_max (0.1) is never the best


def test_tables_cli_reads_a_results_csv(tmp_path):
    import subprocess
    import sys

    _rows([("mm2fsk", "d05", "photogrammetry", 2.0), ("mm2fsk", "d10", "photogrammetry", 0.2)]).to_csv(
        tmp_path / "rows.csv", index=False)
    result = subprocess.run([sys.executable, "-m", "bench.report.tables", "table2", "--results",
                             str(tmp_path / "rows.csv"), "--csv", str(tmp_path / "t.csv"), "--latex",
                             str(tmp_path / "t.tex")], capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "| MM-2FSK Δ10.0 | 0/2 | **0.20** [0.20, 0.20] |" in result.stdout
    assert "2 captures (01_plate, 03_sphere)" in result.stdout
    assert r"\begin{table}" in (tmp_path / "t.tex").read_text()
    pairs = pd.read_csv(tmp_path / "t_pairs.csv")
    assert len(pairs) == 4 and set(pairs.captures) == {2}                # one pair of rows, four metrics


def test_one_failed_cell_leaves_its_capture_out_of_every_rows_p_and_keeps_the_row_ranked():
    """The fair-table rule on a results file with one failed cell: every row's P over the same two captures,
    the failure counted beside the row, the failed row still ranked (and here the best), C_g kept where defined."""
    from bench.report.tables import best_rows, pair_of, paired_comparisons, summarise, summary_markdown

    rows = _rows([("mm2fsk", "d10", "realsense", 0.5), ("2fsk", "d05", "none", 0.1), ("bp", "d05", "none", 0.7)],
                 captures=("01_plate", "03_sphere", "05_steps"))       # P = value + 0, 1, 2 on the three captures
    failed = (rows.method == "2fsk") & (rows.object == "05_steps")
    rows.loc[failed, ["P_cm", "P_e_cm", "failure"]] = [float("nan"), float("nan"), "no radar point inside mask_bb"]
    rows.loc[failed, "C_g_cm"] = 50.0               # still defined: it counts for C_g, failure or not
    summary = summarise(rows)
    line = summary.set_index("row")
    assert list(line.failed) == [0, 1, 0] and (line.captures == 3).all()      # BP, 2FSK, MM-2FSK
    assert (line.P_cm_n == 2).all() and (line.C_g_cm_n == 3).all()
    assert line.loc["MM-2FSK Δ10.0", "P_cm"] == pytest.approx(1.0)           # (0.5 + 1.5) / 2, not (.. + 2.5) / 3
    assert line.loc["2FSK Δ0.5", "P_cm"] == pytest.approx(0.6)
    assert line.loc["BP Δ0.5", "P_cm"] == pytest.approx(1.2)
    assert line.loc["2FSK Δ0.5", "C_g_cm"] == pytest.approx((0.1 + 0.1 + 50.0) / 3)
    assert list(line.P_cm_rank) == [3, 1, 2] and summary.row[best_rows(summary)["P_cm"]] == "2FSK Δ0.5"
    assert summary.row[best_rows(summary)["C_g_cm"]] == "MM-2FSK Δ10.0"
    markdown = summary_markdown(summary)
    assert "| 2FSK Δ0.5 | 1/3 |" in markdown and "**0.60** [0.10, 1.10]" in markdown
    assert "* 2FSK Δ0.5 (1 of 3): 05_steps 30: no radar point inside mask_bb" in markdown
    # paired on the two common captures: 2FSK lower on both; exact two-sided p = 2 of 4 sign patterns
    assert pair_of(paired_comparisons(rows), "P_cm", "2FSK Δ0.5", "MM-2FSK Δ10.0") == (2, 2, 0, 0.5)
    assert line.loc["MM-2FSK Δ10.0", "P_cm_vs"] == "2FSK Δ0.5" and line.loc["MM-2FSK Δ10.0", "P_cm_worse"] == 2


def test_summary_and_pairs_scored_once_are_what_summarise_and_paired_comparisons_give():
    from bench.report.tables import paired_comparisons, summarise, summary_and_pairs

    rows = _rows([("mm2fsk", "d10", "realsense", 0.5), ("2fsk", "d05", "none", 0.1), ("bp", "d05", "none", 0.7)],
                 captures=("01_plate", "03_sphere", "05_steps"))
    rows.loc[(rows.method == "bp") & (rows.object == "03_sphere"), "P_cm"] = 3.0
    summary, pairs = summary_and_pairs(rows)
    pd.testing.assert_frame_equal(summary, summarise(rows))
    pd.testing.assert_frame_equal(pairs, paired_comparisons(rows))
    assert len(pairs) == 3 * 4 and summary.P_cm_low.notna().all()       # 3 pairs of rows x 4 metrics; intervals


def test_a_capture_below_the_coverage_floor_is_a_failure():
    from bench.report.tables import summarise

    rows = _rows([("mm2fsk", "d10", "realsense", 0.5), ("2fsk", "d05", "none", 0.1)])
    rows["coverage_pct"] = 80.0
    rows.loc[(rows.method == "2fsk") & (rows.object == "03_sphere"), "coverage_pct"] = 0.4   # 26 stray pixels
    line = summarise(rows).set_index("row")
    assert line.loc["2FSK Δ0.5", "failed"] == 1
    assert line.loc["2FSK Δ0.5", "failures"] == "03_sphere 30: covers 0.4 % of the silhouette (floor 1 %)"
    assert (line.P_cm_n == 1).all() and line.loc["MM-2FSK Δ10.0", "P_cm"] == pytest.approx(0.5)
    assert summarise(rows, floor_pct=0.3).failed.sum() == 0


def test_a_missing_row_is_a_failure_and_contended_runtimes_are_not_shown():
    from bench.report.tables import summarise

    rows = _rows([("mm2fsk", "d10", "realsense", 0.5), ("bp", "d05", "none", 2.0)])
    rows = rows.drop(index=rows.index[(rows.method == "bp") & (rows.object == "03_sphere")])
    rows.loc[rows.method == "mm2fsk", "timing"] = "parallel"
    summary = summarise(rows).set_index("row")
    assert summary.loc["BP Δ0.5", "failed"] == 1 and summary.loc["BP Δ0.5", "failures"] == "03_sphere 30: not run"
    assert summary.loc["MM-2FSK Δ10.0", "P_cm"] == pytest.approx(0.5)       # 01_plate only, as BP's
    assert np.isnan(summary.loc["MM-2FSK Δ10.0", "runtime_ms"])
    assert summary.loc["BP Δ0.5", "runtime_ms"] == pytest.approx(1.0)


def test_rows_of_a_parameter_sweep_stay_apart():
    from bench.report.tables import summarise

    rows = pd.concat([_rows([("custom", "d10", "realsense", v)]).assign(params=p, label="Bias")
                      for v, p in ((0.2, "offset_mm=0"), (0.4, "offset_mm=2"), (0.7, "offset_mm=5"))])
    summary = summarise(rows)
    assert list(summary.row) == ["Bias Δ10.0 offset_mm=0", "Bias Δ10.0 offset_mm=2", "Bias Δ10.0 offset_mm=5"]
    assert list(summary.C_g_cm) == pytest.approx([0.2, 0.4, 0.7])


def test_intervals_and_paired_tests_come_from_scipy_resampling():
    from bench.report.uncertainty import mean_interval, paired

    values = [0.1, 0.5, 0.3, 1.2, 0.2, 0.4, 0.3]
    interval = mean_interval(values)
    assert interval.n == 7 and interval.low < interval.mean < interval.high
    assert min(values) < interval.low and interval.high < max(values)
    assert mean_interval([0.4, 0.4]).low == 0.4 and np.isnan(mean_interval([0.4]).low)
    better = paired(values, [v + 0.1 for v in values])
    assert (better.n, better.a_better, better.b_better) == (7, 7, 0)
    assert better.p_value == pytest.approx(2 / 2 ** 7)                     # exact: 2 of the 128 sign patterns
    assert paired([1.0, 2.0, 3.0], [1.0, 2.0, 3.0]).p_value == 1.0


def test_caption_describes_the_rows_it_holds():
    from bench.report.tables import caption

    text = caption("table2", _rows([("2fsk", "d05", "none", 1.0)]))
    assert "2FSK with the scalar prior" in text and "MM-2FSK" not in text


def _latex_engine() -> str | None:
    """pdflatex, installed from Debian if missing and possible (skip reason otherwise)."""
    import shutil
    import subprocess

    if shutil.which("pdflatex") is None and shutil.which("apt-get") is not None:
        sudo = [] if os.geteuid() == 0 else ["sudo", "-n"]
        subprocess.run([*sudo, "apt-get", "install", "-y", "-q", "--no-install-recommends", "texlive-latex-base",
                        "texlive-latex-recommended"], capture_output=True, timeout=600)
    return shutil.which("pdflatex")


def test_latex_tables_compile(tmp_path):
    import subprocess

    from bench.report.tables import caption, styler_latex, summarise, summary_latex

    engine = _latex_engine()
    if engine is None:
        pytest.skip("no pdflatex and it could not be installed (apt-get texlive-latex-base texlive-latex-recommended)")
    rows = _rows([("mm2fsk", "d10", "realsense", 0.5), ("bp", "full", "none", 0.1), ("3fsk", "d05_d10", "none", 2.0)])
    rows.loc[0, "failure"] = "no valid pixel"
    tables = [summary_latex(summarise(rows), caption("table3", rows) + " 100% of_all & #1 {x} ~ ^ $"),
              styler_latex(table1(), "Table I_x")]
    document = "\\documentclass{article}\n\\usepackage{booktabs}\n\\begin{document}\n%s\n\\end{document}\n"
    (tmp_path / "t.tex").write_text(document % "\n".join(tables))
    result = subprocess.run([engine, "-interaction=nonstopmode", "-halt-on-error", "t.tex"], cwd=tmp_path,
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stdout[-2000:]


def test_the_verdict_names_the_best_the_front_and_what_the_radar_adds():
    from bench.report.tables import paired_comparisons, summarise
    from bench.report.verdict import verdict

    rows = _rows([("mm2fsk", "d10", "realsense", 0.5), ("prior_only", "d10", "realsense", 0.4),
                  ("bp", "d05", "none", 0.7)])
    rows["label"] = np.where(rows.method == "prior_only", "Prior only", None)
    rows["runtime_ms"] = rows.method.map({"mm2fsk": 80.0, "prior_only": 30.0, "bp": 5000.0})
    found = verdict(summarise(rows), paired_comparisons(rows))
    assert found["best"][2] == ("P: Prior only (no radar), 0.90 cm [0.40, 1.40] over 2 of 2 captures; better than "
                                "the runner-up MM-2FSK Δ10.0 (1.00 cm) in 2 of 2 captures, p 0.5")
    assert found["front"] == ["Runtime against error (P): the front, fastest first: Prior only (no radar) (30 ms, "
                              "P 0.90 cm)."]
    assert ("P: MM-2FSK Δ10.0 1.00 cm against the camera's 0.90 cm (1.11x); the radar better in 0 of 2 captures, "
            "the camera in 2, p 0.5") in found["baseline"]
    assert found["marked"] == ["No row failed on any capture: every mean covers every capture."]
