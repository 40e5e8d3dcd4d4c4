"""`python -m bench.report.tables table1|table2|table3|runtime [--results PATH] [--csv FILE] [--latex FILE]`.

Table I lists, per two-frequency configuration, the frequencies actually selected from the MAROON sweep
`linspace(72, 82, 128)` GHz, their difference and the maximum unambiguous depth correction c / (4 delta_f).
Tables II and III (and the runtime table) summarise result rows per method x frequency configuration x prior x
grid (x swept parameters, the `params` column, where the rows carry it), metrics in centimetres, in the paper's row
order.

Fair comparison (bench.report.scoring): a row reconstructed a capture when its metrics are defined and its points
cover at least `--coverage-floor` (scoring.COVERAGE_FLOOR_PCT, 1 %) of the ground-truth silhouette; every other
capture of the table is one of the row's failures (also one it was not run on), listed with its reason and counted
in `failed`. Every mean of a metric is over the captures where every row of the table counts that metric: P and P_e
where every row reconstructed the capture, C_g, C_s, coverage and off % wherever every row defines them (a failure
included). So all rows of a table are compared on the same captures, bold marks the best mean per metric (BP_max
excluded, as in the paper: the many-frequency reference, not a high-speed method) and the ranking follows the means.
Uncertainty (bench.report.uncertainty): each mean with its 95 % bootstrap interval over captures, and each row
against the best row per metric, paired per capture (in how many captures it is better, permutation-test p).
Runtimes are means over rows timed alone (`timing == alone`); rows timed while other jobs shared the machine are
never shown as runtimes. PATH is a sweep root (its merged `results.csv`, else the jobs' `*/results.csv`) or a
results CSV; by default the committed `results/<table>/`. Markdown goes to stdout; `--csv` writes the summary
(with intervals, ranks and paired comparisons) and beside it `<name>_pairs.csv`, every pair of rows per metric.
"""
from __future__ import annotations

import argparse
import itertools
from pathlib import Path

import numpy as np
import pandas as pd

from bench import cli
from bench.report import scoring, uncertainty
from methods.domain.radar import MAROON_FREQS_HZ
from methods.ops.frequencies import CONFIGS_GHZ, max_unambiguous_depth_m, select_frequencies
from methods.registry import BUILTIN, label_of

RESULTS_DIR = Path(__file__).resolve().parents[2] / "results"
METRICS_CM = scoring.METRICS_CM
GROUP_COLUMNS = scoring.GROUP_COLUMNS
CAPTURE_COLUMNS = scoring.CAPTURE_COLUMNS
PER_CAPTURE = scoring.PER_CAPTURE               # frames of a capture are averaged first, then the captures
INTERVAL_COLUMNS = ["coverage_pct", *METRICS_CM, "off_pct"]      # means shown with a bootstrap interval
FREQ_ORDER = ["full", *(name for name in CONFIGS_GHZ if name != "full")]       # BP_max first, as in the paper
TITLES = {"table2": "Table II", "table3": "Table III", "beyond": "Table III extended (MM-3FSK, prior only)",
          "runtime": "Runtime and error"}
PRIOR_WORDS = {"photogrammetry": "the photogrammetry (ground-truth) prior", "realsense": "the RealSense prior",
               "none": "no per-pixel prior"}
BASELINE_METHOD = "prior_only"      # examples/prior_only.py: the depth camera alone, no radar (its freq is unused)
SHOWN_COLUMNS = {"coverage_pct": "coverage %", "C_g_cm": "C_g", "C_s_cm": "C_s", "P_cm": "P", "P_e_cm": "P_e",
                 "off_pct": "off %"}


def table1(freqs_hz: np.ndarray = MAROON_FREQS_HZ) -> pd.DataFrame:
    """Columns config, delta_f_GHz, f1_GHz, f2_GHz, dd_max_cm for the six two-frequency configurations."""
    rows = []
    for name, targets_ghz in CONFIGS_GHZ.items():
        if targets_ghz is None or len(targets_ghz) != 2:
            continue
        f1_hz, f2_hz = freqs_hz[select_frequencies(freqs_hz, targets_ghz)]
        rows.append({"config": name, "delta_f_GHz": (f2_hz - f1_hz) / 1e9, "f1_GHz": f1_hz / 1e9,
                     "f2_GHz": f2_hz / 1e9, "dd_max_cm": max_unambiguous_depth_m(f2_hz - f1_hz) * 100.0})
    return pd.DataFrame(rows)


