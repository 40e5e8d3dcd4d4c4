"""Warp kernels of the FSK depths on the device (kernels only, launched by `methods.backends.warp.fsk`): for MM-2FSK
the compaction of the covered pixels, depth and magnitude at the prior, the magnitude filter; for 2FSK and 3FSK
the points of each pass, pass 1's strongest pixel (a reduction), the refocused guess, the pair and slope depths.
Each reproduces the numpy expression it names (methods.fsk, methods.fsk3) in the same precision (complex64
phasors, float32 phases, float64 depths)."""
from __future__ import annotations

import warp as wp

from methods.backends.warp.kernels.prior import FAR


@wp.kernel(enable_backward=False)
def compact_covered_pixels(n_cols: int, zbuf: wp.array(dtype=wp.float64), x_m: wp.array(dtype=wp.float64),
                           y_m: wp.array(dtype=wp.float64), slot: wp.array(dtype=wp.int32),
                           points: wp.array(dtype=wp.vec3d), pixel: wp.array(dtype=wp.int32),
                           maps: wp.array2d(dtype=wp.float64), use_roi: int, roi: wp.array(dtype=wp.uint8)):
    """maps = (depth NaN, magnitude NaN, prior or NaN); covered pixels (inside the ROI `roi` with use_roi) -> next
    slot of (x, y, prior) points."""
    p = wp.tid()
    z = zbuf[p]
    nan = wp.float64(wp.nan)
    maps[0, p] = nan
    maps[1, p] = nan
    if z < FAR:
        maps[2, p] = z
        if use_roi != 0 and roi[p] == wp.uint8(0):
            return
        i = wp.atomic_add(slot, 0, 1)
        points[i] = wp.vec3d(x_m[p % n_cols], y_m[p // n_cols], z)
        pixel[i] = p
    else:
        maps[2, p] = nan


@wp.func
def pair_correction_m(c1: wp.vec2f, c2: wp.vec2f, m_per_rad: wp.float64):
    """`fsk.depth_correction_m`: m_per_rad * angle(c2 conj c1) (float32 phase, as numpy's complex64)."""
    re = c2[0] * c1[0] + c2[1] * c1[1]
    im = c2[1] * c1[0] - c2[0] * c1[1]
    return m_per_rad * wp.float64(wp.atan2(im, re))


# Each per-point step is one wp.func, launched by a kernel over n points and by its `_counted` twin over a launch of
# fixed size (a CUDA graph), whose threads from count[0] on do nothing.

@wp.func
def depth_at_prior_at(i: int, ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32),
                      m_per_rad: wp.float64, maps: wp.array2d(dtype=wp.float64), peak: wp.array(dtype=wp.float32)):
    """depth = prior - c angle(c2 conj c1) / (4 pi (f2 - f1)); magnitude = |(c1 + c2) / 2| (float32 as numpy)."""
    p = pixel[i]
    c1 = ph[0, i]
    c2 = ph[1, i]
    maps[0, p] = maps[2, p] - pair_correction_m(c1, c2, m_per_rad)
    mag = wp.length((c1 + c2) * wp.float32(0.5))
    maps[1, p] = wp.float64(mag)
    wp.atomic_max(peak, i % peak.shape[0], mag)


@wp.kernel(enable_backward=False)
def fsk_depth_at_prior(ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32), m_per_rad: wp.float64,
                       maps: wp.array2d(dtype=wp.float64), peak: wp.array(dtype=wp.float32)):
    """`depth_at_prior_at` at every point."""
    depth_at_prior_at(wp.tid(), ph, pixel, m_per_rad, maps, peak)


@wp.func
def magnitude_filter_at(p: int, keep_ratio: wp.float64, peak: wp.array(dtype=wp.float32),
                        maps: wp.array2d(dtype=wp.float64)):
    """`filtering.keep_mask`: depth NaN where magnitude is 0 or < max * keep_ratio (10^(-threshold_db / 20), 0 for
    no threshold)."""
    mag = maps[1, p]
    if mag <= wp.float64(0.0) or mag < wp.float64(peak[0]) * keep_ratio:
        maps[0, p] = wp.float64(wp.nan)


@wp.kernel(enable_backward=False)
def magnitude_filter(pixel: wp.array(dtype=wp.int32), keep_ratio: wp.float64, peak: wp.array(dtype=wp.float32),
                     maps: wp.array2d(dtype=wp.float64)):
    """`magnitude_filter_at` at every point's pixel."""
    magnitude_filter_at(pixel[wp.tid()], keep_ratio, peak, maps)


