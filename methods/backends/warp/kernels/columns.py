"""Warp kernels of the column-separable back-projection (launched by `methods.backends.warp.columns`).

Transmitters on a few columns (equal x and z): for an image row y and a column c the transmit path of element t
is sqrt(rho^2 + (y - y_t)^2) with rho = sqrt((x - x_c)^2 + (z - z_c)^2), so per row the transmit sums
T[r, c](rho) = sum_{t in c} S[r, t] exp(j k sqrt(rho^2 + dy_t^2)) form a table over rho, and a voxel needs only its
receive phasors and one interpolated table value per receiver and column. The table is stored demodulated by
exp(j k g(rho)) (g the mean of the row's extreme paths, `ColumnPlan`), which leaves a slowly varying function of
rho that 4-point Lagrange interpolation reproduces within the plan's bound.

* `column_phasors`: E[j, f, q, m] = exp(j k_f (sqrt(rho_m^2 + dy_jq^2) - g_jc(rho_m))) per row j, frequency f,
  table transmitter q (of column c) and rho sample m (float64 phase, reduced before the float32 sincos);
* `column_table`: B[j, f, r, c, m] = sum_{q in c} S[f, r, t_q] E[j, f, q, m] (flattened rows (j, f, r, c)), each
  sample stored with its successor (vec4f (B[m], B[m + 1])) so that the 4 taps take two 16-byte loads (measured
  10 % faster on the H100 than four 8-byte loads);
* `column_gather`: per voxel the sum over frequencies of sum_r exp(j k e_r) (sum_c exp(j k (|p| + g_c)) B_c(rho_c)
  + exp(j 2 k |p|) sum_{t small} S[f, r, t] exp(j k e_t)), with e = |p - q| - |p| (cancellation-free, float32)
  and the interpolated B_c; transmitters of small columns (QAR50's end elements) are taken directly.
"""
from __future__ import annotations

import warp as wp

from methods.backends.warp.kernels.correlation import cmul, path_excess_m, phasor_of_cycles, reduced_phase

MAX_COLUMNS = 4                    # table columns a gather thread holds in registers
MAX_SMALL = 8                      # transmitters of small columns taken directly
vec_cols = wp.types.vector(length=MAX_COLUMNS, dtype=wp.float32)
vec_cols_d = wp.types.vector(length=MAX_COLUMNS, dtype=wp.float64)
vec_cols_i = wp.types.vector(length=MAX_COLUMNS, dtype=wp.int32)
vec_small = wp.types.vector(length=MAX_SMALL, dtype=wp.float32)


@wp.func
def mean_path_m(r2: wp.float64, a_lo: wp.float64, a_hi: wp.float64) -> wp.float64:
    """g(rho): the mean of sqrt(rho^2 + a) at the row's smallest and largest squared y offset of a column."""
    return wp.float64(0.5) * (wp.sqrt(r2 + a_lo) + wp.sqrt(r2 + a_hi))


@wp.kernel(enable_backward=False)
def column_phasors(rows_y: wp.array(dtype=wp.float64), tx_y: wp.array(dtype=wp.float64),
                   tx_col: wp.array(dtype=wp.int32), a_lo: wp.array2d(dtype=wp.float64),
                   a_hi: wp.array2d(dtype=wp.float64), cycles_per_m: wp.array(dtype=wp.float64),
                   rho0_m: wp.float64, step_m: wp.float64, phasors: wp.array4d(dtype=wp.vec2f)):
    """E[j, f, q, m] (module doc); cycles_per_m = f / c."""
    j, f, q, m = wp.tid()
    rho = rho0_m + wp.float64(m) * step_m
    r2 = rho * rho
    c = tx_col[q]
    dy = rows_y[j] - tx_y[q]
    path = wp.sqrt(r2 + dy * dy) - mean_path_m(r2, a_lo[j, c], a_hi[j, c])
    phasors[j, f, q, m] = phasor_of_cycles(cycles_per_m[f] * path)


@wp.kernel(enable_backward=False)
def column_table(signal: wp.array3d(dtype=wp.vec2f), table_tx: wp.array(dtype=wp.int32),
                 col_start: wp.array(dtype=wp.int32), phasors: wp.array4d(dtype=wp.vec2f),
                 table: wp.array2d(dtype=wp.vec4f)):
    """B[((j F + f) R + r) C + c, m] = sum over the column's transmitters q of S[f, r, t_q] E[j, f, q, m]."""
    j, f, rc, m = wp.tid()
    n_cols = col_start.shape[0] - 1
    r = rc // n_cols
    c = rc % n_cols
    acc = wp.vec2f(0.0, 0.0)
    nxt = wp.vec2f(0.0, 0.0)
    last = phasors.shape[3] - 1
    for q in range(col_start[c], col_start[c + 1]):
        sq = signal[f, r, table_tx[q]]
        acc += cmul(sq, phasors[j, f, q, m])
        nxt += cmul(sq, phasors[j, f, q, wp.min(m + 1, last)])
    table[(j * signal.shape[0] + f) * signal.shape[1] * n_cols + rc, m] = wp.vec4f(acc[0], acc[1], nxt[0], nxt[1])


