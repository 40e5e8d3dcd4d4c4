"""Where the captures' objects sit against the scalar-prior methods' unambiguous windows.

The paper runs 2FSK and 3FSK from a scalar prior of 0.40 m on objects at about 30 cm (Section IV.A), so whether an
object's surface lies inside `0.40 m +- c / (4 delta_f)` decides whether those cells wrap: Δ0.5 (0.551 GHz) keeps
[0.264, 0.536] m, Δ1 [0.332, 0.468] m, Δ2 (3FSK's middle pair) [0.366, 0.434] m. `placement` measures, per capture,
the visible surface on the radar pixels (the photogrammetry prior, i.e. the ground truth as the radar grid sees it)
and the share of it inside each window; given a sweep's rows it adds the scalar-prior cells' P per capture, so a
wrapped object is named rather than hidden in a mean.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

WINDOW_CONFIGS = ("d05", "d1", "d2")       # 2FSK Δ0.5 and Δ1, 3FSK(Δ2, Δ10)'s coarse pair
SCALAR_PRIOR_CELLS = ("2fsk_d05", "3fsk_d05_d10", "2fsk_d1")


def windows_m(freqs_hz: np.ndarray, configs=WINDOW_CONFIGS, prior_m: float | None = None) -> dict[str, tuple]:
    """{config: (near, far)} in metres: the depths a scalar-prior first pass at `prior_m` (default: the methods'
    0.40 m) corrects without wrapping, for each configuration's pair among the frame's frequencies."""
    from methods.api import frequency_indices
    from methods.fsk import DEFAULT_PRIOR_M
    from methods.ops.frequencies import max_unambiguous_depth_m

    prior_m = DEFAULT_PRIOR_M if prior_m is None else prior_m
    out = {}
    for config in configs:
        pair = np.asarray(freqs_hz)[frequency_indices(freqs_hz, config)]
        half_m = max_unambiguous_depth_m(float(np.ptp(pair)))
        out[config] = (prior_m - half_m, prior_m + half_m)
    return out


def placement(root: Path, objects: list[str], rows: pd.DataFrame | None = None,
              distance_cm: int = 30) -> pd.DataFrame:
    """One line per capture `<root>/<object>/<distance_cm>`: the visible surface's depth (cm: nearest, median,
    farthest radar pixel of the ground truth), the share of its pixels inside each window of `windows_m`, and with
    `rows` (bench.report.agreement.cells_of_sweeps: a `cell` column) P (cm) of the scalar-prior cells."""
    from bench.maroon.reader import read_capture
    from bench.report.tables import row_label
    from methods.api import prior_image_m

    lines = []
    for name in objects:
        capture = read_capture(Path(root) / name / str(distance_cm), parts=("radar", "mesh"))
        truth_m = np.asarray(prior_image_m(capture, "photogrammetry", capture.radar.grid))
        depth_m = truth_m[np.isfinite(truth_m)]
        line = {"capture": name, "surface near cm": np.nan, "median cm": np.nan, "far cm": np.nan}
        if depth_m.size:
            line.update({"surface near cm": 100 * depth_m.min(), "median cm": 100 * np.median(depth_m),
                         "far cm": 100 * depth_m.max()})
        for config, (near_m, far_m) in windows_m(capture.radar.freqs_hz).items():
            inside = (depth_m >= near_m) & (depth_m <= far_m)
            label = f"in {row_label('2fsk', config).split()[-1]} [{100 * near_m:.1f}, {100 * far_m:.1f}]"
            line[label] = float(inside.mean()) if depth_m.size else np.nan
        if rows is not None:
            for cell in SCALAR_PRIOR_CELLS:
                picked = rows[(rows["cell"] == cell) & (rows["object"] == name)]
                line[f"{row_label(*cell.split('_', 1))} P cm"] = (float(picked["P_cm"].mean()) if len(picked)
                                                                  else np.nan)
        lines.append(line)
    return pd.DataFrame(lines)
