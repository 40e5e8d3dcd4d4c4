"""Where a catalogue's captures are built: worker processes, or threads of this process.

A capture is built in parts (bench.synth.parts.CAPTURE_PARTS: radar, camera, ground truth) that each draw from their own
seeded streams and write their own files, so the parts of all captures are independent tasks. Their CPU stages (ray
casting, depth camera, mesh smoothing, file encoding) hold the interpreter for much of their time: threads of one
process take turns (8 capture threads used ~4 of a 16-core host), processes do not. Workers are forked from a
forkserver that has imported the generator once (not from this process, which may hold a CUDA context: CUDA
does not survive a fork). The radar sums of a Warp device ("cuda", "warp-cpu") stay in this process, which holds
the device (bench.synth.radar.remote): the workers send it their rows and receive the frames.
"""
from __future__ import annotations

import contextlib
import functools
import multiprocessing
import multiprocessing.forkserver
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor, ThreadPoolExecutor

from threadpoolctl import threadpool_limits

from bench.synth.radar import leg_sum, remote
from methods.domain.host import usable_cores

MIN_CORES_FOR_PROCESSES = 4     # below this, threads: a worker's start (imports: ~1 s of a core) is not won back
START_METHOD = "forkserver"    # not fork (this process may hold CUDA), not spawn (each worker would import all)
PRELOAD = ["bench.synth.parts", "bench.synth.camera.depth"]     # what a worker needs (Open3D too), imported once
                                                               # by the forkserver


def capture_workers() -> int:
    """Capture parts built at once: one per leg_sum.PARTIAL_SUMS cores and at least two, so that one part's
    single-threaded stages overlap the others' radar sums (docs/measurements/synth.md)."""
    return max(2, usable_cores() // leg_sum.PARTIAL_SUMS)


def capture_processes() -> bool:
    """Whether the parts are built in worker processes (else threads of this process): with the cores for it, and
    where a worker may import the main module again (as multiprocessing's workers do) without running it: a module
    run with `python -m` (the command line, Hydra, pytest) or none (`python -c`). A script run by path may not
    guard its body with `if __name__ == "__main__"`; its captures are built in threads."""
    main = sys.modules.get("__main__")
    safe_main = getattr(main, "__spec__", None) is not None or getattr(main, "__file__", None) is None
    return (safe_main and usable_cores() >= MIN_CORES_FOR_PROCESSES
            and not multiprocessing.current_process().daemon        # a daemonic process may not have children
            and START_METHOD in multiprocessing.get_all_start_methods() and _semaphores_work())


@functools.cache
def _semaphores_work() -> bool:
    """Whether this machine gives multiprocessing the semaphores its pools need (no writable /dev/shm in some
    containers: then threads)."""
    try:
        multiprocessing.get_context(START_METHOD).Lock()
    except (OSError, ImportError, NotImplementedError):
        return False
    return True


def prestart() -> None:
    """Start the forkserver and its imports now, where parts will be built in processes: they then overlap what this
    process does first (its own imports, starting the device)."""
    if capture_processes() and START_METHOD == "forkserver":
        multiprocessing.get_context("forkserver").set_forkserver_preload(PRELOAD)
        multiprocessing.forkserver.ensure_running()


@contextlib.contextmanager
def builders(count: int, device: str) -> Iterator[Callable[..., Future]]:
    """`submit(function, *args)` running calls on `count` workers (processes where capture_processes(), else
    threads) whose radar sums run on `device`; on leaving, waits for the calls submitted."""
    if not capture_processes():
        with ThreadPoolExecutor(count, thread_name_prefix="capture") as pool:
            yield pool.submit
        return
    context = multiprocessing.get_context(START_METHOD)
    if START_METHOD == "forkserver":
        context.set_forkserver_preload(PRELOAD)
    with contextlib.ExitStack() as stack:
        server = stack.enter_context(remote.DeviceServer()) if device != "cpu" else None
        threads = max(leg_sum.PARTIAL_SUMS, usable_cores() // count)     # the cores shared out among the workers' sums
        pool = stack.enter_context(ProcessPoolExecutor(
            count, mp_context=context, initializer=_start_worker,
            initargs=(threads, None if server is None else server.address)))
        yield pool.submit


def _start_worker(block_threads: int, device_address: tuple[str, bytes] | None) -> None:
    """A worker's set-up: BLAS on one thread (as the parent's catalogue: bench.synth.radar.leg_sum), its share of
    the cores for the block sums, and the Warp device's sums sent to the parent."""
    threadpool_limits(limits=1, user_api="blas")
    leg_sum.limit_threads(block_threads)
    if device_address is not None:
        remote.connect(*device_address)
