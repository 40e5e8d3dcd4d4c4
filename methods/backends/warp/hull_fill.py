"""`raster.fill_convex_hull` on a Warp device (launching `hull_fill_kernels`): the z-buffer stays on the device;
only the rim's pixel indices come to the host (4 bytes per rim pixel, ~0.5-1.5 k pixels for a catalogue object)
for scipy's Delaunay triangulation, and its triangles go back (12 bytes each) to be rasterised into the empty
pixels. Exact: the same rim, in the same row-major order, gives Qhull the same input as the CPU function, and the
rasteriser is the CPU scanline in float64 (`prior_kernels.raster_triangle`).
"""
from __future__ import annotations

import numpy as np
import warp as wp
from scipy.spatial import Delaunay, QhullError

from methods.backends.warp.frames import BufferPool
from methods.backends.warp.kernels import hull_fill as kernels

FAR_M = 1.0e300


def fill_hull(buffers: BufferPool, zbuf: wp.array, ny: int, nx: int) -> int:
    """Fill the empty pixels of the z-buffer (ny * nx, 1e300 = empty) inside the convex hull of the covered ones
    in place; returns the number of pixels added."""
    dev = buffers.wp_device
    count = buffers.get("prior.fill_count", 2, wp.int32)
    count.zero_()
    rim = buffers.get("prior.rim", ny * nx, wp.int32)
    wp.launch(kernels.rim_pixels, dim=ny * nx, inputs=[ny, nx, zbuf, count, rim], device=dev)
    n_rim = int(count.numpy()[0])
    flat = np.sort(rim[:n_rim].numpy())                      # row-major, as np.nonzero gives the CPU function
    rows, cols = np.divmod(flat, nx)
    try:
        simplices = Delaunay(np.column_stack([cols, rows]).astype(np.float64)).simplices
    except (QhullError, ValueError):          # fewer than 3 rim pixels, or all on one line: no area to fill
        return 0
    tris = wp.array(np.ascontiguousarray(flat[simplices], dtype=np.int32), dtype=wp.vec3i, device=dev)
    fill = buffers.get("prior.fill", ny * nx, wp.float64)
    fill.fill_(FAR_M)
    wp.launch(kernels.raster_rim_triangles, dim=len(simplices), inputs=[tris, ny, nx, zbuf, fill], device=dev)
    wp.launch(kernels.merge_fill, dim=ny * nx, inputs=[zbuf, fill, count], device=dev)
    return int(count.numpy()[1])

