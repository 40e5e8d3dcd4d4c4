"""Warp kernels and functions of the correlation (kernels only; launched by `methods.backends.warp.correlation`).

One thread per point or voxel; points come from an (N, 3) array or from an x/y/z grid (`point_at`).
* `correlate_direct`: the plain direct sum, one sincos per antenna pair and frequency (the comparison baseline).
* `correlate_separable`: T + R sincos per point and frequency, then `a^T S b` as complex multiply-adds.
* `correlate_tiles_tx_halves` (kernel "tc" on CUDA): blocks of 128 points; per frequency and Tx half h the
  real-split product M_h^T A^T on the tensor cores (`wp.tile_matmul`, fp16 operands, fp32 accumulation),
  A^T = [cos; sin](k e_rx), M = [[Sr, Si], [-Si, Sr]], operand rows padded off multiples of 128 bytes; then the
  Tx dot as per-thread partial sums in fp32 (`prepare_points` forms the per-point data).
* `correlate_tiles_tx_split` (kernel "tc3", CUDA): the same with each fp16 operand split into hi + scaled lo parts and
  three products per half, for ~fp32 operand precision (1.8e-4 -> ~1e-6 relative error against float64).
* `correlate_tiles_rx_product` (kernel "tc" on Warp-CPU, which runs tiles with block_dim 1): blocks of 64 points,
  the product [cos|sin](k e_rx) (64 x 192) @ M (192 x 192), then a row-wise dot with the Tx steering.
* `range_profiles` + `range_gather`: range-compressed back-projection (methods/ops/range_compression.py): profiles in
  fp16 over the path window the volume needs only (fits L2), Tx steering in registers in chunks of 16.
* `volume_peak_depth`: BP's argmax + parabola over z of a (z, pixel) volume on the device.
The measured alternatives of each kernel (versions, layouts, chunk sizes) are in docs/measurements/gpu.md.
Phases use the same cancellation-free split as the numpy backend: |p - q| = |p| + e(p, q) with e in float32 and the
common phase 2 k |p| in float64, reduced mod 2 pi.
"""
from __future__ import annotations

import warp as wp

MAX_ANTENNAS = 96
TX_CHUNK = wp.constant(32)          # Tx steering values a thread keeps in registers at a time
vec_ant = wp.types.vector(length=MAX_ANTENNAS, dtype=wp.float32)
vec_chunk = wp.types.vector(length=32, dtype=wp.float32)
wp.set_module_options({"max_unroll": 32})


