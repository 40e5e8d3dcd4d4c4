"""Scoring a computed capture (metrics, its row, its depth files and store cell) in worker processes.

On a GPU the methods take milliseconds while scoring a capture takes tens (resampling onto the metric grid and
`metrics.evaluate`: 20-30 ms a row, BP's dense maps the most) and writing its depth PNGs and store cell as much
again: done in the main thread, that is most of a sweep. With `evaluation.workers` N > 0 each computed capture is
handed to a pool of N processes while the main thread reads and reconstructs the next one; the run's ordered files
(results.csv lines, arrays.h5) are still written in capture order by its writer thread, each waiting for its
capture's result. The numbers are those of the main thread's scoring (the same functions on the same arrays).

Off by default (`evaluation.workers=0`): the workers share the host with the timed calls, and on the H100 host that
moved the methods' runtimes by +5-10 % (BP) and up to +80 % (a ~1 ms FSK median; docs/measurements/sweep.md), so
rows scored beside workers are timed 'parallel' and tables show no runtime for them: for sweeps whose errors, not
runtimes, are wanted. `auto` is N = min(cores - 2, MAX_AUTO_WORKERS) for a GPU job that runs alone, 0 where other
jobs of the sweep share the machine (joblib, SLURM arrays) and on the CPU devices, whose methods use every core.
The pool is started once per process, from a fresh interpreter (multiprocessing's forkserver: never forked from a
process holding CUDA or threads), and serves every later job of a basic launcher's sweep.
"""
from __future__ import annotations

import dataclasses
import functools
import logging
import multiprocessing
import pickle
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor
from pathlib import Path

import numpy as np

from bench.harness.results import write_depth
from methods.domain.capture import RadarGrid
from methods.domain.host import usable_cores
from metrics.evaluate import GroundTruth, evaluate, no_ground_truth_scores
from metrics.resample import resample_depth_m, resample_nearest

log = logging.getLogger("bench")
MAX_AUTO_WORKERS = 6
OUTPUT_PROCESS_MIN_CORES = 4
OUTPUT_THREADS = 4      # the output process's threads for one capture: its depth files and its three arrays at once
HOST_DEVICES = ("cpu", "warp-cpu")    # methods on the CPU's cores: 'auto' leaves them every core
# what a worker imports before it takes work (in the fork server: once for all workers): scoring, the cell's HDF5,
# the KD-trees and the depth previews' colour map
PRELOAD = ["bench.harness.workers", "bench.harness.store", "scipy.spatial", "matplotlib.cm"]


@dataclasses.dataclass
class Scoring:
    """What scoring one reconstruction needs: its maps on the grid it was computed on, the capture's metric grid and
    ground truth (None: no mesh), the profile, and the method's own reason for an all-invalid result."""

    depth_m: np.ndarray
    magnitude: np.ndarray
    computed_grid: RadarGrid
    metric_grid: RadarGrid
    gt: GroundTruth | None
    faithful: bool
    invalid_reason: str | None


class Pickled:
    """A ground truth handed to workers as the bytes it was pickled to once (`shipped`): every task of a capture
    then copies ~3 MB of bytes instead of pickling its arrays again while the next timed call runs."""

    def __init__(self, data: bytes):
        self.data = data

    def __reduce__(self):
        return pickle.loads, (self.data,)


SHIPPED_KEPT = 4        # as many as the ground truths the harness keeps (app._ground_truth's cache)
_SHIPPED: dict[int, tuple[GroundTruth, Pickled]] = {}


def shipped(gt: GroundTruth | None) -> GroundTruth | Pickled | None:
    """`gt` as it goes to a worker, pickled once per ground truth (the sweep's captures: a few kept at a time)."""
    if gt is None:
        return None
    if id(gt) not in _SHIPPED:
        if len(_SHIPPED) >= SHIPPED_KEPT:
            _SHIPPED.pop(next(iter(_SHIPPED)))
        _ = gt.points.tree         # built before pickling, so every task unpickles it instead of building it anew
        _SHIPPED[id(gt)] = gt, Pickled(pickle.dumps(gt, protocol=pickle.HIGHEST_PROTOCOL))
    return _SHIPPED[id(gt)][1]


