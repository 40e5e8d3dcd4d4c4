"""Per-capture outcomes of a table's rows: which captures each row reconstructed (the success rule with its
coverage floor), its metric values per capture, and the captures every compared row covers.

A row is one method x frequency configuration x prior x grid (x swept parameters, where the rows carry them). A
capture is `object` x `distance`; its frames are averaged first. A row *reconstructed* a capture when every frame
of it that any row was run on has all four metrics defined, no `failure` recorded and the row's points cover at
least `floor_pct` of the ground-truth silhouette (`coverage_pct`; results without that column are judged without
the floor). A row that was not run on a capture failed it.

Which captures a metric counts, per row: P and P_e only where the row reconstructed the capture (they average the
error of the points it returned, which says nothing when it returned a few stray ones); C_g, C_s, coverage and
off % wherever they are defined, failure or not (C_g measures how much of the object is missing: a failure is
exactly what it should see). A table's means of a metric are over the captures where every compared row counts
it (`common_captures`).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

METRICS_CM = ["C_g_cm", "C_s_cm", "P_cm", "P_e_cm"]
ON_SUCCESS = ("P_cm", "P_e_cm")                       # counted only where the row reconstructed the capture
WHEREVER_DEFINED = ("C_g_cm", "C_s_cm", "coverage_pct", "off_pct")
GROUP_COLUMNS = ["method", "freq", "prior", "grid"]
PARAMETERS = "params"           # swept settings of a row (bench.harness.app: `offset_mm=2`), when present
CAPTURE_COLUMNS = ["object", "distance", "frame"]
PER_CAPTURE = ["object", "distance"]
# The least share of the silhouette that still counts as a reconstruction. A smooth ball shows the array only the cap
# whose normals bisect a transmit and a receive direction: 5.4 % of its silhouette at 30 cm, 1.6 % at 60 cm (the
# generator's farthest distance; tests/bench/report/test_scoring.py computes it from the QAR50 array), so a floor
# above that fails an ideal radar on a ball. 1 % stays below it and above the stray-pixel "successes" the floor is
# for (3-26 of 6,127 silhouette pixels, 0.05-0.4 %).
COVERAGE_FLOOR_PCT = 1.0
NOT_RUN = "not run"


def group_columns(rows: pd.DataFrame) -> list[str]:
    """The columns that make a row's identity: GROUP_COLUMNS and the swept parameters where the rows have them."""
    return GROUP_COLUMNS + ([PARAMETERS] if PARAMETERS in rows else [])


def _failure_reason(rows: pd.DataFrame, floor_pct: float) -> pd.Series:
    """Per result row: why it is not a success ('' for a success)."""
    # astype(object) first: an all-NaN column reads back as float64, which fillna("") will refuse in pandas 4
    failure = (rows["failure"].astype(object).fillna("").astype(str) if "failure" in rows
               else pd.Series("", index=rows.index))
    undefined = ~rows[METRICS_CM].notna().all(axis=1)
    reason = failure.where(failure != "", np.where(undefined, "metric undefined", ""))
    if "coverage_pct" in rows:
        coverage = rows["coverage_pct"].astype(float)
        low = (reason == "") & (coverage < floor_pct)          # NaN: not recorded (older rows), no floor
        reason = reason.where(~low, [f"covers {c:.2g} % of the silhouette (floor {floor_pct:g} %)" for c in coverage])
    return reason


def outcomes(rows: pd.DataFrame, floor_pct: float = COVERAGE_FLOOR_PCT) -> pd.DataFrame:
    """One line per (row identity, capture) for every capture of the table: `row_id` (0, 1, ... in the rows'
    order), the identity columns, `capture` ('object distance'), `ok`, `reason` ('' when ok, 'not run' where the
    row has no result) and the capture's metric values (frames averaged): P and P_e are NaN where the row did not
    reconstruct the capture, C_g, C_s, coverage and off % are kept wherever every frame defines them."""
    keys = group_columns(rows)
    rows = rows.assign(_reason=_failure_reason(rows, floor_pct))
    if PARAMETERS in rows:
        rows[PARAMETERS] = rows[PARAMETERS].astype(object).fillna("").astype(str)
    rows = rows.drop_duplicates(keys + CAPTURE_COLUMNS)
    frames_per_capture = rows[CAPTURE_COLUMNS].drop_duplicates().groupby(PER_CAPTURE).size().rename("_expected")
    values = [c for c in (*METRICS_CM, "coverage_pct", "off_pct", "off_px", "off_err_cm") if c in rows]
    grouped = rows.groupby(keys + PER_CAPTURE, sort=False)
    if grouped.ngroups == len(rows):     # one frame per capture: each value is its own mean (NaN where undefined)
        lines = grouped[values].mean()
    else:
        lines = grouped[values].agg(lambda v: v.mean() if v.notna().all() else np.nan)
    lines["_frames"] = grouped.size()
    lines["reason"] = grouped["_reason"].agg(lambda r: next((x for x in r if x), ""))
    lines = lines.reset_index().join(frames_per_capture, on=PER_CAPTURE)
    lines.loc[(lines.reason == "") & (lines._frames < lines._expected), "reason"] = "a frame not run"
    identities = rows[keys].drop_duplicates().reset_index(drop=True).rename_axis("row_id").reset_index()
    captures = frames_per_capture.reset_index()[PER_CAPTURE]
    full = identities.merge(captures, how="cross").merge(lines, on=keys + PER_CAPTURE, how="left")
    full["reason"] = full["reason"].fillna(NOT_RUN)
    full["ok"] = full["reason"] == ""
    for metric in ON_SUCCESS:
        full.loc[~full.ok, metric] = np.nan
    full.insert(len(keys) + 1, "capture", full.object.astype(str) + " " + full.distance.astype(str))
    return full.drop(columns=["_frames", "_expected"])


def metric_matrix(outcome: pd.DataFrame, metric: str) -> pd.DataFrame:
    """`metric` per row (index `row_id`) and capture (columns), NaN where not counted."""
    return outcome.pivot(index="row_id", columns="capture", values=metric)


def common_captures(matrix: pd.DataFrame) -> list[str]:
    """The captures where every row that counts the metric somewhere counts it (rows that count it nowhere are
    left out: they would leave no capture to compare; they are shown with their failures)."""
    counted = matrix.notna()
    taking_part = counted.any(axis=1)
    return [c for c in matrix.columns if counted.loc[taking_part, c].all()] if taking_part.any() else []
