"""BP's depth search on a dense coarse volume (the skip `bp_dense_z_search`, methods.skips.settings): the volume at
every `step`-th depth (and the last) with the volume kernel; per pixel its `n_cand` largest coarse local maxima and
around each a window of 2 step + 3 depths, evaluated as points by the same kernel (only at pixels whose coarse
maximum can pass the filter, compacted); `volume_peak_depth`'s argmax and parabola over the windows
(`zsearch_kernels`). The two-frequency BP magnitude varies slowly along z (depth of focus ~ lambda (R/D)^2, the two
frequencies beat over c / (2 df)); the window samples are the dense volume's own values (same kernel, same point),
so the depth is the dense one wherever its largest peak is among the candidates (speckle makes near-equal peaks:
hence several). Cost: n_z / step samples a pixel plus n_cand (2 step + 3) at the refined ones instead of n_z
(H100, paper grid, 6 mm and 3 candidates: 9.6-10.4 against 37 ms; docs/measurements/formation.md section 5)."""
from __future__ import annotations

from contextlib import nullcontext

import numpy as np
import warp as wp

from methods.backends.warp import correlation
from methods.backends.warp.frames import BufferPool, FrameCache
from methods.backends.warp.kernels import zsearch as zsearch_kernels


class _Named:
    """A BufferPool seen under a prefix: the coarse and window launches keep their own reused buffers."""

    def __init__(self, pool: BufferPool, prefix: str):
        self.pool, self.prefix = pool, prefix

    def get(self, name, shape, dtype):
        return self.pool.get(self.prefix + name, shape, dtype)

    def constant(self, key, build):
        return self.pool.constant(key, build)


def coarse_indices(n_z: int, step: int) -> np.ndarray:
    """Depth indices of the coarse pass: every `step`-th and the last."""
    return np.unique(np.append(np.arange(0, n_z, step), n_z - 1)).astype(np.int32)


def volume_peak(frames: FrameCache, buffers: BufferPool, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, dz_m: float,
                step: int, n_cand: int = 3, keep_ratio: float = 0.0, *, kernel: str, timer=None
                ) -> tuple[np.ndarray, np.ndarray, int]:
    """As `correlation.volume_peak` (depth, max projection, each float64 (ny, nx)) through the coarse volume and
    each pixel's windows around its `n_cand` largest coarse peaks; pixels whose coarse maximum is below
    `keep_ratio` times the image's coarse maximum get no windows (NaN depth, their coarse maximum as max
    projection). Also the number of pixels whose maximum lies on a window edge inside the grid (where the dense
    volume may differ). `timer` gets the stages "correlate" and "depth"."""
    stage = timer.stage if timer is not None else (lambda name: nullcontext())
    n_z, n_px = len(z_m), len(x_m) * len(y_m)
    # a window of +-(step + 1): a maximum within one coarse step of the coarse peak keeps both of the parabola's
    # neighbours inside it (at +-step it could sit on the edge, where the clipped neighbour biased the depth by half
    # a depth step); the caller keeps n_z >= 4 step
    half = step + 1
    n_w = 2 * half + 1
    with stage("correlate"):
        inputs = frames.inputs(signal, freqs_hz, tx_m, rx_m)
        dev = wp.get_device(inputs.device)
        k_c = coarse_indices(n_z, step)
        coarse = correlation.make_launch(frames, _Named(buffers, "zs.coarse."), signal, freqs_hz, tx_m, rx_m,
                                         kernel=kernel, grid_m=(x_m, y_m, z_m[k_c]), reuse=True, inputs=inputs)()
        grid = buffers.constant(("zsearch", x_m.tobytes(), y_m.tobytes(), z_m.tobytes(), step), lambda: (
            wp.array(k_c, dtype=wp.int32, device=dev),
            *(wp.array(np.asarray(v, dtype=np.float64), dtype=wp.float64, device=dev) for v in (x_m, y_m, z_m))))
        counters = buffers.get("zs.counters", 3, wp.int32)     # slots, points, window edges
        counters.zero_()
        n_slots, n_points, on_edge = counters[0:1], counters[1:2], counters[2:3]
        image_max = buffers.get("zs.image_max", 1, wp.float32)
        image_max.zero_()
        pixel_max = buffers.get("zs.pixel_max", n_px, wp.float32)
        wp.launch(zsearch_kernels.coarse_max, dim=n_px, inputs=[coarse, len(k_c), pixel_max, image_max], device=dev)
        slot_pixel = buffers.get("zs.slot_pixel", n_px, wp.int32)
        start = buffers.get("zs.start", n_px * n_cand, wp.int32)
        points = buffers.get("zs.points", n_px * n_cand * n_w, wp.vec3d)
        maps = buffers.get("peak", (2, n_px), wp.float64)
        wp.launch(zsearch_kernels.window_points, dim=n_px,
                  inputs=[coarse, *grid, half, n_cand, pixel_max, image_max, float(keep_ratio), n_slots, n_points,
                          slot_pixel, start, points, maps], device=dev)
        if dev.is_cpu:                 # (the host knows the count at no cost: only those points)
            points = points[:int(n_points.numpy()[0])]
        vals = correlation.make_launch(frames, _Named(buffers, "zs.window."), signal, freqs_hz, tx_m, rx_m,
                                       kernel=kernel, points_m=points, sum_freqs=True, reuse=True, inputs=inputs,
                                       count=n_points)()
        wp.synchronize_device(dev)
    with stage("depth"):
        wp.launch(zsearch_kernels.window_peak_depth, dim=n_px,
                  inputs=[vals, n_w, n_cand, start, n_slots, slot_pixel, n_z, float(z_m[0]), float(dz_m), maps,
                          on_edge], device=dev)
        # both copies back into pinned buffers, one wait (two pageable copies each waited on their own)
        maps_host = buffers.pinned_flat(maps.size, wp.float64, "zs.maps.pinned")
        edge_host = buffers.pinned_flat(1, wp.int32, "zs.edge.pinned")
        wp.copy(maps_host, maps, count=maps.size)
        wp.copy(edge_host, on_edge, count=1)
        wp.synchronize_device(dev)
        host = maps_host.numpy()[:maps.size].reshape(2, len(y_m), len(x_m)).copy()
        n_edge = int(edge_host.numpy()[0])
    return host[0], host[1], n_edge