def score(task: Scoring, device: str = "cpu") -> tuple[dict, dict]:
    """(metric columns, arrays on the metric grid: depth_m, magnitude, gt_depth_m) of a reconstruction; `device`:
    the sweep's, where its methods run in this process ("cuda": the nearest points searched on the GPU, the same
    numbers; metrics.chamfer.on_gpu), else the default (a worker process: the KD-tree)."""
    depth_m = resample_depth_m(task.depth_m, task.computed_grid, task.metric_grid)
    if task.gt is not None:
        scores, gt_depth_m = evaluate(depth_m, task.gt, faithful=task.faithful, device=device), task.gt.depth_m
    else:
        scores, gt_depth_m = no_ground_truth_scores("no photogrammetry mesh"), depth_m * float("nan")
    magnitude = resample_nearest(task.magnitude, task.computed_grid, task.metric_grid)
    if task.invalid_reason:       # the method's own account of an all-invalid result, not just 'no valid'
        scores["failure"] = task.invalid_reason
    return scores, {"depth_m": depth_m, "magnitude": magnitude, "gt_depth_m": gt_depth_m}


@functools.lru_cache(maxsize=4)
def _store(root: str):
    from bench.harness.store import Store

    return Store(root)


def score_and_write(task: Scoring, row: dict, out_dir: Path, stem: str, grid_attrs: dict, store_root: str | None
                    ) -> tuple[dict, bytes | None, dict[str, float]]:
    """In a worker: score the reconstruction into `row` (its score columns), then `write` its files (on this thread:
    the workers share the cores). Returns (row, the arrays' image or None, seconds spent on metrics and outputs)."""
    started = time.perf_counter()
    scores, arrays = score(task)
    row.update(scores)
    scored = time.perf_counter()
    row, image, seconds = write(row, arrays, task.metric_grid, out_dir, stem, grid_attrs, store_root, threads=0)
    return row, image, {"metrics": scored - started, **seconds}


def write(row: dict, arrays: dict, grid: RadarGrid, out_dir: Path, stem: str, grid_attrs: dict,
          store_root: str | None, arrays_attrs: dict | None = None, threads: int = OUTPUT_THREADS
          ) -> tuple[dict, bytes | None, dict[str, float]]:
    """In a worker (or the output process, `output_process`): a scored capture's depth PNG, JSON and preview and,
    with a store, its cell (arrays, then the row). Returns (row, where there is no store to copy the arrays from,
    the cell's image, bench.harness.store.cell_image, else None, seconds spent on outputs). With `arrays_attrs`
    (the output process: the one writer of the run's arrays.h5, its tasks done in order) the arrays go into
    `out_dir/arrays.h5` here too, with these attributes, and no image is returned. With `threads`
    (the output process: it has cores of its own) the depth files and each array's compression run on that many
    threads of this process (zlib and the file writes release the interpreter lock), the HDF5 writing here after
    them, in task order."""
    from bench.harness.store import cell_image, compress_arrays, write_arrays

    started = time.perf_counter()
    threads_pool = _threads(threads)
    if threads_pool is None:
        write_depth(out_dir, stem, arrays["depth_m"], grid)
        compressed = compress_arrays(arrays)
    else:
        depth = threads_pool.submit(write_depth, out_dir, stem, arrays["depth_m"], grid)
        compressed = compress_arrays(arrays, threads_pool)
        depth.result()
    image = None
    if store_root is not None:
        _store(store_root).put(row["key"], row, compressed, grid_attrs)
    if arrays_attrs is not None:
        write_arrays(out_dir / "arrays.h5", stem, compressed, arrays_attrs)
    elif store_root is None:
        image = cell_image(compressed, grid_attrs)
    return row, image, {"outputs": time.perf_counter() - started}


def copy_stored(store_root: str, key: str, path: Path, stem: str, attrs: dict) -> dict[str, float]:
    """In the output process (the one writer of the run's arrays.h5, its tasks done in order): a stored cell's
    arrays copied into `path` as group `stem` (bench.harness.store.Store.copy_arrays: ~4 ms a capture on the 2-core
    machine, which the job's writer thread no longer spends beside the timed calls). Returns the seconds spent."""
    started = time.perf_counter()
    _store(store_root).copy_arrays(key, path, stem, attrs)
    return {"outputs": time.perf_counter() - started}


