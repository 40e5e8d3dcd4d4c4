"""2FSK with a scalar depth prior (paper section II-A; MAROON_FORMAT.md 6.3), and the FSK building blocks.

Residual phasors c_k at a guess depth d~ follow `c_k ~ exp(-j 4 pi f_k (d - d~) / c)`, so the depth is
`d = d~ - c * angle(c2 * conj(c1)) / (4 pi (f2 - f1))` (DESIGN.md section 4), unambiguous while
|d - d~| < c / (4 (f2 - f1)).

Two passes from the scalar prior z0 (default 0.40 m as in the paper): pass 1 correlates every pixel at z0; the
pixel with the largest |c1| gives the correction z1 = z0 - dz(that pixel), applied to all pixels; pass 2
correlates every pixel at z1 and corrects each pixel by its own dz. The filter quantity is the magnitude of the
mean residual phasor over the pairs and both frequencies of the final pass.

Region of interest and skips (methods.skips.roi, methods.skips.settings): both passes run only on the ROI's pixels
(pass 1's
strongest pixel is taken among them), and with `fsk_keep` pass 2 runs only where the filter can keep a pixel
(methods.skips.keep_skip); depths outside the ROI's depth interval are invalid. With neither (`roi=none`) the
computation is today's.

A backend that holds the frame on a device (`Backend.device_fsk`: Warp) runs both passes, the strongest-pixel
reduction, the depth and the filter there and copies the maps back once (methods.backends.warp.fsk.two_pass, the same
expressions); with `fsk_keep` it does so where it can keep on its device (`Backend.keeps_on_device`: Warp on CUDA,
the same rule in the FSK graph, methods.backends.warp.frame_graph.KeptFskGraph), else the host drives the passes.
"""
from __future__ import annotations

import numpy as np

from methods.backends import backend_for
from methods.backends.base import Backend
from methods.domain.antennas import AntennaArray
from methods.domain.capture import RadarGrid
from methods.domain.samples import FrameSamples
from methods.method import Frame, Method
from methods.ops.correlate import C_M_PER_S
from methods.ops.filtering import DEFAULT_THRESHOLD_DB, filter_depth
from methods.ops.timing import StageTimer
from methods.reconstruction import Reconstruction
from methods.skips.keep_skip import run_where_kept
from methods.skips.roi import Roi, full_roi, pixel_pitch_m
from methods.skips.settings import NONE, SkipSettings

DEFAULT_PRIOR_M = 0.40


def depth_correction_m(c_lo: np.ndarray, c_hi: np.ndarray, f_lo_hz: float, f_hi_hz: float) -> np.ndarray:
    """dz = c angle(c_hi conj(c_lo)) / (4 pi (f_hi - f_lo)) in metres; the depth is `guess - dz`."""
    phase = np.angle(c_hi * np.conj(c_lo)).astype(np.float64)
    return C_M_PER_S * phase / (4.0 * np.pi * (f_hi_hz - f_lo_hz))


def correlate_pixels(signal: np.ndarray, freqs_hz: np.ndarray, antennas: AntennaArray, x_m: np.ndarray,
                     y_m: np.ndarray, z_m: np.ndarray | float, backend: Backend | str) -> np.ndarray:
    """Residual phasors (F, N) at the points (x_m, y_m, z_m), each (N,) (z may be a scalar), on `backend` (or a
    device name)."""
    points_m = np.column_stack([x_m, y_m, np.broadcast_to(z_m, np.shape(x_m))])
    return backend_for(backend).correlate(signal, freqs_hz, antennas.tx_m, antennas.rx_m, points_m)


def mean_phasor_magnitude(phasors: np.ndarray) -> np.ndarray:
    """|mean over frequencies| of residual phasors (F, N) already averaged over pairs: the filter quantity."""
    return np.abs(phasors.mean(axis=0)).astype(np.float64)


FILTER_QUANTITIES = ("mean", "first")


def filter_magnitude(phasors: np.ndarray, quantity: str = "mean") -> np.ndarray:
    """The 2FSK/MM-2FSK filter quantity of residual phasors (2, N): 'mean' = |mean of both frequencies| (the
    paper's text, our default), 'first' = |first (lower) frequency's phasor| (the reference code's
    extract_depth; profile=faithful)."""
    if quantity not in FILTER_QUANTITIES:
        raise ValueError(f"unknown filter_quantity {quantity!r}; choose one of {', '.join(FILTER_QUANTITIES)}")
    return mean_phasor_magnitude(phasors) if quantity == "mean" else np.abs(phasors[0]).astype(np.float64)


