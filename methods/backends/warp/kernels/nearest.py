"""Warp kernels of the exact nearest-neighbour search by brute force (launched by `methods.backends.warp.nearest`).

Each query point's nearest point is found in slices of the point set (`nearest_in_slices`: thread (slice, query),
consecutive threads on consecutive queries of one slice, so a warp's 32 threads read the same point at once) and
the slices' winners are then compared (`pick_nearest`). Squared distances in float64, summed as SciPy's cKDTree
sums them for p = 2 ((dx^2 + dy^2) + dz^2), with floating-point contraction off for this module: an FMA would
round (dx^2 + dy^2) + dz^2 once instead of twice, so two points whose distances differ in the last bits could be
ordered otherwise than on the host. Ties (equal squared distances) go to the lower point index, in both kernels.
"""
from __future__ import annotations

import warp as wp

wp.set_module_options({"fuse_fp": False, "enable_backward": False})


@wp.func
def squared_distance(a: wp.vec3d, b: wp.vec3d) -> wp.float64:
    dx = a[0] - b[0]
    dy = a[1] - b[1]
    dz = a[2] - b[2]
    return (dx * dx + dy * dy) + dz * dz


@wp.kernel
def nearest_in_slices(queries: wp.array(dtype=wp.vec3d), points: wp.array(dtype=wp.vec3d), n_queries: int,
                      n_points: int, slice_points: int, best_d2: wp.array(dtype=wp.float64),
                      best_index: wp.array(dtype=wp.int32)):
    """Thread s * n_queries + q: the nearest of points [s * slice_points, (s + 1) * slice_points) to query q (every
    slice holds at least one point)."""
    t = wp.tid()
    q = t % n_queries
    first = (t // n_queries) * slice_points
    last = wp.min(first + slice_points, n_points)
    a = queries[q]
    best = squared_distance(a, points[first])
    index = first
    for j in range(first + 1, last):
        d2 = squared_distance(a, points[j])
        if d2 < best:
            best = d2
            index = j
    best_d2[t] = best
    best_index[t] = index


@wp.kernel
def pick_nearest(best_d2: wp.array(dtype=wp.float64), best_index: wp.array(dtype=wp.int32), n_queries: int,
                 n_slices: int, offset: int, nearest: wp.array(dtype=wp.int32)):
    """nearest[offset + q]: the point index of query q's nearest over the slices (in slice order: a tie keeps the
    earlier slice's, i.e. lower, index)."""
    q = wp.tid()
    best = best_d2[q]
    index = best_index[q]
    for s in range(1, n_slices):
        d2 = best_d2[s * n_queries + q]
        if d2 < best:
            best = d2
            index = best_index[s * n_queries + q]
    nearest[offset + q] = index
