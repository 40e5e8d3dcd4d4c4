"""CPU correlation backend: complex64 separable steering vectors and float32 BLAS products.

Per point p and frequency f the pair sum is `a^T S b` with steering vectors `a_r = exp(jk |p - rx_r|)` and
`b_t = exp(jk |p - tx_t|)`, k = 2 pi f / c. For a chunk of points, `A S` is one real float32 matrix product of
`[cos | sin]` (n x 2R) with `[[Sr, Si], [-Si, Sr]]` (2R x 2T), and the contraction with `b` is a row-wise dot.

Precision: phases reach ~1e3 rad, where a float32 phase has an ulp of 6e-5 rad. Every distance is written as
`|p - q| = |p| + delta` with `delta = (|q|^2 - 2 p.q) / (|p - q| + |p|)`, which float32 gives to a relative 1e-7
(|delta| <= |q| ~ 0.1 m, so k delta <= ~200 rad and its error ~2e-5 rad); the large common phase `2 k |p|` is
formed in float64 per point and reduced mod 2 pi. Result: ~1e-5 relative error against the float64 reference.
"""
from __future__ import annotations

import functools
import math
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from threadpoolctl import ThreadpoolController

from methods.backends.base import Backend, check_inputs, grid_vectors
from methods.domain.host import usable_cores
from methods.domain.radar import C_M_PER_S
from methods.ops.depth_peak import peak_depth_m
from methods.ops.timing import StageTimer

CHUNK_POINTS = 2048     # most points per block: keeps the (chunk x 2*94) float32 work arrays in L2 cache
# fewer points run on the calling thread (single-threaded BLAS): a pool costs ~1 ms a call, more than the work
# (BP's depth search climbs in rounds of a few dozen points; 50 points: 0.5-1.0 against 1.6-2.6 ms, load 5)
MIN_PARALLEL_POINTS = 128


def correlation_threads() -> int:
    """Worker threads over point chunks: CORRELATE_THREADS if set, else one per core this process may use."""
    return max(1, int(os.environ.get("CORRELATE_THREADS", "0")) or usable_cores())


@functools.cache
def _blas_controller() -> ThreadpoolController:
    """The process's BLAS thread pools, inspected once: `threadpool_limits` scans every loaded library on each
    call (1-4 ms per frame in a sweep process that has loaded Open3D, h5py and scipy)."""
    return ThreadpoolController()


_POOLS: dict[tuple[int, int], ThreadPoolExecutor] = {}


def _pool(n_threads: int) -> ThreadPoolExecutor:
    """A worker pool kept per process (its pid: a forked child starts its own) and size: BP's search calls the
    correlation ~30 times a frame, and starting two threads a call cost 0.1-5 ms (more on a loaded machine)."""
    key = (os.getpid(), n_threads)
    if key not in _POOLS:
        _POOLS[key] = ThreadPoolExecutor(n_threads, thread_name_prefix="correlate")
    return _POOLS[key]


def chunk_starts(n_points: int, n_threads: int) -> range:
    """Starts of equal point chunks of at most CHUNK_POINTS, as many as a multiple of `n_threads`: 13.7 k points
    (a catalogue frame) on 2 threads make 8 chunks of 1.7 k, not 7 of 2048 leaving one thread a chunk alone."""
    n_chunks = max(1, math.ceil(n_points / (CHUNK_POINTS * n_threads))) * n_threads
    return range(0, n_points, max(1, math.ceil(n_points / n_chunks)))


def path_excess_m(points_m: np.ndarray, norm_m: np.ndarray, ant_m: np.ndarray) -> np.ndarray:
    """`|p - q| - |p|` in float32 for points (n, 3) and antennas (A, 3), metres, cancellation-free."""
    p32 = points_m.astype(np.float32)
    q32 = ant_m.astype(np.float32)
    num = p32 @ (-2.0 * q32.T)                                  # -2 p.q, (n, A)
    num += np.einsum("ai,ai->a", q32, q32)[None, :]             # + |q|^2
    norm32 = norm_m.astype(np.float32)[:, None]
    den = norm32 * norm32 + num                                  # |p - q|^2
    np.maximum(den, 0.0, out=den)
    np.sqrt(den, out=den)
    den += norm32                                                # |p - q| + |p|
    num /= den
    return num


def phasor_mod_2pi(cycles: np.ndarray) -> np.ndarray:
    """complex64 exp(j 2 pi cycles) for float64 `cycles`, reduced to [-0.5, 0.5] before float32."""
    frac = (cycles - np.rint(cycles)).astype(np.float32) * np.float32(2.0 * np.pi)
    out = np.empty(frac.shape, dtype=np.complex64)
    out.real = np.cos(frac)
    out.imag = np.sin(frac)
    return out


def _real_block_matrix(signal_f: np.ndarray) -> np.ndarray:
    """float32 [[Sr, Si], [-Si, Sr]] (2R x 2T) so that [cos | sin] @ M = [Re(A S) | Im(A S)]."""
    sr = signal_f.real.astype(np.float32)
    si = signal_f.imag.astype(np.float32)
    return np.block([[sr, si], [-si, sr]])


