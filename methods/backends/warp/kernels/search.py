"""Warp kernels of BP's coarse-to-fine depth search on the device (launched by `methods.backends.warp.search`).

The per-pixel rules are `methods.skips.bp_search.search_depth`'s, one block per pixel (its threads split the (Tx
chunk, receiver) units of each sample, `range_partial`, and a tile reduction sums and broadcasts the value, so every
thread takes the same decisions), the samples |V| of every pixel in `mag`
(-1: not evaluated) and the level that evaluated each in `level`, both (N, n_z) so that a pixel's samples
share cache lines:
* `search_coarse`: each pixel's coarse samples (every `step`-th depth and the last), its coarse maximum, and the
  image's coarse maximum (atomic);
* `search_refine`: the filter-aware skip against the image's coarse maximum, then level by level the candidates
  (samples evaluated before the level within its window of the pixel's best) and their +-spacing neighbours, the
  climb to the argmax, and the parabola depth (as `volume_peak_depth`); a peak on a depth edge that is not a grid
  edge gives NaN.
Values come from the range-compressed profiles (the volume's and the point gather's own values).
"""
from __future__ import annotations

import warp as wp

from methods.backends.warp.kernels.correlation import range_partial

SEARCH_OPTIONS = {"enable_backward": False, "max_unroll": 32}
SEARCH_BLOCK = 32                  # threads per pixel on CUDA (one warp)


@wp.func
def sample(p: int, k: int, lane: int, xs: wp.array(dtype=wp.float64), ys: wp.array(dtype=wp.float64), z0_m: wp.float64,
           dz_m: wp.float64, rx: wp.array(dtype=wp.vec3f), tx: wp.array(dtype=wp.vec3f), k_carrier: wp.float32,
           samples_per_m: wp.float32, m0: wp.float32,
           profiles: wp.array2d(dtype=wp.vec2h)) -> wp.float32:
    """|V| of pixel p at depth index k, the same in every thread of the block (lane: this thread's index)."""
    point = wp.vec3d(xs[p], ys[p], z0_m + wp.float64(k) * dz_m)
    part = range_partial(point, lane, wp.block_dim(), rx, tx, k_carrier, samples_per_m, m0, profiles)
    return wp.length(wp.tile_extract(wp.tile_sum(wp.tile(part, preserve_type=True)), 0))


@wp.kernel(module="unique", module_options=SEARCH_OPTIONS)
def search_coarse(xs: wp.array(dtype=wp.float64), ys: wp.array(dtype=wp.float64), z0_m: wp.float64,
                  dz_m: wp.float64, step: wp.array(dtype=wp.int32), rx: wp.array(dtype=wp.vec3f),
                  tx: wp.array(dtype=wp.vec3f), k_carrier: wp.float32, carrier_cycles_per_m: wp.float64,
                  samples_per_m: wp.float32, m0: wp.float32, profiles: wp.array2d(dtype=wp.vec2h),
                  mag: wp.array2d(dtype=wp.float32), level: wp.array2d(dtype=wp.int32),
                  coarse_max: wp.array(dtype=wp.float32), image_max: wp.array(dtype=wp.float32),
                  count: wp.array(dtype=wp.int32), peak_k: wp.array(dtype=wp.int32)):
    """Coarse samples of pixel p (mag set to -1 elsewhere), its maximum and the first depth index holding it, the
    image's maximum (image_max zeroed). Every thread of the block writes the same values."""
    p, lane = wp.tid()
    n_z = mag.shape[1]
    for k in range(lane, n_z, wp.block_dim()):     # (the first sample's tile sum orders these before any use)
        mag[p, k] = -1.0
    s = wp.min(step[p], wp.max(n_z - 1, 1))
    best = wp.float32(0.0)
    kb = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    n = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    k = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    while k < n_z:
        v = sample(p, k, lane, xs, ys, z0_m, dz_m, rx, tx, k_carrier, samples_per_m, m0, profiles)
        mag[p, k] = v
        level[p, k] = 0
        if v > best:
            best = v
            kb = k
        n += 1
        if k == n_z - 1:
            k = n_z
        else:
            k = wp.min(k + s, n_z - 1)
    coarse_max[p] = best
    peak_k[p] = kb
    if lane == 0:
        wp.atomic_max(image_max, 0, best)
        wp.atomic_add(count, 0, n)


@wp.func
def candidate_ratio(loss_curve_db: wp.array2d(dtype=wp.float32), p: int, spacing: int, margin_db: wp.float32
                    ) -> wp.float32:
    """10^(-(loss at spacing + margin) / 20): the candidate window of a level (`SearchPlan.candidate_db`)."""
    k = wp.clamp(spacing, 1, loss_curve_db.shape[1]) - 1
    return wp.pow(10.0, -(loss_curve_db[p, k] + margin_db) / 20.0)


