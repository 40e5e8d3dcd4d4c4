"""The radar echo from frequency nodes on compact blocks (bench.synth.radar.leg_sum, frequency_nodes) against float64
sums on fresh random scenes: extended surfaces of many scatterers (the node path), the lobe and element gains, and the
bistatic rows of multipath."""
import numpy as np
import pytest

from bench.maroon.antennas import load_antenna_array
from bench.synth.radar import frequency_nodes, leg_sum, multipath
from bench.synth.radar.model import leg_gains, simulate_frame

C_M_PER_S = 299_792_458.0
FREQS_HZ = np.linspace(72e9, 82e9, 128)
# complex64 sums of ~1e3 terms and the node fit's NODE_ERROR per unit weight: ~1e-6 of the peak; 1e-5 leaves margin
# and is still ~90 dB below the generator's thermal noise (docs/measurements/synth.md)
TOLERANCE = 1e-5


@pytest.mark.parametrize("half_width_m", [0.004, 0.02, 0.05])
def test_node_fit_meets_its_bound_on_fresh_offsets(half_width_m):
    """|exp(-j 2 pi f dp / c) - L exp(-j 2 pi g dp / c)| <= NODE_ERROR for random |dp| <= W, with few nodes."""
    nodes_hz, fit = frequency_nodes.interpolator(FREQS_HZ, half_width_m)
    assert fit is not None and fit.shape == (128, len(nodes_hz)) and len(nodes_hz) <= 32
    offsets_m = np.random.default_rng(11).uniform(-half_width_m, half_width_m, 3000)
    centre_hz = 0.5 * (FREQS_HZ[0] + FREQS_HZ[-1])

    def phasors(f_hz):
        return np.exp(-2j * np.pi * np.outer(f_hz - centre_hz, offsets_m) / C_M_PER_S)

    error = np.abs(fit.astype(np.complex128) @ phasors(nodes_hz) - phasors(FREQS_HZ)).max()
    assert error <= frequency_nodes.NODE_ERROR
    assert np.abs(fit).sum(axis=1).max() <= frequency_nodes.NODE_GAIN


def test_wide_spans_and_the_direct_setting_compute_every_frequency(monkeypatch):
    nodes_hz, fit = frequency_nodes.interpolator(FREQS_HZ, 0.5)          # 1 m of path: more nodes than it saves
    assert fit is None and np.array_equal(nodes_hz, FREQS_HZ)
    monkeypatch.setattr(frequency_nodes, "MAX_NODE_SHARE", 0.0)
    assert frequency_nodes.interpolator(FREQS_HZ, 0.004)[1] is None


def test_compact_blocks_partition_the_rows_into_small_regions():
    points = np.random.default_rng(2).uniform(-0.1, 0.1, (10_000, 3))
    blocks = leg_sum.compact_blocks(points, 1000)
    assert np.array_equal(np.sort(np.concatenate(blocks)), np.arange(len(points)))
    assert all(500 <= len(b) <= 1000 for b in blocks)
    assert max(np.prod(np.ptp(points[b], axis=0)) for b in blocks) <= 0.2 ** 3 / 8   # 16 blocks, each a small box


def _antennas(step: int = 4):
    antennas = load_antenna_array(all_elements=True)
    return antennas.tx_m[::step], antennas.rx_m[1::step]


def _reference(points, amplitudes, tx_m, rx_m, normals, lobe_rad, element_exponent):
    """float64 sum over scatterers of a_k g_rx g_tx exp(-j k (d_rx + d_tx)) / (d_rx d_tx), (n_rx, n_tx, F)."""
    antennas = np.concatenate([rx_m, tx_m])
    dist = np.linalg.norm(points[:, None, :] - antennas[None], axis=2)
    legs = leg_gains(points, antennas, normals, lobe_rad, element_exponent) / dist
    phase = np.exp(-2j * np.pi * dist[..., None] * FREQS_HZ / C_M_PER_S)          # (K, E, F)
    n_rx = len(rx_m)
    rx = amplitudes[:, None, None] * legs[:, :n_rx, None] * phase[:, :n_rx]
    tx = legs[:, n_rx:, None] * phase[:, n_rx:]
    return np.einsum("krf,ktf->rtf", rx, tx)


def _uses_nodes(monkeypatch) -> list[int]:
    counts = []
    original = leg_sum.interpolator

    def spy(freqs_hz, half_width_m):
        nodes_hz, fit = original(freqs_hz, half_width_m)
        counts.append(len(nodes_hz))
        return nodes_hz, fit
    monkeypatch.setattr(leg_sum, "interpolator", spy)
    return counts


