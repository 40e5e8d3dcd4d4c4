"""MM-2FSK's whole new frame as one CUDA graph (`warp_backend.frame_graph`) equals the step-by-step device path
(`warp_backend.prior.realsense_prior` with the scanline fill, then `warp_backend.fsk.depth_at_prior`) on fresh
random frames: the same prior, covered count and valid pixels, depths within 1e-12 m (each slot is computed
alone, so its order in the compaction changes nothing). On Warp-CPU the same launches run without a graph."""
from __future__ import annotations

import numpy as np
import pytest

from bench.synth.memory import (
    ANTENNAS,
    CAMERA,
    MAROON_FREQS_HZ,
    plane_depth_frame,
    realsense2radar,
    simulate,
    square_grid,
)
from methods.ops.frequencies import config_indices

from devices import CUDA


def _mm2fsk_setting(device):
    """The MM-2FSK graph tests' setting: backend, fresh generator, camera transform, 61 x 61 grid, the Δ10 pair and
    the camera's pixel rows and columns."""
    from methods.backends import backend_for

    return (backend_for(device), np.random.default_rng(), realsense2radar(), square_grid(0.05, 61),
            MAROON_FREQS_HZ[config_indices(MAROON_FREQS_HZ, "d10")], np.mgrid[:CAMERA.height, :CAMERA.width])


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_frame_graph_equals_the_step_by_step_device_path(device):
    from methods.backends.warp import fsk
    from methods.backends.warp.frame_graph import frame_graph
    from methods.backends.warp.prior import realsense_prior
    from methods.ops.timing import StageTimer

    backend, rng, cam2radar, grid, freqs_hz, (rows, cols) = _mm2fsk_setting(device)
    for _ in range(2):
        z0 = rng.uniform(0.28, 0.34)
        frame = plane_depth_frame(z0, rng.uniform(-0.2, 0.2), rng.uniform(-0.2, 0.2), cam2radar,
                                  mask=(cols - 320) ** 2 + (rows - 240) ** 2 < rng.uniform(80, 200) ** 2)
        r0, c0 = rng.integers(180, 300), rng.integers(260, 380)
        frame.depth_mm[(rows - r0) ** 2 + (cols - c0) ** 2 < rng.uniform(5, 25) ** 2] = 0      # a camera hole
        points = np.column_stack([rng.uniform(-0.03, 0.03, (40, 2)), np.full(40, z0)])
        signal = simulate(points, np.exp(2j * np.pi * rng.random(40)), freqs_hz)
        keep_ratio = 10.0 ** (-14.0 / 20.0)
        step = realsense_prior(backend.buffers, frame, cam2radar, grid, fill="scanline")
        expected = fsk.depth_at_prior(backend.buffers, lambda p, signal=signal: backend.make_launch(
            signal, freqs_hz, ANTENNAS.tx_m, ANTENNAS.rx_m, points_m=p, reuse=True)(), signal, freqs_hz, grid, step,
            keep_ratio, StageTimer())
        graph = frame_graph(backend.buffers, frame, cam2radar, grid, 10.0, freqs_hz, ANTENNAS.tx_m, ANTENNAS.rx_m,
                            keep_ratio)
        depth_m, magnitude, prior_m, n_covered, n_used = graph.run(frame, signal)
        assert n_covered == n_used == step.n_covered > 100
        for got, want in zip((depth_m, magnitude, prior_m), expected, strict=False):
            assert np.array_equal(np.isfinite(got), np.isfinite(want))
            assert np.max(np.abs(got - want), where=np.isfinite(want), initial=0.0) < 1e-12


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
@pytest.mark.parametrize("freq", ["d05", "d05_d10"])
def test_fsk_graph_equals_the_step_by_step_device_path(device, freq):
    from methods.backends import backend_for
    from methods.backends.warp import fsk
    from methods.backends.warp.frame_graph import fsk_graph
    from methods.ops.timing import StageTimer

    backend = backend_for(device)
    rng = np.random.default_rng()
    grid = square_grid(0.04, 41)
    freqs_hz = MAROON_FREQS_HZ[config_indices(MAROON_FREQS_HZ, freq)]
    three = len(freqs_hz) == 3
    pixels = rng.random(grid.image_shape) < 0.8
    z0 = rng.uniform(0.33, 0.45)
    points = np.column_stack([rng.uniform(-0.03, 0.03, (40, 2)), np.full(40, z0)])
    signal = simulate(points, np.exp(2j * np.pi * rng.random(40)), freqs_hz)
    keep_ratio = 10.0 ** (-14.0 / 20.0)

    def correlator(sig, hz):
        return lambda p: backend.make_launch(sig, hz, ANTENNAS.tx_m, ANTENNAS.rx_m, points_m=p, reuse=True)()
    pair = [1, 2] if three else [0, 1]
    if three:
        coarse = np.ascontiguousarray(signal[:, :, pair])
        *expected, details = fsk.three_fsk(backend.buffers, correlator(coarse, freqs_hz[pair]),
                                           correlator(signal, freqs_hz), grid, pixels, freqs_hz, freqs_hz[pair], 0.40,
                                           keep_ratio, StageTimer())
    else:
        *expected, details = fsk.two_pass(backend.buffers, correlator(signal, freqs_hz), grid, pixels, freqs_hz, 0.40,
                                          keep_ratio, False, StageTimer())
    maps, (z1_m, ref) = fsk_graph(backend.buffers, grid, pixels, freqs_hz, pair, three, ANTENNAS.tx_m, ANTENNAS.rx_m,
                                  0.40, keep_ratio).run(signal)
    assert (ref, z1_m) == (details["reference_pixel"], pytest.approx(details["z1_m"], abs=1e-12))
    assert np.isfinite(maps[0]).sum() > 50
    for got, want in zip(maps, expected, strict=False):
        assert np.array_equal(np.isfinite(got), np.isfinite(want))
        assert np.max(np.abs(got - want), where=np.isfinite(want), initial=0.0) < 1e-12


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_frame_graph_restricts_to_the_roi_as_the_host_path_does(device):
    """A mask_bb-like region of interest: the graph correlates only the prior's pixels inside it and filters
    relative to their maximum, as MM-2FSK's host path does with the same prior image and backend."""
    from methods.backends.warp.prior import DeferredPrior
    from methods.mm2fsk import reconstruct_mm2fsk
    from methods.prior.image import HostPrior
    from methods.skips.roi import Roi

    backend, rng, cam2radar, grid, freqs_hz, (rows, cols) = _mm2fsk_setting(device)
    z0 = rng.uniform(0.28, 0.34)
    frame = plane_depth_frame(z0, 0.1, -0.1, cam2radar, mask=(cols - 320) ** 2 + (rows - 240) ** 2 < 150 ** 2)
    points = np.column_stack([rng.uniform(-0.03, 0.03, (40, 2)), np.full(40, z0)])
    signal = simulate(points, np.exp(2j * np.pi * rng.random(40)), freqs_hz)
    pixels = np.zeros(grid.image_shape, bool)
    pixels[10:45, 5:40] = True
    roi = Roi(pixels, 0.2, 0.5, ("mask_bb",))
    deferred = DeferredPrior(backend.buffers, frame, cam2radar, grid, 10.0)
    if device == "warp-cpu":            # Warp-CPU's backend builds host priors: run the graph path by hand
        from methods.backends.warp.frame_graph import frame_graph
        got_depth, got_mag, prior_m, n_covered, n_used = frame_graph(
            backend.buffers, frame, cam2radar, grid, 10.0, freqs_hz, ANTENNAS.tx_m, ANTENNAS.rx_m,
            10.0 ** (-14.0 / 20.0)).run(frame, signal, pixels)
    else:
        got = reconstruct_mm2fsk(signal, freqs_hz, ANTENNAS, grid, deferred, backend=backend, roi=roi)
        got_depth, got_mag, prior_m = got.depth_m, got.magnitude, got.extra["prior_depth_m"]
        n_used = got.extra["prior_pixels"]
    expected = reconstruct_mm2fsk(signal, freqs_hz, ANTENNAS, grid, HostPrior(prior_m, grid), backend=backend,
                                  roi=roi)
    assert n_used == expected.extra["prior_pixels"] == (np.isfinite(prior_m) & pixels).sum() > 100
    valid, reference = np.isfinite(got_depth), np.isfinite(expected.depth_m)
    assert not valid[~pixels].any() and np.mean(valid != reference) <= 0.002
    assert np.max(np.abs(got_depth - expected.depth_m)[valid & reference]) < 1e-6
    assert np.array_equal(np.isfinite(got_mag), np.isfinite(expected.magnitude))


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
@pytest.mark.parametrize("freq", ["d05", "d05_d10"])
def test_fsk_graph_with_the_keep_skip_equals_the_host_driven_skip(device, freq, monkeypatch):
    """`fsk_keep` inside the FSK graph (KeptFskGraph: lattice pass, marks, neighbourhood compacted on the device)
    against `keep_skip.run_where_kept` driven from the host on the same backend: the same pixels evaluated (fewer
    than the ROI's: a small object), the same reference pixel, the guess within 1e-7 m, depths within 1e-6 m,
    magnitudes within 1e-5 of the maximum, the same valid pixels but at the filter's edge (float32 phases: the
    tolerances of test_gpu_mm3fsk), on fresh random frames with a region of interest; on CUDA `reconstruct_2fsk` /
    `reconstruct_3fsk` take the graph."""
    from methods.backends import backend_for
    from methods.backends.warp.frame_graph import fsk_graph
    from methods.fsk import keep_rule, reconstruct_2fsk
    from methods.fsk3 import reconstruct_3fsk
    from methods.skips.roi import Roi
    from methods.skips.settings import SkipSettings

    backend = backend_for(device)
    rng = np.random.default_rng()
    grid = square_grid(0.04, 41)
    freqs_hz = MAROON_FREQS_HZ[config_indices(MAROON_FREQS_HZ, freq)]
    three = len(freqs_hz) == 3
    pixels = rng.random(grid.image_shape) < 0.9
    z0 = rng.uniform(0.33, 0.45)
    points = np.column_stack([rng.uniform(-0.008, 0.008, (12, 2)), np.full(12, z0)])
    signal = simulate(points, np.exp(2j * np.pi * rng.random(12)), freqs_hz)
    roi = Roi(pixels, -np.inf, np.inf, ("test",))
    skips = SkipSettings(fsk_keep=True)
    keep = keep_rule(skips, grid, 14.0)
    assert keep is not None and keep[0] > 1
    run = reconstruct_3fsk if three else reconstruct_2fsk
    if backend.keeps_on_device:
        via_reconstruct = run(signal, freqs_hz, ANTENNAS, grid, prior_m=0.40, backend=backend, roi=roi, skips=skips)
    monkeypatch.setattr(backend, "keeps_on_device", False)          # the host-driven skip on the same backend
    want = run(signal, freqs_hz, ANTENNAS, grid, prior_m=0.40, backend=backend, roi=roi, skips=skips)
    maps, (z1_m, ref), evaluated = fsk_graph(backend.buffers, grid, pixels, freqs_hz, [1, 2] if three else [0, 1],
                                             three, ANTENNAS.tx_m, ANTENNAS.rx_m, 0.40, 10.0 ** (-14.0 / 20.0),
                                             keep=keep).run(signal)
    assert evaluated == want.extra["roi_px"] and 0 < evaluated < pixels.sum()
    # the host takes pass 1's correction with numpy's complex64 angle, the device with float32 atan2: z1 agrees to
    # an ulp of the phase (0.04 m/rad x 2.4e-7 rad = 1e-8 m), so pass 2 runs at points that differ by that much
    assert (ref, z1_m) == (want.extra["reference_pixel"], pytest.approx(want.extra["z1_m"], abs=1e-7))
    assert np.array_equal(np.isfinite(maps[1]), np.isfinite(want.magnitude))       # the same pixels evaluated
    valid, reference = np.isfinite(maps[0]), np.isfinite(want.depth_m)
    assert valid.sum() > 10 and np.mean(valid != reference) <= 0.002                 # pixels at the filter's edge
    # 3FSK: a weak pixel's coarse angle is ill-conditioned (points 1e-8 m apart can move its coarse depth by cm,
    # measured 2-4e-5 of the maximum in its fine magnitude on the H100), so 3FSK's values compare where both keep
    # the depth; 2FSK's refocus is common to every pixel, so its magnitudes compare everywhere evaluated
    strong = (valid & reference) if three else np.isfinite(want.magnitude)
    scale = np.nanmax(want.magnitude)
    assert np.max(np.abs(maps[1] - want.magnitude)[strong]) < 1e-5 * scale
    assert np.max(np.abs(maps[0] - want.depth_m)[valid & reference]) < 1e-6
    if three:
        assert np.array_equal(np.isfinite(maps[2]), np.isfinite(want.extra["coarse_depth_m"]))
        assert np.max(np.abs(maps[2] - want.extra["coarse_depth_m"])[valid & reference]) < 1e-6
    if device == CUDA:
        assert via_reconstruct.extra["roi_px"] == evaluated
        assert np.array_equal(np.isfinite(via_reconstruct.depth_m), valid)


