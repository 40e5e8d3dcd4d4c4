"""Table I from the frequency grid matches the paper; the Hydra frequency configs match the methods' table."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from bench.tables import table1
from methods.frequencies import CONFIGS_GHZ

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
def test_frequency_config_files_match_the_table(name):
    path = Path(__file__).parents[1] / "configs" / "freq" / f"{name}.yaml"
    config = yaml.safe_load(path.read_text())
    assert config["name"] == name
    expected = CONFIGS_GHZ[name]
    assert config["f_ghz"] == (None if expected is None else list(expected))


def _rows(cells, captures=("01_plate", "03_sphere")):
    """Result rows with P_cm etc. = the given per-cell value on every capture."""
    import pandas as pd

    return pd.DataFrame([{"object": obj, "distance": 30, "method": m, "freq": f, "prior": p, "grid": "g",
                          "device": "cpu", "runtime_ms": 1.0, "C_g_cm": v, "C_s_cm": v, "P_cm": v + i, "P_e_cm": v}
                         for m, f, p, v in cells for i, obj in enumerate(captures)])


def test_row_labels_follow_the_paper():
    from bench.tables import row_label

    assert [row_label("bp", "full"), row_label("bp", "d05"), row_label("mm2fsk", "d10"),
            row_label("3fsk", "d1_d10")] == ["BP_max", "BP Δ0.5", "MM-2FSK Δ10.0", "3FSK(Δ1.0, Δ10.0)"]


def test_summary_averages_over_captures_orders_like_the_paper_and_marks_the_best():
    from bench.tables import summarise, summary_latex, summary_markdown

    rows = _rows([("mm2fsk", "d10", "realsense", 0.5), ("bp", "d05", "none", 0.7), ("bp", "full", "none", 0.1),
                  ("2fsk", "d05", "none", 2.0)])
    summary = summarise(rows)
    assert list(summary.row) == ["BP_max", "BP Δ0.5", "2FSK Δ0.5", "MM-2FSK Δ10.0"]
    assert summary.set_index("row").loc["BP Δ0.5", "P_cm"] == pytest.approx(1.2)   # mean of 0.7 and 1.7
    assert (summary.captures == 2).all()
    markdown = summary_markdown(summary)
    assert "| MM-2FSK Δ10.0 | **0.50** | **0.50** | **1.00** | **0.50** |" in markdown   # BP_max is not "best"
    assert r"\textbf{0.50}" in summary_latex(summary, "caption")


def test_tables_cli_reads_a_results_csv(tmp_path):
    import subprocess
    import sys

    _rows([("mm2fsk", "d05", "photogrammetry", 2.0), ("mm2fsk", "d10", "photogrammetry", 0.2)]).to_csv(
        tmp_path / "rows.csv", index=False)
    result = subprocess.run([sys.executable, "-m", "bench.tables", "table2", "--results", str(tmp_path / "rows.csv"),
                             "--csv", str(tmp_path / "t.csv"), "--latex", str(tmp_path / "t.tex")],
                            capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result.stderr
    assert "| MM-2FSK Δ10.0 | **0.20** |" in result.stdout and "Mean over 2 captures" in result.stdout
    assert (tmp_path / "t.tex").read_text().startswith(r"\begin{table}")
