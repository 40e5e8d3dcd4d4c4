"""Warp correlation kernels, run on CUDA ("cuda") or on Warp's single-threaded CPU device ("warp-cpu").

Kernels (one thread per point or voxel; points come from an (N, 3) array or from an x/y/z grid):
* `_direct_kernel`: the plain direct sum, one sincos per antenna pair and frequency (the comparison baseline).
* `_separable_kernel`: T + R sincos per point and frequency, then `a^T S b` as complex multiply-adds.
* `_profile_kernel` + `_range_kernel`: range-compressed back-projection (see methods/range_compression.py).
Phases use the same cancellation-free split as the numpy backend: |p - q| = |p| + e(p, q) with e in float32 and the
common phase 2 k |p| in float64, reduced mod 2 pi.
"""
from __future__ import annotations

import functools

import numpy as np
import warp as wp

from methods import range_compression

C_M_PER_S = 299_792_458.0
MAX_ANTENNAS = 96
TX_CHUNK = wp.constant(32)          # Tx steering values a thread keeps in registers at a time
vec_ant = wp.types.vector(length=MAX_ANTENNAS, dtype=wp.float32)
vec_chunk = wp.types.vector(length=32, dtype=wp.float32)
wp.set_module_options({"max_unroll": 32})


@functools.cache
def _init() -> None:
    wp.config.log_level = wp.LOG_WARNING
    wp.init()


def cuda_available() -> bool:
    """True when Warp sees a CUDA device."""
    _init()
    return wp.get_cuda_device_count() > 0


def _wp_device(device: str) -> str:
    _init()
    return "cpu" if device == "warp-cpu" else "cuda:0"


