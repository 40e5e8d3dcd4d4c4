"""MM-3FSK (beyond the paper; its discussion proposes it): the per-pixel prior of MM-2FSK with the coarse-to-fine
correction of 3FSK, so that a prior error beyond the fine pair's unambiguous range no longer wraps.

For frequencies f_lo < f_mid < f_hi (d05_d10: 72.00, 81.45, 82.00 GHz), per pixel with a prior d0:

1. Coarse: the neighbouring pair with the smallest difference (f_mid, f_hi: 0.55 GHz for d05_d10) is correlated
   at (x, y, d0); its correction dz = c angle(c_hi conj(c_mid)) / (4 pi df_min) is unambiguous while
   |d - d0| < c / (4 df_min) (13.6 cm for d05_d10, 7.5 cm for d1_d10, 3.7 cm for d2_d10), but noisy: on the
   synthetic catalogue MM-2FSK d05 alone is off by ~3 cm per pixel. A depth camera's calibration error moves the
   whole prior, so the prior is shifted by one offset, the median of the corrections over the pixels the filter
   keeps (the strongest ones), as 2FSK's first pass shifts its scalar guess by its strongest pixel's correction;
   per-pixel coarse noise thus never reaches the fine step.
2. Fine: the three frequencies are correlated again at (x, y, d0 - offset) and the least-squares phase slope over
   frequency (`fsk3.slope_correction_m`, dominated by the 10 GHz span) gives the depth per pixel. It unwraps
   correctly while |d - (d0 - offset)| < c / (4 (f_hi - f_lo)) = 0.75 cm.

MM-2FSK d10 wraps as soon as the prior is off by more than 0.75 cm (a depth-camera calibration error of that
size is common); MM-3FSK keeps d10's precision up to the coarse pair's range. Cost: two correlation passes
(2 + 3 frequencies per pixel) against one (2) for MM-2FSK. What it does not correct: prior errors that
vary across the object by more than 0.75 cm (the offset is one number). The filter quantity is the magnitude of the mean
residual phasor over the pairs and the three frequencies of the fine pass, thresholded relative to the maximum.
Only pixels with a prior (inside the ROI) are correlated; depths outside the ROI's depth interval are invalid.

Where the backend holds a RealSense prior not built yet (Warp on CUDA, fill 'scanline'), the prior, both
correlations, the median offset, the depth and the filter run as one device graph with one copy back
(`Backend.mm3fsk_at_prior`, methods.backends.warp.frame_graph; the offset within 3e-11 m of np.median's); any
other prior runs the passes from the host.
"""
from __future__ import annotations

import numpy as np

from methods.backends.base import Backend
from methods.fsk import correlate_pixels, depth_correction_m, mean_phasor_magnitude, roi_depth_m
from methods.fsk3 import slope_correction_m
from methods.method import Frame, Method
from methods.ops.filtering import filter_depth, keep_mask
from methods.ops.timing import StageTimer
from methods.prior.image import Prior
from methods.reconstruction import Reconstruction


def coarse_pair(freqs_hz: np.ndarray) -> list[int]:
    """Indices of the neighbouring pair with the smallest frequency difference of three ascending frequencies."""
    return list(min([(0, 1), (1, 2)], key=lambda p: freqs_hz[p[1]] - freqs_hz[p[0]]))


