"""A whole MM-2FSK (or MM-3FSK) new frame as two CUDA graphs: the RealSense prior (camera quads, the scanline hole
fill), then the correlation at the prior (tables built from the raw samples, tensor cores), depth and filter, and the
copies in and out, replayed per frame with two launches and one synchronisation (`FrameGraph.run`); the host
gathers the frame's samples while the device builds the prior (one graph cost 0.69-0.78 ms a 301 x 301 call on the
H100, against 0.56 ms with the prior launched first: formation.md section 13).

The launches are those of the step-by-step device path (`warp_backend.prior.realsense_prior` with fill
'scanline', then `warp_backend.fsk.depth_at_prior`), on buffers allocated once per setting (depth image size,
grid, camera, transform, frequencies, antennas, filter threshold: `graph_key`) so that their addresses stay
fixed, and with launch sizes that do not depend on the frame: the covered pixels are compacted into slots as
before and every later kernel runs over all ny * nx slots, threads (and the correlation's blocks) past the count
returning at once, so the count never goes to the host before the end. A new frame's depth image and mask are
copied into pinned staging buffers on the host, its samples gathered into one (straight from the frame:
`methods.domain.samples.FrameSamples`) and checked for NaN/Inf on the device; the graphs' first nodes copy them to
the device, and the maps come back into pinned buffers lent to the caller (`HostMaps`). With a coarse pair
(MM-3FSK, `methods.mm3fsk`) the correlation at the prior is the coarse pair's; the median of its corrections over
the pixels the filter keeps (`MedianOffset`: a radix select on the corrections quantised to 2^32 steps over +-3.2
rad, within 3e-11 m of np.median's for d05_d10's pair) moves every point, the three frequencies are correlated
there and the slope gives the depth, still one copy back. Warp-CPU has no graphs: there `run` issues the same
launches (the correlation with the separable kernel, Warp-CPU's default), which is how the tests compare this path
with the step-by-step one without a GPU.
"""
from __future__ import annotations

import sys
import weakref

import numpy as np
import warp as wp

from methods.backends.warp.frames import C_M_PER_S, FrameInputs, antennas4
from methods.backends.warp.fsk import grid_arrays
from methods.backends.warp.kernels import correlation as ck
from methods.backends.warp.kernels import fsk as fsk_kernels
from methods.backends.warp.kernels import prior as prior_kernels
from methods.backends.warp.kernels import tables as table_kernels
from methods.backends.warp.prior import pixel_scale
from methods.domain.errors import NonFiniteSignal
from methods.domain.samples import FrameSamples

GRAPHS_KEPT = 4
PEAK_SHARDS = int(fsk_kernels.PEAK_SHARDS)     # partial maxima of the magnitude (fsk_kernels.reduce_peak)
_GRAPHS: dict = {}


def graph_key(depth, realsense2radar, grid, max_jump_mm, freqs_hz, tx_m, rx_m, keep_ratio, device,
              coarse=None) -> tuple:
    """Everything a FrameGraph bakes in (sizes, constants, scalar launch arguments)."""
    k = depth.intrinsics
    return (str(device), depth.depth_mm.shape, depth.mask is not None, (k.fx, k.fy, k.cx, k.cy),
            float(depth.depth_scale_m), np.asarray(realsense2radar, dtype=np.float64).tobytes(), grid,
            max_jump_mm, np.asarray(freqs_hz, dtype=np.float64).tobytes(), tx_m.tobytes(), rx_m.tobytes(),
            float(keep_ratio), None if coarse is None else tuple(coarse))


def reduce_peak(shards: wp.array, peak: wp.array, dev) -> None:
    """peak[0] = the maximum of the PEAK_SHARDS shards (one block)."""
    wp.launch_tiled(fsk_kernels.reduce_peak, dim=[1], inputs=[shards, peak], block_dim=PEAK_SHARDS, device=dev)


