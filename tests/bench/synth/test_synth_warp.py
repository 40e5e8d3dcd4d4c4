"""The radar sums on a Warp device (bench.synth.radar.warp_sum; `--device cuda`) against float64 sums on fresh random
scenes: the frame, and the depth a method reconstructs from it; a capture built on the device differs from the NumPy
path's only in its radar frames, within the same tolerance, and its provenance is in the manifest and the cache key
(`--device cuda` without a GPU: tests/bench/test_cli.py's MISTAKES). Warp-CPU runs here; the same cases run on CUDA
where Warp sees a GPU (mark `cuda`)."""
from __future__ import annotations

import json

import numpy as np
import pytest

from bench.maroon.antennas import load_antenna_array
from bench.synth import SynthConfig, generate_catalogue
from bench.synth.memory import ANTENNAS, TABLE1_FREQS_HZ, make_capture, square_grid
from bench.synth.radar import leg_sum, multipath
from bench.synth.radar.model import leg_gains, simulate_frame
from methods import reconstruct

from devices import CUDA

pytest.importorskip("warp")

C_M_PER_S = 299_792_458.0
FREQS_HZ = np.linspace(72e9, 82e9, 128)
DEVICES = ["warp-cpu", CUDA]
# The device path sums each block's node products in float32 (slices of <= 256 rows), interpolates with the NumPy
# path's fits (NODE_ERROR 1e-6 per unit weight) and adds blocks in float64: ~1e-6 of the frame, as the NumPy path
# (measured 2-6e-7 here); 1e-5 leaves margin and is ~90 dB below the generator's thermal noise
FRAME_TOLERANCE = 1e-5
# a phase error of ~1e-5 rad moves a 3FSK depth by c dphi / (4 pi 0.5 GHz) ~ 0.5 um, ~1e-6 of 0.4 m (measured 1e-9)
DEPTH_TOLERANCE = 1e-6
CUTOFF = 1e-2          # the generator's LOBE_CUTOFF


def _seeded() -> np.random.Generator:
    seed = int(np.random.SeedSequence().entropy % 2**32)
    print(f"seed {seed}")
    return np.random.default_rng(seed)


def _relative_l2(found: np.ndarray, expected: np.ndarray) -> float:
    return float(np.linalg.norm(found - expected) / np.linalg.norm(expected))


def _float64_frame(points, amplitudes, tx_m, rx_m, freqs_hz, normals=None, lobe_rad=None, element_exponent=0.0):
    """sum_k a_k g_rx g_tx exp(-j 2 pi f (d_rx + d_tx) / c) / (d_rx d_tx) in float64, (n_rx, n_tx, F)."""
    out = np.empty((len(rx_m), len(tx_m), len(freqs_hz)), dtype=np.complex128)
    legs = [leg_gains(points, antennas, normals, lobe_rad, element_exponent)
            / np.linalg.norm(points[:, None] - antennas[None], axis=2) for antennas in (rx_m, tx_m)]
    dist = [np.linalg.norm(points[:, None] - antennas[None], axis=2) for antennas in (rx_m, tx_m)]
    for i, f_hz in enumerate(freqs_hz):
        rx = amplitudes[:, None] * legs[0] * np.exp(-2j * np.pi * f_hz * dist[0] / C_M_PER_S)
        out[:, :, i] = rx.T @ (legs[1] * np.exp(-2j * np.pi * f_hz * dist[1] / C_M_PER_S))
    return out


def _node_counts(monkeypatch) -> list[int]:
    counts, original = [], leg_sum.interpolator

    def spy(freqs_hz, half_width_m):
        nodes_hz, fit = original(freqs_hz, half_width_m)
        counts.append(len(nodes_hz))
        return nodes_hz, fit
    monkeypatch.setattr(leg_sum, "interpolator", spy)
    return counts


