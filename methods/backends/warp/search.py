"""BP's coarse-to-fine depth search on a Warp device end to end (kernels: `search_kernels`): the frame's range
profiles once per frame over the searched box (`FrameProfiles`, shared by the coarse ROI and the search), one
launch for the coarse samples and one for refinement, climb and depth, and one copy back of the (depth, max
projection) maps; the same rules and results as the host-driven `methods.skips.bp_search` over the same values."""
from __future__ import annotations

import numpy as np
import warp as wp

from methods.backends.warp.correlation import range_profiles
from methods.backends.warp.frames import BufferPool, FrameInputs
from methods.backends.warp.kernels import search as search_kernels


class FrameProfiles:
    """The range profiles of the last frame searched, over the box they were built for: a later box inside it (the
    search after the coarse ROI) reuses them, as their values do not depend on the window."""

    def __init__(self):
        self._held = None

    def args(self, inputs: FrameInputs, x_m, y_m, z_m) -> list:
        """The gather's arguments after the points (`correlation.range_profiles`) covering the box of x_m, y_m, z_m
        (coordinate arrays of any length: the box of their values)."""
        lo = np.array([np.min(x_m), np.min(y_m), np.min(z_m)])
        hi = np.array([np.max(x_m), np.max(y_m), np.max(z_m)])
        if self._held is not None:
            held_inputs, held_lo, held_hi, args = self._held
            if held_inputs is inputs and np.all(lo >= held_lo) and np.all(hi <= held_hi):
                return args
        build, args = range_profiles(inputs, inputs.freqs_hz, (np.array([lo[0], hi[0]]), np.array([lo[1], hi[1]]),
                                                               np.array([lo[2], hi[2]])))
        build()
        self._held = (inputs, lo, hi, args)
        return args


def _coarse(inputs, buffers, gather_args, x_m, y_m, z_m, step) -> dict:
    """Launch `search_coarse` over the pixels (x_m, y_m); the device arrays the refinement continues from."""
    dev = inputs.device
    n_px, n_z = len(x_m), len(z_m)
    dz_m = float(z_m[1] - z_m[0]) if n_z > 1 else 1.0
    state = {
        "where": [wp.array(np.asarray(x_m, dtype=np.float64), dtype=wp.float64, device=dev),
                  wp.array(np.asarray(y_m, dtype=np.float64), dtype=wp.float64, device=dev),
                  wp.float64(z_m[0]), wp.float64(dz_m),
                  wp.array(np.asarray(step, dtype=np.int32), dtype=wp.int32, device=dev)],
        "mag": buffers.get("search.mag", (n_px, n_z), wp.float32),
        "level": buffers.get("search.level", (n_px, n_z), wp.int32),
        "coarse_max": buffers.get("search.coarse_max", n_px, wp.float32),
        "peak_k": buffers.get("search.peak_k", n_px, wp.int32),
        "image_max": wp.zeros(1, dtype=wp.float32, device=dev),
        "count": wp.zeros(1, dtype=wp.int32, device=dev)}
    wp.launch_tiled(search_kernels.search_coarse, dim=[n_px], block_dim=search_kernels.SEARCH_BLOCK,
                    inputs=state["where"] + gather_args + [state[k] for k in ("mag", "level", "coarse_max",
                                                                              "image_max", "count", "peak_k")],
                    device=dev)
    return state


def coarse_peaks(inputs: FrameInputs, buffers: BufferPool, profiles: FrameProfiles, x_m, y_m, z_m, step,
                 hull_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Each pixel's coarse maximum over every step-th depth of z_m (and the last), the first depth index holding it,
    and the samples evaluated (`bp_search.coarse_roi`'s coarse pass); profiles over the box of `hull_m` (K, 3)."""
    state = _coarse(inputs, buffers, profiles.args(inputs, *np.asarray(hull_m).T), x_m, y_m, z_m, step)
    return (state["coarse_max"].numpy().copy(), state["peak_k"].numpy().astype(np.int64),
            int(state["count"].numpy()[0]))


def search_depth(inputs: FrameInputs, buffers: BufferPool, profiles: FrameProfiles, x_m: np.ndarray,
                 y_m: np.ndarray, z_m: np.ndarray, plan, threshold_db: float | None,
                 z_edges_are_grid_edges: tuple[bool, bool], hull_m: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, int]:
    """As `bp_search.search_depth` for the pixels (x_m, y_m) (N,) over the equidistant depths z_m, with the
    frame's range-compressed values (many equidistant frequencies): (depth_m, max projection, samples evaluated);
    `plan` a `bp_search.SearchPlan` (step, loss_curve_db, margin_db); profiles over the box of `hull_m` (K, 3),
    which must hold the points."""
    dev = inputs.device
    gather_args = profiles.args(inputs, *np.asarray(hull_m).T)
    state = _coarse(inputs, buffers, gather_args, x_m, y_m, z_m, plan.step)
    loss = wp.array(np.ascontiguousarray(plan.loss_curve_db, dtype=np.float32), dtype=wp.float32, device=dev)
    maps = buffers.get("search.maps", (2, len(x_m)), wp.float64)
    keep_ratio = 0.0 if threshold_db is None else float(10.0 ** (-threshold_db / 20.0))
    wp.launch_tiled(search_kernels.search_refine, dim=[len(x_m)], block_dim=search_kernels.SEARCH_BLOCK,
                    inputs=state["where"] + [loss, wp.float32(plan.margin_db), wp.float32(keep_ratio),
                                             int(z_edges_are_grid_edges[0]), int(z_edges_are_grid_edges[1])]
                    + gather_args + [state[k] for k in ("mag", "level", "coarse_max", "image_max", "count")]
                    + [maps], device=dev)
    host = maps.numpy()
    return host[0].copy(), host[1].copy(), int(state["count"].numpy()[0])