class GraphCorrelator:
    """One frequency set's correlation over a fixed number of device points, on fixed buffers: `load(signal)`
    stages a frame's samples (host), `enqueue_tables()` copies them in and builds the tensor-core tables, and
    `enqueue(points)` launches the correlation into `out` (F, n). Warp-CPU: the separable kernel from host tables."""

    def __init__(self, dev, n_points: int, freqs_hz, tx_m, rx_m):
        n_rx, n_tx, n_f = len(rx_m), len(tx_m), len(freqs_hz)
        self.device, self.freqs_hz, self.tx_m, self.rx_m = dev, freqs_hz, tx_m, rx_m
        self.raw_host = wp.empty((n_rx, n_tx, n_f), dtype=wp.vec2f, device="cpu", pinned=not dev.is_cpu)
        self.raw_view = self.raw_host.numpy().view(np.complex64)[..., 0]      # made once: a frame only copies
        self.raw = wp.empty_like(self.raw_host, device=dev)
        self.gain_raw = wp.empty(n_f, dtype=wp.float32, device=dev)
        self.gain = wp.empty(n_f, dtype=wp.float32, device=dev)
        self.mat_h = wp.empty((n_f, 2, int(ck.TC_ANT), int(ck.TC2_KP)), dtype=wp.float16, device=dev)
        self.pts = wp.empty(n_points, dtype=wp.vec4f, device=dev)
        self.common = wp.empty((n_f, n_points), dtype=wp.vec2f, device=dev)
        self.out = wp.empty((n_f, n_points), dtype=wp.vec2f, device=dev)
        self.k = wp.array((2 * np.pi * freqs_hz / C_M_PER_S).astype(np.float32), dtype=wp.float32, device=dev)
        self.cycles = wp.array(2.0 * freqs_hz / C_M_PER_S, dtype=wp.float64, device=dev)
        self.rx4 = wp.array(antennas4(rx_m, int(ck.TC_ANT)), dtype=wp.vec4f, device=dev)
        self.tx4 = wp.array(antennas4(tx_m, int(ck.TC_ANT)), dtype=wp.vec4f, device=dev)
        self.scale = wp.float32(1.0 / (n_rx * n_tx))
        self.every = wp.array([2**31 - 1], dtype=wp.int32, device=dev)
        self.nonfinite = wp.zeros(1, dtype=wp.int32, device=dev)
        self.nonfinite_host = wp.zeros(1, dtype=wp.int32, device="cpu", pinned=not dev.is_cpu)
        self.nonfinite_view = self.nonfinite_host.numpy()

    def load(self, signal: np.ndarray | FrameSamples, indices: list[int] | None = None) -> None:
        """Stage a frame's samples (n_rx, n_tx, F) (with `indices`, those frequencies of it) for the next run: a
        FrameSamples is gathered from its frame straight into the staging buffer."""
        if isinstance(signal, FrameSamples):
            signal.gather(self.raw_view, indices)
        elif indices is not None and signal.dtype == np.complex64:     # gathered straight into the staging buffer
            np.take(signal, indices, axis=2, out=self.raw_view, mode="clip")
        else:
            np.copyto(self.raw_view, signal if indices is None else signal[:, :, indices], casting="same_kind")

    def enqueue_tables(self, check: bool = False) -> None:
        """Copy the staged samples in and build the tensor-core tables; `check`: also flag NaN/Inf samples
        (`nonfinite_staged` after the run)."""
        dev = self.device
        wp.copy(self.raw, self.raw_host)
        if check:
            self.nonfinite.zero_()
            wp.launch(table_kernels.flag_nonfinite, dim=self.raw.shape, inputs=[self.raw, self.nonfinite], device=dev)
            wp.copy(self.nonfinite_host, self.nonfinite)
        if dev.is_cpu:
            return
        table_kernels.launch_tables(self.raw, self.scale, self.gain_raw, self.gain, self.mat_h, dev)

    def nonfinite_staged(self) -> bool:
        """Whether the last run's samples held NaN or Inf (after the device finished a run that checked them)."""
        return bool(self.nonfinite_view[0])

    def enqueue(self, points: wp.array, count: wp.array | None = None, n_freqs: int | None = None) -> wp.array:
        """Phasors (F, n) of the n points into `out`; with `count` (device int32) only of the first count[0]
        (the tensor-core blocks past it return at once; Warp-CPU computes them all); with `n_freqs` only the first
        n_freqs frequencies' rows (the same values: each frequency is summed on its own)."""
        dev, n = self.device, points.shape[0]
        f = len(self.freqs_hz) if n_freqs is None else n_freqs
        empty = wp.empty(0, dtype=wp.float64, device=dev)
        if dev.is_cpu:
            inputs = FrameInputs(self.raw_view, self.freqs_hz, self.tx_m,
                                 self.rx_m, dev.alias)
            wp.launch(ck.correlate_separable, dim=n,
                      inputs=[0, points, empty, empty, empty, inputs.rx, inputs.tx_padded, inputs.k[:f],
                              inputs.cycles[:f], inputs.signal_padded[:f], 0, self.out], device=dev)
            return self.out
        count = self.every if count is None else count
        wp.launch(ck.prepare_points, dim=n, inputs=[0, points, empty, empty, empty, self.cycles[:f], self.pts,
                                                    self.common, count], device=dev)
        n_blocks = (n + int(ck.TC2_POINTS) - 1) // int(ck.TC2_POINTS)
        wp.launch_tiled(ck.correlate_tiles_tx_halves, dim=[n_blocks],
                        inputs=[self.pts, self.rx4, self.tx4, self.k[:f], self.gain, self.mat_h, self.common, 0,
                                self.out, count], block_dim=ck.TC_BLOCK, device=dev)
        return self.out


LENT_SETS = 3        # host buffer sets a graph lends out at a time (a caller keeping every result gets copies)


def _captured(device, enqueue):
    """`enqueue()`'s copies and launches captured as a CUDA graph on `device` (None on Warp-CPU: no graphs)."""
    if device.is_cpu:
        return None
    with wp.ScopedCapture(device=device) as capture:
        enqueue()
    return capture.graph


def _launch(graph, enqueue) -> None:
    """Replay a captured graph, or issue `enqueue()`'s launches where there is none (Warp-CPU)."""
    if graph is not None:
        wp.capture_launch(graph)
    else:
        enqueue()