# 2FSK and 3FSK with a scalar prior on the device (`methods.backends.warp.fsk.two_pass` / `three_fsk`): the points
# of a pass are made here, pass 1's strongest pixel is found by a reduction, and the depth and filter stay here.

@wp.kernel(enable_backward=False)
def points_at_depth(pixel: wp.array(dtype=wp.int32), n_cols: int, x_m: wp.array(dtype=wp.float64),
                    y_m: wp.array(dtype=wp.float64), z_m: wp.float64, points: wp.array(dtype=wp.vec3d)):
    """Point i = (x, y) of pixel[i] at the depth z_m."""
    i = wp.tid()
    p = pixel[i]
    points[i] = wp.vec3d(x_m[p % n_cols], y_m[p // n_cols], z_m)


@wp.kernel(enable_backward=False)
def first_magnitude_peak(ph: wp.array2d(dtype=wp.vec2f), peak: wp.array(dtype=wp.float32)):
    """peak[0] = max_i |ph[0, i]| (zeroed before)."""
    i = wp.tid()
    wp.atomic_max(peak, i % peak.shape[0], wp.length(ph[0, i]))


@wp.kernel(enable_backward=False)
def first_argmax(ph: wp.array2d(dtype=wp.vec2f), peak: wp.array(dtype=wp.float32), ref: wp.array(dtype=wp.int32)):
    """ref[0] = the first i with |ph[0, i]| == peak (np.argmax's tie rule; ref set to a large value before)."""
    i = wp.tid()
    if wp.length(ph[0, i]) == peak[0]:
        wp.atomic_min(ref, 0, i)


@wp.kernel(enable_backward=False)
def refocus_points(ph: wp.array2d(dtype=wp.vec2f), ref: wp.array(dtype=wp.int32), z0_m: wp.float64,
                   m_per_rad: wp.float64, points: wp.array(dtype=wp.vec3d), scalars: wp.array(dtype=wp.float64)):
    """2FSK's common guess z1 = z0 - correction of pass 1's strongest pixel: every point moves to z1 (each thread
    computes the same z1); scalars = (z1, reference pixel)."""
    i = wp.tid()
    r = ref[0]
    z1 = z0_m - pair_correction_m(ph[0, r], ph[1, r], m_per_rad)
    q = points[i]
    points[i] = wp.vec3d(q[0], q[1], z1)
    if i == 0:
        scalars[0] = z1
        scalars[1] = wp.float64(r)


@wp.kernel(enable_backward=False)
def reference_point(ref: wp.array(dtype=wp.int32), points: wp.array(dtype=wp.vec3d),
                    ref_point: wp.array(dtype=wp.vec3d)):
    """ref_point[0] = the point of pass 1's strongest pixel."""
    ref_point[0] = points[ref[0]]


@wp.kernel(enable_backward=False)
def refocus_points_from_first(ph: wp.array2d(dtype=wp.vec2f), ref: wp.array(dtype=wp.int32), z0_m: wp.float64,
                              m_per_rad: wp.float64, points: wp.array(dtype=wp.vec3d),
                              scalars: wp.array(dtype=wp.float64)):
    """`refocus_points` with the strongest pixel's pair phasors in column 0 of `ph` (a one-point correlation)."""
    i = wp.tid()
    z1 = z0_m - pair_correction_m(ph[0, 0], ph[1, 0], m_per_rad)
    q = points[i]
    points[i] = wp.vec3d(q[0], q[1], z1)
    if i == 0:
        scalars[0] = z1
        scalars[1] = wp.float64(ref[0])


@wp.func
def pair_depth_at(i: int, ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32), m_per_rad: wp.float64,
                  first_only: int, points: wp.array(dtype=wp.vec3d), maps: wp.array2d(dtype=wp.float64),
                  peak: wp.array(dtype=wp.float32)):
    """2FSK pass 2: depth = guess - correction, magnitude |(c1 + c2) / 2| (or |c1| with first_only: the faithful
    filter); peak = their maximum (zeroed before)."""
    p = pixel[i]
    c1 = ph[0, i]
    c2 = ph[1, i]
    maps[0, p] = points[i][2] - pair_correction_m(c1, c2, m_per_rad)
    mag = wp.length((c1 + c2) * wp.float32(0.5))
    if first_only != 0:
        mag = wp.length(c1)
    maps[1, p] = wp.float64(mag)
    wp.atomic_max(peak, i % peak.shape[0], mag)


@wp.kernel(enable_backward=False)
def pair_depth(ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32), m_per_rad: wp.float64,
               first_only: int, points: wp.array(dtype=wp.vec3d), maps: wp.array2d(dtype=wp.float64),
               peak: wp.array(dtype=wp.float32)):
    """`pair_depth_at` at every point."""
    pair_depth_at(wp.tid(), ph, pixel, m_per_rad, first_only, points, maps, peak)


