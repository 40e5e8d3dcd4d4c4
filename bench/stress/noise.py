"""Noise against the physical limit: MM-2FSK depth standard deviation vs the Cramer-Rao bound.

Per-sample SNR = mean |s|^2 / sigma^2 over the frame's samples (two frequencies), complex Gaussian noise of
power sigma^2 (`bench.synth.radar.model.noise_frame`). With N = 8836 pairs the normalised matched-filter phasor
c_k = (1/N) sum s w carries noise of variance sigma^2 / N, so each phase has variance 1 / (2 N SNR_k) and the
phase of c2 conj(c1) the sum of both, 1 / (N SNR): hence

    crb_m = c / (4 pi df sqrt(N SNR))                        (the issue's formula; the two-phase sum included)

for a target whose energy all focuses in the pixel (a point target, |c_k|^2 = mean |s|^2). For any pixel the
same argument with its noise-free focused phasors c_k gives the bound the 2FSK estimator can reach there,

    focused_crb_m = c / (4 pi df) sqrt(sum_k sigma^2 / (2 N |c_k|^2)),

which is what an extended target (the plate: its energy spreads over many pixels) must be compared with.
Scenes: a point at (0, 0, 0.30) m with the prior exactly at it on one pixel; the 6 x 6 cm plate at 0.30 m
with the exact prior on an 11 x 11 grid over +-1 cm. The std is over noise realisations (per pixel, pooled).
"""
from __future__ import annotations

import numpy as np

from bench.stress.scenes import antennas, config_freqs_hz, frame, noise_power, pixel_grid
from bench.synth.memory import plate_points_m
from bench.synth.radar.model import noise_frame
from methods.backends import correlate
from methods.mm2fsk import reconstruct_mm2fsk
from methods.ops.correlate import C_M_PER_S

TARGET_Z_M = 0.30
N_PAIRS = 94 * 94


def crb_m(delta_f_hz: float, snr_db: float, n_pairs: int = N_PAIRS) -> float:
    """sigma_d = c / (4 pi df sqrt(N SNR)) in metres, SNR per sample (linear from dB)."""
    return C_M_PER_S / (4.0 * np.pi * delta_f_hz * np.sqrt(n_pairs * 10.0 ** (snr_db / 10.0)))


def focused_crb_m(phasors: np.ndarray, delta_f_hz: float, noise_power_per_sample: float,
                  n_pairs: int = N_PAIRS) -> np.ndarray:
    """Per-pixel bound (N,) in metres from noise-free focused phasors (2, N) and the per-sample noise power."""
    phase_var = noise_power_per_sample / (2.0 * n_pairs * np.abs(phasors) ** 2)
    return C_M_PER_S / (4.0 * np.pi * delta_f_hz) * np.sqrt(phase_var.sum(axis=0))


def _scene(kind: str, freqs_hz: np.ndarray):
    """(signal, grid, prior image) of the point or plate scene."""
    if kind == "point":
        grid = pixel_grid(0.001, 3, TARGET_Z_M)
        prior_m = np.full(grid.image_shape, np.nan)
        prior_m[1, 1] = TARGET_Z_M                     # the centre pixel sits on the point
        return frame([[0.0, 0.0, TARGET_Z_M]], freqs_hz), grid, prior_m
    grid = pixel_grid(0.01, 11, TARGET_Z_M)
    return frame(plate_points_m(TARGET_Z_M), freqs_hz), grid, np.full(grid.image_shape, TARGET_Z_M)


def noise_rows(snrs_db, configs, realisations: dict[str, int], seed: int = 0) -> list[dict]:
    """One row per (scene, config, SNR): measured depth std, both bounds and their ratios, bias, valid fraction."""
    rng = np.random.default_rng(seed)
    array = antennas()
    rows = []
    for kind, n_real in realisations.items():
        for config in configs:
            freqs_hz = config_freqs_hz(config)
            delta_f_hz = float(freqs_hz[1] - freqs_hz[0])
            signal, grid, prior_m = _scene(kind, freqs_hz)
            has_prior = np.isfinite(prior_m)
            x_m, y_m = grid.pixel_xy_m()
            points_m = np.column_stack([x_m[has_prior], y_m[has_prior], prior_m[has_prior]])
            clean = correlate(signal, freqs_hz, array.tx_m, array.rx_m, points_m)
            for snr_db in snrs_db:
                depths_m = np.array([reconstruct_mm2fsk(signal + noise_frame(signal.shape, noise_power(signal, 0.0),
                                                                             snr_db, rng),
                                                        freqs_hz, array, grid, prior_m).depth_m[has_prior]
                                     for _ in range(n_real)])                         # (realisations, pixels)
                valid = np.isfinite(depths_m)
                counts = valid.sum(axis=0)
                usable = counts >= 2
                std_m = float(np.sqrt(np.mean(np.nanvar(depths_m[:, usable], axis=0, ddof=1))))
                bound_m = crb_m(delta_f_hz, snr_db)
                focused_m = float(np.sqrt(np.mean(focused_crb_m(clean[:, usable], delta_f_hz,
                                                                noise_power(signal, snr_db)) ** 2)))
                rows.append({"scene": kind, "config": config, "delta_f_hz": delta_f_hz, "snr_db": float(snr_db),
                             "realisations": n_real, "pixels": int(usable.sum()), "valid_fraction": float(valid.mean()),
                             "std_m": std_m, "crb_m": bound_m, "ratio": std_m / bound_m,
                             "focused_crb_m": focused_m, "focused_ratio": std_m / focused_m,
                             "bias_m": float(np.nanmean(depths_m) - TARGET_Z_M)})
    return rows
