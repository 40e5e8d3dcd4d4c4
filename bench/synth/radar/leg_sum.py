"""The radar frame as a sum over rows of receive-leg times transmit-leg phasors, in compact blocks.

    s[rx, tx, f] = sum_k wr[k, rx] exp(-j 2 pi f pr[k, rx] / c) wt[k, tx] exp(-j 2 pi f pt[k, tx] / c)

(a row k is one scatterer, or one bistatic pair of multipath; pr, pt path lengths in m of its two legs, wr, wt
complex weights). Per frequency this is a complex64 matrix product (n_rx x K)(K x n_tx). The rows are split into
blocks that lie close together in space (recursive median splits, `compact_blocks`), so that within a block each
antenna's leg lengths span little; the block's sum then varies slowly with frequency after its centre path is
factored out and is computed at a few node frequencies and interpolated to all (bench.synth.radar.frequency_nodes).

Phases are formed in float64 and reduced modulo one cycle; across equidistant nodes the phasors advance by one
complex64 multiply per step and are re-formed exactly every `RESEED_STEPS` nodes. Blocks alternate between
PARTIAL_SUMS sums, added in a fixed order: results do not depend on the machine's thread count. Each block's
contribution is computed on one process-wide pool of threads, one per core, shared by the captures built at once
(a capture's blocks then use the cores other captures have finished with: the bowl's multipath is the catalogue's
long pole), and added to its sum in block order.

On a Warp device ("cuda" or "warp-cpu": bench.synth.radar.warp_sum) the same blocks and node fits are used; the
legs, node sums, interpolation and the block order's additions (in float64) run on the device.
"""
from __future__ import annotations

import collections
import contextlib
import functools
import threading
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from threadpoolctl import threadpool_limits

from bench.synth.config import C_M_PER_S
from bench.synth.radar.frequency_nodes import interpolator
from methods.domain.host import usable_cores

RESEED_STEPS = 16       # exact phasors every 16 nodes bound the complex64 recursion error to ~1e-6
BLOCK_ROWS = 2048       # rows per block: small enough that a block spans a few cm, large enough for BLAS
CHUNK_ELEMENTS = 1 << 16   # elements per chunk of row_chunks: 512 kB of float64, a pass and its temporaries within a
                           # core's L2 cache (a block's (192, ~2000) arrays are 6x that: passes over them ran 2-3x
                           # slower, memory-bound); not smaller: each chunk's calls take the GIL the other threads want
PARTIAL_SUMS = 2        # blocks alternate between two sums, one thread each: fixed, so results do not depend on
                        # the machine (the order of float32 additions is always the same)

# legs(rows) -> (path (n_rx + n_tx, k) m float64, weight (n_rx + n_tx, k) complex64) for the given row indices,
# antenna-major, receive legs first; k may be smaller than len(rows) (rows that add nothing dropped)
Legs = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]


