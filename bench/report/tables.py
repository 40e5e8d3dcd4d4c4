"""`python -m bench.report.tables table1|table2|table3|runtime [--results PATH] [--csv FILE] [--latex FILE]`.

Table I lists, per two-frequency configuration, the frequencies actually selected from the MAROON sweep
`linspace(72, 82, 128)` GHz, their difference and the maximum unambiguous depth correction c / (4 delta_f).
Tables II and III (and the runtime table) summarise result rows per method x frequency configuration x prior x
grid, metrics in centimetres, in the paper's row order. Counting rule: the table's captures are every capture
any row was run on; a capture where a row has no row or a metric is undefined (`failure`) is a failed capture of
that row, never a missing value. Frame sequences: a capture's frames are averaged first (a capture fails for a
row when any of its frames does), then the captures. `ok` counts each row's successes; a row that failed anywhere is
marked † (not
comparable): its means cover only its successes and it is not ranked. Every other row is a mean over the same
captures for every metric. The best value per metric among the comparable rows is in bold (BP_max excluded, as in
the paper: it is the many-frequency reference, not a high-speed method). Runtimes are means over rows timed alone
(`timing == alone`); rows timed while other jobs shared the machine are never shown as runtimes. PATH is a sweep
root (its merged `results.csv`, else the jobs' `*/results.csv`) or a results CSV; by default the committed
`results/<table>/`. Markdown goes to stdout.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from bench import cli
from methods.domain.radar import MAROON_FREQS_HZ
from methods.ops.frequencies import CONFIGS_GHZ, max_unambiguous_depth_m, select_frequencies
from methods.registry import BUILTIN, label_of

RESULTS_DIR = Path(__file__).resolve().parents[2] / "results"
METRICS_CM = ["C_g_cm", "C_s_cm", "P_cm", "P_e_cm"]
GROUP_COLUMNS = ["method", "freq", "prior", "grid"]
CAPTURE_COLUMNS = ["object", "distance", "frame"]
PER_CAPTURE = ["object", "distance"]           # frames of a capture are averaged first, then the captures
FREQ_ORDER = ["full", *(name for name in CONFIGS_GHZ if name != "full")]       # BP_max first, as in the paper
TITLES = {"table2": "Table II", "table3": "Table III", "beyond": "Table III extended (MM-3FSK, prior only)",
          "runtime": "Runtime and error"}
PRIOR_WORDS = {"photogrammetry": "the photogrammetry (ground-truth) prior", "realsense": "the RealSense prior",
               "none": "no per-pixel prior"}
NOT_COMPARABLE = "†"
SHOWN_COLUMNS = {"ok": "ok", "C_g_cm": "C_g", "C_s_cm": "C_s", "P_cm": "P", "P_e_cm": "P_e", "off_pct": "off %",
                 "off_err_cm": "off err", "runtime_ms": "runtime_ms"}


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


def row_label(method: str, freq: str, label: str | None = None) -> str:
    """The paper's row names: BP_max, BP Δ0.5, 2FSK Δ1.0, 3FSK(Δ0.5, Δ10.0), MM-2FSK Δ10.0. `label` is the
    method's own (its class's `label`, the rows' `label` column); by default that of the built-in `method`."""
    label = label or label_of(method)
    if freq == "full":
        return f"{label}_max"
    parts = [_nominal_delta(part) for part in freq.split("_")]
    if len(parts) == 1:
        return f"{label} {parts[0]}"
    return f"{label}({', '.join(parts)})"


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


def succeeded(rows: pd.DataFrame) -> pd.Series:
    """Per result row: every metric defined and no `failure` recorded (older files have no failure column)."""
    ok = rows[METRICS_CM].notna().all(axis=1)
    if "failure" in rows:
        failure = rows["failure"]
        ok &= failure.isna() | (failure.astype(str) == "")     # all-NaN columns read back as float64
    return ok


def _weighted_off_error_cm(group: pd.DataFrame) -> float:
    """Mean distance of all off-object pixels of the group's captures (each capture weighted by its count)."""
    if "off_px" not in group or group.off_px.fillna(0).sum() == 0:
        return float("nan")
    weights = group.off_px.fillna(0)
    return float((group.off_err_cm.fillna(0) * weights).sum() / weights.sum())


def summarise(rows: pd.DataFrame) -> pd.DataFrame:
    """One line per method x freq x prior x grid in the paper's order: captures, ok, comparable, mean metrics over
    the row's successful captures, off-object share and error, runtime (ms, rows timed alone) and its count."""
    rows = rows.copy()
    rows["_ok"] = succeeded(rows)
    rows["_alone"] = rows["timing"].eq("alone") if "timing" in rows else False
    frames = rows[CAPTURE_COLUMNS].drop_duplicates()
    n_captures = len(frames[PER_CAPTURE].drop_duplicates())
    frames_per_capture = frames.groupby(PER_CAPTURE).size()
    lines = []
    for keys, group in rows.groupby(GROUP_COLUMNS, sort=False):
        good = group[group._ok].drop_duplicates(CAPTURE_COLUMNS)
        # a capture counts when every frame of it that any row was run on succeeded; its frames are averaged
        # first, so a capture with many frames weighs as much as one with a single frame
        done = good.groupby(PER_CAPTURE).size()
        complete = done[done == frames_per_capture.reindex(done.index)].index
        good = good.set_index(PER_CAPTURE).loc[complete].reset_index()
        per_capture = good.groupby(PER_CAPTURE)[[c for c in METRICS_CM + ["off_pct"] if c in good]].mean()
        alone = group[group._alone].groupby(PER_CAPTURE).runtime_ms.mean()
        ok = len(per_capture)
        line = dict(zip(GROUP_COLUMNS, keys, strict=False), captures=n_captures, ok=ok, comparable=ok == n_captures)
        line.update({m: per_capture[m].mean() if ok else float("nan") for m in METRICS_CM})
        line["off_pct"] = per_capture["off_pct"].mean() if "off_pct" in per_capture and ok else float("nan")
        line["off_err_cm"] = _weighted_off_error_cm(good)
        line["runtime_ms"] = alone.mean() if len(alone) else float("nan")
        line["runtime_rows"] = int(group._alone.sum())
        lines.append(line)
    summary = pd.DataFrame(lines)
    order = summary.method.map(_method_order) * 100 + summary.freq.map(FREQ_ORDER.index)
    summary = summary.iloc[np.argsort(order.to_numpy(), kind="stable")].reset_index(drop=True)
    labels = method_labels(rows)
    summary.insert(0, "row", [row_label(m, f, labels[m]) for m, f in zip(summary.method, summary.freq, strict=False)])
    return summary