@wp.func
def _point(i: int, grid: int, points: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.float64),
           y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64)):
    if grid == 0:
        return points[i]
    nx = x.shape[0]
    ny = y.shape[0]
    return wp.vec3d(x[i % nx], y[(i // nx) % ny], z[i // (nx * ny)])


@wp.func
def _excess_m(p: wp.vec3f, norm_m: wp.float32, q: wp.vec3f) -> wp.float32:
    """|p - q| - |p| without cancellation, metres."""
    num = wp.dot(q, q) - 2.0 * wp.dot(p, q)
    return num / (wp.sqrt(wp.max(norm_m * norm_m + num, 0.0)) + norm_m)


@wp.func
def _phasor_cycles(cycles: wp.float64) -> wp.vec2f:
    """exp(j 2 pi cycles) as (re, im), reduced in float64 before float32."""
    frac = wp.float32(cycles - wp.round(cycles)) * wp.float32(2.0 * wp.pi)
    return wp.vec2f(wp.cos(frac), wp.sin(frac))


@wp.func
def _cmul(a: wp.vec2f, b: wp.vec2f) -> wp.vec2f:
    return wp.vec2f(a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


@wp.kernel
def _direct_kernel(grid: int, points: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.float64),
                   y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64),
                   rx: wp.array(dtype=wp.vec3f), tx: wp.array(dtype=wp.vec3f),
                   k_rad_per_m: wp.array(dtype=wp.float32), signal: wp.array3d(dtype=wp.vec2f),
                   sum_freqs: int, out: wp.array2d(dtype=wp.vec2f)):
    """Plain float32 direct sum: phase k (|p - rx| + |p - tx|) and one sincos per pair and frequency."""
    i = wp.tid()
    p = wp.vec3f(_point(i, grid, points, x, y, z))
    total = wp.vec2f(0.0, 0.0)
    for f in range(signal.shape[0]):
        acc = wp.vec2f(0.0, 0.0)
        for r in range(rx.shape[0]):
            d_rx = wp.length(p - rx[r])
            for t in range(tx.shape[0]):
                phase = k_rad_per_m[f] * (d_rx + wp.length(p - tx[t]))
                acc += _cmul(signal[f, r, t], wp.vec2f(wp.cos(phase), wp.sin(phase)))
        if sum_freqs == 0:
            out[f, i] = acc
        total += acc
    if sum_freqs != 0:
        out[0, i] = total


@wp.kernel
def _separable_kernel(grid: int, points: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.float64),
                      y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64),
                      rx: wp.array(dtype=wp.vec3f), tx: wp.array(dtype=wp.vec3f),
                      k_rad_per_m: wp.array(dtype=wp.float32), cycles_per_m: wp.array(dtype=wp.float64),
                      signal: wp.array3d(dtype=wp.vec2f), sum_freqs: int, out: wp.array2d(dtype=wp.vec2f)):
    """Separable sum a^T S b: R + T sincos per point and frequency, R*T complex multiply-adds.

    The Tx axis (padded to a multiple of TX_CHUNK with zero signal) is walked in chunks whose steering values
    stay in registers (unrolled loop); the Rx steering vector is kept in a thread-local array.
    """
    i = wp.tid()
    p64 = _point(i, grid, points, x, y, z)
    norm64 = wp.length(p64)
    p = wp.vec3f(p64)
    norm = wp.float32(norm64)
    a_re = vec_ant()
    a_im = vec_ant()
    total = wp.vec2f(0.0, 0.0)
    for f in range(signal.shape[0]):
        k = k_rad_per_m[f]
        for r in range(rx.shape[0]):
            phase = k * _excess_m(p, norm, rx[r])
            a_re[r] = wp.cos(phase)
            a_im[r] = wp.sin(phase)
        acc = wp.vec2f(0.0, 0.0)
        for chunk in range(signal.shape[2] // TX_CHUNK):
            t0 = chunk * TX_CHUNK
            b_re = vec_chunk()
            b_im = vec_chunk()
            for j in range(TX_CHUNK):
                phase = k * _excess_m(p, norm, tx[t0 + j])
                b_re[j] = wp.cos(phase)
                b_im[j] = wp.sin(phase)
            for r in range(rx.shape[0]):
                sb = wp.vec2f(0.0, 0.0)
                for j in range(TX_CHUNK):
                    sb += _cmul(signal[f, r, t0 + j], wp.vec2f(b_re[j], b_im[j]))
                acc += _cmul(wp.vec2f(a_re[r], a_im[r]), sb)
        val = _cmul(acc, _phasor_cycles(norm64 * cycles_per_m[f]))
        if sum_freqs == 0:
            out[f, i] = val
        total += val
    if sum_freqs != 0:
        out[0, i] = total


@wp.kernel
def _profile_kernel(signal: wp.array2d(dtype=wp.vec2f), grid_index: wp.array(dtype=wp.int32),
                    twiddle: wp.array(dtype=wp.vec2f), shift: wp.array(dtype=wp.vec2f),
                    profiles: wp.array2d(dtype=wp.vec2f)):
    """profiles[pair, m] = shift[m] sum_n signal[pair, n] twiddle[(i_n m) mod L]; column L repeats column 0."""
    pair, m = wp.tid()
    n_samples = twiddle.shape[0]
    acc = wp.vec2f(0.0, 0.0)
    for n in range(signal.shape[1]):
        acc += _cmul(signal[pair, n], twiddle[(grid_index[n] * m) % n_samples])
    val = _cmul(shift[m], acc)
    profiles[pair, m] = val
    if m == 0:
        profiles[pair, n_samples] = val


@wp.kernel
def _range_kernel(points: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64),
                  z: wp.array(dtype=wp.float64),
                  rx: wp.array(dtype=wp.vec3f), tx: wp.array(dtype=wp.vec3f), k_carrier: wp.float32,
                  carrier_cycles_per_m: wp.float64, samples_per_m: wp.float32,
                  profiles: wp.array2d(dtype=wp.vec2f), out: wp.array2d(dtype=wp.vec2f)):
    """Voxel value: sum over pairs of carrier phasor times the linearly interpolated range profile."""
    i = wp.tid()
    p64 = _point(i, 1, points, x, y, z)
    norm64 = wp.length(p64)
    p = wp.vec3f(p64)
    norm = wp.float32(norm64)
    n_tx = tx.shape[0]
    n_samples = wp.float32(profiles.shape[1] - 1)
    e_tx = vec_ant()
    b_re = vec_ant()
    b_im = vec_ant()
    for t in range(n_tx):
        e_tx[t] = _excess_m(p, norm, tx[t])
        b_re[t] = wp.cos(k_carrier * e_tx[t])
        b_im[t] = wp.sin(k_carrier * e_tx[t])
    acc = wp.vec2f(0.0, 0.0)
    for r in range(rx.shape[0]):
        e_rx = _excess_m(p, norm, rx[r])
        base = (2.0 * norm + e_rx) * samples_per_m
        gb = wp.vec2f(0.0, 0.0)
        for t in range(n_tx):
            u = base + e_tx[t] * samples_per_m
            u = u - n_samples * wp.floor(u / n_samples)
            iu = wp.min(wp.int32(u), wp.int32(n_samples) - 1)
            w = u - wp.float32(iu)
            g0 = profiles[r * n_tx + t, iu]
            g = g0 + w * (profiles[r * n_tx + t, iu + 1] - g0)
            gb += _cmul(g, wp.vec2f(b_re[t], b_im[t]))
        phase = k_carrier * e_rx
        acc += _cmul(wp.vec2f(wp.cos(phase), wp.sin(phase)), gb)
    out[0, i] = _cmul(acc, _phasor_cycles(norm64 * carrier_cycles_per_m))


