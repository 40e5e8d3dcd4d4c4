"""Warp kernels of BP's coarse-to-fine depth search on the device (launched by `methods.backends.warp.search`).

The per-pixel rules are `methods.skips.bp_search.search_depth`'s, run level-synchronously over every pixel: each
sample |V| is one thread's `range_partial` (the point gather's own function and summation order, so a sample has the
host search's value; neighbouring threads read neighbouring positions of the same range-profile rows), and the
per-pixel decisions are one thread per pixel between the evaluation launches. The samples of every pixel are in
`mag` (N, n_z) (-1: not evaluated, -2: queued for this level's evaluation) and the level that evaluated each in
`level`:
* `coarse_samples` (one thread per pixel and coarse sample: every `step`-th depth and the last) and
  `coarse_reduce` (per pixel: its coarse maximum, first depth index of it, the image's coarse maximum, the count);
* per refinement level, `level_queue` (per pixel: the filter-aware skip against the image's coarse maximum, the
  candidates, i.e. samples evaluated before the level within its window of the pixel's best, and their unevaluated
  +-spacing neighbours queued in `todo`) and `evaluate_queued` (one thread per queued sample);
* `search_finish` (per pixel): the climb to the argmax and the parabola depth (as `volume_peak_depth`); a peak on a
  depth edge that is not a grid edge gives NaN.
Values come from the range-compressed profiles (the volume's and the point gather's own values).
"""
from __future__ import annotations

import warp as wp

from methods.backends.warp.kernels.correlation import range_partial

SEARCH_OPTIONS = {"enable_backward": False, "max_unroll": 32}
NOT_EVALUATED = wp.constant(-1.0)
QUEUED = wp.constant(-2.0)


@wp.func
def sample(p: int, k: int, xs: wp.array(dtype=wp.float64), ys: wp.array(dtype=wp.float64), z0_m: wp.float64,
           dz_m: wp.float64, rx: wp.array(dtype=wp.vec3f), tx: wp.array(dtype=wp.vec3f), k_carrier: wp.float32,
           samples_per_m: wp.float32, m0: wp.float32, profiles: wp.array2d(dtype=wp.vec2h)) -> wp.float32:
    """|V| of pixel p at depth index k (one thread: `range_gather`'s sum without its unit-modulus common phasor)."""
    point = wp.vec3d(xs[p], ys[p], z0_m + wp.float64(k) * dz_m)
    return wp.length(range_partial(point, 0, 1, rx, tx, k_carrier, samples_per_m, m0, profiles))


@wp.func
def coarse_spacing(step: wp.array(dtype=wp.int32), p: int, n_z: int) -> int:
    return wp.min(step[p], wp.max(n_z - 1, 1))


@wp.kernel(module="unique", module_options=SEARCH_OPTIONS)
def coarse_samples(xs: wp.array(dtype=wp.float64), ys: wp.array(dtype=wp.float64), z0_m: wp.float64,
                   dz_m: wp.float64, step: wp.array(dtype=wp.int32), rx: wp.array(dtype=wp.vec3f),
                   tx: wp.array(dtype=wp.vec3f), k_carrier: wp.float32, carrier_cycles_per_m: wp.float64,
                   samples_per_m: wp.float32, m0: wp.float32, profiles: wp.array2d(dtype=wp.vec2h),
                   mag: wp.array2d(dtype=wp.float32), level: wp.array2d(dtype=wp.int32)):
    """Thread i: coarse sample c = i // N of pixel p = i % N (depth c * step, the last depth for the first c past it;
    threads beyond return). mag must hold NOT_EVALUATED elsewhere."""
    i = wp.tid()
    n_px = xs.shape[0]
    n_z = mag.shape[1]
    p = i % n_px
    c = i // n_px
    s = coarse_spacing(step, p, n_z)
    k = c * s
    if k >= n_z - 1:
        if c > 0 and (c - 1) * s >= n_z - 1:
            return
        k = n_z - 1
    mag[p, k] = sample(p, k, xs, ys, z0_m, dz_m, rx, tx, k_carrier, samples_per_m, m0, profiles)
    level[p, k] = 0


@wp.kernel(module="unique", module_options=SEARCH_OPTIONS)
def coarse_reduce(step: wp.array(dtype=wp.int32), mag: wp.array2d(dtype=wp.float32),
                  coarse_max: wp.array(dtype=wp.float32), peak_k: wp.array(dtype=wp.int32),
                  image_max: wp.array(dtype=wp.float32), count: wp.array(dtype=wp.int32)):
    """Pixel p's coarse maximum and the first depth index holding it; the image's maximum and the samples counted
    (image_max and count zeroed before)."""
    p = wp.tid()
    n_z = mag.shape[1]
    s = coarse_spacing(step, p, n_z)
    best = wp.float32(0.0)
    kb = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    n = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    k = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    while k < n_z:
        v = mag[p, k]
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
def searched(p: int, step: wp.array(dtype=wp.int32), n_z: int, loss_curve_db: wp.array2d(dtype=wp.float32),
             margin_db: wp.float32, keep_ratio: wp.float32, coarse_max: wp.array(dtype=wp.float32),
             image_max: wp.array(dtype=wp.float32)) -> bool:
    """Pixel p is refined: a non-zero coarse maximum that the filter-aware skip keeps (keep_ratio 0: no skip)."""
    cmax = coarse_max[p]
    active = cmax > 0.0
    if keep_ratio > 0.0:
        window = candidate_ratio(loss_curve_db, p, coarse_spacing(step, p, n_z), margin_db)
        active = active and cmax >= image_max[0] * keep_ratio * window
    return active


