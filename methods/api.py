"""The one entry point of the methods: `reconstruct(capture, method, freq, prior, device, grid, **params)`.

It selects the configuration's frequencies from the loaded radar frame, builds the prior, checks the combination
against what the method declares (methods.method) and runs it on the device's backend (methods.backends). Timings
exclude file I/O (the capture is already in memory) and one-time kernel compilation (the backend's warm-up runs
first).

`roi` picks the skips (methods.skips.settings: 'auto' = those measured to agree with the full computation, 'none' = the
full computation of every method, 'all', or a mapping of settings) and the region of interest they use
(methods.skips.roi: the capture's metadata mask_bb, the prior, a coarse pass). `extra["roi_px"]` is the number of pixels
the method evaluated (its last stage).
"""
from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from methods.backends import backend_for
from methods.backends.base import Backend
from methods.domain.capture import Capture, RadarGrid
from methods.domain.errors import NonFiniteSignal, UsageError
from methods.domain.samples import FrameSamples
from methods.fsk import DEFAULT_PRIOR_M
from methods.method import SENSOR_PRIORS, Frame, Method
from methods.ops.filtering import DEFAULT_THRESHOLD_DB
from methods.ops.frequencies import config_targets_ghz, select_frequencies
from methods.ops.timing import StageTimer
from methods.prior.image import HostPrior, Prior
from methods.prior.priors import DEFAULT_FILL, DEFAULT_MAX_JUMP_MM, check_fill, mesh_prior_m, realsense_prior_m
from methods.reconstruction import Reconstruction
from methods.registry import make_method
from methods.skips.roi import Roi, full_roi, intersect, roi_from_mask_bb
from methods.skips.settings import SkipSettings, resolve


def parse_prior(prior: str | float | None) -> str | float | None:
    """None for 'none', the sensor name for 'realsense'/'photogrammetry', else a scalar depth in metres."""
    if prior is None or prior == "none":
        return None
    if prior in SENSOR_PRIORS:
        return prior
    try:
        value = float(prior)
    except (TypeError, ValueError):
        raise UsageError(f"prior must be 'none', 'realsense', 'photogrammetry' or a depth in metres, "
                         f"got {prior!r}") from None
    if not math.isfinite(value) or value <= 0:
        raise UsageError(f"a scalar prior is a depth in metres in front of the array (> 0), got {prior!r}")
    return value


def _transform(capture: Capture, key: str) -> np.ndarray:
    if key not in capture.transforms:
        raise UsageError(f"capture {capture.name} has no '{key}' transform in its alignment "
                         f"(available: {', '.join(sorted(capture.transforms)) or 'none'})")
    return capture.transforms[key]


def prior_image_m(capture: Capture, source: str, grid: RadarGrid, device: str | Backend = "cpu",
                  keep_on_device: bool = False, max_jump_mm: float | None = DEFAULT_MAX_JUMP_MM,
                  faithful: bool = False, fill: str = DEFAULT_FILL) -> Prior:
    """Per-pixel prior (ny, nx) in metres on `grid` from 'realsense' or 'photogrammetry' (NaN = no prior), as a
    `Prior`: rasterised on the backend's device with `keep_on_device` where it can (np.asarray copies it back).

    max_jump_mm (RealSense depth-jump rule, None = off), faithful (the reference's construction) and fill (the
    hole-fill rule, 'delaunay' | 'scanline') as in methods.prior.priors; a jump rule or construction other than the
    defaults is built on the host."""
    check_fill(fill)
    backend = backend_for(device)
    notes = f" ({'; '.join(capture.notes)})" if capture.notes else ""
    on_host = faithful or max_jump_mm != DEFAULT_MAX_JUMP_MM
    if source == "realsense":
        if capture.realsense is None:
            raise UsageError(f"prior='realsense' needs a RealSense depth frame, but capture {capture.name} "
                             f"has none{notes}")
        if on_host:
            return HostPrior(realsense_prior_m(capture.realsense, _transform(capture, "realsense2radar"), grid,
                                               max_jump_mm=max_jump_mm, faithful=faithful, fill=fill), grid)
        return backend.realsense_prior(capture.realsense, _transform(capture, "realsense2radar"), grid,
                                       keep_on_device, fill)
    if capture.mesh is None:
        raise UsageError(f"prior='photogrammetry' needs the photogrammetry mesh, but capture {capture.name} "
                         f"has none{notes}")
    if faithful:
        return HostPrior(mesh_prior_m(capture.mesh, _transform(capture, "photogrammetry2radar"), grid,
                                      faithful=True), grid)
    return backend.mesh_prior(capture.mesh, _transform(capture, "photogrammetry2radar"), grid, keep_on_device, fill)