def _nominal_delta(name: str) -> str:
    """'d05' -> 'Δ0.5', 'd10' -> 'Δ10.0' (the paper's notation)."""
    digits = name[1:]
    return f"Δ{float('0.' + digits[1:]) if digits.startswith('0') else float(digits)}"


def row_label(method: str, freq: str, label: str | None = None, parameters: str = "") -> str:
    """The paper's row names: BP_max, BP Δ0.5, 2FSK Δ1.0, 3FSK(Δ0.5, Δ10.0), MM-2FSK Δ10.0, followed by the
    row's swept parameters (`params`) where it has any ('custom Δ10.0 offset_mm=2'). `label` is the method's own (its
    class's `label`, the rows' `label` column); by default that of the built-in `method`. The depth camera alone
    (BASELINE_METHOD) uses no radar frequency: 'Prior only (no radar)'."""
    label = label or label_of(method)
    if method == BASELINE_METHOD:
        name = f"{label} (no radar)"
    elif freq == "full":
        name = f"{label}_max"
    else:
        parts = [_nominal_delta(part) for part in freq.split("_")]
        name = f"{label} {parts[0]}" if len(parts) == 1 else f"{label}({', '.join(parts)})"
    return f"{name} {parameters}" if parameters else name


def job_label(results_csv: Path) -> str:
    """The row label of one job's results (its first row: method, freq, its own `label` and `params`)."""
    first = pd.read_csv(results_csv, nrows=1).iloc[0]
    given = lambda column: str(first[column]) if column in first and pd.notna(first[column]) else None  # noqa: E731
    return row_label(first.method, first.freq, given("label"), given(scoring.PARAMETERS) or "")


def method_labels(rows: pd.DataFrame) -> dict[str, str]:
    """Label per method name of the rows: their `label` column (methods of one's own), else the built-in's."""
    labels = {}
    for method, group in rows.groupby("method", sort=False):
        given = group["label"].dropna() if "label" in group else pd.Series(dtype=object)
        labels[method] = str(given.iloc[0]) if len(given) else label_of(method)
    return labels


def _method_order(method: str) -> int:
    """Built-ins in their registry order, other methods after them."""
    return list(BUILTIN).index(method) if method in BUILTIN else len(BUILTIN)


def _freq_order(freq: str) -> int:
    """BP_max first, then the configurations in Table I's order, unknown ones last."""
    return FREQ_ORDER.index(freq) if freq in FREQ_ORDER else len(FREQ_ORDER)



def _weighted_off_error_cm(lines: pd.DataFrame) -> float:
    """Mean distance of all off-object pixels of the captures `lines` (each capture weighted by its count)."""
    if "off_px" not in lines or lines.off_px.fillna(0).sum() == 0:
        return float("nan")
    weights = lines.off_px.fillna(0)
    return float((lines.off_err_cm.fillna(0) * weights).sum() / weights.sum())


def _failures_text(lines: pd.DataFrame) -> str:
    """'capture: reason; ...' of a row's failed captures."""
    return "; ".join(f"{c}: {r}" for c, r in zip(lines.capture, lines.reason, strict=True) if r)


def _ranked(summary: pd.DataFrame, metric: str) -> pd.Series:
    """Rank (1 = lowest mean) of the rows that may be best on `metric` (BP_max excluded), NaN for the others."""
    candidates = summary[metric].where(summary.freq != "full")
    return candidates.rank(method="min")


def _against_best(summary: pd.DataFrame, matrices: dict[str, pd.DataFrame], common: dict[str, list]) -> None:
    """Per metric, each row against the best row (the best against the runner-up), paired on the common captures:
    columns `<metric>_vs`, `_better`, `_worse`, `_pairs` (captures compared) and `_p` (bench.report.uncertainty)."""
    for metric in METRICS_CM:
        order = summary[f"{metric}_rank"].dropna().sort_values(kind="stable").index
        against = {index: order[1] if len(order) > 1 and index == order[0] else (order[0] if len(order) else None)
                   for index in summary.index}
        against = {index: other for index, other in against.items() if other is not None and other != index}
        matrix = matrices[metric][common[metric]]
        values = dict(zip(matrix.index, matrix.to_numpy(), strict=True))
        results = dict(zip(against, uncertainty.paired_all(
            [(values[summary.row_id[index]], values[summary.row_id[other]]) for index, other in against.items()]),
            strict=True))
        columns = {k: [] for k in ("vs", "better", "worse", "pairs", "p")}
        for index in summary.index:
            if index not in results:
                for k, empty in (("vs", ""), ("better", 0), ("worse", 0), ("pairs", 0), ("p", np.nan)):
                    columns[k].append(empty)
                continue
            result = results[index]
            for k, value in (("vs", summary.row[against[index]]), ("better", result.a_better),
                             ("worse", result.b_better), ("pairs", result.n), ("p", result.p_value)):
                columns[k].append(value)
        for k, values in columns.items():
            summary[f"{metric}_{k}"] = values


