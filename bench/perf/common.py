"""What the benchmarks share: the output folder, CSV rows, percentiles and the options every subcommand takes."""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

# the benchmarks' CSVs (bench.perf.correlate, .perf_frames, .perf_sweep); not tracked
DEFAULT_OUT = Path("outputs/perf")


def percentile(values: list[float], q: float) -> float:
    """The q-th percentile of `values` (NaN when there are none)."""
    return float(np.percentile(values, q)) if values else float("nan")


def write_rows(rows: list[dict], path: Path, columns: list[str] | None = None, digits: int = 4) -> None:
    """Write benchmark rows as CSV, floats to `digits` significant digits."""
    columns = columns or list(dict.fromkeys(k for r in rows for k in r))
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=columns)
        writer.writeheader()
        writer.writerows({k: (f"{v:.{digits}g}" if isinstance(v, float) else v) for k, v in r.items()} for r in rows)
    print(f"wrote {path}")


def add_device_option(parser, default: str = "cpu", choices=("cpu", "cuda", "auto", "warp-cpu")) -> None:
    """`--device`, as every benchmark names it."""
    parser.add_argument("--device", default=default, choices=list(choices))


def add_out_option(parser, what: str = "the CSVs") -> None:
    """`--out DIR` (default outputs/perf; `--out results` refreshes the committed figures)."""
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help=f"folder for {what} (default: %(default)s)")
