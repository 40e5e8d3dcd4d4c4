"""`python -m bench.tables table1 [--csv FILE]`: the paper's tables as Markdown (Table I from the frequency grid).

Table I lists, per two-frequency configuration, the frequencies actually selected from the MAROON sweep
`linspace(72, 82, 128)` GHz, their difference and the maximum unambiguous depth correction c / (4 delta_f).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from methods.frequencies import CONFIGS_GHZ, max_unambiguous_depth_m, select_frequencies

MAROON_FREQS_HZ = np.linspace(72e9, 82e9, 128)


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


def to_markdown(table: pd.DataFrame) -> str:
    """A plain Markdown table, numbers to two decimals."""
    header = "| " + " | ".join(table.columns) + " |"
    rule = "|" + "|".join("---" for _ in table.columns) + "|"
    body = ["| " + " | ".join(f"{v:.2f}" if isinstance(v, float) else str(v) for v in row) + " |"
            for row in table.itertuples(index=False)]
    return "\n".join([header, rule, *body])


def main() -> int:
    parser = argparse.ArgumentParser(prog="python -m bench.tables", description=__doc__)
    parser.add_argument("table", choices=["table1"])
    parser.add_argument("--csv", type=Path, help="also write the table as CSV")
    args = parser.parse_args()
    table = table1()
    print(to_markdown(table))
    if args.csv:
        table.to_csv(args.csv, index=False, float_format="%.4f")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