@pytest.mark.parametrize("specular", [False, True])
def test_extended_surface_matches_float64_sum(monkeypatch, specular):
    """A rough 8 x 8 cm patch of 6000 scatterers at 30-33 cm (several blocks, each from few nodes) with random
    complex amplitudes; with the quasi-specular lobe and the element pattern when `specular`."""
    rng = np.random.default_rng(7)
    n = 6000
    points = np.column_stack([rng.uniform(-0.04, 0.04, n), rng.uniform(-0.04, 0.04, n), rng.uniform(0.30, 0.33, n)])
    amplitudes = (rng.normal(size=n) + 1j * rng.normal(size=n)) * 1e-6
    normals = np.column_stack([rng.normal(0, 0.3, n), rng.normal(0, 0.3, n), -np.ones(n)])
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    lobe_rad = np.deg2rad(rng.uniform(15.0, 40.0, n))
    tx_m, rx_m = _antennas()
    options = (normals, lobe_rad, 1.0) if specular else (None, None, 0.0)
    counts = _uses_nodes(monkeypatch)
    frame = simulate_frame(points, amplitudes, tx_m, rx_m, FREQS_HZ, *options)
    reference = _reference(points, amplitudes, tx_m, rx_m, *options)
    assert len(counts) >= 3 and max(counts) < len(FREQS_HZ)                       # blocks from nodes
    assert frame.dtype == np.complex64 and frame.shape == reference.shape
    assert np.abs(frame - reference).max() < TOLERANCE * np.abs(reference).max()


def test_multipath_rows_match_float64_sum(monkeypatch):
    """Bistatic pairs (p1, p2): forward tx -> p1 -> p2 -> rx and reverse, the hop on p1's leg, the second
    surface's lobe and the pair's amplitude on p2's leg."""
    rng = np.random.default_rng(5)
    n = 3000
    first = np.column_stack([rng.uniform(-0.03, 0.0, n), rng.uniform(-0.03, 0.03, n), rng.uniform(0.30, 0.32, n)])
    second = first + np.column_stack([rng.uniform(0.02, 0.04, n), rng.normal(0, 0.003, n), rng.normal(0, 0.003, n)])
    outgoing = np.column_stack([rng.normal(0, 0.2, n), rng.normal(0, 0.2, n), -np.ones(n)])
    outgoing /= np.linalg.norm(outgoing, axis=1, keepdims=True)
    pairs = multipath.BouncePairs(first, second, np.linalg.norm(second - first, axis=1),
                                  rng.uniform(0.5, 1.0, n) * 1e-6, outgoing, np.full(n, np.deg2rad(20.0)))
    tx_m, rx_m = _antennas()
    counts = _uses_nodes(monkeypatch)
    frame = multipath.simulate_pairs(pairs, tx_m, rx_m, FREQS_HZ, element_exponent=1.0)

    def legs(points, antennas, extra_m, lobe):
        dist = np.linalg.norm(points[:, None, :] - antennas[None], axis=2)
        gain = leg_gains(points, antennas, element_exponent=1.0)
        if lobe:
            cos = np.einsum("kec,kc->ke", antennas[None] - points[:, None], pairs.outgoing) / dist
            gain = gain * np.exp(-0.5 * (np.arccos(np.clip(cos, -1, 1)) / pairs.lobe_rad[:, None]) ** 2)
            gain = gain * pairs.amplitude[:, None]
        phase = np.exp(-2j * np.pi * (dist + extra_m[:, None])[..., None] * FREQS_HZ / C_M_PER_S)
        return (gain / dist)[..., None] * phase

    zero = np.zeros(n)
    reference = (np.einsum("krf,ktf->rtf", legs(second, rx_m, zero, True), legs(first, tx_m, pairs.hop_m, False))
                 + np.einsum("krf,ktf->rtf", legs(first, rx_m, pairs.hop_m, False), legs(second, tx_m, zero, True)))
    assert max(counts) < len(FREQS_HZ)
    assert np.abs(frame - reference).max() < TOLERANCE * np.abs(reference).max()


def _whole_array_phasors(path_m, freq_hz):
    """exact_phasors as whole-array passes (what it computed before its passes ran in cache-sized chunks)."""
    cycles = path_m * (np.asarray(freq_hz) / C_M_PER_S)
    cycles -= np.rint(cycles)
    angle = (cycles * (-2.0 * np.pi)).astype(np.float32)
    parts = np.stack([np.cos(angle), np.sin(angle)], axis=-1)
    return parts.view(np.complex64)[..., 0]


@pytest.mark.parametrize(("path_shape", "freq_shape"), [((192, 1500), ()), ((1, 192), (128, 1)), ((), ()),
                                                         ((192, 0), ()), ((3, 5, 7), (5, 1))])
