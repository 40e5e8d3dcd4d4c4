"""The Backend interface every correlation backend implements, and the input checks they share.

A backend offers:

* `correlate(signal, freqs_hz, tx_m, rx_m, points_m)` -> complex64 (F, N) back-projection phasors at points, and
  `correlate_summed(...)` -> (N,) summed over frequencies where the data lives;
* `volume(...)` -> complex64 (nz, ny, nx) frequency-summed on a grid, and `volume_peak(...)` -> BP's (depth, max
  projection) maps with the volume kept where it was computed;
* `realsense_prior(...)` / `mesh_prior(...)` -> a `methods.prior.image.Prior`, on the device when asked and
  possible, and `depth_at_prior(...)` for a device-resident one;
* `warm_up(...)`: compile what a timed run will need.

C[f, p] = sum_{r,t} S[r,t,f] exp(+j 2 pi f (|p - rx_r| + |p - tx_t|) / c) / (n_rx n_tx); `methods.ops.correlate`
holds the float64 reference every backend is tested against.
"""
from __future__ import annotations

from contextlib import AbstractContextManager, nullcontext

import numpy as np

from methods.domain.capture import DepthFrame, Mesh, RadarGrid
from methods.prior.image import HostPrior, Prior
from methods.prior.priors import DEFAULT_FILL, mesh_prior_m, realsense_prior_m


def check_inputs(signal, freqs_hz, tx_m, rx_m):
    """Validated (signal complex64 or complex128 (n_rx, n_tx, F), freqs_hz float64 (F,), tx_m, rx_m float64 (., 3))."""
    signal = np.asarray(signal)
    freqs_hz = np.atleast_1d(np.asarray(freqs_hz, dtype=np.float64))
    tx_m = np.asarray(tx_m, dtype=np.float64).reshape(-1, 3)
    rx_m = np.asarray(rx_m, dtype=np.float64).reshape(-1, 3)
    if signal.ndim == 2 and len(freqs_hz) == 1:
        signal = signal[:, :, None]
    if signal.shape != (len(rx_m), len(tx_m), len(freqs_hz)):
        raise ValueError(f"signal must have shape (n_rx, n_tx, F) = ({len(rx_m)}, {len(tx_m)}, {len(freqs_hz)}), "
                         f"got {signal.shape}")
    # copy=False: a complex64 frame passes as it is (a BP_max search calls this ~10 times per frame: 9 MB each)
    return (signal.astype(np.complex64 if signal.dtype != np.complex128 else np.complex128, copy=False), freqs_hz,
            tx_m, rx_m)


