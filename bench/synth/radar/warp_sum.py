"""The radar sum on a Warp device ("cuda" or "warp-cpu"; kernels in `bench.synth.radar.warp_kernels`).

`leg_sum` computes each block's legs and its nodes on its pool's threads, with the NumPy path's own
`leg_sum.block_nodes` (the same centres, node frequencies and fits), lays them out for the device (`prepare`) and
hands them, in block order, to a `DeviceSum`, which forms the node sums and the interpolation on the device and adds
each block to a float64 frame. The device work of all captures built at once goes through one lock, block by block,
each frame into its own sum: a capture's frame does not depend on what else runs
(tests/bench/synth/test_synth_warp.py).
"""
from __future__ import annotations

import functools
import threading
from dataclasses import dataclass

import numpy as np

from bench.synth.config import C_M_PER_S

WARP_DEVICES = {"cuda": "cuda:0", "warp-cpu": "cpu"}     # the project's device names (methods.backends.DEVICES)
_device_lock = threading.Lock()


@functools.cache
def _warp():
    """Warp and the kernels, imported and initialised on first use only (the NumPy path never imports Warp)."""
    import warp as wp

    from bench.synth.radar import warp_kernels
    from methods.backends.warp.runtime import init

    init()
    return wp, warp_kernels


@dataclass(frozen=True)
class Block:
    """One block ready for the device: legs (E, k) m float64 and their weights as (E, k, 2) float32, the centre
    path per antenna (E,) m, the node frequencies over c (M,) 1/m and the fit (F, M, 2) float32 (None: direct)."""

    path_m: np.ndarray
    weight: np.ndarray
    centre_m: np.ndarray
    node_cycles_per_m: np.ndarray
    fit: np.ndarray | None


def prepare(path_m: np.ndarray, weight: np.ndarray, centre_m: np.ndarray, nodes_hz: np.ndarray,
            fit: np.ndarray | None) -> Block:
    """A block of legs (bench.synth.radar.leg_sum.Legs) and its nodes (leg_sum.block_nodes) as the device takes
    them."""
    parts = np.ascontiguousarray(weight, dtype=np.complex64).view(np.float32).reshape(*weight.shape, 2)
    fit_parts = None if fit is None else np.ascontiguousarray(fit).view(np.float32).reshape(*fit.shape, 2)
    return Block(np.ascontiguousarray(path_m, dtype=np.float64), parts, centre_m,
                 np.asarray(nodes_hz, dtype=np.float64) / C_M_PER_S, fit_parts)


class DeviceSum:
    """The frame (n_rx, n_tx, F) of blocks added one after the other on `device` ("cuda", "warp-cpu")."""

    def __init__(self, device: str, n_rx: int, n_tx: int, freqs_hz: np.ndarray):
        wp, self._kernels = _warp()
        self._wp, self._device, self._n_rx, self._n_tx = wp, WARP_DEVICES[device], n_rx, n_tx
        with _device_lock:
            # f / c as leg_sum.exact_phasors forms it
            self._cycles_per_m = wp.array(np.asarray(freqs_hz, dtype=np.float64) / C_M_PER_S, dtype=wp.float64,
                                          device=self._device)
            self._frame = wp.zeros((len(freqs_hz), n_rx, n_tx), dtype=wp.vec2d, device=self._device)

    def add(self, block: Block | None) -> None:
        """Add one block (`prepare`)."""
        if block is None:
            return
        wp, kernels, n_rx, n_tx = self._wp, self._kernels, self._n_rx, self._n_tx
        n_antennas, n_rows = block.path_m.shape
        n_nodes, tile, slices = len(block.node_cycles_per_m), kernels.PAIR_TILE, kernels.ROW_SLICES
        with _device_lock, wp.ScopedDevice(self._device):
            path = wp.array(block.path_m, dtype=wp.float64)
            weight = wp.array(block.weight, dtype=wp.vec2f)
            centre = wp.array(block.centre_m, dtype=wp.float64)
            node_cycles = wp.array(block.node_cycles_per_m, dtype=wp.float64)
            fit = wp.array(block.fit if block.fit is not None else np.zeros((1, 1, 2), np.float32), dtype=wp.vec2f)
            phasors = wp.empty((n_nodes, n_rows, n_antennas), dtype=wp.vec2f)
            wp.launch(kernels.leg_phasors, dim=phasors.shape, inputs=[path, centre, weight, node_cycles, phasors])
            partial = wp.empty((slices, n_nodes, n_rx, n_tx), dtype=wp.vec2f)
            rows_per_slice = -(-n_rows // slices)
            wp.launch(kernels.pair_products, dim=(slices, n_nodes, -(-n_rx // tile), -(-n_tx // tile)),
                      inputs=[phasors, n_rx, rows_per_slice, partial])
            nodes = wp.empty((n_nodes, n_rx, n_tx), dtype=wp.vec2f)
            wp.launch(kernels.add_slices, dim=nodes.shape, inputs=[partial, nodes])
            wp.launch(kernels.interpolate_add, dim=self._frame.shape,
                      inputs=[nodes, fit, int(block.fit is None), centre, self._cycles_per_m, self._frame])

    def result(self) -> np.ndarray:
        """The frame, complex64 (n_rx, n_tx, F) (rounded once from the float64 sum)."""
        with _device_lock:
            frame = self._frame.numpy()                     # (F, n_rx, n_tx, 2) float64; waits for the device
        summed = frame[..., 0] + 1j * frame[..., 1]
        return np.ascontiguousarray(summed.transpose(1, 2, 0)).astype(np.complex64)
