"""Warp kernels of the two-frequency depth at a per-pixel prior (MM-2FSK on the device; kernels only, launched by
`methods.warp_backend.fsk`): compaction of the covered pixels, depth and magnitude, the magnitude filter."""
from __future__ import annotations

import warp as wp

from methods.warp_backend.prior_kernels import FAR

@wp.kernel(enable_backward=False)
def compact_covered_pixels(n_cols: int, zbuf: wp.array(dtype=wp.float64), x_m: wp.array(dtype=wp.float64),
                           y_m: wp.array(dtype=wp.float64), slot: wp.array(dtype=wp.int32),
                           points: wp.array(dtype=wp.vec3d), pixel: wp.array(dtype=wp.int32),
                           maps: wp.array2d(dtype=wp.float64)):
    """maps = (depth NaN, magnitude NaN, prior or NaN); covered pixels -> next slot of (x, y, prior) points."""
    p = wp.tid()
    z = zbuf[p]
    nan = wp.float64(wp.nan)
    maps[0, p] = nan
    maps[1, p] = nan
    if z < FAR:
        maps[2, p] = z
        i = wp.atomic_add(slot, 0, 1)
        points[i] = wp.vec3d(x_m[p % n_cols], y_m[p // n_cols], z)
        pixel[i] = p
    else:
        maps[2, p] = nan


@wp.kernel(enable_backward=False)
def fsk_depth_at_prior(ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32), m_per_rad: wp.float64,
                       maps: wp.array2d(dtype=wp.float64), peak: wp.array(dtype=wp.float32)):
    """depth = prior - c angle(c2 conj c1) / (4 pi (f2 - f1)); magnitude = |(c1 + c2) / 2| (float32 as numpy)."""
    i = wp.tid()
    p = pixel[i]
    c1 = ph[0, i]
    c2 = ph[1, i]
    re = c2[0] * c1[0] + c2[1] * c1[1]
    im = c2[1] * c1[0] - c2[0] * c1[1]
    maps[0, p] = maps[2, p] - m_per_rad * wp.float64(wp.atan2(im, re))
    mean = (c1 + c2) * wp.float32(0.5)
    mag = wp.length(mean)
    maps[1, p] = wp.float64(mag)
    wp.atomic_max(peak, 0, mag)


@wp.kernel(enable_backward=False)
def magnitude_filter(pixel: wp.array(dtype=wp.int32), keep_ratio: wp.float64, peak: wp.array(dtype=wp.float32),
                     maps: wp.array2d(dtype=wp.float64)):
    """`filtering.keep_mask`: depth NaN where magnitude is 0 or < max * keep_ratio (10^(-threshold_db / 20), 0 for
    no threshold)."""
    p = pixel[wp.tid()]
    mag = maps[1, p]
    if mag <= wp.float64(0.0) or mag < wp.float64(peak[0]) * keep_ratio:
        maps[0, p] = wp.float64(wp.nan)
