"""The one correlation API used by every method (DESIGN.md section 5).

For radar-space points p and frequencies f the back-projection phasor is

    C[f, p] = sum_{r, t} S[r, t, f] * exp(+j 2 pi f (|p - rx_r| + |p - tx_t|) / c) / (n_rx * n_tx)

with `S[rx, tx, f]` the calibrated frame (signal model `S ~ exp(-j 2 pi f tau)`). `sum_freqs=True` returns the
coherent sum over f. This module holds the float64 direct-sum reference; fast paths live beside it and are tested
against it.
"""
from __future__ import annotations

import numpy as np

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


DEVICES = ("cpu", "cuda", "auto", "warp-cpu")


class DeviceUnavailableError(RuntimeError):
    """A device was asked for that this machine cannot run (e.g. "cuda" where Warp sees no GPU).

    Command lines turn it into one line naming their own option (bench.cli.resolve_device)."""

    def __init__(self, device: str, problem: str):
        self.device, self.problem = device, problem
        super().__init__(f"device={device!r} was asked for, but {problem}")


def resolve_device(device: str) -> str:
    """Map a requested device to the one used: "cpu" (numpy + BLAS), "cuda" (Warp), "warp-cpu" (Warp on the CPU).

    "auto" gives "cuda" when Warp sees a CUDA device, else "cpu". "cuda" without a CUDA device raises
    DeviceUnavailableError (a RuntimeError); an unknown name raises ValueError.
    """
    if device not in DEVICES:
        raise ValueError(f"device must be one of {DEVICES}, got {device!r}")
    if device == "cpu" or device == "warp-cpu":
        return device
    from methods import backend_warp  # Warp is imported only when a Warp device is asked for
    has_cuda = backend_warp.cuda_available()
    if device == "auto":
        return "cuda" if has_cuda else "cpu"
    if not has_cuda:
        raise DeviceUnavailableError(device, "Warp sees no CUDA device")
    return "cuda"


def _check_inputs(signal, freqs_hz, tx_m, rx_m):
    signal = np.asarray(signal)
    freqs_hz = np.atleast_1d(np.asarray(freqs_hz, dtype=np.float64))
    tx_m = np.asarray(tx_m, dtype=np.float64).reshape(-1, 3)
    rx_m = np.asarray(rx_m, dtype=np.float64).reshape(-1, 3)
    if signal.ndim == 2 and len(freqs_hz) == 1:
        signal = signal[:, :, None]
    if signal.shape != (len(rx_m), len(tx_m), len(freqs_hz)):
        raise ValueError(f"signal must have shape (n_rx, n_tx, F) = ({len(rx_m)}, {len(tx_m)}, {len(freqs_hz)}), "
                         f"got {signal.shape}")
    return signal.astype(np.complex64 if signal.dtype != np.complex128 else np.complex128), freqs_hz, tx_m, rx_m


def correlate(signal, freqs_hz, tx_m, rx_m, points_m, *, sum_freqs: bool = False, device: str = "cpu") -> np.ndarray:
    """Back-projection phasors at points: complex64 (F, N), or (N,) summed over frequencies with `sum_freqs`.

    signal (n_rx, n_tx, F) complex, freqs_hz (F,), tx_m (n_tx, 3), rx_m (n_rx, 3), points_m (N, 3), radar space,
    metres. C[f, p] = sum_{r,t} S[r,t,f] exp(+j 2 pi f (|p - rx_r| + |p - tx_t|) / c) / (n_rx n_tx).
    Precision against `correlate_reference` (relative): CPU and Warp float32 paths ~1e-5 (phases formed
    carefully); the CUDA default multiplies on tensor cores with fp16 inputs and fp32 accumulation, ~3e-4
    (bounded by 1e-3 in the tests; notes/gpu.md explains why that is enough).
    """
    signal, freqs_hz, tx_m, rx_m = _check_inputs(signal, freqs_hz, tx_m, rx_m)
    points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    device = resolve_device(device)
    if device == "cpu":
        from methods.backend_numpy import correlate_numpy
        out = correlate_numpy(signal, freqs_hz, tx_m, rx_m, points_m)
    else:
        from methods import backend_warp
        out = backend_warp.correlate_warp(signal, freqs_hz, tx_m, rx_m, points_m, device=device)
    return out.sum(axis=0) if sum_freqs else out


def correlate_volume(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, *, device: str = "cpu",
                     method: str = "auto") -> np.ndarray:
    """Coherent sum over all frequencies on the grid x_m (nx,), y_m (ny,), z_m (nz,): complex64 (nz, ny, nx).

    Axes follow the order the coordinate vectors are given (pass y descending for row 0 = +y).
    `method`: "direct" (per-frequency separable sum, exact to float32), "range" (range-compressed: per pair an
    oversampled inverse DFT along frequency once, then linear interpolation of the range profiles and one phase
    rotation per voxel; relative error <= RANGE_REL_TOL; needs frequencies on an equidistant grid), or "auto"
    (range compression on Warp devices from RANGE_MIN_FREQS frequencies on, when the grid allows it).
    """
    signal, freqs_hz, tx_m, rx_m = _check_inputs(signal, freqs_hz, tx_m, rx_m)
    x_m, y_m, z_m = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (x_m, y_m, z_m))
    device = resolve_device(device)
    from methods import range_compression
    if method not in ("auto", "direct", "range"):
        raise ValueError(f"method must be 'auto', 'direct' or 'range', got {method!r}")
    if method == "auto":
        method = "range" if range_compression.worth_it(freqs_hz, device) else "direct"
    if device != "cpu":
        from methods import backend_warp
        kernel = "range" if method == "range" else None      # None: the backend's default (tensor cores on CUDA)
        return backend_warp.volume_warp(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, device=device, kernel=kernel)
    if method == "range":
        raise ValueError("range compression runs on Warp devices ('cuda', 'warp-cpu'), not on device='cpu'")
    out = np.empty((len(z_m), len(y_m), len(x_m)), dtype=np.complex64)
    yy, xx = np.meshgrid(y_m, x_m, indexing="ij")
    for iz, z in enumerate(z_m):
        plane_m = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, z)], axis=1)
        out[iz] = correlate(signal, freqs_hz, tx_m, rx_m, plane_m, sum_freqs=True, device=device).reshape(xx.shape)
    return out


def volume_peak_depth(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, *, device: str, timer=None
                      ) -> tuple[np.ndarray, np.ndarray]:
    """`correlate_volume` (method "auto") followed by `methods.bp.peak_depth_m` over z, on a Warp device: the
    volume stays on the device and only (depth_m, max projection), each float64 (ny, nx), come back.
    z_m must be equidistant (the BP grid). `timer` (StageTimer) gets the stages "correlate" and "depth"."""
    signal, freqs_hz, tx_m, rx_m = _check_inputs(signal, freqs_hz, tx_m, rx_m)
    x_m, y_m, z_m = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (x_m, y_m, z_m))
    device = resolve_device(device)
    if device == "cpu":
        raise ValueError("volume_peak_depth runs on Warp devices ('cuda', 'warp-cpu')")
    from methods import backend_warp, range_compression
    kernel = "range" if range_compression.worth_it(freqs_hz, device) else None
    dz_m = float(z_m[1] - z_m[0]) if len(z_m) > 1 else 0.0
    return backend_warp.volume_peak_warp(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, dz_m, device=device,
                                         kernel=kernel, timer=timer)
