"""`WarpBackend`: the backend of the Warp devices ("cuda", "warp-cpu"), owning its device, frame cache and buffer
pool (methods.backends describes what a backend offers)."""
from __future__ import annotations

import numpy as np
import warp as wp

from methods.backends.base import Backend, check_inputs, grid_vectors
from methods.backends.warp import columns, correlation, fsk, prior, search, zsearch
from methods.backends.warp.frame_graph import frame_graph, fsk_graph
from methods.backends.warp.frames import BufferPool, FrameCache
from methods.backends.warp.prior import DeferredPrior
from methods.backends.warp.runtime import init
from methods.domain.samples import FrameSamples
from methods.ops import range_compression
from methods.ops.filtering import DEFAULT_THRESHOLD_DB
from methods.ops.timing import StageTimer
from methods.prior.image import Prior
from methods.prior.priors import DEFAULT_FILL, DEFAULT_MAX_JUMP_MM


class WarpBackend(Backend):
    """Warp kernels on one device. `name` "cuda" (the first CUDA device: tensor-core correlation, priors rasterised
    on the device) or "warp-cpu" (Warp's single-threaded CPU device: the fp32 separable kernel, host priors; the
    tests' reference for the kernels without a GPU)."""

    prefers_box_volume = True
    searches_volume_z = True
    dense_beats_search = True
    device_fsk = True

    def __init__(self, name: str):
        init()
        self.name = name
        self.device = wp.get_device("cpu" if name == "warp-cpu" else "cuda:0")
        self.frames = FrameCache(self.device.alias)
        self.buffers = BufferPool(self.device.alias)
        #: tensor cores on CUDA, fp16 operands ("tc": 1.1-2.7e-4 relative error against float64, BP d05 9.9 ms on the
        #: H100); "tc3" splits each operand into fp16 hi + lo (4e-6, the issue's 1e-4 met, BP d05 17.2 ms): the
        #: accurate option, not the default while BP d05's 10 ms target holds. Warp-CPU runs tiles with block_dim
        #: 1, where the fp32 separable kernel is faster
        self.default_kernel = "separable" if self.device.is_cpu else "tc"
        self.rasterises_prior = not self.device.is_cpu
        self.keeps_on_device = not self.device.is_cpu      # the fsk_keep skip inside the FSK graph (CUDA only)
        self.warmed: set = set()
        #: BP's coarse-to-fine search with many frequencies runs on the device (`search`); False: host-driven.
        #: On by default where it pays: CUDA (H100 BP_max frame 190 vs 380 ms); on Warp-CPU the frame's range
        #: profiles over the whole search hull, one thread, cost more than the host search saves (22 vs 13 s)
        self.device_search = not self.device.is_cpu
        self.search_profiles = search.FrameProfiles()
        #: per-term interpolation bound of the "columns" volume kernel (its accuracy knob: the rho step follows)
        self.column_term_tol = columns.TERM_TOL
        self.last_window_edges = None

    def holding_frame(self, signal):
        return self.frames.held(signal)

    def checks_samples(self, samples) -> bool:
        """Whether this backend checks `samples` (a FrameSamples or an array (n_rx, n_tx, F)) for NaN/Inf on the
        device where it stages them, raising `NonFiniteSignal`: on CUDA the frame graphs (MM-2FSK, MM-3FSK, their
        gathered complex64 samples) and the frame cache (`FrameCache.checks`: frames of >= 1 MB). The caller then
        skips its own check before the run and asks `samples_checked` after it (a method that staged them elsewhere
        was not checked)."""
        if isinstance(samples, FrameSamples):
            return not self.device.is_cpu and samples.dtype == np.complex64
        return self.frames.checks(np.asarray(samples))

    def samples_checked(self, samples) -> bool:
        """Whether these samples were checked (and found finite): by a frame graph (`FrameSamples.checked`) or by
        the last frame lookup of this very array."""
        if isinstance(samples, FrameSamples):
            return samples.checked or (samples.taken is not None and self.frames.checked(samples.taken))
        return self.frames.checked(samples)

    def make_launch(self, signal, freqs_hz, tx_m, rx_m, *, kernel: str | None = None, points_m=None, grid_m=None,
                    sum_freqs: bool = False, reuse: bool = False):
        """`correlation.make_launch` on this device (the benchmarks time the function it returns)."""
        return correlation.make_launch(self.frames, self.buffers, signal, freqs_hz, tx_m, rx_m,
                                       kernel=kernel or self.default_kernel, points_m=points_m, grid_m=grid_m,
                                       sum_freqs=sum_freqs, reuse=reuse, term_tol=self.column_term_tol)

    def correlate(self, signal, freqs_hz, tx_m, rx_m, points_m, kernel: str | None = None) -> np.ndarray:
        """complex64 (F, N); `kernel` "tc", "separable" or "direct" (None: the device's default)."""
        return self._points(signal, freqs_hz, tx_m, rx_m, points_m, kernel, sum_freqs=False)

    def correlate_summed(self, signal, freqs_hz, tx_m, rx_m, points_m, kernel: str | None = None) -> np.ndarray:
        """complex64 (N,), the frequency sum taken on the device; many equidistant frequencies (BP_max's search)
        gather from range-compressed profiles as the volume does (`kernel` None), so a point and the voxel at the
        same position get the same value."""
        if kernel is None:
            kernel = self._volume_kernel(np.asarray(freqs_hz, dtype=np.float64), "auto")
        return self._points(signal, freqs_hz, tx_m, rx_m, points_m, kernel, sum_freqs=True)[0]

    def summed_at_points(self, signal, freqs_hz, tx_m, rx_m):
        """As `correlate_summed` (default kernel) for many calls on one frame: the frame's inputs are looked up once
        (the cache's exact comparison of a 128-frequency frame costs ~3 ms per call on the H100's host)."""
        signal, freqs_hz, tx_m, rx_m = check_inputs(signal, freqs_hz, tx_m, rx_m)
        inputs = self.frames.inputs(signal, freqs_hz, tx_m, rx_m)
        kernel = self._volume_kernel(freqs_hz, "auto")

        def run(points_m):
            points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
            launch = correlation.make_launch(self.frames, self.buffers, signal, freqs_hz, tx_m, rx_m, kernel=kernel,
                                             points_m=points_m, sum_freqs=True, reuse=True, inputs=inputs)
            return correlation.to_complex(launch())[0]
        return run

    def search_depth(self, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, plan, threshold_db, z_edges_are_grid_edges,
                     hull_m=None):
        """On the device end to end with many equidistant frequencies (range-compressed values, as
        `summed_at_points` gives them); None (the host-driven search) otherwise or when `device_search` is off."""
        inputs = self._search_inputs(signal, freqs_hz, tx_m, rx_m, z_m)
        if inputs is None:
            return None
        return search.search_depth(inputs, self.buffers, self.search_profiles, np.asarray(x_m, dtype=np.float64),
                                   np.asarray(y_m, dtype=np.float64), np.asarray(z_m, dtype=np.float64), plan,
                                   threshold_db, z_edges_are_grid_edges, _hull(x_m, y_m, z_m, hull_m))

    def coarse_peaks(self, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, step, hull_m=None):
        """As `search_depth`, for the coarse ROI's pass: (coarse maximum, its first depth index, samples) or None."""
        inputs = self._search_inputs(signal, freqs_hz, tx_m, rx_m, z_m)
        if inputs is None:
            return None
        return search.coarse_peaks(inputs, self.buffers, self.search_profiles, np.asarray(x_m, dtype=np.float64),
                                   np.asarray(y_m, dtype=np.float64), np.asarray(z_m, dtype=np.float64), step,
                                   _hull(x_m, y_m, z_m, hull_m))

    def _search_inputs(self, signal, freqs_hz, tx_m, rx_m, z_m):
        """The frame's inputs where the device search applies (many equidistant frequencies, `device_search`)."""
        signal, freqs_hz, tx_m, rx_m = check_inputs(signal, freqs_hz, tx_m, rx_m)
        if not self.device_search or self._volume_kernel(freqs_hz, "auto") != "range" or len(z_m) < 2:
            return None
        return self.frames.inputs(signal, freqs_hz, tx_m, rx_m)

    def _points(self, signal, freqs_hz, tx_m, rx_m, points_m, kernel, sum_freqs):
        signal, freqs_hz, tx_m, rx_m = check_inputs(signal, freqs_hz, tx_m, rx_m)
        points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
        run = self.make_launch(signal, freqs_hz, tx_m, rx_m, kernel=kernel, points_m=points_m, sum_freqs=sum_freqs,
                               reuse=True)
        return correlation.to_complex(run())

    def _volume_kernel(self, freqs_hz, method: str) -> str:
        if method not in ("auto", "direct", "range", "columns"):
            raise ValueError(f"method must be 'auto', 'direct', 'range' or 'columns', got {method!r}")
        if method == "auto":
            method = "range" if range_compression.worth_it(freqs_hz) else "direct"
        return method if method in ("range", "columns") else self.default_kernel

    def volume(self, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, method: str = "auto", kernel: str | None = None
               ) -> np.ndarray:
        """As `Backend.volume`; `kernel` names a Warp kernel directly (tests, benchmarks)."""
        signal, freqs_hz, tx_m, rx_m = check_inputs(signal, freqs_hz, tx_m, rx_m)
        x_m, y_m, z_m = grid_vectors(x_m, y_m, z_m)
        kernel = kernel or self._volume_kernel(freqs_hz, method)
        run = self.make_launch(signal, freqs_hz, tx_m, rx_m, kernel=kernel, grid_m=(x_m, y_m, z_m), reuse=True)
        return correlation.to_complex(run())[0].reshape(len(z_m), len(y_m), len(x_m))

    def volume_peak(self, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, dz_m: float, timer=None,
                    method: str = "auto", z_step: int = 1, z_candidates: int = 3, z_keep_ratio: float = 0.0):
        """As `Backend.volume_peak`; `method` as in `volume` ("columns": the accurate column-separable sum);
        `z_step` > 1: the coarse volume at every z_step-th depth and a window of +-z_step depths around each pixel's
        `z_candidates` largest coarse local maxima, only at pixels whose coarse maximum reaches `z_keep_ratio` times
        the image's (`zsearch`; the dense volume where z_m is shorter than
        4 z_step or the kernel takes no points). `self.last_window_edges`: that search's pixels whose maximum lay
        on an inner window edge (None after a dense volume)."""
        signal, freqs_hz, tx_m, rx_m = check_inputs(signal, freqs_hz, tx_m, rx_m)
        x_m, y_m, z_m = grid_vectors(x_m, y_m, z_m)
        kernel = self._volume_kernel(freqs_hz, method)
        self.last_window_edges = None
        if z_step > 1 and len(z_m) >= 4 * z_step and kernel in ("tc", "tc3", "separable", "direct"):
            depth_m, proj, self.last_window_edges = zsearch.volume_peak(
                self.frames, self.buffers, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, dz_m, z_step, z_candidates,
                z_keep_ratio, kernel=kernel, timer=timer)
            return depth_m, proj
        return correlation.volume_peak(self.frames, self.buffers, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, dz_m,
                                       kernel=kernel, timer=timer, term_tol=self.column_term_tol)

    def realsense_prior(self, depth, realsense2radar, grid, keep_on_device: bool = False,
                        fill: str = DEFAULT_FILL) -> Prior:
        if keep_on_device and self.rasterises_prior:
            if fill == "scanline":                 # built inside MM-2FSK's frame graph (depth_at_prior)
                return prior.DeferredPrior(self.buffers, depth, realsense2radar, grid, DEFAULT_MAX_JUMP_MM)
            return prior.realsense_prior(self.buffers, depth, realsense2radar, grid, fill=fill)
        return super().realsense_prior(depth, realsense2radar, grid, fill=fill)

    def mesh_prior(self, mesh, photogrammetry2radar, grid, keep_on_device: bool = False,
                   fill: str = DEFAULT_FILL) -> Prior:
        if keep_on_device and self.rasterises_prior:
            return prior.mesh_prior(self.buffers, mesh, photogrammetry2radar, grid, fill=fill)
        return super().mesh_prior(mesh, photogrammetry2radar, grid, fill=fill)

    def depth_at_prior(self, signal, freqs_hz, tx_m, rx_m, grid, prior: Prior,
                       threshold_db: float | None = DEFAULT_THRESHOLD_DB, timer=None, roi_pixels=None):
        if not prior.device_resident:
            raise ValueError("depth_at_prior needs a prior held on this backend's device")
        if threshold_db is not None and threshold_db < 0:
            raise ValueError(f"threshold_db is dB below the maximum and must be >= 0, got {threshold_db}")
        keep_ratio = 0.0 if threshold_db is None else float(10.0 ** (-threshold_db / 20.0))
        timer = timer or StageTimer()
        if isinstance(prior, DeferredPrior) and prior.pending and len(freqs_hz) == 2:
            freqs_hz, tx_m, rx_m = staged_inputs(signal, freqs_hz, tx_m, rx_m)
            with timer.stage("correlate"):             # the prior, correlation, depth and filter: one graph
                graph = frame_graph(self.buffers, prior.depth, prior.realsense2radar, grid, prior.max_jump_mm,
                                    freqs_hz, tx_m, rx_m, keep_ratio)
                depth_m, magnitude, prior_m, n_covered, n_used = graph.run(prior.depth, signal, roi_pixels)
            prior.resolve(prior_m, n_covered, n_used)
            return depth_m, magnitude, prior_m
        if roi_pixels is not None:
            raise ValueError("only a pending DeferredPrior's frame graph restricts pixels to a region of interest")
        signal, freqs_hz, tx_m, rx_m = check_inputs(signal, freqs_hz, tx_m, rx_m)
        if isinstance(prior, DeferredPrior):
            prior = prior.materialise()

        def correlate_points(points):
            return self.make_launch(signal, freqs_hz, tx_m, rx_m, points_m=points, reuse=True)()
        return fsk.depth_at_prior(self.buffers, correlate_points, signal, freqs_hz, grid, prior, keep_ratio, timer)

    def mm3fsk_at_prior(self, signal, freqs_hz, tx_m, rx_m, grid, prior, coarse, threshold_db, timer,
                        roi_pixels=None):
        """MM-3FSK's frame graph (prior, both correlations, median offset, depth, filter: one launch) for a RealSense
        prior not built yet; None (the host path) for any other prior."""
        if not (isinstance(prior, DeferredPrior) and prior.pending):
            return None
        freqs_hz, tx_m, rx_m = staged_inputs(signal, freqs_hz, tx_m, rx_m)
        with timer.stage("correlate"):
            graph = frame_graph(self.buffers, prior.depth, prior.realsense2radar, grid, prior.max_jump_mm, freqs_hz,
                                tx_m, rx_m, self._keep_ratio(threshold_db), coarse)
            depth_m, magnitude, prior_m, n_covered, n_used = graph.run(prior.depth, signal, roi_pixels)
        prior.resolve(prior_m, n_covered, n_used)
        return (depth_m, magnitude, prior_m), graph.offset_m

    def _point_correlator(self, signal, freqs_hz, tx_m, rx_m):
        """Function device points (n,) vec3d -> device phasors (F, n) of this frame (inputs looked up once)."""
        signal, freqs_hz, tx_m, rx_m = check_inputs(signal, freqs_hz, tx_m, rx_m)
        inputs = self.frames.inputs(signal, freqs_hz, tx_m, rx_m)
        return lambda points: correlation.make_launch(self.frames, self.buffers, signal, freqs_hz, tx_m, rx_m,
                                                      kernel=self.default_kernel, points_m=points, reuse=True,
                                                      inputs=inputs)()

    @staticmethod
    def _keep_ratio(threshold_db) -> float:
        if threshold_db is not None and threshold_db < 0:
            raise ValueError(f"threshold_db is dB below the maximum and must be >= 0, got {threshold_db}")
        return 0.0 if threshold_db is None else float(10.0 ** (-threshold_db / 20.0))

    def fsk_two_pass(self, signal, freqs_hz, tx_m, rx_m, grid, pixels, prior_m, threshold_db, filter_quantity,
                     timer, keep=None):
        freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
        if not self.device.is_cpu:                    # one CUDA graph per setting: stage 'correlate' holds it all
            freqs_hz, tx_m, rx_m = staged_inputs(signal, freqs_hz, tx_m, rx_m)
            with timer.stage("correlate"):
                maps, (z1_m, ref), *evaluated = fsk_graph(
                    self.buffers, grid, pixels, freqs_hz, [0, 1], False, tx_m, rx_m, prior_m,
                    self._keep_ratio(threshold_db), filter_quantity == "first", keep).run(signal)
            return maps[0], maps[1], {"reference_pixel": ref, "z1_m": z1_m, **_evaluated(evaluated)}
        if keep is not None:
            raise ValueError("the fsk_keep skip runs on the device only on CUDA (keeps_on_device)")
        return fsk.two_pass(self.buffers, self._point_correlator(signal, freqs_hz, tx_m, rx_m), grid, pixels,
                            freqs_hz, prior_m, self._keep_ratio(threshold_db), filter_quantity == "first", timer)

    def fsk_three(self, signal, freqs_hz, tx_m, rx_m, grid, pixels, coarse, prior_m, threshold_db, timer,
                  keep=None):
        freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
        if not self.device.is_cpu:
            freqs_hz, tx_m, rx_m = staged_inputs(signal, freqs_hz, tx_m, rx_m)
            with timer.stage("correlate"):
                maps, (z1_m, ref), *evaluated = fsk_graph(
                    self.buffers, grid, pixels, freqs_hz, list(coarse), True, tx_m, rx_m, prior_m,
                    self._keep_ratio(threshold_db), keep=keep).run(signal)
            return maps[0], maps[1], maps[2], {"reference_pixel": ref, "z1_m": z1_m, **_evaluated(evaluated)}
        if keep is not None:
            raise ValueError("the fsk_keep skip runs on the device only on CUDA (keeps_on_device)")
        signal = np.asarray(signal)
        coarse_signal = np.ascontiguousarray(signal[:, :, coarse])
        return fsk.three_fsk(self.buffers, self._point_correlator(coarse_signal, freqs_hz[coarse], tx_m, rx_m),
                             self._point_correlator(signal, freqs_hz, tx_m, rx_m), grid, pixels, freqs_hz,
                             freqs_hz[coarse], prior_m, self._keep_ratio(threshold_db), timer)

    def warm_up(self, signal, freqs_hz, tx_m, rx_m, *, volume: bool, prior: bool) -> None:
        """Compile this device's kernels on a tiny problem, once per (number of frequencies, volume, prior):
        later calls return at once (a per-call warm-up cost ~48 ms per BP_max call and 1-3 ms per other call)."""
        key = (len(freqs_hz), volume, prior)
        if key in self.warmed:
            return
        self.correlate(signal, freqs_hz, tx_m, rx_m, np.array([[0.0, 0.0, 0.3]]))
        if volume:
            self.volume(signal, freqs_hz, tx_m, rx_m, [0.0], [0.0], [0.3, 0.301])
        if prior and self.rasterises_prior:
            from methods.backends.warp.kernels import fsk as fsk_kernels
            from methods.backends.warp.kernels import prior as prior_kernels
            for module in (prior_kernels, fsk_kernels):
                wp.load_module(module=module.__name__, device=self.device)
        self.warmed.add(key)


def staged_inputs(samples, freqs_hz, tx_m, rx_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """`check_inputs`' checks and (freqs_hz, tx_m, rx_m) for samples a frame graph gathers into its own staging buffer
    (a FrameSamples is not taken into an array of its own: its shape is checked)."""
    if isinstance(samples, FrameSamples):
        samples = np.empty(samples.shape, dtype=samples.dtype)     # its shape and type (memory never touched)
    return check_inputs(samples, freqs_hz, tx_m, rx_m)[1:]


def _evaluated(rest: list) -> dict:
    """{"evaluated_px": n} from a KeptFskGraph's extra return value, {} from an FskGraph's."""
    return {"evaluated_px": int(rest[0])} if rest else {}


def _hull(x_m, y_m, z_m, hull_m) -> np.ndarray:
    """Points whose box the search's range profiles cover: `hull_m` (K, 3) where given (one build per frame for the
    coarse ROI and the search), else the corners of the searched points."""
    if hull_m is not None:
        return np.asarray(hull_m, dtype=np.float64).reshape(-1, 3)
    return np.array([[x, y, z] for x in (np.min(x_m), np.max(x_m)) for y in (np.min(y_m), np.max(y_m))
                     for z in (np.min(z_m), np.max(z_m))])