@wp.func
def point_at(i: int, grid: int, points: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.float64),
             y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64)):
    if grid == 0:
        return points[i]
    nx = x.shape[0]
    ny = y.shape[0]
    return wp.vec3d(x[i % nx], y[(i // nx) % ny], z[i // (nx * ny)])


@wp.func
def path_excess_m(p: wp.vec3f, norm_m: wp.float32, q: wp.vec3f) -> wp.float32:
    """|p - q| - |p| without cancellation, metres."""
    num = wp.dot(q, q) - 2.0 * wp.dot(p, q)
    return num / (wp.sqrt(wp.max(norm_m * norm_m + num, 0.0)) + norm_m)


@wp.func
def phasor_of_cycles(cycles: wp.float64) -> wp.vec2f:
    """exp(j 2 pi cycles) as (re, im), reduced in float64 before float32."""
    frac = wp.float32(cycles - wp.round(cycles)) * wp.float32(2.0 * wp.pi)
    return wp.vec2f(wp.cos(frac), wp.sin(frac))


@wp.func
def cmul(a: wp.vec2f, b: wp.vec2f) -> wp.vec2f:
    return wp.vec2f(a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


@wp.kernel
def correlate_direct(grid: int, points: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.float64),
                     y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64), rx: wp.array(dtype=wp.vec3f),
                     tx: wp.array(dtype=wp.vec3f), k_rad_per_m: wp.array(dtype=wp.float32),
                     signal: wp.array3d(dtype=wp.vec2f), sum_freqs: int, out: wp.array2d(dtype=wp.vec2f)):
    """Plain float32 direct sum: phase k (|p - rx| + |p - tx|) and one sincos per pair and frequency."""
    i = wp.tid()
    p = wp.vec3f(point_at(i, grid, points, x, y, z))
    total = wp.vec2f(0.0, 0.0)
    for f in range(signal.shape[0]):
        acc = wp.vec2f(0.0, 0.0)
        for r in range(rx.shape[0]):
            d_rx = wp.length(p - rx[r])
            for t in range(tx.shape[0]):
                phase = k_rad_per_m[f] * (d_rx + wp.length(p - tx[t]))
                acc += cmul(signal[f, r, t], wp.vec2f(wp.cos(phase), wp.sin(phase)))
        if sum_freqs == 0:
            out[f, i] = acc
        total += acc
    if sum_freqs != 0:
        out[0, i] = total


@wp.kernel
def correlate_separable(grid: int, points: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.float64),
                        y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64), rx: wp.array(dtype=wp.vec3f),
                        tx: wp.array(dtype=wp.vec3f), k_rad_per_m: wp.array(dtype=wp.float32),
                        cycles_per_m: wp.array(dtype=wp.float64), signal: wp.array3d(dtype=wp.vec2f), sum_freqs: int,
                        out: wp.array2d(dtype=wp.vec2f)):
    """Separable sum a^T S b: R + T sincos per point and frequency, R*T complex multiply-adds.

    The Tx axis (padded to a multiple of TX_CHUNK with zero signal) is walked in chunks whose steering values
    stay in registers (unrolled loop); the Rx steering vector is kept in a thread-local array.
    """
    i = wp.tid()
    p64 = point_at(i, grid, points, x, y, z)
    norm64 = wp.length(p64)
    p = wp.vec3f(p64)
    norm = wp.float32(norm64)
    a_re = vec_ant()
    a_im = vec_ant()
    total = wp.vec2f(0.0, 0.0)
    for f in range(signal.shape[0]):
        k = k_rad_per_m[f]
        for r in range(rx.shape[0]):
            phase = k * path_excess_m(p, norm, rx[r])
            a_re[r] = wp.cos(phase)
            a_im[r] = wp.sin(phase)
        acc = wp.vec2f(0.0, 0.0)
        for chunk in range(signal.shape[2] // TX_CHUNK):
            t0 = chunk * TX_CHUNK
            b_re = vec_chunk()
            b_im = vec_chunk()
            for j in range(TX_CHUNK):
                phase = k * path_excess_m(p, norm, tx[t0 + j])
                b_re[j] = wp.cos(phase)
                b_im[j] = wp.sin(phase)
            for r in range(rx.shape[0]):
                sb = wp.vec2f(0.0, 0.0)
                for j in range(TX_CHUNK):
                    sb += cmul(signal[f, r, t0 + j], wp.vec2f(b_re[j], b_im[j]))
                acc += cmul(wp.vec2f(a_re[r], a_im[r]), sb)
        val = cmul(acc, phasor_of_cycles(norm64 * cycles_per_m[f]))
        if sum_freqs == 0:
            out[f, i] = val
        total += val
    if sum_freqs != 0:
        out[0, i] = total


TC_POINTS = wp.constant(64)        # points per block of `correlate_tiles_rx_product` (tc v1)
TC_ANT = wp.constant(96)           # antennas per side, padded (zero signal in the pads)
TC_K = wp.constant(192)            # 2 * TC_ANT: [cos | sin] columns, [Re | Im] output columns
TC_BLOCK = 256                     # threads per block (both tc kernels)


@wp.func
def path_excess4_m(p: wp.vec4f, q: wp.vec4f) -> wp.float32:
    """|p - q| - |p| for p = (x, y, z, |p|) and q = (x, y, z, |q|^2), metres (as `path_excess_m`)."""
    num = q[3] - 2.0 * (p[0] * q[0] + p[1] * q[1] + p[2] * q[2])
    return num / (wp.sqrt(wp.max(p[3] * p[3] + num, 0.0)) + p[3])


@wp.func
def reduced_phase(e: wp.float32, k: wp.float32) -> wp.float32:
    """k e reduced to [-pi, pi] (two-constant Cody-Waite), so fast-math sin/cos stay accurate (abs err ~5e-7)."""
    ph = k * e
    n = wp.round(ph * 0.15915494309189535)
    return (ph - n * 6.2831854820251465) + n * 1.7484556000744883e-07


@wp.func
def cos_half(e: wp.float32, k: wp.float32) -> wp.float16:
    return wp.float16(wp.cos(reduced_phase(e, k)))


@wp.func
def sin_half(e: wp.float32, k: wp.float32) -> wp.float16:
    return wp.float16(wp.sin(reduced_phase(e, k)))


@wp.func
def tx_steering_term(yre: wp.float32, yim: wp.float32, e: wp.float32, k: wp.float32) -> wp.vec2f:
    """(yre + j yim) * exp(j k e): one term of the row-wise dot with the Tx steering vector."""
    ph = reduced_phase(e, k)
    c = wp.cos(ph)
    s = wp.sin(ph)
    return wp.vec2f(yre * c - yim * s, yre * s + yim * c)


@wp.func
def cmul_gain(a: wp.vec2f, b: wp.vec2f, g: wp.float32) -> wp.vec2f:
    return wp.vec2f(a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0]) * g


