"""Warp kernels of the radar sum (kernels only; launched by `bench.synth.radar.warp_sum`), one source for the CPU
and CUDA.

Each row (a scatterer, or a bistatic pair of multipath) has two sides, receive and transmit; a side is the point q
its leg leaves towards an antenna a, a lobe axis u and half-width (rad; 0: no lobe), a complex amplitude and a path
added to the leg. The leg (`legs`, as bench.synth.radar.model.simulate_frame and multipath's legs form them) has the
path |a - q| + added, and the weight amplitude g / |a - q| with the gain g = exp(-(theta / lobe)^2 / 2) (theta the
angle between u and a - q) times the element pattern clip((q_z - a_z) / |a - q|, 0, 1)^exponent. A row whose lobe
cosine towards every antenna is below its limit adds nothing (`audible`: the NumPy path drops it).

As on the NumPy path (bench.synth.radar.leg_sum.block_sum) a block's sum is formed at M node frequencies g_m with
each antenna's centre path c[e] factored out, then interpolated to every frequency f_n:

    s[f_n, rx, tx] = exp(-j 2 pi f_n (c[rx] + c[tx]) / c0) sum_m L[n, m] sum_k P[m, k, rx] P[m, k, tx]
    P[m, k, e] = w[e, k] exp(-j 2 pi g_m (p[e, k] - c[e]) / c0)

(a block whose nodes are the frequencies themselves has c = 0 and L = 1: `direct`). `path_bounds` gives the
block's path range per antenna for the centres and the node count (chosen on the host).
* `leg_phasors`: P, as `leg_sum.exact_phasors` forms phasors: the phase in cycles reduced modulo one in float64,
  then float32 cos and sin.
* `pair_products`: one thread per row slice, node and 4 x 4 antenna pairs sums its rows in float32 registers
  (complex multiply-adds as real and imaginary 4 x 4 outer products);
* `add_slices`: the slices' sums added in order;
* `interpolate_add`: per frequency and pair, L applied, the centre phase (one phasor of the summed centre paths,
  reduced in float64), and the result added to a float64 frame.
No atomics: every sum runs in a fixed order, so a frame is the same bit for bit on one device whatever else runs.
"""
from __future__ import annotations

import warp as wp

PAIR_TILE = 4        # antennas per thread and side in pair_products (its vec4 / mat44): 4 x 4 pairs
ROW_SLICES = 8       # a block's rows in this many slices summed by separate threads (parallelism; shorter sums)
BOUND_ROWS = wp.constant(64)   # rows per thread of path_bounds (the host takes the extremes of the threads' ranges)


@wp.func
def leg_gain(antenna: wp.vec3d, point: wp.vec3d, axis: wp.vec3d, lobe_rad: wp.float64, exponent: wp.float64,
             distance_m: wp.float64) -> wp.float64:
    """Lobe times element pattern of the leg point -> antenna (module doc)."""
    gain = wp.float64(1.0)
    if lobe_rad > wp.float64(0.0):
        cosine = wp.clamp(wp.dot(antenna - point, axis) / distance_m, wp.float64(-1.0), wp.float64(1.0))
        theta = wp.acos(cosine) / lobe_rad
        gain = wp.exp(wp.float64(-0.5) * theta * theta)
    if exponent != wp.float64(0.0):
        element = wp.clamp((point[2] - antenna[2]) / distance_m, wp.float64(0.0), wp.float64(1.0))
        if exponent != wp.float64(1.0):
            element = wp.pow(element, exponent)
        gain = gain * element
    return gain


@wp.kernel
def audible(antennas: wp.array(dtype=wp.vec3d), n_rx: int, points: wp.array2d(dtype=wp.vec3d),
            axes: wp.array2d(dtype=wp.vec3d), lobe_rad: wp.array2d(dtype=wp.float64),
            cos_limit: wp.array(dtype=wp.float64), flags: wp.array(dtype=wp.int32)):
    """flags[k] = 1 if row k's lobe cosine towards some antenna reaches cos_limit[k] (sides without a lobe: 1)."""
    k = wp.tid()
    best = wp.float64(-2.0)
    for e in range(antennas.shape[0]):
        side = 0
        if e >= n_rx:
            side = 1
        if lobe_rad[side, k] > wp.float64(0.0):
            to_antenna = antennas[e] - points[side, k]
            best = wp.max(best, wp.dot(to_antenna, axes[side, k]) / wp.length(to_antenna))
        else:
            best = wp.float64(2.0)
    flags[k] = wp.where(best >= cos_limit[k], 1, 0)


@wp.kernel
def legs(rows: wp.array(dtype=wp.int32), antennas: wp.array(dtype=wp.vec3d), n_rx: int,
         points: wp.array2d(dtype=wp.vec3d), axes: wp.array2d(dtype=wp.vec3d), lobe_rad: wp.array2d(dtype=wp.float64),
         amplitude: wp.array2d(dtype=wp.vec2f), added_m: wp.array2d(dtype=wp.float64), exponent: wp.float64,
         path_m: wp.array2d(dtype=wp.float64), weight: wp.array2d(dtype=wp.vec2f)):
    """path_m[e, j], weight[e, j] of the block's row rows[j] towards antenna e (receive antennas first)."""
    e, j = wp.tid()
    k = rows[j]
    side = 0
    if e >= n_rx:
        side = 1
    point = points[side, k]
    distance = wp.length(antennas[e] - point)
    path_m[e, j] = distance + added_m[side, k]
    gain = wp.float32(leg_gain(antennas[e], point, axes[side, k], lobe_rad[side, k], exponent, distance) / distance)
    weight[e, j] = amplitude[side, k] * gain


