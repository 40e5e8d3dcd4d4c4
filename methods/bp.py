"""Back-projection (BP, BP_max): coherent sum over any set of frequencies on a voxel grid, max projection over z,
argmax + 3-point parabola on the dB values (MAROON_FORMAT.md 6.1-6.2).

Depth per pixel: k* = argmax_k |V|, then z = z[k*] + dz (A- - A+) / (2 (A- - 2 A0 + A+)) with A = 20 log10 |V| at
k*-1, k*, k*+1; indices are clipped at the ends of the z range (giving the reference code's -+dz/2 there) and a
flat triple gets no offset. The filter quantity is the linear max projection max_k |V|.

Optional search band around a prior: a scalar prior restricts the z range of the grid to |z - prior| <= band_m;
a per-pixel prior image (ny, nx) samples each pixel at prior + k dz, |k dz| <= band_m (dz = the grid's z step),
and pixels without a prior stay NaN.

Region of interest and skips (methods.skips.roi, methods.skips.settings): with an ROI, only its pixels and depths are
evaluated (the rest NaN); the depth search can run coarse-to-fine with a filter-aware pixel skip (on every device,
through the point kernels; on the host with local-maximum candidates, a 2 mm pixel lattice, the coarse ROI's pass
in two passes and, with many frequencies, each pixel's coarse samples within the coarse ROI's local depths) and, on
the CPU with many frequencies, on range-compressed profiles (methods.skips.bp_search, methods.backends.cpu_range);
with many frequencies on CUDA the coarse ROI's pass and the whole search run on the device (`Backend.coarse_peaks`,
`Backend.search_depth`: the host's rules without its shortcuts, so its depths are those of the host search
with the shortcuts off, and within the skip rule of those with them on). With no ROI
and no skip (`roi=none`) the computation is today's: the rectangular volume through `correlate_volume`.
"""
from __future__ import annotations

import numpy as np

from methods.backends import backend_for, cpu_range
from methods.backends.base import Backend
from methods.domain.antennas import AntennaArray
from methods.domain.capture import RadarGrid
from methods.domain.errors import UsageError
from methods.method import Frame, Method, MethodError
from methods.ops.depth_peak import peak_depth_m
from methods.ops.filtering import DEFAULT_THRESHOLD_DB, filter_depth
from methods.ops.timing import StageTimer
from methods.prior.image import Prior
from methods.reconstruction import Reconstruction
from methods.skips import bp_search
from methods.skips.roi import Roi, full_roi, intersect, pixel_pitch_m
from methods.skips.settings import NONE, SkipSettings

DEFAULT_BAND_M = 0.05


def _z_search(backend: Backend, skips: SkipSettings, dz_m: float, threshold_db: float | None) -> dict:
    """`volume_peak`'s depth-search arguments where `bp_dense_z_search` is on and the backend takes it; with a
    threshold (None: no pixel is skipped; pass it only where the volume's box is the filtered region) pixels whose
    coarse maximum lies `dense_z_margin_db` below it are not refined."""
    if not (skips.bp_dense_z_search and backend.searches_volume_z):
        return {}
    keep_ratio = 0.0 if threshold_db is None else 10.0 ** (-(threshold_db + skips.dense_z_margin_db) / 20.0)
    return {"z_step": max(1, int(round(skips.dense_z_step_m / dz_m))), "z_candidates": skips.dense_z_candidates,
            "z_keep_ratio": keep_ratio}


def _volume_depth_m(signal, freqs_hz, antennas, grid, z_m, dz_m, backend: Backend, timer, skips: SkipSettings,
                    threshold_db):
    """Depth and max projection (ny, nx) from the rectangular volume x_m x y_m (descending) x z_m (on a Warp backend
    the volume stays there; only the (ny, nx) maps come back)."""
    return backend.volume_peak(signal, freqs_hz, antennas.tx_m, antennas.rx_m, grid.x_m, grid.y_m[::-1], z_m, dz_m,
                               timer=timer, **_z_search(backend, skips, dz_m, threshold_db))


