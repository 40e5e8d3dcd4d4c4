"""Back-projection (BP, BP_max): coherent sum over any set of frequencies on a voxel grid, max projection over z,
argmax + 3-point parabola on the dB values (MAROON_FORMAT.md 6.1-6.2).

Depth per pixel: k* = argmax_k |V|, then z = z[k*] + dz (A- - A+) / (2 (A- - 2 A0 + A+)) with A = 20 log10 |V| at
k*-1, k*, k*+1; indices are clipped at the ends of the z range (giving the reference code's -+dz/2 there) and a
flat triple gets no offset. The filter quantity is the linear max projection max_k |V|.

Optional search band around a prior: a scalar prior restricts the z range of the grid to |z - prior| <= band_m;
a per-pixel prior image (ny, nx) samples each pixel at prior + k dz, |k dz| <= band_m (dz = the grid's z step),
and pixels without a prior stay NaN.
"""
from __future__ import annotations

import numpy as np

from bench.antennas import AntennaArray
from bench.capture import RadarGrid
from methods.correlate import correlate, correlate_volume
from methods.filtering import DEFAULT_THRESHOLD_DB, filter_depth
from methods.reconstruction import Reconstruction
from methods.timing import StageTimer

DEFAULT_BAND_M = 0.05


def peak_depth_m(magnitude: np.ndarray, z_first_m: np.ndarray | float, dz_m: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Parabola-refined depth and max projection from |V| profiles (K, ...) sampled at z_first + k dz.

    Returns (depth_m, max_projection), each of the trailing shape of `magnitude`.
    """
    n_z = magnitude.shape[0]
    k_best = np.argmax(magnitude, axis=0)

    def pick(k: np.ndarray) -> np.ndarray:
        return np.take_along_axis(magnitude, np.clip(k, 0, n_z - 1)[None], axis=0)[0]

    peak = pick(k_best)
    tiny = np.finfo(np.float32).tiny
    db_minus, db_0, db_plus = (20.0 * np.log10(np.maximum(pick(k_best + s), tiny).astype(np.float64))
                               for s in (-1, 0, 1))
    curvature = db_minus - 2.0 * db_0 + db_plus
    safe = np.where(curvature < 0, curvature, -1.0)
    offset = np.where(curvature < 0, 0.5 * (db_minus - db_plus) / safe, 0.0)
    return z_first_m + (k_best + offset) * dz_m, peak.astype(np.float64)


def _volume_depth_m(signal, freqs_hz, antennas, grid, z_m, dz_m, device, timer):
    """Depth and max projection (ny, nx) from the rectangular volume x_m x y_m (descending) x z_m."""
    if device != "cpu":              # Warp: argmax + parabola on the device; only the (ny, nx) maps come back
        from methods.correlate import volume_peak_depth
        return volume_peak_depth(signal, freqs_hz, antennas.tx_m, antennas.rx_m, grid.x_m, grid.y_m[::-1], z_m,
                                 device=device, timer=timer)
    with timer.stage("correlate"):
        volume = correlate_volume(signal, freqs_hz, antennas.tx_m, antennas.rx_m, grid.x_m, grid.y_m[::-1], z_m,
                                  device=device)
    with timer.stage("depth"):
        return peak_depth_m(np.abs(volume), float(z_m[0]), dz_m)


def _band_depth_m(signal, freqs_hz, antennas, grid, prior_m, band_m, dz_m, device, timer):
    """Depth and max projection (ny, nx) from per-pixel profiles prior + k dz, |k dz| <= band_m; NaN: no prior."""
    has_prior = np.isfinite(prior_m)
    n_band = int(np.floor(band_m / dz_m + 1e-9))
    steps_m = np.arange(-n_band, n_band + 1) * dz_m
    x_m, y_m = grid.pixel_xy_m()
    points_m = np.stack(np.broadcast_arrays(x_m[has_prior][None], y_m[has_prior][None],
                                            prior_m[has_prior][None] + steps_m[:, None]), axis=-1)
    with timer.stage("correlate"):
        profiles = correlate(signal, freqs_hz, antennas.tx_m, antennas.rx_m, points_m.reshape(-1, 3),
                             sum_freqs=True, device=device).reshape(len(steps_m), -1)
    with timer.stage("depth"):
        depth_m, max_proj = np.full(grid.image_shape, np.nan), np.full(grid.image_shape, np.nan)
        depth_m[has_prior], max_proj[has_prior] = peak_depth_m(np.abs(profiles), prior_m[has_prior] + steps_m[0],
                                                               dz_m)
    return depth_m, max_proj


def reconstruct_bp(signal: np.ndarray, freqs_hz: np.ndarray, antennas: AntennaArray, grid: RadarGrid, *,
                   prior_m: float | np.ndarray | None = None, band_m: float = DEFAULT_BAND_M,
                   threshold_db: float | None = DEFAULT_THRESHOLD_DB, device: str = "cpu",
                   timer: StageTimer | None = None) -> Reconstruction:
    """BP depth map on `grid` from `signal` (n_rx, n_tx, F) at `freqs_hz`; see the module doc for `prior_m`."""
    timer = timer or StageTimer()
    z_m = grid.z_m
    if len(z_m) < 2:
        raise ValueError("BP needs a z grid with at least two samples")
    dz_m = float(z_m[1] - z_m[0])
    if prior_m is not None and not np.isscalar(prior_m):
        depth_m, max_proj = _band_depth_m(signal, freqs_hz, antennas, grid, prior_m, band_m, dz_m, device, timer)
    else:
        if prior_m is not None:
            z_m = z_m[np.abs(z_m - prior_m) <= band_m + 1e-9]
            if len(z_m) == 0:
                raise ValueError(f"no z sample of the grid lies within {band_m} m of the prior {prior_m} m")
        depth_m, max_proj = _volume_depth_m(signal, freqs_hz, antennas, grid, z_m, dz_m, device, timer)
    with timer.stage("filter"):
        depth_m = filter_depth(depth_m, max_proj, threshold_db)
    return Reconstruction(depth_m=depth_m, magnitude=max_proj, freqs_hz=np.asarray(freqs_hz),
                          timings_ms=timer.finish(), grid=grid, method="bp",
                          extra={"band_m": None if prior_m is None else band_m})
