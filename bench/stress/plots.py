"""Plots of the stress report (matplotlib, Agg), one PNG per experiment, from the rows of each experiment."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 - after choosing the backend
import pandas as pd  # noqa: E402


def _save(fig, path: Path) -> None:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_precision(rows: list[dict], path: Path) -> None:
    """Max phase (rad) and depth (m) error per configuration and device, worst over distances and grids."""
    df = pd.DataFrame(rows).groupby(["config", "device"])[["max_phase_err_rad", "max_depth_err_m"]].max()
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    for ax, column, bound, label in ((axes[0], "max_phase_err_rad", 1e-3, "phase error (rad)"),
                                     (axes[1], "max_depth_err_m", 10e-6, "depth error (m)")):
        df[column].unstack("device").plot.bar(ax=ax, logy=True)
        ax.axhline(bound, color="k", ls="--", lw=1, label="test bound")
        ax.set_ylabel(f"max {label}")
        ax.legend(fontsize=8)
    axes[0].set_title("float32 paths vs float64 reference")
    _save(fig, path)


def plot_wrapping(rows: list[dict], path: Path) -> None:
    """Success rate (and yield, dashed) against prior offset / dd_max per method and configuration."""
    df = pd.DataFrame(rows)
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for (method, config), part in df.groupby(["method", "config"], sort=False):
        line, = ax.plot(part.offset_ratio, part.success_rate, label=f"{method} {config}", lw=1.2)
        ax.plot(part.offset_ratio, part["yield"], color=line.get_color(), ls=":", lw=1)
    for x in (-1, 1):
        ax.axvline(x, color="k", lw=0.8, ls="--")
    ax.set_xlabel("offset / dd_max  (offset = truth - prior)")
    ax.set_ylabel("success rate (dotted: yield)")
    ax.legend(fontsize=8, ncol=2)
    _save(fig, path)


def plot_noise(rows: list[dict], path: Path) -> None:
    """Measured depth std and the bounds against per-sample SNR; ratios below."""
    df = pd.DataFrame(rows)
    fig, axes = plt.subplots(2, 1, figsize=(8, 7), sharex=True)
    for (scene, config), part in df.groupby(["scene", "config"], sort=False):
        line, = axes[0].semilogy(part.snr_db, part.std_m, "o-", label=f"{scene} {config} measured")
        axes[0].semilogy(part.snr_db, part.crb_m, "--", color=line.get_color(), lw=0.8)
        axes[1].plot(part.snr_db, part.ratio, "o-", color=line.get_color(), label=f"{scene} {config} std / crb")
        axes[1].plot(part.snr_db, part.focused_ratio, "x:", color=line.get_color(),
                     label=f"{scene} {config} std / focused crb")
    axes[0].set_ylabel("depth std (m); dashed: crb")
    axes[0].legend(fontsize=7)
    axes[1].axhline(2.0, color="k", ls="--", lw=0.8)
    axes[1].set_yscale("log")
    axes[1].set_ylabel("ratio")
    axes[1].set_xlabel("per-sample SNR (dB)")
    axes[1].legend(fontsize=7, ncol=2)
    _save(fig, path)


def plot_prior(rows: list[dict], path: Path) -> None:
    """MM-2FSK yield against each prior-degradation knob, one panel per knob, one line per configuration."""
    df = pd.DataFrame(rows)
    knobs = list(dict.fromkeys(df.knob))
    fig, axes = plt.subplots(1, len(knobs), figsize=(4 * len(knobs), 3.6))
    for ax, knob in zip(axes, knobs):
        part = df[df.knob == knob].groupby(["config", "value"])["yield"].mean().unstack("config")
        x = part.index.to_numpy()
        positions = range(len(x))
        for config in part.columns:
            ax.plot(positions, part[config].to_numpy(), "o-", label=config)
        ax.set_xticks(list(positions), [f"{v:g}" for v in x], rotation=45, fontsize=7)
        ax.set_title(knob, fontsize=9)
        ax.set_ylim(-0.05, 1.05)
        ax.axhline(0.9, color="k", ls="--", lw=0.8)
    axes[0].set_ylabel("MM-2FSK yield (correct / object pixels)")
    axes[0].legend(fontsize=8)
    _save(fig, path)
