"""Skips and region of interest (methods.skips.settings, methods.skips.roi, methods.skips.bp_search,
methods.skips.keep_skip,
methods.backends.cpu_range): `roi=none` is today's computation bit for bit; every fast path against its float64
reference on
fresh random inputs; the coarse-to-fine condition; point targets with every skip on; agreement on a small
synthetic capture."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from precision import parabola_depth_bound_m

from bench.synth.memory import (
    ANTENNAS,
    MAROON_FREQS_HZ,
    TABLE1_FREQS_HZ,
    add_noise,
    make_capture,
    plate_points_m,
    simulate,
)
from methods import reconstruct
from methods.backends import correlate_volume
from methods.backends.cpu_range import RANGE_CPU_REL_TOL, correlate_range, path_bounds_m, range_table
from methods.bp import peak_depth_m
from methods.domain.capture import RadarGrid
from methods.fsk import correlate_pixels, mean_phasor_magnitude, two_pass_depth_m
from methods.fsk3 import slope_correction_m
from methods.ops import range_compression
from methods.ops.correlate import correlate_reference
from methods.ops.filtering import filter_depth
from methods.ops.frequencies import config_indices
from methods.skips import bp_search
from methods.skips.bp_search import SearchPlan, search_depth
from methods.skips.roi import dilate, full_roi, roi_from_mask_bb
from methods.skips.settings import ALL, NONE, SkipSettings, default_for, resolve

from devices import CUDA

GRID = RadarGrid((-0.02, -0.02, 0.27), (0.02, 0.02, 0.35), (21, 21, 81))        # 2 mm pixels, 1 mm depth steps
SCATTERERS_M = np.array([[0.004, -0.006, 0.300], [-0.010, 0.008, 0.318], [0.012, 0.010, 0.290]])


def fresh_rng(record_property) -> np.random.Generator:
    """An unseeded generator whose seed the test report records (a failure can be replayed)."""
    seed = int(np.random.SeedSequence().entropy % (2 ** 32))
    record_property("seed", seed)
    return np.random.default_rng(seed)


@pytest.fixture(scope="module")
def scene():
    """Three point scatterers with noise, the Table I frequencies, on GRID."""
    signal = add_noise(simulate(SCATTERERS_M, np.array([1.0, 0.7, 0.5]), TABLE1_FREQS_HZ), snr_db=20.0)
    return make_capture(signal, TABLE1_FREQS_HZ, GRID)


def same(a: np.ndarray, b: np.ndarray) -> None:
    np.testing.assert_array_equal(a, b)          # NaN == NaN here


# ---- roi=none is today's computation -----------------------------------------------------------------------


def test_roi_none_is_todays_bp(scene):
    rec = reconstruct(scene, "bp", "d10", roi="none")
    sig = scene.radar.signal[:, :, [0, 6]]
    volume = correlate_volume(sig, TABLE1_FREQS_HZ[[0, 6]], ANTENNAS.tx_m, ANTENNAS.rx_m, GRID.x_m, GRID.y_m[::-1],
                              GRID.z_m)
    depth_m, peak = peak_depth_m(np.abs(volume), float(GRID.z_m[0]), float(GRID.z_m[1] - GRID.z_m[0]))
    same(rec.depth_m, filter_depth(depth_m, peak))
    same(rec.magnitude, peak)


def test_roi_none_is_todays_2fsk_and_3fsk(scene):
    x_m, y_m = (a.ravel() for a in GRID.pixel_xy_m())
    timer = __import__("methods.ops.timing", fromlist=["StageTimer"]).StageTimer()
    sig2, f2 = scene.radar.signal[:, :, [5, 6]], TABLE1_FREQS_HZ[[5, 6]]
    depth_m, phasors, _ = two_pass_depth_m(sig2, f2, ANTENNAS, x_m, y_m, 0.40, "cpu", timer)
    magnitude = mean_phasor_magnitude(phasors).reshape(GRID.image_shape)
    rec = reconstruct(scene, "2fsk", "d05", roi="none")
    same(rec.depth_m, filter_depth(depth_m.reshape(GRID.image_shape), magnitude))
    same(rec.magnitude, magnitude)

    f3 = TABLE1_FREQS_HZ[[0, 5, 6]]
    coarse_m, _, _ = two_pass_depth_m(scene.radar.signal[:, :, [5, 6]], f3[1:], ANTENNAS, x_m, y_m, 0.40, "cpu", timer)
    fine = correlate_pixels(scene.radar.signal[:, :, [0, 5, 6]], f3, ANTENNAS, x_m, y_m, coarse_m, "cpu")
    depth3 = (coarse_m - slope_correction_m(fine, f3)).reshape(GRID.image_shape)
    rec3 = reconstruct(scene, "3fsk", "d05_d10", roi="none")
    same(rec3.depth_m, filter_depth(depth3, mean_phasor_magnitude(fine).reshape(GRID.image_shape)))


def test_dilate_is_the_binary_dilation_by_the_square():
    from scipy import ndimage
    rng = np.random.default_rng()
    for _ in range(20):
        mask = rng.random((int(rng.integers(1, 80)), int(rng.integers(1, 80)))) < rng.uniform(0, 0.05)
        radius = int(rng.integers(0, 7))
        square = np.ones((2 * radius + 1, 2 * radius + 1), dtype=bool)
        expected = ndimage.binary_dilation(mask, structure=square) if mask.any() else mask
        assert np.array_equal(dilate(mask, radius), expected)


def test_roi_settings():
    assert resolve("none") == NONE and resolve("all") == ALL
    assert resolve(None, "bp", 2) == default_for("bp", 2) and not default_for("bp", 128).mask_bb_depth
    assert resolve({"name": "x", "preset": "none", "bp_coarse_to_fine": True}) == SkipSettings(bp_coarse_to_fine=True)
    with pytest.raises(ValueError, match="unknown roi setting"):
        resolve({"bogus": 1})
    with pytest.raises(ValueError, match="roi must be one of"):
        resolve("most")
    assert ALL.only("fsk_keep") == dataclasses.replace(NONE, fsk_keep=True)
    # Warp devices: the dense kernels beat the host-driven searches for few frequencies (docs/measurements/gpu.md)
    assert resolve("auto", "bp", 3, True) == SkipSettings(mask_bb=True) == default_for("2fsk", 2, True)
    assert resolve("auto", "bp", 2, True) == SkipSettings(mask_bb=True, bp_dense_z_search=True)
    assert default_for("bp", 128, True).bp_coarse_to_fine and default_for("2fsk", 2, False).fsk_keep
    # the host search's local depth windows with many frequencies only (sharp profiles; formation.md section 8)
    assert default_for("bp", 128).search_local_z and not default_for("bp", 2).search_local_z
    # the vertex jump with few frequencies only (smooth profiles; formation.md section 11)
    assert default_for("bp", 2).search_vertex_jump and not default_for("bp", 128).search_vertex_jump
    # ... but where the backend keeps inside its device graph (Warp on CUDA), fsk_keep pays there too
    assert resolve("auto", "3fsk", 3, True, True) == SkipSettings(mask_bb=True, fsk_keep=True)
    assert resolve("auto", "bp", 2, True, True) == SkipSettings(mask_bb=True, bp_dense_z_search=True)
    assert SkipSettings().lattice_px(0.001) == (3, 5) and SkipSettings().lattice_px(0.006)[0] == 1   # no lattice


# ---- fast paths against float64 references -------------------------------------------------------------------


def test_range_cpu_matches_the_float64_direct_sum(record_property):
    rng = fresh_rng(record_property)
    freqs_hz = MAROON_FREQS_HZ[:32]                                    # equidistant, df = 79 MHz
    signal = (rng.standard_normal((94, 94, 32)) + 1j * rng.standard_normal((94, 94, 32))).astype(np.complex64)
    points_m = np.column_stack([rng.uniform(-0.15, 0.15, 40), rng.uniform(-0.15, 0.15, 40), rng.uniform(0.2, 0.5, 40)])
    got = correlate_range(signal, freqs_hz, ANTENNAS.tx_m, ANTENNAS.rx_m, points_m)
    ref = correlate_reference(signal, freqs_hz, ANTENNAS.tx_m, ANTENNAS.rx_m, points_m, sum_freqs=True)
    # linear interpolation at Q = 64 after the division by its mean response sinc^2: rms 9e-5 of a tone at the band
    # edge, less inside the band (methods.backends.cpu_range); BP must be within 1e-4 of the direct sum (issue 30)
    assert np.linalg.norm(got - ref) / np.linalg.norm(ref) < RANGE_CPU_REL_TOL
    assert np.abs(np.abs(got) - np.abs(ref)).max() / np.abs(ref).max() < RANGE_CPU_REL_TOL


def test_range_cpu_depth_order_only_reorders_the_work(record_property, monkeypatch):
    from methods.backends import cpu_range

    rng = fresh_rng(record_property)
    freqs_hz = MAROON_FREQS_HZ[:16]
    signal = (rng.standard_normal((94, 94, 16)) + 1j * rng.standard_normal((94, 94, 16))).astype(np.complex64)
    points_m = np.column_stack([rng.uniform(-0.1, 0.1, 300), rng.uniform(-0.1, 0.1, 300), rng.uniform(0.2, 0.4, 300)])
    table = range_table(signal, freqs_hz, *path_bounds_m(ANTENNAS.tx_m, ANTENNAS.rx_m, points_m))
    monkeypatch.setattr(cpu_range, "CHUNK_POINTS", 64)
    ordered = cpu_range.correlate_range_cpu(table, ANTENNAS.tx_m, ANTENNAS.rx_m, points_m)
    monkeypatch.setattr(cpu_range, "DEPTH_ORDER", False)
    as_given = cpu_range.correlate_range_cpu(table, ANTENNAS.tx_m, ANTENNAS.rx_m, points_m)
    np.testing.assert_allclose(ordered, as_given, rtol=0, atol=1e-6 * np.abs(as_given).max())


def test_range_table_is_the_fft_range_profile(record_property):
    rng = fresh_rng(record_property)
    freqs_hz = MAROON_FREQS_HZ[:32]
    signal = (rng.standard_normal((94, 94, 32)) + 1j * rng.standard_normal((94, 94, 32))).astype(np.complex64)
    table = range_table(signal, freqs_hz, 0.5, 0.9, deconvolve=False)
    rplan = range_compression.plan(freqs_hz, 64)
    profiles = range_compression.profiles_numpy(signal / (94 * 94), rplan)         # float64 FFT
    columns = (table.m0 + np.arange(table.n_window)) % rplan.n_samples
    window = table.values.reshape(94 * 94, table.n_window)
    assert np.abs(window - profiles[:, columns]).max() < 1e-5 * np.abs(profiles).max()
    assert path_bounds_m(ANTENNAS.tx_m, ANTENNAS.rx_m, np.array([[0.0, 0.0, 0.3]]))[0] > 0.6


# ---- the coarse-to-fine condition -------------------------------------------------------------------------------


def _gaussian_profiles(centres_m: np.ndarray, amplitudes: np.ndarray, width_m: float):
    """evaluate(points) = sum_i a_i exp(-(z - c_i)^2 / (2 w^2)) per pixel (pixel index in x): profiles whose fall
    from a peak is known, loss(d) = 20 log10(e) d^2 / (2 w^2) dB."""
    def evaluate(points_m: np.ndarray) -> np.ndarray:
        pixel = np.rint(points_m[:, 0]).astype(int)
        z = points_m[:, 2][:, None]
        return (amplitudes[pixel] * np.exp(-((z - centres_m[pixel]) ** 2) / (2 * width_m ** 2))).sum(axis=1)
    return evaluate


@pytest.mark.parametrize("step", [2, 4, 7])
def test_coarse_to_fine_finds_the_full_grids_peak_when_the_candidate_window_covers_the_loss(step, record_property):
    # Condition (methods.skips.bp_search): a profile falls from any peak by at most loss(d) dB at distance d; then with
    # windows >= loss(half a level's spacing) + loss(dz / 2) the search returns the full grid's argmax. For positive
    # sums of equal-width Gaussians loss(d) = 20 log10(e) d^2 / (2 w^2) holds (Jensen at the stationary point).
    rng = fresh_rng(record_property)
    n_px, width_m, dz_m = 400, 0.004, 0.001
    z_m = np.arange(0.25, 0.35 + 1e-9, dz_m)
    centres = rng.uniform(0.25, 0.35, (n_px, 3))
    amplitudes = rng.uniform(0.2, 1.0, (n_px, 3))
    evaluate = _gaussian_profiles(centres, amplitudes, width_m)
    x = np.arange(n_px, dtype=float)

    def loss_db(d_m):
        return 20 * np.log10(np.e) * d_m ** 2 / (2 * width_m ** 2)
    full = search_depth(evaluate, x, x * 0, z_m, SearchPlan.every_sample(n_px), threshold_db=6.0)
    curve = loss_db(np.arange(1, step + 1) * dz_m / 2)                     # loss at half of each level's spacing
    plan = SearchPlan.uniform(n_px, step, curve, margin_db=loss_db(dz_m / 2))
    fast = search_depth(evaluate, x, x * 0, z_m, plan, threshold_db=6.0)
    full_m, fast_m = (filter_depth(r.depth_m, r.max_projection, 6.0) for r in (full, fast))   # as methods.bp does
    same(np.isfinite(full_m), np.isfinite(fast_m))
    kept = np.isfinite(full_m)
    np.testing.assert_allclose(fast_m[kept], full_m[kept], rtol=0, atol=1e-12)
    np.testing.assert_allclose(fast.max_projection[kept], full.max_projection[kept], rtol=0, atol=0)
    assert fast.n_evaluated < full.n_evaluated


def test_coarse_to_fine_misses_a_peak_when_the_condition_fails():
    # a narrow tall peak (w = 1 mm) between two coarse samples of step 8 mm beside a broad lower one (w = 2 cm):
    # the narrow one falls by 69 dB at 4 mm, so a 0 dB candidate window keeps only the broad peak's samples
    z_m = np.arange(0.25, 0.35 + 1e-9, 0.001)

    def evaluate(points_m):
        z = points_m[:, 2]
        return np.exp(-((z - 0.254) ** 2) / (2 * 0.001 ** 2)) + 0.8 * np.exp(-((z - 0.298) ** 2) / (2 * 0.02 ** 2))
    x = np.zeros(1)
    full = search_depth(evaluate, x, x, z_m, SearchPlan.every_sample(1), threshold_db=None)
    miss = search_depth(evaluate, x, x, z_m, SearchPlan.uniform(1, 8, np.zeros(8)), None)
    found = search_depth(evaluate, x, x, z_m, SearchPlan.uniform(1, 8, np.full(8, 75.0)), None)
    assert full.depth_m[0] == pytest.approx(0.254, abs=1e-4)
    assert miss.depth_m[0] == pytest.approx(0.298, abs=1e-3)
    assert found.depth_m[0] == full.depth_m[0]


@pytest.mark.parametrize("n_rows", [20, 3])          # most pixels, or a few (read through a copy of their rows)
def test_candidates_match_a_plain_loop(n_rows, record_property):
    rng = fresh_rng(record_property)
    mag = np.where(rng.random((30, 40)) < 0.3, rng.random((30, 40)), -1.0).astype(np.float32)   # (pixels, depths)
    mag[rng.random(30) < 0.2] = -1.0                                   # pixels without an evaluated sample
    rows = np.sort(rng.choice(30, size=n_rows, replace=False))         # the pixels asked about
    ratio = rng.uniform(0.2, 1.0, n_rows)
    ratio[0] = 1.0                                                     # a window of 0 dB
    for local_max in (False, True):
        want = []
        for i, p in enumerate(rows):
            ev = np.flatnonzero(mag[p] >= 0)
            for j, k in enumerate(ev):
                near = mag[p, ev[max(j - 1, 0):j + 2]]
                if mag[p, k] >= mag[p].max() * ratio[i] and (not local_max or mag[p, k] >= near.max()):
                    want.append((p, k))
        got = bp_search._candidates(mag, rows, ratio, local_max)
        assert list(zip(*(a.tolist() for a in got[:2]), strict=True)) == want
        for p, k, left, right in zip(*got, strict=True):                  # the nearest evaluated on either side
            ev = np.flatnonzero(mag[p] >= 0)
            assert left == max(ev[ev < k], default=-1) and right == min(ev[ev > k], default=-1)


def _search_pair(evaluate, x, y, z_m, plan, **options):
    """(search without shortcuts, with `options`), filtered as methods.bp does."""
    full = search_depth(evaluate, x, y, z_m, plan, threshold_db=6.0)
    fast = search_depth(evaluate, x, y, z_m, plan, threshold_db=6.0, **options)
    return full, fast, [filter_depth(r.depth_m, r.max_projection, 6.0) for r in (full, fast)]


def test_local_max_candidates_find_the_same_peaks_with_fewer_samples(record_property):
    # sums of 3 Gaussians 1 cm wide (flat over a coarse step, as two-frequency profiles) and the default 1 dB margin:
    # the lobes are unimodal between the evaluated samples except where two peaks merge, so the local-maximum
    # search finds the same argmax on nearly every pixel (100 % in 8 draws; 98 % asserted) with ~2.3x fewer refined
    # samples (the full search refines every flank sample within the window)
    rng = fresh_rng(record_property)
    n_px, width_m, dz_m, step = 400, 0.010, 0.001, 7
    z_m = np.arange(0.25, 0.35 + 1e-9, dz_m)
    evaluate = _gaussian_profiles(rng.uniform(0.25, 0.35, (n_px, 3)), rng.uniform(0.2, 1.0, (n_px, 3)), width_m)
    loss_db = 20 * np.log10(np.e) * (np.arange(1, step + 1) * dz_m / 2) ** 2 / (2 * width_m ** 2)
    plan = SearchPlan.uniform(n_px, step, loss_db, margin_db=1.0)        # the default candidate_margin_db
    x = np.arange(n_px, dtype=float)
    full, fast, (full_m, fast_m) = _search_pair(evaluate, x, x * 0, z_m, plan, local_max=True)
    kept = np.isfinite(full_m) & np.isfinite(fast_m)
    assert kept.sum() >= 0.98 * np.isfinite(full_m).sum()
    assert np.mean(fast_m[kept] == full_m[kept]) >= 0.98
    coarse = n_px * len(bp_search._coarse_indices(len(z_m), step))
    assert fast.n_evaluated - coarse < 0.6 * (full.n_evaluated - coarse)


def test_pixel_lattice_inherits_the_peaks_of_laterally_smooth_profiles(record_property):
    # 24 x 24 pixels whose profiles (two Gaussian lobes) move slowly across the image: the pixels between lattice
    # pixels evaluate only the coarse samples near their corners' candidates and find the same peaks. The second
    # lobe stays >= 1.4 dB below the first (<= 0.8 + 0.046): lobes nearer a tie than the lattice's 1 dB margin, moving
    # ~1 mm a pixel, can swap between a pixel and its corners (seen on 5 % of draws up to 0.95: a measured skip, whose
    # rule on radar scenes is formation.md's)
    rng = fresh_rng(record_property)
    n_side, width_m, dz_m, step = 24, 0.004, 0.001, 7
    rows, cols = np.divmod(np.arange(n_side * n_side), n_side)
    tilt = rng.uniform(-0.001, 0.001, 2)
    centres = np.stack([0.28 + tilt[0] * rows + tilt[1] * cols, 0.32 - tilt[1] * rows + tilt[0] * cols], axis=1)
    amplitudes = np.stack([np.full(len(rows), 1.0), rng.uniform(0.3, 0.8) + 0.002 * rows], axis=1)
    evaluate = _gaussian_profiles(centres, amplitudes, width_m)
    z_m = np.arange(0.25, 0.35 + 1e-9, dz_m)
    loss_db = 20 * np.log10(np.e) * (np.arange(1, step + 1) * dz_m / 2) ** 2 / (2 * width_m ** 2)
    plan = SearchPlan.uniform(len(rows), step, loss_db, margin_db=loss_db[0])
    x = np.arange(len(rows), dtype=float)                     # the pixel index (the profiles' lookup)
    lattice = bp_search.Lattice(rows, cols, 2, margin_db=1.0)
    full, fast, (full_m, fast_m) = _search_pair(evaluate, x, x * 0, z_m, plan, lattice=lattice, local_max=True)
    same(np.isfinite(full_m), np.isfinite(fast_m))
    np.testing.assert_array_equal(fast_m, full_m)
    assert fast.n_evaluated < 0.8 * full.n_evaluated
    corners, own = lattice.corners()
    assert own.sum() == 12 * 12 + 2 * 24 - 1 and (corners[~own] >= 0).all()   # lattice + last row and column


def test_lattice_pixels_whose_peak_no_corner_holds_are_searched_again(record_property):
    # the bottle's lost pixels (formation.md 14): the magnitude is laterally smooth over the 2 mm lattice but the
    # depth of broad two-frequency lobes is not, so a pixel between lattice pixels can hold its peak where none of
    # its corners has a candidate. Here every pixel has lobe A (1 cm wide) at the lattice pixels' depth and a random
    # third of the other pixels a stronger lobe B 3-5 cm deeper, which the lattice pixels hold 20 dB down; their A
    # lies 4-26 dB below their corners', some below the filter's skip level. Without the re-check the inherited
    # samples find A (a wrong depth) or nothing (a lost pixel); with it those pixels take every coarse sample and
    # the depths are the full grid's, for about one lattice pixel's samples each
    rng = fresh_rng(record_property)
    n_side, width_m, dz_m, step = 20, 0.010, 0.001, 7
    rows, cols = np.divmod(np.arange(n_side * n_side), n_side)
    n_px = len(rows)
    inherits = ((rows % 2 + cols % 2) > 0) & (rows < n_side - 1) & (cols < n_side - 1)   # four corners in the set
    hidden = inherits & (rng.random(n_px) < 1 / 3)
    z_a = rng.uniform(0.26, 0.28)
    centres = np.stack([np.full(n_px, z_a), np.full(n_px, z_a + rng.uniform(0.03, 0.05))], axis=1)
    amplitudes = np.stack([np.where(hidden, rng.uniform(0.05, 0.6, n_px), rng.uniform(0.9, 1.0, n_px)),
                           np.where(hidden, rng.uniform(0.7, 0.95, n_px), 0.1)], axis=1)
    evaluate = _gaussian_profiles(centres, amplitudes, width_m)
    z_m = np.arange(0.25, 0.35 + 1e-9, dz_m)
    loss_db = 20 * np.log10(np.e) * (np.arange(1, step + 1) * dz_m / 2) ** 2 / (2 * width_m ** 2)
    plan = SearchPlan.uniform(n_px, step, loss_db, margin_db=1.0)
    x = np.arange(n_px, dtype=float)
    full = search_depth(evaluate, x, x * 0, z_m, SearchPlan.every_sample(n_px), 6.0)
    full_m = filter_depth(full.depth_m, full.max_projection, 6.0)
    assert np.isfinite(full_m[hidden]).all() and np.all(np.abs(full_m[hidden] - centres[hidden, 1]) < dz_m)
    found = {}
    for recheck_db in (-1.0, 2.0):
        lattice = bp_search.Lattice(rows, cols, 2, 1.0, recheck_db=recheck_db)
        found[recheck_db] = search_depth(evaluate, x, x * 0, z_m, plan, 6.0, lattice=lattice, local_max=True)
    before, after = (filter_depth(r.depth_m, r.max_projection, 6.0) for r in found.values())
    wrong = ~np.isclose(before, full_m, rtol=0, atol=1e-9, equal_nan=True)
    assert wrong[hidden].all() and not wrong[~hidden].any()                        # the shortcut alone misses B
    assert (~np.isfinite(before[hidden])).any() and np.isfinite(before[hidden]).any()   # lost and moved pixels
    same(after, full_m)
    coarse = len(bp_search._coarse_indices(len(z_m), step))
    assert found[2.0].n_evaluated - found[-1.0].n_evaluated < hidden.sum() * (coarse + 12)


def _blob_scene(rng, n_side: int = 61, pitch_m: float = 0.001):
    """An object on an n_side x n_side pixel image: a Gaussian blob of reflectivity (sigma 6 mm) at a random place
    whose depth tilts steeply across it, depth profiles Gaussian (w = 4 mm), plus a -40 dB random floor at every
    pixel and depth. Returns (evaluate, x (ny, nx), y (ny, nx), z_m, plan_of)."""
    axis = (np.arange(n_side) - n_side // 2) * pitch_m
    yy, xx = np.meshgrid(axis[::-1], axis, indexing="ij")
    x0, y0 = rng.uniform(-0.01, 0.01, 2)
    tilt = rng.uniform(0.6, 1.0, 2) * rng.choice([-1, 1], 2)               # the depth moves ~3 cm across the ROI
    z_m = np.arange(0.22, 0.42 + 1e-9, 0.001)
    floor = rng.uniform(0, 0.01, (n_side * n_side, len(z_m)))

    def evaluate(points_m):
        x, y, z = points_m.T
        amp = np.exp(-((x - x0) ** 2 + (y - y0) ** 2) / (2 * 0.006 ** 2))
        centre = 0.31 + tilt[0] * (x - x0) + tilt[1] * (y - y0)
        col = np.rint(x / pitch_m).astype(int) + n_side // 2
        row = n_side // 2 - np.rint(y / pitch_m).astype(int)
        k = np.rint((z - z_m[0]) / 0.001).astype(int)
        return amp * np.exp(-((z - centre) ** 2) / (2 * 0.004 ** 2)) + floor[row * n_side + col, k]

    curve = 20 * np.log10(np.e) * (np.arange(1, 9) * 0.001 / 2) ** 2 / (2 * 0.004 ** 2)
    return evaluate, xx, yy, z_m, lambda x, y: SearchPlan.uniform(len(x), 4, curve, margin_db=1.0)


def test_coarse_roi_in_two_passes_finds_the_same_roi_with_fewer_samples(record_property):
    # the host's coarse ROI pass first on every 2nd lattice pixel, then only next to those within the margin: the
    # same ROI (pixels, depths, local depth bounds) on a blob over a floor, with fewer samples; with a margin that
    # keeps every first-pass pixel, every lattice pixel is evaluated (the samples of the one-pass ROI)
    rng = fresh_rng(record_property)
    evaluate, xx, yy, z_m, plan_of = _blob_scene(rng)
    pixels = np.ones(xx.shape, dtype=bool)
    one, n_one = bp_search.coarse_roi(evaluate, pixels, xx, yy, z_m, plan_of, 14.0, 4, 6, 6.0, 0.01)
    two, n_two = bp_search.coarse_roi(evaluate, pixels, xx, yy, z_m, plan_of, 14.0, 4, 6, 6.0, 0.01,
                                      prepass_margin_db=3.0)
    _, n_all = bp_search.coarse_roi(evaluate, pixels, xx, yy, z_m, plan_of, 14.0, 4, 6, 6.0, 0.01,
                                    prepass_margin_db=200.0)
    same(two.pixels, one.pixels)
    assert (two.z_min_m, two.z_max_m) == (one.z_min_m, one.z_max_m)
    same(two.z_window_m[0], one.z_window_m[0])
    same(two.z_window_m[1], one.z_window_m[1])
    assert n_two < 0.7 * n_one and n_all == n_one
    assert 0 < one.pixels.sum() < 0.5 * pixels.size                          # the blob, not the floor


def test_local_depth_windows_hold_the_peaks_and_bound_the_coarse_samples(record_property):
    # the coarse ROI's per-pixel depth bounds: every ROI pixel's window lies inside the ROI's depths; the search's
    # coarse samples only inside them find the same depths as over all depths, with fewer samples; a window that
    # excludes a pixel's peak lobe makes it miss (the windows are applied)
    rng = fresh_rng(record_property)
    evaluate, xx, yy, z_m, plan_of = _blob_scene(rng)
    roi, _ = bp_search.coarse_roi(evaluate, np.ones(xx.shape, dtype=bool), xx, yy, z_m, plan_of, 14.0, 4, 6, 6.0,
                                  0.01)
    low, high = (w[roi.pixels] for w in roi.z_window_m)
    assert (low >= roi.z_min_m - 1e-12).all() and (high <= roi.z_max_m + 1e-12).all() and (high > low).all()
    z_in = z_m[roi.z_indices(z_m)]
    x, y = xx[roi.pixels], yy[roi.pixels]
    window = (np.ceil((low - z_in[0]) / 0.001 - 1e-6).astype(int),
              np.floor((high - z_in[0]) / 0.001 + 1e-6).astype(int))
    plan = plan_of(x, y)
    full = search_depth(evaluate, x, y, z_in, plan, 14.0)
    local = search_depth(evaluate, x, y, z_in, plan, 14.0, z_window=window)
    full_m, local_m = (filter_depth(r.depth_m, r.max_projection, 14.0) for r in (full, local))
    same(np.isfinite(full_m), np.isfinite(local_m))
    np.testing.assert_array_equal(local_m, full_m)
    assert local.n_evaluated < full.n_evaluated
    off = (np.zeros(len(x), dtype=int), np.full(len(x), 10))             # the first 10 mm only: far from the blob
    missed = search_depth(evaluate, x, y, z_in, plan, None, z_window=off)
    kept = np.isfinite(full_m)
    assert np.mean(np.abs(missed.depth_m[kept] - full_m[kept]) > 0.005) > 0.5


def test_search_takes_the_coarse_roi_pass_values_instead_of_evaluating_them_again(record_property):
    # the coarse ROI's values at its lattice pixels (every other coarse sample of the search there) are taken, not
    # evaluated again: the same samples, values and depths with fewer evaluations; a value planted in the pass's
    # record shows up in the search (it is read)
    rng = fresh_rng(record_property)
    evaluate, xx, yy, z_m, plan_of = _blob_scene(rng)
    roi, _ = bp_search.coarse_roi(evaluate, np.ones(xx.shape, dtype=bool), xx, yy, z_m, plan_of, 14.0, 4, 6, 6.0,
                                  0.01)
    z_in = z_m[roi.z_indices(z_m)]
    x, y, plan = xx[roi.pixels], yy[roi.pixels], plan_of(xx[roi.pixels], yy[roi.pixels])
    known = roi.evaluated.for_search(*np.nonzero(roi.pixels), z_in)
    plain = search_depth(evaluate, x, y, z_in, plan, 14.0)
    reused = search_depth(evaluate, x, y, z_in, plan, 14.0, known=known)
    same(reused.depth_m, plain.depth_m)
    same(reused.max_projection, plain.max_projection)
    n_known = int((known.take(*np.nonzero(np.ones((len(z_in), len(x)), dtype=bool))) >= 0).sum())
    assert 0 < n_known and reused.n_evaluated < plain.n_evaluated
    p = int(np.flatnonzero(known.slot >= 0)[np.argmax(plain.max_projection[known.slot >= 0])])  # strongest reused
    known.mag[known.slot[p], :] = np.where(known.mag[known.slot[p], :] >= 0, 1e3, -1.0)
    assert search_depth(evaluate, x, y, z_in, plan, 14.0, known=known).max_projection[p] == 1e3


def test_weak_lattice_corners_leave_their_pixels_unevaluated_and_the_kept_depths_unchanged(record_property):
    # an inherited pixel whose four lattice corners all lie 3 dB below the filter's skip level evaluates nothing: on
    # a blob over a floor the filtered depths stay those of the lattice search, with fewer samples; pixels that pass
    # the filter are never among the skipped ones
    rng = fresh_rng(record_property)
    evaluate, xx, yy, z_m, plan_of = _blob_scene(rng)
    rows, cols = np.nonzero(np.ones(xx.shape, dtype=bool))
    x, y, plan = xx.ravel(), yy.ravel(), plan_of(xx.ravel(), yy.ravel())
    results = {}
    for weak_db in (-1.0, 3.0, 200.0):
        lattice = bp_search.Lattice(rows, cols, 2, 1.0, weak_db)
        results[weak_db] = search_depth(evaluate, x, y, z_m, plan, 14.0, lattice=lattice, local_max=True)
    off, on, huge = (filter_depth(r.depth_m, r.max_projection, 14.0) for r in results.values())
    same(on, off)
    same(huge, off)
    assert results[3.0].n_evaluated < 0.8 * results[-1.0].n_evaluated
    assert results[200.0].n_evaluated == results[-1.0].n_evaluated                 # nothing that far below
    skipped = results[3.0].max_projection == 0
    assert skipped.any() and not np.isfinite(off[skipped]).any()


def test_vertex_jump_refines_single_lobes_at_the_parabola_vertex(record_property):
    # one Gaussian lobe per pixel (a parabola in dB): the vertex through the candidate and its neighbours is the
    # lobe's peak, so the jump (vertex +- 1, then the climb) finds the depths of the halving search with fewer
    # samples; the vertex of a parabola sampled unevenly, rounded and kept between the neighbours
    rng = fresh_rng(record_property)
    n_px, width_m, dz_m, step = 300, 0.010, 0.001, 7
    z_m = np.arange(0.25, 0.35 + 1e-9, dz_m)
    evaluate = _gaussian_profiles(rng.uniform(0.26, 0.34, (n_px, 1)), rng.uniform(0.2, 1.0, (n_px, 1)), width_m)
    loss_db = 20 * np.log10(np.e) * (np.arange(1, step + 1) * dz_m / 2) ** 2 / (2 * width_m ** 2)
    plan = SearchPlan.uniform(n_px, step, loss_db, margin_db=1.0)
    x = np.arange(n_px, dtype=float)
    halving, jump = (search_depth(evaluate, x, x * 0, z_m, plan, None, local_max=True, jump=j) for j in (False, True))
    same(jump.depth_m, halving.depth_m)
    coarse = n_px * len(bp_search._coarse_indices(len(z_m), step))
    assert jump.n_evaluated - coarse < 0.75 * (halving.n_evaluated - coarse)
    vertex_k = rng.uniform(20, 30)
    mag = np.full((1, 60), -1.0, dtype=np.float32)
    ks = np.array([int(vertex_k) - 6, int(vertex_k) + 1, int(vertex_k) + 9])
    mag[0, ks] = 10.0 ** (-0.05 * (ks - vertex_k) ** 2 / 20.0)
    pixel = np.zeros(1, dtype=int)
    assert bp_search._vertex(mag, pixel, ks[1:2], ks[:1], ks[2:])[0] == np.rint(vertex_k)
    assert bp_search._vertex(mag, pixel, ks[1:2], np.array([-1]), ks[2:])[0] == ks[1]   # a side missing


# ---- physics with every skip on ---------------------------------------------------------------------------------


def test_point_targets_reconstruct_where_they_are_with_every_skip(scene):
    for config in ("d05", "d10"):
        rec = reconstruct(scene, "bp", config, roi="all")
        none = reconstruct(scene, "bp", config, roi="none")
        same(np.isfinite(rec.depth_m), np.isfinite(none.depth_m))
        # the two paths sum the same phasors in another order (float32): bounded per pixel by the parabola's
        # sensitivity (a fixed 1e-7 m was missed by 1.4e-7 m on one pixel of another machine); d10's bounds are
        # ~1 um, d05's ~50 um (0.55 GHz apart, its depth profile is flat over a 1 mm step)
        indices = config_indices(TABLE1_FREQS_HZ, config)
        bound_m = parabola_depth_bound_m(scene.radar.signal[:, :, indices], TABLE1_FREQS_HZ[indices], GRID)[rec.valid]
        assert np.all(np.abs(rec.depth_m[rec.valid] - none.depth_m[none.valid]) <= bound_m)
        assert np.median(bound_m) < 0.1 * (GRID.z_m[1] - GRID.z_m[0])      # a shift by one depth step still fails
        row, col = np.unravel_index(np.nanargmax(rec.magnitude), GRID.image_shape)
        assert (GRID.x_m[col], GRID.y_m[::-1][row]) == pytest.approx((0.004, -0.006), abs=1.1e-3)
        assert rec.depth_m[row, col] == pytest.approx(0.300, abs=0.5e-3)
        assert rec.extra["evaluated_voxels"] < none.extra["evaluated_voxels"]


def test_bp_max_point_target_with_range_compression_and_search():
    target_m = np.array([0.004, 0.002, 0.311])
    grid = RadarGrid((-0.004, -0.006, 0.28), (0.012, 0.010, 0.34), (9, 9, 61))
    capture = make_capture(simulate(target_m[None], np.ones(1), MAROON_FREQS_HZ), MAROON_FREQS_HZ, grid)
    rec = reconstruct(capture, "bp", "full", roi="all")
    assert rec.extra["range_cpu"]
    row, col = np.unravel_index(np.nanargmax(rec.magnitude), grid.image_shape)
    assert (row, col) == (4, 4)
    assert rec.depth_m[row, col] == pytest.approx(target_m[2], abs=0.2e-3)


# ---- the region of interest -------------------------------------------------------------------------------------


def test_mask_bb_roi_is_inclusive_and_ignores_absent_bounds():
    roi = roi_from_mask_bb({"xmin": -0.01, "ymax": 0.0, "zmin": 0.3}, GRID)
    x_m, y_m = GRID.pixel_xy_m()
    same(roi.pixels, (x_m >= -0.01) & (y_m <= 0.0))
    assert roi.pixels[GRID.image_shape[0] // 2, 5]              # x = -0.01 exactly: inside (inclusive)
    assert (roi.z_min_m, roi.z_max_m) == (0.3, np.inf)
    assert full_roi(GRID).is_full(GRID) and not roi.is_full(GRID)


def test_mask_bb_limits_every_method(scene):
    capture = dataclasses.replace(scene, metadata=dataclasses.replace(
        scene.metadata, mask_bb_m={"xmax": 0.0, "zmin": 0.295, "zmax": 0.34}))
    x_m, _ = GRID.pixel_xy_m()
    settings = dataclasses.replace(NONE, mask_bb=True, mask_bb_depth=True)
    for method, config in (("bp", "d10"), ("2fsk", "d05"), ("3fsk", "d05_d10")):
        rec = reconstruct(capture, method, config, roi=settings)
        assert not np.isfinite(rec.depth_m[x_m > 0]).any()
        assert np.nanmin(rec.depth_m) >= 0.295 and np.nanmax(rec.depth_m) <= 0.34
        assert rec.extra["roi_px"] == int((x_m <= 0).sum())


# ---- agreement on a small synthetic capture ---------------------------------------------------------------------


def agreement(a, b) -> float:
    both = a.valid & b.valid
    return float(np.mean(np.abs(a.depth_m[both] - b.depth_m[both]) <= 1e-4))


def test_skips_agree_with_the_full_computation_on_a_synthetic_capture(synth_capture):
    from bench.maroon import reader
    capture = reader.read_capture(synth_capture("03_sphere", 30, frequency_points=16), parts=("radar",))
    for method, config in (("2fsk", "d05"), ("3fsk", "d05_d10")):
        full = reconstruct(capture, method, config, roi="none")
        fast = reconstruct(capture, method, config, roi=ALL.only("fsk_keep"))
        assert agreement(full, fast) >= 0.99 and fast.valid.sum() == pytest.approx(full.valid.sum(), rel=0.01)
        assert fast.extra["roi_px"] < 0.5 * full.valid.size
    coarse = RadarGrid((-0.06, -0.06, 0.24), (0.06, 0.06, 0.36), (61, 61, 61))        # 2 mm pixels and steps
    fine = RadarGrid((-0.03, -0.03, 0.24), (0.03, 0.03, 0.36), (61, 61, 121))         # 1 mm: the search's lattice
    for config, grid in (("d05", coarse), (None, coarse), ("d05", fine)):
        full = reconstruct(capture, "bp", config, grid=grid, roi="none")
        fast = reconstruct(capture, "bp", config, grid=grid, roi="auto")
        assert agreement(full, fast) >= 0.99 and fast.valid.sum() == pytest.approx(full.valid.sum(), rel=0.01)
        assert fast.extra["evaluated_voxels"] < full.extra["evaluated_voxels"]
        assert fast.extra["search_lattice_px"] == (2 if grid is fine else 1)


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_coarse_roi_without_the_search_is_the_box_volume_on_warp_devices(device):
    """Warp devices evaluate every depth of the coarse ROI as the dense volume over its bounding box (bp._box_depth_m):
    the same depths as the CPU's every-sample search of the same ROI (Warp-CPU's float32 kernel within 1e-5 m;
    CUDA's tensor-core kernel, fp16 operands, within the agreement rule's 0.1 mm: measured 4e-5 m)."""
    freqs_hz = MAROON_FREQS_HZ[config_indices(MAROON_FREQS_HZ, "d05")]
    points_m = plate_points_m(0.31, half_size_m=0.02)
    seed = int(np.random.default_rng().integers(1000))
    signal = add_noise(simulate(points_m, np.ones(len(points_m)), freqs_hz), 20, seed=seed)
    capture = make_capture(signal, freqs_hz, RadarGrid((-0.04, -0.04, 0.26), (0.04, 0.04, 0.36), (21, 21, 51)))
    settings = SkipSettings(mask_bb=True, coarse_roi=True)
    cpu = reconstruct(capture, "bp", None, device="cpu", roi=settings)
    box = reconstruct(capture, "bp", None, device=device, roi=settings)
    assert np.array_equal(np.isfinite(cpu.depth_m), np.isfinite(box.depth_m)) and np.isfinite(box.depth_m).any()
    assert np.nanmax(np.abs(cpu.depth_m - box.depth_m)) < (1e-4 if device == "cuda" else 1e-5)


@pytest.mark.parametrize(("n_f", "factored"), [(2, False), (17, True), (128, True)])
def test_point_target_phasor_sums_equal_the_direct_float64_sum(n_f, factored, monkeypatch):
    """The search plan's factored phasor sums (equidistant wavenumbers) against exp summed term by term: within
    1e-12 relative on random path changes (float64 roundoff of ~20 operations), any number of frequencies."""
    rng = np.random.default_rng()
    f0_hz, df_hz = rng.uniform(70e9, 75e9), rng.uniform(10e6, 100e6)
    k = 2 * np.pi * (f0_hz + df_hz * np.arange(n_f)) / 299_792_458.0
    delta_m = rng.uniform(-0.02, 0.02, (7, 94))
    direct = np.exp(1j * delta_m[:, :, None] * k[None, None]).sum(axis=1)
    products = []
    matmul = np.matmul
    monkeypatch.setattr(np, "matmul", lambda a, b: products.append(a.shape) or matmul(a, b))
    sums = bp_search._phasor_sums(delta_m, k)
    monkeypatch.undo()
    assert bool(products) == factored                                   # the path this many frequencies take
    assert sums.shape == direct.shape
    assert np.abs(sums - direct).max() <= 1e-12 * np.abs(direct).max()
    uneven = np.sort(rng.uniform(k[0], k[0] * 1.1, n_f))                   # not equidistant: the direct sum
    assert np.array_equal(bp_search._phasor_sums(delta_m, uneven),
                          np.exp(1j * delta_m[:, :, None] * uneven[None, None]).sum(axis=1))


@pytest.mark.parametrize("prior", ["none", 0.31])
def test_bp_max_first_timed_call_finds_its_search_plan_built_by_the_warm_up(prior, monkeypatch):
    """`reconstruct` builds the search plan's loss table in BP's warm-up, before the method's timer starts: a
    first BP_max call of a process (the table's cache empty) builds it there, never inside `run`; the same values."""
    from methods.bp import BP

    grid = RadarGrid((-0.004, -0.006, 0.28), (0.012, 0.010, 0.34), (5, 5, 61))
    capture = make_capture(simulate(np.array([[0.004, 0.002, 0.311]]), np.ones(1), MAROON_FREQS_HZ),
                           MAROON_FREQS_HZ, grid)
    bp_search._loss_by_radius.cache_clear()
    built_in_run = []
    run = BP.run

    def counted_run(self, *args, **kwargs):
        before = bp_search._loss_by_radius.cache_info().misses
        result = run(self, *args, **kwargs)
        built_in_run.append(bp_search._loss_by_radius.cache_info().misses - before)
        return result

    monkeypatch.setattr(BP, "run", counted_run)
    rec = reconstruct(capture, "bp", "full", prior=prior, roi="auto")
    assert built_in_run == [0]
    assert bp_search._loss_by_radius.cache_info().misses == 1          # built once, by the warm-up
    assert rec.extra["coarse_step_median"] is not None                  # the search ran (it used the plan)
    monkeypatch.setattr(BP, "warm_up", lambda *args, **kwargs: None)   # without it, `run` builds it: same depths
    bp_search._loss_by_radius.cache_clear()
    again = reconstruct(capture, "bp", "full", prior=prior, roi="auto")
    assert built_in_run == [0, 1]
    same(again.depth_m, rec.depth_m)
