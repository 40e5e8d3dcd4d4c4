"""Planning of range-compressed back-projection (many frequencies over a volume).

With frequencies on an equidistant grid f_n = f0 + i_n df, the pair sum over frequencies at path length d is
`exp(j 2 pi f_c d / c) g(d)`, with carrier f_c = f0 + n_c df (n_c the grid centre) and the baseband range profile
`g(d) = sum_n S_n exp(j 2 pi (i_n - n_c) df d / c)`, periodic in d with period c / df. Sampling g at
L = Q * n_grid points per period (an oversampled inverse DFT) and interpolating linearly costs per voxel and pair
two gathers and one complex multiply instead of one sincos per frequency.

Linear interpolation of a tone at ν cycles/sample attenuates it by at most 1 - sinc^2-like (π ν)^2 / 2 at
half-sample offsets; the profile's band reaches ν = 1 / (2 Q), so with Q = 16 the worst-case amplitude error is
π^2 / (8 Q^2) = 0.48 % and the measured relative error over random scenes is ~0.2 %: RANGE_REL_TOL = 1e-2.

The Warp kernels keep only the profile samples of the path lengths the volume can reach (`sample_window`: for the
paper's box about 0.4-1.5 m of the 3.8 m period) and store them in fp16 (relative rounding <= 2^-11 = 0.05 %,
unbiased, far under the interpolation error): 9024 pairs x ~580 samples x 4 B = 21 MB, resident in the H100's L2
(50 MB), where the full float32 table (145 MB) streamed from HBM.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from methods.domain.radar import C_M_PER_S

OVERSAMPLING = 16          # Q: profile samples per grid bin
RANGE_REL_TOL = 1e-2       # stated bound of ||range - direct|| / ||direct||
RANGE_MIN_FREQS = 16       # from this many frequencies on, "auto" uses range compression on Warp devices
MAX_PATH_M = 3.0           # longest Tx->voxel->Rx path the periodic profile must hold without wrapping


@dataclass(frozen=True)
class RangePlan:
    """Frequency grid and profile sampling for one frequency set."""

    grid_index: np.ndarray   # (F,) int, i_n
    df_hz: float             # grid step
    f_carrier_hz: float      # f0 + n_c df
    n_centre: float          # n_c = (n_grid - 1) / 2
    n_samples: int           # L, a power of two

    @property
    def samples_per_m(self) -> float:
        """Profile samples per metre of path length: L df / c."""
        return self.n_samples * self.df_hz / C_M_PER_S


def plan(freqs_hz: np.ndarray, oversampling: int = OVERSAMPLING) -> RangePlan | None:
    """RangePlan for frequencies on an equidistant grid, or None (fewer than 2, off-grid, or path wrap).

    `oversampling` (Q): profile samples per grid bin; L = Q * n_grid rounded up to a power of two."""
    freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
    if len(freqs_hz) < 2:
        return None
    f0 = freqs_hz.min()
    df_hz = np.min(np.diff(np.unique(freqs_hz)))
    index = (freqs_hz - f0) / df_hz
    if np.max(np.abs(index - np.rint(index))) > 1e-6 or len(np.unique(freqs_hz)) != len(freqs_hz):
        return None
    if MAX_PATH_M * df_hz / C_M_PER_S >= 1.0:
        return None
    index = np.rint(index).astype(np.int64)
    n_grid = int(index.max()) + 1
    n_samples = 1 << int(np.ceil(np.log2(oversampling * n_grid)))
    n_centre = (n_grid - 1) / 2.0
    return RangePlan(index, float(df_hz), float(f0 + n_centre * df_hz), n_centre, n_samples)


def worth_it(freqs_hz: np.ndarray) -> bool:
    """The Warp backend's choice for a volume with method "auto": range compression with many frequencies.

    The numpy backend keeps the per-frequency BLAS sum for volumes; BP's depth search on the CPU uses the numpy
    range-compressed gather of `methods.backends.cpu_range` instead (measured faster there, docs/measurements/gpu.md).
    """
    return len(freqs_hz) >= RANGE_MIN_FREQS and plan(freqs_hz) is not None


def path_bounds_m(tx_m: np.ndarray, rx_m: np.ndarray, lo_m, hi_m) -> tuple[float, float]:
    """Lower and upper bounds of |p - rx| + |p - tx| over the box [lo_m, hi_m] (3,) and all pairs, metres: the
    stretch of path the range profiles must cover."""
    lo_m, hi_m = np.asarray(lo_m, dtype=np.float64), np.asarray(hi_m, dtype=np.float64)

    def near_far(ant_m):
        near = np.linalg.norm(np.clip(ant_m, lo_m, hi_m) - ant_m, axis=1)
        far = np.linalg.norm(np.maximum(np.abs(ant_m - lo_m), np.abs(ant_m - hi_m)), axis=1)
        return near.min(), far.max()
    near_rx, far_rx = near_far(rx_m)
    near_tx, far_tx = near_far(tx_m)
    return float(near_rx + near_tx), float(far_rx + far_tx)


def sample_window(rplan: RangePlan, path_min_m: float, path_max_m: float, margin: int = 2) -> tuple[int, int]:
    """(m0, n): the profile samples m0 .. m0 + n - 1 (taken mod L) cover the paths [path_min_m, path_max_m] with
    `margin` samples either side, for linear interpolation between neighbours."""
    m0 = int(np.floor(path_min_m * rplan.samples_per_m)) - margin
    m1 = int(np.ceil(path_max_m * rplan.samples_per_m)) + margin
    return m0, m1 - m0 + 1


def profile_shift(rplan: RangePlan) -> np.ndarray:
    """complex (L,) exp(-j 2 pi n_c m / L) that centres the inverse DFT of the grid-indexed spectrum."""
    m = np.arange(rplan.n_samples)
    return np.exp(-2j * np.pi * rplan.n_centre * m / rplan.n_samples)


def profiles_numpy(signal: np.ndarray, rplan: RangePlan) -> np.ndarray:
    """Range profiles (n_rx * n_tx, L) complex128 by FFT: the float64 check of the Warp DFT kernel."""
    n_rx, n_tx, _ = signal.shape
    spectrum = np.zeros((n_rx * n_tx, rplan.n_samples), dtype=np.complex128)
    spectrum[:, rplan.grid_index] = signal.reshape(n_rx * n_tx, -1)
    return np.fft.ifft(spectrum, axis=1) * rplan.n_samples * profile_shift(rplan)[None, :]