def _vec2(a: np.ndarray) -> np.ndarray:
    """complex array -> float32 (..., 2) for wp.vec2f arrays."""
    return np.stack([a.real, a.imag], axis=-1).astype(np.float32)


class _Inputs:
    """Device copies of the antenna positions, wavenumbers and normalised signal (F, R, T)."""

    def __init__(self, signal, freqs_hz, tx_m, rx_m, device: str):
        if len(tx_m) > MAX_ANTENNAS or len(rx_m) > MAX_ANTENNAS:
            raise ValueError(f"Warp kernels hold at most {MAX_ANTENNAS} antennas per side")
        self.device = _wp_device(device)
        scale = 1.0 / (len(rx_m) * len(tx_m))
        self.tx = wp.array(tx_m.astype(np.float32), dtype=wp.vec3f, device=self.device)
        self.rx = wp.array(rx_m.astype(np.float32), dtype=wp.vec3f, device=self.device)
        self.k = wp.array((2 * np.pi * freqs_hz / C_M_PER_S).astype(np.float32), dtype=wp.float32, device=self.device)
        self.cycles = wp.array(2.0 * freqs_hz / C_M_PER_S, dtype=wp.float64, device=self.device)
        sig = np.ascontiguousarray(np.moveaxis(signal, 2, 0)) * scale
        self.signal = wp.array(_vec2(sig), dtype=wp.vec2f, device=self.device)
        n_pad = -len(tx_m) % int(TX_CHUNK)
        self.signal_padded = wp.array(_vec2(np.pad(sig, ((0, 0), (0, 0), (0, n_pad)))), dtype=wp.vec2f,
                                      device=self.device)
        self.tx_padded = wp.array(np.pad(tx_m, ((0, n_pad), (0, 0)), mode="edge").astype(np.float32),
                                  dtype=wp.vec3f, device=self.device)
        self.n_freqs = len(freqs_hz)


def _range_launch(inputs: _Inputs, freqs_hz, points, x, y, z, out):
    """Upload the DFT tables once; return a function that builds the range profiles and gathers every voxel."""
    rplan = range_compression.plan(freqs_hz)
    if rplan is None:
        raise ValueError("range compression needs >= 2 distinct frequencies on an equidistant grid "
                         f"with df < c / {range_compression.MAX_PATH_M} m")
    dev = inputs.device
    n_freqs, n_rx, n_tx = inputs.signal.shape
    sig_pairs = inputs.signal.numpy().reshape(n_freqs, n_rx * n_tx, 2).transpose(1, 0, 2)
    sig = wp.array(np.ascontiguousarray(sig_pairs), dtype=wp.vec2f, device=dev)
    m = np.arange(rplan.n_samples)
    twiddle = wp.array(_vec2(np.exp(2j * np.pi * m / rplan.n_samples)), dtype=wp.vec2f, device=dev)
    shift = wp.array(_vec2(range_compression.profile_shift(rplan)), dtype=wp.vec2f, device=dev)
    index = wp.array(rplan.grid_index.astype(np.int32), dtype=wp.int32, device=dev)
    profiles = wp.empty((n_rx * n_tx, rplan.n_samples + 1), dtype=wp.vec2f, device=dev)
    k_c = 2 * np.pi * rplan.f_carrier_hz / C_M_PER_S
    gather_args = [points, x, y, z, inputs.rx, inputs.tx, float(k_c), 2.0 * rplan.f_carrier_hz / C_M_PER_S,
                   float(rplan.samples_per_m), profiles, out]

    def run():
        wp.launch(_profile_kernel, dim=(n_rx * n_tx, rplan.n_samples), inputs=[sig, index, twiddle, shift, profiles],
                  device=dev)
        wp.launch(_range_kernel, dim=out.shape[1], inputs=gather_args, device=dev)
        return out
    return run


