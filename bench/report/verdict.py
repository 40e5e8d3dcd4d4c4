"""The verdict a report opens with, computed from a table's summary and paired comparisons (bench.report.tables):
the best row per metric with its interval and its margin over the runner-up, the rows on the runtime-against-
error front, what the radar adds over the depth camera alone, and why any row is marked (its failures).
"""
from __future__ import annotations

import numpy as np
import pandas as pd

from bench.report import tables, uncertainty
from bench.report.plots import pareto_front

FRONT_METRIC = "P_cm"


def _mean(line: pd.Series, metric: str) -> str:
    text = f"{line[metric]:.2f} cm"
    if np.isfinite(line[f"{metric}_low"]):
        text += f" [{line[f'{metric}_low']:.2f}, {line[f'{metric}_high']:.2f}]"
    return text


def best_lines(summary: pd.DataFrame) -> list[str]:
    """Per metric: the best row, its mean and interval, and how it compares with the runner-up, paired."""
    lines = []
    for metric, index in tables.best_rows(summary).items():
        best = summary.loc[index]
        n, total = int(best[f"{metric}_n"]), int(best.captures)
        text = f"{tables.SHOWN_COLUMNS[metric]}: {best.row}, {_mean(best, metric)} over {n} of {total} captures"
        if best[f"{metric}_pairs"]:
            runner = summary[summary.row == best[f"{metric}_vs"]].iloc[0]
            if runner[metric] == best[metric]:
                text += f"; tied with {runner.row}"
            else:
                text += (f"; better than the runner-up {runner.row} ({runner[metric]:.2f} cm) in "
                         f"{best[f'{metric}_better']} of {best[f'{metric}_pairs']} captures, "
                         f"p {uncertainty.p_text(best[f'{metric}_p'])}")
        lines.append(text)
    return lines


def front_line(summary: pd.DataFrame) -> str:
    """The rows no other row beats in both runtime (measured alone) and mean P."""
    timed = summary[np.isfinite(summary.runtime_ms) & np.isfinite(summary[FRONT_METRIC])]
    if timed.empty:
        return "Runtime against error: no runtime measured alone (run the sweep one job at a time)."
    front = timed[pareto_front(timed.runtime_ms, timed[FRONT_METRIC])].sort_values("runtime_ms")
    parts = [f"{row} ({runtime_ms:.4g} ms, P {error_cm:.2f} cm)"
             for row, runtime_ms, error_cm in zip(front.row, front.runtime_ms, front[FRONT_METRIC], strict=True)]
    return f"Runtime against error (P): the front, fastest first: {'; '.join(parts)}."


def baseline_lines(summary: pd.DataFrame, pairs: pd.DataFrame) -> list[str]:
    """What the radar adds: the best radar row on P against the depth camera alone, per metric, paired."""
    baseline = summary[summary.method == tables.BASELINE_METHOD]
    radar = summary[(summary.method != tables.BASELINE_METHOD) & (summary.freq != "full")]
    if baseline.empty or radar[FRONT_METRIC].isna().all():
        return []
    camera, best = baseline.iloc[0], radar.loc[radar[FRONT_METRIC].idxmin()]
    lines = []
    for metric in tables.METRICS_CM:
        found = tables.pair_of(pairs, metric, best.row, camera.row)
        if found is None or not np.isfinite(best[metric]) or not np.isfinite(camera[metric]):
            continue
        n, better, worse, p = found
        lines.append(f"{tables.SHOWN_COLUMNS[metric]}: {best.row} {best[metric]:.2f} cm against the camera's "
                     f"{camera[metric]:.2f} cm ({best[metric] / camera[metric]:.2f}x); the radar better in "
                     f"{better} of {n} captures, the camera in {worse}, p {uncertainty.p_text(p)}")
    return [f"What the radar adds over the depth camera alone ({camera.row}), for the best radar row on P:",
            *lines]


def marked_lines(summary: pd.DataFrame) -> list[str]:
    """Why a row is marked: its failed captures and their reasons (bench.report.tables.failures_list)."""
    failures = tables.failures_list(summary)
    if not failures:
        return ["No row failed on any capture: every mean covers every capture."]
    return ["Rows with failed captures (each mean above leaves out the captures some row failed on):", *failures]


def verdict(summary: pd.DataFrame, pairs: pd.DataFrame) -> dict[str, list[str]]:
    """The verdict's parts as plain-text lines: best per metric, front, baseline, marked rows."""
    return {"best": best_lines(summary), "front": [front_line(summary)], "baseline": baseline_lines(summary, pairs),
            "marked": marked_lines(summary)}
