"""Launching the correlation kernels (`correlation_kernels`) for one frame: which kernel, its inputs in their
layout, the launch shape, and the copy back. Frame inputs and work buffers come from the backend's `FrameCache`
and `BufferPool` (methods.backends.warp.frames)."""
from __future__ import annotations

from contextlib import nullcontext

import numpy as np
import warp as wp

from methods.backends.warp import columns
from methods.backends.warp.frames import C_M_PER_S, BufferPool, FrameCache, FrameInputs
from methods.backends.warp.kernels import correlation as kernels
from methods.ops import range_compression


def path_window_m(tx_m, rx_m, x_m, y_m, z_m) -> tuple[float, float]:
    """Bounds of |p - rx| + |p - tx| over the box of the grid and all pairs, metres."""
    lo_m = [np.min(x_m), np.min(y_m), np.min(z_m)]
    hi_m = [np.max(x_m), np.max(y_m), np.max(z_m)]
    return range_compression.path_bounds_m(tx_m, rx_m, lo_m, hi_m)


def range_profiles(inputs: FrameInputs, freqs_hz, box_m):
    """(function that builds the frame's range profiles over the paths the box `box_m` = (x_m, y_m, z_m) can reach,
    the gather's arguments after the points: rx, tx, k_c, carrier cycles per metre, samples per metre, m0,
    profiles). The DFT tables are uploaded once per frequency plan, the raw frame once per frame."""
    rplan = range_compression.plan(freqs_hz)
    if rplan is None:
        raise ValueError("range compression needs >= 2 distinct frequencies on an equidistant grid "
                         f"with df < c / {range_compression.MAX_PATH_M} m")
    dev = inputs.device
    n_rx, n_tx_pad = len(inputs.rx_m), len(inputs.tx_m) + inputs.n_tx_pad
    m0, n_window = range_compression.sample_window(rplan, *path_window_m(inputs.tx_m, inputs.rx_m, *box_m))
    twiddle, shift, index = inputs.range_tables(rplan)
    profiles = wp.empty((n_rx * n_tx_pad, n_window), dtype=wp.vec2h, device=dev)
    k_c = 2 * np.pi * rplan.f_carrier_hz / C_M_PER_S
    gather_args = [inputs.rx, inputs.tx_padded, wp.float32(k_c), wp.float64(2.0 * rplan.f_carrier_hz / C_M_PER_S),
                   wp.float32(rplan.samples_per_m), wp.float32(m0), profiles]

    def build():
        wp.launch(kernels.range_profiles, dim=(n_rx * n_tx_pad, n_window),
                  inputs=[inputs.raw_device, wp.float32(inputs.scale), n_tx_pad, index, twiddle, shift,
                          int(m0) % rplan.n_samples, profiles], device=dev)
    return build, gather_args


def _range_launch(inputs: FrameInputs, freqs_hz, flag, points, x, y, z, out, box_m):
    """Return a function that builds the range profiles over the paths the box `box_m` can reach
    (`range_profiles`) and gathers every voxel (flag 1) or point (flag 0)."""
    build, gather_args = range_profiles(inputs, freqs_hz, box_m)
    args = [flag, points, x, y, z] + gather_args + [out]

    def run():
        build()
        wp.launch(kernels.range_gather, dim=out.shape[1], inputs=args, block_dim=256, device=inputs.device)
        return out
    return run


