"""Exact nearest neighbours on a Warp device by brute force (launching `kernels.nearest`): the index of every query
point's nearest point, for the metrics' Chamfer distances (metrics.chamfer), which compute each pair's distance on
the host from these indices.

Table III's rows pair 0.5-20 k radar points with 7-16 k ground-truth points: ~1e8 float64 pair distances a
direction, well under a millisecond of an H100's work, against ~13 ms a row for the KD-trees on its host's 16
cores. A query set alone would start too few threads to fill the GPU (20 k queries: ~150 a multiprocessor), so the
points are cut into slices, one thread per (slice, query) (`slices`), and a second kernel compares the slices'
winners. The squared distances are computed as the host computes them (kernels.nearest), so the nearest index is
the host's; ties go to the lower index.
"""
from __future__ import annotations

import functools

import numpy as np
import warp as wp

from methods.backends.warp.frames import BufferPool
from methods.backends.warp.kernels import nearest as kernels
from methods.backends.warp.runtime import init

#: (slice, query) threads aimed at per search: ~1,000 per multiprocessor of an H100 (132), enough to hide the
#: float64 latency; fewer points than MIN_SLICE_POINTS are not given a thread of their own
TARGET_THREADS = 1 << 17
MIN_SLICE_POINTS = 64


def slices(n_queries: int, n_points: int) -> tuple[int, int]:
    """(points a slice, slices) for `n_queries` queries among `n_points` > 0 points: every slice non-empty."""
    wanted = max(1, min(-(-TARGET_THREADS // max(n_queries, 1)), n_points // MIN_SLICE_POINTS))
    slice_points = -(-n_points // wanted)
    return slice_points, -(-n_points // slice_points)


@functools.cache
def _buffers(wp_device: str) -> BufferPool:
    return BufferPool(wp_device)


def _capacity(n: int) -> int:
    """A buffer's length for n elements: the next power of two, so that sizes changing from row to row reuse it."""
    return 1 << max(n - 1, 1).bit_length()


class DevicePoints:
    """(N, 3) points (m, float64) on a Warp device (default: the first CUDA device), with the host's copy."""

    def __init__(self, points_m: np.ndarray, wp_device: str = "cuda:0"):
        init()
        self.points_m = np.ascontiguousarray(points_m, dtype=np.float64).reshape(-1, 3)
        self.wp_device = wp_device
        self.array = wp.array(self.points_m, dtype=wp.vec3d, device=wp_device) if len(self.points_m) else None

    def __len__(self) -> int:
        return len(self.points_m)


def _launch(queries: DevicePoints, points: DevicePoints, nearest: wp.array, offset: int) -> None:
    """nearest[offset:offset + len(queries)] = each query's nearest point index (in stream order, not waited for)."""
    n_queries, n_points = len(queries), len(points)
    if not n_queries:
        return
    if not n_points:
        raise ValueError("no points to search for the nearest")
    slice_points, n_slices = slices(n_queries, n_points)
    dev, pool = queries.wp_device, _buffers(queries.wp_device)
    best_d2 = pool.get("nearest.d2", _capacity(n_queries * n_slices), wp.float64)
    best_index = pool.get("nearest.index", _capacity(n_queries * n_slices), wp.int32)
    wp.launch(kernels.nearest_in_slices, dim=n_queries * n_slices,
              inputs=[queries.array, points.array, n_queries, n_points, slice_points, best_d2, best_index], device=dev)
    wp.launch(kernels.pick_nearest, dim=n_queries, inputs=[best_d2, best_index, n_queries, n_slices, offset, nearest],
              device=dev)


def nearest_indices(*pairs: tuple[DevicePoints, DevicePoints]) -> list[np.ndarray]:
    """For each (queries, points) pair on one device, the index (int32) of every query's nearest point: the searches
    launched one after the other, their results copied back at once. Points must be non-empty where queries are."""
    counts = [len(queries) for queries, _ in pairs]
    if not sum(counts):
        return [np.zeros(0, dtype=np.int32) for _ in pairs]
    device = pairs[0][0].wp_device
    nearest = _buffers(device).get("nearest.out", _capacity(sum(counts)), wp.int32)
    offsets = np.concatenate([[0], np.cumsum(counts)])
    for (queries, points), offset in zip(pairs, offsets[:-1], strict=True):
        _launch(queries, points, nearest, int(offset))
    out = nearest[:sum(counts)].numpy()
    return [out[a:b] for a, b in zip(offsets[:-1], offsets[1:], strict=True)]