def frequency_indices(freqs_hz: np.ndarray, freq: str | Sequence[float] | None, where: Path | None = None
                      ) -> np.ndarray:
    """Indices of the frame frequencies for a configuration name, a list of target GHz, or None (all). A target
    this frame cannot serve is a UsageError naming `where` (the frame's file). Read-only: the selection of a frame's
    frequency vector is looked up once (a fresh frame paid ~0.1 ms of NumPy for it on the H100's host)."""
    targets_ghz = config_targets_ghz(freq) if isinstance(freq, str) else freq
    if targets_ghz is None:
        return np.arange(len(freqs_hz))
    try:
        return _selected(np.asarray(freqs_hz, dtype=np.float64).tobytes(), tuple(float(f) for f in targets_ghz))
    except UsageError as err:
        raise UsageError(f"{where}: {err}" if where is not None else str(err)) from None


@functools.lru_cache(maxsize=64)
def _selected(freqs_key: bytes, targets_ghz: tuple[float, ...]) -> np.ndarray:
    indices = select_frequencies(np.frombuffer(freqs_key, dtype=np.float64), list(targets_ghz))
    indices.flags.writeable = False
    return indices


def _check_frequencies_hz(capture: Capture, freqs_hz: np.ndarray) -> None:
    """Refuse a frequency vector that is not finite or not in Hz (e.g. in GHz)."""
    problem = _frequency_problem(freqs_hz.tobytes())
    if problem is not None:
        raise UsageError(problem.format(name=capture.name))


@functools.lru_cache(maxsize=64)
def _frequency_problem(freqs_key: bytes) -> str | None:
    """What is wrong with a float64 frequency vector (its bytes), a message with {name} for the capture, or None;
    looked up once per vector (four reductions cost ~15 us of a fresh-frame call on the H100's host)."""
    freqs_hz = np.frombuffer(freqs_key, dtype=np.float64)
    if freqs_hz.size == 0:
        return "capture {name} has no frequencies"
    if not np.all(np.isfinite(freqs_hz)) or freqs_hz.min() < 1e9:
        return (f"the frequencies of capture {{name}} must be finite and in Hz (>= 1 GHz), found "
                f"{freqs_hz.min():g}-{freqs_hz.max():g} (in GHz? multiply by 1e9)")
    return None


def _nonfinite_signal(capture: Capture) -> UsageError:
    return UsageError(f"the radar frame of capture {capture.name} has NaN or Inf samples")


def _check_signal(capture: Capture, signal: np.ndarray) -> None:
    """Refuse a radar frame with NaN or Inf samples (it would turn every depth into a silent NaN). A finite sum
    proves every sample finite (NaN and Inf propagate); only a sum that is not finite (a NaN, an Inf, or an overflow
    of finite samples) pays the element-wise check."""
    if not np.isfinite(signal.sum()) and not np.all(np.isfinite(signal)):
        raise _nonfinite_signal(capture)


def _any_valid(depth_m: np.ndarray) -> bool:
    """Whether some depth is finite: a finite one among every 331st proves it (a prime longer than a row: the samples
    spread over rows and columns; ~300 reads of a 301 x 301 map, where every read of a map fresh from the device is
    a cache miss: a whole pass cost ~45 us on the H100's host), else a NaN-skipping maximum that is finite (one pass,
    no mask), else the element-wise test."""
    depth_m = np.asarray(depth_m)
    if depth_m.size and depth_m.dtype.kind == "f":
        if np.isfinite(depth_m.reshape(-1)[::331]).any() or np.isfinite(np.fmax.reduce(depth_m, axis=None)):
            return True
    return bool(np.isfinite(depth_m).any())


