"""A whole MM-2FSK new frame as one CUDA graph: the RealSense prior (camera quads, the scanline hole fill), the
correlation at the prior (tables built from the raw samples, tensor cores), depth and filter, and the copies in
and out, replayed per frame with one launch and one synchronisation (`FrameGraph.run`).

The launches are those of the step-by-step device path (`warp_backend.prior.realsense_prior` with fill
'scanline', then `warp_backend.fsk.depth_at_prior`), on buffers allocated once per setting (depth image size,
grid, camera, transform, frequencies, antennas, filter threshold: `graph_key`) so that their addresses stay
fixed, and with launch sizes that do not depend on the frame: the covered pixels are compacted into slots as
before and every later kernel runs over all ny * nx slots, threads past the count doing nothing (the correlation
computes the unused slots too: ~0.05 ms more on the H100, less than one host round trip). A new frame's samples,
depth image and mask are copied into pinned staging buffers on the host; the graph's first nodes copy them to the
device. Warp-CPU has no graphs: there `run` issues the same launches (the correlation with the separable kernel,
Warp-CPU's default), which is how the tests compare this path with the step-by-step one without a GPU.
"""
from __future__ import annotations

import numpy as np
import warp as wp

from methods.warp_backend import correlation_kernels as ck
from methods.warp_backend import fsk_kernels, prior_kernels, table_kernels
from methods.warp_backend.frames import C_M_PER_S, FrameInputs, antennas4
from methods.warp_backend.fsk import grid_arrays
from methods.warp_backend.prior import pixel_scale

GRAPHS_KEPT = 4
_GRAPHS: dict = {}


def graph_key(depth, realsense2radar, grid, max_jump_mm, freqs_hz, tx_m, rx_m, keep_ratio, device) -> tuple:
    """Everything a FrameGraph bakes in (sizes, constants, scalar launch arguments)."""
    k = depth.intrinsics
    return (str(device), depth.depth_mm.shape, depth.mask is not None, (k.fx, k.fy, k.cx, k.cy),
            float(depth.depth_scale_m), np.asarray(realsense2radar, dtype=np.float64).tobytes(), grid,
            max_jump_mm, np.asarray(freqs_hz, dtype=np.float64).tobytes(), tx_m.tobytes(), rx_m.tobytes(),
            float(keep_ratio))


