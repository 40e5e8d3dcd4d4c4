"""3FSK (paper section III, its reference [22]): a coarse 2FSK step with the smallest frequency difference, then
a fine step with the large differences on the per-pixel coarse depth.

What is implemented, for frequencies f_lo < f_mid < f_hi (e.g. d05_d10: 72.00, 81.45, 82.00 GHz):

1. Coarse: the neighbouring pair with the smallest difference (f_mid, f_hi: 0.55 GHz for d05_d10, unambiguous
   over +-13.6 cm) runs the two-pass 2FSK of `methods.fsk` from the scalar prior (default 0.40 m): pass 1 at the
   prior, one global correction from the strongest pixel, pass 2 per pixel. Result: a per-pixel coarse depth d1
   that is unambiguous but noisy (a phase error e gives a depth error c e / (4 pi 0.55 GHz)).
2. Fine: all three frequencies are correlated once more at (x, y, d1). Their residual phases relative to f_hi,
   `angle(c_k conj(c_hi))`, lie on a line over frequency with slope -4 pi (d - d1) / c; the least-squares slope
   s through the three points gives d = d1 - c s / (4 pi). The fit is dominated by the two large differences
   (f_hi - f_lo = 10 GHz, f_mid - f_lo = 9.45 GHz), so the same phase error costs ~18x less depth, and with two
   frequencies it reduces to the 2FSK formula. The relative phases unwrap correctly only while
   |d - d1| < c / (4 (f_hi - f_lo)) (0.75 cm for d05_d10): the coarse step must land that close.

Why: the coarse difference must cover the prior's error (c / (4 df_min) > 10 cm holds for d05_d10, not for
d1_d10 or d2_d10, which therefore fail like 2FSK d1 / d2, as in the paper's Table III), and the fine difference
must be wide for precision. Re-correlating at d1 refocuses every pixel at its own depth, so the fine phases are
clean. Cost: three correlation passes (2 + 2 + 3 frequencies per pixel) against two (2 + 2) for 2FSK, in line
with the paper's 7 ms vs 4 ms. The filter quantity is the magnitude of the mean residual phasor over the pairs
and the three frequencies of the fine pass.

Region of interest and skips: the passes run only on the ROI's pixels; with `fsk_keep` the coarse step's pass 2
and the fine pass run only where the filter (on the fine pass's magnitude) can keep a pixel (methods.skips.keep_skip);
depths outside the ROI's depth interval are invalid. With neither (`roi=none`) the computation is today's.
A `device_fsk` backend (Warp) runs every pass, the depth and the filter on its device and copies the maps back once
(methods.backends.warp.fsk.three_fsk, the same expressions); with `fsk_keep` only where it keeps on its device
(`Backend.keeps_on_device`), else the host drives the passes.
"""
from __future__ import annotations

import numpy as np

from methods.backends import backend_for
from methods.backends.base import Backend
from methods.domain.antennas import AntennaArray
from methods.domain.capture import RadarGrid
from methods.domain.samples import FrameSamples
from methods.fsk import (
    DEFAULT_PRIOR_M,
    correlate_pixels,
    device_result,
    finish,
    first_pass_z1_m,
    keep_rule,
    mean_phasor_magnitude,
    second_pass,
)
from methods.method import Frame, Method
from methods.ops.correlate import C_M_PER_S
from methods.ops.filtering import DEFAULT_THRESHOLD_DB
from methods.ops.timing import StageTimer
from methods.reconstruction import Reconstruction
from methods.skips.keep_skip import run_where_kept
from methods.skips.roi import Roi, full_roi, pixel_pitch_m
from methods.skips.settings import NONE, SkipSettings


def slope_correction_m(phasors: np.ndarray, freqs_hz: np.ndarray) -> np.ndarray:
    """Depth correction (N,) m from the least-squares phase slope over frequency of phasors (F, N).

    Phases are taken relative to the highest frequency; the depth is `guess - correction`.
    """
    rel_phase = np.angle(phasors * np.conj(phasors[-1])).astype(np.float64)      # (F, N)
    offsets_hz = np.asarray(freqs_hz, dtype=np.float64) - freqs_hz[-1]
    centred_hz = offsets_hz - offsets_hz.mean()
    slope = centred_hz @ (rel_phase - rel_phase.mean(axis=0)) / (centred_hz @ centred_hz)   # rad / Hz
    return C_M_PER_S * slope / (4.0 * np.pi)


