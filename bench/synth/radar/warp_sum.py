"""The radar sum on a Warp device ("cuda" or "warp-cpu"; kernels in `bench.synth.radar.warp_kernels`).

The rows arrive as their two sides (`Side`, `Rows`: what `model.simulate_frame` and `multipath.simulate_pairs` build
their legs from); the legs, the node sums, the interpolation and the sum over blocks run on the device. The blocks
are the NumPy path's (`leg_sum.compact_blocks`, rows that add nothing dropped first), and so are the node
frequencies and fits (`leg_sum.nodes_of_bounds` on each block's path range, read back from the device). Each block
is added to a float64 frame in block order. A frame's blocks go in two passes: every block's legs and path bounds,
the bounds read back at once for the fits, then every block's node sums (so the host waits for the device once per
frame, not once per block). The device work of all captures built at once goes through one lock, each frame into
its own sum: a capture's frame does not depend on what else runs (tests/bench/synth/test_synth_warp.py).
"""
from __future__ import annotations

import functools
import threading
from dataclasses import dataclass

import numpy as np

from bench.synth.config import C_M_PER_S
from bench.synth.radar import leg_sum

WARP_DEVICES = {"cuda": "cuda:0", "warp-cpu": "cpu"}     # the project's device names (methods.backends.DEVICES)
_device_lock = threading.Lock()


@functools.cache
def _warp():
    """Warp and the kernels, imported and initialised on first use only (the NumPy path never imports Warp); under
    the device lock, as captures built at once may ask first together."""
    with _device_lock:
        import warp as wp

        from bench.synth.radar import warp_kernels
        from methods.backends.warp.runtime import init

        init()
        return wp, warp_kernels


def start() -> None:
    """Import and initialise Warp and the kernels now (a device server starts them while its workers get going)."""
    _warp()


_delegate: list = []     # set in worker processes: the function that sums a frame in the process holding the device


def delegate(function) -> None:
    """Have `frame(...)` computed by `function(rows, blocks, rx_m, tx_m, freqs_hz, device)` (frame_of_blocks's
    arguments) from now on (bench.synth.radar.remote.connect)."""
    _delegate[:] = [function]


@dataclass(frozen=True)
class Side:
    """One side of every row: the point its legs leave (K, 3) m, the lobe axis (K, 3) (unit vectors) and half-width
    (K,) rad (None: no lobe), the complex amplitude (K,) (None: 1) and the path added to its legs (K,) m (None: 0)."""

    point_m: np.ndarray
    axis: np.ndarray | None = None
    lobe_rad: np.ndarray | None = None
    amplitude: np.ndarray | None = None
    added_m: np.ndarray | None = None


def joined(first: Side, second: Side) -> Side:
    """The rows of `first`, then those of `second`, as one side (an absent field as its default)."""
    n_first, n_second = len(first.point_m), len(second.point_m)

    def field(name, default):
        a, b = getattr(first, name), getattr(second, name)
        if a is None and b is None:
            return None
        return np.concatenate([default(n_first) if a is None else a, default(n_second) if b is None else b])

    return Side(np.concatenate([first.point_m, second.point_m]), field("axis", lambda n: np.zeros((n, 3))),
                field("lobe_rad", np.zeros), field("amplitude", np.ones), field("added_m", np.zeros))


@dataclass(frozen=True)
class Rows:
    """The rows of a frame: receive and transmit sides, the element-pattern exponent, and per row the lobe cosine
    (K,) that some antenna must reach for the row to count (None: every row counts)."""

    rx: Side
    tx: Side
    element_exponent: float = 0.0
    cos_limit: np.ndarray | None = None