def mm3fsk_depth_m(signal: np.ndarray, freqs_hz: np.ndarray, antennas, x_m: np.ndarray, y_m: np.ndarray,
                   prior_m: np.ndarray, backend: Backend, timer: StageTimer, threshold_db: float | None
                   ) -> tuple[np.ndarray, np.ndarray, float]:
    """Depth (N,) m, its fine phasors (3, N) and the prior offset (m) at pixels (x_m, y_m) (N,) with priors
    prior_m (N,), from a three-frequency `signal` (n_rx, n_tx, 3) at ascending `freqs_hz`; the offset is the median
    coarse correction over the pixels `threshold_db` keeps (module doc)."""
    coarse = coarse_pair(freqs_hz)
    with timer.stage("correlate"):
        first = correlate_pixels(signal[:, :, coarse], freqs_hz[coarse], antennas, x_m, y_m, prior_m, backend)
    with timer.stage("depth"):
        correction_m = depth_correction_m(first[0], first[1], *freqs_hz[coarse])
        kept = keep_mask(mean_phasor_magnitude(first), threshold_db)
        offset_m = float(np.median(correction_m[kept])) if kept.any() else 0.0      # no signal: no shift
        start_m = prior_m - offset_m
    with timer.stage("correlate"):
        fine = correlate_pixels(signal, freqs_hz, antennas, x_m, y_m, start_m, backend)
    with timer.stage("depth"):
        depth_m = start_m - slope_correction_m(fine, freqs_hz)
    return depth_m, fine, offset_m


class MM3FSK(Method):
    """MM-3FSK with a per-pixel sensor prior (module doc)."""

    name = "mm3fsk"
    label = "MM-3FSK"
    n_freqs = 3
    priors = ("realsense", "photogrammetry")
    device_prior = True

    def run(self, frame: Frame, prior: Prior, backend: Backend, timer: StageTimer) -> Reconstruction:
        freqs_hz = np.asarray(frame.freqs_hz, dtype=np.float64)
        if not np.all(np.diff(freqs_hz) > 0):
            raise ValueError(f"MM-3FSK needs three ascending frequencies, got {freqs_hz}")
        grid, roi = frame.grid, frame.roi
        on_device = None
        if prior.device_resident:                  # a RealSense prior not built yet: one frame graph (Warp)
            on_device = backend.mm3fsk_at_prior(frame.samples, freqs_hz, frame.antennas.tx_m, frame.antennas.rx_m,
                                                grid, prior, coarse_pair(freqs_hz), frame.threshold_db, timer,
                                                None if roi.pixels.all() else roi.pixels)
        if on_device is not None:
            (depth_m, magnitude, prior_image_m), offset_m = on_device
            n = prior.n_used
            offset_m = offset_m if n else float("nan")         # as the host path: no pixel, no offset
            with timer.stage("filter"):
                depth_m = roi_depth_m(depth_m, roi)            # the device filtered by magnitude already
        else:
            prior_image_m = prior.host_m()
            depth_m, magnitude, offset_m, n = self._host(frame, freqs_hz, prior_image_m, backend, timer)
        return Reconstruction(depth_m=depth_m, magnitude=magnitude, freqs_hz=freqs_hz, timings_ms=timer.finish(),
                              grid=grid, method=self.name,
                              extra={"prior_depth_m": prior_image_m, "prior_pixels": n, "roi_px": n,
                                     "prior_offset_m": offset_m, "roi_sources": roi.sources + ("prior",)})

    @staticmethod
    def _host(frame: Frame, freqs_hz: np.ndarray, prior_image_m: np.ndarray, backend: Backend, timer: StageTimer
              ) -> tuple[np.ndarray, np.ndarray, float, int]:
        """Depth and magnitude (ny, nx), the prior offset (m) and the pixels correlated, the passes driven from
        the host (`mm3fsk_depth_m`)."""
        grid, roi = frame.grid, frame.roi
        has_prior = np.isfinite(prior_image_m) & roi.pixels
        x_img, y_img = grid.pixel_xy_m()
        depth_m, magnitude = np.full(grid.image_shape, np.nan), np.full(grid.image_shape, np.nan)
        offset_m = float("nan")
        if has_prior.any():
            depth_m[has_prior], fine, offset_m = mm3fsk_depth_m(frame.signal, freqs_hz, frame.antennas,
                                                                x_img[has_prior], y_img[has_prior],
                                                                prior_image_m[has_prior], backend, timer,
                                                                frame.threshold_db)
            with timer.stage("filter"):
                magnitude[has_prior] = mean_phasor_magnitude(fine)
        with timer.stage("filter"):
            depth_m = roi_depth_m(filter_depth(depth_m, magnitude, frame.threshold_db), roi)
        return depth_m, magnitude, offset_m, int(has_prior.sum())