def _distinct(labels: list[str], summary: pd.DataFrame) -> list[str]:
    """Row labels made unique: where rows share one (same method and configuration, another prior or grid), the
    prior and then the grid are added ('MM-2FSK Δ10.0 (photogrammetry)')."""
    for column in ("prior", "grid"):
        counts = pd.Series(labels).value_counts()
        labels = [f"{label} ({value})" if counts[label] > 1 else label
                  for label, value in zip(labels, summary[column], strict=True)]
    return labels


def _scored(rows: pd.DataFrame, floor_pct: float) -> tuple[pd.DataFrame, pd.DataFrame, dict, dict]:
    """(outcomes, summary, metric matrices, common captures per metric) of a table's rows."""
    outcome = scoring.outcomes(rows, floor_pct)
    keys = scoring.group_columns(rows)
    rows = rows.assign(_alone=rows["timing"].eq("alone") if "timing" in rows else False,
                       runtime_ms=rows["runtime_ms"] if "runtime_ms" in rows else np.nan)
    if scoring.PARAMETERS in rows:
        rows[scoring.PARAMETERS] = rows[scoring.PARAMETERS].astype(object).fillna("").astype(str)
    shown = [m for m in INTERVAL_COLUMNS if m in outcome]
    matrices = {m: scoring.metric_matrix(outcome, m) for m in shown}
    common = {m: scoring.common_captures(matrices[m]) for m in shown}
    n_captures = outcome.capture.nunique()
    intervals = {}                   # (metric, row_id) -> Interval, bootstrapped together per metric
    for metric in shown:
        matrix = matrices[metric][common[metric]]
        intervals.update(zip([(metric, row_id) for row_id in matrix.index],
                             uncertainty.mean_intervals(matrix.to_numpy()), strict=True))
    lines = []
    for row_id, part in outcome.groupby("row_id", sort=True):
        identity = part.iloc[0][keys].to_dict()
        line = {"row_id": row_id, **identity, "captures": n_captures, "failed": int((~part.ok).sum()),
                "ok": int(part.ok.sum()), "failures": _failures_text(part)}
        for metric in shown:
            interval = intervals[metric, row_id]
            line.update({metric: interval.mean, f"{metric}_low": interval.low, f"{metric}_high": interval.high,
                         f"{metric}_n": interval.n})
        line["off_err_cm"] = _weighted_off_error_cm(part[part.capture.isin(common.get("off_pct", []))])
        timed = rows[rows._alone & np.logical_and.reduce([rows[k].eq(v) for k, v in identity.items()])]
        alone = timed.groupby(PER_CAPTURE).runtime_ms.mean()
        line["runtime_ms"] = alone.mean() if len(alone) else float("nan")
        line["runtime_rows"] = len(timed)
        lines.append(line)
    summary = pd.DataFrame(lines)
    order = summary.method.map(_method_order) * 100 + summary.freq.map(_freq_order)
    summary = summary.iloc[np.argsort(order.to_numpy(), kind="stable")].reset_index(drop=True)
    labels = method_labels(rows)
    summary.insert(0, "row", _distinct([row_label(m, f, labels[m], p) for m, f, p in zip(
        summary.method, summary.freq, summary.get(scoring.PARAMETERS, [""] * len(summary)), strict=True)], summary))
    for metric in METRICS_CM:
        summary[f"{metric}_rank"] = _ranked(summary, metric)
    _against_best(summary, matrices, common)
    return outcome, summary, matrices, common