_THREADS: dict[int, ThreadPoolExecutor] = {}


def _threads(threads: int) -> ThreadPoolExecutor | None:
    """This process's pool of `threads` threads for `write` (None for 0 or 1), started on first use."""
    if threads <= 1:
        return None
    if threads not in _THREADS:
        _THREADS[threads] = ThreadPoolExecutor(threads, thread_name_prefix="outputs")
    return _THREADS[threads]


def output_process(shared: bool = False) -> ProcessPoolExecutor | None:
    """Where a job without scoring workers writes each capture's depth files, cell and compressed arrays (into
    arrays.h5, whose one writer it is: a stored cell's arrays are copied there too, `copy_stored`): one process
    (`write`, the pool of 1, started once) on a host of OUTPUT_PROCESS_MIN_CORES cores or more where the job runs
    alone, else None (the job's writer thread writes them, as on 2 cores, where a
    process would take a core from the methods). A thread shares the interpreter lock with the main thread: on the
    H100 host its PNG, preview and HDF5 work took 46 ms a capture (~25 ms on an idle 2-core machine), fell behind
    the methods and metrics, and each job began by waiting for the last one's files (Table III: 5.2 s on the
    thread, 1.3 s waited for). The rows stay timed as they were (the thread did the same work beside the timed
    calls). Since the arrays are compressed in Python (bench.harness.h5chunks) on OUTPUT_THREADS threads, a capture
    takes this process ~12-13 ms (~21 ms of CPU; 39-40 ms before) on the H100 host, and the jobs no longer wait for
    it (Table III: 1.4-1.6 s waited -> 0.05 s; docs/measurements/sweep.md)."""
    return None if shared or usable_cores() < OUTPUT_PROCESS_MIN_CORES else pool(1)


def pool_size(setting, device: str, shared: bool = False) -> int:
    """Workers for `evaluation.workers` (a whole number >= 0, or 'auto': module doc) on the resolved `device`;
    `shared`: other jobs of the sweep run beside this one (joblib, SLURM arrays), which 'auto' leaves the cores to."""
    if setting == "auto":
        if device in HOST_DEVICES or shared:
            return 0
        return max(0, min(usable_cores() - 2, MAX_AUTO_WORKERS))
    return int(setting)


_POOLS: dict[int, ProcessPoolExecutor] = {}


def pool(workers: int) -> ProcessPoolExecutor | None:
    """The process's pool of `workers` processes (None for 0), started on first use and kept for later jobs."""
    if workers <= 0:
        return None
    if workers not in _POOLS:
        context = multiprocessing.get_context("forkserver")
        context.set_forkserver_preload(PRELOAD)       # not '__main__': `python -m bench` would run the app again
        try:
            _POOLS[workers] = ProcessPoolExecutor(workers, mp_context=context, initializer=_one_query_thread)
        except (OSError, ImportError, NotImplementedError) as err:   # no semaphores (no writable /dev/shm)
            log.warning("no worker processes on this machine (%s): the job's own threads do their work", err)
            return None
        # its processes started by another thread: the fork server's imports (~1 s) and the workers' starts happen
        # while this one goes on (Warp's start, reading, the first reconstruction), not when it hands over work
        threading.Thread(target=_start, args=(_POOLS[workers], workers), name="workers-start", daemon=True).start()
    return _POOLS[workers]


def _one_query_thread() -> None:
    """A worker's nearest-neighbour queries on one thread (the pool's processes already share the cores)."""
    from metrics import chamfer

    chamfer.QUERY_THREADS = 1


def _start(pool: ProcessPoolExecutor, workers: int) -> None:
    """Start every worker (a pool starts one per task handed over while none is idle)."""
    for started in [pool.submit(int) for _ in range(workers)]:
        started.result()


def done(value) -> Future:
    """A finished future holding `value` (what the main thread computed itself)."""
    future = Future()
    future.set_result(value)
    return future