class _HostSet:
    """One set of host buffers for a graph's maps (rows, n), and the launches that fill it: `compute` (the frame's
    launches that end in the maps) then the copies into the set, captured together as one CUDA graph (a launch of
    its own for the copies cost more of the host's time than the copies). Its rows are lent as reshaped views of
    one base array each: every array lent, and every view of one, refers to that base, so the set is free again
    once no base has a reference beyond the set's own (`sys.getrefcount`; the base also keeps the memory alive
    after the graph is dropped)."""

    def __init__(self, maps: wp.array, magnitude: wp.array, compute):
        dev = maps.device
        rows, n = maps.shape
        self.hosts = [wp.empty(n, dtype=wp.float32 if r == 1 else wp.float64, device="cpu", pinned=not dev.is_cpu)
                      for r in range(rows)]
        self.views = [h.numpy() for h in self.hosts]
        if any(isinstance(v.base, np.ndarray) for v in self.views):     # views of views would skip to that base
            raise RuntimeError("a host buffer's numpy view must be the base of the views made from it")
        self._own = self._references()                               # the set's own
        sources = [magnitude if r == 1 else maps[r] for r in range(rows)]

        def enqueue():
            compute()
            for host, source in zip(self.hosts, sources, strict=True):
                wp.copy(host, source)
        self._enqueue = enqueue
        self.graph = _captured(dev, enqueue)

    def _references(self) -> list[int]:
        return [sys.getrefcount(self.views[r]) for r in range(len(self.views))]

    @property
    def free(self) -> bool:
        return self._references() == self._own

    def launch(self) -> None:
        _launch(self.graph, self._enqueue)

    def lend(self, shape) -> list[np.ndarray]:
        """The rows as arrays of `shape`, views of the set's buffers, lent until none of them is alive."""
        return [v.reshape(shape) for v in self.views]


class HostMaps:
    """A graph's float64 maps (rows, n) copied back into page-locked host buffers that the caller gets as they are,
    without a copy on the host (three copies out of one staging set cost ~0.14 ms of a 301 x 301 MM-2FSK frame on
    the H100's host): row 1, the magnitude, in float32 (exact: the kernels compute it in float32), the others in
    float64. A set of buffers is lent with a frame's arrays and reused only once none of them, nor a view of one, is
    alive (`_HostSet.free`): a result the caller keeps is never overwritten. While LENT_SETS sets are lent, a
    frame's arrays are copies of a spare set's (as before). Each set launches the frame's computing launches
    (`compute`, which ends with `enqueue`) and its copies as one graph."""

    def __init__(self, maps: wp.array, compute):
        self.maps, self.compute = maps, compute
        self.magnitude = wp.empty(maps.shape[1], dtype=wp.float32, device=maps.device)
        self._sets: list[_HostSet] = []
        self._spare: _HostSet | None = None

    def enqueue(self) -> None:
        """Launch the float32 conversion of the magnitude (the last of `compute`'s launches)."""
        wp.launch(fsk_kernels.magnitude_to_float32, dim=self.magnitude.shape[0], inputs=[self.maps, self.magnitude],
                  device=self.maps.device)

    def next_set(self) -> _HostSet:
        """The set the next frame's maps go to: a free lent set (made, and captured, on first need), else the
        spare. Asked for before the frame's launches."""
        for host_set in self._sets:
            if host_set.free:
                return host_set
        if len(self._sets) < LENT_SETS:
            self._sets.append(_HostSet(self.maps, self.magnitude, self.compute))
            return self._sets[-1]
        if self._spare is None:
            self._spare = _HostSet(self.maps, self.magnitude, self.compute)
        return self._spare

    def take(self, host_set: _HostSet, shape) -> list[np.ndarray]:
        """The rows of `host_set` (after the device finished its launch), each of `shape`: lent, or copies of the
        spare's."""
        if host_set is self._spare:
            return [v.reshape(shape).copy() for v in host_set.views]
        return host_set.lend(shape)


