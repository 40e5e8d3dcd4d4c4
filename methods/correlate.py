"""The correlation API by device name, and its float64 reference (DESIGN.md section 5).

For radar-space points p and frequencies f the back-projection phasor is

    C[f, p] = sum_{r, t} S[r, t, f] * exp(+j 2 pi f (|p - rx_r| + |p - tx_t|) / c) / (n_rx * n_tx)

with `S[rx, tx, f]` the calibrated frame (signal model `S ~ exp(-j 2 pi f tau)`). `sum_freqs=True` returns the
coherent sum over f. This module holds the float64 direct-sum reference every backend is tested against, and
`correlate` / `correlate_volume` / `volume_peak_depth` by device name for scripts and tests; methods hold the
resolved backend (methods.backend) and call it directly.
"""
from __future__ import annotations

import numpy as np

from methods.backend import backend_for

C_M_PER_S = 299_792_458.0


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


def correlate(signal, freqs_hz, tx_m, rx_m, points_m, *, sum_freqs: bool = False, device: str = "cpu") -> np.ndarray:
    """Back-projection phasors at points: complex64 (F, N), or (N,) summed over frequencies with `sum_freqs`.

    signal (n_rx, n_tx, F) complex, freqs_hz (F,), tx_m (n_tx, 3), rx_m (n_rx, 3), points_m (N, 3), radar space,
    metres. C[f, p] = sum_{r,t} S[r,t,f] exp(+j 2 pi f (|p - rx_r| + |p - tx_t|) / c) / (n_rx n_tx).
    Precision against `correlate_reference` (relative): CPU and Warp float32 paths ~1e-5 (phases formed
    carefully); the CUDA default multiplies on tensor cores with fp16 inputs and fp32 accumulation, ~3e-4
    (bounded by 1e-3 in the tests; notes/gpu.md explains why that is enough). The sum over frequencies is taken
    on the host here (as the per-frequency output); `Backend.correlate_summed` takes it where the data lives.
    """
    out = backend_for(device).correlate(signal, freqs_hz, tx_m, rx_m, points_m)
    return out.sum(axis=0) if sum_freqs else out


def correlate_volume(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, *, device: str = "cpu",
                     method: str = "auto") -> np.ndarray:
    """Coherent sum over all frequencies on the grid x_m (nx,), y_m (ny,), z_m (nz,): complex64 (nz, ny, nx).

    Axes follow the order the coordinate vectors are given (pass y descending for row 0 = +y).
    `method`: "direct" (per-frequency separable sum, exact to float32), "range" (range-compressed: per pair an
    oversampled inverse DFT along frequency once, then linear interpolation of the range profiles and one phase
    rotation per voxel; relative error <= RANGE_REL_TOL; needs frequencies on an equidistant grid; Warp devices
    only), or "auto" (range compression on Warp devices from RANGE_MIN_FREQS frequencies on, when the grid allows
    it).
    """
    return backend_for(device).volume(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, method=method)


def volume_peak_depth(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, *, device: str, timer=None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """`correlate_volume` (method "auto") followed by `methods.depth_peak.peak_depth_m` over z: (depth_m, max
    projection), each float64 (ny, nx); on a Warp device the volume stays there. z_m must be equidistant (the BP
    grid). `timer` (StageTimer) gets the stages "correlate" and "depth"."""
    z_m = np.atleast_1d(np.asarray(z_m, dtype=np.float64))
    dz_m = float(z_m[1] - z_m[0]) if len(z_m) > 1 else 0.0
    return backend_for(device).volume_peak(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, dz_m, timer=timer)
