"""The correlation backends (DESIGN.md section 5) and the factory that resolves one from the `device` option.

`backend_for(device)` gives a process-wide `Backend` (`base`): `NumpyBackend` ("cpu": complex64 steering vectors
and float32 BLAS, `cpu`, with the range-compressed search in `cpu_range`) or `WarpBackend` ("cuda", "warp-cpu":
`warp/`, owning its device, frame cache and buffer pool). Methods talk to the backend only; no device name is
compared outside this package. `correlate`, `correlate_volume` and `volume_peak_depth` are the same operations by
device name, for scripts and tests.
"""
from __future__ import annotations

import functools

import numpy as np

from methods.backends.base import Backend

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
    from methods.backends.warp.runtime import cuda_available  # Warp is imported only when a Warp device is asked for
    has_cuda = cuda_available()
    if device == "auto":
        return "cuda" if has_cuda else "cpu"
    if not has_cuda:
        raise DeviceUnavailableError(device, "Warp sees no CUDA device")
    return "cuda"


def backend_for(device: str) -> Backend:
    """The process-wide backend of a device name (resolved with `resolve_device`; a `Backend` passes through)."""
    if isinstance(device, Backend):
        return device
    return _backend(resolve_device(device))


@functools.cache
def _backend(name: str) -> Backend:
    if name == "cpu":
        from methods.backends.cpu import NumpyBackend
        return NumpyBackend()
    from methods.backends.warp.backend import WarpBackend
    return WarpBackend(name)


def correlate(signal, freqs_hz, tx_m, rx_m, points_m, *, sum_freqs: bool = False, device: str = "cpu") -> np.ndarray:
    """Back-projection phasors at points: complex64 (F, N), or (N,) summed over frequencies with `sum_freqs`.

    signal (n_rx, n_tx, F) complex, freqs_hz (F,), tx_m (n_tx, 3), rx_m (n_rx, 3), points_m (N, 3), radar space,
    metres. C[f, p] = sum_{r,t} S[r,t,f] exp(+j 2 pi f (|p - rx_r| + |p - tx_t|) / c) / (n_rx n_tx).
    Precision against `correlate_reference` (relative): CPU and Warp float32 paths ~1e-5 (phases formed
    carefully); the CUDA default multiplies on tensor cores with fp16 inputs and fp32 accumulation, ~3e-4
    (bounded by 1e-3 in the tests; docs/measurements/gpu.md explains why that is enough). The sum over frequencies is
    taken on the host here (as the per-frequency output); `Backend.correlate_summed` takes it where the data lives.
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
    """`correlate_volume` (method "auto") followed by `methods.ops.depth_peak.peak_depth_m` over z: (depth_m, max
    projection), each float64 (ny, nx); on a Warp device the volume stays there. z_m must be equidistant (the BP
    grid). `timer` (StageTimer) gets the stages "correlate" and "depth"."""
    z_m = np.atleast_1d(np.asarray(z_m, dtype=np.float64))
    dz_m = float(z_m[1] - z_m[0]) if len(z_m) > 1 else 0.0
    return backend_for(device).volume_peak(signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, dz_m, timer=timer)