def reconstruct_3fsk(signal: np.ndarray | FrameSamples, freqs_hz: np.ndarray, antennas: AntennaArray,
                     grid: RadarGrid, *,
                     prior_m: float = DEFAULT_PRIOR_M, threshold_db: float | None = DEFAULT_THRESHOLD_DB,
                     backend: Backend | str = "cpu", roi: Roi | None = None, skips: SkipSettings = NONE,
                     timer: StageTimer | None = None) -> Reconstruction:
    """3FSK depth map on `grid`'s pixels from a three-frequency frame `signal` (n_rx, n_tx, 3), f ascending (or a
    FrameSamples, which a device graph gathers itself); `roi` (None = the whole grid) and `skips.fsk_keep` as in
    the module doc."""
    freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
    if len(freqs_hz) != 3 or not np.all(np.diff(freqs_hz) > 0):
        raise ValueError(f"3FSK needs three ascending frequencies, got {freqs_hz}")
    timer = timer or StageTimer()
    backend = backend_for(backend)
    roi = roi if roi is not None else full_roi(grid)
    pixels = roi.pixels
    pairs = [(0, 1), (1, 2)]                            # the smallest difference is between neighbours
    coarse = list(min(pairs, key=lambda p: freqs_hz[p[1]] - freqs_hz[p[0]]))
    extra = {"prior_m": prior_m, "coarse_pair_hz": tuple(freqs_hz[coarse])}
    if not pixels.any():
        nan = np.full(grid.image_shape, np.nan)
        return finish(nan, nan.copy(), grid, freqs_hz, "3fsk", threshold_db, timer,
                      {**extra, "coarse_depth_m": nan.copy(), "roi_px": 0, "roi_sources": roi.sources}, roi)
    keep = keep_rule(skips, grid, threshold_db)
    if backend.device_fsk and (keep is None or backend.keeps_on_device):
        depth_m, magnitude, coarse_m, details = backend.fsk_three(signal, freqs_hz, antennas.tx_m, antennas.rx_m,
                                                                  grid, pixels, coarse, prior_m, threshold_db, timer,
                                                                  keep=keep)
        evaluated = details.pop("evaluated_px", None)
        if evaluated is None:                       # (a count, not a sum: ~20 us of a call on the H100's host)
            evaluated = int(np.count_nonzero(pixels))
        extra.update(coarse_depth_m=coarse_m, **details, roi_px=evaluated, roi_sources=roi.sources)
        return device_result(depth_m, magnitude, grid, freqs_hz, "3fsk", timer, extra, roi)
    signal = np.asarray(signal)
    x_img, y_img = grid.pixel_xy_m()
    coarse_signal, coarse_hz = signal[:, :, coarse], freqs_hz[coarse]
    z1_m, details = first_pass_z1_m(coarse_signal, coarse_hz, antennas, x_img[pixels], y_img[pixels], prior_m,
                                    backend, timer)

    def run(mask: np.ndarray) -> dict[str, np.ndarray]:
        x_m, y_m = x_img[mask], y_img[mask]
        coarse_m, _ = second_pass(coarse_signal, coarse_hz, antennas, x_m, y_m, z1_m, backend, timer)
        with timer.stage("correlate"):
            phasors = correlate_pixels(signal, freqs_hz, antennas, x_m, y_m, coarse_m, backend)
        with timer.stage("depth"):
            depth_m = coarse_m - slope_correction_m(phasors, freqs_hz)
        with timer.stage("filter"):
            return {"depth_m": depth_m, "magnitude": mean_phasor_magnitude(phasors), "coarse_m": coarse_m}

    step_px, radius_px = skips.lattice_px(pixel_pitch_m(grid))
    evaluated, images = run_where_kept(pixels, run, threshold_db, step_px, skips.keep_margin_db, radius_px,
                                       enabled=skips.fsk_keep)
    extra.update(coarse_depth_m=images["coarse_m"], **details, roi_px=int(evaluated.sum()), roi_sources=roi.sources)
    return finish(images["depth_m"], images["magnitude"], grid, freqs_hz, "3fsk", threshold_db, timer, extra, roi)


class ThreeFSK(Method):
    """3FSK with a scalar prior (module doc)."""

    name = "3fsk"
    label = "3FSK"
    n_freqs = 3
    priors = ("scalar",)

    def run(self, frame: Frame, prior: float, backend: Backend, timer: StageTimer) -> Reconstruction:
        return reconstruct_3fsk(frame.samples, frame.freqs_hz, frame.antennas, frame.grid, prior_m=prior,
                                threshold_db=frame.threshold_db, backend=backend, roi=frame.roi, skips=frame.skips,
                                timer=timer)
