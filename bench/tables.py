"""`python -m bench.tables table1|table2|table3|runtime [--results PATH] [--csv FILE] [--latex FILE]`.

Table I lists, per two-frequency configuration, the frequencies actually selected from the MAROON sweep
`linspace(72, 82, 128)` GHz, their difference and the maximum unambiguous depth correction c / (4 delta_f).
Tables II and III (and the runtime table) average result rows over captures like the paper, one line per method x
frequency configuration x prior, metrics in centimetres, the best value per metric in bold (BP_max excluded, as in
the paper: it is the many-frequency reference, not a high-speed method). PATH is a sweep root (its merged
`results.csv`, else the jobs' `*/results.csv`) or a results CSV; by default the committed `results/<table>/`.
Markdown goes to stdout.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from methods.frequencies import CONFIGS_GHZ, max_unambiguous_depth_m, select_frequencies

MAROON_FREQS_HZ = np.linspace(72e9, 82e9, 128)
RESULTS_DIR = Path(__file__).resolve().parents[1] / "results"
METRICS_CM = ["C_g_cm", "C_s_cm", "P_cm", "P_e_cm"]
METHOD_LABELS = {"bp": "BP", "2fsk": "2FSK", "3fsk": "3FSK", "mm2fsk": "MM-2FSK"}
GROUP_COLUMNS = ["method", "freq", "prior", "grid"]
FREQ_ORDER = ["full", *(name for name in CONFIGS_GHZ if name != "full")]       # BP_max first, as in the paper
CAPTIONS = {
    "table2": "Table II: MM-2FSK with the photogrammetry (ground-truth) prior per frequency configuration.",
    "table3": "Table III: BP, 2FSK, 3FSK and MM-2FSK (RealSense prior; 2FSK/3FSK from the scalar 0.40 m prior).",
    "runtime": "Runtime and error of every method and configuration.",
}


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


def row_label(method: str, freq: str) -> str:
    """The paper's row names: BP_max, BP Δ0.5, 2FSK Δ1.0, 3FSK(Δ0.5, Δ10.0), MM-2FSK Δ10.0."""
    if freq == "full":
        return f"{METHOD_LABELS[method]}_max"
    parts = [_nominal_delta(part) for part in freq.split("_")]
    if len(parts) == 1:
        return f"{METHOD_LABELS[method]} {parts[0]}"
    return f"{METHOD_LABELS[method]}({', '.join(parts)})"


def summarise(rows: pd.DataFrame) -> pd.DataFrame:
    """Mean metrics (cm) and runtime (ms) per method x freq x prior x grid, in the paper's row order."""
    summary = (rows.groupby(GROUP_COLUMNS, sort=False)
               .agg(captures=("P_cm", "size"), **{m: (m, "mean") for m in METRICS_CM + ["runtime_ms"]})
               .reset_index())
    order = summary.method.map(list(METHOD_LABELS).index) * 100 + summary.freq.map(FREQ_ORDER.index)
    summary = summary.iloc[np.argsort(order.to_numpy(), kind="stable")].reset_index(drop=True)
    summary.insert(0, "row", [row_label(m, f) for m, f in zip(summary.method, summary.freq)])
    return summary


def best_rows(summary: pd.DataFrame) -> dict[str, int]:
    """Per metric, the index of the smallest mean among the non-BP_max rows."""
    candidates = summary[summary.freq != "full"]
    return {m: int(candidates[m].idxmin()) for m in METRICS_CM if candidates[m].notna().any()}


def caption(name: str, rows: pd.DataFrame) -> str:
    """What the table shows and on what: captures, distances, grids, units, how best is marked."""
    objects, distances = sorted(rows.object.unique()), sorted(rows.distance.unique())
    grids = "; ".join(f"{METHOD_LABELS[m]} on grid {', '.join(sorted(g.grid.unique()))}"
                      for m, g in rows.groupby("method"))
    return (f"{CAPTIONS[name]} Mean over {len(objects)} captures ({', '.join(objects)}) at "
            f"{', '.join(map(str, distances))} cm; {grids}. Metrics in centimetres, runtime in ms per frame "
            f"({', '.join(sorted(rows.device.unique()))}); best per metric in bold, BP_max excluded.")


def _formatted(summary: pd.DataFrame, bold) -> pd.DataFrame:
    shown = summary[["row", *METRICS_CM, "runtime_ms"]].copy()
    best = best_rows(summary)
    for metric in METRICS_CM:
        shown[metric] = [bold(f"{v:.2f}") if best.get(metric) == i else f"{v:.2f}"
                         for i, v in summary[metric].items()]
    shown["runtime_ms"] = [f"{v:.1f}" for v in summary.runtime_ms]
    return shown.rename(columns={"row": "", **{m: m.removesuffix("_cm") for m in METRICS_CM}})


def to_markdown(table: pd.DataFrame) -> str:
    """A plain Markdown table, floats to two decimals."""
    header = "| " + " | ".join(map(str, table.columns)) + " |"
    rule = "|" + "|".join("---" for _ in table.columns) + "|"
    body = ["| " + " | ".join(f"{v:.2f}" if isinstance(v, float) else str(v) for v in row) + " |"
            for row in table.itertuples(index=False)]
    return "\n".join([header, rule, *body])


def summary_markdown(summary: pd.DataFrame) -> str:
    return to_markdown(_formatted(summary, lambda s: f"**{s}**"))


def summary_latex(summary: pd.DataFrame, caption_text: str) -> str:
    shown = _formatted(summary, lambda s: rf"\textbf{{{s}}}")
    shown[""] = shown[""].str.replace("Δ", r"$\Delta$").str.replace("_max", r"$_{\max}$")
    return shown.style.hide(axis="index").to_latex(caption=caption_text, hrules=True)


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


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.tables", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("table", choices=["table1", *CAPTIONS])
    parser.add_argument("--results", type=Path, help="sweep root or results CSV (default: results/<table>/)")
    parser.add_argument("--csv", type=Path, help="also write the table as CSV")
    parser.add_argument("--latex", type=Path, help="also write the table as LaTeX")
    args = parser.parse_args()
    if args.table == "table1":
        table = table1()
        print(to_markdown(table))
        if args.csv:
            table.to_csv(args.csv, index=False, float_format="%.4f")
        if args.latex:
            args.latex.write_text(table.style.hide(axis="index").format(precision=2).to_latex(hrules=True))
        return 0
    rows = read_rows(args.results or RESULTS_DIR / args.table)
    summary, text = summarise(rows), caption(args.table, rows)
    print(f"{text}\n\n{summary_markdown(summary)}")
    if args.csv:
        summary.to_csv(args.csv, index=False, float_format="%.4f")
    if args.latex:
        args.latex.write_text(summary_latex(summary, text))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