def first_pass_z1_m(signal: np.ndarray, freqs_hz: np.ndarray, antennas: AntennaArray, x_m: np.ndarray,
                    y_m: np.ndarray, prior_m: float, backend: Backend, timer: StageTimer) -> tuple[float, dict]:
    """Pass 1 of 2FSK: correlate the pixels (x_m, y_m) (N,) at the scalar prior; the strongest pixel's correction
    gives the common guess z1 (m). Returns (z1, details). `signal` (n_rx, n_tx, 2) holds f_lo < f_hi."""
    f_lo, f_hi = freqs_hz
    with timer.stage("correlate"):
        first = correlate_pixels(signal, freqs_hz, antennas, x_m, y_m, prior_m, backend)
    with timer.stage("depth"):
        ref = int(np.argmax(np.abs(first[0])))
        z1_m = prior_m - float(depth_correction_m(first[0, ref], first[1, ref], f_lo, f_hi))
    return z1_m, {"reference_pixel": ref, "z1_m": z1_m}


def second_pass(signal: np.ndarray, freqs_hz: np.ndarray, antennas: AntennaArray, x_m: np.ndarray,
                y_m: np.ndarray, z1_m: float, backend: Backend, timer: StageTimer) -> tuple[np.ndarray, np.ndarray]:
    """Pass 2 of 2FSK at z1 for the pixels (x_m, y_m) (N,): depth (N,) m and the phasors (2, N)."""
    with timer.stage("correlate"):
        second = correlate_pixels(signal, freqs_hz, antennas, x_m, y_m, z1_m, backend)
    with timer.stage("depth"):
        depth_m = z1_m - depth_correction_m(second[0], second[1], *freqs_hz)
    return depth_m, second


def two_pass_depth_m(signal: np.ndarray, freqs_hz: np.ndarray, antennas: AntennaArray, x_m: np.ndarray,
                     y_m: np.ndarray, prior_m: float, backend: Backend, timer: StageTimer
                     ) -> tuple[np.ndarray, np.ndarray, dict]:
    """Two-pass 2FSK over pixels (x_m, y_m) from a scalar prior: depth (N,) m, final phasors (2, N), details.

    `signal` (n_rx, n_tx, 2) holds the frequencies `freqs_hz` (f_lo < f_hi).
    """
    z1_m, details = first_pass_z1_m(signal, freqs_hz, antennas, x_m, y_m, prior_m, backend, timer)
    depth_m, second = second_pass(signal, freqs_hz, antennas, x_m, y_m, z1_m, backend, timer)
    return depth_m, second, details


def roi_depth_m(depth_m: np.ndarray, roi: Roi) -> np.ndarray:
    """Depths outside the ROI's depth interval become NaN (the point lies outside the ROI)."""
    if np.isinf(roi.z_min_m) and np.isinf(roi.z_max_m):
        return depth_m
    with np.errstate(invalid="ignore"):
        return np.where((depth_m >= roi.z_min_m) & (depth_m <= roi.z_max_m), depth_m, np.nan)


def finish(depth_m: np.ndarray, magnitude: np.ndarray, grid: RadarGrid, freqs_hz: np.ndarray, method: str,
           threshold_db: float | None, timer: StageTimer, extra: dict, roi: Roi | None = None) -> Reconstruction:
    """Filter the depth image (ny, nx) by the mean-phasor magnitude image (ny, nx; NaN = not evaluated), drop
    depths outside the ROI's depth interval, and package the Reconstruction."""
    with timer.stage("filter"):
        depth_m = filter_depth(depth_m, magnitude, threshold_db)
        if roi is not None:
            depth_m = roi_depth_m(depth_m, roi)
    return Reconstruction(depth_m=depth_m, magnitude=magnitude, freqs_hz=np.asarray(freqs_hz),
                          timings_ms=timer.finish(), grid=grid, method=method, extra=extra)


def keep_rule(skips: SkipSettings, grid: RadarGrid, threshold_db: float | None) -> tuple | None:
    """(lattice step px, neighbourhood radius px, margin dB, threshold dB) of the `fsk_keep` skip where it applies
    (`keep_skip.run_where_kept`: on, a threshold set, a lattice step > 1 pixel), else None (every pixel)."""
    if not skips.fsk_keep or threshold_db is None:
        return None
    step_px, radius_px = skips.lattice_px(pixel_pitch_m(grid))
    return None if step_px <= 1 else (step_px, radius_px, float(skips.keep_margin_db), float(threshold_db))