@wp.kernel(enable_backward=False)
def prepare_points(grid: int, points: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.float64),
                   y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64),
                   cycles_per_m: wp.array(dtype=wp.float64), pts: wp.array(dtype=wp.vec4f),
                   common: wp.array2d(dtype=wp.vec2f), count: wp.array(dtype=wp.int32)):
    """Per point: (x, y, z, |p|) in float32 and the common phasor exp(j 2 k |p|) per frequency (float64 reduced);
    only the first count[0] points (a launch of fixed size in a CUDA graph: the rest are left as they were, and the
    tensor-core blocks that would read them return at once or compute lanes nobody reads)."""
    i = wp.tid()
    if i >= count[0]:
        return
    p64 = point_at(i, grid, points, x, y, z)
    norm64 = wp.length(p64)
    pts[i] = wp.vec4f(wp.float32(p64[0]), wp.float32(p64[1]), wp.float32(p64[2]), wp.float32(norm64))
    for f in range(cycles_per_m.shape[0]):
        common[f, i] = phasor_of_cycles(norm64 * cycles_per_m[f])


@wp.kernel(module="unique", module_options={"fast_math": True, "enable_backward": False})
def correlate_tiles_rx_product(pts: wp.array(dtype=wp.vec4f), rx: wp.array(dtype=wp.vec4f),
                               tx: wp.array(dtype=wp.vec4f), k_rad_per_m: wp.array(dtype=wp.float32),
                               gain: wp.array(dtype=wp.float32), mat: wp.array3d(dtype=wp.float16),
                               common: wp.array2d(dtype=wp.vec2f), sum_freqs: int, out: wp.array2d(dtype=wp.vec2f)):
    """Separable sum on the tensor cores, one block per TC_POINTS points.

    Per frequency: A = [cos | sin](k e_rx) (fp16, phases reduced to [-pi, pi] before the fast sin/cos),
    Y = A @ [[Sr, Si], [-Si, Sr]] / gain (fp16 operands, fp32 accumulation) = [Re(a^T S) | Im(a^T S)], then
    sum_t Y_t exp(j k e_tx) in fp32, times the common phasor and the gain. Own module: fast math for this kernel only.
    """
    blk = wp.tid()
    i0 = blk * TC_POINTS
    p = wp.tile_load(pts, shape=TC_POINTS, offset=i0, storage="shared")
    pb = wp.tile_broadcast(wp.tile_reshape(p, shape=(TC_POINTS, 1)), shape=(TC_POINTS, TC_ANT))
    qr = wp.tile_load(rx, shape=TC_ANT, storage="shared")
    qt = wp.tile_load(tx, shape=TC_ANT, storage="shared")
    e_rx = wp.tile_map(path_excess4_m, pb, wp.tile_broadcast(wp.tile_reshape(qr, shape=(1, TC_ANT)),
                                                       shape=(TC_POINTS, TC_ANT)))
    e_tx = wp.tile_map(path_excess4_m, pb, wp.tile_broadcast(wp.tile_reshape(qt, shape=(1, TC_ANT)),
                                                       shape=(TC_POINTS, TC_ANT)))
    a = wp.tile_empty(shape=(TC_POINTS, TC_K), dtype=wp.float16, storage="shared")
    y = wp.tile_empty(shape=(TC_POINTS, TC_K), dtype=wp.float32, storage="shared")
    total = wp.tile_zeros(shape=TC_POINTS, dtype=wp.vec2f)
    for f in range(k_rad_per_m.shape[0]):
        k = k_rad_per_m[f]
        wp.tile_assign(a, wp.tile_map(cos_half, e_rx, k), offset=(0, 0))
        wp.tile_assign(a, wp.tile_map(sin_half, e_rx, k), offset=(0, TC_ANT))
        m = wp.tile_load(mat[f], shape=(TC_K, TC_K), storage="shared", aligned=True)
        wp.tile_matmul(a, m, y, alpha=1.0, beta=0.0)
        y_re = wp.tile_view(y, offset=(0, 0), shape=(TC_POINTS, TC_ANT))
        y_im = wp.tile_view(y, offset=(0, TC_ANT), shape=(TC_POINTS, TC_ANT))
        acc = wp.tile_sum(wp.tile_map(tx_steering_term, y_re, y_im, e_tx, k), axis=1)
        val = wp.tile_map(cmul_gain, acc, wp.tile_load(common[f], shape=TC_POINTS, offset=i0), gain[f])
        if sum_freqs == 0:
            wp.tile_store(out[f], val, offset=i0)
        else:
            total = total + val
    if sum_freqs != 0:
        wp.tile_store(out[0], total, offset=i0)


