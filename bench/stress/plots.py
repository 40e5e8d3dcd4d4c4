"""Plots of the stress report (matplotlib, Agg), one PNG per experiment, from the rows of each experiment."""
from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402 - after choosing the backend
import pandas as pd  # noqa: E402

KNOB_LABELS = {"disparity_sigma_px": "stereo noise: disparity sigma (px)",
               "dropout_fraction": "holes: dropout fraction (share of pixels)",
               "extrinsic_error_mm": "extrinsic error: translation (mm)",
               "extrinsic_error_deg": "extrinsic error: rotation (degrees)"}
CPU_PHASE_BOUND_RAD, CPU_DEPTH_BOUND_M = 1e-3, 10e-6      # tests/test_stress_*: CPU and Warp-CPU only
NOISE_RATIO_BOUND = 2.0                                    # tests/test_stress_numerics: point-target std / crb
BREAK_YIELD = 0.9                                          # bench.stress.prior_degradation.BREAK_YIELD


def _save(fig, path: Path) -> None:
    """Legends sit outside the axes (they never hide data): a constrained layout keeps them in the picture."""
    fig.savefig(path, dpi=110, bbox_inches="tight")
    plt.close(fig)


def plot_precision(rows: list[dict], path: Path) -> None:
    """Max phase (rad) and depth (m) error per configuration and device, worst over distances and grids; the test
    bound applies to the CPU paths (CUDA's fp16 tensor-core products are measured against their own budget)."""
    df = pd.DataFrame(rows).groupby(["config", "device"])[["max_phase_err_rad", "max_depth_err_m"]].max()
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.2), layout="constrained")
    for ax, column, bound, label in ((axes[0], "max_phase_err_rad", CPU_PHASE_BOUND_RAD, "phase error (rad)"),
                                     (axes[1], "max_depth_err_m", CPU_DEPTH_BOUND_M, "depth error (m)")):
        df[column].unstack("device").plot.bar(ax=ax, logy=True, legend=False)
        ax.axhline(bound, color="k", ls="--", lw=1, label="test bound of the CPU paths (cpu, warp-cpu; CUDA's fp16 "
                                                          "products are not held to it)")
        ax.text(0.0, bound, f" CPU test bound {bound:g}", fontsize=7, va="bottom", transform=ax.get_yaxis_transform())
        ax.set(ylabel=f"largest {label}", xlabel="frequency configuration", title=f"largest {label}")
        ax.tick_params(axis="x", rotation=45)
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, [f"device: {lab}" if "bound" not in lab else lab for lab in labels], loc="outside lower center",
               ncols=len(labels), fontsize=8)
    fig.suptitle("Precision: float32 correlation against the float64 direct sum, worst over distances 0.2-0.6 m "
                 "and grid sizes (pixels within -14 dB)", fontsize=10)
    _save(fig, path)


def plot_wrapping(rows: list[dict], path: Path) -> None:
    """Success rate (and yield, dotted) against prior offset / dd_max, one panel per method."""
    df = pd.DataFrame(rows)
    methods = list(dict.fromkeys(df.method))
    fig, axes = plt.subplots(1, len(methods), figsize=(4.6 * len(methods), 4.0), sharey=True, squeeze=False,
                             layout="constrained")
    for ax, method in zip(axes[0], methods, strict=False):
        for config, part in df[df.method == method].groupby("config", sort=False):
            line, = ax.plot(part.offset_ratio, part.success_rate, label=f"{config} success", lw=1.4)
            ax.plot(part.offset_ratio, part["yield"], color=line.get_color(), ls=":", lw=1.2,
                    label=f"{config} yield")
        for x in (-1, 1):
            ax.axvline(x, color="k", lw=0.8, ls="--")
        ax.set(title=method.upper().replace("MM2FSK", "MM-2FSK"), xlabel="offset / dd_max (offset = truth - prior)",
               ylim=(-0.05, 1.12))
        ax.text(1.0, 1.06, " ±dd_max", fontsize=7, ha="left")
        ax.legend(fontsize=7, loc="lower center", ncols=2, bbox_to_anchor=(0.5, -0.5))
    axes[0, 0].set_ylabel("share of pixels within dd_max / 2 of the truth")
    fig.suptitle("Phase wrapping: success (valid pixels in the right ambiguity interval) and yield (all pixels) "
                 "against the prior's offset", fontsize=10)
    _save(fig, path)


def plot_noise(rows: list[dict], path: Path) -> None:
    """Measured depth std and the Cramér-Rao bound against per-sample SNR; ratios below."""
    df = pd.DataFrame(rows)
    fig, axes = plt.subplots(2, 1, figsize=(9, 7.5), sharex=True, layout="constrained")
    for (scene, config), part in df.groupby(["scene", "config"], sort=False):
        line, = axes[0].semilogy(part.snr_db, part.std_m, "o-", label=f"{scene} {config}: measured std")
        axes[0].semilogy(part.snr_db, part.crb_m, "--", color=line.get_color(), lw=0.9,
                         label=f"{scene} {config}: Cramér-Rao bound")
        axes[1].plot(part.snr_db, part.ratio, "o-", color=line.get_color(), label=f"{scene} {config}: std / crb")
        axes[1].plot(part.snr_db, part.focused_ratio, "x:", color=line.get_color(),
                     label=f"{scene} {config}: std / focused crb")
    axes[0].set(ylabel="MM-2FSK depth std (m)", title="depth noise against the two-frequency phase bound")
    axes[1].axhline(NOISE_RATIO_BOUND, color="k", ls="--", lw=0.8,
                    label=f"test bound: point target std < {NOISE_RATIO_BOUND:g} x crb")
    axes[1].set(yscale="log", ylabel="ratio to the bound", xlabel="per-sample SNR (dB)",
                title="ratio (the plate spreads its energy: compare it with the focused bound)")
    for ax in axes:
        ax.legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    _save(fig, path)


def plot_prior(rows: list[dict], path: Path) -> None:
    """MM-2FSK yield against each prior-degradation knob, one panel per knob, one line per configuration."""
    df = pd.DataFrame(rows)
    knobs = list(dict.fromkeys(df.knob))
    fig, axes = plt.subplots(1, len(knobs), figsize=(4 * len(knobs), 4.0), sharey=True, squeeze=False,
                             layout="constrained")
    for ax, knob in zip(axes[0], knobs, strict=False):
        part = df[df.knob == knob].groupby(["config", "value"])["yield"].mean().unstack("config")
        x = part.index.to_numpy()
        positions = range(len(x))
        for config in part.columns:
            ax.plot(positions, part[config].to_numpy(), "o-", label=f"MM-2FSK {config}")
        ax.set_xticks(list(positions), [f"{v:g}" for v in x], rotation=45, fontsize=7)
        ax.set(title=knob, xlabel=KNOB_LABELS.get(knob, knob), ylim=(-0.05, 1.05))
        ax.title.set_fontsize(9)
        ax.axhline(BREAK_YIELD, color="k", ls="--", lw=0.8, label=f"breaks below yield {BREAK_YIELD:g}")
    axes[0, 0].set_ylabel("MM-2FSK yield (object pixels within dd_max / 2)")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside right", fontsize=8)
    fig.suptitle("Prior degradation: one RealSense knob at a time (mean over repetitions)", fontsize=10)
    _save(fig, path)