@wp.kernel(module="unique", module_options=SEARCH_OPTIONS)
def level_queue(lvl: int, step: wp.array(dtype=wp.int32), loss_curve_db: wp.array2d(dtype=wp.float32),
                margin_db: wp.float32, keep_ratio: wp.float32, coarse_max: wp.array(dtype=wp.float32),
                image_max: wp.array(dtype=wp.float32), mag: wp.array2d(dtype=wp.float32),
                level: wp.array2d(dtype=wp.int32), queued: wp.array(dtype=wp.int32), todo: wp.array(dtype=wp.int32),
                count: wp.array(dtype=wp.int32)):
    """Level lvl (1, 2, ...) of pixel p: its spacing halves (rounded up) from the coarse step once per level while
    above 1; the candidates (evaluated before the level, within the window of the previous spacing of the pixel's
    best) queue their unevaluated neighbours at +-spacing into todo (p * n_z + k) after queued[lvl - 1] (zeroed)."""
    p = wp.tid()
    n_z = mag.shape[1]
    if not searched(p, step, n_z, loss_curve_db, margin_db, keep_ratio, coarse_max, image_max):
        return
    previous = coarse_spacing(step, p, n_z)
    for _level in range(lvl - 1):
        previous = (previous + 1) // 2
    if previous <= 1:
        return
    threshold = mag[p, first_argmax(mag, p)] * candidate_ratio(loss_curve_db, p, previous, margin_db)
    spacing = (previous + 1) // 2
    n = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    for k in range(n_z):
        if mag[p, k] >= threshold and level[p, k] < lvl:
            for side in range(2):
                kk = k - spacing + 2 * side * spacing
                if kk >= 0 and kk < n_z:
                    if mag[p, kk] == NOT_EVALUATED:
                        mag[p, kk] = QUEUED
                        n += 1
    if n > 0:
        j = wp.atomic_add(queued, lvl - 1, n)
        wp.atomic_add(count, 0, n)
        for k in range(n_z):
            if mag[p, k] == QUEUED:
                todo[j] = p * n_z + k
                j += 1


@wp.kernel(module="unique", module_options=SEARCH_OPTIONS)
def evaluate_queued(lvl: int, queued: wp.array(dtype=wp.int32), todo: wp.array(dtype=wp.int32),
                    xs: wp.array(dtype=wp.float64), ys: wp.array(dtype=wp.float64), z0_m: wp.float64,
                    dz_m: wp.float64, rx: wp.array(dtype=wp.vec3f), tx: wp.array(dtype=wp.vec3f),
                    k_carrier: wp.float32, carrier_cycles_per_m: wp.float64, samples_per_m: wp.float32,
                    m0: wp.float32, profiles: wp.array2d(dtype=wp.vec2h), mag: wp.array2d(dtype=wp.float32),
                    level: wp.array2d(dtype=wp.int32)):
    """Thread i < queued[lvl - 1]: the queued sample todo[i] evaluated at level lvl."""
    i = wp.tid()
    if i >= queued[lvl - 1]:
        return
    n_z = mag.shape[1]
    p = todo[i] // n_z
    k = todo[i] % n_z
    mag[p, k] = sample(p, k, xs, ys, z0_m, dz_m, rx, tx, k_carrier, samples_per_m, m0, profiles)
    level[p, k] = lvl


@wp.func
def db_of(m: wp.float32) -> wp.float64:
    return wp.float64(20.0) * wp.log10(wp.max(wp.float64(m), wp.float64(1.1754943508222875e-38)))


@wp.kernel(module="unique", module_options=SEARCH_OPTIONS)
def search_finish(xs: wp.array(dtype=wp.float64), ys: wp.array(dtype=wp.float64), z0_m: wp.float64,
                  dz_m: wp.float64, step: wp.array(dtype=wp.int32), loss_curve_db: wp.array2d(dtype=wp.float32),
                  margin_db: wp.float32, keep_ratio: wp.float32, edge_lo: int, edge_hi: int,
                  rx: wp.array(dtype=wp.vec3f), tx: wp.array(dtype=wp.vec3f), k_carrier: wp.float32,
                  carrier_cycles_per_m: wp.float64, samples_per_m: wp.float32, m0: wp.float32,
                  profiles: wp.array2d(dtype=wp.vec2h), mag: wp.array2d(dtype=wp.float32),
                  coarse_max: wp.array(dtype=wp.float32), image_max: wp.array(dtype=wp.float32),
                  count: wp.array(dtype=wp.int32), maps: wp.array2d(dtype=wp.float64)):
    """Climb and depth of pixel p after its levels: maps[0, p] depth (NaN: skipped or on a cut edge), maps[1, p]
    the max projection (the coarse maximum where skipped). keep_ratio 0: no filter-aware skip; edge_lo/edge_hi 1
    where the first/last depth is a grid edge."""
    p = wp.tid()
    n_z = mag.shape[1]
    if not searched(p, step, n_z, loss_curve_db, margin_db, keep_ratio, coarse_max, image_max):
        maps[0, p] = wp.float64(wp.nan)
        maps[1, p] = wp.float64(coarse_max[p])
        return
    n = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    climbing = int(1)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    while climbing == 1:
        kb = first_argmax(mag, p)
        climbing = 0
        for side in range(2):
            kk = kb - 1 + 2 * side
            if kk >= 0 and kk < n_z:
                if mag[p, kk] < 0.0:
                    mag[p, kk] = sample(p, kk, xs, ys, z0_m, dz_m, rx, tx, k_carrier, samples_per_m, m0, profiles)
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
    if n > 0:
        wp.atomic_add(count, 0, n)