def summarise(rows: pd.DataFrame, floor_pct: float = scoring.COVERAGE_FLOOR_PCT) -> pd.DataFrame:
    """One line per row (method x freq x prior x grid x parameters) in the paper's order: `captures`, `failed`,
    `ok`, `failures` ('capture: reason; ...'), per metric (and coverage, off %) the mean over the captures every
    row counts, its bootstrap interval (`_low`, `_high`) and capture count (`_n`), per metric the rank among the
    rows that may be best and the paired comparison with the best row (`_vs`, `_better`, `_worse`, `_pairs`,
    `_p`); off err (weighted by off-object pixels), runtime (ms, rows timed alone) and its count."""
    return _scored(rows, floor_pct)[1]


PAIR_COLUMNS = ["metric", "a", "b", "captures", "a_better", "b_better", "mean_diff_cm", "p"]


def paired_comparisons(rows: pd.DataFrame, floor_pct: float = scoring.COVERAGE_FLOOR_PCT) -> pd.DataFrame:
    """Every pair of rows per metric on the metric's common captures: `metric`, `a`, `b`, `captures`, `a_better`,
    `b_better` (captures where each is lower), `mean_diff_cm` (a - b) and the permutation test's `p`."""
    return summary_and_pairs(rows, floor_pct)[1]


def summary_and_pairs(rows: pd.DataFrame, floor_pct: float = scoring.COVERAGE_FLOOR_PCT
                      ) -> tuple[pd.DataFrame, pd.DataFrame]:
    """(`summarise`, `paired_comparisons`) of the rows, scored once (the scoring and the bootstrap intervals are
    most of either's cost)."""
    _, summary, matrices, common = _scored(rows, floor_pct)
    lines = []
    for metric in METRICS_CM:
        matrix = matrices[metric][common[metric]]
        values = dict(zip(matrix.index, matrix.to_numpy(), strict=True))
        combinations = list(itertools.combinations(summary[["row_id", "row"]].itertuples(index=False), 2))
        results = uncertainty.paired_all([(values[i], values[j]) for (i, _), (j, _) in combinations])
        for ((_, a), (_, b)), result in zip(combinations, results, strict=True):
            lines.append({"metric": metric, "a": a, "b": b, "captures": result.n, "a_better": result.a_better,
                          "b_better": result.b_better, "mean_diff_cm": result.mean_diff, "p": result.p_value})
    return summary, pd.DataFrame(lines, columns=PAIR_COLUMNS)


def pair_of(pairs: pd.DataFrame, metric: str, a: str, b: str) -> tuple[int, int, int, float] | None:
    """(captures, a better, b better, p) of rows `a` and `b` on `metric` from `paired_comparisons`, whichever
    order it holds them in; None when it has no such pair."""
    for first, second, flip in ((a, b, False), (b, a, True)):
        found = pairs[(pairs.metric == metric) & (pairs.a == first) & (pairs.b == second)]
        if len(found):
            line = found.iloc[0]
            better, worse = (line.b_better, line.a_better) if flip else (line.a_better, line.b_better)
            return int(line.captures), int(better), int(worse), float(line.p)
    return None


def best_rows(summary: pd.DataFrame) -> dict[str, int]:
    """Per metric, the index of the rank-1 row (the smallest mean on the common captures, BP_max excluded)."""
    return {m: int(summary[f"{m}_rank"].idxmin()) for m in METRICS_CM if summary[f"{m}_rank"].notna().any()}


def _methods_sentence(rows: pd.DataFrame) -> str:
    parts, labels = [], method_labels(rows)
    for method, group in rows.groupby("method", sort=False):
        priors = " / ".join(PRIOR_WORDS.get(p, f"prior {p}") for p in group.prior.unique())
        if method in ("2fsk", "3fsk") and set(group.prior) == {"none"}:
            priors = "the scalar prior (0.40 m by default)"
        grids = ", ".join(sorted(group.grid.unique()))
        computed = (f" (computed on grid {grids})" if grids != "from_capture" else "")
        parts.append(f"{labels[method]} with {priors}{computed}")
    return "; ".join(parts)