def _band_depth_m(signal, freqs_hz, antennas, grid, prior_m, band_m, dz_m, backend, timer, pixels=None):
    """Depth and max projection (ny, nx) from per-pixel profiles prior + k dz, |k dz| <= band_m; NaN: no prior
    (or outside `pixels`, the ROI's pixels, when given)."""
    has_prior = np.isfinite(prior_m) if pixels is None else np.isfinite(prior_m) & pixels
    n_band = int(np.floor(band_m / dz_m + 1e-9))
    steps_m = np.arange(-n_band, n_band + 1) * dz_m
    x_m, y_m = grid.pixel_xy_m()
    points_m = np.stack(np.broadcast_arrays(x_m[has_prior][None], y_m[has_prior][None],
                                            prior_m[has_prior][None] + steps_m[:, None]), axis=-1)
    with timer.stage("correlate"):
        profiles = backend.correlate(signal, freqs_hz, antennas.tx_m, antennas.rx_m,
                                     points_m.reshape(-1, 3)).sum(axis=0).reshape(len(steps_m), -1)
    with timer.stage("depth"):
        depth_m, max_proj = np.full(grid.image_shape, np.nan), np.full(grid.image_shape, np.nan)
        depth_m[has_prior], max_proj[has_prior] = peak_depth_m(np.abs(profiles), prior_m[has_prior] + steps_m[0],
                                                               dz_m)
    return depth_m, max_proj


def _evaluator(signal, freqs_hz, antennas, backend: Backend, use_range, points_hull_m):
    """Frequency-summed correlation at points: the CPU range-compressed gather (table built once over the paths
    of `points_hull_m`, the corners of every point the search may evaluate), or the backend's sum over
    frequencies (on a Warp backend the sum is taken there and only (N,) values come back)."""
    if use_range:
        table = cpu_range.range_table(signal, freqs_hz, *cpu_range.path_bounds_m(antennas.tx_m, antennas.rx_m,
                                                                                 points_hull_m))
        return lambda points_m: cpu_range.correlate_range_cpu(table, antennas.tx_m, antennas.rx_m, points_m)
    return backend.summed_at_points(signal, freqs_hz, antennas.tx_m, antennas.rx_m)


