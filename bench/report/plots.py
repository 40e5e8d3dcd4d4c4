"""Figures of a sweep: runtime against error with the Pareto front, and per-capture signed depth-error maps (PNG)."""
from __future__ import annotations

import os
import threading
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the file-only backend)
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from matplotlib.ticker import LogFormatter  # noqa: E402

from methods.domain.host import usable_cores  # noqa: E402

MARKERS = "osD^vP*Xph<>"   # the rows of one method in the runtime plot (its colour), repeating beyond 12
ERROR_LIMIT_CM = 2.0     # colour scale of the signed error maps: -2 .. +2 cm (larger errors saturate)


class _PlainLogLabels(LogFormatter):
    """Log-axis tick labels as plain numbers (`%g`: 0.4, 2, 50), where LogFormatter writes 4e-01 below 1."""

    def _num_to_string(self, x, vmin, vmax):
        return f"{x:g}"


def pareto_front(runtime_ms: np.ndarray, error_cm: np.ndarray) -> np.ndarray:
    """Bool mask of the points no other point beats in both runtime and error (ties kept)."""
    runtime_ms, error_cm = np.asarray(runtime_ms, float), np.asarray(error_cm, float)
    dominated = ((runtime_ms[None, :] <= runtime_ms[:, None]) & (error_cm[None, :] <= error_cm[:, None])
                 & ((runtime_ms[None, :] < runtime_ms[:, None]) | (error_cm[None, :] < error_cm[:, None])))
    return ~dominated.any(axis=1) & np.isfinite(error_cm)


def runtime_vs_error(summary: pd.DataFrame, path: Path, title: str) -> Path:
    """Mean runtime (ms, log) against mean P (cm, log) per summary row (bench.report.tables.summarise: every row's
    P over the same captures), the Pareto front marked and joined. Each row is named in the legend (colour: method,
    marker: the row within its method), never by a label on the plot, so no two names can overlap. Only rows with
    a runtime measured alone are drawn; rows that failed on some capture are drawn hollow."""
    shown = summary[np.isfinite(summary.runtime_ms) & np.isfinite(summary.P_cm)]
    fig, ax = plt.subplots(figsize=(9.0, 5.0))
    colours = plt.get_cmap("tab10")
    for number, (_, group) in enumerate(shown.groupby("method", sort=False)):
        colour = colours(number % 10)
        for position, (_, row) in enumerate(group.iterrows()):
            marker = MARKERS[position % len(MARKERS)]
            failed = int(row.get("failed", 0))
            label = row.row if not failed else f"{row.row} (failed {failed}/{row.captures})"
            ax.scatter(row.runtime_ms, row.P_cm, s=42, marker=marker, label=label, edgecolors=[colour],
                       facecolors="none" if failed else [colour], linewidths=1.2)
    front = shown[pareto_front(shown.runtime_ms, shown.P_cm)].sort_values("runtime_ms")
    ax.step(front.runtime_ms, front.P_cm, where="post", color="k", lw=1, ls="--")
    ax.scatter(front.runtime_ms, front.P_cm, s=150, facecolors="none", edgecolors="k", label="Pareto front")
    missing = len(summary) - len(shown)
    note = f"\n{missing} of {len(summary)} rows have no runtime measured alone and are not drawn" if missing else ""
    ax.set(xlabel="runtime per frame, measured alone (ms)", ylabel="mean P (cm), same captures for every row",
           title=f"{title}{note}")
    if len(shown):
        ax.set(xscale="log", yscale="log")
        for axis in (ax.xaxis, ax.yaxis):    # plain-text labels (10, 20, 0.5): the default's mathtext costs a merge
            axis.set_major_formatter(_PlainLogLabels(labelOnlyBase=False))       # ~0.15 s for its parser
            axis.set_minor_formatter(_PlainLogLabels(labelOnlyBase=False, minor_thresholds=(2, 0.5)))
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    else:
        ax.text(0.5, 0.5, "no runtime measured alone\n(run the sweep one job at a time)", ha="center",
                transform=ax.transAxes)
    ax.grid(True, which="both", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def depth_error_maps(runs: list[tuple[str, Path]], out_dir: Path, workers: int | None = None) -> list[Path]:
    """One PNG per capture: the signed depth error (depth - ground truth, cm) of every run side by side.

    Diverging colours (red: the radar put the surface behind the truth, blue: in front; a wrap shows its
    direction), saturating at +-ERROR_LIMIT_CM; "no depth" in grey, depth where the ground truth has no surface in
    black (bench.report.pictures). runs: (label, arrays.h5 of the run) pairs; every capture found gets a figure,
    redrawn only when its cells' labels or arrays (or this code) changed (bench.report.keyed). The figures to
    draw are drawn by `workers` forked processes (default: one per core; ~0.3 s each for Table III's 14 cells), where
    this process may fork (`_fork_safe`), else here one after another: the same files either way.
    """
    from bench.report import keyed, pictures

    out_dir.mkdir(parents=True, exist_ok=True)
    paths, keys, stale = [], keyed.Keys(out_dir), {}
    for stem in pictures.capture_stems([h5_path for _, h5_path in runs]):
        cells = [(label, arrays) for label, h5_path in runs
                 if (arrays := pictures.read_arrays(h5_path, stem)) is not None]
        path = out_dir / f"{stem}.png"
        key = keyed.digest(Path(__file__), *(part for label, a in cells
                                             for part in (label, a.depth_m, a.gt_depth_m, a.x_m, a.y_m)))
        paths.append(path)
        if not keys.fresh(stem, key, [path]):
            stale[stem] = key
    workers = min(len(stale), workers or usable_cores())
    if workers > 1 and _fork_safe():
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        with ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("fork")) as pool:
            futures = {stem: pool.submit(_depth_error_map, runs, stem, out_dir / f"{stem}.png") for stem in stale}
            for stem, future in futures.items():
                future.result()
                keys.record(stem, stale[stem])
    else:
        for stem, key in stale.items():
            _depth_error_map(runs, stem, out_dir / f"{stem}.png")
            keys.record(stem, key)
    return paths


