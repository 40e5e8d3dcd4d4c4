"""Warp kernels of BP's depth search on a dense coarse volume (launched by `methods.backends.warp.zsearch`):

* `coarse_max`: per pixel the maximum of |V| over the coarse depths, and the image's (atomic max);
* `window_points`: a pixel whose coarse maximum is below keep_ratio times the image's (it cannot pass the filter:
  the caller's ratio holds the coarse sampling's loss) gets NaN depth and its coarse maximum as max projection;
  every other takes a slot (atomic counter, compacted) and its n_cand largest local maxima of |V| over the coarse
  depths (the first of equal ones; a pixel with fewer repeats its largest) with around each a window of 2 half + 1
  fine depth samples (shifted inside the grid), written as points (slot-major, then candidate) for the correlation
  kernels, and the slots' point count for them;
* `window_peak_depth`: `volume_peak_depth`'s argmax and parabola over each slot's windows, and whether the maximum
  lies on a window edge that is not a grid edge (the full volume may hold a larger value beyond it).
"""
from __future__ import annotations

import warp as wp


@wp.func
def coarse_mag(coarse: wp.array2d(dtype=wp.vec2f), c: int, n_c: int, n_px: int, i: int) -> wp.float32:
    """|V| at coarse depth c of pixel i; -1 outside 0 .. n_c - 1."""
    if c < 0 or c >= n_c:
        return wp.float32(-1.0)
    return wp.length(coarse[0, c * n_px + i])


@wp.kernel(enable_backward=False)
def coarse_max(coarse: wp.array2d(dtype=wp.vec2f), n_c: int, pixel_max: wp.array(dtype=wp.float32),
               image_max: wp.array(dtype=wp.float32)):
    """pixel_max[i] = max over the n_c coarse depths of |V| at pixel i; image_max[0] (zeroed before) their max."""
    i = wp.tid()
    n_px = pixel_max.shape[0]
    best = wp.float32(0.0)
    for c in range(n_c):
        best = wp.max(best, wp.length(coarse[0, c * n_px + i]))
    pixel_max[i] = best
    wp.atomic_max(image_max, 0, best)


@wp.kernel(enable_backward=False)
def window_points(coarse: wp.array2d(dtype=wp.vec2f), coarse_k: wp.array(dtype=wp.int32),
                  x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64),
                  half: int, n_cand: int, pixel_max: wp.array(dtype=wp.float32),
                  image_max: wp.array(dtype=wp.float32), keep_ratio: wp.float32, n_slots: wp.array(dtype=wp.int32),
                  n_points: wp.array(dtype=wp.int32), slot_pixel: wp.array(dtype=wp.int32),
                  start: wp.array(dtype=wp.int32), points: wp.array(dtype=wp.vec3d),
                  maps: wp.array2d(dtype=wp.float64)):
    """Pixel i (x fastest) of the coarse volume (1, n_coarse * n_px) at the fine depth indices coarse_k: below the
    keep ratio its maps (NaN, coarse maximum); else slot q = n_slots[0]++ (zeroed before), slot_pixel[q] = i and for
    candidate c (0 = the largest local maximum, ...) the window start clamp(k - half, 0, n_z - n_w) into
    start[q * n_cand + c] and its points into points[(q * n_cand + c) * n_w ...]; n_points[0] grows with them."""
    i = wp.tid()
    nx = x.shape[0]
    n_px = nx * y.shape[0]
    n_c = coarse_k.shape[0]
    n_w = 2 * half + 1
    if pixel_max[i] < keep_ratio * image_max[0]:
        maps[0, i] = wp.float64(wp.nan)
        maps[1, i] = wp.float64(pixel_max[i])
        return
    q = wp.atomic_add(n_slots, 0, 1)
    wp.atomic_add(n_points, 0, n_cand * n_w)
    slot_pixel[q] = i
    px = x[i % nx]
    py = y[i // nx]
    taken = wp.float32(3.4e38)      # candidates in decreasing |V|: the next is the largest below the last taken
    taken_c = int(-1)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    kb = int(0)  # noqa: UP018
    for cand in range(n_cand):
        best = wp.float32(-1.0)
        best_c = int(-1)  # noqa: UP018
        for c in range(n_c):
            m = coarse_mag(coarse, c, n_c, n_px, i)
            is_peak = m >= coarse_mag(coarse, c - 1, n_c, n_px, i) and m >= coarse_mag(coarse, c + 1, n_c, n_px, i)
            below = m < taken or (m == taken and c > taken_c)
            if is_peak and below and m > best:
                best = m
                best_c = c
        if best_c >= 0:
            taken = best
            taken_c = best_c
            kb = coarse_k[best_c]
        s = wp.max(wp.min(kb - half, z.shape[0] - n_w), 0)
        start[q * n_cand + cand] = s
        for j in range(n_w):
            points[(q * n_cand + cand) * n_w + j] = wp.vec3d(px, py, z[s + j])


@wp.kernel(enable_backward=False)
def window_peak_depth(vals: wp.array2d(dtype=wp.vec2f), n_w: int, n_cand: int, start: wp.array(dtype=wp.int32),
                      n_slots: wp.array(dtype=wp.int32), slot_pixel: wp.array(dtype=wp.int32), n_z: int,
                      z_first_m: wp.float64, dz_m: wp.float64, maps: wp.array2d(dtype=wp.float64),
                      on_edge: wp.array(dtype=wp.int32)):
    """As `volume_peak_depth` over slot q's windows (values vals[0, (q * n_cand + c) * n_w + j] at depth index
    start[q * n_cand + c] + j), into the maps of its pixel: the first argmax in z and the parabola on its neighbours
    in its window (clipped at the grid's ends); on_edge[0] counts the slots whose maximum lies on a window edge that
    is not a grid edge. Slots from n_slots[0] on return at once."""
    q = wp.tid()
    if q >= n_slots[0]:
        return
    i = slot_pixel[q]
    best = wp.float32(-1.0)
    wb = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    jb = int(0)  # noqa: UP018
    for c in range(n_cand):
        w = q * n_cand + c
        for j in range(n_w):
            m = wp.length(vals[0, w * n_w + j])
            if m > best or (m == best and start[w] + j < start[wb] + jb):
                best = m
                wb = w
                jb = j
    s = start[wb]
    if (jb == 0 and s > 0) or (jb == n_w - 1 and s + n_w < n_z):
        wp.atomic_add(on_edge, 0, 1)
    tiny = wp.float64(1.1754943508222875e-38)
    db_m = wp.float64(20.0) * wp.log10(wp.max(wp.float64(wp.length(vals[0, wb * n_w + wp.max(jb - 1, 0)])), tiny))
    db_0 = wp.float64(20.0) * wp.log10(wp.max(wp.float64(best), tiny))
    db_p = wp.float64(20.0) * wp.log10(wp.max(wp.float64(wp.length(vals[0, wb * n_w + wp.min(jb + 1, n_w - 1)])),
                                              tiny))
    curvature = db_m - wp.float64(2.0) * db_0 + db_p
    offset = wp.float64(0.0)
    if curvature < wp.float64(0.0):
        offset = wp.float64(0.5) * (db_m - db_p) / curvature
    maps[0, i] = z_first_m + (wp.float64(s + jb) + offset) * dz_m
    maps[1, i] = wp.float64(best)
