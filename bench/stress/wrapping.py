"""Phase wrapping: prior offsets swept through and beyond the maximum unambiguous depth correction dd_max.

Scene: the 6 x 6 cm plate at PLATE_Z_M, a 7 x 7 pixel grid over its central +-1 cm. The prior is the truth
minus `offset` (offset = truth - prior, the correction the method must find): a scalar prior for 2FSK / 3FSK,
a constant prior image for MM-2FSK. A valid pixel is correct when its depth is within dd_max / 2 of the truth
(the right ambiguity interval; a wrapped estimate lands about 2 dd_max away). success_rate = correct / valid
pixels (the wrapping property; 0 when no pixel is valid), yield = correct / all pixels: they differ where the
-14 dB filter drops pixels, e.g. MM-2FSK d05 with the prior 8-14 cm in front of the plate, where the one-pass
correlation is defocused and half the 7 x 7 pixels fall below the filter while the valid ones stay correct.
dd_max = c / (4 df) of the configuration's smallest frequency step (for 3FSK the coarse pair, which must absorb
the prior error).

Boundary (defined and measured, see `boundaries`): success is 1 for |offset| <= dd_max and 0 from about
1.04-1.06 dd_max on (up to ~1.9, then the next period). At |offset| = dd_max the nominal phase is +-pi, but the
near-field round trip changes by less than twice the depth (off-axis pairs), so the measured phase is a few %
short of pi and the estimate is still right; the switch to the alias 2 dd_max away happens at 1.00-1.06 dd_max,
per pixel, never to a depth in between.
"""
from __future__ import annotations

import numpy as np

from bench.stress.scenes import antennas, config_freqs_hz, dd_max_m, frame, pixel_grid
from bench.synth.memory import plate_points_m
from methods.domain.capture import RadarGrid
from methods.domain.radar import MAROON_FREQS_HZ
from methods.fsk import reconstruct_2fsk
from methods.fsk3 import reconstruct_3fsk
from methods.mm2fsk import reconstruct_mm2fsk
from methods.ops.frequencies import config_indices

PLATE_Z_M = 0.40
CASES = (("2fsk", "d05"), ("2fsk", "d2"), ("2fsk", "d10"), ("3fsk", "d05_d10"),
         ("mm2fsk", "d05"), ("mm2fsk", "d2"), ("mm2fsk", "d10"))


def offset_ratios(quick: bool) -> np.ndarray:
    """offset / dd_max values: a coarse sweep over [-2, 2] plus a fine one around +-1."""
    coarse = np.linspace(-2.0, 2.0, 21 if quick else 81)
    fine = np.arange(0.90, 1.105, 0.05 if quick else 0.01)
    return np.unique(np.round(np.concatenate([coarse, fine, -fine]), 6))


def _reconstruct(method: str, signal: np.ndarray, freqs_hz: np.ndarray, grid: RadarGrid, prior_m: float):
    array = antennas()
    if method == "mm2fsk":
        return reconstruct_mm2fsk(signal, freqs_hz, array, grid, np.full(grid.image_shape, prior_m))
    run = reconstruct_2fsk if method == "2fsk" else reconstruct_3fsk
    return run(signal, freqs_hz, array, grid, prior_m=prior_m)


def wrapping_rows(ratios: np.ndarray, cases=CASES) -> list[dict]:
    """One row per (method, config, offset ratio): success rate, yield, valid fraction, median |error| / dd_max."""
    grid = pixel_grid(0.01, 7, PLATE_Z_M)
    all_freqs_hz = MAROON_FREQS_HZ[np.unique(np.concatenate([config_indices(MAROON_FREQS_HZ, c) for _, c in cases]))]
    signal_all = frame(plate_points_m(PLATE_Z_M), all_freqs_hz)
    rows = []
    for method, config in cases:
        freqs_hz = config_freqs_hz(config)
        signal = np.ascontiguousarray(signal_all[:, :, np.searchsorted(all_freqs_hz, freqs_hz)])
        dd_max = dd_max_m(config)
        for ratio in ratios:
            rec = _reconstruct(method, signal, freqs_hz, grid, PLATE_Z_M - ratio * dd_max)
            error_m = np.abs(rec.depth_m - PLATE_Z_M)
            correct = rec.valid & (np.nan_to_num(error_m, nan=np.inf) < dd_max / 2)
            rows.append({"method": method, "config": config, "dd_max_m": dd_max, "offset_ratio": float(ratio),
                         "offset_m": float(ratio * dd_max),
                         "success_rate": float(correct.sum() / max(rec.valid.sum(), 1)),
                         "yield": float(correct.mean()), "valid_fraction": float(rec.valid.mean()),
                         "median_error_ratio": float(np.nanmedian(error_m) / dd_max) if rec.valid.any() else np.nan})
    return rows


def boundaries(rows: list[dict]) -> list[dict]:
    """Per (method, config) and side: the largest |offset| / dd_max up to which every offset succeeds, and the
    smallest beyond which success is 0 up to 1.9 (NaN when the sweep never fails there)."""
    out = []
    for method, config in dict.fromkeys((r["method"], r["config"]) for r in rows):
        mine = [r for r in rows if r["method"] == method and r["config"] == config]
        for side in (+1, -1):
            ratios = sorted((abs(r["offset_ratio"]), r["success_rate"]) for r in mine
                            if np.sign(r["offset_ratio"]) in (0, side))
            last_ok = 0.0
            for ratio, rate in ratios:
                if rate < 1.0:
                    break
                last_ok = ratio
            failing = [ratio for ratio, rate in ratios if ratio > last_ok and ratio <= 1.9]
            first_zero = next((r for r in failing if all(rt == 0.0 for q, rt in ratios if r <= q <= 1.9)), np.nan)
            out.append({"method": method, "config": config, "side": "+" if side > 0 else "-",
                        "full_success_up_to": last_ok, "zero_success_from": first_zero})
    return out