def make_launch(frames: FrameCache, buffers: BufferPool, signal, freqs_hz, tx_m, rx_m, *, kernel: str,
                points_m=None, grid_m=None, sum_freqs: bool = False, reuse: bool = False,
                inputs: FrameInputs | None = None, term_tol: float = columns.TERM_TOL, count: wp.array | None = None):
    """Upload inputs once; return a function that runs `kernel` and returns the device output (rows, N) vec2f.

    kernel: "tc" (tensor cores, fp16 operands), "tc3" (tensor cores, split fp16 operands: CUDA only; close to
    fp32 operand precision at ~1.7x the time of "tc": docs/measurements/formation.md section 7), "separable"
    (fp32), "direct", "range" (frequency sum only; the
    range profiles are rebuilt on every call, as a new frame needs, over the paths the grid's or the points' box
    can reach) or "columns" (grids only: the column-separable sum of `columns` with the rho step of `term_tol`,
    tables rebuilt on every call).
    Points come from `points_m` (N, 3) or from
    `grid_m` = (x_m, y_m, z_m); with a grid the output is summed over frequencies, flat in (z, y, x) order.
    Frame inputs are cached by content; with `reuse` the output and work buffers are pre-allocated ones shared
    between calls (the API copies the output back before returning). The benchmark times the returned function.
    `inputs`: the frame's FrameInputs when the caller already holds them (no cache lookup: a search on one frame).
    `count`: (1,) int32 on the device, the points that count (the tensor-core blocks past it return at once on
    CUDA; their outputs are left unwritten); None = all.
    """
    inputs = inputs or frames.inputs(signal, freqs_hz, tx_m, rx_m)
    dev = inputs.device
    empty = wp.empty(0, dtype=wp.float64, device=dev)
    if kernel == "range" and grid_m is None:           # the profile window needs the points' box on the host
        if isinstance(points_m, wp.array):
            raise ValueError("the range kernel takes host points (their box sets the profile window)")
        box_m = tuple(np.asarray(points_m, dtype=np.float64).reshape(-1, 3).T)
    else:
        box_m = grid_m
    if grid_m is None:
        if not isinstance(points_m, wp.array):          # (a device-resident vec3d array is used as it is)
            points_m = wp.array(points_m, dtype=wp.vec3d, device=dev)
        points, x, y, z, flag = points_m, empty, empty, empty, 0
    else:
        points, flag, sum_freqs = wp.empty(0, dtype=wp.vec3d, device=dev), 1, True
        x, y, z = _grid_arrays(buffers, grid_m, dev) if reuse else _upload_grid(grid_m, dev)
    n_out = points_m.shape[0] if grid_m is None else x.shape[0] * y.shape[0] * z.shape[0]
    out_shape = (1 if sum_freqs else inputs.n_freqs, n_out)
    out = buffers.get("out", out_shape, wp.vec2f) if reuse else wp.empty(out_shape, dtype=wp.vec2f, device=dev)
    if kernel == "columns":
        if grid_m is None:
            raise ValueError("the columns kernel computes volumes: pass grid_m")
        rplan = columns.cached_plan(inputs.tx_m, inputs.freqs_hz, *grid_m, term_tol)
        if rplan is None:
            raise ValueError("the columns kernel needs transmitters on at most "
                             f"{columns.kernels.MAX_COLUMNS} columns of >= {columns.MIN_TABLE_COLUMN} elements")
        return columns.make_volume_launch(inputs, buffers, rplan, *grid_m, out)
    if kernel == "range":
        if not sum_freqs:
            raise ValueError("the range kernel gives the frequency sum only (sum_freqs=True)")
        return _range_launch(inputs, freqs_hz, flag, points, x, y, z, out, box_m)
    if kernel == "tc3" and wp.get_device(dev).is_cpu:
        raise ValueError("the split tensor-core kernel tc3 runs on CUDA only")
    if kernel in ("tc", "tc3"):
        rx4, tx4, gain, mat = inputs.tile_tables(with_mat=wp.get_device(dev).is_cpu, split=kernel == "tc3")
        if reuse:
            pts = buffers.get("pts", n_out, wp.vec4f)
            common = buffers.get("common", (inputs.n_freqs, n_out), wp.vec2f)
        else:
            pts = wp.empty(n_out, dtype=wp.vec4f, device=dev)
            common = wp.empty((inputs.n_freqs, n_out), dtype=wp.vec2f, device=dev)
        every = count if count is not None else buffers.constant(
            ("count.all", str(dev)), lambda: wp.array([2**31 - 1], dtype=wp.int32, device=dev))
        prep_args = [flag, points, x, y, z, inputs.cycles, pts, common, every]
        if not wp.get_device(dev).is_cpu:    # (tx halves need real blocks: Warp-CPU runs block_dim 1: rx product)
            tc_kernel = kernels.correlate_tiles_tx_split if kernel == "tc3" else kernels.correlate_tiles_tx_halves
            n_tile = int(kernels.TC2_POINTS)
            tc_args = [pts, rx4, tx4, inputs.k, gain, mat, common, int(sum_freqs), out, every]
        else:
            tc_kernel, n_tile = kernels.correlate_tiles_rx_product, int(kernels.TC_POINTS)
            tc_args = [pts, rx4, tx4, inputs.k, gain, mat, common, int(sum_freqs), out]
        n_blocks = (n_out + n_tile - 1) // n_tile

        def run_tc():
            wp.launch(kernels.prepare_points, dim=n_out, inputs=prep_args, device=dev)
            wp.launch_tiled(tc_kernel, dim=[n_blocks], inputs=tc_args, block_dim=kernels.TC_BLOCK, device=dev)
            return out
        return run_tc
    if kernel == "direct":
        fn, args = kernels.correlate_direct, [flag, points, x, y, z, inputs.rx, inputs.tx, inputs.k, inputs.signal]
    elif kernel == "separable":
        fn, args = kernels.correlate_separable, [flag, points, x, y, z, inputs.rx, inputs.tx_padded, inputs.k,
                                                 inputs.cycles, inputs.signal_padded]
    else:
        raise ValueError(f"unknown kernel {kernel!r} (range compression needs a grid)")
    args += [int(sum_freqs), out]

    def run():
        wp.launch(fn, dim=n_out, inputs=args, device=dev)
        return out
    return run


