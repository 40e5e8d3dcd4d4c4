"""One-sided Chamfer distances with a KD-tree (MAROON_FORMAT.md 5.5, paper eq. 11).

`C(P -> Q) = mean_{p in P} min_{q in Q} |p - q|`. C_s is reconstruction -> ground truth, C_g ground truth ->
reconstruction. Build the ground-truth tree once per capture (`PointSet`) and reuse it for every method.

Queries run on a thread pool the process keeps (`_pool`), each in interleaved chunks (every c-th point) queried
with SciPy's one-thread query: a point's nearest distance does not depend on the other points of its query, so the
distances are those of one query bit for bit. SciPy's own `workers=N` starts N threads for every call (Table III's
224 queries a sweep: 3,584 thread starts on a 16-core host; a 64-point query with 16 costs ~1.4 ms against 0.09 ms
on one) and splits the points into N contiguous runs, of which the one over a method's off-object clutter takes
longest while the others wait (Table III's 112 rows scored on the H100 host: 16.0-17.1 -> 12.5-13.4 ms a row).

Where the sweep runs on CUDA (`on_gpu`), the nearest point of every query is found by brute force on the GPU
instead (methods.backends.warp.nearest; the ground truth's points kept there with its PointSet) and each pair's
distance computed here with the KD-tree's own formula (`distances_m`): the same distances bit for bit. Any other
device keeps the KD-tree and never imports Warp.
"""
from __future__ import annotations

import functools
import os
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from methods.domain.host import usable_cores

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

    from methods.backends.warp.nearest import DevicePoints


#: threads of a nearest-neighbour query; None: one per core the process may run on (`usable_cores`; not SciPy's
#: `workers=-1`, which is every core of the host) where it scores
#: alone; scoring worker processes set 1 (bench.harness.workers), so that a pool of them does not start a thread
#: per core each beside the timed calls
QUERY_THREADS: int | None = None
LEAF_POINTS = 64
#: fewest points of a chunk handed to a pool thread: a query of fewer than twice as many runs on the calling thread
#: (handing a chunk over costs tens of microseconds; a point's query ~0.5-4 us off a lattice surface). One chunk
#: per thread: interleaved chunks cost about the same each (Table III's rows on the H100 host's 16 cores: one a
#: thread 12.5-13.4 ms a row, two 13.6-14.3, four of >= 256 points 18-21; chunks of >= 1,024 points 14.7)
MIN_CHUNK_POINTS = 512


@dataclass
class PointSet:
    """(N, 3) points in metres with their KD-tree and their copy on the CUDA device, each made on first use."""

    points_m: np.ndarray
    _tree: cKDTree | None = field(default=None, repr=False)
    _device: DevicePoints | None = field(default=None, repr=False, compare=False)

    @property
    def tree(self) -> cKDTree:
        if self._tree is None:
            self._tree = _build_tree(self.points_m)
        return self._tree

    @property
    def device_points(self) -> DevicePoints:
        """The points on the first CUDA device (one upload for every row scored against them)."""
        if self._device is None:
            from methods.backends.warp.nearest import DevicePoints

            self._device = DevicePoints(self.points_m)
        return self._device

    def __getstate__(self) -> dict:
        return {**self.__dict__, "_device": None}       # device memory stays in its process (scoring workers)


def distances_m(d_m: np.ndarray) -> np.ndarray:
    """Lengths (m) of difference vectors (..., 3), summed as SciPy's cKDTree sums them for p = 2 (((0 + dx^2) +
    dy^2) + dz^2, then the square root): the distance of a pair the GPU found equals the tree's bit for bit."""
    return np.sqrt((d_m[..., 0] * d_m[..., 0] + d_m[..., 1] * d_m[..., 1]) + d_m[..., 2] * d_m[..., 2])


def on_gpu(device: str) -> bool:
    """Whether a sweep on `device` (methods.backends.resolve_device's names) searches nearest points on the GPU:
    "cuda" where Warp sees a CUDA device (the sweep started it); any other device the KD-tree, without Warp."""
    return device == "cuda" and _cuda_seen()


@functools.cache
def _cuda_seen() -> bool:
    try:
        from methods.backends.warp.runtime import cuda_available
    except ImportError:
        return False
    return cuda_available()


def _nearest_on_gpu(*pairs: tuple[np.ndarray, PointSet | DevicePoints]) -> list[np.ndarray]:
    """For each (source points (m), destination), the distance of every source point to its nearest destination
    point, found on the GPU (inf without destination points, as the KD-tree gives it)."""
    from methods.backends.warp.nearest import DevicePoints, nearest_indices

    pairs = [(src if isinstance(src, DevicePoints) else DevicePoints(src),
              dst.device_points if isinstance(dst, PointSet) else dst) for src, dst in pairs]
    searched = [(src, dst) for src, dst in pairs if len(dst)]
    found = iter(nearest_indices(*searched))
    return [distances_m(src.points_m - dst.points_m[next(found)]) if len(dst) else np.full(len(src), np.inf)
            for src, dst in pairs]


