"""Warp kernels of the exact nearest-neighbour search by brute force (launched by `methods.backends.warp.nearest`).

Each query point's nearest point is found in slices of the point set (`nearest_in_slices`: thread (slice, four
queries), consecutive threads on consecutive queries of one slice, so a warp's 32 threads read the same point at
once) and
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


#: queries a thread compares with each point it reads (a point's three loads then serve four distances)
QUERIES_PER_THREAD = 4


@wp.func
def keep_nearest(a: wp.vec3d, p: wp.vec3d, j: int, best: wp.float64, index: int):
    d2 = squared_distance(a, p)
    if d2 < best:
        return d2, j
    return best, index


@wp.kernel
def nearest_in_slices(queries: wp.array(dtype=wp.vec3d), points: wp.array(dtype=wp.vec3d), n_queries: int,
                      n_points: int, slice_points: int, best_d2: wp.array(dtype=wp.float64),
                      best_index: wp.array(dtype=wp.int32)):
    """Thread s * n_groups + g, n_groups = ceil(n_queries / 4): the nearest of points [s * slice_points, (s + 1) *
    slice_points) to queries g, g + n_groups, g + 2 n_groups, g + 3 n_groups (those < n_queries; every slice holds
    at least one point); written at s * n_queries + q."""
    t = wp.tid()
    n_groups = (n_queries + 3) // 4
    g = t % n_groups
    s = t // n_groups
    first = s * slice_points
    last = wp.min(first + slice_points, n_points)
    q0 = g
    q1 = wp.min(g + n_groups, n_queries - 1)
    q2 = wp.min(g + 2 * n_groups, n_queries - 1)
    q3 = wp.min(g + 3 * n_groups, n_queries - 1)
    a0 = queries[q0]
    a1 = queries[q1]
    a2 = queries[q2]
    a3 = queries[q3]
    p = points[first]
    b0 = squared_distance(a0, p)
    b1 = squared_distance(a1, p)
    b2 = squared_distance(a2, p)
    b3 = squared_distance(a3, p)
    i0 = first
    i1 = first
    i2 = first
    i3 = first
    for j in range(first + 1, last):
        p = points[j]
        b0, i0 = keep_nearest(a0, p, j, b0, i0)
        b1, i1 = keep_nearest(a1, p, j, b1, i1)
        b2, i2 = keep_nearest(a2, p, j, b2, i2)
        b3, i3 = keep_nearest(a3, p, j, b3, i3)
    row = s * n_queries
    best_d2[row + q0] = b0
    best_index[row + q0] = i0
    if g + n_groups < n_queries:
        best_d2[row + q1] = b1
        best_index[row + q1] = i1
    if g + 2 * n_groups < n_queries:
        best_d2[row + q2] = b2
        best_index[row + q2] = i2
    if g + 3 * n_groups < n_queries:
        best_d2[row + q3] = b3
        best_index[row + q3] = i3


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
