"""The one entry point of the methods: `reconstruct(capture, method, freq, prior, device, grid, **params)`.

It selects the configuration's frequencies from the loaded radar frame, builds the prior, checks the combination
and runs one method. Timings exclude file I/O (the capture is already in memory) and one-time kernel
compilation (a tiny warm-up call runs first on Warp devices).

`roi` picks the skips (methods.skips: 'auto' = those measured to agree with the full computation, 'none' = the
full computation of every method, 'all', or a mapping of settings) and the region of interest they use
(methods.roi: the capture's metadata mask_bb, the prior, a coarse pass). `extra["roi_px"]` is the number of pixels
the method evaluated (its last stage).
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from bench.capture import Capture, RadarGrid
from methods.bp import reconstruct_bp
from methods.backend import Backend, backend_for
from methods.frequencies import config_indices, select_frequencies
from methods.fsk import DEFAULT_PRIOR_M, reconstruct_2fsk
from methods.fsk3 import reconstruct_3fsk
from methods.mm2fsk import reconstruct_mm2fsk
from methods.prior_image import Prior
from methods.reconstruction import Reconstruction
from methods.roi import Roi, full_roi, intersect, roi_from_mask_bb
from methods.skips import SkipSettings, resolve
from methods.timing import StageTimer

METHODS = ("bp", "2fsk", "3fsk", "mm2fsk")
SENSOR_PRIORS = ("realsense", "photogrammetry")
_N_FREQS = {"2fsk": 2, "mm2fsk": 2, "3fsk": 3}
_COMMON_PARAMS = {"threshold_db", "scalar_prior_m"}
_PARAMS = {"bp": _COMMON_PARAMS | {"band_m"}, "2fsk": _COMMON_PARAMS, "3fsk": _COMMON_PARAMS, "mm2fsk": _COMMON_PARAMS}


def parse_prior(prior: str | float | None) -> str | float | None:
    """None for 'none', the sensor name for 'realsense'/'photogrammetry', else a scalar depth in metres."""
    if prior is None or prior == "none":
        return None
    if prior in SENSOR_PRIORS:
        return prior
    try:
        value = float(prior)
    except (TypeError, ValueError):
        raise ValueError(f"prior must be 'none', 'realsense', 'photogrammetry' or a depth in metres, "
                         f"got {prior!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise ValueError(f"a scalar prior is a depth in metres in front of the array (> 0), got {prior!r}")
    return value


def _transform(capture: Capture, key: str) -> np.ndarray:
    if key not in capture.transforms:
        raise ValueError(f"capture {capture.name} has no '{key}' transform in its alignment "
                         f"(available: {', '.join(sorted(capture.transforms)) or 'none'})")
    return capture.transforms[key]


def prior_image_m(capture: Capture, source: str, grid: RadarGrid, device: str | Backend = "cpu",
                  keep_on_device: bool = False) -> Prior:
    """Per-pixel prior (ny, nx) in metres on `grid` from 'realsense' or 'photogrammetry' (NaN = no prior), as a
    `Prior`: rasterised on the backend's device with `keep_on_device` where it can (np.asarray copies it back)."""
    backend = backend_for(device)
    notes = f" ({'; '.join(capture.notes)})" if capture.notes else ""
    if source == "realsense":
        if capture.realsense is None:
            raise ValueError(f"prior='realsense' needs a RealSense depth frame, but capture {capture.name} "
                             f"has none{notes}")
        return backend.realsense_prior(capture.realsense, _transform(capture, "realsense2radar"), grid,
                                       keep_on_device)
    if capture.mesh is None:
        raise ValueError(f"prior='photogrammetry' needs the photogrammetry mesh, but capture {capture.name} "
                         f"has none{notes}")
    return backend.mesh_prior(capture.mesh, _transform(capture, "photogrammetry2radar"), grid, keep_on_device)


def frequency_indices(freqs_hz: np.ndarray, freq: str | Sequence[float] | None) -> np.ndarray:
    """Indices of the frame frequencies for a configuration name, a list of target GHz, or None (all)."""
    if freq is None:
        return np.arange(len(freqs_hz))
    if isinstance(freq, str):
        return config_indices(freqs_hz, freq)
    return select_frequencies(freqs_hz, [float(f) for f in freq])


def _check(method: str, freq: object, n_freqs: int, prior: str | float | None, params: dict) -> None:
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    needed = _N_FREQS.get(method)
    if needed is not None and n_freqs != needed:
        raise ValueError(f"{method} needs a {needed}-frequency configuration, but freq={freq!r} selects "
                         f"{n_freqs} frequencies")
    if method == "mm2fsk" and prior not in SENSOR_PRIORS:
        raise ValueError(f"mm2fsk needs a per-pixel prior: prior='realsense' or 'photogrammetry', got {prior!r}")
    if method in ("2fsk", "3fsk") and prior in SENSOR_PRIORS:
        raise ValueError(f"{method} uses a scalar prior (a depth in metres, default {DEFAULT_PRIOR_M}); "
                         f"for prior={prior!r} use method='mm2fsk'")
    unknown = set(params) - _PARAMS[method]
    if unknown:
        raise ValueError(f"unknown parameter(s) {', '.join(sorted(unknown))} for {method}; "
                         f"allowed: {', '.join(sorted(_PARAMS[method]))}")
    if "band_m" in params and prior is None:
        raise ValueError("band_m sets BP's search band around a prior; give a prior as well")


