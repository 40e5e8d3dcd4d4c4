"""Warp kernels and functions of the depth prior on the radar grid (kernels only; launched by
`methods.backends.warp.prior`), reproducing the CPU prior (`methods.prior.priors`, `methods.prior.raster`) in float64:

* `raster_camera_quads`: one thread per 2x2 quad of the depth image. Its four corners are back-projected with the
  intrinsics (paper eq. 9, same float64 expressions as `prior.backproject_mm`), mapped with realsense2radar
  (`apply_transform`'s order of operations) onto continuous radar pixel coordinates, and the quad's triangles are
  formed exactly as `prior.grid_triangles` does (rule 'sound' with the depth-jump rule: 2 triangles, or 1 for
  three valid corners, each only where its camera depths jump by <= max_jump_mm). The quad culling of
  `prior.quads_around_centres` is not needed: it only drops triangles that cover no pixel centre.
* `raster_triangle`: the scanline rasteriser of `raster.rasterize_nearest_z` for one triangle (same row range, edge
  crossings, inclusive 1e-9 px epsilon, plane evaluation), nearest z kept with a float64 `atomic_min` z-buffer.
  Camera pixels are smaller than radar pixels, so a triangle covers 0-2 centres and the loops stay short.
* `covered_spans`, `hull_rows`, `hull_lattice_count`: the covered pixel count, each row's first/last covered
  column and each column's first/last covered row, and, exactly in integer arithmetic, the lattice points of the
  convex hull of the covered pixels (the input of the host's decision whether `raster.fill_convex_hull` can add
  pixels).
* `scanline_fill`: `raster.fill_scanline` (prior fill 'scanline'), one thread per pixel, into a second buffer.
"""
from __future__ import annotations

import warp as wp

FAR = wp.constant(wp.float64(1.0e300))          # z-buffer value of an uncovered pixel
EPS_PX = wp.constant(wp.float64(1e-9))            # the inclusive edge epsilon of methods.prior.raster, pixels
vec9d = wp.types.vector(length=9, dtype=wp.float64)   # fx, fy, cx, cy, mm per depth unit, xmin, ymax, px/m x, y


@wp.func
def edge_span(rowf: wp.float64, ua: wp.float64, va: wp.float64, ub: wp.float64, vb: wp.float64, lo: wp.float64,
              hi: wp.float64):
    """Column where the row line crosses edge a-b (t in [-eps, 1 + eps]) merged into [lo, hi]."""
    if vb != va:                                 # horizontal edges never cross (inf/NaN t on the CPU)
        t = (rowf - va) / (vb - va)
        if t >= -EPS_PX and t <= wp.float64(1.0) + EPS_PX:
            col = ua + t * (ub - ua)
            lo = wp.min(lo, col)
            hi = wp.max(hi, col)
    return lo, hi


@wp.func
def raster_triangle(u0: wp.float64, v0: wp.float64, z0: wp.float64, u1: wp.float64, v1: wp.float64, z1: wp.float64,
                    u2: wp.float64, v2: wp.float64, z2: wp.float64, n_rows: int, n_cols: int,
                    zbuf: wp.array(dtype=wp.float64)):
    """One triangle of `raster.rasterize_nearest_z` into the nearest-z buffer (row-major n_rows x n_cols)."""
    row_lo = wp.ceil(wp.min(wp.min(v0, v1), v2) - EPS_PX)
    row_hi = wp.floor(wp.max(wp.max(v0, v1), v2) + EPS_PX)
    last_row = wp.float64(n_rows - 1)
    last_col = wp.float64(n_cols - 1)
    if row_hi < wp.max(row_lo, wp.float64(0.0)) or row_lo > last_row:
        return
    if wp.max(wp.max(u0, u1), u2) < -EPS_PX or wp.min(wp.min(u0, u1), u2) > last_col + EPS_PX:
        return
    du1 = u1 - u0
    du2 = u2 - u0
    dv1 = v1 - v0
    dv2 = v2 - v0
    dz1 = z1 - z0
    dz2 = z2 - z0
    area2 = du1 * dv2 - du2 * dv1
    if wp.abs(area2) <= wp.float64(1e-12):
        return
    slope_u = (dz1 * dv2 - dz2 * dv1) / area2
    slope_v = (du1 * dz2 - du2 * dz1) / area2
    r_first = wp.int32(wp.max(row_lo, wp.float64(0.0)))
    r_last = wp.int32(wp.min(row_hi, last_row))
    for row in range(r_first, r_last + 1):
        rowf = wp.float64(row)
        lo = FAR
        hi = -FAR
        lo, hi = edge_span(rowf, u0, v0, u1, v1, lo, hi)
        lo, hi = edge_span(rowf, u1, v1, u2, v2, lo, hi)
        lo, hi = edge_span(rowf, u2, v2, u0, v0, lo, hi)
        if hi >= lo:
            first = wp.max(wp.ceil(lo - EPS_PX), wp.float64(0.0))
            last = wp.min(wp.floor(hi + EPS_PX), last_col)
            if last >= first:
                for col in range(wp.int32(first), wp.int32(last) + 1):
                    depth = z0 + slope_u * (wp.float64(col) - u0) + slope_v * (rowf - v0)
                    wp.atomic_min(zbuf, row * n_cols + col, depth)


