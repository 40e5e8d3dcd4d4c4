"""Precision: every float32 correlation path against the float64 direct sum (`correlate_reference`).

Scene: the 6 x 6 cm plate at each object distance, all Table I (and 3FSK) frequencies at once. Points: the
pixel centres of an n x n grid over +-2 cm at the plate depth plus a uniform prior-like offset of +-5 mm. The
reference is evaluated on `n_ref` pixels drawn among those that pass the methods' -14 dB filter (the only ones
that yield a depth), the fast path on the whole grid (on the drawn pixels only for Warp's one-thread CPU path).
Per configuration: the largest phase error |angle(c_fast conj(c_ref))| (rad) over its frequencies and the
largest depth error (m) of the configuration's depth estimate (2FSK formula, or 3FSK's slope fit) from fast vs
reference phasors.
"""
from __future__ import annotations

import numpy as np

from bench.stress.scenes import TABLE1_CONFIGS, THREE_FREQ_CONFIGS, antennas, frame, pixel_grid
from bench.synth.memory import plate_points_m
from methods.backends import correlate, resolve_device
from methods.domain.radar import MAROON_FREQS_HZ
from methods.fsk import depth_correction_m
from methods.fsk3 import slope_correction_m
from methods.ops.correlate import correlate_reference
from methods.ops.filtering import keep_mask
from methods.ops.frequencies import config_indices

CONFIGS = TABLE1_CONFIGS + THREE_FREQ_CONFIGS
GRID_HALF_M = 0.02
PRIOR_JITTER_M = 0.005


def available_devices() -> list[str]:
    """The float32 paths runnable here: 'cpu' (numpy + BLAS), 'warp-cpu', and 'cuda' when Warp sees a GPU."""
    devices = ["cpu"]
    try:
        devices.append("warp-cpu")
        if resolve_device("auto") == "cuda":
            devices.append("cuda")
    except ImportError:                 # Warp not installed: the numpy path only
        devices.remove("warp-cpu")
    return devices


def _depth_m(phasors: np.ndarray, freqs_hz: np.ndarray) -> np.ndarray:
    """Depth correction (N,) from phasors (F, N): 2FSK formula for two frequencies, 3FSK slope for three."""
    if len(freqs_hz) == 2:
        return depth_correction_m(phasors[0], phasors[1], freqs_hz[0], freqs_hz[1])
    return slope_correction_m(phasors, freqs_hz)


def compare(fast: np.ndarray, ref: np.ndarray, freqs_hz: np.ndarray, config_idx: np.ndarray) -> dict:
    """Max phase error (rad), max relative error and max depth error (m) of one configuration's columns."""
    f, r = fast[config_idx].astype(np.complex128), ref[config_idx]
    phase_rad = np.abs(np.angle(f * np.conj(r)))
    rel = np.abs(f - r) / np.abs(r)
    depth_m = np.abs(_depth_m(f, freqs_hz[config_idx]) - _depth_m(r, freqs_hz[config_idx]))
    return {"max_phase_err_rad": float(phase_rad.max()), "max_rel_err": float(rel.max()),
            "max_depth_err_m": float(depth_m.max())}


def precision_rows(distances_m, grid_sizes, devices, n_ref: int, seed: int = 0) -> list[dict]:
    """One row per (distance, grid size, device, configuration); see the module doc."""
    rng = np.random.default_rng(seed)
    array = antennas()
    used = np.unique(np.concatenate([config_indices(MAROON_FREQS_HZ, c) for c in CONFIGS]))
    freqs_hz = MAROON_FREQS_HZ[used]
    config_idx = {c: np.searchsorted(used, config_indices(MAROON_FREQS_HZ, c)) for c in CONFIGS}
    rows = []
    for z_m in distances_m:
        signal = frame(plate_points_m(z_m), freqs_hz)
        for n_xy in grid_sizes:
            x_m, y_m = pixel_grid(GRID_HALF_M, n_xy, z_m).pixel_xy_m()
            z_px = z_m + rng.uniform(-PRIOR_JITTER_M, PRIOR_JITTER_M, x_m.size)
            points_m = np.column_stack([x_m.ravel(), y_m.ravel(), z_px])
            cpu = correlate(signal, freqs_hz, array.tx_m, array.rx_m, points_m)
            passing = np.flatnonzero(keep_mask(np.abs(cpu.mean(axis=0))))
            drawn = rng.choice(passing, size=min(n_ref, len(passing)), replace=False)
            ref = correlate_reference(signal, freqs_hz, array.tx_m, array.rx_m, points_m[drawn])
            for device in devices:
                if device == "cpu":
                    fast = cpu[:, drawn]
                elif device == "warp-cpu":
                    fast = correlate(signal, freqs_hz, array.tx_m, array.rx_m, points_m[drawn], device=device)
                else:
                    fast = correlate(signal, freqs_hz, array.tx_m, array.rx_m, points_m, device=device)[:, drawn]
                for config in CONFIGS:
                    rows.append({"distance_m": z_m, "grid_n": n_xy, "device": device, "config": config,
                                 "ref_points": len(drawn), **compare(fast, ref, freqs_hz, config_idx[config])})
    return rows
