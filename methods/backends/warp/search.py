"""BP's coarse-to-fine depth search on a Warp device end to end (kernels: `search_kernels`): the frame's range
profiles once over the searched box, one launch for the coarse samples and one for refinement, climb and depth,
and one copy back of the (depth, max projection) maps; the same rules and results as the host-driven
`methods.skips.bp_search.search_depth` over the same values."""
from __future__ import annotations

import numpy as np
import warp as wp

from methods.backends.warp import search_kernels
from methods.backends.warp.correlation import range_profiles
from methods.backends.warp.frames import BufferPool, FrameInputs
from methods.skips.bp_search import SearchPlan, SearchResult


def search_depth(inputs: FrameInputs, buffers: BufferPool, x_m: np.ndarray, y_m: np.ndarray, z_m: np.ndarray,
                 plan: SearchPlan, threshold_db: float | None, z_edges_are_grid_edges: tuple[bool, bool]
                 ) -> SearchResult:
    """As `bp_search.search_depth` for the pixels (x_m, y_m) (N,) over the equidistant depths z_m, with the
    frame's range-compressed values (many equidistant frequencies)."""
    dev = inputs.device
    n_px, n_z = len(x_m), len(z_m)
    dz_m = float(z_m[1] - z_m[0]) if n_z > 1 else 1.0
    build, gather_args = range_profiles(inputs, inputs.freqs_hz, (x_m, y_m, z_m))
    xs = wp.array(np.asarray(x_m, dtype=np.float64), dtype=wp.float64, device=dev)
    ys = wp.array(np.asarray(y_m, dtype=np.float64), dtype=wp.float64, device=dev)
    step = wp.array(np.asarray(plan.step, dtype=np.int32), dtype=wp.int32, device=dev)
    loss = wp.array(np.ascontiguousarray(plan.loss_curve_db, dtype=np.float32), dtype=wp.float32, device=dev)
    mag = buffers.get("search.mag", (n_z, n_px), wp.float32)
    level = buffers.get("search.level", (n_z, n_px), wp.int32)
    coarse_max = buffers.get("search.coarse_max", n_px, wp.float32)
    maps = buffers.get("search.maps", (2, n_px), wp.float64)
    image_max = wp.zeros(1, dtype=wp.float32, device=dev)
    count = wp.zeros(1, dtype=wp.int32, device=dev)
    keep_ratio = 0.0 if threshold_db is None else float(10.0 ** (-threshold_db / 20.0))
    where = [xs, ys, wp.float64(z_m[0]), wp.float64(dz_m), step]
    build()
    block = search_kernels.SEARCH_BLOCK
    wp.launch_tiled(search_kernels.search_coarse, dim=[n_px], block_dim=block,
                    inputs=where + gather_args + [mag, level, coarse_max, image_max, count], device=dev)
    wp.launch_tiled(search_kernels.search_refine, dim=[n_px], block_dim=block,
                    inputs=where + [loss, wp.float32(plan.margin_db), wp.float32(keep_ratio),
                                    int(z_edges_are_grid_edges[0]), int(z_edges_are_grid_edges[1])]
                    + gather_args + [mag, level, coarse_max, image_max, count, maps], device=dev)
    host = maps.numpy()
    return SearchResult(host[0].copy(), host[1].copy(), int(count.numpy()[0]))