def _no_pixel_reason(capture: Capture, grid: RadarGrid, region: Roi, signal: np.ndarray,
                     threshold_db: float | None) -> str:
    """Why a reconstruction kept no pixel, naming its cause: the capture's mask_bb (its metadata.json) leaving no
    pixel or depth of the grid, a frame without signal (its file), else the depth filter's setting."""
    if region.n_pixels == 0 or len(region.z_indices(grid.z_m)) == 0:
        what, axes = ("pixel", "xy") if region.n_pixels == 0 else ("depth sample", "z")
        bounds = ", ".join(f"{k} {v:g}" for k, v in sorted(capture.metadata.mask_bb_m.items()) if k[0] in axes)
        return (f"the mask_bb of {capture.path / 'metadata.json'} ({bounds} m) excludes every {what} of the grid "
                f"(x {grid.bb_min_m[0]:g}..{grid.bb_max_m[0]:g}, y {grid.bb_min_m[1]:g}..{grid.bb_max_m[1]:g}, "
                f"z {grid.bb_min_m[2]:g}..{grid.bb_max_m[2]:g} m)")
    if not np.any(signal):
        return f"the radar frame {capture.radar.path} has no signal (every sample of the used frequencies is zero)"
    return f"no pixel has a nonzero magnitude within the depth filter (threshold_db={threshold_db})"


def capture_roi(capture: Capture, grid: RadarGrid, skips: SkipSettings) -> Roi:
    """The ROI the capture itself gives before any pass: its metadata mask_bb's x/y bounds (`skips.mask_bb`) and z
    bounds (`skips.mask_bb_depth`) (methods.skips.roi), else the whole grid. The prior's footprint and the coarse pass
    narrow it inside the methods. Built once per grid, bounds and skips (its pixels read-only: a fresh frame of the
    same setting paid ~0.1 ms of NumPy for it on the H100's host)."""
    bounds = tuple(sorted((k, float(v)) for k, v in capture.metadata.mask_bb_m.items()))
    return _capture_roi(grid, bounds, bool(skips.mask_bb), bool(skips.mask_bb_depth))


@functools.lru_cache(maxsize=64)
def _capture_roi(grid: RadarGrid, bounds: tuple[tuple[str, float], ...], mask_bb: bool, mask_bb_depth: bool) -> Roi:
    roi = full_roi(grid)
    if mask_bb:
        roi = intersect(roi, roi_from_mask_bb({k: v for k, v in bounds if k[0] in "xy"}, grid))
    if mask_bb_depth:
        roi = intersect(roi, roi_from_mask_bb({k: v for k, v in bounds if k[0] == "z"}, grid))
    roi.pixels.flags.writeable = False
    return roi


@functools.lru_cache(maxsize=64)
def _preset(roi: str, method: str, n_freqs: int, dense_beats_search: bool, keeps_on_device: bool) -> SkipSettings:
    """`resolve` of a preset name, once per setting (SkipSettings are frozen; ~10 us a call on the H100's host)."""
    return resolve(roi, method, n_freqs, dense_beats_search, keeps_on_device)


def _run(capture: Capture, method: Method, samples: FrameSamples, freqs_hz: np.ndarray, prior_value,
         backend: Backend, grid: RadarGrid, skips: SkipSettings, threshold_db: float | None, scalar_prior_m: float,
         prior_options: dict | None) -> tuple[Reconstruction, object]:
    """Warm-up, prior and `method.run` of `reconstruct` (the result and the prior it ran with)."""
    antennas = capture.antennas
    backend.warm_up(samples, freqs_hz, antennas.tx_m, antennas.rx_m, volume=method.uses_volume,
                    prior=method.device_prior)
    method.warm_up(freqs_hz, antennas, grid, skips, prior_value)
    timer = StageTimer()
    region = capture_roi(capture, grid, skips)
    if prior_value in SENSOR_PRIORS:
        with timer.stage("prior"):
            run_prior = prior_image_m(capture, prior_value, grid, backend, keep_on_device=method.device_prior,
                                      **(prior_options or {}))
    elif prior_value is None and "none" not in method.priors:
        run_prior = scalar_prior_m          # a method of scalar priors starts from the default one
    else:
        run_prior = prior_value
    result = method.run(Frame(samples, freqs_hz, antennas, grid, region, skips, threshold_db, capture.name),
                        run_prior, backend, timer)
    return result, run_prior