def _window_indices(z_window_m, pixels: np.ndarray, z_m: np.ndarray, pad_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The coarse ROI's depth bounds (low, high) (ny, nx) metres at `pixels`, widened by pad_m on each side, as
    indices into the equidistant z_m."""
    dz_m = float(z_m[1] - z_m[0])
    low = np.ceil((z_window_m[0][pixels] - pad_m - z_m[0]) / dz_m - 1e-6)
    high = np.floor((z_window_m[1][pixels] + pad_m - z_m[0]) / dz_m + 1e-6)
    return np.clip(low, 0, len(z_m) - 1).astype(int), np.clip(high, 0, len(z_m) - 1).astype(int)


def _box_corners_m(x_m, y_m, z_m) -> np.ndarray:
    """(8, 3) corners of the box spanned by the coordinate arrays."""
    return np.array([[x, y, z] for x in (np.min(x_m), np.max(x_m)) for y in (np.min(y_m), np.max(y_m))
                     for z in (np.min(z_m), np.max(z_m))])


def _plan_of(freqs_hz, antennas, z_m, dz_m, skips: SkipSettings):
    """Function (x_m, y_m) -> the coarse-to-fine plan of those pixels (methods.skips.bp_search.plan_search) at the
    nearest depth of z_m."""
    z_near_m = float(np.min(z_m))
    return lambda x_m, y_m: bp_search.plan_search(freqs_hz, antennas, x_m, y_m, z_near_m, dz_m,
                                                  skips.psf_max_loss_db, skips.max_coarse_step_m,
                                                  skips.candidate_margin_db)


def _host_search_options(skips: SkipSettings, grid, pixels: np.ndarray) -> dict:
    """`bp_search.search_depth`'s shortcuts as `skips` set them (only with `bp_coarse_to_fine`): the pixel lattice
    over the searched `pixels` (ny, nx) bool, and local-maximum candidates."""
    if not skips.bp_coarse_to_fine:
        return {}
    lattice = None
    if skips.search_lattice_step_m > 0:
        step_px = skips.lattice_px(pixel_pitch_m(grid), skips.search_lattice_step_m)[0]
        if step_px > 1:
            rows, cols = np.nonzero(pixels)                 # the order of x_img[pixels]
            lattice = bp_search.Lattice(rows, cols, step_px, skips.search_lattice_margin_db,
                                        skips.search_lattice_weak_db, skips.search_lattice_recheck_db)
    return {"lattice": lattice, "local_max": skips.search_local_max, "jump": skips.search_vertex_jump}


def _searched_depth_m(signal, freqs_hz, antennas, grid, z_outer, z_m, dz_m, roi: Roi, skips: SkipSettings,
                      threshold_db, backend, timer, extra: dict):
    """Depth and max projection (ny, nx) over the ROI's pixels and the depths z_m (z_outer, the grid's or the prior
    band's depths, cut to the ROI): coarse ROI, coarse-to-fine search, range compression as `skips` say; NaN
    outside the ROI. A peak on a depth edge of z_m that is not an edge of z_outer gives NaN (bp_search)."""
    x_img, y_img = grid.pixel_xy_m()
    z_edges = ((len(z_m) > 0 and bool(np.isclose(z_m[0], z_outer[0], atol=1e-9))),
               (len(z_m) > 0 and bool(np.isclose(z_m[-1], z_outer[-1], atol=1e-9))))
    use_range = skips.bp_range_cpu and backend.host_range_search and cpu_range.worth_it(freqs_hz)
    pixels = roi.pixels
    n_evaluated, plan, local_z, evaluated = 0, None, None, None
    depth_m, max_proj = np.full(grid.image_shape, np.nan), np.full(grid.image_shape, np.nan)
    with timer.stage("correlate"):
        if pixels.any() and len(z_m):
            hull_m = _box_corners_m(x_img[pixels], y_img[pixels], z_m)
            evaluate = _evaluator(signal, freqs_hz, antennas, backend, use_range, hull_m)
            # the plan from the depths before the coarse ROI narrows them: its nearest depth (the sharpest focus)
            # depends on the grid and mask_bb only, so it is computed once per configuration (bp_search cache)
            plan_of = _plan_of(freqs_hz, antennas, z_m, dz_m, skips)
            if skips.coarse_roi and threshold_db is not None and len(z_m) > 1:
                step_px, radius_px = skips.lattice_px(pixel_pitch_m(grid), skips.roi_lattice_step_m)
                def coarse_peaks(x_m, y_m, z_c, step):       # on the device where the backend can
                    return None if use_range else backend.coarse_peaks(signal, freqs_hz, antennas.tx_m,
                                                                       antennas.rx_m, x_m, y_m, z_c, step, hull_m)
                found, n_coarse = bp_search.coarse_roi(evaluate, pixels, x_img, y_img, z_m, plan_of, threshold_db,
                                                       step_px, radius_px, skips.roi_keep_margin_db,
                                                       skips.roi_margin_m, coarse_peaks,
                                                       None if skips.roi_prepass_margin_db < 0
                                                       else skips.roi_prepass_margin_db)
                n_evaluated += n_coarse
                local_z, evaluated = found.z_window_m, found.evaluated
                extra["coarse_roi_voxels"] = n_coarse
                keep_z = (z_m >= found.z_min_m - 1e-9) & (z_m <= found.z_max_m + 1e-9)
                # the depth edges the coarse ROI cut are ROI edges, not grid edges, from now on
                z_edges = (z_edges[0] and bool(keep_z[0]), z_edges[1] and bool(keep_z[-1]))
                z_m, pixels = z_m[keep_z], found.pixels
                roi = intersect(roi, found)
            if pixels.any() and len(z_m) and backend.prefers_box_volume and not skips.bp_coarse_to_fine:
                n_evaluated += _box_depth_m(signal, freqs_hz, antennas, grid, z_m, dz_m, pixels, z_edges, backend,
                                            depth_m, max_proj)
            elif pixels.any() and len(z_m):
                x_px, y_px = x_img[pixels], y_img[pixels]
                plan = (plan_of(x_px, y_px) if skips.bp_coarse_to_fine
                        else bp_search.SearchPlan.every_sample(len(x_px)))
                on_device = None if use_range else backend.search_depth(
                    signal, freqs_hz, antennas.tx_m, antennas.rx_m, x_px, y_px, z_m, plan, threshold_db, z_edges,
                    hull_m)
                found_depth = None if on_device is None else bp_search.SearchResult(*on_device)
                extra["search_lattice_px"] = 1                      # every pixel evaluates its coarse depths
                if found_depth is None:
                    options = _host_search_options(skips, grid, pixels)
                    if skips.search_local_z and local_z is not None and len(z_m) > 1:
                        options["z_window"] = _window_indices(local_z, pixels, z_m, skips.search_local_z_pad_m)
                    if evaluated is not None:           # the coarse ROI's values at its lattice pixels
                        options["known"] = evaluated.for_search(*np.nonzero(pixels), z_m)
                    found_depth = bp_search.search_depth(evaluate, x_px, y_px, z_m, plan, threshold_db, z_edges,
                                                         **options)
                    if options.get("lattice"):
                        extra["search_lattice_px"] = options["lattice"].step_px
                depth_m[pixels], max_proj[pixels] = found_depth.depth_m, found_depth.max_projection
                n_evaluated += found_depth.n_evaluated
    extra.update(roi_px=int(pixels.sum()), roi_z_m=(float(z_m[0]), float(z_m[-1])) if len(z_m) else None,
                 evaluated_voxels=n_evaluated, range_cpu=use_range, roi_sources=roi.sources,
                 coarse_step_median=None if plan is None else float(np.median(plan.step)))
    return depth_m, max_proj


def _box_depth_m(signal, freqs_hz, antennas, grid, z_m, dz_m, pixels, z_edges, backend, depth_m, max_proj) -> int:
    """Every depth sample of the ROI's pixels (the search with step 1) as a Warp device computes it fastest: the
    dense volume over their bounding box (H100, two frequencies: coarse ROI + box 55 ms against 790 ms through
    the point search; the whole grid's volume, 40 ms, is still faster on the catalogue, so `roi=auto` leaves the
    coarse ROI off there), into depth_m / max_proj (ny, nx) at `pixels`; as the search, a peak on a depth edge of
    z_m that is not a grid edge (`z_edges` False there) gives NaN. Returns the voxels evaluated."""
    rows, cols = np.nonzero(pixels)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    box_depth, box_proj = backend.volume_peak(signal, freqs_hz, antennas.tx_m, antennas.rx_m, grid.x_m[c0:c1],
                                              grid.y_m[::-1][r0:r1], z_m, dz_m)
    # the parabola puts an argmax at the first sample at or before it (offset -1/2 or 0), one at the second at or
    # after z_m[0] + dz / 2: so depth <= z_m[0] + dz / 4 is exactly argmax 0 (the last sample likewise)
    on_cut = (((box_depth <= z_m[0] + dz_m / 4) & (not z_edges[0]))
              | ((box_depth >= z_m[-1] - dz_m / 4) & (not z_edges[1])))
    inside = pixels[r0:r1, c0:c1]
    depth_m[r0:r1, c0:c1] = np.where(inside & ~on_cut, box_depth, depth_m[r0:r1, c0:c1])
    max_proj[r0:r1, c0:c1] = np.where(inside, box_proj, max_proj[r0:r1, c0:c1])
    return int((r1 - r0) * (c1 - c0) * len(z_m))


def _warp_roi_depth_m(signal, freqs_hz, antennas, grid, z_m, dz_m, roi: Roi, backend, timer, extra: dict,
                      skips: SkipSettings, threshold_db):
    """Warp devices: the rectangular volume over the ROI's bounding box (rows, columns, z_m), NaN outside the ROI."""
    rows, cols = np.nonzero(roi.pixels)
    depth_m, max_proj = np.full(grid.image_shape, np.nan), np.full(grid.image_shape, np.nan)
    if len(rows) and len(z_m):
        r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
        inside = roi.pixels[r0:r1, c0:c1]
        box_depth, box_proj = backend.volume_peak(signal, freqs_hz, antennas.tx_m, antennas.rx_m, grid.x_m[c0:c1],
                                                  grid.y_m[::-1][r0:r1], z_m, dz_m, timer=timer,
                                                  **_z_search(backend, skips, dz_m,
                                                              threshold_db if inside.all() else None))
        depth_m[r0:r1, c0:c1] = np.where(inside, box_depth, np.nan)
        max_proj[r0:r1, c0:c1] = np.where(inside, box_proj, np.nan)
        extra.update(evaluated_voxels=int((r1 - r0) * (c1 - c0) * len(z_m)))
    extra.update(roi_px=roi.n_pixels, roi_z_m=(float(z_m[0]), float(z_m[-1])) if len(z_m) else None,
                 roi_sources=roi.sources)
    return depth_m, max_proj


def reconstruct_bp(signal: np.ndarray, freqs_hz: np.ndarray, antennas: AntennaArray, grid: RadarGrid, *,
                   prior_m: float | np.ndarray | None = None, band_m: float = DEFAULT_BAND_M,
                   threshold_db: float | None = DEFAULT_THRESHOLD_DB, backend: Backend | str = "cpu",
                   timer: StageTimer | None = None, roi: Roi | None = None,
                   skips: SkipSettings = NONE) -> Reconstruction:
    """BP depth map on `grid` from `signal` (n_rx, n_tx, F) at `freqs_hz`; see the module doc for `prior_m`.

    `roi` (methods.skips.roi; None = the whole grid) bounds the pixels and depths evaluated; `skips`
    (methods.skips.settings)
    switches the coarse ROI, the coarse-to-fine search and CPU range compression (the last two on the CPU only).
    """
    timer = timer or StageTimer()
    backend = backend_for(backend)
    z_m = grid.z_m
    if len(z_m) < 2:
        raise UsageError("BP needs a z grid with at least two samples")
    dz_m = float(z_m[1] - z_m[0])
    roi = roi if roi is not None else full_roi(grid)
    extra: dict = {"band_m": None if prior_m is None else band_m}
    if prior_m is not None and not np.isscalar(prior_m):
        pixels = None if roi.pixels.all() else roi.pixels
        depth_m, max_proj = _band_depth_m(signal, freqs_hz, antennas, grid, prior_m, band_m, dz_m, backend, timer,
                                          pixels)
        extra.update(roi_px=int((np.isfinite(prior_m) & roi.pixels).sum()), roi_sources=roi.sources + ("prior",))
    else:
        if prior_m is not None:
            z_m = z_m[np.abs(z_m - prior_m) <= band_m + 1e-9]
            if len(z_m) == 0:
                raise UsageError(f"no z sample of the grid lies within {band_m} m of the prior {prior_m} m")
        z_outer = z_m                          # the depths today's computation searches (grid, or prior band)
        z_m = z_outer[roi.z_indices(z_outer)]
        roi_cuts = not roi.pixels.all() or len(z_m) != len(z_outer)
        host_range = backend.host_range_search and skips.bp_range_cpu and cpu_range.worth_it(freqs_hz)
        searched = skips.coarse_roi or skips.bp_coarse_to_fine or host_range
        if searched or (roi_cuts and not backend.prefers_box_volume):
            with backend.holding_frame(signal):        # the search looks the frame up several times
                depth_m, max_proj = _searched_depth_m(signal, freqs_hz, antennas, grid, z_outer, z_m, dz_m, roi,
                                                      skips, threshold_db, backend, timer, extra)
        elif roi_cuts:
            depth_m, max_proj = _warp_roi_depth_m(signal, freqs_hz, antennas, grid, z_m, dz_m, roi, backend, timer,
                                                  extra, skips, threshold_db)
        else:
            depth_m, max_proj = _volume_depth_m(signal, freqs_hz, antennas, grid, z_m, dz_m, backend, timer, skips,
                                                threshold_db)
            extra.update(roi_px=roi.n_pixels, evaluated_voxels=roi.n_pixels * len(z_m), roi_sources=roi.sources)
    with timer.stage("filter"):
        depth_m = filter_depth(depth_m, max_proj, threshold_db)
    return Reconstruction(depth_m=depth_m, magnitude=max_proj, freqs_hz=np.asarray(freqs_hz),
                          timings_ms=timer.finish(), grid=grid, method="bp", extra=extra)


class BP(Method):
    """Back-projection (module doc): BP over any frequencies; BP_max with all of them (`freq=full`)."""

    name = "bp"
    label = "BP"
    n_freqs = None
    priors = ("none", "scalar", "realsense", "photogrammetry")
    params = {"band_m": DEFAULT_BAND_M}
    uses_volume = True

    def check(self, n_freqs: int, freq: object, prior: str | float | None) -> None:
        super().check(n_freqs, freq, prior)
        if "band_m" in self.given and prior is None:
            raise MethodError("band_m sets BP's search band around a prior; give a prior as well")

    def warm_up(self, freqs_hz, antennas, grid, skips, prior) -> None:
        """The search plan's point-target loss table (`bp_search.plan_search`, cached per process and configuration;
        0.65 s on two cores for BP_max's 128 frequencies) for the depths `run` will search with a scalar prior or
        none, where the skips plan a search: so a first timed call does not build it (a `mask_bb_depth` ROI that
        moves the nearest depth still builds its own there)."""
        if not (skips.bp_coarse_to_fine or skips.coarse_roi) or isinstance(prior, str):
            return
        z_m = grid.z_m                                       # as `reconstruct_bp` cuts it (a full-grid ROI)
        if len(z_m) < 2:
            return
        dz_m = float(z_m[1] - z_m[0])
        if prior is not None:
            z_m = z_m[np.abs(z_m - prior) <= self.values["band_m"] + 1e-9]
        if len(z_m):
            _plan_of(freqs_hz, antennas, z_m, dz_m, skips)(np.zeros(1), np.zeros(1))

    def run(self, frame: Frame, prior: Prior | float | None, backend: Backend, timer: StageTimer) -> Reconstruction:
        prior_m = prior.host_m() if isinstance(prior, Prior) else prior
        return reconstruct_bp(frame.signal, frame.freqs_hz, frame.antennas, frame.grid, prior_m=prior_m,
                              band_m=self.values["band_m"], threshold_db=frame.threshold_db, backend=backend,
                              timer=timer, roi=frame.roi, skips=frame.skips)