@wp.func
def first_argmax(mag: wp.array2d(dtype=wp.float32), p: int) -> int:
    n_z = mag.shape[1]
    kb = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    best = mag[p, 0]
    for k in range(1, n_z):
        if mag[p, k] > best:
            best = mag[p, k]
            kb = k
    return kb


@wp.func
def db_of(m: wp.float32) -> wp.float64:
    return wp.float64(20.0) * wp.log10(wp.max(wp.float64(m), wp.float64(1.1754943508222875e-38)))


@wp.kernel(module="unique", module_options=SEARCH_OPTIONS)
def search_refine(xs: wp.array(dtype=wp.float64), ys: wp.array(dtype=wp.float64), z0_m: wp.float64,
                  dz_m: wp.float64, step: wp.array(dtype=wp.int32), loss_curve_db: wp.array2d(dtype=wp.float32),
                  margin_db: wp.float32, keep_ratio: wp.float32, edge_lo: int, edge_hi: int,
                  rx: wp.array(dtype=wp.vec3f), tx: wp.array(dtype=wp.vec3f), k_carrier: wp.float32,
                  carrier_cycles_per_m: wp.float64, samples_per_m: wp.float32, m0: wp.float32,
                  profiles: wp.array2d(dtype=wp.vec2h), mag: wp.array2d(dtype=wp.float32),
                  level: wp.array2d(dtype=wp.int32), coarse_max: wp.array(dtype=wp.float32),
                  image_max: wp.array(dtype=wp.float32), count: wp.array(dtype=wp.int32),
                  maps: wp.array2d(dtype=wp.float64)):
    """Refinement, climb and depth of pixel p: maps[0, p] depth (NaN: skipped or on a cut edge), maps[1, p] the
    max projection (the coarse maximum where skipped). keep_ratio 0: no filter-aware skip; edge_lo/edge_hi 1 where
    the first/last depth is a grid edge."""
    p, lane = wp.tid()
    n_z = mag.shape[1]
    spacing = wp.min(step[p], wp.max(n_z - 1, 1))
    window = candidate_ratio(loss_curve_db, p, spacing, margin_db)
    cmax = coarse_max[p]
    active = cmax > 0.0
    if keep_ratio > 0.0:
        active = active and cmax >= image_max[0] * keep_ratio * window
    if not active:
        maps[0, p] = wp.float64(wp.nan)
        maps[1, p] = wp.float64(cmax)
        return
    n = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    lvl = int(1)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    while spacing > 1:
        best = mag[p, first_argmax(mag, p)]
        threshold = best * window
        spacing = (spacing + 1) // 2
        for k in range(n_z):
            if mag[p, k] >= threshold and level[p, k] < lvl:
                for side in range(2):
                    kk = k - spacing + 2 * side * spacing
                    if kk >= 0 and kk < n_z:
                        if mag[p, kk] < 0.0:
                            mag[p, kk] = sample(p, kk, lane, xs, ys, z0_m, dz_m, rx, tx, k_carrier,
                                                samples_per_m, m0, profiles)
                            level[p, kk] = lvl
                            n += 1
        window = candidate_ratio(loss_curve_db, p, spacing, margin_db)
        lvl += 1
    climbing = int(1)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    while climbing == 1:
        kb = first_argmax(mag, p)
        climbing = 0
        for side in range(2):
            kk = kb - 1 + 2 * side
            if kk >= 0 and kk < n_z:
                if mag[p, kk] < 0.0:
                    mag[p, kk] = sample(p, kk, lane, xs, ys, z0_m, dz_m, rx, tx, k_carrier,
                                        samples_per_m, m0, profiles)
                    n += 1
                    climbing = 1
    kb = first_argmax(mag, p)
    db_m = db_of(mag[p, wp.max(kb - 1, 0)])
    db_0 = db_of(mag[p, kb])
    db_p = db_of(mag[p, wp.min(kb + 1, n_z - 1)])
    curvature = db_m - wp.float64(2.0) * db_0 + db_p
    offset = wp.float64(0.0)
    if curvature < wp.float64(0.0):
        offset = wp.float64(0.5) * (db_m - db_p) / curvature
    depth = z0_m + (wp.float64(kb) + offset) * dz_m
    if (kb == 0 and edge_lo == 0) or (kb == n_z - 1 and edge_hi == 0):
        depth = wp.float64(wp.nan)
    maps[0, p] = depth
    maps[1, p] = wp.float64(mag[p, kb])
    if lane == 0:
        wp.atomic_add(count, 0, n)
