"""Figures of a sweep: runtime against error with the Pareto front, and per-capture depth-error maps (PNG)."""
from __future__ import annotations

from pathlib import Path

import h5py
import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the file-only backend)
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402

ERROR_LIMIT_CM = 2.0     # colour scale of the error maps: 0 .. 2 cm (larger errors saturate)


def pareto_front(runtime_ms: np.ndarray, error_cm: np.ndarray) -> np.ndarray:
    """Bool mask of the points no other point beats in both runtime and error (ties kept)."""
    runtime_ms, error_cm = np.asarray(runtime_ms, float), np.asarray(error_cm, float)
    dominated = ((runtime_ms[None, :] <= runtime_ms[:, None]) & (error_cm[None, :] <= error_cm[:, None])
                 & ((runtime_ms[None, :] < runtime_ms[:, None]) | (error_cm[None, :] < error_cm[:, None])))
    return ~dominated.any(axis=1) & np.isfinite(error_cm)


def runtime_vs_error(summary: pd.DataFrame, path: Path, title: str) -> Path:
    """Mean runtime (ms, log) against mean P (cm, log) per summary row (bench.tables.summarise), the Pareto front
    marked and joined. Only rows with a runtime measured alone are drawn; rows that failed on some capture are
    drawn hollow and take no part in the front (their mean covers fewer captures)."""
    shown = summary[np.isfinite(summary.runtime_ms) & np.isfinite(summary.P_cm)]
    fig, ax = plt.subplots(figsize=(7.5, 5.0))
    for method, group in shown.groupby("method", sort=False):
        colour = ax.scatter([], [], s=30).get_facecolor()[0]
        ax.scatter(group.runtime_ms, group.P_cm, label=method, s=30,
                   facecolors=[colour if ok else "none" for ok in group.comparable], edgecolors=[colour])
        for _, row in group.iterrows():
            label = row.row if row.comparable else f"{row.row} (failed {row.captures - row.ok}/{row.captures})"
            ax.annotate(label, (row.runtime_ms, row.P_cm), fontsize=7, xytext=(3, 3), textcoords="offset points")
    ranked = shown[shown.comparable]
    front = ranked[pareto_front(ranked.runtime_ms, ranked.P_cm)].sort_values("runtime_ms")
    ax.step(front.runtime_ms, front.P_cm, where="post", color="k", lw=1, ls="--")
    ax.scatter(front.runtime_ms, front.P_cm, s=120, facecolors="none", edgecolors="k", label="Pareto front")
    missing = len(summary) - len(shown)
    note = f"\n{missing} of {len(summary)} rows have no runtime measured alone and are not drawn" if missing else ""
    ax.set(xlabel="runtime per frame, measured alone (ms)", ylabel="mean P (cm)", title=f"{title}{note}")
    if len(shown):
        ax.set(xscale="log", yscale="log")
    else:
        ax.text(0.5, 0.5, "no runtime measured alone\n(run the sweep one job at a time)", ha="center",
                transform=ax.transAxes)
    ax.grid(True, which="both", alpha=0.3)
    if len(shown):
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _compared_extent_cm(h5_paths: list[Path], stem: str, margin_cm: float = 1.0) -> tuple[tuple, tuple]:
    """(x range, y range) in cm of the pixels where any run has both a depth and ground truth, plus a margin."""
    x_cm, y_cm = [], []
    for h5_path in h5_paths:
        with h5py.File(h5_path, "r") as h5:
            if stem not in h5:
                continue
            group = h5[stem]
            compared = np.isfinite(group["depth_m"][()] - group["gt_depth_m"][()])
            (nx, ny, _), lo, hi = group.attrs["grid_size"], group.attrs["bb_min_m"] * 100, group.attrs["bb_max_m"] * 100
        rows, cols = np.nonzero(compared)
        x_cm.append(np.linspace(lo[0], hi[0], nx)[cols])
        y_cm.append(np.linspace(hi[1], lo[1], ny)[rows])        # row 0 = +y
    x_cm, y_cm = np.concatenate(x_cm), np.concatenate(y_cm)
    if x_cm.size == 0:
        return (lo[0], hi[0]), (lo[1], hi[1])
    return (x_cm.min() - margin_cm, x_cm.max() + margin_cm), (y_cm.min() - margin_cm, y_cm.max() + margin_cm)


def depth_error_maps(runs: list[tuple[str, Path]], out_dir: Path) -> list[Path]:
    """One PNG per capture: |depth - ground truth| (cm) of every run side by side, on each run's pixel grid.

    runs: (label, arrays.h5 of the run) pairs; every capture group found in the files gets a figure.
    """
    stems = sorted({stem for _, h5_path in runs for stem in h5py.File(h5_path, "r")})
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for stem in stems:
        crop_cm = _compared_extent_cm([h5_path for _, h5_path in runs], stem)
        ncols = min(len(runs), 7)
        nrows = -(-len(runs) // ncols)
        aspect = (crop_cm[1][1] - crop_cm[1][0]) / (crop_cm[0][1] - crop_cm[0][0])
        fig, axes = plt.subplots(nrows, ncols, figsize=(2.2 * ncols + 1.0, (2.2 * aspect + 0.4) * nrows + 0.5),
                                 squeeze=False, layout="constrained")
        for ax in axes.flat:
            ax.set_axis_off()
        for ax, (label, h5_path) in zip(axes.flat, runs):
            with h5py.File(h5_path, "r") as h5:
                if stem not in h5:
                    continue
                group = h5[stem]
                error_cm = np.abs(group["depth_m"][()] - group["gt_depth_m"][()]) * 100.0
                (x0, y0, _), (x1, y1, _) = group.attrs["bb_min_m"] * 100, group.attrs["bb_max_m"] * 100
            image = ax.imshow(error_cm, extent=(x0, x1, y0, y1), vmin=0, vmax=ERROR_LIMIT_CM, cmap="magma")
            ax.set(xlim=crop_cm[0], ylim=crop_cm[1])
            ax.set_title(label, fontsize=8)
        fig.colorbar(image, ax=axes, shrink=0.8, label=f"|depth error| (cm), saturates at {ERROR_LIMIT_CM}")
        fig.suptitle(f"{stem}: depth error per method (x, y in cm; blank = no depth or no ground truth)", fontsize=9)
        path = out_dir / f"{stem}.png"
        fig.savefig(path, dpi=100)
        plt.close(fig)
        paths.append(path)
    return paths