def best_rows(summary: pd.DataFrame) -> dict[str, int]:
    """Per metric, the index of the smallest mean among the comparable non-BP_max rows."""
    candidates = summary[(summary.freq != "full") & summary.comparable]
    return {m: int(candidates[m].idxmin()) for m in METRICS_CM if candidates[m].notna().any()}


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


def caption(name: str, rows: pd.DataFrame) -> str:
    """What the table holds, from its rows: methods and priors, captures, grids, counting and metric rules."""
    objects, distances = sorted(rows.object.unique()), sorted(rows.distance.unique())
    n_captures = len(rows[PER_CAPTURE].drop_duplicates())
    n_frames = len(rows[CAPTURE_COLUMNS].drop_duplicates())
    frames = f", {n_frames} frames, each capture's frames averaged first" if n_frames > n_captures else ""
    faithful = "metrics" in rows and rows["metrics"].eq("faithful").any()
    metric_rule = ("MAROON's reference metric definitions (metrics.faithful=true): P counts every radar point, "
                   "off-object ones with their full depth as error" if faithful else
                   "P and P_e: mean |depth error| over radar points on the object's ground-truth silhouette "
                   "(P_e: the silhouette eroded by MAROON's kernel in mm), the same region for every method; "
                   "off %: share of radar points off the silhouette (false positives), off err: their mean "
                   "distance to the object")
    devices = ", ".join(sorted(rows.device.astype(str).unique()))
    return (f"{TITLES.get(name, name)}: {_methods_sentence(rows)}. {n_captures} captures "
            f"({', '.join(objects)}) at {', '.join(map(str, distances))} cm{frames}, every depth map scored on its "
            f"capture's calibration pixel grid (methods computed on another grid are resampled: bilinear on one "
            f"surface, else nearest pixel). Means over each row's successful captures (ok); a row marked "
            f"{NOT_COMPARABLE} failed on some capture, covers fewer captures and is not ranked; all other rows cover "
            f"the same captures. {metric_rule}. Metrics in cm; runtime in ms per frame ({devices}), only from "
            f"runs timed alone (n/a otherwise). Best per metric in bold among the comparable rows, BP_max excluded.")


def _formatted(summary: pd.DataFrame, bold) -> pd.DataFrame:
    """The shown table: labels (marked when not comparable), ok as 'k/N', numbers as text, best in `bold`."""
    best = best_rows(summary)
    shown = pd.DataFrame({"": [r if c else f"{r} {NOT_COMPARABLE}" for r, c in zip(summary.row, summary.comparable,
                                                                                   strict=False)],
                          "ok": [f"{k}/{n}" for k, n in zip(summary.ok, summary.captures, strict=False)]})
    for metric in METRICS_CM:
        shown[metric] = [("–" if not np.isfinite(v) else bold(f"{v:.2f}") if best.get(metric) == i else f"{v:.2f}")
                         for i, v in summary[metric].items()]
    shown["off_pct"] = ["–" if not np.isfinite(v) else f"{v:.1f}" for v in summary.off_pct]
    shown["off_err_cm"] = ["–" if not np.isfinite(v) else f"{v:.2f}" for v in summary.off_err_cm]
    shown["runtime_ms"] = ["n/a" if not np.isfinite(v) else f"{v:.1f}" for v in summary.runtime_ms]
    return shown.rename(columns=SHOWN_COLUMNS)


def to_markdown(table: pd.DataFrame) -> str:
    """A plain Markdown table, floats to two decimals."""
    header = "| " + " | ".join(map(str, table.columns)) + " |"
    rule = "|" + "|".join("---" for _ in table.columns) + "|"
    body = ["| " + " | ".join(f"{v:.2f}" if isinstance(v, float) else str(v) for v in row) + " |"
            for row in table.itertuples(index=False)]
    return "\n".join([header, rule, *body])


def summary_markdown(summary: pd.DataFrame) -> str:
    return to_markdown(_formatted(summary, lambda s: f"**{s}**"))


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
    shown = _formatted(summary, lambda s: f"\x00{s}\x01")
    bold_cells = {c for c in shown.columns if c not in ("", "ok")}
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
    parser.add_argument("--csv", type=Path, help="also write the table as CSV")
    parser.add_argument("--latex", type=Path, help="also write the table as LaTeX")
    args = parser.parse_args()
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
    summary, text = summarise(rows), caption(args.table, rows)
    print(f"{text}\n\n{summary_markdown(summary)}")
    if csv_file:
        summary.to_csv(csv_file, index=False, float_format="%.4f")
    if latex_file:
        latex_file.write_text(summary_latex(summary, text))
    return 0


if __name__ == "__main__":
    cli.run_guarded(main)