@pytest.mark.parametrize("device", DEVICES)
def test_device_frame_matches_float64_sum(device, monkeypatch):
    """A rough patch of 4000 scatterers at 30-36 cm with random complex amplitudes, lobes and the element pattern
    (blocks from few nodes) plus a far group (a block computed at every frequency); a tenth of the facets
    face sideways with strong amplitudes, and those whose lobe reaches no antenna with a gain of 1e-2 are left
    out (as the generator skips them: the reference sums the others)."""
    rng = _seeded()
    n = 4000
    points = np.column_stack([rng.uniform(-0.04, 0.04, n), rng.uniform(-0.04, 0.04, n), rng.uniform(0.30, 0.36, n)])
    # a far group spanning too wide for nodes, as many as a block: the median splits give it a block of its own
    points[-1000:] = rng.uniform([-0.3, -0.3, 1.0], [0.3, 0.3, 1.5], (1000, 3))
    amplitudes = (rng.normal(size=n) + 1j * rng.normal(size=n)) * 1e-6
    normals = np.column_stack([rng.normal(0, 0.3, n), rng.normal(0, 0.3, n), -np.ones(n)])
    normals[: n // 10, 2] = rng.uniform(-0.2, 0.2, n // 10)                     # facing sideways ...
    amplitudes[: n // 10] *= 1e4             # ... and strong: a row left in where it should be out shows
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    lobe_rad = np.deg2rad(rng.uniform(15.0, 60.0, n))
    antennas = load_antenna_array(all_elements=True)
    tx_m, rx_m = antennas.tx_m[::5], antennas.rx_m[2::5]                       # 20 x 20: not a multiple of 4
    monkeypatch.setattr(leg_sum, "BLOCK_ROWS", 1000)
    counts = _node_counts(monkeypatch)
    frame = simulate_frame(points, amplitudes, tx_m, rx_m, FREQS_HZ, normals, lobe_rad, 1.0, CUTOFF, device=device)
    heard = leg_gains(points, np.concatenate([rx_m, tx_m]), normals, lobe_rad).max(axis=1) >= CUTOFF
    assert 0.8 * n < heard.sum() < 0.99 * n
    reference = _float64_frame(points[heard], amplitudes[heard], tx_m, rx_m, FREQS_HZ, normals[heard],
                               lobe_rad[heard], 1.0)
    assert min(counts) < len(FREQS_HZ) == max(counts)             # blocks from nodes and a block at every frequency
    assert frame.dtype == np.complex64 and frame.shape == reference.shape
    assert _relative_l2(frame, reference) < FRAME_TOLERANCE
    assert np.abs(frame - reference).max() < FRAME_TOLERANCE * np.abs(reference).max()
    again = simulate_frame(points, amplitudes, tx_m, rx_m, FREQS_HZ, normals, lobe_rad, 1.0, CUTOFF, device=device)
    assert np.array_equal(again.view(np.uint64), frame.view(np.uint64))       # the same bit for bit on a device


@pytest.mark.parametrize("device", DEVICES)
def test_device_multipath_rows_match_the_numpy_path(device):
    """Bistatic pairs (forward and reverse rows with their own legs) summed on the device against the NumPy path,
    itself held to float64 sums (test_synth_nodes.py)."""
    rng = _seeded()
    n = 1500
    first = np.column_stack([rng.uniform(-0.03, 0.0, n), rng.uniform(-0.03, 0.03, n), rng.uniform(0.30, 0.32, n)])
    second = first + np.column_stack([rng.uniform(0.02, 0.04, n), rng.normal(0, 0.003, n), rng.normal(0, 0.003, n)])
    outgoing = np.column_stack([rng.normal(0, 0.2, n), rng.normal(0, 0.2, n), -np.ones(n)])
    outgoing /= np.linalg.norm(outgoing, axis=1, keepdims=True)
    pairs = multipath.BouncePairs(first, second, np.linalg.norm(second - first, axis=1),
                                  rng.uniform(0.5, 1.0, n) * 1e-6, outgoing, np.full(n, np.deg2rad(20.0)))
    tx_m, rx_m = ANTENNAS.tx_m[::6], ANTENNAS.rx_m[1::6]
    numpy_frame = multipath.simulate_pairs(pairs, tx_m, rx_m, FREQS_HZ, element_exponent=1.0)
    device_frame = multipath.simulate_pairs(pairs, tx_m, rx_m, FREQS_HZ, element_exponent=1.0, device=device)
    assert _relative_l2(device_frame, numpy_frame) < FRAME_TOLERANCE


@pytest.mark.parametrize("device", DEVICES)
def test_depth_from_a_device_frame_is_the_float64_frames_depth(device):
    """A tilted plate at a random depth within 3FSK's window of the 0.40 m prior, 94 x 94 antennas: 3FSK's depth
    map from the device's frame against the one from the float64 frame."""
    rng = _seeded()
    axis = np.arange(-0.02, 0.02, 0.0009)
    x, y = np.meshgrid(axis, axis)
    slope = rng.uniform(-0.15, 0.15, 2)
    points = np.column_stack([x.ravel(), y.ravel(), (rng.uniform(0.37, 0.43) + slope[0] * x + slope[1] * y).ravel()])
    amplitudes = 1e-6 * np.exp(1j * rng.uniform(0.0, 0.3, len(points)))
    reference = _float64_frame(points, amplitudes, ANTENNAS.tx_m, ANTENNAS.rx_m, TABLE1_FREQS_HZ)
    frame = simulate_frame(points, amplitudes, ANTENNAS.tx_m, ANTENNAS.rx_m, TABLE1_FREQS_HZ, device=device)
    assert _relative_l2(frame, reference) < FRAME_TOLERANCE
    grid = square_grid(0.02, 21, 0.30, 0.50, 201)
    expected = reconstruct(make_capture(reference.astype(np.complex64), TABLE1_FREQS_HZ, grid), "3fsk", "d05_d10")
    found = reconstruct(make_capture(frame, TABLE1_FREQS_HZ, grid), "3fsk", "d05_d10")
    both = expected.valid & found.valid
    assert both.sum() >= 0.99 * max(expected.valid.sum(), found.valid.sum()) and both.sum() > 300
    assert _relative_l2(found.depth_m[both], expected.depth_m[both]) < DEPTH_TOLERANCE


def _files(capture_dir):
    return {p.relative_to(capture_dir): p.read_bytes() for p in sorted(capture_dir.rglob("*")) if p.is_file()}


def test_a_capture_built_on_a_device_differs_only_in_its_radar_frames(tmp_path):
    """Same seeds, camera, ground truth and layout; radar frames within the tolerance; the device in the manifest
    and in the cache key (asking for the other device regenerates, asking again finds it cached)."""
    config = SynthConfig(frequency_points=2)                      # Warp-CPU sums on one thread: keep it small
    numpy_root, device_root = tmp_path / "numpy", tmp_path / "device"
    generate_catalogue(numpy_root, [30], ["01_plate"], config)
    built = generate_catalogue(device_root, [30], ["01_plate"], config, device="warp-cpu")
    expected, found = _files(numpy_root / "01_plate"), _files(device_root / "01_plate")
    radar = {p for p in expected if p.suffix == ".npy"}
    assert built[0].status == "generated" and expected.keys() == found.keys() and len(radar) == 2
    assert all(expected[p] == found[p] for p in expected if p not in radar)
    for path in radar:
        a, b = (np.load(root / "01_plate" / path, allow_pickle=True).item()["xr"] for root in (numpy_root, device_root))
        assert _relative_l2(b, a) < FRAME_TOLERANCE and not np.array_equal(a, b)
    manifests = [json.loads((root / "synth_manifest.json").read_text())["captures"]["01_plate/30"]
                 for root in (numpy_root, device_root)]
    assert [m["device"] for m in manifests] == ["cpu", "warp-cpu"] and manifests[0]["hash"] != manifests[1]["hash"]
    assert generate_catalogue(device_root, [30], ["01_plate"], config, device="warp-cpu")[0].status == "cached"
    assert generate_catalogue(device_root, [30], ["01_plate"], config)[0].status == "generated"
    assert _files(device_root / "01_plate") == expected                 # back to the NumPy path's files