@wp.func
def coarse_point_at(i: int, ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32), m_per_rad: wp.float64,
                    points: wp.array(dtype=wp.vec3d), maps: wp.array2d(dtype=wp.float64)):
    """3FSK's coarse step: the point moves to its coarse depth guess - correction (maps[2] = coarse depth)."""
    q = points[i]
    coarse = q[2] - pair_correction_m(ph[0, i], ph[1, i], m_per_rad)
    points[i] = wp.vec3d(q[0], q[1], coarse)
    maps[2, pixel[i]] = coarse


@wp.kernel(enable_backward=False)
def coarse_points(ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32), m_per_rad: wp.float64,
                  points: wp.array(dtype=wp.vec3d), maps: wp.array2d(dtype=wp.float64)):
    """`coarse_point_at` at every point."""
    coarse_point_at(wp.tid(), ph, pixel, m_per_rad, points, maps)


@wp.func
def slope_depth_at(c1: wp.vec2f, c2: wp.vec2f, c3: wp.vec2f, centred_hz: wp.vec3d, m_per_rad_hz: wp.float64,
                   guess_m: wp.float64):
    """(depth, magnitude) of `fsk3.slope_correction_m` on three phasors relative to the last: depth = guess - c s /
    (4 pi), s the least-squares phase slope (centred_hz = f - mean f over centred_hz . centred_hz, m_per_rad_hz =
    c / (4 pi)); magnitude |(c1 + c2 + c3) / 3|."""
    r0 = pair_correction_m(c3, c1, wp.float64(1.0))        # angle(c_k conj c3)
    r1 = pair_correction_m(c3, c2, wp.float64(1.0))
    r2 = pair_correction_m(c3, c3, wp.float64(1.0))
    mean = (r0 + r1 + r2) / wp.float64(3.0)
    slope = centred_hz[0] * (r0 - mean) + centred_hz[1] * (r1 - mean) + centred_hz[2] * (r2 - mean)
    return guess_m - m_per_rad_hz * slope, wp.length((c1 + c2 + c3) / wp.float32(3.0))


@wp.func
def slope_depth_point(i: int, ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32),
                      centred_hz: wp.vec3d, m_per_rad_hz: wp.float64, points: wp.array(dtype=wp.vec3d),
                      maps: wp.array2d(dtype=wp.float64), peak: wp.array(dtype=wp.float32)):
    """3FSK's fine step (`slope_depth_at` at the point's coarse depth); peak = the magnitudes' maximum (zeroed
    before)."""
    depth, mag = slope_depth_at(ph[0, i], ph[1, i], ph[2, i], centred_hz, m_per_rad_hz, points[i][2])
    p = pixel[i]
    maps[0, p] = depth
    maps[1, p] = wp.float64(mag)
    wp.atomic_max(peak, i % peak.shape[0], mag)


@wp.kernel(enable_backward=False)
def slope_depth(ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32), centred_hz: wp.vec3d,
                m_per_rad_hz: wp.float64, points: wp.array(dtype=wp.vec3d), maps: wp.array2d(dtype=wp.float64),
                peak: wp.array(dtype=wp.float32)):
    """`slope_depth_point` at every point."""
    slope_depth_point(wp.tid(), ph, pixel, centred_hz, m_per_rad_hz, points, maps, peak)


@wp.kernel(enable_backward=False)
def depth_at_prior_counted(ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32),
                           count: wp.array(dtype=wp.int32), m_per_rad: wp.float64, maps: wp.array2d(dtype=wp.float64),
                           peak: wp.array(dtype=wp.float32)):
    """`depth_at_prior_at` at points below count[0]."""
    i = wp.tid()
    if i < count[0]:
        depth_at_prior_at(i, ph, pixel, m_per_rad, maps, peak)