@wp.func
def camera_corner(depth: wp.array2d(dtype=wp.uint16), mask: wp.array2d(dtype=wp.uint8), use_mask: int, r: int, c: int,
                  cam: vec9d, xf: wp.mat44d):
    """(u, v, z, valid) of camera pixel (r, c): radar column, row and depth; valid 1 or 0."""
    d = depth[r, c]
    if d == wp.uint16(0):
        return wp.vec4d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0), wp.float64(0.0))
    if use_mask != 0 and mask[r, c] == wp.uint8(0):
        return wp.vec4d(wp.float64(0.0), wp.float64(0.0), wp.float64(0.0), wp.float64(0.0))
    z_mm = wp.float64(d) * cam[4]
    x_mm = (wp.float64(c) - cam[2]) * z_mm / cam[0]
    y_mm = (wp.float64(r) - cam[3]) * z_mm / cam[1]
    px = xf[0, 0] * x_mm + xf[0, 1] * y_mm + xf[0, 2] * z_mm
    px += xf[0, 3]
    py = xf[1, 0] * x_mm + xf[1, 1] * y_mm + xf[1, 2] * z_mm
    py += xf[1, 3]
    pz = xf[2, 0] * x_mm + xf[2, 1] * y_mm + xf[2, 2] * z_mm
    pz += xf[2, 3]
    return wp.vec4d((px - cam[5]) * cam[7], (cam[6] - py) * cam[8], pz, wp.float64(1.0))


@wp.func
def raster_corners(a: wp.vec4d, b: wp.vec4d, c: wp.vec4d, n_rows: int, n_cols: int, zbuf: wp.array(dtype=wp.float64)):
    raster_triangle(a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2], n_rows, n_cols, zbuf)


@wp.func
def camera_z_mm(depth: wp.array2d(dtype=wp.uint16), r: int, c: int, cam: vec9d):
    """Camera depth (mm) of pixel (r, c), as `prior.backproject_mm` (the depth-jump rule compares these)."""
    return wp.float64(depth[r, c]) * cam[4]


@wp.func
def close_mm(za: wp.float64, zb: wp.float64, max_jump_mm: wp.float64):
    """The depth-jump rule for one edge: |za - zb| <= max_jump_mm (a negative max_jump_mm = no rule)."""
    return max_jump_mm < wp.float64(0.0) or wp.abs(za - zb) <= max_jump_mm