def row_chunks(n_rows: int, n_columns: int) -> list[slice]:
    """Slices of rows holding about CHUNK_ELEMENTS elements each (at least one row): elementwise passes over a
    (rows, columns) array done chunk by chunk stay in the core's cache (the same values: every element is computed
    by the same operations)."""
    step = max(1, CHUNK_ELEMENTS // max(1, n_columns))
    return [slice(start, start + step) for start in range(0, n_rows, step)]


def exact_phasors(path_m: np.ndarray, freq_hz) -> np.ndarray:
    """exp(-j 2 pi f path / c) as complex64: phase reduced modulo one cycle in float64, then float32 cos/sin."""
    scale = np.asarray(freq_hz) / C_M_PER_S
    shape = np.broadcast_shapes(np.shape(path_m), scale.shape)
    out = np.empty(shape, dtype=np.complex64)
    table = (int(np.prod(shape[:1])), int(np.prod(shape[1:])))     # (first axis, the rest); a scalar as (1, 1)
    path_m, scale = (np.broadcast_to(a, shape).reshape(table) for a in (path_m, scale))
    flat = out.reshape(table)
    for rows in row_chunks(*path_m.shape):
        cycles = path_m[rows] * scale[rows]
        cycles -= np.rint(cycles)
        cycles *= -2.0 * np.pi
        angle = cycles.astype(np.float32)
        flat[rows].real = np.cos(angle)
        flat[rows].imag = np.sin(angle)
    return out


def compact_blocks(positions: np.ndarray, block_rows: int = BLOCK_ROWS) -> list[np.ndarray]:
    """Row indices split into blocks of at most `block_rows`: each split halves a block at the median of the
    coordinate (column of `positions`, (K, D)) that spans most, so that blocks are spatially compact."""
    blocks, todo = [], [np.arange(len(positions))]
    while todo:
        rows = todo.pop()
        if len(rows) <= block_rows:
            blocks.append(rows)
            continue
        coordinates = positions[rows]
        axis = int(np.ptp(coordinates, axis=0).argmax())
        half = len(rows) // 2
        order = np.argpartition(coordinates[:, axis], half)
        todo += [rows[order[half:]], rows[order[:half]]]
    return blocks


class _BlasLimit:
    """BLAS held to one thread while any sum runs (counted: sums of several captures may overlap, and the process-wide
    limit must not be lifted under one of them). numpy's OpenBLAS workers busy-wait: on shared cores these many
    small (96 x K) @ (K x 96) products run 2-6x faster single-threaded (measured); Python threads use the cores."""

    def __init__(self):
        self._lock, self._users, self._limits = threading.Lock(), 0, None

    @contextlib.contextmanager
    def __call__(self):
        with self._lock:
            if self._users == 0:
                self._limits = threadpool_limits(limits=1, user_api="blas")
            self._users += 1
        try:
            yield
        finally:
            with self._lock:
                self._users -= 1
                if self._users == 0:
                    self._limits.restore_original_limits()


single_threaded_blas = _BlasLimit()


_thread_limit: list[int] = []      # set in worker processes that share the cores (bench.synth.workers)


def limit_threads(count: int) -> None:
    """Give the block pool `count` threads (at least PARTIAL_SUMS) instead of one per core; call before the first
    sum. The frames do not depend on it (module doc)."""
    _thread_limit[:] = [count]


@functools.cache
def _threads() -> int:
    """Threads of the block pool: one per core (or limit_threads's count), at least PARTIAL_SUMS."""
    return max(PARTIAL_SUMS, *_thread_limit[:1] or [usable_cores()])


@functools.cache
def _block_pool() -> ThreadPoolExecutor:
    """The process-wide pool computing blocks (module doc)."""
    return ThreadPoolExecutor(_threads(), thread_name_prefix="leg-sum")


def leg_sum(legs: Legs, positions: np.ndarray, n_rx: int, n_tx: int, freqs_hz: np.ndarray) -> np.ndarray:
    """The frame (n_rx, n_tx, F) complex64 of all rows; `positions` (K, D) places the rows for blocking."""
    freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
    outs = [np.zeros((len(freqs_hz), n_rx, n_tx), dtype=np.complex64) for _ in range(PARTIAL_SUMS)]
    blocks = compact_blocks(np.asarray(positions, dtype=np.float64), BLOCK_ROWS)
    pool = _block_pool()

    def block(rows: np.ndarray, into: np.ndarray | None) -> np.ndarray | None:
        return block_sum(*legs(rows), freqs_hz, n_rx, into)

    window = 2 * _threads()      # blocks in flight (each result is F x n_rx x n_tx complex64: ~9 MB)
    pending: collections.deque = collections.deque()
    spare: list[np.ndarray] = []      # results already added, written over by later blocks: fresh ~9 MB arrays
    with single_threaded_blas():      # cost page faults (a fifth of the generator's system time)
        for number, rows in enumerate(blocks):
            pending.append((number, pool.submit(block, rows, spare.pop() if spare else None)))
            while len(pending) >= window or (number == len(blocks) - 1 and pending):
                done, future = pending.popleft()
                contribution = future.result()
                if contribution is not None:
                    outs[done % PARTIAL_SUMS] += contribution
                    if contribution.shape == outs[0].shape:
                        spare.append(contribution)
    out = outs[0]
    for other in outs[1:]:
        out += other
    return np.ascontiguousarray(out.transpose(1, 2, 0))


def block_nodes(path_m: np.ndarray, freqs_hz: np.ndarray,
                n_rx: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """A block's centre path per antenna (E,) m, its node frequencies (M,) Hz and the fit (F, M) complex64 from the
    nodes to every frequency (frequency_nodes.interpolator); fit None (the nodes are the frequencies) with the
    centres 0."""
    return nodes_of_bounds(path_m.min(axis=1), path_m.max(axis=1), freqs_hz, n_rx)


def nodes_of_bounds(low: np.ndarray, high: np.ndarray, freqs_hz: np.ndarray,
                    n_rx: int) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """block_nodes from the block's shortest and longest path per antenna (E,) m."""
    centre = 0.5 * (low + high)
    # every pair's path lies within centre_rx + centre_tx +- (largest receive half-span + largest transmit one)
    half_span = 0.5 * (high - low)
    nodes_hz, fit = interpolator(freqs_hz, half_span[:n_rx].max() + half_span[n_rx:].max())
    if fit is None:                 # direct: every frequency is a node, nothing to factor out
        centre[:] = 0.0
    return centre, nodes_hz, fit


def block_sum(path_m: np.ndarray, weight: np.ndarray, freqs_hz: np.ndarray, n_rx: int,
              into: np.ndarray | None = None) -> np.ndarray | None:
    """One block's sum (F, n_rx, n_tx) complex64 (path_m, weight: (n_rx + n_tx, k), receive legs first; None for
    no rows): at the node frequencies, then interpolated to every frequency, into `into` (a C-contiguous
    complex64 array of that shape, overwritten) where given. Added to a sum it gives what adding node by node gave
    (0 + x is x)."""
    if path_m.shape[1] == 0:
        return None
    centre, nodes_hz, fit = block_nodes(path_m, freqs_hz, n_rx)
    offsets_m = path_m - centre[:, None]
    at_nodes = np.empty((len(nodes_hz), n_rx, path_m.shape[0] - n_rx), dtype=np.complex64)
    steps_hz = np.diff(nodes_hz)
    equidistant = len(steps_hz) > 0 and np.allclose(steps_hz, steps_hz[0], rtol=1e-9, atol=1e-3)
    reseed = RESEED_STEPS if equidistant else 1
    step = exact_phasors(offsets_m, steps_hz[0]) if equidistant else None
    for n, node_hz in enumerate(nodes_hz):
        if n % reseed == 0:
            phasor = exact_phasors(offsets_m, node_hz)
            phasor *= weight
        else:
            phasor *= step
        np.matmul(phasor[:n_rx], phasor[n_rx:].T, out=at_nodes[n])     # rows: receive legs, then transmit legs
    if fit is None:
        return at_nodes
    shape = (len(freqs_hz), *at_nodes.shape[1:])
    every = np.empty(shape, dtype=np.complex64) if into is None else into
    np.matmul(fit, at_nodes.reshape(len(nodes_hz), -1), out=every.reshape(len(freqs_hz), -1))
    centre_phasor = exact_phasors(centre[None, :], freqs_hz[:, None])          # the centre path, factored out
    every *= centre_phasor[:, :n_rx, None]
    every *= centre_phasor[:, None, n_rx:]
    return every
