"""Range-compressed back-projection on the CPU (numpy): the frequency-summed correlation at arbitrary points for
frames with many frequencies (BP_max), one gather per antenna pair and point instead of one product per frequency.

With frequencies on an equidistant grid (`methods.ops.range_compression.plan`), the pair sum over frequencies at path
length d is `exp(j k_c d) g_rt(d)` with the baseband range profile `g_rt(d) = sum_n S_rtn exp(j 2 pi (i_n - n_c)
df d / c)`. The profile is sampled once per frame at L = Q * n_grid points per period c / df (Q = OVERSAMPLING,
64 here: the table stays in memory, unlike the GPU's L2-bound fp16 table) but only over the path lengths the points
can reach (a window of ~0.7 m at the paper's box: 8836 pairs x ~1500 samples x 2 x 8 B = 210 MB), as one complex64
matrix product (pairs x F) @ (F x window) - the inverse DFT restricted to the window (`profiles_numpy`'s FFT is its
float64 check). Per point: `d = 2|p| + e_rx + e_tx` with the cancellation-free excesses of `backend_numpy`, the
profile interpolated linearly at d, times the carrier `exp(j k_c d)` = common phasor (float64, reduced mod 2 pi) x
rx steering x tx steering (separable, so 188 sincos per point instead of 8836).

Error: linear interpolation of a tone at nu cycles per sample returns it times (1 - t) exp(-j 2 pi nu t) + t exp(j 2
pi nu (1 - t)) at offset t, whose mean over t is sinc^2(nu) (the triangle kernel's response); the table divides
each frequency by sinc^2(nu_n) (`deconvolve`, as a NUFFT divides by its kernel's transform), leaving the part that
varies with t: rms 9e-5, max 2e-4 at the band edge nu = 1 / (2 Q) for Q = 64 (3.6e-4 / 8e-4 at Q = 32, 8.8e-4 /
1.2e-3 at Q = 32 without the division). Measured against the float64 direct sum on random scenes (128 frequencies,
docs/measurements/formation.md): 3e-5 relative L2 (Q = 32 without the division, the earlier default: 4.3e-4, above
the 1e-4 BP must meet); tests: RANGE_CPU_REL_TOL. The table is twice Q = 32's and the gather ~10-25 % slower.
Cost (measured, docs/measurements/gpu.md): ~4-7x less than the per-frequency BLAS sum at 128 frequencies on the 2-core
CPU; it pays from ~16 frequencies on (`worth_it`).

Layout: points sorted by depth, in chunks of CHUNK_POINTS, and in each chunk the pairs in blocks of RX_BLOCK receive
rows, arrays ordered (rx, tx, point) so that one pair's samples for all points of a chunk are gathered together
(points at one depth have close paths, so few cache lines per pair row and chunk: 7.8 against 12.4 ns per pair
and point in BP's search order, docs/measurements/formation.md); chunks run on worker threads (numpy releases the
GIL).
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from methods.backends.cpu import correlation_threads
from methods.backends.cpu import path_excess_m as _path_excess_m
from methods.backends.cpu import phasor_mod_2pi as _phasor_mod_2pi
from methods.domain.radar import C_M_PER_S
from methods.ops import range_compression

OVERSAMPLING = 64          # Q on the CPU (profile samples per frequency-grid bin)
RANGE_CPU_REL_TOL = 1e-4   # stated bound of ||range - direct|| / ||direct|| (measured 3e-5)
MIN_FREQS = 16             # from this many frequencies on, BP's CPU depth search uses range compression
CHUNK_POINTS = 1024        # points per chunk (depth-ordered: larger chunks share more cache lines per pair row) ...
RX_BLOCK = 4               # ... receive rows per gather block: (4 x 94 x 1024) work arrays, 6.7 against 8.1 ns per
                           # pair and point for 256 x 8 (docs/measurements/formation.md)
DEPTH_ORDER = True         # chunks of points sorted by depth (False: in the caller's order, for the benchmark)


@dataclass(frozen=True)
class RangeTable:
    """A frame's windowed range profiles, pair-major: sample j of pair q at `values[q * n_window + j]`, path length
    (m0 + j) / samples_per_m, and `slopes[i] = values[i + 1] - values[i]` (linear interpolation in two passes).
    Both (n_rx * n_tx * n_window,) complex64."""

    values: np.ndarray
    slopes: np.ndarray
    n_rx: int
    n_tx: int
    m0: int                  # first sample index (path m0 / samples_per_m)
    n_window: int
    samples_per_m: float
    f_carrier_hz: float


def worth_it(freqs_hz: np.ndarray) -> bool:
    """Whether the CPU range-compressed path applies and pays: >= MIN_FREQS frequencies on an equidistant grid."""
    return len(freqs_hz) >= MIN_FREQS and range_compression.plan(freqs_hz, OVERSAMPLING) is not None


def path_bounds_m(tx_m: np.ndarray, rx_m: np.ndarray, points_m: np.ndarray) -> tuple[float, float]:
    """Lower and upper bounds of |p - rx| + |p - tx| over the bounding box of `points_m` and all pairs, metres."""
    return range_compression.path_bounds_m(tx_m, rx_m, points_m.min(axis=0), points_m.max(axis=0))


def range_table(signal: np.ndarray, freqs_hz: np.ndarray, path_min_m: float, path_max_m: float,
                oversampling: int = OVERSAMPLING, deconvolve: bool = True) -> RangeTable:
    """Windowed range profiles of `signal` (n_rx, n_tx, F) covering paths [path_min_m, path_max_m], normalised by
    n_rx * n_tx like `correlate`, each frequency divided by the linear interpolation's mean response sinc^2(nu_n)
    unless `deconvolve` is False (module doc). Raises ValueError when the frequencies are not on an equidistant
    grid."""
    freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
    rplan = range_compression.plan(freqs_hz, oversampling)
    if rplan is None:
        raise ValueError("CPU range compression needs >= 2 distinct frequencies on an equidistant grid")
    n_rx, n_tx, n_freqs = signal.shape
    m0, n_window = range_compression.sample_window(rplan, path_min_m, path_max_m)
    # exp(j 2 pi (i_n - n_c) m / L) for the window's sample indices m; the product (i_n - n_c) m is formed in float64
    # and reduced mod L before the trigonometry (arguments up to ~1e5 cycles otherwise)
    cycles = np.outer(rplan.grid_index - rplan.n_centre, m0 + np.arange(n_window, dtype=np.float64))
    cycles = np.mod(cycles, rplan.n_samples) / rplan.n_samples
    dft = np.exp(2j * np.pi * cycles)                                                   # (F, n_window)
    if deconvolve:
        dft /= np.sinc((rplan.grid_index - rplan.n_centre) / rplan.n_samples)[:, None] ** 2
    dft = dft.astype(np.complex64)
    pairs = (signal.reshape(n_rx * n_tx, n_freqs) / (n_rx * n_tx)).astype(np.complex64)
    values = (pairs @ dft).ravel()
    slopes = np.empty_like(values)
    slopes[:-1] = values[1:] - values[:-1]
    slopes[-1] = 0
    return RangeTable(values, slopes, n_rx, n_tx, m0, n_window, rplan.samples_per_m, rplan.f_carrier_hz)


def _steering(k_rad_per_m: float, excess_m: np.ndarray) -> np.ndarray:
    """complex64 exp(j k e) for float32 excesses (|k e| <~ 200 rad: float32 phases suffice, as in backend_numpy)."""
    phase = excess_m * np.float32(k_rad_per_m)
    out = np.empty(phase.shape, dtype=np.complex64)
    out.real = np.cos(phase)
    out.imag = np.sin(phase)
    return out


def _chunk(table: RangeTable, tx_m: np.ndarray, rx_m: np.ndarray, points_m: np.ndarray) -> np.ndarray:
    """Frequency-summed correlation (n,) complex64 of one chunk of points."""
    norm_m = np.sqrt(np.einsum("ni,ni->n", points_m, points_m))
    excess_rx = _path_excess_m(points_m, norm_m, rx_m).T.copy()           # (R, n) float32
    excess_tx = _path_excess_m(points_m, norm_m, tx_m).T.copy()           # (T, n)
    spm = table.samples_per_m
    # sample position of the path 2|p| + e_rx + e_tx relative to the window start; 2|p| in float64 first
    u_rx = ((2.0 * norm_m * spm - table.m0)[None, :] + excess_rx * np.float32(spm)).astype(np.float32)
    u_tx = excess_tx * np.float32(spm)
    k_c = 2.0 * np.pi * table.f_carrier_hz / C_M_PER_S
    steer_rx, steer_tx = _steering(k_c, excess_rx), _steering(k_c, excess_tx)
    row_start = (np.arange(table.n_rx * table.n_tx, dtype=np.intp) * table.n_window).reshape(table.n_rx, table.n_tx)
    acc = np.zeros(len(points_m), dtype=np.complex64)
    for r0 in range(0, table.n_rx, RX_BLOCK):
        r1 = min(r0 + RX_BLOCK, table.n_rx)
        u = u_rx[r0:r1, None, :] + u_tx[None, :, :]                       # (rb, T, n), inside the window by
        whole = np.floor(u)                                                # construction (path_bounds_m + margin)
        u -= whole                                                         # interpolation weight
        # intp indices: numpy's take converts int32 indices element by element (measured 10x slower)
        index = whole.astype(np.intp)
        index += row_start[r0:r1, :, None]
        profile = table.slopes.take(index)
        profile *= u
        profile += table.values.take(index)                                # interpolated g_rt(d)
        profile *= steer_tx[None, :, :]
        acc += np.einsum("rn,rn->n", profile.sum(axis=1), steer_rx[r0:r1])
    return acc * _phasor_mod_2pi(norm_m * (2.0 * table.f_carrier_hz / C_M_PER_S))


def correlate_range_cpu(table: RangeTable, tx_m: np.ndarray, rx_m: np.ndarray, points_m: np.ndarray) -> np.ndarray:
    """Frequency-summed correlation complex64 (N,) at points (N, 3), metres, from the frame's `range_table` (which
    must cover the points' paths: build it with `path_bounds_m` of these or enclosing points)."""
    points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    out = np.empty(len(points_m), dtype=np.complex64)
    starts = range(0, len(points_m), CHUNK_POINTS)
    # chunks of points at nearly the same depth: each pair's samples of a chunk then lie close together in its
    # profile row (BP's search hands over a pixel's depths one after another; measured 1.5x faster in depth order)
    order = np.argsort(points_m[:, 2], kind="stable") if DEPTH_ORDER else np.arange(len(points_m))

    def work(start: int) -> None:
        chunk = order[start:start + CHUNK_POINTS]
        out[chunk] = _chunk(table, tx_m, rx_m, points_m[chunk])

    n_threads = correlation_threads()
    with threadpool_limits(limits=1, user_api="blas"):
        if n_threads == 1 or len(starts) <= 1:
            for s in starts:
                work(s)
        else:
            with ThreadPoolExecutor(n_threads) as pool:
                list(pool.map(work, starts))
    return out


def correlate_range(signal: np.ndarray, freqs_hz: np.ndarray, tx_m: np.ndarray, rx_m: np.ndarray,
                    points_m: np.ndarray) -> np.ndarray:
    """One-shot: table for these points, then `correlate_range_cpu`. complex64 (N,)."""
    points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    table = range_table(signal, freqs_hz, *path_bounds_m(tx_m, rx_m, points_m))
    return correlate_range_cpu(table, tx_m, rx_m, points_m)