def make_launch(signal, freqs_hz, tx_m, rx_m, *, device: str, kernel: str, points_m=None, grid_m=None,
                sum_freqs: bool = False):
    """Upload inputs once; return a function that runs `kernel` and returns the device output (rows, N) vec2f.

    kernel: "separable", "direct" or "range" (grid only; the range profiles are rebuilt on every call, as a new
    frame needs). Points come from `points_m` (N, 3) or from `grid_m` = (x_m, y_m, z_m); with a grid the output
    is summed over frequencies, flat in (z, y, x) order. The benchmark times the returned function.
    """
    inputs = _Inputs(signal, freqs_hz, tx_m, rx_m, device)
    dev = inputs.device
    empty = wp.empty(0, dtype=wp.float64, device=dev)
    if grid_m is None:
        points, x, y, z, flag = wp.array(points_m, dtype=wp.vec3d, device=dev), empty, empty, empty, 0
    else:
        points, flag, sum_freqs = wp.empty(0, dtype=wp.vec3d, device=dev), 1, True
        x, y, z = (wp.array(v, dtype=wp.float64, device=dev) for v in grid_m)
    n_out = len(points_m) if grid_m is None else x.shape[0] * y.shape[0] * z.shape[0]
    out = wp.empty((1 if sum_freqs else inputs.n_freqs, n_out), dtype=wp.vec2f, device=dev)
    if kernel == "range" and grid_m is not None:
        return _range_launch(inputs, freqs_hz, points, x, y, z, out)
    if kernel == "direct":
        fn, args = _direct_kernel, [flag, points, x, y, z, inputs.rx, inputs.tx, inputs.k, inputs.signal]
    elif kernel == "separable":
        fn, args = _separable_kernel, [flag, points, x, y, z, inputs.rx, inputs.tx_padded, inputs.k, inputs.cycles,
                                       inputs.signal_padded]
    else:
        raise ValueError(f"unknown kernel {kernel!r} (range compression needs a grid)")
    args += [int(sum_freqs), out]

    def run():
        wp.launch(fn, dim=n_out, inputs=args, device=dev)
        return out
    return run


def _to_complex(out: wp.array) -> np.ndarray:
    a = out.numpy()
    return (a[..., 0] + 1j * a[..., 1]).astype(np.complex64)


def correlate_warp(signal, freqs_hz, tx_m, rx_m, points_m, *, device: str, kernel: str = "separable",
                   sum_freqs: bool = False) -> np.ndarray:
    """Correlation at points (N, 3) with a Warp kernel ("separable" or "direct"): complex64 (F, N) or (N,)."""
    run = make_launch(signal, freqs_hz, tx_m, rx_m, device=device, kernel=kernel, points_m=points_m,
                      sum_freqs=sum_freqs)
    res = _to_complex(run())
    return res[0] if sum_freqs else res


def volume_warp(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, *, device: str, kernel: str = "separable"):
    """Frequency-summed correlation on the grid, complex64 (nz, ny, nx); kernel "separable", "direct" or "range"."""
    run = make_launch(signal, freqs_hz, tx_m, rx_m, device=device, kernel=kernel, grid_m=(x_m, y_m, z_m))
    return _to_complex(run())[0].reshape(len(z_m), len(y_m), len(x_m))