@wp.kernel(enable_backward=False)
def magnitude_filter_counted(pixel: wp.array(dtype=wp.int32), count: wp.array(dtype=wp.int32),
                             keep_ratio: wp.float64, peak: wp.array(dtype=wp.float32),
                             maps: wp.array2d(dtype=wp.float64)):
    """`magnitude_filter_at` at the pixels of points below count[0]."""
    i = wp.tid()
    if i < count[0]:
        magnitude_filter_at(pixel[i], keep_ratio, peak, maps)


PEAK_SHARDS = wp.constant(256)   # partial maxima of the magnitude (the kernels' shards arrays; reduce_peak)


@wp.kernel(enable_backward=False)
def reduce_peak(shards: wp.array(dtype=wp.float32), peak: wp.array(dtype=wp.float32)):
    """peak[0] = max of the PEAK_SHARDS shards: the kernels above take the maximum into shards[i % n_shards] (a
    float atomic max is a compare-and-swap loop; 90 k threads on one address cost ~0.1 ms on the H100); one block
    reduces them (launch_tiled, block_dim PEAK_SHARDS: 1-2 us on the H100 against 10-18 us for one thread's loop)."""
    wp.tile_store(peak, wp.tile_max(wp.tile_load(shards, shape=PEAK_SHARDS)))


# MM-3FSK at a prior inside a frame graph (`frame_graph.FrameGraph` with a coarse pair): the coarse pair's
# corrections, the median over the pixels the filter keeps (an exact radix select on quantised keys), every point
# moved by that offset, then the three frequencies' slope depth. Launch sizes fixed; threads from count[0] on return.

MEDIAN_BINS = 256           # one 8-bit digit of a 32-bit key per level
MEDIAN_LEVELS = 4
MEDIAN_KEYS = 4294967296.0  # 2^32 quantisation steps over the correction range


@wp.kernel(enable_backward=False)
def coarse_correction_counted(ph: wp.array2d(dtype=wp.vec2f), count: wp.array(dtype=wp.int32),
                              m_per_rad: wp.float64, correction: wp.array(dtype=wp.float64),
                              magnitude: wp.array(dtype=wp.float32), peak: wp.array(dtype=wp.float32)):
    """MM-3FSK's coarse step: correction = `fsk.depth_correction_m` of the pair, magnitude = |(c1 + c2) / 2|
    (`fsk.mean_phasor_magnitude`), peak = its maximum (shards, zeroed before)."""
    i = wp.tid()
    if i >= count[0]:
        return
    c1 = ph[0, i]
    c2 = ph[1, i]
    correction[i] = pair_correction_m(c1, c2, m_per_rad)
    mag = wp.length((c1 + c2) * wp.float32(0.5))
    magnitude[i] = mag
    wp.atomic_max(peak, i % peak.shape[0], mag)


@wp.kernel(enable_backward=False)
def median_keys(count: wp.array(dtype=wp.int32), correction: wp.array(dtype=wp.float64),
                magnitude: wp.array(dtype=wp.float32), keep_ratio: wp.float64, peak: wp.array(dtype=wp.float32),
                lo_m: wp.float64, width_m: wp.float64, keys: wp.array(dtype=wp.int64),
                n_kept: wp.array(dtype=wp.int32)):
    """key = the correction quantised to 2^32 steps over [lo_m, lo_m + width_m) (monotone: the k-th smallest key is
    the k-th smallest correction's), -1 where `filtering.keep_mask` drops the pixel; n_kept counts the others
    (zeroed before)."""
    i = wp.tid()
    if i >= count[0]:
        return
    mag = magnitude[i]
    if mag <= wp.float32(0.0) or wp.float64(mag) < wp.float64(peak[0]) * keep_ratio:
        keys[i] = wp.int64(-1)
        return
    q = wp.floor((correction[i] - lo_m) / width_m * wp.float64(MEDIAN_KEYS))
    q = wp.clamp(q, wp.float64(0.0), wp.float64(MEDIAN_KEYS) - wp.float64(1.0))
    keys[i] = wp.int64(q)
    wp.atomic_add(n_kept, 0, 1)


@wp.kernel(enable_backward=False)
def median_start(n_kept: wp.array(dtype=wp.int32), rank: wp.array2d(dtype=wp.int32),
                 prefix: wp.array2d(dtype=wp.int64)):
    """Level 0 of the select: the two ranks np.median averages ((n - 1) // 2 and n // 2), empty prefixes; the
    histograms (levels, 2, MEDIAN_BINS) are zeroed by the caller."""
    s = wp.tid()
    n = n_kept[0]
    rank[0, s] = (n - 1 + s) // 2
    prefix[0, s] = wp.int64(0)