def _upload_grid(grid_m, dev) -> tuple[wp.array, wp.array, wp.array]:
    return tuple(wp.array(np.asarray(v, dtype=np.float64), dtype=wp.float64, device=dev) for v in grid_m)


def _grid_arrays(buffers: BufferPool, grid_m, dev) -> tuple[wp.array, wp.array, wp.array]:
    """The grid's (x, y, z) float64 device arrays, uploaded once per grid (three uploads cost ~0.1 ms of a BP
    call's host time on the H100)."""
    key = ("grid_m", str(dev)) + tuple(np.asarray(v, dtype=np.float64).tobytes() for v in grid_m)
    return buffers.constant(key, lambda: _upload_grid(grid_m, dev))


def volume_peak(frames: FrameCache, buffers: BufferPool, signal, freqs_hz, tx_m, rx_m, x_m, y_m, z_m, dz_m: float,
                *, kernel: str, timer=None,
                term_tol: float = columns.TERM_TOL) -> tuple[np.ndarray, np.ndarray]:
    """BP depth extraction on the device: the volume (as `make_launch` on the grid) stays there,
    `volume_peak_depth` reduces it over z, and only (depth, max projection), each float64 (ny, nx), come back.
    `timer` (a StageTimer) gets the stages "correlate" and "depth" (synchronised)."""
    stage = timer.stage if timer is not None else (lambda name: nullcontext())
    with stage("correlate"):
        run = make_launch(frames, buffers, signal, freqs_hz, tx_m, rx_m, kernel=kernel, grid_m=(x_m, y_m, z_m),
                          reuse=True, term_tol=term_tol)
        vol = run()
        dev = vol.device
        wp.synchronize_device(dev)
    with stage("depth"):
        n_px = len(x_m) * len(y_m)
        maps = buffers.get("peak", (2, n_px), wp.float64)
        wp.launch(kernels.volume_peak_depth, dim=n_px, inputs=[vol, len(z_m), float(z_m[0]), float(dz_m), maps],
                  device=dev)
        host = maps.numpy().reshape(2, len(y_m), len(x_m))
        if dev.is_cpu:
            host = host.copy()
    return host[0], host[1]


def to_complex(out: wp.array) -> np.ndarray:
    """Device (rows, N) vec2f -> host complex64 (rows, N): one copy back, reinterpreted without a conversion."""
    a = out.numpy()
    if out.device.is_cpu:          # a view of the (reused) Warp buffer there: copy
        a = a.copy()
    return a.view(np.complex64)[..., 0]