def _check_frequencies_hz(capture: Capture, freqs_hz: np.ndarray) -> None:
    """Refuse a frequency vector that is not finite or not in Hz (e.g. in GHz)."""
    if freqs_hz.size == 0:
        raise ValueError(f"capture {capture.name} has no frequencies")
    if not np.all(np.isfinite(freqs_hz)) or freqs_hz.min() < 1e9:
        raise ValueError(f"the frequencies of capture {capture.name} must be finite and in Hz (>= 1 GHz), found "
                         f"{freqs_hz.min():g}-{freqs_hz.max():g} (in GHz? multiply by 1e9)")


def _check_signal(capture: Capture, signal: np.ndarray) -> None:
    """Refuse a radar frame with NaN or Inf samples (it would turn every depth into a silent NaN)."""
    if not np.all(np.isfinite(signal)):
        raise ValueError(f"the radar frame of capture {capture.name} has NaN or Inf samples")


def capture_roi(capture: Capture, grid: RadarGrid, skips: SkipSettings) -> Roi:
    """The ROI the capture itself gives before any pass: its metadata mask_bb's x/y bounds (`skips.mask_bb`) and z
    bounds (`skips.mask_bb_depth`) (methods.roi), else the whole grid. The prior's footprint and the coarse pass
    narrow it inside the methods."""
    roi = full_roi(grid)
    bounds = capture.metadata.mask_bb_m
    if skips.mask_bb:
        roi = intersect(roi, roi_from_mask_bb({k: v for k, v in bounds.items() if k[0] in "xy"}, grid))
    if skips.mask_bb_depth:
        roi = intersect(roi, roi_from_mask_bb({k: v for k, v in bounds.items() if k[0] == "z"}, grid))
    return roi


def reconstruct(capture: Capture, method: str, freq: str | Sequence[float] | None,
                prior: str | float | None = "none", device: str = "cpu", grid: RadarGrid | None = None,
                roi: str | dict | SkipSettings | None = "auto", **params) -> Reconstruction:
    """Depth map of the capture's loaded radar frame with `method` (bp | 2fsk | 3fsk | mm2fsk).

    freq: a configuration name of `methods.frequencies` (d05 ... d10, full, d05_d10, d1_d10, d2_d10), a list of
    target frequencies in GHz (nearest present ones are used), or None for all frequencies.
    prior: 'none', 'realsense', 'photogrammetry' (MM-2FSK; BP searches a band around it), or a scalar depth in
    metres (2FSK/3FSK start from it; BP searches a band around it). grid: overrides the frame's grid.
    roi: the skips and region of interest (module doc; 'none' = the full computation).
    params: threshold_db (filter, dB below the maximum, default 14; None = off); scalar_prior_m (the scalar
    prior of 2FSK/3FSK when prior='none', default 0.40 m; other methods ignore it); band_m (BP with a prior).
    A sensor prior that covers no radar pixel (empty mask, object outside the grid) gives an explicit all-invalid
    result: every depth NaN and `extra["invalid_reason"]` saying why; so does a frame without signal (all
    zero). `invalid_reason` is None when some pixel is valid. A frame with NaN/Inf
    samples or frequencies not in Hz raises ValueError.
    """
    frame = capture.radar
    if frame is None:
        raise ValueError(f"capture {capture.name} has no radar frame loaded")
    _check_frequencies_hz(capture, np.asarray(frame.freqs_hz, dtype=np.float64))
    indices = frequency_indices(frame.freqs_hz, freq)
    prior_value = parse_prior(prior)
    invalid_reason = None
    _check(method, freq, len(indices), prior_value, params)
    skips = resolve(roi, method, len(indices))
    backend = backend_for(device)
    grid = grid or frame.grid
    signal = np.ascontiguousarray(frame.signal[:, :, indices])
    _check_signal(capture, signal)
    freqs_hz = frame.freqs_hz[indices]
    backend.warm_up(signal, freqs_hz, capture.antennas.tx_m, capture.antennas.rx_m, volume=method == "bp",
                    prior=method == "mm2fsk")

    scalar_prior_m = float(params.pop("scalar_prior_m", DEFAULT_PRIOR_M))
    timer = StageTimer()
    antennas = capture.antennas
    region = capture_roi(capture, grid, skips)
    if prior_value in SENSOR_PRIORS:
        with timer.stage("prior"):
            sensor_prior = prior_image_m(capture, prior_value, grid, backend, keep_on_device=method == "mm2fsk")
        # an explicit all-invalid result (extra["invalid_reason"]) below
        if not sensor_prior.n_covered:
            invalid_reason = f"the {prior_value} prior of capture {capture.name} covers no radar pixel"
        prior_m = sensor_prior.host_m() if method == "bp" else sensor_prior
    else:
        prior_m = prior_value
    if method == "bp":
        result = reconstruct_bp(signal, freqs_hz, antennas, grid, prior_m=prior_m, backend=backend, timer=timer,
                                roi=region, skips=skips, **params)
    elif method == "mm2fsk":
        result = reconstruct_mm2fsk(signal, freqs_hz, antennas, grid, prior_m, backend=backend, timer=timer,
                                    roi=region, **params)
    else:
        run = reconstruct_2fsk if method == "2fsk" else reconstruct_3fsk
        result = run(signal, freqs_hz, antennas, grid, prior_m=scalar_prior_m if prior_m is None else prior_m,
                     backend=backend, roi=region, skips=skips, **params)
    if invalid_reason is None and not result.valid.any():
        invalid_reason = "no pixel has a nonzero magnitude within the filter threshold (a frame without signal?)"
    result.extra.update(freq=freq, prior=prior, device=backend.name, invalid_reason=invalid_reason)
    return result