def _fork_safe() -> bool:
    """Whether this process may fork workers: where fork exists and only this thread runs (a lock another thread
    holds at the fork would stay held in the child)."""
    return hasattr(os, "fork") and threading.active_count() == 1


def _depth_error_map(runs: list[tuple[str, Path]], stem: str, path: Path) -> None:
    """The figure of capture `stem` (depth_error_maps) into `path`: drawn straight into pixels (bench.report.sheet,
    as the report's pictures), every map on the same window and equal scales."""
    from bench.report import pictures, sheet

    error_map = plt.get_cmap("RdBu_r").with_extremes(bad=pictures.NO_DEPTH_COLOUR)
    cells = [(label, arrays) for label, h5_path in runs
             if (arrays := pictures.read_arrays(h5_path, stem)) is not None]
    xlim, ylim = pictures.crop_cm([arrays for _, arrays in cells])
    ncols = min(len(cells), 7)
    nrows = -(-len(cells) // ncols)
    aspect = (ylim[1] - ylim[0]) / (xlim[1] - xlim[0])
    dpi = 100
    width, height = round((2.4 * ncols + 1.6) * dpi), round(((2.4 * aspect + 0.7) * nrows + 1.3) * dpi)
    page = sheet.Sheet(width, height, dpi)
    boxes = sheet.grid(sheet.Box(round(0.6 * dpi), round(0.7 * dpi), width - round(1.8 * dpi),
                                 height - round(1.3 * dpi)), nrows, ncols, hspace=0.7 / (2.4 * aspect), wspace=0.3)
    for number, (label, arrays) in enumerate(cells):
        view = boxes[number // ncols][number % ncols].fit(1 / aspect)
        page.paste(pictures.map_rgb(pictures.signed_error_cm(arrays), arrays.extent_cm, xlim, ylim, view, error_map,
                                    -ERROR_LIMIT_CM, ERROR_LIMIT_CM, pictures.no_error_categories(arrays)), view)
        page.axes(view, xlim, ylim, title=label, xlabel="x (cm)", ylabel="y (cm)")
    page.colorbar(sheet.Box(width - round(1.0 * dpi), round(0.15 * height), round(0.2 * dpi), round(0.7 * height)),
                  error_map, -ERROR_LIMIT_CM, ERROR_LIMIT_CM,
                  f"depth - ground truth (cm), saturates at ±{ERROR_LIMIT_CM:g}", extend="both")
    entries = [(pictures.NO_DEPTH_COLOUR, "no depth"), (pictures.NO_TRUTH_COLOUR, "depth, no ground truth"),
               (matplotlib.colors.to_hex(error_map(1.0)), "behind the surface"),
               (matplotlib.colors.to_hex(error_map(0.0)), "in front of it")]
    page.legend(((width - page.legend_width(entries, 7)) // 2, height - page.px(20)), entries, 7, across=True)
    page.text((width / 2, page.px(8)), f"{stem}: signed depth error per method (radar space, x and y in cm)", 9,
              anchor="mt")
    page.save(path)