def _common_sentence(summary: pd.DataFrame) -> str:
    """How many captures each kind of mean covers, from the summary's `_n` columns."""
    n = {m: int(summary[f"{m}_n"].max()) if f"{m}_n" in summary and len(summary) else 0 for m in INTERVAL_COLUMNS}
    total = int(summary.captures.max()) if len(summary) else 0
    chamfer = f"C_g and C_s over {n['C_g_cm']}" if n["C_g_cm"] == n["C_s_cm"] else \
        f"C_g over {n['C_g_cm']}, C_s over {n['C_s_cm']}"
    projective = f"P and P_e over {n['P_cm']}" if n["P_cm"] == n["P_e_cm"] else \
        f"P over {n['P_cm']}, P_e over {n['P_e_cm']}"
    return (f"Every mean is over the captures where every row counts the metric: {projective} of the {total} "
            f"captures (those every row reconstructed), {chamfer} (wherever every row defines them, a failure "
            f"included)")


def caption(name: str, rows: pd.DataFrame, floor_pct: float = scoring.COVERAGE_FLOOR_PCT,
            summary: pd.DataFrame | None = None) -> str:
    """What the table holds, from its rows: methods and priors, captures, grids, success, counting and metric
    rules (`summary`: the rows' summarise(), computed when not given)."""
    summary = summarise(rows, floor_pct) if summary is None else summary
    objects, distances = sorted(rows.object.unique()), sorted(rows.distance.unique())
    n_captures = len(rows[PER_CAPTURE].drop_duplicates())
    n_frames = len(rows[CAPTURE_COLUMNS].drop_duplicates())
    frames = f", {n_frames} frames, each capture's frames averaged first" if n_frames > n_captures else ""
    faithful = "metrics" in rows and rows["metrics"].eq("faithful").any()
    metric_rule = ("MAROON's reference metric definitions (metrics.faithful=true): P counts every radar point, "
                   "off-object ones with their full depth as error" if faithful else
                   "P and P_e: mean |depth error| over radar points on the object's ground-truth silhouette "
                   "(P_e: the silhouette eroded by MAROON's kernel in mm), the same region for every method")
    floor = (f"its points cover at least {floor_pct:g} % of the object's ground-truth silhouette (coverage)"
             if "coverage_pct" in rows else "(coverage not recorded in these results: no floor applied)")
    devices = ", ".join(sorted(rows.device.astype(str).unique()))
    return (f"{TITLES.get(name, name)}: {_methods_sentence(rows)}. {n_captures} captures "
            f"({', '.join(objects)}) at {', '.join(map(str, distances))} cm{frames}, every depth map scored on its "
            f"capture's calibration pixel grid (methods computed on another grid are resampled: bilinear on one "
            f"surface, else nearest pixel). A row reconstructed a capture when its metrics are defined and {floor}; "
            f"failed counts the others (reasons below the table). {_common_sentence(summary)}. Each mean with its "
            f"{uncertainty.CONFIDENCE:.0%} bootstrap interval over those captures. {metric_rule}; off %: share of "
            f"the radar points off the silhouette or outside mask_bb (false positives), off err: mean distance of "
            f"those inside mask_bb to the object. Metrics in cm; runtime in ms per frame ({devices}), only from runs "
            f"timed alone (n/a otherwise). Best mean per metric in bold, BP_max excluded.")


def _number(value: float, digits: int = 2) -> str:
    return "–" if not np.isfinite(value) else f"{value:.{digits}f}"


def _with_interval(line: pd.Series, metric: str, digits: int, bold) -> str:
    """'mean [low, high]', the mean through `bold` when it is the best."""
    mean = _number(line[metric], digits)
    if mean == "–":
        return mean
    interval = (f" [{_number(line[f'{metric}_low'], digits)}, {_number(line[f'{metric}_high'], digits)}]"
                if np.isfinite(line[f"{metric}_low"]) else "")
    return f"{bold(mean)}{interval}"


def _header(summary: pd.DataFrame, metric: str) -> str:
    n = int(summary[f"{metric}_n"].max()) if len(summary) else 0
    return f"{SHOWN_COLUMNS[metric]} ({n} of {int(summary.captures.max()) if len(summary) else 0})"


def _formatted(summary: pd.DataFrame, bold) -> pd.DataFrame:
    """The shown table: labels, failed as 'k/N', each mean with its interval, the best through `bold`."""
    best = best_rows(summary)
    shown = pd.DataFrame({"": summary.row, "failed": [f"{k}/{n}" for k, n in zip(summary.failed, summary.captures,
                                                                                strict=True)]})
    plain = lambda text: text   # noqa: E731
    for metric in [m for m in INTERVAL_COLUMNS if m in summary]:
        digits = 1 if metric.endswith("_pct") else 2
        shown[_header(summary, metric)] = [
            _with_interval(line, metric, digits, bold if best.get(metric) == i else plain)
            for i, line in summary.iterrows()]
    shown["off err"] = [_number(v) for v in summary.off_err_cm]
    shown["runtime_ms"] = ["n/a" if not np.isfinite(v) else f"{v:.1f}" for v in summary.runtime_ms]
    return shown