class FrameGraph:
    """The buffers and launches of one setting (module doc); `run(depth, signal)` computes a frame."""

    def __init__(self, buffers, depth, realsense2radar, grid, max_jump_mm, freqs_hz, tx_m, rx_m, keep_ratio):
        dev = wp.get_device(buffers.wp_device)
        self.device, self.grid = dev, grid
        ny, nx = self.shape = grid.image_shape
        n_px = ny * nx
        height, width = depth.depth_mm.shape
        n_rx, n_tx, n_f = len(rx_m), len(tx_m), len(freqs_hz)
        pinned = not dev.is_cpu
        self.depth_host = wp.empty((height, width), dtype=wp.uint16, device="cpu", pinned=pinned)
        self.mask_host = wp.empty((height, width) if depth.mask is not None else (1, 1), dtype=wp.uint8,
                                  device="cpu", pinned=pinned)
        self.raw_host = wp.empty((n_rx, n_tx, n_f), dtype=wp.vec2f, device="cpu", pinned=pinned)
        self.maps_host = wp.empty((3, n_px), dtype=wp.float64, device="cpu", pinned=pinned)
        self.stats_host = wp.empty(2, dtype=wp.int32, device="cpu", pinned=pinned)
        self.count_host = wp.empty(1, dtype=wp.int32, device="cpu", pinned=pinned)
        self.d_img = wp.empty_like(self.depth_host, device=dev)
        self.m_img = wp.empty_like(self.mask_host, device=dev)
        self.raw = wp.empty_like(self.raw_host, device=dev)
        self.zbuf = wp.empty(n_px, dtype=wp.float64, device=dev)
        self.filled = wp.empty(n_px, dtype=wp.float64, device=dev)
        self.stats = wp.empty(2 + 4 * ny + 2 * nx, dtype=wp.int32, device=dev)
        self.gain_raw = wp.empty(n_f, dtype=wp.float32, device=dev)
        self.gain = wp.empty(n_f, dtype=wp.float32, device=dev)
        self.mat_h = wp.empty((n_f, 2, int(ck.TC_ANT), int(ck.TC2_KP)), dtype=wp.float16, device=dev)
        self.slot = wp.empty(1, dtype=wp.int32, device=dev)
        self.peak = wp.empty(1, dtype=wp.float32, device=dev)
        self.points = wp.zeros(n_px, dtype=wp.vec3d, device=dev)          # unused slots: finite points
        self.pixel = wp.zeros(n_px, dtype=wp.int32, device=dev)
        self.pts = wp.empty(n_px, dtype=wp.vec4f, device=dev)
        self.common = wp.empty((n_f, n_px), dtype=wp.vec2f, device=dev)
        self.out = wp.empty((n_f, n_px), dtype=wp.vec2f, device=dev)
        self.maps = wp.empty((3, n_px), dtype=wp.float64, device=dev)
        k = depth.intrinsics
        self.cam = prior_kernels.vec9d(k.fx, k.fy, k.cx, k.cy, depth.depth_scale_m * 1000.0, *pixel_scale(grid))
        self.xf = wp.mat44d(*np.asarray(realsense2radar, dtype=np.float64).ravel())
        self.max_jump = wp.float64(-1.0 if max_jump_mm is None else max_jump_mm)
        self.use_mask = int(depth.mask is not None)
        self.x_m, self.y_m = grid_arrays(buffers, grid)
        self.k = wp.array((2 * np.pi * freqs_hz / C_M_PER_S).astype(np.float32), dtype=wp.float32, device=dev)
        self.cycles = wp.array(2.0 * freqs_hz / C_M_PER_S, dtype=wp.float64, device=dev)
        self.rx4 = wp.array(antennas4(rx_m, int(ck.TC_ANT)), dtype=wp.vec4f, device=dev)
        self.tx4 = wp.array(antennas4(tx_m, int(ck.TC_ANT)), dtype=wp.vec4f, device=dev)
        self.scale = wp.float32(1.0 / (n_rx * n_tx))
        self.m_per_rad = float(C_M_PER_S / (4.0 * np.pi * (freqs_hz[1] - freqs_hz[0])))
        self.keep_ratio = float(keep_ratio)
        self.freqs_hz, self.tx_m, self.rx_m = freqs_hz, tx_m, rx_m
        self.graph = None
        if not dev.is_cpu:
            with wp.ScopedCapture(device=dev) as capture:
                self._enqueue()
            self.graph = capture.graph

    def _correlate(self) -> None:
        """Phasors (2, ny * nx) of every slot: tensor cores on CUDA; Warp-CPU's separable kernel from host tables."""
        dev, n_px = self.device, self.points.shape[0]
        empty = wp.empty(0, dtype=wp.float64, device=dev)
        if dev.is_cpu:
            inputs = FrameInputs(self.raw_host.numpy().view(np.complex64)[..., 0], self.freqs_hz, self.tx_m,
                                 self.rx_m, dev.alias)
            wp.launch(ck.correlate_separable, dim=n_px,
                      inputs=[0, self.points, empty, empty, empty, inputs.rx, inputs.tx_padded, inputs.k,
                              inputs.cycles, inputs.signal_padded, 0, self.out], device=dev)
            return
        wp.launch(table_kernels.signal_gain, dim=self.raw.shape, inputs=[self.raw, self.scale, self.gain_raw],
                  device=dev)
        wp.launch(table_kernels.tx_half_table, dim=self.mat_h.shape,
                  inputs=[self.raw, self.scale, self.gain_raw, self.gain, self.mat_h], device=dev)
        wp.launch(ck.prepare_points, dim=n_px, inputs=[0, self.points, empty, empty, empty, self.cycles, self.pts,
                                                       self.common], device=dev)
        n_blocks = (n_px + int(ck.TC2_POINTS) - 1) // int(ck.TC2_POINTS)
        wp.launch_tiled(ck.correlate_tiles_tx_halves, dim=[n_blocks],
                        inputs=[self.pts, self.rx4, self.tx4, self.k, self.gain, self.mat_h, self.common, 0,
                                self.out], block_dim=ck.TC_BLOCK, device=dev)

    def _enqueue(self) -> None:
        """Every copy and launch of a frame, in stream order (captured once on CUDA; issued per frame on Warp-CPU)."""
        dev = self.device
        ny, nx = self.shape
        n_px = ny * nx
        height, width = self.d_img.shape
        wp.copy(self.d_img, self.depth_host)
        wp.copy(self.m_img, self.mask_host)
        wp.copy(self.raw, self.raw_host)
        self.gain_raw.zero_()
        self.slot.zero_()
        self.peak.zero_()
        wp.launch(prior_kernels.clear_zbuffer, dim=n_px, inputs=[ny, self.zbuf, self.stats], device=dev)
        wp.launch(prior_kernels.raster_camera_quads, dim=(height - 1) * (width - 1),
                  inputs=[self.d_img, self.m_img, self.use_mask, self.cam, self.xf, self.max_jump, ny, nx,
                          self.zbuf], device=dev)
        wp.launch(prior_kernels.covered_spans, dim=n_px, inputs=[ny, nx, self.zbuf, self.stats], device=dev)
        wp.launch(prior_kernels.scanline_fill, dim=n_px, inputs=[ny, nx, self.zbuf, self.stats, self.filled],
                  device=dev)
        wp.launch(fsk_kernels.compact_covered_pixels, dim=n_px,
                  inputs=[nx, self.filled, self.x_m, self.y_m, self.slot, self.points, self.pixel, self.maps],
                  device=dev)
        self._correlate()
        wp.launch(fsk_kernels.depth_at_prior_counted, dim=n_px,
                  inputs=[self.out, self.pixel, self.slot, self.m_per_rad, self.maps, self.peak], device=dev)
        wp.launch(fsk_kernels.magnitude_filter_counted, dim=n_px,
                  inputs=[self.pixel, self.slot, self.keep_ratio, self.peak, self.maps], device=dev)
        wp.copy(self.maps_host, self.maps)
        wp.copy(self.stats_host, self.stats, count=2)

    def run(self, depth, signal: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """(depth_m, magnitude, prior_m) (ny, nx) NaN where none, and the prior's covered pixels, of a new frame:
        its depth frame (the setting's size) and two-frequency samples (n_rx, n_tx, 2)."""
        np.copyto(self.depth_host.numpy(), depth.depth_mm, casting="unsafe")
        if self.use_mask:
            np.copyto(self.mask_host.numpy(), depth.mask, casting="unsafe")
        np.copyto(self.raw_host.numpy().view(np.complex64)[..., 0], signal, casting="same_kind")
        if self.graph is not None:
            wp.capture_launch(self.graph)
        else:
            self._enqueue()
        wp.synchronize_device(self.device)
        maps = self.maps_host.numpy().reshape(3, *self.shape).copy()
        n_covered, n_filled = (int(v) for v in self.stats_host.numpy())
        return maps[0], maps[1], maps[2], n_covered + n_filled


def frame_graph(buffers, depth, realsense2radar, grid, max_jump_mm, freqs_hz, tx_m, rx_m, keep_ratio) -> FrameGraph:
    """The FrameGraph of this setting, built (and on CUDA captured) on first use."""
    key = graph_key(depth, realsense2radar, grid, max_jump_mm, freqs_hz, tx_m, rx_m, keep_ratio, buffers.wp_device)
    if key not in _GRAPHS:
        _GRAPHS[key] = FrameGraph(buffers, depth, realsense2radar, grid, max_jump_mm, freqs_hz, tx_m, rx_m,
                                  keep_ratio)
        while len(_GRAPHS) > GRAPHS_KEPT:
            _GRAPHS.pop(next(iter(_GRAPHS)))
    return _GRAPHS[key]
