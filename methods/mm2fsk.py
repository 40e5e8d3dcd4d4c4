"""MM-2FSK (paper section II-B): 2FSK with a per-pixel depth prior from an optical sensor, one pass.

Only pixels that have a prior (finite in `prior_depth_m`, see `methods.prior.priors`) are correlated, each at its own
prior depth; depth = prior - c angle(c2 conj(c1)) / (4 pi (f2 - f1)). Pixels without a prior stay NaN. The filter
quantity is the magnitude of the mean residual phasor over pairs and both frequencies (with
`filter_quantity='first'`, the reference's: the first frequency's), thresholded relative to the maximum over the
correlated pixels.

Region of interest (methods.skips.roi): only pixels with a prior inside the ROI are correlated, and depths outside its
depth interval are invalid; the prior's footprint is itself the ROI this method always had.
"""
from __future__ import annotations

import numpy as np

from methods.backends import backend_for
from methods.backends.base import Backend
from methods.domain.antennas import AntennaArray
from methods.domain.capture import RadarGrid
from methods.domain.samples import FrameSamples
from methods.fsk import FILTER_QUANTITIES, correlate_pixels, depth_correction_m, filter_magnitude, roi_depth_m
from methods.method import Frame, Method
from methods.ops.filtering import DEFAULT_THRESHOLD_DB, filter_depth
from methods.ops.timing import StageTimer
from methods.prior.image import HostPrior, Prior
from methods.reconstruction import Reconstruction
from methods.skips.roi import Roi


def reconstruct_mm2fsk(signal: np.ndarray | FrameSamples, freqs_hz: np.ndarray, antennas: AntennaArray, grid: RadarGrid,
                       prior: Prior | np.ndarray, *, threshold_db: float | None = DEFAULT_THRESHOLD_DB,
                       backend: Backend | str = "cpu", timer: StageTimer | None = None, roi: Roi | None = None,
                       filter_quantity: str = "mean") -> Reconstruction:
    """MM-2FSK depth map (ny, nx) from a two-frequency `signal` (n_rx, n_tx, 2) and a prior (ny, nx) on `grid`
    (a `Prior` or an image in metres, NaN = no prior), metres. `signal` may be a FrameSamples (a frame's samples at
    the two frequencies), which the device's frame graph gathers itself.

    Pass the `timer` that already timed the prior so that `total` includes it. `roi` (None = the whole grid)
    bounds the pixels correlated and the depths kept. A device-resident prior stays on its backend's device unless
    the ROI cuts pixels and the prior cannot restrict them itself (`Prior.takes_roi`: the frame graph can; else the
    host path restricts them) or the filter quantity is not the default 'mean' (`fsk.filter_magnitude`; the device
    kernels compute that one).
    """
    if filter_quantity not in FILTER_QUANTITIES:
        raise ValueError(f"unknown filter_quantity {filter_quantity!r}; choose one of {', '.join(FILTER_QUANTITIES)}")
    if len(freqs_hz) != 2:
        raise ValueError(f"MM-2FSK needs exactly two frequencies, got {len(freqs_hz)}")
    if not isinstance(prior, Prior):
        prior = HostPrior(np.asarray(prior, dtype=np.float64), grid)
    if prior.shape != grid.image_shape:
        raise ValueError(f"prior shape {prior.shape} does not match the radar image {grid.image_shape}")
    backend = backend_for(backend)
    roi_cut = roi is not None and not roi.pixels.all()
    if roi is not None and not roi_cut and np.isinf(roi.z_min_m) and np.isinf(roi.z_max_m):
        roi = None                                   # the whole grid: nothing to restrict
    timer = timer or StageTimer()
    sources = (() if roi is None else roi.sources) + ("prior",)
    if prior.device_resident and (not roi_cut or prior.takes_roi) and filter_quantity == "mean":
        depth_m, magnitude, prior_m = backend.depth_at_prior(signal, freqs_hz, antennas.tx_m, antennas.rx_m, grid,
                                                             prior, threshold_db, timer,
                                                             roi.pixels if roi_cut else None)
        if roi is not None:                          # the ROI's depth interval: drop depths outside it
            depth_m = roi_depth_m(depth_m, roi)
        used = prior.n_used if roi_cut else prior.n_covered
        return Reconstruction(depth_m=depth_m, magnitude=magnitude, freqs_hz=np.asarray(freqs_hz),
                              timings_ms=timer.finish(), grid=grid, method="mm2fsk",
                              extra={"prior_depth_m": prior_m, "prior_pixels": used, "roi_px": used,
                                     "roi_sources": sources})
    signal = np.asarray(signal)
    prior_depth_m = prior.host_m()
    has_prior = np.isfinite(prior_depth_m) if roi is None else np.isfinite(prior_depth_m) & roi.pixels
    x_m, y_m = grid.pixel_xy_m()
    prior_m = prior_depth_m[has_prior]
    with timer.stage("correlate"):
        phasors = correlate_pixels(signal, freqs_hz, antennas, x_m[has_prior], y_m[has_prior], prior_m, backend)
    with timer.stage("depth"):
        depth_m = np.full(grid.image_shape, np.nan)
        depth_m[has_prior] = prior_m - depth_correction_m(phasors[0], phasors[1], *freqs_hz)
    with timer.stage("filter"):
        magnitude = np.full(grid.image_shape, np.nan)
        magnitude[has_prior] = filter_magnitude(phasors, filter_quantity)
        depth_m = filter_depth(depth_m, magnitude, threshold_db)
        if roi is not None:
            depth_m = roi_depth_m(depth_m, roi)
    return Reconstruction(depth_m=depth_m, magnitude=magnitude, freqs_hz=np.asarray(freqs_hz),
                          timings_ms=timer.finish(), grid=grid, method="mm2fsk",
                          extra={"prior_depth_m": prior_depth_m, "prior_pixels": int(has_prior.sum()),
                                 "roi_px": int(has_prior.sum()), "roi_sources": sources})


class MM2FSK(Method):
    """MM-2FSK with a per-pixel sensor prior (module doc)."""

    name = "mm2fsk"
    label = "MM-2FSK"
    n_freqs = 2
    priors = ("realsense", "photogrammetry")
    device_prior = True
    params = {"filter_quantity": "mean"}     # 'first': the reference code's filter (profile=faithful)

    def run(self, frame: Frame, prior: Prior, backend: Backend, timer: StageTimer) -> Reconstruction:
        return reconstruct_mm2fsk(frame.samples, frame.freqs_hz, frame.antennas, frame.grid, prior,
                                  threshold_db=frame.threshold_db, backend=backend, timer=timer, roi=frame.roi,
                                  filter_quantity=self.values["filter_quantity"])
