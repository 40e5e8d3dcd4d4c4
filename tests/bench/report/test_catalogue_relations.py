"""bench.report.catalogue: the paper's relations per generator seed and profile, paired over the captures both cells
reconstructed, the seeds pooled, the cells within 2x on their own captures, the objects that drive a relation, the
camera's error against the prior's cost, and the CLI's one-line error. Rows are made by hand."""
from __future__ import annotations

import subprocess
import sys

import pandas as pd
import pytest

from bench.report import catalogue

METRICS = ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm")
OBJECTS = ("01_plate", "03_sphere", "04_bottle")


def _rows(values: dict[str, float], seed: int, profile: str = "sound", objects=OBJECTS) -> pd.DataFrame:
    """One row per cell and object, every metric equal to the cell's value (cm)."""
    lines = []
    for cell, value in values.items():
        name, _, prior = cell.partition("@")
        method, freq = name.split("_", 1) if not name.startswith("prior_only") else ("prior_only", "d10")
        lines += [{"object": o, "distance": 30, "frame": 0, "method": method, "freq": freq,
                   "prior": prior or ("realsense" if method in ("mm2fsk", "prior_only") else "none"), "grid": "g",
                   "metrics": profile, "failure": "", "cell": cell, "seed": seed, **{m: value for m in METRICS}}
                  for o in objects]
    return pd.DataFrame(lines)


@pytest.fixture
def rows() -> pd.DataFrame:
    # seed 0: MM-2FSK Δ10 at 0.5 beats BP_max's 1.0; seed 1: MM-2FSK Δ10 at 2.0 loses. Ground-truth prior 0.1.
    cells = {"bp_full": 1.0, "mm2fsk_d10@photogrammetry": 0.1, "prior_only_d10": 3.0, "2fsk_d05": 2.5}
    return pd.concat([_rows({**cells, "mm2fsk_d10": 0.5}, 0), _rows({**cells, "mm2fsk_d10": 2.0}, 1)],
                     ignore_index=True)


def test_relations_hold_or_reverse_per_seed_paired_and_pooled(rows):
    table = catalogue.relation_table(rows).set_index("relation")
    line = table.loc["BP_max < MM-2FSK Δ10.0 on P"]
    assert line["seed 0"] == "reversed 1.00 vs 0.50 (0/3, p 0.25)"       # exact test, 2^3 sign patterns
    assert line["seed 1"] == "holds 1.00 vs 2.00 (3/3, p 0.25)"
    assert line["pooled"].startswith("holds 1.00 vs 1.25 (3/6, ")        # the seeds' captures as six
    assert line["paper"] == "0.94 vs 1.36"
    cost = table.loc["prior cost MM-2FSK Δ10.0 on P >= 4x"]
    assert cost["seed 0"].startswith("holds x5.00 (truth better 3/3") and cost["paper"] == "x7.16"
    camera = table.loc["camera alone clearly worse than MM-2FSK Δ10.0 on P"]
    assert camera["seed 0"] == "not clear 0.50 vs 3.00 (x6.00) (3/3, p 0.25)"  # worse, but p >= 0.05
    assert camera["pooled"].startswith("holds 1.25 vs 3.00")                     # 6 captures: p 1/32
    assert "BP Δ0.5" not in " ".join(table.index)                                # not run: no line


def test_a_failed_capture_leaves_a_pair_and_own_means(rows):
    failed = (rows.cell == "bp_full") & (rows.object == "03_sphere") & (rows.seed == 0)
    rows.loc[failed, ["P_cm", "P_e_cm", "failure"]] = [float("nan"), float("nan"), "no radar point inside mask_bb"]
    line = catalogue.relation_table(rows).set_index("relation").loc["BP_max < MM-2FSK Δ10.0 on P"]
    assert line["seed 0"].startswith("reversed 1.00 vs 0.50 (0/2, ")
    means = catalogue.own_means(rows[rows.seed == 0]).set_index("cell")
    assert means.loc["BP_max", "failed sound"] == "1/3" and means.loc["BP_max", "P sound"] == 1.0
    assert means.loc["MM-2FSK Δ10.0 (photogrammetry)", "P paper"] == 0.19


def test_drivers_name_the_objects_a_relation_loses_on(rows):
    bottle = (rows.cell == "bp_full") & (rows.object == "04_bottle")
    rows.loc[bottle, list(METRICS)] = 9.0
    rows.loc[rows.cell == "mm2fsk_d10", list(METRICS)] = 2.0
    table, lines = catalogue.drivers(rows, "bp_full", "mm2fsk_d10")
    assert table.iloc[0].object == "04_bottle" and table.iloc[0].difference == pytest.approx(7.0)
    assert lines == ["sound: BP_max < MM-2FSK Δ10.0 on P holds once the 1 objects where it loses most are left out "
                     "(04_bottle): 1.00 vs 2.00 cm over 4 captures"]


def test_the_prior_cost_follows_the_camera_error_beyond_the_unambiguous_range(rows):
    # per capture: the cost rises with the share of the prior's pixels beyond Δ10's correction
    shares = {"01_plate": 0.0, "03_sphere": 0.3, "04_bottle": 0.9}
    for i, (name, share) in enumerate(shares.items()):
        rows.loc[(rows.cell == "mm2fsk_d10") & (rows.object == name), "P_cm"] = 0.1 * (1 + 10 * share) + i * 1e-3
    errors = pd.DataFrame([{"capture": o, "pixels": 100, "median error mm": 20.0 * s, "mean |error| mm": 20.0 * s,
                            "share beyond 7.5 mm": s, "seed": seed} for o, s in shares.items() for seed in (0, 1)])
    table, lines = catalogue.camera_against_range(rows, errors)
    assert lines[0] == ("captures whose prior has its median error beyond 7.5 mm (MM-2FSK Δ10's unambiguous "
                        "correction): 2 of 6; mean share of pixels beyond: 0.40")
    assert lines[1].startswith("sound: per capture, the prior's cost against its share of pixels beyond: Spearman "
                               "1.00")
    assert table.set_index("object").loc["04_bottle", "cost sound"] == pytest.approx(10.0, rel=0.01)
    # the bottle's two captures (one per seed) lie beyond: MM-2FSK Δ10 1.00 cm there against the camera's 3.00
    assert ("sound: captures whose prior's median error lies beyond 7.5 mm: P MM-2FSK Δ10 1.00 vs the camera alone "
            "3.00 cm, the radar better in 2 of 2 (p 0.5)") in lines


def test_a_missing_folder_is_one_line(tmp_path):
    proc = subprocess.run([sys.executable, "-m", "bench.report.catalogue", str(tmp_path / "nope")],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 2 and proc.stderr.strip().splitlines() == [
        f"error: {tmp_path / 'nope'}: FOLDER does not exist"]
