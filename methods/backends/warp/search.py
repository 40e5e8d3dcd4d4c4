"""BP's coarse-to-fine depth search on a Warp device end to end (kernels: `search_kernels`): the frame's range
profiles once per frame over the searched box (`FrameProfiles`, shared by the coarse ROI and the search), built
from the uploaded raw frame; the coarse samples of every pixel in one launch (a thread per sample), then per
refinement level one launch that queues each pixel's samples and one that evaluates them (a thread per sample),
the climb and depth per pixel, and one copy back of the (depth, max projection) maps; the same rules and results as
the host-driven `methods.skips.bp_search` over the same values (each sample is the point gather's own sum)."""
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
    """Each pixel's coarse samples (`search_coarse` and `coarse_reduce`) over the pixels (x_m, y_m); the device
    arrays the refinement continues from."""
    dev = inputs.device
    n_px, n_z = len(x_m), len(z_m)
    dz_m = float(z_m[1] - z_m[0]) if n_z > 1 else 1.0
    spacing = np.minimum(np.asarray(step, dtype=np.int64), max(n_z - 1, 1))
    state = {
        "where": [wp.array(np.asarray(x_m, dtype=np.float64), dtype=wp.float64, device=dev),
                  wp.array(np.asarray(y_m, dtype=np.float64), dtype=wp.float64, device=dev),
                  wp.float64(z_m[0]), wp.float64(dz_m)],
        "step": wp.array(np.asarray(step, dtype=np.int32), dtype=wp.int32, device=dev),
        "spacing_max": int(spacing.max()) if n_px else 1,
        "mag": buffers.get("search.mag", (n_px, n_z), wp.float32),
        "level": buffers.get("search.level", (n_px, n_z), wp.int32),
        "coarse_max": buffers.get("search.coarse_max", n_px, wp.float32),
        "peak_k": buffers.get("search.peak_k", n_px, wp.int32),
        "image_max": wp.zeros(1, dtype=wp.float32, device=dev),
        "count": wp.zeros(1, dtype=wp.int32, device=dev)}
    if n_px == 0:
        return state
    state["mag"].fill_(search_kernels.NOT_EVALUATED)
    n_coarse = (n_z - 1 + int(spacing.min()) - 1) // int(spacing.min()) + 1     # the samples of the finest step
    wp.launch(search_kernels.coarse_samples, dim=n_px * n_coarse,
              inputs=state["where"] + [state["step"]] + gather_args + [state["mag"], state["level"]], device=dev)
    wp.launch(search_kernels.coarse_reduce, dim=n_px,
              inputs=[state["step"]] + [state[k] for k in ("mag", "coarse_max", "peak_k", "image_max", "count")],
              device=dev)
    return state


def coarse_peaks(inputs: FrameInputs, buffers: BufferPool, profiles: FrameProfiles, x_m, y_m, z_m, step,
                 hull_m: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Each pixel's coarse maximum over every step-th depth of z_m (and the last), the first depth index holding it,
    and the samples evaluated (`bp_search.coarse_roi`'s coarse pass); profiles over the box of `hull_m` (K, 3)."""
    state = _coarse(inputs, buffers, profiles.args(inputs, *np.asarray(hull_m).T), x_m, y_m, z_m, step)
    return (state["coarse_max"].numpy().copy(), state["peak_k"].numpy().astype(np.int64),
            int(state["count"].numpy()[0]))


def _levels(spacing: int) -> int:
    """Refinement levels of a coarse spacing: halvings (rounded up) until 1."""
    n = 0
    while spacing > 1:
        spacing, n = (spacing + 1) // 2, n + 1
    return n


def search_depth(inputs: FrameInputs, buffers: BufferPool, profiles: FrameProfiles, x_m: np.ndarray,
                 y_m: np.ndarray, z_m: np.ndarray, plan, threshold_db: float | None,
                 z_edges_are_grid_edges: tuple[bool, bool], hull_m: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, int]:
    """As `bp_search.search_depth` for the pixels (x_m, y_m) (N,) over the equidistant depths z_m, with the
    frame's range-compressed values (many equidistant frequencies): (depth_m, max projection, samples evaluated);
    `plan` a `bp_search.SearchPlan` (step, loss_curve_db, margin_db); profiles over the box of `hull_m` (K, 3),
    which must hold the points."""
    dev = inputs.device
    n_px, n_z = len(x_m), len(z_m)
    gather_args = profiles.args(inputs, *np.asarray(hull_m).T)
    state = _coarse(inputs, buffers, gather_args, x_m, y_m, z_m, plan.step)
    if n_px == 0:
        return np.zeros(0), np.zeros(0), 0
    loss = wp.array(np.ascontiguousarray(plan.loss_curve_db, dtype=np.float32), dtype=wp.float32, device=dev)
    keep_ratio = 0.0 if threshold_db is None else float(10.0 ** (-threshold_db / 20.0))
    rule = [state["step"], loss, wp.float32(plan.margin_db), wp.float32(keep_ratio)]
    mag, level, count = state["mag"], state["level"], state["count"]
    n_levels = _levels(state["spacing_max"])
    queued = wp.zeros(max(n_levels, 1), dtype=wp.int32, device=dev)
    todo = buffers.get("search.todo", n_px * n_z, wp.int32)
    for lvl in range(1, n_levels + 1):
        wp.launch(search_kernels.level_queue, dim=n_px,
                  inputs=[lvl] + rule + [state["coarse_max"], state["image_max"], mag, level, queued, todo, count],
                  device=dev)
        wp.launch(search_kernels.evaluate_queued, dim=n_px * n_z,
                  inputs=[lvl, queued, todo] + state["where"] + gather_args + [mag, level], device=dev)
    maps = buffers.get("search.maps", (2, n_px), wp.float64)
    wp.launch(search_kernels.search_finish, dim=n_px,
              inputs=state["where"] + rule + [int(z_edges_are_grid_edges[0]), int(z_edges_are_grid_edges[1])]
              + gather_args + [mag, state["coarse_max"], state["image_max"], count, maps], device=dev)
    host = maps.numpy()
    return host[0].copy(), host[1].copy(), int(count.numpy()[0])
