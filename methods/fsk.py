"""2FSK with a scalar depth prior (paper section II-A; MAROON_FORMAT.md 6.3), and the FSK building blocks.

Residual phasors c_k at a guess depth d~ follow `c_k ~ exp(-j 4 pi f_k (d - d~) / c)`, so the depth is
`d = d~ - c * angle(c2 * conj(c1)) / (4 pi (f2 - f1))` (DESIGN.md section 4), unambiguous while
|d - d~| < c / (4 (f2 - f1)).

Two passes from the scalar prior z0 (default 0.40 m as in the paper): pass 1 correlates every pixel at z0; the
pixel with the largest |c1| gives the correction z1 = z0 - dz(that pixel), applied to all pixels; pass 2
correlates every pixel at z1 and corrects each pixel by its own dz. The filter quantity is the magnitude of the
mean residual phasor over the pairs and both frequencies of the final pass.
"""
from __future__ import annotations

import numpy as np

from bench.antennas import AntennaArray
from bench.capture import RadarGrid
from methods.correlate import C_M_PER_S, correlate
from methods.filtering import DEFAULT_THRESHOLD_DB, filter_depth
from methods.reconstruction import Reconstruction
from methods.timing import StageTimer

DEFAULT_PRIOR_M = 0.40


def depth_correction_m(c_lo: np.ndarray, c_hi: np.ndarray, f_lo_hz: float, f_hi_hz: float) -> np.ndarray:
    """dz = c angle(c_hi conj(c_lo)) / (4 pi (f_hi - f_lo)) in metres; the depth is `guess - dz`."""
    phase = np.angle(c_hi * np.conj(c_lo)).astype(np.float64)
    return C_M_PER_S * phase / (4.0 * np.pi * (f_hi_hz - f_lo_hz))


def correlate_pixels(signal: np.ndarray, freqs_hz: np.ndarray, antennas: AntennaArray, x_m: np.ndarray,
                     y_m: np.ndarray, z_m: np.ndarray | float, device: str) -> np.ndarray:
    """Residual phasors (F, N) at the points (x_m, y_m, z_m), each (N,) (z may be a scalar)."""
    points_m = np.column_stack([x_m, y_m, np.broadcast_to(z_m, np.shape(x_m))])
    return correlate(signal, freqs_hz, antennas.tx_m, antennas.rx_m, points_m, device=device)


def mean_phasor_magnitude(phasors: np.ndarray) -> np.ndarray:
    """|mean over frequencies| of residual phasors (F, N) already averaged over pairs: the filter quantity."""
    return np.abs(phasors.mean(axis=0)).astype(np.float64)


def two_pass_depth_m(signal: np.ndarray, freqs_hz: np.ndarray, antennas: AntennaArray, x_m: np.ndarray,
                     y_m: np.ndarray, prior_m: float, device: str, timer: StageTimer
                     ) -> tuple[np.ndarray, np.ndarray, dict]:
    """Two-pass 2FSK over pixels (x_m, y_m) from a scalar prior: depth (N,) m, final phasors (2, N), details.

    `signal` (n_rx, n_tx, 2) holds the frequencies `freqs_hz` (f_lo < f_hi).
    """
    f_lo, f_hi = freqs_hz
    with timer.stage("correlate"):
        first = correlate_pixels(signal, freqs_hz, antennas, x_m, y_m, prior_m, device)
    with timer.stage("depth"):
        ref = int(np.argmax(np.abs(first[0])))
        z1_m = prior_m - float(depth_correction_m(first[0, ref], first[1, ref], f_lo, f_hi))
    with timer.stage("correlate"):
        second = correlate_pixels(signal, freqs_hz, antennas, x_m, y_m, z1_m, device)
    with timer.stage("depth"):
        depth_m = z1_m - depth_correction_m(second[0], second[1], f_lo, f_hi)
    return depth_m, second, {"reference_pixel": ref, "z1_m": z1_m}


def finish(depth_m: np.ndarray, phasors: np.ndarray, grid: RadarGrid, freqs_hz: np.ndarray, method: str,
           threshold_db: float | None, timer: StageTimer, extra: dict) -> Reconstruction:
    """Filter the per-pixel depths (ny*nx,) by the mean phasor magnitude and package the Reconstruction."""
    with timer.stage("filter"):
        magnitude = mean_phasor_magnitude(phasors).reshape(grid.image_shape)
        depth_m = filter_depth(depth_m.reshape(grid.image_shape), magnitude, threshold_db)
    return Reconstruction(depth_m=depth_m, magnitude=magnitude, freqs_hz=np.asarray(freqs_hz),
                          timings_ms=timer.finish(), grid=grid, method=method, extra=extra)


def reconstruct_2fsk(signal: np.ndarray, freqs_hz: np.ndarray, antennas: AntennaArray, grid: RadarGrid, *,
                     prior_m: float = DEFAULT_PRIOR_M, threshold_db: float | None = DEFAULT_THRESHOLD_DB,
                     device: str = "cpu") -> Reconstruction:
    """2FSK depth map on `grid`'s pixels from a two-frequency frame `signal` (n_rx, n_tx, 2)."""
    if len(freqs_hz) != 2:
        raise ValueError(f"2FSK needs exactly two frequencies, got {len(freqs_hz)}")
    timer = StageTimer()
    x_m, y_m = (a.ravel() for a in grid.pixel_xy_m())
    depth_m, phasors, details = two_pass_depth_m(signal, freqs_hz, antennas, x_m, y_m, prior_m, device, timer)
    return finish(depth_m, phasors, grid, freqs_hz, "2fsk", threshold_db, timer, {"prior_m": prior_m, **details})