def device_result(depth_m: np.ndarray, magnitude: np.ndarray, grid: RadarGrid, freqs_hz: np.ndarray, method: str,
                  timer: StageTimer, extra: dict, roi: Roi) -> Reconstruction:
    """The Reconstruction of maps the device already filtered: depths outside the ROI's depth interval dropped."""
    return Reconstruction(depth_m=roi_depth_m(depth_m, roi), magnitude=magnitude, freqs_hz=np.asarray(freqs_hz),
                          timings_ms=timer.finish(), grid=grid, method=method, extra=extra)


def reconstruct_2fsk(signal: np.ndarray | FrameSamples, freqs_hz: np.ndarray, antennas: AntennaArray,
                     grid: RadarGrid, *,
                     prior_m: float = DEFAULT_PRIOR_M, threshold_db: float | None = DEFAULT_THRESHOLD_DB,
                     backend: Backend | str = "cpu", roi: Roi | None = None, skips: SkipSettings = NONE,
                     timer: StageTimer | None = None, filter_quantity: str = "mean") -> Reconstruction:
    """2FSK depth map on `grid`'s pixels from a two-frequency frame `signal` (n_rx, n_tx, 2) (or a FrameSamples,
    which a device graph gathers itself); `roi` (None = the whole grid) and `skips.fsk_keep` as in the module doc;
    `filter_quantity` as in `filter_magnitude`."""
    if len(freqs_hz) != 2:
        raise ValueError(f"2FSK needs exactly two frequencies, got {len(freqs_hz)}")
    timer = timer or StageTimer()
    backend = backend_for(backend)
    roi = roi if roi is not None else full_roi(grid)
    pixels = roi.pixels
    if not pixels.any():
        nan = np.full(grid.image_shape, np.nan)
        return finish(nan, nan.copy(), grid, freqs_hz, "2fsk", threshold_db, timer,
                      {"prior_m": prior_m, "roi_px": 0, "roi_sources": roi.sources}, roi)
    keep = keep_rule(skips, grid, threshold_db)
    if backend.device_fsk and (keep is None or backend.keeps_on_device):
        depth_m, magnitude, details = backend.fsk_two_pass(signal, freqs_hz, antennas.tx_m, antennas.rx_m, grid,
                                                           pixels, prior_m, threshold_db, filter_quantity, timer,
                                                           keep=keep)
        evaluated = details.pop("evaluated_px", None)
        if evaluated is None:                       # (a count, not a sum: ~20 us of a call on the H100's host)
            evaluated = int(np.count_nonzero(pixels))
        extra = {"prior_m": prior_m, **details, "roi_px": evaluated, "roi_sources": roi.sources}
        return device_result(depth_m, magnitude, grid, freqs_hz, "2fsk", timer, extra, roi)
    signal = np.asarray(signal)
    x_img, y_img = grid.pixel_xy_m()
    z1_m, details = first_pass_z1_m(signal, freqs_hz, antennas, x_img[pixels], y_img[pixels], prior_m, backend,
                                    timer)

    def run(mask: np.ndarray) -> dict[str, np.ndarray]:
        depth_m, phasors = second_pass(signal, freqs_hz, antennas, x_img[mask], y_img[mask], z1_m, backend, timer)
        with timer.stage("filter"):
            return {"depth_m": depth_m, "magnitude": filter_magnitude(phasors, filter_quantity)}

    step_px, radius_px = skips.lattice_px(pixel_pitch_m(grid))
    evaluated, images = run_where_kept(pixels, run, threshold_db, step_px, skips.keep_margin_db, radius_px,
                                       enabled=skips.fsk_keep)
    extra = {"prior_m": prior_m, **details, "roi_px": int(evaluated.sum()), "roi_sources": roi.sources}
    return finish(images["depth_m"], images["magnitude"], grid, freqs_hz, "2fsk", threshold_db, timer, extra, roi)


class TwoFSK(Method):
    """2FSK with a scalar prior (module doc)."""

    name = "2fsk"
    label = "2FSK"
    n_freqs = 2
    priors = ("scalar",)
    params = {"filter_quantity": "mean"}     # 'first': the reference code's filter (profile=faithful)

    def run(self, frame: Frame, prior: float, backend: Backend, timer: StageTimer) -> Reconstruction:
        return reconstruct_2fsk(frame.samples, frame.freqs_hz, frame.antennas, frame.grid, prior_m=prior,
                                threshold_db=frame.threshold_db, backend=backend, roi=frame.roi, skips=frame.skips,
                                timer=timer, filter_quantity=self.values["filter_quantity"])