def _correlate_chunk(signal_blocks, wavenumbers_rad_per_m, tx_m, rx_m, points_m, out):
    """Fill out[:, :] (F, n) complex64 for one chunk of points."""
    n = len(points_m)
    n_rx, n_tx = len(rx_m), len(tx_m)
    norm_m = np.sqrt(np.einsum("ni,ni->n", points_m, points_m))          # float64 |p|
    excess_rx = path_excess_m(points_m, norm_m, rx_m)                   # (n, R) float32
    excess_tx = path_excess_m(points_m, norm_m, tx_m)                   # (n, T) float32
    steer_rx = np.empty((n, 2 * n_rx), dtype=np.float32)                 # [cos | sin]
    phase_rx = np.empty((n, n_rx), dtype=np.float32)
    phase_tx = np.empty((n, n_tx), dtype=np.float32)
    cos_tx = np.empty((n, n_tx), dtype=np.float32)
    sin_tx = np.empty((n, n_tx), dtype=np.float32)
    for i, (k, block) in enumerate(zip(wavenumbers_rad_per_m, signal_blocks, strict=False)):
        k32 = np.float32(k)
        np.multiply(excess_rx, k32, out=phase_rx)
        np.cos(phase_rx, out=steer_rx[:, :n_rx])
        np.sin(phase_rx, out=steer_rx[:, n_rx:])
        prod = steer_rx @ block                                          # (n, 2T): [Re(aS) | Im(aS)]
        np.multiply(excess_tx, k32, out=phase_tx)
        np.cos(phase_tx, out=cos_tx)
        np.sin(phase_tx, out=sin_tx)
        zr, zi = prod[:, :n_tx], prod[:, n_tx:]
        re = np.einsum("nt,nt->n", zr, cos_tx) - np.einsum("nt,nt->n", zi, sin_tx)
        im = np.einsum("nt,nt->n", zr, sin_tx) + np.einsum("nt,nt->n", zi, cos_tx)
        common = phasor_mod_2pi(norm_m * (2.0 * k / (2.0 * np.pi)))
        out[i].real = re
        out[i].imag = im
        out[i] *= common


def correlate_numpy(signal: np.ndarray, freqs_hz: np.ndarray, tx_m: np.ndarray, rx_m: np.ndarray,
                    points_m: np.ndarray) -> np.ndarray:
    """Per-frequency correlation, complex64 (F, N), normalised by n_rx * n_tx. Threads over point chunks."""
    freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
    n_rx, n_tx = len(rx_m), len(tx_m)
    scale = 1.0 / (n_rx * n_tx)
    blocks = [_real_block_matrix(signal[:, :, i] * scale) for i in range(len(freqs_hz))]
    wavenumbers = 2.0 * np.pi * freqs_hz / C_M_PER_S
    out = np.empty((len(freqs_hz), len(points_m)), dtype=np.complex64)
    n_threads = correlation_threads()
    starts = chunk_starts(len(points_m), n_threads)

    def work(start: int) -> None:
        stop = min(start + starts.step, len(points_m))
        chunk_out = np.empty((len(freqs_hz), stop - start), dtype=np.complex64)
        _correlate_chunk(blocks, wavenumbers, tx_m, rx_m, points_m[start:stop], chunk_out)
        out[:, start:stop] = chunk_out

    if n_threads == 1 or len(starts) == 1:
        for s in starts:
            work(s)
    elif len(points_m) < MIN_PARALLEL_POINTS:
        with _blas_controller().limit(limits=1, user_api="blas"):    # (BLAS threads spin on a few dozen rows)
            for s in starts:
                work(s)
    else:
        # each worker runs single-threaded BLAS products: BLAS threads on top of ours oversubscribe the cores
        # (measured 0.37 s instead of 0.19 s for 301x301 points x 2 frequencies on 2 cores)
        with _blas_controller().limit(limits=1, user_api="blas"):
            list(_pool(n_threads).map(work, starts))
    return out


class NumpyBackend(Backend):
    """The CPU default ("cpu"): `correlate_numpy` on worker threads; volumes plane by plane; priors on the host."""

    name = "cpu"
    host_range_search = True

    def correlate(self, signal, freqs_hz, tx_m, rx_m, points_m) -> np.ndarray:
        signal, freqs_hz, tx_m, rx_m = check_inputs(signal, freqs_hz, tx_m, rx_m)
        return correlate_numpy(signal, freqs_hz, tx_m, rx_m, np.asarray(points_m, dtype=np.float64).reshape(-1, 3))

    def correlate_summed(self, signal, freqs_hz, tx_m, rx_m, points_m) -> np.ndarray:
        return self.correlate(signal, freqs_hz, tx_m, rx_m, points_m).sum(axis=0)

    def volume(self, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, method: str = "auto") -> np.ndarray:
        if method not in ("auto", "direct", "range"):
            raise ValueError(f"method must be 'auto', 'direct' or 'range', got {method!r}")
        if method == "range":
            raise ValueError("range compression runs on Warp devices ('cuda', 'warp-cpu'), not on device='cpu'")
        signal, freqs_hz, tx_m, rx_m = check_inputs(signal, freqs_hz, tx_m, rx_m)
        x_m, y_m, z_m = grid_vectors(x_m, y_m, z_m)
        out = np.empty((len(z_m), len(y_m), len(x_m)), dtype=np.complex64)
        yy, xx = np.meshgrid(y_m, x_m, indexing="ij")
        for iz, z in enumerate(z_m):
            plane_m = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)], axis=1)
            out[iz] = self.correlate_summed(signal, freqs_hz, tx_m, rx_m, plane_m).reshape(xx.shape)
        return out

    def volume_peak(self, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, dz_m: float, timer=None):
        timer = timer or StageTimer()
        with timer.stage("correlate"):
            volume = self.volume(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m)
        with timer.stage("depth"):
            return peak_depth_m(np.abs(volume), float(np.asarray(z_m, dtype=np.float64)[0]), dz_m)