TC2_POINTS = wp.constant(128)      # points per block of `correlate_tiles_tx_halves` (tc v2)
TC2_GROUPS = wp.constant(TC_BLOCK // 128)   # threads per point: each takes every TC2_GROUPS-th Tx of a half
TC2_HALF = wp.constant(48)         # Tx antennas per half (2 x 48 = TC_ANT)
TC2_PAD = wp.constant(8)           # zero rows/columns that move the shared-memory rows off multiples of 128 bytes
TC2_KP = wp.constant(200)          # K padded: TC_K + TC2_PAD (rows of M_h^T and A^T)
TC2_NP = wp.constant(136)          # N padded: TC2_POINTS + TC2_PAD (columns of A^T and Y_h^T; pads never read)


@wp.kernel(module="unique", module_options={"fast_math": True, "enable_backward": False})
def correlate_tiles_tx_halves(pts: wp.array(dtype=wp.vec4f), rx: wp.array(dtype=wp.vec4f), tx: wp.array(dtype=wp.vec4f),
                              k_rad_per_m: wp.array(dtype=wp.float32), gain: wp.array(dtype=wp.float32),
                              mat_h: wp.array4d(dtype=wp.float16), common: wp.array2d(dtype=wp.vec2f), sum_freqs: int,
                              out: wp.array2d(dtype=wp.vec2f), count: wp.array(dtype=wp.int32)):
    """Separable sum on the tensor cores (tc v2): the transposed product per Tx half, Y_h^T = M_h^T A^T (96 x 128,
    fp32 accumulation), with M_h^T = rows [Re | Im] of the Tx half h (96 x 192 fp16, `FrameInputs.tx_half_tables`)
    and A^T = [cos; sin](k e_rx) (192 x 128 fp16), so that shared memory is A^T + M_h^T + Y_h^T. K and N are padded
    by 8 (zero K rows, unused N columns). The Tx dot runs per thread from the (point-contiguous) Y_h^T columns:
    thread lane takes point lane % 128 and every TC2_GROUPS-th Tx of the half, then `wp.tile` +
    `tile_sum(axis=0)` combine the partial sums. Blocks from point count[0] on return at once (a launch of fixed
    size in a CUDA graph: the whole block takes the same branch)."""
    blk, lane = wp.tid()
    i0 = blk * TC2_POINTS
    if i0 >= count[0]:
        return
    pt = lane % TC2_POINTS
    grp = lane // TC2_POINTS
    p = wp.tile_load(pts, shape=TC2_POINTS, offset=i0, storage="shared")
    qr = wp.tile_load(rx, shape=TC_ANT, storage="shared")
    qt = wp.tile_load(tx, shape=TC_ANT, storage="shared")
    pb = wp.tile_broadcast(wp.tile_reshape(p, shape=(1, TC2_POINTS)), shape=(TC_ANT, TC2_POINTS))
    qb = wp.tile_broadcast(wp.tile_reshape(qr, shape=(TC_ANT, 1)), shape=(TC_ANT, TC2_POINTS))
    a = wp.tile_empty(shape=(TC2_KP, TC2_NP), dtype=wp.float16, storage="shared")
    wp.tile_assign(a, wp.tile_zeros(shape=(TC2_PAD, TC2_NP), dtype=wp.float16), offset=(TC_K, 0))  # 0 x garbage: NaN
    e_rx = wp.tile_map(path_excess4_m, pb, qb)
    y = wp.tile_empty(shape=(TC_ANT, TC2_NP), dtype=wp.float32, storage="shared")
    pp = p[pt]
    total = wp.tile_zeros(shape=TC2_POINTS, dtype=wp.vec2f)
    for f in range(k_rad_per_m.shape[0]):
        k = k_rad_per_m[f]
        wp.tile_assign(a, wp.tile_map(cos_half, e_rx, k), offset=(0, 0))
        wp.tile_assign(a, wp.tile_map(sin_half, e_rx, k), offset=(TC_ANT, 0))
        acc = wp.vec2f(0.0, 0.0)
        for h in range(mat_h.shape[1]):                  # run-time bound (2): one M_h^T allocation, not unrolled
            m = wp.tile_load(mat_h[f, h], shape=(TC_ANT, TC2_KP), storage="shared", aligned=True)
            wp.tile_matmul(m, a, y, alpha=1.0, beta=0.0)
            for jj in range(grp, TC2_HALF, TC2_GROUPS):
                d = tx_steering_term(y[jj, pt], y[jj + TC2_HALF, pt], path_excess4_m(pp, qt[h * TC2_HALF + jj]), k)
                acc = acc + d
        part = wp.tile_reshape(wp.tile(acc, preserve_type=True), shape=(TC2_GROUPS, TC2_POINTS))
        val = wp.tile_map(cmul_gain, wp.tile_sum(part, axis=0),
                          wp.tile_load(common[f], shape=TC2_POINTS, offset=i0), gain[f])
        if sum_freqs == 0:
            wp.tile_store(out[f], val, offset=i0)
        else:
            total = total + val
    if sum_freqs != 0:
        wp.tile_store(out[0], total, offset=i0)


TC3_SCALE = wp.constant(2048.0)      # 2^11: an fp16 rounding's residual scaled back into fp16's normal range
TC3_UNSCALE = wp.constant(1.0 / 2048.0)


@wp.func
def cos_lo(e: wp.float32, k: wp.float32) -> wp.float16:
    """(cos - fp16(cos)) * TC3_SCALE in fp16: cos_half + cos_lo / TC3_SCALE is the fp32 cosine to ~2^-22 (the
    kernel's fast_math cosine itself is good to ~2^-21: the measured 4e-6 against float64 includes both)."""
    c = wp.cos(reduced_phase(e, k))
    return wp.float16((c - wp.float32(wp.float16(c))) * TC3_SCALE)


@wp.func
def sin_lo(e: wp.float32, k: wp.float32) -> wp.float16:
    s = wp.sin(reduced_phase(e, k))
    return wp.float16((s - wp.float32(wp.float16(s))) * TC3_SCALE)


@wp.kernel(module="unique", module_options={"fast_math": True, "enable_backward": False})
def correlate_tiles_tx_split(pts: wp.array(dtype=wp.vec4f), rx: wp.array(dtype=wp.vec4f), tx: wp.array(dtype=wp.vec4f),
                             k_rad_per_m: wp.array(dtype=wp.float32), gain: wp.array(dtype=wp.float32),
                             mat_hl: wp.array4d(dtype=wp.float16), common: wp.array2d(dtype=wp.vec2f), sum_freqs: int,
                             out: wp.array2d(dtype=wp.vec2f), count: wp.array(dtype=wp.int32)):
    """`correlate_tiles_tx_halves` with split fp16 operands (kernel "tc3"): each operand X = X_hi + X_lo / 2^11 (both
    fp16), and per Tx half Y_h^T = M_hi A_hi + (M_hi A_lo + M_lo A_hi) / 2^11 on the tensor cores (fp32
    accumulation; the lo * lo term, ~2^-22, is left out), so the product carries ~fp32 operand precision instead of
    fp16's 2^-11. mat_hl (F, 4, 96, TC2_KP): slot 2 h + 0 is M_h^T's hi part (`tx_half_tables`' values), slot
    2 h + 1 its scaled residual. Shared memory: A_hi, A_lo, one M slot, Y_h^T (~204 KB, one block per SM)."""
    blk, lane = wp.tid()
    i0 = blk * TC2_POINTS
    if i0 >= count[0]:
        return
    pt = lane % TC2_POINTS
    grp = lane // TC2_POINTS
    p = wp.tile_load(pts, shape=TC2_POINTS, offset=i0, storage="shared")
    qr = wp.tile_load(rx, shape=TC_ANT, storage="shared")
    qt = wp.tile_load(tx, shape=TC_ANT, storage="shared")
    pb = wp.tile_broadcast(wp.tile_reshape(p, shape=(1, TC2_POINTS)), shape=(TC_ANT, TC2_POINTS))
    qb = wp.tile_broadcast(wp.tile_reshape(qr, shape=(TC_ANT, 1)), shape=(TC_ANT, TC2_POINTS))
    a = wp.tile_empty(shape=(TC2_KP, TC2_NP), dtype=wp.float16, storage="shared")
    a_lo = wp.tile_empty(shape=(TC2_KP, TC2_NP), dtype=wp.float16, storage="shared")
    wp.tile_assign(a, wp.tile_zeros(shape=(TC2_PAD, TC2_NP), dtype=wp.float16), offset=(TC_K, 0))  # 0 x garbage: NaN
    wp.tile_assign(a_lo, wp.tile_zeros(shape=(TC2_PAD, TC2_NP), dtype=wp.float16), offset=(TC_K, 0))
    e_rx = wp.tile_map(path_excess4_m, pb, qb)
    y = wp.tile_empty(shape=(TC_ANT, TC2_NP), dtype=wp.float32, storage="shared")
    pp = p[pt]
    total = wp.tile_zeros(shape=TC2_POINTS, dtype=wp.vec2f)
    n_half = mat_hl.shape[1] // 2
    n_part = mat_hl.shape[1] // n_half
    for f in range(k_rad_per_m.shape[0]):
        k = k_rad_per_m[f]
        wp.tile_assign(a, wp.tile_map(cos_half, e_rx, k), offset=(0, 0))
        wp.tile_assign(a, wp.tile_map(sin_half, e_rx, k), offset=(TC_ANT, 0))
        wp.tile_assign(a_lo, wp.tile_map(cos_lo, e_rx, k), offset=(0, 0))
        wp.tile_assign(a_lo, wp.tile_map(sin_lo, e_rx, k), offset=(TC_ANT, 0))
        acc = wp.vec2f(0.0, 0.0)
        for h in range(n_half):                          # run-time bounds: one M slot allocation, not unrolled
            for part in range(n_part):
                m = wp.tile_load(mat_hl[f, h * n_part + part], shape=(TC_ANT, TC2_KP), storage="shared",
                                 aligned=True)
                if part == 0:
                    wp.tile_matmul(m, a, y, alpha=1.0, beta=0.0)
                    wp.tile_matmul(m, a_lo, y, alpha=TC3_UNSCALE, beta=1.0)
                else:
                    wp.tile_matmul(m, a, y, alpha=TC3_UNSCALE, beta=1.0)
            for jj in range(grp, TC2_HALF, TC2_GROUPS):
                d = tx_steering_term(y[jj, pt], y[jj + TC2_HALF, pt], path_excess4_m(pp, qt[h * TC2_HALF + jj]), k)
                acc = acc + d
        part_sum = wp.tile_reshape(wp.tile(acc, preserve_type=True), shape=(TC2_GROUPS, TC2_POINTS))
        val = wp.tile_map(cmul_gain, wp.tile_sum(part_sum, axis=0),
                          wp.tile_load(common[f], shape=TC2_POINTS, offset=i0), gain[f])
        if sum_freqs == 0:
            wp.tile_store(out[f], val, offset=i0)
        else:
            total = total + val
    if sum_freqs != 0:
        wp.tile_store(out[0], total, offset=i0)


RANGE_CHUNK = wp.constant(16)      # Tx steering values the range gather keeps in registers at a time
vec_range = wp.types.vector(length=16, dtype=wp.float32)


@wp.func
def lerp_profile(profiles: wp.array2d(dtype=wp.vec2h), row: int, iu: int, w: wp.float32) -> wp.vec2f:
    g0 = wp.vec2f(profiles[row, iu])
    return g0 + w * (wp.vec2f(profiles[row, iu + 1]) - g0)


@wp.kernel(enable_backward=False)
def range_profiles(raw: wp.array3d(dtype=wp.vec2f), scale: wp.float32, n_tx_padded: int,
                   grid_index: wp.array(dtype=wp.int32), twiddle: wp.array(dtype=wp.vec2f),
                   shift: wp.array(dtype=wp.vec2f), m0: int, profiles: wp.array2d(dtype=wp.vec2h)):
    """profiles[pair, j] = shift[m] sum_n scale raw[r, t, n] twiddle[(i_n m) mod L], m = (m0 + j) mod L, in fp16,
    pair = r * n_tx_padded + t (zero for the padded t >= T): straight from the uploaded raw frame (R, T, F)."""
    pair, j = wp.tid()
    r = pair // n_tx_padded
    t = pair % n_tx_padded
    if t >= raw.shape[1]:
        profiles[pair, j] = wp.vec2h(wp.float16(0.0), wp.float16(0.0))
        return
    n_samples = twiddle.shape[0]
    m = (m0 + j) % n_samples
    acc = wp.vec2f(0.0, 0.0)
    for n in range(raw.shape[2]):
        acc += cmul(raw[r, t, n] * scale, twiddle[(grid_index[n] * m) % n_samples])
    profiles[pair, j] = wp.vec2h(cmul(shift[m], acc))


@wp.func
def range_partial(p64: wp.vec3d, lane: int, stride: int, rx: wp.array(dtype=wp.vec3f), tx: wp.array(dtype=wp.vec3f),
                  k_carrier: wp.float32, samples_per_m: wp.float32, m0: wp.float32,
                  profiles: wp.array2d(dtype=wp.vec2h)) -> wp.vec2f:
    """Range-compressed value at point p64 without its common phasor, over this lane's share of the (Tx chunk,
    receiver) units: sum over pairs of carrier phasor times the linearly interpolated range profile. Tx (padded to a
    multiple of TX_CHUNK, zero profiles in the pads) in chunks of RANGE_CHUNK whose sample offsets and carrier
    phasors stay in registers; units chunk-major, lane l of `stride` takes a contiguous run of them (a lane of a
    32-thread block computes the steering of one or two chunks, not all); the profile window starts at sample m0."""
    norm64 = wp.length(p64)
    p = wp.vec3f(p64)
    norm = wp.float32(norm64)
    n_tx = tx.shape[0]
    n_rx = rx.shape[0]
    u_max = wp.float32(profiles.shape[1]) - 1.001
    n_units = (n_tx // RANGE_CHUNK) * n_rx
    per_lane = (n_units + stride - 1) // stride
    acc = wp.vec2f(0.0, 0.0)
    u_tx = vec_range()
    b_re = vec_range()
    b_im = vec_range()
    chunk = int(-1)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    for unit in range(lane * per_lane, wp.min((lane + 1) * per_lane, n_units)):
        t0 = (unit // n_rx) * RANGE_CHUNK
        r = unit % n_rx
        if unit // n_rx != chunk:
            chunk = unit // n_rx
            for j in range(RANGE_CHUNK):
                e = path_excess_m(p, norm, tx[t0 + j])
                u_tx[j] = e * samples_per_m
                b_re[j] = wp.cos(k_carrier * e)
                b_im[j] = wp.sin(k_carrier * e)
        e_rx = path_excess_m(p, norm, rx[r])
        base = (2.0 * norm + e_rx) * samples_per_m - m0
        row = r * n_tx + t0
        gb = wp.vec2f(0.0, 0.0)
        for j in range(RANGE_CHUNK):
            u = wp.clamp(base + u_tx[j], 0.0, u_max)
            iu = wp.int32(u)
            w = u - wp.float32(iu)
            g = lerp_profile(profiles, row + j, iu, w)
            gb += cmul(g, wp.vec2f(b_re[j], b_im[j]))
        phase = k_carrier * e_rx
        acc += cmul(wp.vec2f(wp.cos(phase), wp.sin(phase)), gb)
    return acc


@wp.kernel(module="unique", module_options={"enable_backward": False, "max_unroll": 32})
def range_gather(grid: int, points: wp.array(dtype=wp.vec3d), x: wp.array(dtype=wp.float64),
                 y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64),
                 rx: wp.array(dtype=wp.vec3f), tx: wp.array(dtype=wp.vec3f), k_carrier: wp.float32,
                 carrier_cycles_per_m: wp.float64, samples_per_m: wp.float32, m0: wp.float32,
                 profiles: wp.array2d(dtype=wp.vec2h), out: wp.array2d(dtype=wp.vec2f)):
    """Range-compressed value of voxel or point i (`point_at`: flat voxel i of the grid x, y, z, or points[i]):
    `range_partial` over every receiver times the common phasor exp(j k_c 2 |p|) (float64 reduced)."""
    i = wp.tid()
    p64 = point_at(i, grid, points, x, y, z)
    acc = range_partial(p64, 0, 1, rx, tx, k_carrier, samples_per_m, m0, profiles)
    out[0, i] = cmul(acc, phasor_of_cycles(wp.length(p64) * carrier_cycles_per_m))


@wp.kernel(enable_backward=False)
def volume_peak_depth(vol: wp.array2d(dtype=wp.vec2f), n_z: int, z_first_m: wp.float64, dz_m: wp.float64,
                      maps: wp.array2d(dtype=wp.float64)):
    """`bp.peak_depth_m` for one pixel of a (z, pixel) volume: first argmax of |V| over z, parabola on the dB of
    k-1, k, k+1 (clipped at the ends, float64), maps = (depth, max |V|)."""
    i = wp.tid()
    n_px = maps.shape[1]
    best = wp.float32(-1.0)
    kb = int(0)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    for k in range(n_z):
        m = wp.length(vol[0, k * n_px + i])
        if m > best:
            best = m
            kb = k
    tiny = wp.float64(1.1754943508222875e-38)
    db_m = wp.float64(20.0) * wp.log10(wp.max(wp.float64(wp.length(vol[0, wp.max(kb - 1, 0) * n_px + i])), tiny))
    db_0 = wp.float64(20.0) * wp.log10(wp.max(wp.float64(best), tiny))
    db_p = wp.float64(20.0) * wp.log10(wp.max(wp.float64(wp.length(vol[0, wp.min(kb + 1, n_z - 1) * n_px + i])),
                                              tiny))
    curvature = db_m - wp.float64(2.0) * db_0 + db_p
    offset = wp.float64(0.0)
    if curvature < wp.float64(0.0):
        offset = wp.float64(0.5) * (db_m - db_p) / curvature
    maps[0, i] = z_first_m + (wp.float64(kb) + offset) * dz_m
    maps[1, i] = wp.float64(best)