def frame(rows: Rows, positions: np.ndarray, rx_m: np.ndarray, tx_m: np.ndarray, freqs_hz: np.ndarray,
          device: str) -> np.ndarray:
    """The frame (n_rx, n_tx, F) complex64 of `rows` on `device`; `positions` (K, D) places the rows for blocking
    (as bench.synth.radar.leg_sum.leg_sum). The blocks are made here, in the worker where the sums are delegated
    (their cost, ~0.1 s per 100 k rows, off the process that serves every worker)."""
    blocks = leg_sum.compact_blocks(np.asarray(positions, dtype=np.float64), leg_sum.BLOCK_ROWS)
    if _delegate:
        return _delegate[0](rows, blocks, rx_m, tx_m, freqs_hz, device)
    return frame_of_blocks(rows, blocks, rx_m, tx_m, freqs_hz, device)


def frame_of_blocks(rows: Rows, blocks: list[np.ndarray], rx_m: np.ndarray, tx_m: np.ndarray,
                    freqs_hz: np.ndarray, device: str) -> np.ndarray:
    """`frame` of `rows` split into `blocks` (leg_sum.compact_blocks' row indices), summed in block order."""
    freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
    total = _DeviceFrame(rows, np.concatenate([rx_m, tx_m]), len(rx_m), freqs_hz, WARP_DEVICES[device])
    total.add(blocks)
    return total.result()