def against_best(summary: pd.DataFrame) -> pd.DataFrame:
    """Per row and metric, the paired comparison with the best row as text: 'best better in 6/7, p 0.03'; for the
    best row its margin over the runner-up ('best; better than X in 6/7, p 0.03')."""
    best = best_rows(summary)
    shown = pd.DataFrame({"": summary.row})
    for metric in METRICS_CM:
        cells = []
        for i, line in summary.iterrows():
            pairs = int(line[f"{metric}_pairs"])
            if not pairs:
                cells.append("–")
            elif best.get(metric) == i:
                cells.append(f"best; better than {line[f'{metric}_vs']} in {line[f'{metric}_better']}/{pairs}, "
                             f"p {uncertainty.p_text(line[f'{metric}_p'])}")
            else:
                cells.append(f"best better in {line[f'{metric}_worse']}/{pairs}, "
                             f"p {uncertainty.p_text(line[f'{metric}_p'])}")
        shown[SHOWN_COLUMNS[metric]] = cells
    return shown


def failures_list(summary: pd.DataFrame) -> list[str]:
    """'row (k of N): capture: reason; ...' for every row that failed somewhere."""
    return [f"{line.row} ({line.failed} of {line.captures}): {line.failures}" for line in summary.itertuples()
            if line.failed]


def to_markdown(table: pd.DataFrame) -> str:
    """A plain Markdown table, floats to two decimals, missing numbers as '–'."""
    header = "| " + " | ".join(map(str, table.columns)) + " |"
    rule = "|" + "|".join("---" for _ in table.columns) + "|"
    body = ["| " + " | ".join(_number(v) if isinstance(v, float) else str(v) for v in row) + " |"
            for row in table.itertuples(index=False)]
    return "\n".join([header, rule, *body])


def summary_markdown(summary: pd.DataFrame) -> str:
    """The table, the paired comparisons with the best row and the failures, in Markdown."""
    failures = failures_list(summary)
    return "\n".join([to_markdown(_formatted(summary, lambda s: f"**{s}**")),
                      "\nPaired with the best row of each metric (per capture, on the same captures as the means; "
                      "two-sided permutation test, not corrected for the number of comparisons):\n",
                      to_markdown(against_best(summary)),
                      "\nFailures (captures a row did not reconstruct):\n",
                      "\n".join(f"* {line}" for line in failures) or "none"])


_LATEX_SPECIALS = {"\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
                   "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}"}
_LATEX_SYMBOLS = {"Δ": r"$\Delta$", "†": r"$^\dagger$", "–": "--", "±": r"$\pm$"}


def latex_text(text: str) -> str:
    """Plain text as LaTeX: TeX's special characters escaped, then Δ † – ± as LaTeX symbols (for captions)."""
    return "".join(_LATEX_SYMBOLS.get(ch, _LATEX_SPECIALS.get(ch, ch)) for ch in str(text))


def styler_latex(table: pd.DataFrame, caption_text: str | None = None, keep: set[str] = frozenset()) -> str:
    """LaTeX (booktabs rules) of a table through pandas' Styler, which escapes every cell and header; columns in
    `keep` hold LaTeX already. The preamble needs `\\usepackage{booktabs}`."""
    escape = lambda value: latex_text(value)   # noqa: E731
    styler = table.style.hide(axis="index")
    text_columns = [c for c in table.columns if c not in keep and not pd.api.types.is_numeric_dtype(table[c])]
    styler = styler.format({c: escape for c in text_columns}, precision=2)
    styler = styler.format_index(escape, axis=1)
    body = styler.to_latex(caption=None if caption_text is None else latex_text(caption_text), hrules=True,
                           position="htbp")
    return "% needs \\usepackage{booktabs}\n" + body