@wp.kernel(enable_backward=False)
def raster_camera_quads(depth: wp.array2d(dtype=wp.uint16), mask: wp.array2d(dtype=wp.uint8), use_mask: int,
                        cam: vec9d, xf: wp.mat44d, max_jump_mm: wp.float64, n_rows: int, n_cols: int,
                        zbuf: wp.array(dtype=wp.float64)):
    """One 2x2 quad of the depth image: its triangles into the z-buffer, as `methods.domain.lattice.
    lattice_triangles` forms them (rule 'sound'): four valid corners give (p00, p10, p01) when |z00 - z10| and
    |z10 - z01| are <= max_jump_mm and (p11, p01, p10) when |z11 - z01| and |z01 - z10| are; three valid corners
    give their triangle (in 00, 01, 10, 11 order) when all three of its jumps are (camera millimetres)."""
    q = wp.tid()
    w1 = depth.shape[1] - 1
    r = q // w1
    c = q % w1
    p00 = camera_corner(depth, mask, use_mask, r, c, cam, xf)
    p01 = camera_corner(depth, mask, use_mask, r, c + 1, cam, xf)
    p10 = camera_corner(depth, mask, use_mask, r + 1, c, cam, xf)
    p11 = camera_corner(depth, mask, use_mask, r + 1, c + 1, cam, xf)
    v00 = p00[3] > wp.float64(0.5)
    v01 = p01[3] > wp.float64(0.5)
    v10 = p10[3] > wp.float64(0.5)
    v11 = p11[3] > wp.float64(0.5)
    n_valid = int(v00) + int(v01) + int(v10) + int(v11)
    if n_valid < 3:
        return
    z00 = camera_z_mm(depth, r, c, cam)
    z01 = camera_z_mm(depth, r, c + 1, cam)
    z10 = camera_z_mm(depth, r + 1, c, cam)
    z11 = camera_z_mm(depth, r + 1, c + 1, cam)
    if n_valid == 4:
        if close_mm(z00, z10, max_jump_mm) and close_mm(z10, z01, max_jump_mm):
            raster_corners(p00, p10, p01, n_rows, n_cols, zbuf)
        if close_mm(z11, z01, max_jump_mm) and close_mm(z01, z10, max_jump_mm):
            raster_corners(p11, p01, p10, n_rows, n_cols, zbuf)
    elif not v00:
        if close_mm(z01, z10, max_jump_mm) and close_mm(z10, z11, max_jump_mm) and close_mm(z01, z11, max_jump_mm):
            raster_corners(p01, p10, p11, n_rows, n_cols, zbuf)
    elif not v01:
        if close_mm(z00, z10, max_jump_mm) and close_mm(z10, z11, max_jump_mm) and close_mm(z00, z11, max_jump_mm):
            raster_corners(p00, p10, p11, n_rows, n_cols, zbuf)
    elif not v10:
        if close_mm(z00, z01, max_jump_mm) and close_mm(z01, z11, max_jump_mm) and close_mm(z00, z11, max_jump_mm):
            raster_corners(p00, p01, p11, n_rows, n_cols, zbuf)
    else:
        if close_mm(z00, z01, max_jump_mm) and close_mm(z01, z10, max_jump_mm) and close_mm(z00, z10, max_jump_mm):
            raster_corners(p00, p01, p10, n_rows, n_cols, zbuf)


@wp.kernel(enable_backward=False)
def raster_mesh_triangles(verts: wp.array(dtype=wp.vec3d), tris: wp.array(dtype=wp.vec3i), n_rows: int, n_cols: int,
                          zbuf: wp.array(dtype=wp.float64)):
    """One mesh triangle (vertices as radar column, row, z) into the z-buffer."""
    t = tris[wp.tid()]
    a = verts[t[0]]
    b = verts[t[1]]
    c = verts[t[2]]
    raster_triangle(a[0], a[1], a[2], b[0], b[1], b[2], c[0], c[1], c[2], n_rows, n_cols, zbuf)


@wp.kernel(enable_backward=False)
def clear_zbuffer(n_rows: int, zbuf: wp.array(dtype=wp.float64), stats: wp.array(dtype=wp.int32)):
    """z-buffer = FAR (1e300, no prior); stats = [covered, hull lattice points or pixels filled, (first col, last
    col) per row, (hull first col, hull last col) per row, (first row, last row) per column]."""
    p = wp.tid()
    zbuf[p] = FAR
    if p < n_rows:
        stats[2 + 2 * p] = 2147483647
        stats[3 + 2 * p] = -1
        stats[2 + 2 * n_rows + 2 * p] = 2147483647
        stats[3 + 2 * n_rows + 2 * p] = -1
    if p < zbuf.shape[0] // n_rows:
        stats[2 + 4 * n_rows + 2 * p] = 2147483647
        stats[3 + 4 * n_rows + 2 * p] = -1
    if p == 0:
        stats[0] = 0
        stats[1] = 0


@wp.kernel(enable_backward=False)
def covered_spans(n_rows: int, n_cols: int, zbuf: wp.array(dtype=wp.float64), stats: wp.array(dtype=wp.int32)):
    """Covered-pixel count, each row's first and last covered column (input of the hull test) and each column's
    first and last covered row (of the scanline fill)."""
    p = wp.tid()
    if zbuf[p] < FAR:
        r = p // n_cols
        c = p % n_cols
        wp.atomic_add(stats, 0, 1)
        wp.atomic_min(stats, 2 + 2 * r, c)
        wp.atomic_max(stats, 3 + 2 * r, c)
        wp.atomic_min(stats, 2 + 4 * n_rows + 2 * c, r)
        wp.atomic_max(stats, 3 + 4 * n_rows + 2 * c, r)