def _build_tree(points_m: np.ndarray) -> cKDTree:
    # imported here: scipy.spatial costs ~0.3 s, which a process that only builds ground truths (a sweep scoring in
    # workers, bench.harness.workers) need not pay
    from scipy.spatial import cKDTree

    # sliding-midpoint splits, not median splits: radar points often lie centimetres off the ground truth's lattice
    # surface, where median-split cells make each query visit many leaves (15-25x slower on the synthetic captures;
    # the nearest distances are the same, the tree's shape only changes the search), and leaves of LEAF_POINTS
    # points: such a query's ball holds hundreds of lattice points, fewer larger leaves cost less to visit (Table
    # III's 112 rows: 20 % less query time than SciPy's 16, the same distances)
    return cKDTree(points_m, leafsize=LEAF_POINTS, balanced_tree=False, compact_nodes=False)


_POOL: list = []          # [(threads, ThreadPoolExecutor)] of this process, at most one


def _threads() -> int:
    return QUERY_THREADS or usable_cores()


def _pool(threads: int) -> ThreadPoolExecutor:
    """The process's query threads, started on first use and kept (a new pool where the thread count changed)."""
    if not _POOL or _POOL[0][0] != threads:
        if _POOL:
            _POOL.pop()[1].shutdown(wait=False)
        _POOL.append((threads, ThreadPoolExecutor(threads, thread_name_prefix="nearest")))
    return _POOL[0][1]


if hasattr(os, "register_at_fork"):       # a forked child has none of its parent's threads: it starts its own pool
    os.register_at_fork(after_in_child=_POOL.clear)


def _chunks(points: int, threads: int) -> int:
    return max(1, min(threads, points // MIN_CHUNK_POINTS))


def _submit(tree: cKDTree, src_m: np.ndarray, threads: int) -> tuple[np.ndarray, list[Future]]:
    """`src_m`'s nearest distances to `tree`'s points queried in interleaved chunks on the pool: (the array they are
    written into, the chunks' futures)."""
    chunks = _chunks(len(src_m), threads)
    if chunks == 1:
        return tree.query(src_m, k=1, workers=1)[0], []
    distances = np.empty(len(src_m))

    def chunk(first: int) -> None:
        distances[first::chunks] = tree.query(src_m[first::chunks], k=1, workers=1)[0]

    pool = _pool(threads)
    return distances, [pool.submit(chunk, first) for first in range(chunks)]


def _wait(futures: list[Future]) -> None:
    for future in futures:
        future.result()


def nearest_distances_m(src_m: np.ndarray, dst: PointSet, device: str = "cpu") -> np.ndarray:
    """Distance (m) from every source point to its nearest destination point; (N,) float64. `device`: the sweep's
    (`on_gpu`)."""
    if on_gpu(device):
        return _nearest_on_gpu((src_m, dst))[0]
    distances, futures = _submit(dst.tree, np.asarray(src_m, dtype=np.float64), _threads())
    _wait(futures)
    return distances


def nearest_both_ways_m(a_m: np.ndarray, b: PointSet, device: str = "cpu") -> tuple[np.ndarray, np.ndarray]:
    """(nearest distances (m) from every point of `a_m` to `b`, from every point of `b` to `a_m`): the same as two
    `nearest_distances_m` calls (`a_m`'s tree as PointSet builds it), with `a_m`'s tree built on a pool thread
    while the first direction's chunks run; on the GPU (`on_gpu(device)`) `a_m` uploaded once for both. Both sets
    non-empty."""
    if on_gpu(device):
        from methods.backends.warp.nearest import DevicePoints

        a = DevicePoints(a_m)
        return tuple(_nearest_on_gpu((a, b), (b.device_points, a)))
    a_m, threads = np.asarray(a_m, dtype=np.float64), _threads()
    if threads <= 1:
        return nearest_distances_m(a_m, b), _build_tree(a_m).query(b.points_m, k=1, workers=1)[0]
    a_tree = _pool(threads).submit(_build_tree, a_m)
    to_b, futures = _submit(b.tree, a_m, threads)
    to_a, more = _submit(a_tree.result(), np.asarray(b.points_m, dtype=np.float64), threads)
    _wait(futures + more)
    return to_b, to_a


def one_sided_chamfer_m(src_m: np.ndarray, dst: PointSet) -> float:
    """Mean nearest-neighbour distance from `src_m` to `dst` in metres; NaN when either set is empty."""
    if len(src_m) == 0 or len(dst.points_m) == 0:
        return float("nan")
    return float(np.mean(nearest_distances_m(src_m, dst)))