@wp.kernel(enable_backward=False)
def median_histogram(count: wp.array(dtype=wp.int32), keys: wp.array(dtype=wp.int64), shift: int, level: int,
                     prefix: wp.array2d(dtype=wp.int64), hist: wp.array3d(dtype=wp.int32)):
    """Per rank s: histogram (this level's) of the next 8-bit digit (bits shift .. shift + 7) of the kept keys whose
    higher bits equal the level's prefix[s]."""
    i = wp.tid()
    if i >= count[0]:
        return
    key = keys[i]
    if key < wp.int64(0):
        return
    digit = wp.int32((key >> wp.int64(shift)) & wp.int64(255))
    high = key >> wp.int64(shift + 8)
    for s in range(2):
        if high == prefix[level, s]:
            wp.atomic_add(hist, level, s, digit, 1)


MEDIAN_GROUP = 16           # bins per group of the digit's two-level prefix sum (16 groups of 16)


@wp.kernel(enable_backward=False)
def median_groups(level: int, hist: wp.array3d(dtype=wp.int32), groups: wp.array3d(dtype=wp.int32)):
    """groups[level, s, g] = the keys in bins g * MEDIAN_GROUP .. (g + 1) * MEDIAN_GROUP - 1 of this level."""
    s, g = wp.tid()
    n = int(0)  # noqa: UP018
    for c in range(MEDIAN_GROUP):
        n += hist[level, s, g * MEDIAN_GROUP + c]
    groups[level, s, g] = n


@wp.kernel(enable_backward=False)
def median_digit(level: int, rank: wp.array2d(dtype=wp.int32), prefix: wp.array2d(dtype=wp.int64),
                 hist: wp.array3d(dtype=wp.int32), groups: wp.array3d(dtype=wp.int32)):
    """Thread (s, b): if bin b of this level holds the rank-th key of rank s, the next level's prefix gains digit b
    and its rank drops by the keys below the bin (one thread per rank matches). The keys below come from the
    groups before b's and the bins before b in its group (<= 30 loads: a 256-bin loop per thread cost ~10 us a
    level on the H100); each level has its own histogram, ranks and prefixes, so no thread waits on another."""
    s, b = wp.tid()
    g = b // MEDIAN_GROUP
    below = int(0)  # noqa: UP018
    for c in range(g):
        below += groups[level, s, c]
    for c in range(g * MEDIAN_GROUP, b):
        below += hist[level, s, c]
    r = rank[level, s]
    if below <= r and r < below + hist[level, s, b]:
        rank[level + 1, s] = r - below
        prefix[level + 1, s] = (prefix[level, s] << wp.int64(8)) | wp.int64(b)


@wp.kernel(enable_backward=False)
def shift_points_by_median(count: wp.array(dtype=wp.int32), n_kept: wp.array(dtype=wp.int32),
                           prefix: wp.array2d(dtype=wp.int64), lo_m: wp.float64, width_m: wp.float64,
                           points: wp.array(dtype=wp.vec3d), offset: wp.array(dtype=wp.float64)):
    """offset = the mean of the two selected keys' bin centres (the last level's prefixes; 0 when nothing is kept: no
    shift); every point moves to prior - offset."""
    i = wp.tid()
    if i >= count[0]:
        return
    step = width_m / wp.float64(MEDIAN_KEYS)
    off = wp.float64(0.0)
    if n_kept[0] > 0:
        last = prefix.shape[0] - 1
        off = lo_m + (wp.float64(prefix[last, 0]) + wp.float64(prefix[last, 1]) + wp.float64(1.0)) * wp.float64(0.5) \
            * step
    q = points[i]
    points[i] = wp.vec3d(q[0], q[1], q[2] - off)
    if i == 0:
        offset[0] = off


@wp.kernel(enable_backward=False)
def slope_depth_counted(ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32),
                        count: wp.array(dtype=wp.int32), centred_hz: wp.vec3d, m_per_rad_hz: wp.float64,
                        points: wp.array(dtype=wp.vec3d), maps: wp.array2d(dtype=wp.float64),
                        peak: wp.array(dtype=wp.float32)):
    """`slope_depth_point` at points below count[0]."""
    i = wp.tid()
    if i < count[0]:
        slope_depth_point(i, ph, pixel, centred_hz, m_per_rad_hz, points, maps, peak)


