"""summary.md of the stress report: the headline numbers of every experiment as small markdown tables."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd


def _table(df: pd.DataFrame) -> str:
    """A markdown table of a small frame (numbers in %.3g)."""
    def cell(v):
        return f"{v:.3g}" if isinstance(v, (float, np.floating)) else str(v)
    lines = ["| " + " | ".join(map(str, df.columns)) + " |", "|" + "---|" * len(df.columns)]
    lines += ["| " + " | ".join(cell(v) for v in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines)


def write_summary(results: dict[str, list[dict]], seconds: dict[str, float], quick: bool, path: Path) -> None:
    """Write the summary of `results` (experiment name -> rows) to `path`."""
    precision = pd.DataFrame(results["precision"]).groupby("device", as_index=False)[
        ["max_phase_err_rad", "max_rel_err", "max_depth_err_m"]].max()
    noise = pd.DataFrame(results["noise"])[["scene", "config", "snr_db", "std_m", "crb_m", "ratio", "focused_ratio",
                                            "valid_fraction"]]
    breaks = pd.DataFrame(results["prior_breaks"])
    hostile = pd.DataFrame(results["hostile"])[["case", "outcome", "runtime_warnings", "dataset_unchanged",
                                                "pickle_executed"]]
    sections = [
        f"# Stress report ({'quick' if quick else 'full'} run; {sum(seconds.values()):.0f} s)\n",
        "Regenerate with `python -m bench.stress`; docs/guide/stress.md explains every column.\n",
        "## 1. Precision: float32 paths vs the float64 reference (worst over distances, grids, configurations)\n",
        _table(precision),
        "\n## 2. Phase wrapping: |offset| / dd_max up to which every offset succeeds, and from which none does\n",
        _table(pd.DataFrame(results["wrapping_boundaries"])),
        "\n## 3. Noise: MM-2FSK depth std against the Cramer-Rao bound (ratio = std / crb)\n",
        _table(noise),
        "\n## 4. Prior degradation: first knob value where MM-2FSK's yield < 0.9 (NaN: never in the sweep)\n",
        _table(breaks),
        "\n## 5. Hostile input\n",
        _table(hostile),
        "",
    ]
    path.write_text("\n".join(sections))