@wp.kernel(enable_backward=False)
def hull_rows(n_rows: int, stats: wp.array(dtype=wp.int32)):
    """Row r of the convex hull of the covered pixels, exactly in integers: its lattice columns are
    [ceil(min L), floor(max R)] over all pairs of covered rows i <= r <= j, L (R) the linear interpolation at row r
    between rows i and j's first (last) covered columns. Thread (r, i) takes every j >= r."""
    r, i = wp.tid()
    if i > r or stats[3 + 2 * i] < 0:
        return
    xl_i = stats[2 + 2 * i]
    xr_i = stats[3 + 2 * i]
    lo = int(2147483647)  # noqa: UP018 (Warp: a dynamic variable, not a constant)
    hi = -1
    if i == r:
        lo = xl_i
        hi = xr_i
    for j in range(r + 1, n_rows):
        if stats[3 + 2 * j] >= 0:
            den = j - i
            t = r - i
            num_l = xl_i * den + (stats[2 + 2 * j] - xl_i) * t        # >= 0: columns are >= 0
            num_r = xr_i * den + (stats[3 + 2 * j] - xr_i) * t
            lo = wp.min(lo, (num_l + den - 1) // den)
            hi = wp.max(hi, num_r // den)
    if hi >= 0:
        wp.atomic_min(stats, 2 + 2 * n_rows + 2 * r, lo)
        wp.atomic_max(stats, 3 + 2 * n_rows + 2 * r, hi)


@wp.kernel(enable_backward=False)
def hull_lattice_count(n_rows: int, stats: wp.array(dtype=wp.int32)):
    """stats[1] = lattice points inside or on the convex hull of the covered pixels."""
    r = wp.tid()
    lo = stats[2 + 2 * n_rows + 2 * r]
    hi = stats[3 + 2 * n_rows + 2 * r]
    if hi >= lo:
        wp.atomic_add(stats, 1, hi - lo + 1)


@wp.func
def line_estimate(zbuf: wp.array(dtype=wp.float64), base: int, stride: int, k: int, first: int, last: int):
    """`raster._span_estimate` for the empty pixel at position k of the line base + i * stride whose first and last
    covered positions are `first`, `last` (last < 0: none): (linear interpolation between the nearest covered
    pixels on either side, their distance in pixels), or (0, 0) where a side has none."""
    if last < 0 or k < first or k > last:
        return wp.float64(0.0), int(0)  # noqa: UP018 (Warp: typed return)
    lo = k - 1
    while zbuf[base + lo * stride] >= FAR:
        lo -= 1
    hi = k + 1
    while zbuf[base + hi * stride] >= FAR:
        hi += 1
    span = hi - lo
    z_lo = zbuf[base + lo * stride]
    z_hi = zbuf[base + hi * stride]
    return z_lo + (z_hi - z_lo) * (wp.float64(k - lo) / wp.float64(span)), span


@wp.kernel(enable_backward=False)
def scanline_fill(n_rows: int, n_cols: int, zbuf: wp.array(dtype=wp.float64), stats: wp.array(dtype=wp.int32),
                  out: wp.array(dtype=wp.float64)):
    """`raster.fill_scanline` of the z-buffer into `out` (covered pixels copied; stats[1] += pixels filled): row
    and column interpolations weighted by 1 / span, z = (z_r s_c + z_c s_r) / (s_r + s_c)."""
    p = wp.tid()
    z = zbuf[p]
    if z < FAR:
        out[p] = z
        return
    r = p // n_cols
    c = p % n_cols
    z_r, s_r = line_estimate(zbuf, r * n_cols, 1, c, stats[2 + 2 * r], stats[3 + 2 * r])
    z_c, s_c = line_estimate(zbuf, c, n_cols, r, stats[2 + 4 * n_rows + 2 * c], stats[3 + 4 * n_rows + 2 * c])
    if s_r > 0 and s_c > 0:
        out[p] = (z_r * wp.float64(s_c) + z_c * wp.float64(s_r)) / wp.float64(s_r + s_c)
    elif s_r > 0:
        out[p] = z_r
    elif s_c > 0:
        out[p] = z_c
    else:
        out[p] = FAR
        return
    wp.atomic_add(stats, 1, 1)