def grid_vectors(x_m, y_m, z_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three coordinate vectors of a grid as float64 (n,) arrays."""
    return tuple(np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (x_m, y_m, z_m))


class Backend:
    """What every backend offers (module doc). `name` is the device recorded in results rows."""

    name: str
    #: BP's CPU range-compressed depth search (methods.backends.cpu_range) is this backend's fast path for many
    # frequencies
    host_range_search = False
    #: BP over a region of interest computes the rectangular volume of its bounding box (else the point search)
    prefers_box_volume = False
    #: `volume_peak` takes `z_step` (a coarse volume and a window around each pixel's maximum: `bp_dense_z_search`)
    searches_volume_z = False
    #: dense kernels beat the host-driven searches for few frequencies (the `roi=auto` defaults, methods.skips.settings)
    dense_beats_search = False
    #: 2FSK and 3FSK run their passes where the data lives (`fsk_two_pass`, `fsk_three`): one copy back
    device_fsk = False
    #: with `device_fsk`: the `fsk_keep` skip also runs on the device (`keep` of fsk_two_pass / fsk_three)
    keeps_on_device = False

    def checks_samples(self, samples) -> bool:
        """Whether this backend checks `samples` (a methods.domain.samples.FrameSamples, or an array (n_rx, n_tx, F))
        for NaN/Inf itself where it stages them (raising `NonFiniteSignal`), so that the caller need not; then
        `samples_checked` says after the run whether it did."""
        return False

    def samples_checked(self, samples) -> bool:
        """Whether these very samples were checked (and found finite) by this backend."""
        return False

    def correlate(self, signal, freqs_hz, tx_m, rx_m, points_m) -> np.ndarray:
        """complex64 (F, N) phasors at points_m (N, 3), radar space, metres."""
        raise NotImplementedError

    def correlate_summed(self, signal, freqs_hz, tx_m, rx_m, points_m) -> np.ndarray:
        """complex64 (N,) phasors summed over frequencies."""
        raise NotImplementedError

    def summed_at_points(self, signal, freqs_hz, tx_m, rx_m):
        """Function points_m (N, 3) -> `correlate_summed` there, for many calls on one frame (BP's depth search):
        a backend may prepare the frame's inputs once."""
        return lambda points_m: self.correlate_summed(signal, freqs_hz, tx_m, rx_m, points_m)

    def search_depth(self, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, plan, threshold_db, z_edges_are_grid_edges,
                     hull_m=None):
        """BP's coarse-to-fine search (`methods.skips.bp_search.search_depth`, `plan` its SearchPlan) where the data
        lives: (depth_m, max projection, samples evaluated), or None where this backend leaves it to the host.
        `hull_m` (K, 3): points whose box holds every point a frame's calls search (tables built once per frame)."""
        return None

    def coarse_peaks(self, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, step, hull_m=None):
        """The coarse ROI's pass where the data lives: per pixel (x_m, y_m) the maximum of |V| over every step-th
        depth of z_m and the last, the first depth index holding it, and the samples evaluated; or None (host)."""
        return None

    def volume(self, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, method: str = "auto") -> np.ndarray:
        """complex64 (nz, ny, nx) frequency-summed phasors on the grid (axes in the order the vectors are given)."""
        raise NotImplementedError

    def volume_peak(self, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, dz_m: float, timer=None
                    ) -> tuple[np.ndarray, np.ndarray]:
        """BP's (depth_m, max projection), each float64 (ny, nx), over z_m (equidistant, step dz_m); `timer` gets
        the stages "correlate" and "depth"."""
        raise NotImplementedError

    def realsense_prior(self, depth: DepthFrame, realsense2radar: np.ndarray, grid: RadarGrid,
                        keep_on_device: bool = False, fill: str = DEFAULT_FILL) -> Prior:
        """`methods.prior.priors.realsense_prior_m` as a Prior (on the device with `keep_on_device` where possible)."""
        return HostPrior(realsense_prior_m(depth, realsense2radar, grid, fill=fill), grid)

    def mesh_prior(self, mesh: Mesh, photogrammetry2radar: np.ndarray, grid: RadarGrid,
                   keep_on_device: bool = False, fill: str = DEFAULT_FILL) -> Prior:
        """`methods.prior.priors.mesh_prior_m` as a Prior (on the device with `keep_on_device` where possible)."""
        return HostPrior(mesh_prior_m(mesh, photogrammetry2radar, grid, fill=fill), grid)

    def fsk_two_pass(self, signal, freqs_hz, tx_m, rx_m, grid: RadarGrid, pixels: np.ndarray, prior_m: float,
                     threshold_db: float | None, filter_quantity: str, timer, keep: tuple | None = None):
        """2FSK over the True `pixels` (ny, nx) where the data lives: (depth_m, magnitude) (ny, nx) filtered, and
        the details (reference_pixel, z1_m; with `keep`, `fsk.keep_rule`'s tuple on a `keeps_on_device` backend, also
        evaluated_px) (`device_fsk` backends)."""
        raise NotImplementedError(f"{type(self).__name__} runs 2FSK on the host")

    def fsk_three(self, signal, freqs_hz, tx_m, rx_m, grid: RadarGrid, pixels: np.ndarray, coarse: list[int],
                  prior_m: float, threshold_db: float | None, timer, keep: tuple | None = None):
        """3FSK over the True `pixels` where the data lives, `coarse` the indices of the coarse pair: (depth_m,
        magnitude, coarse_depth_m) (ny, nx) and the details (`device_fsk` backends)."""
        raise NotImplementedError(f"{type(self).__name__} runs 3FSK on the host")

    def depth_at_prior(self, signal, freqs_hz, tx_m, rx_m, grid: RadarGrid, prior: Prior,
                       threshold_db: float | None, timer, roi_pixels: np.ndarray | None = None
                       ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Two-frequency depth at a device-resident prior, where it lives: (depth_m, magnitude, prior_m) (ny, nx);
        `roi_pixels` (ny, nx) bool restricts the correlated pixels where `prior.takes_roi`."""
        raise NotImplementedError(f"{type(self).__name__} holds no device-resident priors")

    def mm3fsk_at_prior(self, signal, freqs_hz, tx_m, rx_m, grid: RadarGrid, prior: Prior, coarse: list[int],
                        threshold_db: float | None, timer, roi_pixels: np.ndarray | None = None):
        """MM-3FSK (`methods.mm3fsk`, `coarse` the coarse pair's indices) at a device-resident prior where it lives:
        ((depth_m, magnitude, prior_m) (ny, nx), prior offset m), the correlated pixels restricted to `roi_pixels`
        (ny, nx) bool; or None where this backend leaves it to the host."""
        return None

    def holding_frame(self, signal: np.ndarray) -> AbstractContextManager:
        """A block within which the caller's `signal` array stays unchanged, so a backend that caches frames by
        content may find it by identity (nothing to do where nothing is cached)."""
        return nullcontext()

    def warm_up(self, signal, freqs_hz, tx_m, rx_m, *, volume: bool, prior: bool) -> None:
        """Compile what a timed run will need (nothing to compile on the numpy backend)."""