def test_chunked_passes_give_the_whole_array_values_bit_for_bit(path_shape, freq_shape, monkeypatch):
    """The generator's captures stay byte-identical only if chunking changes no value: exact phasors (broadcast
    shapes, a scalar, an empty block) and leg distances against whole-array passes on fresh random inputs, with
    chunks far smaller than the arrays."""
    from bench.synth.radar.model import leg_distances

    monkeypatch.setattr(leg_sum, "CHUNK_ELEMENTS", 100)
    rng = np.random.default_rng()
    path_m = rng.uniform(0.2, 1.5, path_shape)
    freq_hz = rng.uniform(72e9, 82e9, freq_shape)
    found = leg_sum.exact_phasors(path_m, freq_hz)
    expected = _whole_array_phasors(path_m, freq_hz)
    assert found.shape == expected.shape and found.dtype == np.complex64
    assert np.array_equal(found.view(np.uint64), expected.view(np.uint64))
    points_m, antennas_m = rng.uniform(-0.2, 0.4, (700, 3)), rng.uniform(-0.07, 0.07, (192, 3))
    squared = (np.einsum("ec,ec->e", antennas_m, antennas_m)[:, None] + np.einsum("kc,kc->k", points_m, points_m)
               - 2.0 * (antennas_m @ points_m.T))
    assert np.array_equal(leg_distances(points_m, antennas_m), np.sqrt(np.maximum(squared, 0.0)))


def test_a_block_summed_into_a_used_buffer_is_the_block_summed_fresh():
    """leg_sum hands blocks the results it has already added, to be written over: the values must be those of a
    fresh array whatever the buffer held."""
    rng = np.random.default_rng()
    path_m = 0.6 + rng.uniform(-0.004, 0.004, (12, 300))              # 6 receive, 6 transmit legs, 300 rows
    weight = (rng.normal(size=path_m.shape) + 1j * rng.normal(size=path_m.shape)).astype(np.complex64)
    fresh = leg_sum.block_sum(path_m, weight, FREQS_HZ, 6)
    used = (rng.normal(size=fresh.shape) + 1j * rng.normal(size=fresh.shape)).astype(np.complex64)
    found = leg_sum.block_sum(path_m, weight, FREQS_HZ, 6, into=used)
    assert found is used and np.array_equal(found.view(np.uint64), fresh.view(np.uint64))


@pytest.mark.parametrize("half_width_m", [0.004, 0.05, 0.7])     # nodes and fit; a wide span: no fit (direct)
def test_a_fit_read_back_from_the_disk_cache_is_the_fit_computed(half_width_m, tmp_path, monkeypatch):
    """Kept between runs (bench.synth.radar.fit_cache): what a later run reads is the computed array byte for byte
    (values, dtype, memory order), so the frames are the same whether the fit was computed or read."""

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    freqs = np.linspace(72e9, 82e9, 128)
    frequency_nodes._fit.cache_clear()
    computed = frequency_nodes.interpolator(freqs, half_width_m)
    assert len(list((tmp_path / "mm2fsk-bench" / "synth-fits").glob("*.npz"))) == 1
    frequency_nodes._fit.cache_clear()                     # a new process: from disk
    read = frequency_nodes.interpolator(freqs, half_width_m)
    frequency_nodes._fit.cache_clear()
    assert (read[1] is None) == (computed[1] is None) == (half_width_m > 0.5)
    for a, b in zip(read, computed, strict=True):
        if b is not None:
            assert a.dtype == b.dtype and a.flags.f_contiguous == b.flags.f_contiguous
            assert a.tobytes(order="A") == b.tobytes(order="A")
    assert read[1] is not None or np.array_equal(read[0], freqs)


def test_a_damaged_or_unwritable_fit_cache_computes_the_fit(tmp_path, monkeypatch):

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    freqs = np.linspace(72e9, 82e9, 64)
    frequency_nodes._fit.cache_clear()
    expected = frequency_nodes.interpolator(freqs, 0.02)
    (kept,) = (tmp_path / "mm2fsk-bench" / "synth-fits").glob("*.npz")
    kept.write_bytes(b"not a fit")
    frequency_nodes._fit.cache_clear()
    found = frequency_nodes.interpolator(freqs, 0.02)
    assert np.array_equal(found[1], expected[1]) and np.load(kept)["fit"].tobytes() == expected[1].tobytes()
    (tmp_path / "file").write_text("")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "file"))     # the cache folder cannot be made
    frequency_nodes._fit.cache_clear()
    assert np.array_equal(frequency_nodes.interpolator(freqs, 0.02)[1], expected[1])
    frequency_nodes._fit.cache_clear()
