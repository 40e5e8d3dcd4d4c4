"""Warp kernels of the prior's hole filling on the device (launched by `methods.backends.warp.prior`), reproducing
`raster.fill_convex_hull` exactly: the rim of the covered region (`rim_pixels`: covered pixels with an uncovered
or out-of-image 8-neighbour, i.e. `covered & ~binary_erosion(covered, 3x3, border_value=0)`), the rim's Delaunay
triangles rasterised with the same scanline (`raster_rim_triangles`, vertices at integer pixel positions with their
z-buffer depths), and the merge into the empty pixels only (`merge_fill`). The Delaunay triangulation itself runs
on the host (scipy's Qhull on the rim's row-major pixel list, as the CPU function orders it).
"""
from __future__ import annotations

import warp as wp

from methods.backends.warp.kernels.prior import FAR, raster_triangle


@wp.kernel(enable_backward=False)
def rim_pixels(n_rows: int, n_cols: int, zbuf: wp.array(dtype=wp.float64), count: wp.array(dtype=wp.int32),
               rim: wp.array(dtype=wp.int32)):
    """Flat indices of the rim pixels into `rim` (unordered; count[0] = how many)."""
    p = wp.tid()
    if zbuf[p] >= FAR:
        return
    r = p // n_cols
    c = p % n_cols
    edge = r == 0 or c == 0 or r == n_rows - 1 or c == n_cols - 1      # erosion's border_value = 0
    if not edge:
        for dr in range(-1, 2):
            for dc in range(-1, 2):
                if zbuf[(r + dr) * n_cols + c + dc] >= FAR:
                    edge = True
    if edge:
        rim[wp.atomic_add(count, 0, 1)] = p


@wp.kernel(enable_backward=False)
def raster_rim_triangles(tris: wp.array(dtype=wp.vec3i), n_rows: int, n_cols: int,
                         zbuf: wp.array(dtype=wp.float64), fill: wp.array(dtype=wp.float64)):
    """One Delaunay triangle of rim pixels (flat indices) into the nearest-z buffer `fill`."""
    t = tris[wp.tid()]
    a = t[0]
    b = t[1]
    c = t[2]
    raster_triangle(wp.float64(a % n_cols), wp.float64(a // n_cols), zbuf[a],
                    wp.float64(b % n_cols), wp.float64(b // n_cols), zbuf[b],
                    wp.float64(c % n_cols), wp.float64(c // n_cols), zbuf[c], n_rows, n_cols, fill)


@wp.kernel(enable_backward=False)
def merge_fill(zbuf: wp.array(dtype=wp.float64), fill: wp.array(dtype=wp.float64), count: wp.array(dtype=wp.int32)):
    """Empty z-buffer pixels take the fill's depth where it has one (count[1] += pixels added)."""
    p = wp.tid()
    if zbuf[p] >= FAR and fill[p] < FAR:
        zbuf[p] = fill[p]
        wp.atomic_add(count, 1, 1)