def reconstruct(capture: Capture, method: str | type | Method, freq: str | Sequence[float] | None,
                prior: str | float | None = "none", device: str | Backend = "cpu", grid: RadarGrid | None = None,
                roi: str | dict | SkipSettings | None = "auto", threshold_db: float | None = DEFAULT_THRESHOLD_DB,
                scalar_prior_m: float = DEFAULT_PRIOR_M, prior_options: dict | None = None,
                **params) -> Reconstruction:
    """Depth map of the capture's loaded radar frame with `method`: a built-in name (bp | 2fsk | 3fsk | mm2fsk |
    mm3fsk), a dotted class path, a `methods.method.Method` subclass or instance (methods.registry).

    freq: a configuration name of `methods.ops.frequencies` (d05 ... d10, full, d05_d10, d1_d10, d2_d10), a list of
    target frequencies in GHz (nearest present ones are used), or None for all frequencies.
    prior: 'none', 'realsense', 'photogrammetry', or a scalar depth in metres; a method that needs a scalar prior
    gets `scalar_prior_m` (default 0.40 m) for 'none'. grid: overrides the frame's grid.
    roi: the skips and region of interest (module doc; 'none' = the full computation). threshold_db: the depth
    filter, dB below the strongest pixel (default 14; None = off). prior_options: how a sensor prior is built
    (`prior_image_m`'s max_jump_mm, faithful and fill). params: the method's own parameters (its `params`; e.g. band_m
    for BP with a prior, filter_quantity for 2FSK/MM-2FSK).
    A sensor prior that covers no radar pixel (empty mask, object outside the grid) gives an explicit all-invalid
    result: every depth NaN and `invalid_reason` saying why; so does a frame without signal (all zero).
    `invalid_reason` is None when some pixel is valid. A frame with NaN/Inf samples or frequencies not in Hz, and
    a combination the method does not accept (methods.method.MethodError), raise UsageError (a ValueError).
    """
    method = make_method(method, params)
    frame = capture.radar
    if frame is None:
        raise UsageError(f"capture {capture.name} has no radar frame loaded")
    _check_frequencies_hz(capture, np.asarray(frame.freqs_hz, dtype=np.float64))
    indices = frequency_indices(frame.freqs_hz, freq, frame.path)
    prior_value = parse_prior(prior)
    invalid_reason = None
    method.check(len(indices), freq, prior_value)
    backend = backend_for(device)
    skips = (_preset(roi, method.name, len(indices), backend.dense_beats_search, backend.keeps_on_device)
             if isinstance(roi, str) else
             resolve(roi, method.name, len(indices), backend.dense_beats_search, backend.keeps_on_device))
    grid = grid or frame.grid
    every = len(indices) == frame.signal.shape[2] and np.array_equal(indices, np.arange(len(indices)))
    samples = FrameSamples(frame.signal, None if every else indices)    # (BP_max: the frame itself, not a copy)
    # a backend that checks the samples on its device where it stages them (`checks_samples`: Warp on CUDA) spares
    # the host's check (a 9 MB frame's sum cost ~1 ms on the H100's host, a two-frequency one ~0.02 ms); it says after
    # the run whether it did (`samples_checked`: a method that never staged them on the device was not checked)
    device_checks = backend.checks_samples(samples)
    if not device_checks:
        _check_signal(capture, samples.array())
    freqs_hz = frame.freqs_hz[indices]
    try:
        result, run_prior = _run(capture, method, samples, freqs_hz, prior_value, backend, grid, skips, threshold_db,
                                 scalar_prior_m, prior_options)
    except NonFiniteSignal:                 # the backend's check
        raise _nonfinite_signal(capture) from None
    except Exception:
        if device_checks and not backend.samples_checked(samples):
            _check_signal(capture, samples.array())
        raise
    if device_checks and not backend.samples_checked(samples):
        _check_signal(capture, samples.array())
    # an explicit all-invalid result; counted after the run (a deferred device prior is built by the method)
    if prior_value in SENSOR_PRIORS and not run_prior.n_covered:
        invalid_reason = f"the {prior_value} prior of capture {capture.name} covers no radar pixel"
    if invalid_reason is None and not _any_valid(result.depth_m):
        invalid_reason = _no_pixel_reason(capture, grid, capture_roi(capture, grid, skips), samples.array(),
                                          threshold_db)
    result.extra.update(freq=freq, prior=prior)
    result.device, result.invalid_reason = backend.name, invalid_reason
    return result