@wp.kernel(enable_backward=False)
def magnitude_to_float32(maps: wp.array2d(dtype=wp.float64), magnitude: wp.array(dtype=wp.float32)):
    """magnitude = maps[1] in float32: exact, every magnitude is a float32 value (NaN stays NaN)."""
    p = wp.tid()
    magnitude[p] = wp.float32(maps[1, p])


# 2FSK / 3FSK with `fsk_keep` (methods.skips.keep_skip) inside an FSK graph: pass 2 (3FSK: the coarse pass 2 and the
# fine pass) first on a pixel lattice, the lattice pixels within threshold + margin of the lattice maximum marked,
# then only the other ROI pixels within the square neighbourhood of a marked one (compacted into slots).

@wp.kernel(enable_backward=False)
def points_at_guess(pixel: wp.array(dtype=wp.int32), n_cols: int, x_m: wp.array(dtype=wp.float64),
                    y_m: wp.array(dtype=wp.float64), scalars: wp.array(dtype=wp.float64),
                    points: wp.array(dtype=wp.vec3d)):
    """Point i = (x, y) of pixel[i] at the common guess scalars[0] (z1)."""
    i = wp.tid()
    p = pixel[i]
    points[i] = wp.vec3d(x_m[p % n_cols], y_m[p // n_cols], scalars[0])


@wp.kernel(enable_backward=False)
def mark_lattice(pixel: wp.array(dtype=wp.int32), maps: wp.array2d(dtype=wp.float64),
                 peak: wp.array(dtype=wp.float32), mark_ratio: wp.float64, marked: wp.array(dtype=wp.uint8)):
    """`keep_skip.run_where_kept`: a lattice pixel is marked when its magnitude >= the lattice maximum times
    10^(-(threshold + margin) / 20) (marked zeroed before)."""
    p = pixel[wp.tid()]
    if maps[1, p] >= wp.float64(peak[0]) * mark_ratio:
        marked[p] = wp.uint8(1)


@wp.kernel(enable_backward=False)
def compact_kept_rest(n_rows: int, n_cols: int, radius: int, roi: wp.array(dtype=wp.uint8),
                      on_lattice: wp.array(dtype=wp.uint8), marked: wp.array(dtype=wp.uint8),
                      x_m: wp.array(dtype=wp.float64), y_m: wp.array(dtype=wp.float64),
                      scalars: wp.array(dtype=wp.float64), count: wp.array(dtype=wp.int32),
                      pixel: wp.array(dtype=wp.int32), points: wp.array(dtype=wp.vec3d)):
    """`dilate(marked, radius) & pixels & ~lattice`: ROI pixels off the lattice with a marked pixel within `radius`
    in x and in y go to the next slot (count zeroed before), their points at the common guess scalars[0]."""
    p = wp.tid()
    if roi[p] == wp.uint8(0) or on_lattice[p] != wp.uint8(0):
        return
    r = p // n_cols
    c = p % n_cols
    hit = int(0)  # noqa: UP018
    for rr in range(wp.max(r - radius, 0), wp.min(r + radius, n_rows - 1) + 1):
        for cc in range(wp.max(c - radius, 0), wp.min(c + radius, n_cols - 1) + 1):
            if marked[rr * n_cols + cc] != wp.uint8(0):
                hit = 1
    if hit == 0:
        return
    i = wp.atomic_add(count, 0, 1)
    pixel[i] = p
    points[i] = wp.vec3d(x_m[c], y_m[r], scalars[0])


@wp.kernel(enable_backward=False)
def pair_depth_counted(ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32),
                       count: wp.array(dtype=wp.int32), m_per_rad: wp.float64, first_only: int,
                       points: wp.array(dtype=wp.vec3d), maps: wp.array2d(dtype=wp.float64),
                       peak: wp.array(dtype=wp.float32)):
    """`pair_depth_at` at points below count[0]."""
    i = wp.tid()
    if i < count[0]:
        pair_depth_at(i, ph, pixel, m_per_rad, first_only, points, maps, peak)


@wp.kernel(enable_backward=False)
def coarse_points_counted(ph: wp.array2d(dtype=wp.vec2f), pixel: wp.array(dtype=wp.int32),
                          count: wp.array(dtype=wp.int32), m_per_rad: wp.float64, points: wp.array(dtype=wp.vec3d),
                          maps: wp.array2d(dtype=wp.float64)):
    """`coarse_point_at` at points below count[0]."""
    i = wp.tid()
    if i < count[0]:
        coarse_point_at(i, ph, pixel, m_per_rad, points, maps)