@wp.kernel(module="unique", module_options={"fast_math": True, "enable_backward": False})
def column_gather(x: wp.array(dtype=wp.float64), y: wp.array(dtype=wp.float64), z: wp.array(dtype=wp.float64),
                  rx: wp.array(dtype=wp.vec3f), small_tx: wp.array(dtype=wp.vec3f),
                  small_signal: wp.array3d(dtype=wp.vec2f), cols_xz: wp.array(dtype=wp.vec2d),
                  a_lo: wp.array2d(dtype=wp.float64), a_hi: wp.array2d(dtype=wp.float64),
                  k_rad_per_m: wp.array(dtype=wp.float32), cycles_per_m: wp.array(dtype=wp.float64),
                  rho0_m: wp.float64, inv_step: wp.float64, table: wp.array2d(dtype=wp.vec4f),
                  out: wp.array2d(dtype=wp.vec2f)):
    """Frequency-summed value of voxel i (row-major over (y row, z, x): threads of a row share its table),
    written to out[0, (z * ny + y) * nx + x] (the layout of `volume_peak_depth`). Loops over columns and small
    transmitters have constant bounds (unrolled: their per-voxel values stay in registers); receive phases are
    reduced before the fast sin/cos (`reduced_phase`), common phases in float64."""
    i = wp.tid()
    nx = x.shape[0]
    nz = z.shape[0]
    ny = y.shape[0]
    ix = i % nx
    iz = (i // nx) % nz
    j = i // (nx * nz)
    p64 = wp.vec3d(x[ix], y[j], z[iz])
    norm64 = wp.length(p64)
    p = wp.vec3f(p64)
    norm = wp.float32(norm64)
    n_cols = cols_xz.shape[0]
    n_small = small_tx.shape[0]
    n_rx = rx.shape[0]
    n_freqs = k_rad_per_m.shape[0]
    last = table.shape[1] - 3
    base = vec_cols_i()
    w0 = vec_cols()
    w1 = vec_cols()
    w2 = vec_cols()
    w3 = vec_cols()
    path = vec_cols_d()
    for c in range(MAX_COLUMNS):
        if c < n_cols:
            dx = x[ix] - cols_xz[c][0]
            dz = z[iz] - cols_xz[c][1]
            r2 = dx * dx + dz * dz
            path[c] = norm64 + mean_path_m(r2, a_lo[j, c], a_hi[j, c])
            u = (wp.sqrt(r2) - rho0_m) * inv_step
            b = wp.clamp(wp.int32(wp.floor(u)) - 1, 0, last)
            base[c] = b
            s = wp.float32(u - wp.float64(b + 1))
            sp = s + 1.0
            sm = s - 1.0
            s2 = s - 2.0
            w0[c] = -s * sm * s2 / 6.0
            w1[c] = sp * sm * s2 * 0.5
            w2[c] = -sp * s * s2 * 0.5
            w3[c] = sp * s * sm / 6.0
    total = wp.vec2f(0.0, 0.0)
    for f in range(n_freqs):
        k = k_rad_per_m[f]
        q_re = vec_cols()
        q_im = vec_cols()
        for c in range(MAX_COLUMNS):
            if c < n_cols:
                q = phasor_of_cycles(cycles_per_m[f] * path[c])
                q_re[c] = q[0]
                q_im[c] = q[1]
        s_re = vec_small()
        s_im = vec_small()
        common = phasor_of_cycles(cycles_per_m[f] * wp.float64(2.0) * norm64)     # exp(j k 2 |p|)
        for t in range(MAX_SMALL):
            if t < n_small:
                e = path_excess_m(p, norm, small_tx[t])
                v = cmul(common, wp.vec2f(wp.cos(reduced_phase(e, k)), wp.sin(reduced_phase(e, k))))
                s_re[t] = v[0]
                s_im[t] = v[1]
        row0 = (j * n_freqs + f) * n_rx * n_cols
        acc = wp.vec2f(0.0, 0.0)
        for r in range(n_rx):
            inner = wp.vec2f(0.0, 0.0)
            for c in range(MAX_COLUMNS):
                if c < n_cols:
                    row = row0 + r * n_cols + c
                    b = base[c]
                    t01 = table[row, b]
                    t23 = table[row, b + 2]
                    v = wp.vec2f(t01[0] * w0[c] + t01[2] * w1[c] + t23[0] * w2[c] + t23[2] * w3[c],
                                 t01[1] * w0[c] + t01[3] * w1[c] + t23[1] * w2[c] + t23[3] * w3[c])
                    inner += cmul(wp.vec2f(q_re[c], q_im[c]), v)
            for t in range(MAX_SMALL):
                if t < n_small:
                    inner += cmul(small_signal[f, r, t], wp.vec2f(s_re[t], s_im[t]))
            ph = reduced_phase(path_excess_m(p, norm, rx[r]), k)
            acc += cmul(wp.vec2f(wp.cos(ph), wp.sin(ph)), inner)
        total += acc
    out[0, (iz * ny + j) * nx + ix] = total