def _graph_and_frames(device, n_frames: int):
    """An MM-2FSK frame graph of the test setting and `n_frames` fresh (depth frame, samples) of a tilted plane."""
    from methods.backends.warp.frame_graph import frame_graph

    backend, rng, cam2radar, grid, freqs_hz, (rows, cols) = _mm2fsk_setting(device)
    frames = []
    for _ in range(n_frames):
        z0 = rng.uniform(0.28, 0.34)
        depth = plane_depth_frame(z0, rng.uniform(-0.2, 0.2), 0.0, cam2radar,
                                  mask=(cols - 320) ** 2 + (rows - 240) ** 2 < 150 ** 2)
        points = np.column_stack([rng.uniform(-0.03, 0.03, (40, 2)), np.full(40, z0)])
        frames.append((depth, simulate(points, np.exp(2j * np.pi * rng.random(40)), freqs_hz)))
    graph = frame_graph(backend.buffers, frames[0][0], cam2radar, grid, 10.0, freqs_hz, ANTENNAS.tx_m, ANTENNAS.rx_m,
                        10.0 ** (-14.0 / 20.0))
    return graph, frames


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_lent_maps_survive_later_frames_and_their_buffers_come_back_once_dropped(device):
    """The graph hands out its host buffers without copying them (`HostMaps`): maps the caller keeps (or only a view
    of) are never overwritten by later frames, even after the graph itself is dropped; once dropped, a set is lent
    again; with every set held, the maps are copies."""
    import gc

    from methods.backends.warp import frame_graph as fg

    graph, frames = _graph_and_frames(device, fg.LENT_SETS + 3)
    first = graph.run(*frames[0])[:3]
    kept = [m.copy() for m in first]
    view = first[0][5:-5:2]                          # only a view of the first depth map stays alive
    kept_view = view.copy()
    address = first[0].__array_interface__["data"][0]
    assert not first[0].flags.owndata and np.isfinite(first[0]).sum() > 100
    later = [graph.run(*frame)[:3] for frame in frames[1:fg.LENT_SETS]]
    for maps in later:                               # a set of its own each: the first maps are intact
        assert all(m.__array_interface__["data"][0] != address for m in maps)
    assert all(np.array_equal(m, k, equal_nan=True) for m, k in zip(first, kept, strict=True))
    held = later + [first]
    copies = graph.run(*frames[fg.LENT_SETS])[:3]     # every set lent: copies
    assert all(m.flags.owndata for m in copies)
    del first, held, later, copies
    assert np.array_equal(view, kept_view, equal_nan=True)
    again = graph.run(*frames[fg.LENT_SETS + 1])[0]  # a dropped set is lent again, not the view's
    assert not again.flags.owndata and again.__array_interface__["data"][0] != address
    del again
    fg._GRAPHS.clear()                               # the graph and its buffers dropped: the view keeps its memory
    del graph
    gc.collect()
    other, frames = _graph_and_frames(device, 2)
    for frame in frames:
        other.run(*frame)
    assert np.array_equal(view, kept_view, equal_nan=True)


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_the_graph_gathers_frame_samples_and_refuses_nan_ones(device):
    """A FrameSamples (the frame's samples at the pair's frequencies among others) is gathered by the graph itself:
    the same maps as from the taken array, and marked checked; a NaN or Inf sample at a used frequency raises
    NonFiniteSignal, one at an unused frequency does not."""
    from methods.domain.errors import NonFiniteSignal
    from methods.domain.samples import FrameSamples

    graph, [(depth, pair)] = _graph_and_frames(device, 1)
    frame = np.stack([pair[:, :, 0], pair[:, :, 1] * 1j, pair[:, :, 1]], axis=2)     # used: 0 and 2
    want = [m.copy() for m in graph.run(depth, pair)[:3]]
    samples = FrameSamples(frame, np.array([0, 2]))
    got = graph.run(depth, samples)[:3]
    assert samples.checked and samples.taken is None
    assert all(np.array_equal(g, w, equal_nan=True) for g, w in zip(got, want, strict=True))
    frame[7, 3, 1] = np.nan                           # an unused frequency: not looked at
    assert np.array_equal(graph.run(depth, FrameSamples(frame, np.array([0, 2])))[0], want[0], equal_nan=True)
    for bad in (np.nan, np.inf):
        frame[7, 3, 2] = bad
        samples = FrameSamples(frame, np.array([0, 2]))
        with pytest.raises(NonFiniteSignal), np.errstate(invalid="ignore"):     # (Warp-CPU's host tables)
            graph.run(depth, samples)
        assert not samples.checked


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_a_staged_roi_is_reused_only_for_the_same_read_only_mask(device):
    """The graph stages a read-only ROI mask once and reuses it for the same array; another mask, a writable one
    changed in place, or none restage it: each frame is restricted to its own ROI."""
    graph, [(depth, signal)] = _graph_and_frames(device, 1)
    shape = graph.shape
    left, right = np.zeros(shape, bool), np.zeros(shape, bool)
    left[:, : shape[1] // 2], right[:, shape[1] // 2:] = True, True
    for mask in (left, right):
        mask.flags.writeable = False
    writable = left.copy()
    whole = np.isfinite(graph.run(depth, signal)[2])
    for roi, changed in ((left, None), (left, None), (right, None), (None, None), (writable, None),
                         (writable, right), (left, None)):
        if changed is not None:
            writable[...] = changed
        depth_m, _, _, _, n_used = graph.run(depth, signal, roi)
        used = whole if roi is None else whole & roi
        assert n_used == used.sum() > 20 and not np.isfinite(depth_m[~used]).any()