class MedianOffset:
    """MM-3FSK's prior offset on the device (module doc): `enqueue` launches, over a fixed number of slots (the
    first count[0] used), the median of the corrections (m) whose magnitude the filter keeps into `offset` and
    moves every used point's depth by it. Exact up to the quantisation: within width / 2^33 of np.median."""

    def __init__(self, dev, n: int, m_per_rad: float):
        self.device = dev
        # the corrections' range: float32 atan2 stays inside +-3.2 rad
        self.lo_m, self.width_m = wp.float64(-3.2 * m_per_rad), wp.float64(6.4 * m_per_rad)
        self.keys = wp.empty(n, dtype=wp.int64, device=dev)
        self.n_kept = wp.empty(1, dtype=wp.int32, device=dev)
        levels = fsk_kernels.MEDIAN_LEVELS
        self.rank = wp.empty((levels + 1, 2), dtype=wp.int32, device=dev)
        self.prefix = wp.zeros((levels + 1, 2), dtype=wp.int64, device=dev)
        self.hist = wp.empty((levels, 2, fsk_kernels.MEDIAN_BINS), dtype=wp.int32, device=dev)
        self.groups = wp.empty((levels, 2, fsk_kernels.MEDIAN_BINS // fsk_kernels.MEDIAN_GROUP), dtype=wp.int32,
                               device=dev)
        self.offset = wp.zeros(1, dtype=wp.float64, device=dev)

    @property
    def bound_m(self) -> float:
        """The largest difference from np.median's offset (m): half a quantisation step."""
        return float(self.width_m) / fsk_kernels.MEDIAN_KEYS / 2.0

    def enqueue(self, count, correction, magnitude, keep_ratio: float, peak, points) -> None:
        dev, n = self.device, self.keys.shape[0]
        self.n_kept.zero_()
        wp.launch(fsk_kernels.median_keys, dim=n, inputs=[count, correction, magnitude, keep_ratio, peak, self.lo_m,
                                                          self.width_m, self.keys, self.n_kept], device=dev)
        self.hist.zero_()
        wp.launch(fsk_kernels.median_start, dim=2, inputs=[self.n_kept, self.rank, self.prefix], device=dev)
        for level in range(fsk_kernels.MEDIAN_LEVELS):
            shift = 8 * (fsk_kernels.MEDIAN_LEVELS - 1 - level)
            wp.launch(fsk_kernels.median_histogram, dim=n, inputs=[count, self.keys, shift, level, self.prefix,
                                                                   self.hist], device=dev)
            wp.launch(fsk_kernels.median_groups, dim=self.groups.shape[1:], inputs=[level, self.hist, self.groups],
                      device=dev)
            wp.launch(fsk_kernels.median_digit, dim=(2, fsk_kernels.MEDIAN_BINS),
                      inputs=[level, self.rank, self.prefix, self.hist, self.groups], device=dev)
        wp.launch(fsk_kernels.shift_points_by_median, dim=n,
                  inputs=[count, self.n_kept, self.prefix, self.lo_m, self.width_m, points, self.offset], device=dev)


class FrameGraph:
    """The buffers and launches of one setting (module doc); `run(depth, signal)` computes a frame. `coarse`:
    MM-3FSK's coarse pair (indices into three ascending `freqs_hz`), None for MM-2FSK's two frequencies."""

    def __init__(self, buffers, depth, realsense2radar, grid, max_jump_mm, freqs_hz, tx_m, rx_m, keep_ratio,
                 coarse=None):
        dev = wp.get_device(buffers.wp_device)
        self.device, self.grid = dev, grid
        ny, nx = self.shape = grid.image_shape
        n_px = ny * nx
        height, width = depth.depth_mm.shape
        pinned = not dev.is_cpu
        self.depth_host = wp.empty((height, width), dtype=wp.uint16, device="cpu", pinned=pinned)
        self.mask_host = wp.empty((height, width) if depth.mask is not None else (1, 1), dtype=wp.uint8,
                                  device="cpu", pinned=pinned)
        self.stats_host = wp.empty(2, dtype=wp.int32, device="cpu", pinned=pinned)
        self.slot_host = wp.empty(1, dtype=wp.int32, device="cpu", pinned=pinned)
        self.roi_host = wp.empty(n_px, dtype=wp.uint8, device="cpu", pinned=pinned)
        self.roi = wp.empty(n_px, dtype=wp.uint8, device=dev)
        self.d_img = wp.empty_like(self.depth_host, device=dev)
        self.m_img = wp.empty_like(self.mask_host, device=dev)
        self.zbuf = wp.empty(n_px, dtype=wp.float64, device=dev)
        self.filled = wp.empty(n_px, dtype=wp.float64, device=dev)
        self.stats = wp.empty(2 + 4 * ny + 2 * nx, dtype=wp.int32, device=dev)
        self.slot = wp.empty(1, dtype=wp.int32, device=dev)
        self.peak = wp.empty(1, dtype=wp.float32, device=dev)
        self.shards = wp.empty(PEAK_SHARDS, dtype=wp.float32, device=dev)
        self.points = wp.zeros(n_px, dtype=wp.vec3d, device=dev)          # unused slots: finite points
        self.pixel = wp.zeros(n_px, dtype=wp.int32, device=dev)
        self.maps = wp.empty((3, n_px), dtype=wp.float64, device=dev)
        self.maps_back = HostMaps(self.maps, self._enqueue_frame)
        self.coarse = None if coarse is None else list(coarse)
        pair_hz = freqs_hz if coarse is None else freqs_hz[self.coarse]
        self.correlator = GraphCorrelator(dev, n_px, pair_hz, tx_m, rx_m)
        if coarse is not None:
            self.fine_correlator = GraphCorrelator(dev, n_px, freqs_hz, tx_m, rx_m)
            self.correction = wp.empty(n_px, dtype=wp.float64, device=dev)
            self.coarse_magnitude = wp.empty(n_px, dtype=wp.float32, device=dev)
            offsets_hz = freqs_hz - freqs_hz[-1]
            centred_hz = offsets_hz - offsets_hz.mean()
            self.centred = wp.vec3d(*(centred_hz / (centred_hz @ centred_hz)))
        self.offset_host = wp.zeros(1, dtype=wp.float64, device="cpu", pinned=pinned)
        # numpy views of the staging buffers, made once (a frame only copies into / out of them)
        self.roi_view, self.depth_view, self.mask_view, self.stats_view, self.slot_view, self.offset_view = (
            a.numpy() for a in (self.roi_host, self.depth_host, self.mask_host, self.stats_host, self.slot_host,
                                self.offset_host))
        k = depth.intrinsics
        self.cam = prior_kernels.vec9d(k.fx, k.fy, k.cx, k.cy, depth.depth_scale_m * 1000.0, *pixel_scale(grid))
        self.xf = wp.mat44d(*np.asarray(realsense2radar, dtype=np.float64).ravel())
        self.max_jump = wp.float64(-1.0 if max_jump_mm is None else max_jump_mm)
        self.use_mask = int(depth.mask is not None)
        self.x_m, self.y_m = grid_arrays(buffers, grid)
        self.m_per_rad = float(C_M_PER_S / (4.0 * np.pi * (pair_hz[1] - pair_hz[0])))
        if coarse is not None:
            self.median = MedianOffset(dev, n_px, self.m_per_rad)
        self.keep_ratio = float(keep_ratio)
        self._roi_from = (None, False)      # (weak reference to the read-only mask staged, whether all ones are)
        # the samples' correlator whose staged samples are checked for NaN/Inf (MM-3FSK's fine one holds all three)
        self.checked = self.correlator if coarse is None else self.fine_correlator
        self.prior_graph = _captured(dev, self._enqueue_prior)

    def _roi_staged(self, roi_pixels: np.ndarray | None) -> bool:
        """Whether roi_host already holds this ROI: all ones, or this very read-only mask (the API's cached ROI, the
        same array on every frame of a setting)."""
        ref, all_ones = self._roi_from
        return all_ones if roi_pixels is None else (ref is not None and ref() is roi_pixels)

    def _enqueue_prior(self) -> None:
        """A frame's prior, in stream order (captured once on CUDA; issued per frame on Warp-CPU): the depth image,
        mask and ROI copied in, rasterised, filled and its covered pixels compacted into slots."""
        dev = self.device
        ny, nx = self.shape
        n_px = ny * nx
        height, width = self.d_img.shape
        wp.copy(self.d_img, self.depth_host)
        wp.copy(self.m_img, self.mask_host)
        wp.copy(self.roi, self.roi_host)
        self.slot.zero_()
        wp.launch(prior_kernels.clear_zbuffer, dim=n_px, inputs=[ny, self.zbuf, self.stats], device=dev)
        wp.launch(prior_kernels.raster_camera_quads, dim=(height - 1) * (width - 1),
                  inputs=[self.d_img, self.m_img, self.use_mask, self.cam, self.xf, self.max_jump, ny, nx,
                          self.zbuf], device=dev)
        wp.launch(prior_kernels.covered_spans, dim=n_px, inputs=[ny, nx, self.zbuf, self.stats], device=dev)
        wp.launch(prior_kernels.scanline_fill, dim=n_px, inputs=[ny, nx, self.zbuf, self.stats, self.filled],
                  device=dev)
        wp.launch(fsk_kernels.compact_covered_pixels, dim=n_px,
                  inputs=[nx, self.filled, self.x_m, self.y_m, self.slot, self.points, self.pixel, self.maps, 1,
                          self.roi], device=dev)

    def _enqueue_frame(self) -> None:
        """The rest of a frame after its prior: the staged samples copied in (and checked), the tables, the
        correlation at the prior, depth and filter, and the small results copied out."""
        dev = self.device
        ny, nx = self.shape
        n_px = ny * nx
        self.correlator.enqueue_tables(check=self.coarse is None)
        if self.coarse is not None:           # the fine pass's samples and tables (on CUDA built here, not on the host)
            self.fine_correlator.enqueue_tables(check=True)
        self.shards.zero_()
        ph = self.correlator.enqueue(self.points, self.slot)
        if self.coarse is None:
            wp.launch(fsk_kernels.depth_at_prior_counted, dim=n_px,
                      inputs=[ph, self.pixel, self.slot, self.m_per_rad, self.maps, self.shards], device=dev)
        else:
            self._enqueue_mm3fsk(ph)
        reduce_peak(self.shards, self.peak, dev)
        wp.launch(fsk_kernels.magnitude_filter_counted, dim=n_px,
                  inputs=[self.pixel, self.slot, self.keep_ratio, self.peak, self.maps], device=dev)
        self.maps_back.enqueue()
        wp.copy(self.stats_host, self.stats, count=2)
        wp.copy(self.slot_host, self.slot)
        if self.coarse is not None:
            wp.copy(self.offset_host, self.median.offset)

    def _enqueue_mm3fsk(self, ph: wp.array) -> None:
        """MM-3FSK after the coarse pair's correlation `ph` at the prior: corrections, their median over the kept
        pixels, every point moved by it, the three frequencies there and the slope depth (into maps, shards)."""
        dev, n_px = self.device, self.points.shape[0]
        wp.launch(fsk_kernels.coarse_correction_counted, dim=n_px,
                  inputs=[ph, self.slot, self.m_per_rad, self.correction, self.coarse_magnitude, self.shards],
                  device=dev)
        reduce_peak(self.shards, self.peak, dev)
        self.shards.zero_()
        self.median.enqueue(self.slot, self.correction, self.coarse_magnitude, self.keep_ratio, self.peak,
                            self.points)
        fine = self.fine_correlator.enqueue(self.points, self.slot)
        wp.launch(fsk_kernels.slope_depth_counted, dim=n_px,
                  inputs=[fine, self.pixel, self.slot, self.centred, float(C_M_PER_S / (4.0 * np.pi)), self.points,
                          self.maps, self.shards], device=dev)

    def run(self, depth, signal: np.ndarray | FrameSamples, roi_pixels: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
        """(depth_m, magnitude (float32), prior_m) (ny, nx) NaN where none, the prior's covered pixels and those
        correlated (inside `roi_pixels` (ny, nx) bool, None = all) of a new frame: its depth frame (the setting's
        size) and samples (n_rx, n_tx, F) at the setting's frequencies (a FrameSamples is gathered from its frame
        while the device builds the prior, and marked `checked`). NaN or Inf samples raise NonFiniteSignal. With a
        coarse pair, `offset_m` then holds the frame's prior offset (m). The maps are lent (`HostMaps`)."""
        out = self.maps_back.next_set()
        if not self._roi_staged(roi_pixels):
            np.copyto(self.roi_view, 1 if roi_pixels is None else roi_pixels.ravel(), casting="unsafe")
            self._roi_from = (None if roi_pixels is None or roi_pixels.flags.writeable
                              else weakref.ref(roi_pixels), roi_pixels is None)
        np.copyto(self.depth_view, depth.depth_mm, casting="unsafe")
        if self.use_mask:                                       # a bool mask's bytes are the 0/1 staged: a memcpy
            mask = depth.mask
            np.copyto(self.mask_view, mask.view(np.uint8) if mask.dtype == np.bool_ else mask, casting="unsafe")
        _launch(self.prior_graph, self._enqueue_prior)         # the prior runs while the host gathers the samples
        if self.coarse is None:
            self.correlator.load(signal)
        else:                                 # the pair from the three staged ones (not from the frame again)
            self.fine_correlator.load(signal)
            self.correlator.load(self.fine_correlator.raw_view, self.coarse)
        out.launch()                          # the rest of the frame and the copies into `out`
        wp.synchronize_device(self.device)
        if self.checked.nonfinite_staged():
            raise NonFiniteSignal("the radar frame has NaN or Inf samples")
        if isinstance(signal, FrameSamples):
            signal.checked = True
        depth_m, magnitude, prior_m = self.maps_back.take(out, self.shape)
        n_covered, n_filled = (int(v) for v in self.stats_view)
        return depth_m, magnitude, prior_m, n_covered + n_filled, int(self.slot_view[0])

    @property
    def offset_m(self) -> float:
        """MM-3FSK's prior offset of the last frame run (m): the median coarse correction (0 if none kept)."""
        return float(self.offset_view[0])


def frame_graph(buffers, depth, realsense2radar, grid, max_jump_mm, freqs_hz, tx_m, rx_m, keep_ratio,
                coarse=None) -> FrameGraph:
    """The FrameGraph of this setting (`coarse`: MM-3FSK's pair, None for MM-2FSK), built (and on CUDA captured)
    on first use."""
    freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
    key = graph_key(depth, realsense2radar, grid, max_jump_mm, freqs_hz, tx_m, rx_m, keep_ratio, buffers.wp_device,
                    coarse)
    if key not in _GRAPHS:
        _GRAPHS[key] = FrameGraph(buffers, depth, realsense2radar, grid, max_jump_mm, freqs_hz, tx_m, rx_m,
                                  keep_ratio, coarse)
        while len(_GRAPHS) > GRAPHS_KEPT:
            _GRAPHS.pop(next(iter(_GRAPHS)))
    return _GRAPHS[key]


class FskGraph:
    """2FSK or 3FSK over a fixed pixel list as one CUDA graph (`warp_backend.fsk.two_pass` / `three_fsk`'s launches
    on fixed buffers): the pair's (2FSK: both frequencies; 3FSK: the coarse pair) pass 1 at the scalar prior,
    the strongest pixel, the refocused pass 2, then 2FSK's pair depth or 3FSK's coarse step, third correlation and
    slope, and the filter; `run(signal)` -> (maps: depth, magnitude (float32)[, coarse depth], each (ny, nx); (z1_m,
    reference pixel))."""

    def __init__(self, buffers, grid, flat_pixels: np.ndarray, freqs_hz, pair: list[int], three: bool, tx_m, rx_m,
                 prior_m: float, keep_ratio: float, first_only: bool):
        dev = wp.get_device(buffers.wp_device)
        self.device, self.shape, self.pair, self.three = dev, grid.image_shape, pair, three
        ny, nx = grid.image_shape
        n = len(flat_pixels)
        pinned = not dev.is_cpu
        rows = 3 if three else 2
        self.pixel = wp.array(flat_pixels.astype(np.int32), dtype=wp.int32, device=dev)
        self.points = wp.zeros(n, dtype=wp.vec3d, device=dev)
        self.maps = wp.empty((rows, ny * nx), dtype=wp.float64, device=dev)
        self.maps_back = HostMaps(self.maps, self._enqueue)
        self.scalars = wp.empty(2, dtype=wp.float64, device=dev)
        self.scalars_host = wp.empty(2, dtype=wp.float64, device="cpu", pinned=pinned)
        self.first_peak = wp.empty(1, dtype=wp.float32, device=dev)
        self.peak = wp.empty(1, dtype=wp.float32, device=dev)
        self.first_shards = wp.empty(PEAK_SHARDS, dtype=wp.float32, device=dev)
        self.shards = wp.empty(PEAK_SHARDS, dtype=wp.float32, device=dev)
        self.ref = wp.empty(1, dtype=wp.int32, device=dev)
        self.ref_point = wp.zeros(1, dtype=wp.vec3d, device=dev)
        self.x_m, self.y_m = grid_arrays(buffers, grid)
        self.pair_correlator = GraphCorrelator(dev, n, freqs_hz[pair], tx_m, rx_m)
        self.all_correlator = GraphCorrelator(dev, n, freqs_hz, tx_m, rx_m) if three else None
        self.m_per_rad = float(C_M_PER_S / (4.0 * np.pi * (freqs_hz[pair[1]] - freqs_hz[pair[0]])))
        offsets_hz = np.asarray(freqs_hz, dtype=np.float64) - freqs_hz[-1]
        centred_hz = offsets_hz - offsets_hz.mean()
        self.centred = wp.vec3d(*(centred_hz / (centred_hz @ centred_hz))) if three else None
        self.prior_m, self.keep_ratio, self.first_only = float(prior_m), float(keep_ratio), int(first_only)

    def _first_pass(self) -> None:
        """Clear the outputs, build the tables, pass 1 at the scalar prior and the common guess z1 (scalars; every
        point moved there)."""
        dev, n, nx = self.device, self.points.shape[0], self.shape[1]
        self.maps.fill_(float("nan"))
        self.first_shards.zero_()
        self.shards.zero_()
        self.ref.fill_(2147483647)
        self.pair_correlator.enqueue_tables(check=not self.three)
        if self.three:
            self.all_correlator.enqueue_tables(check=True)
        wp.launch(fsk_kernels.points_at_depth, dim=n, inputs=[self.pixel, nx, self.x_m, self.y_m, self.prior_m,
                                                              self.points], device=dev)
        # pass 1 needs |c1| everywhere but c2 only at the strongest pixel: the first frequency over every point, then
        # the pair at that one point (each point and frequency is summed on its own: the values are the full pass's)
        ph = self.pair_correlator.enqueue(self.points, n_freqs=1)
        wp.launch(fsk_kernels.first_magnitude_peak, dim=n, inputs=[ph, self.first_shards], device=dev)
        reduce_peak(self.first_shards, self.first_peak, dev)
        wp.launch(fsk_kernels.first_argmax, dim=n, inputs=[ph, self.first_peak, self.ref], device=dev)
        wp.launch(fsk_kernels.reference_point, dim=1, inputs=[self.ref, self.points, self.ref_point], device=dev)
        ph = self.pair_correlator.enqueue(self.ref_point)
        wp.launch(fsk_kernels.refocus_points_from_first, dim=n,
                  inputs=[ph, self.ref, self.prior_m, self.m_per_rad, self.points, self.scalars], device=dev)

    def _enqueue(self) -> None:
        dev, n = self.device, self.points.shape[0]
        self._first_pass()
        ph = self.pair_correlator.enqueue(self.points)
        if self.three:
            wp.launch(fsk_kernels.coarse_points, dim=n, inputs=[ph, self.pixel, self.m_per_rad, self.points,
                                                                self.maps], device=dev)
            ph = self.all_correlator.enqueue(self.points)
            wp.launch(fsk_kernels.slope_depth, dim=n,
                      inputs=[ph, self.pixel, self.centred, float(C_M_PER_S / (4.0 * np.pi)), self.points, self.maps,
                              self.shards], device=dev)
        else:
            wp.launch(fsk_kernels.pair_depth, dim=n, inputs=[ph, self.pixel, self.m_per_rad, self.first_only,
                                                             self.points, self.maps, self.shards], device=dev)
        reduce_peak(self.shards, self.peak, dev)
        wp.launch(fsk_kernels.magnitude_filter, dim=n, inputs=[self.pixel, self.keep_ratio, self.peak, self.maps],
                  device=dev)
        self.maps_back.enqueue()
        wp.copy(self.scalars_host, self.scalars)

    def run(self, signal: np.ndarray | FrameSamples) -> tuple[list[np.ndarray], tuple[float, int]]:
        """Maps (depth, magnitude[, coarse depth]) (lent: `HostMaps`) and (z1_m, reference pixel) of a frame's
        samples (n_rx, n_tx, F) (a FrameSamples is gathered from its frame and marked `checked`); NaN or Inf samples
        raise NonFiniteSignal."""
        out = self.maps_back.next_set()
        if self.three:                        # the pair from the three staged ones (not from the frame again)
            self.all_correlator.load(signal)
            self.pair_correlator.load(self.all_correlator.raw_view, self.pair)
        else:
            self.pair_correlator.load(signal, None if self.pair == list(range(signal.shape[2])) else self.pair)
        out.launch()                          # the whole frame and the copies into `out`
        wp.synchronize_device(self.device)
        if (self.all_correlator if self.three else self.pair_correlator).nonfinite_staged():
            raise NonFiniteSignal("the radar frame has NaN or Inf samples")
        if isinstance(signal, FrameSamples):
            signal.checked = True
        z1_m, ref = self.scalars_host.numpy()
        return self.maps_back.take(out, self.shape), (float(z1_m), int(ref))


class KeptFskGraph(FskGraph):
    """An FskGraph with the `fsk_keep` skip (methods.skips.keep_skip.run_where_kept, the same rule): pass 1 over every
    ROI pixel as before, then pass 2 (3FSK: coarse pass 2 and the fine pass) on the ROI's pixel lattice, the lattice
    pixels within threshold + margin_db of the lattice maximum marked, and pass 2 again only on the other ROI pixels
    within `radius_px` (in x and in y) of a marked one, compacted on the device; the filter's maximum is taken over
    both. `run` also returns the pixels evaluated."""

    def __init__(self, buffers, grid, pixels: np.ndarray, freqs_hz, pair, three, tx_m, rx_m, prior_m, keep_ratio,
                 first_only, step_px: int, radius_px: int, margin_db: float, threshold_db: float):
        from methods.skips.roi import lattice
        dev = wp.get_device(buffers.wp_device)
        on_lattice = lattice(pixels, step_px)
        n_px = pixels.size
        self.lattice_pixel = wp.array(np.flatnonzero(on_lattice).astype(np.int32), dtype=wp.int32, device=dev)
        self.lattice_points = wp.zeros(self.lattice_pixel.shape[0], dtype=wp.vec3d, device=dev)
        self.on_lattice = wp.array(on_lattice.ravel().astype(np.uint8), dtype=wp.uint8, device=dev)
        self.roi = wp.array(pixels.ravel().astype(np.uint8), dtype=wp.uint8, device=dev)
        self.marked = wp.empty(n_px, dtype=wp.uint8, device=dev)
        self.rest_pixel = wp.zeros(int(pixels.sum()), dtype=wp.int32, device=dev)
        self.rest_points = wp.zeros(int(pixels.sum()), dtype=wp.vec3d, device=dev)
        self.rest_count = wp.empty(1, dtype=wp.int32, device=dev)
        self.rest_count_host = wp.empty(1, dtype=wp.int32, device="cpu", pinned=not dev.is_cpu)
        self.rest_count_view = self.rest_count_host.numpy()
        self.every_point = wp.array([2**31 - 1], dtype=wp.int32, device=dev)
        self.lattice_peak = wp.empty(1, dtype=wp.float32, device=dev)
        self.radius_px = int(radius_px)
        self.mark_ratio = float(10.0 ** (-(threshold_db + margin_db) / 20.0))
        super().__init__(buffers, grid, np.flatnonzero(pixels), freqs_hz, pair, three, tx_m, rx_m, prior_m,
                         keep_ratio, first_only)

    def _pass2(self, pixel: wp.array, points: wp.array, count: wp.array) -> None:
        """Pass 2 of the guess (3FSK: coarse step, fine pass, slope) at `points` of `pixel` (the first count[0]) into
        the maps and the peak shards."""
        dev, n = self.device, points.shape[0]
        ph = self.pair_correlator.enqueue(points, count)
        if self.three:
            wp.launch(fsk_kernels.coarse_points_counted, dim=n,
                      inputs=[ph, pixel, count, self.m_per_rad, points, self.maps], device=dev)
            ph = self.all_correlator.enqueue(points, count)
            wp.launch(fsk_kernels.slope_depth_counted, dim=n,
                      inputs=[ph, pixel, count, self.centred, float(C_M_PER_S / (4.0 * np.pi)), points, self.maps,
                              self.shards], device=dev)
        else:
            wp.launch(fsk_kernels.pair_depth_counted, dim=n,
                      inputs=[ph, pixel, count, self.m_per_rad, self.first_only, points, self.maps, self.shards],
                      device=dev)

    def _enqueue(self) -> None:
        dev, n, (ny, nx) = self.device, self.points.shape[0], self.shape
        n_lattice = self.lattice_pixel.shape[0]
        self._first_pass()
        self.marked.zero_()
        self.rest_count.zero_()
        wp.launch(fsk_kernels.points_at_guess, dim=n_lattice,
                  inputs=[self.lattice_pixel, nx, self.x_m, self.y_m, self.scalars, self.lattice_points], device=dev)
        self._pass2(self.lattice_pixel, self.lattice_points, self.every_point)
        reduce_peak(self.shards, self.lattice_peak, dev)                  # the shards hold the lattice's only
        wp.launch(fsk_kernels.mark_lattice, dim=n_lattice,
                  inputs=[self.lattice_pixel, self.maps, self.lattice_peak, self.mark_ratio, self.marked], device=dev)
        wp.launch(fsk_kernels.compact_kept_rest, dim=ny * nx,
                  inputs=[ny, nx, self.radius_px, self.roi, self.on_lattice, self.marked, self.x_m, self.y_m,
                          self.scalars, self.rest_count, self.rest_pixel, self.rest_points], device=dev)
        self._pass2(self.rest_pixel, self.rest_points, self.rest_count)
        reduce_peak(self.shards, self.peak, dev)                          # lattice and the rest
        wp.launch(fsk_kernels.magnitude_filter, dim=n_lattice,
                  inputs=[self.lattice_pixel, self.keep_ratio, self.peak, self.maps], device=dev)
        wp.launch(fsk_kernels.magnitude_filter_counted, dim=n,
                  inputs=[self.rest_pixel, self.rest_count, self.keep_ratio, self.peak, self.maps], device=dev)
        self.maps_back.enqueue()
        wp.copy(self.scalars_host, self.scalars)
        wp.copy(self.rest_count_host, self.rest_count)

    def run(self, signal: np.ndarray):
        """As `FskGraph.run`, plus the number of pixels evaluated (lattice and the rest)."""
        maps, details = super().run(signal)
        return maps, details, self.lattice_pixel.shape[0] + int(self.rest_count_view[0])


_PIXEL_KEYS: list = []      # (weak reference to a read-only pixel mask, its packed bytes), the last few


def _pixels_key(pixels: np.ndarray) -> bytes:
    """The packed bits of a pixel mask (ny, nx) bool; a read-only mask (the API's cached ROI, the same array on
    every frame of a capture) is packed once (~15 us a call on the H100's host for 301 x 301 pixels)."""
    if pixels.flags.writeable:
        return np.packbits(pixels).tobytes()
    for ref, packed in _PIXEL_KEYS:
        if ref() is pixels:
            return packed
    packed = np.packbits(pixels).tobytes()
    _PIXEL_KEYS.insert(0, (weakref.ref(pixels), packed))
    del _PIXEL_KEYS[GRAPHS_KEPT:]
    return packed


def fsk_graph(buffers, grid, pixels: np.ndarray, freqs_hz, pair: list[int], three: bool, tx_m, rx_m, prior_m: float,
              keep_ratio: float, first_only: bool = False, keep: tuple | None = None) -> FskGraph:
    """The FskGraph of this setting (pixels (ny, nx) bool, row-major order), built and captured on first use; with
    `keep` = (step_px, radius_px, margin_db, threshold_db) the KeptFskGraph."""
    key = ("fsk", str(buffers.wp_device), grid, _pixels_key(pixels), np.asarray(freqs_hz).tobytes(),
           tuple(pair), three, tx_m.tobytes(), rx_m.tobytes(), float(prior_m), float(keep_ratio), bool(first_only),
           keep)
    if key not in _GRAPHS:
        freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
        if keep is None:
            _GRAPHS[key] = FskGraph(buffers, grid, np.flatnonzero(pixels), freqs_hz, list(pair), three, tx_m, rx_m,
                                    prior_m, keep_ratio, first_only)
        else:
            _GRAPHS[key] = KeptFskGraph(buffers, grid, pixels, freqs_hz, list(pair), three, tx_m, rx_m, prior_m,
                                        keep_ratio, first_only, *keep)
        while len(_GRAPHS) > GRAPHS_KEPT:
            _GRAPHS.pop(next(iter(_GRAPHS)))
    return _GRAPHS[key]