class _DeviceFrame:
    """The frame of blocks of rows added one after the other on a Warp device."""

    def __init__(self, rows: Rows, antennas_m: np.ndarray, n_rx: int, freqs_hz: np.ndarray, device: str):
        wp, self._kernels = _warp()
        self._wp, self._device, self._n_rx, self._freqs_hz = wp, device, n_rx, freqs_hz
        self._exponent = float(rows.element_exponent)
        n_rows = len(rows.rx.point_m)

        def stack(name, fill, dtype):
            values = [getattr(side, name) for side in (rows.rx, rows.tx)]
            return np.stack([np.full(n_rows, fill, dtype) if v is None else np.asarray(v, dtype) for v in values])

        axes = np.stack([np.zeros((n_rows, 3)) if s.axis is None else np.asarray(s.axis, float)
                         for s in (rows.rx, rows.tx)])
        amplitude = stack("amplitude", 1.0, np.complex64)
        with _device_lock, wp.ScopedDevice(device):
            self._antennas = wp.array(np.asarray(antennas_m, dtype=np.float64), dtype=wp.vec3d)
            self._points = wp.array(np.stack([np.asarray(s.point_m, float) for s in (rows.rx, rows.tx)]),
                                    dtype=wp.vec3d)
            self._axes = wp.array(axes, dtype=wp.vec3d)
            self._lobe = wp.array(stack("lobe_rad", 0.0, np.float64), dtype=wp.float64)
            self._amplitude = wp.array(amplitude.view(np.float32).reshape(2, n_rows, 2), dtype=wp.vec2f)
            self._added = wp.array(stack("added_m", 0.0, np.float64), dtype=wp.float64)
            self._cycles_per_m = wp.array(freqs_hz / C_M_PER_S, dtype=wp.float64)   # as leg_sum.exact_phasors
            self._frame = wp.zeros((len(freqs_hz), n_rx, len(antennas_m) - n_rx), dtype=wp.vec2d)
            if rows.cos_limit is None:
                self._audible = np.ones(n_rows, dtype=bool)
            else:
                flags = wp.empty(n_rows, dtype=wp.int32)
                limit = wp.array(np.asarray(rows.cos_limit, dtype=np.float64), dtype=wp.float64)
                wp.launch(self._kernels.audible, dim=n_rows, inputs=[self._antennas, n_rx, self._points,
                                                                     self._axes, self._lobe, limit, flags])
                self._audible = flags.numpy().astype(bool)

    def add(self, blocks: list[np.ndarray]) -> None:
        """Add the blocks of row indices, in order (rows that add nothing dropped, as the NumPy path does): every
        block's legs and path bounds first, the bounds read back at once (the node fits need them on the host), then
        every block's node sums: the host waits for the device once per frame, not once per block."""
        wp, kernels, n_rx = self._wp, self._kernels, self._n_rx
        blocks = [rows for rows in (rows[self._audible[rows]] for rows in blocks) if len(rows)]
        if not blocks:
            return
        n_antennas = self._antennas.shape[0]
        chunks = [-(-len(rows) // int(kernels.BOUND_ROWS)) for rows in blocks]
        legs, ends = [], np.cumsum([len(rows) for rows in blocks])
        with _device_lock, wp.ScopedDevice(self._device):
            indices = wp.array(np.concatenate(blocks).astype(np.int32), dtype=wp.int32)     # one upload for all
            bounds = wp.empty((len(blocks), n_antennas, max(chunks), 2), dtype=wp.float64)
            for number, rows in enumerate(blocks):
                index = indices[ends[number] - len(rows):ends[number]]
                path = wp.empty((n_antennas, len(rows)), dtype=wp.float64)
                weight = wp.empty((n_antennas, len(rows)), dtype=wp.vec2f)
                wp.launch(kernels.legs, dim=path.shape, inputs=[index, self._antennas, n_rx, self._points, self._axes,
                                                                  self._lobe, self._amplitude, self._added,
                                                                  self._exponent, path, weight])
                wp.launch(kernels.path_bounds, dim=(n_antennas, chunks[number]), inputs=[path, bounds[number]])
                legs.append((path, weight))
            ranges = bounds.numpy()
        fits = [leg_sum.nodes_of_bounds(ranges[number, :, :count, 0].min(axis=1),
                                        ranges[number, :, :count, 1].max(axis=1), self._freqs_hz, n_rx)
                for number, count in enumerate(chunks)]
        with _device_lock, wp.ScopedDevice(self._device):
            for (path, weight), fitted in zip(legs, fits, strict=True):
                self._add_nodes(path, weight, *fitted)

    def _add_nodes(self, path, weight, centre_m: np.ndarray, nodes_hz: np.ndarray, fit: np.ndarray | None) -> None:
        """One block's node sums from its legs on the device, interpolated to every frequency and added to the
        frame (the caller holds the device lock)."""
        wp, kernels, n_rx = self._wp, self._kernels, self._n_rx
        n_rows, n_tx = path.shape[1], self._frame.shape[2]
        n_nodes, tile, slices = len(nodes_hz), kernels.PAIR_TILE, kernels.ROW_SLICES
        fit_parts = np.zeros((1, 1, 2), np.float32) if fit is None else np.ascontiguousarray(fit).view(
            np.float32).reshape(*fit.shape, 2)
        centre = wp.array(centre_m, dtype=wp.float64)
        node_cycles = wp.array(np.asarray(nodes_hz, dtype=np.float64) / C_M_PER_S, dtype=wp.float64)
        fit_array = wp.array(fit_parts, dtype=wp.vec2f)
        phasors = wp.empty((n_nodes, n_rows, path.shape[0]), dtype=wp.vec2f)
        wp.launch(kernels.leg_phasors, dim=phasors.shape, inputs=[path, centre, weight, node_cycles, phasors])
        partial = wp.empty((slices, n_nodes, n_rx, n_tx), dtype=wp.vec2f)
        wp.launch(kernels.pair_products, dim=(slices, n_nodes, -(-n_rx // tile), -(-n_tx // tile)),
                  inputs=[phasors, n_rx, -(-n_rows // slices), partial])
        nodes = wp.empty((n_nodes, n_rx, n_tx), dtype=wp.vec2f)
        wp.launch(kernels.add_slices, dim=nodes.shape, inputs=[partial, nodes])
        wp.launch(kernels.interpolate_add, dim=self._frame.shape,
                  inputs=[nodes, fit_array, int(fit is None), centre, self._cycles_per_m, self._frame])

    def result(self) -> np.ndarray:
        """The frame, complex64 (n_rx, n_tx, F) (rounded once from the float64 sum)."""
        with _device_lock:
            summed = self._frame.numpy()                    # (F, n_rx, n_tx, 2) float64; waits for the device
        return np.ascontiguousarray((summed[..., 0] + 1j * summed[..., 1]).transpose(1, 2, 0)).astype(np.complex64)