def summary_latex(summary: pd.DataFrame, caption_text: str) -> str:
    """The table as LaTeX (booktabs), best means in bold; the paired comparisons and failures stay in Markdown."""
    shown = _formatted(summary, lambda s: f"\x00{s}\x01")
    bold_cells = {c for c in shown.columns if c not in ("", "failed")}
    for column in bold_cells:   # bold after escaping: mark the best values, escape, then wrap them
        shown[column] = [latex_text(v).replace("\x00", r"\textbf{").replace("\x01", "}") for v in shown[column]]
    shown[""] = [latex_text(v).replace(r"\_max", r"$_{\max}$") for v in shown[""]]
    return styler_latex(shown, caption_text, keep=bold_cells | {""})


def read_rows(path: Path) -> pd.DataFrame:
    """Result rows from a results CSV, a sweep root's merged results.csv, or its jobs' */results.csv."""
    if path.is_file():
        return pd.read_csv(path)
    if (path / "results.csv").is_file():
        return pd.read_csv(path / "results.csv")
    parts = sorted(path.glob("*/results.csv"))
    if not parts:
        raise FileNotFoundError(f"{path}: no results.csv and no */results.csv")
    return pd.concat([pd.read_csv(p) for p in parts], ignore_index=True)


RESULT_KEYS = ("object", "distance", "frame", "method", "freq", "prior", "grid", "device", "runtime_ms")


def load_rows(table: str, given: Path | None) -> pd.DataFrame:
    """The rows of `--results` (default: the committed `results/<table>/`), or a one-line UserError when the path
    is missing or holds no results CSV."""
    if given is None and not (RESULTS_DIR / table).exists():
        raise cli.UserError(RESULTS_DIR / table, f"no committed results for {table}: run `python -m bench -m "
                            f"experiment={table}` and pass its sweep root with --results DIR")
    path = cli.existing_path(given or RESULTS_DIR / table, "any", "results path")
    try:
        rows = read_rows(path)
    except (pd.errors.ParserError, pd.errors.EmptyDataError, UnicodeDecodeError) as err:
        raise cli.UserError(path, f"not a results CSV ({' '.join(str(err).split())})") from None
    missing = [c for c in (*RESULT_KEYS, *METRICS_CM) if c not in rows]
    if missing:
        raise cli.UserError(path, f"not a results CSV: no column {', '.join(missing)}")
    if rows.empty:
        raise cli.UserError(path, "holds no result rows")
    return rows


def main() -> int:
    parser = cli.ArgumentParser(prog="python -m bench.report.tables", description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("table", choices=["table1", *TITLES])
    parser.add_argument("--results", type=Path, help="sweep root or results CSV (default: results/<table>/)")
    parser.add_argument("--csv", type=Path, help="also write the table as CSV (and <name>_pairs.csv beside it)")
    parser.add_argument("--latex", type=Path, help="also write the table as LaTeX")
    parser.add_argument("--coverage-floor", type=float, default=scoring.COVERAGE_FLOOR_PCT, metavar="PCT",
                        help="share of the silhouette (%%) a row's points must cover for a success (default "
                             f"{scoring.COVERAGE_FLOOR_PCT:g})")
    args = parser.parse_args()
    if not 0.0 <= args.coverage_floor <= 100.0:
        parser.error(f"--coverage-floor {args.coverage_floor:g}: a share between 0 and 100 %")
    csv_file, latex_file = (None if f is None else cli.output_file(f) for f in (args.csv, args.latex))
    if args.table == "table1":
        table = table1()
        print(to_markdown(table))
        if csv_file:
            table.to_csv(csv_file, index=False, float_format="%.4f")
        if latex_file:
            latex_file.write_text(styler_latex(table, "Table I: frequency configurations"))
        return 0
    rows = load_rows(args.table, args.results)
    summary = summarise(rows, args.coverage_floor)
    text = caption(args.table, rows, args.coverage_floor, summary)
    if csv_file:                # the files first: a reader closing stdout early (`| head`) must not lose them
        write_csv(summary, csv_file, paired_comparisons(rows, args.coverage_floor))
    if latex_file:
        latex_file.write_text(summary_latex(summary, text))
    print(f"{text}\n\n{summary_markdown(summary)}")
    return 0


def write_csv(summary: pd.DataFrame, path: Path, pairs: pd.DataFrame) -> None:
    """The summary at `path` and every pair of rows at `<stem>_pairs.csv` beside it."""
    summary.to_csv(path, index=False, float_format="%.4f")
    pairs.to_csv(path.with_name(f"{path.stem}_pairs.csv"), index=False, float_format="%.4g")


if __name__ == "__main__":
    cli.run_guarded(main)
