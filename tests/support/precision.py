"""Bounds that tests derive from the precision of the path they test."""
from __future__ import annotations

import numpy as np

from bench.synth.memory import ANTENNAS
from methods.backends import correlate_volume
from methods.domain.capture import RadarGrid

FLOAT32_CORRELATION_REL = 1e-5   # a float32 CPU correlation path against the float64 sum (methods.ops.correlate;
                                 # measured ~4e-6, tests/methods/test_correlate.py)


def parabola_depth_bound_m(signal: np.ndarray, freqs_hz: np.ndarray, grid: RadarGrid) -> np.ndarray:
    """Per pixel (image shape of `grid`), how far two BP depths (metres) may differ whose |V| come from two float32
    correlation paths (each within FLOAT32_CORRELATION_REL of the float64 sum, so the dB samples differ by at most
    d = 20 log10(1 + 2 rel)): the parabola vertex o = (a - c) / (2 (a - 2b + c)) of the dB samples a, b, c around
    the peak moves by at most d (|do/da| + |do/db| + |do/dc|) = d (1 + 2 |o|) / |a - 2b + c|
    samples (methods.ops.depth_peak)."""
    volume = correlate_volume(signal, freqs_hz, ANTENNAS.tx_m, ANTENNAS.rx_m, grid.x_m, grid.y_m[::-1], grid.z_m)
    db = 20 * np.log10(np.maximum(np.abs(volume).astype(np.float64), np.finfo(np.float32).tiny))
    k = np.clip(np.argmax(db, axis=0), 1, len(grid.z_m) - 2)[None]
    a, b, c = (np.take_along_axis(db, k + s, axis=0)[0] for s in (-1, 0, 1))
    curvature = np.minimum(a - 2 * b + c, -1e-12)
    offset = np.clip(0.5 * (a - c) / curvature, -0.5, 0.5)
    d_db = 20 * np.log10(1 + 2 * FLOAT32_CORRELATION_REL)
    return float(grid.z_m[1] - grid.z_m[0]) * d_db * (1 + 2 * np.abs(offset)) / np.abs(curvature)