@wp.kernel
def path_bounds(path_m: wp.array2d(dtype=wp.float64), bounds: wp.array3d(dtype=wp.float64)):
    """bounds[e, t] = (min, max) of path_m[e, t * BOUND_ROWS:(t + 1) * BOUND_ROWS] (rows beyond the end: none)."""
    e, t = wp.tid()
    low = wp.float64(1.0e30)
    high = wp.float64(-1.0e30)
    for j in range(t * BOUND_ROWS, wp.min((t + 1) * BOUND_ROWS, path_m.shape[1])):
        low = wp.min(low, path_m[e, j])
        high = wp.max(high, path_m[e, j])
    bounds[e, t, 0] = low
    bounds[e, t, 1] = high


@wp.func
def phasor_of_cycles(cycles: wp.float64) -> wp.vec2f:
    """exp(-j 2 pi cycles) as (re, im): reduced modulo one in float64, then float32 cos and sin."""
    angle = wp.float32((cycles - wp.round(cycles)) * wp.float64(-2.0 * wp.pi))
    return wp.vec2f(wp.cos(angle), wp.sin(angle))


@wp.func
def cmul(a: wp.vec2f, b: wp.vec2f) -> wp.vec2f:
    return wp.vec2f(a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


@wp.kernel
def leg_phasors(path_m: wp.array2d(dtype=wp.float64), centre_m: wp.array(dtype=wp.float64),
                weight: wp.array2d(dtype=wp.vec2f), node_cycles_per_m: wp.array(dtype=wp.float64),
                phasors: wp.array3d(dtype=wp.vec2f)):
    """phasors[m, k, e] = weight[e, k] exp(-j 2 pi g_m / c0 (path_m[e, k] - centre_m[e]))."""
    m, k, e = wp.tid()
    phasors[m, k, e] = cmul(weight[e, k], phasor_of_cycles((path_m[e, k] - centre_m[e]) * node_cycles_per_m[m]))


@wp.func
def load_legs(phasors: wp.array3d(dtype=wp.vec2f), m: int, k: int, first: int, end: int):
    """Real and imaginary parts of phasors[m, k, first:first + 4] (zeros at and beyond `end`)."""
    re = wp.vec4f(0.0)
    im = wp.vec4f(0.0)
    for j in range(4):
        e = first + j
        if e < end:
            v = phasors[m, k, e]
            re[j] = v[0]
            im[j] = v[1]
    return re, im


@wp.kernel
def pair_products(phasors: wp.array3d(dtype=wp.vec2f), n_rx: int, rows_per_slice: int,
                  partial: wp.array4d(dtype=wp.vec2f)):
    """partial[slice, m, rx, tx] = sum over the slice's rows k of phasors[m, k, rx] phasors[m, k, n_rx + tx]."""
    piece, m, rx_group, tx_group = wp.tid()
    n_tx = partial.shape[3]
    rx0 = rx_group * 4
    tx0 = tx_group * 4
    sum_re = wp.mat44f(0.0)
    sum_im = wp.mat44f(0.0)
    for k in range(piece * rows_per_slice, wp.min((piece + 1) * rows_per_slice, phasors.shape[1])):
        a_re, a_im = load_legs(phasors, m, k, rx0, n_rx)
        b_re, b_im = load_legs(phasors, m, k, n_rx + tx0, n_rx + n_tx)
        sum_re += wp.outer(a_re, b_re) - wp.outer(a_im, b_im)
        sum_im += wp.outer(a_re, b_im) + wp.outer(a_im, b_re)
    for i in range(4):
        for j in range(4):
            if rx0 + i < n_rx and tx0 + j < n_tx:
                partial[piece, m, rx0 + i, tx0 + j] = wp.vec2f(sum_re[i, j], sum_im[i, j])


@wp.kernel
def add_slices(partial: wp.array4d(dtype=wp.vec2f), nodes: wp.array3d(dtype=wp.vec2f)):
    """nodes[m, rx, tx] = the row slices' sums partial[:, m, rx, tx] added in order."""
    m, rx, tx = wp.tid()
    total = wp.vec2f(0.0, 0.0)
    for piece in range(partial.shape[0]):
        total += partial[piece, m, rx, tx]
    nodes[m, rx, tx] = total


@wp.kernel
def interpolate_add(nodes: wp.array3d(dtype=wp.vec2f), fit: wp.array2d(dtype=wp.vec2f), direct: int,
                    centre_m: wp.array(dtype=wp.float64), cycles_per_m: wp.array(dtype=wp.float64),
                    frame: wp.array3d(dtype=wp.vec2d)):
    """frame[f, rx, tx] += exp(-j 2 pi f / c0 (centre_rx + centre_tx)) sum_m fit[f, m] nodes[m, rx, tx]
    (direct: the nodes are the frequencies, nodes[f, rx, tx] itself)."""
    f, rx, tx = wp.tid()
    total = wp.vec2f(0.0, 0.0)
    if direct != 0:
        total = nodes[f, rx, tx]
    else:
        for m in range(nodes.shape[0]):
            total += cmul(fit[f, m], nodes[m, rx, tx])
        total = cmul(total, phasor_of_cycles((centre_m[rx] + centre_m[nodes.shape[1] + tx]) * cycles_per_m[f]))
    frame[f, rx, tx] += wp.vec2d(wp.float64(total[0]), wp.float64(total[1]))
