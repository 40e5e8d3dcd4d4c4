"""The correlation's float64 reference (DESIGN.md section 5) and the speed of light it is defined with.

For radar-space points p and frequencies f the back-projection phasor is

    C[f, p] = sum_{r, t} S[r, t, f] * exp(+j 2 pi f (|p - rx_r| + |p - tx_t|) / c) / (n_rx * n_tx)

with `S[rx, tx, f]` the calibrated frame (signal model `S ~ exp(-j 2 pi f tau)`). `sum_freqs=True` returns the
coherent sum over f. This module holds the float64 direct-sum reference every backend is tested against; the same
correlation by device name is `methods.backends.correlate` (methods hold the resolved backend and call it).
"""
from __future__ import annotations

import numpy as np

from methods.domain.radar import C_M_PER_S


def correlate_reference(signal: np.ndarray, freqs_hz: np.ndarray, tx_m: np.ndarray, rx_m: np.ndarray,
                        points_m: np.ndarray, sum_freqs: bool = False) -> np.ndarray:
    """Float64 direct sum, one point at a time. Returns complex128 (F, N), or (N,) with `sum_freqs`."""
    signal = np.asarray(signal, dtype=np.complex128)
    freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
    points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    out = np.empty((len(freqs_hz), len(points_m)), dtype=np.complex128)
    for n, p in enumerate(points_m):
        d_rx_m = np.linalg.norm(p - rx_m, axis=1)                   # (n_rx,)
        d_tx_m = np.linalg.norm(p - tx_m, axis=1)                   # (n_tx,)
        path_m = d_rx_m[:, None] + d_tx_m[None, :]                  # (n_rx, n_tx)
        phase = 2.0 * np.pi * freqs_hz[None, None, :] * path_m[:, :, None] / C_M_PER_S
        out[:, n] = np.sum(signal * np.exp(1j * phase), axis=(0, 1))
    out /= len(rx_m) * len(tx_m)
    return out.sum(axis=0) if sum_freqs else out
