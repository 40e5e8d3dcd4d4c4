"""Synthetic radar frames: exact signal model, file layout, physics, determinism, caching and atomic writes."""
from __future__ import annotations

import json
import os

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial import cKDTree

from bench.maroon.antennas import load_antenna_array
from bench.synth import SynthConfig, ensure_capture, generate_catalogue, simulate_frame, writer
from bench.synth.meshes import extrude_strip, indexed, triangle_normals
from bench.synth.radar.model import noise_frame
from bench.synth.sampling import visible_samples
from bench.synth.scenes import FULL_CATALOGUE, build_scene
from methods.domain.capture import RadarGrid
from methods.domain.radar import C_M_PER_S, MAROON_FREQS_HZ
from methods.ops.correlate import correlate_reference

RADAR_DIR = "radar_72.0_82.0_128"
FAST = SynthConfig(frequency_points=16)       # ~1 s per capture: for layout, determinism and caching tests


def _load(path):
    return np.load(path, allow_pickle=True).item()   # our own files; the dataset reader uses a safe unpickler


def _float64_frame(points_m, amplitudes, tx_m, rx_m, freqs_hz):
    d_rx = np.linalg.norm(points_m[:, None, :] - rx_m[None], axis=2)            # (K, n_rx)
    d_tx = np.linalg.norm(points_m[:, None, :] - tx_m[None], axis=2)            # (K, n_tx)
    path = d_rx[:, :, None, None] + d_tx[:, None, :, None]                       # (K, n_rx, n_tx, 1)
    terms = amplitudes[:, None, None, None] * np.exp(-2j * np.pi * freqs_hz * path / C_M_PER_S)
    return np.sum(terms / (d_rx[:, :, None, None] * d_tx[:, None, :, None]), axis=0)


@pytest.mark.parametrize("equidistant", [True, False])
def test_point_scatterers_match_float64_formula(equidistant):
    """Tolerance: max |s - s_ref| / max |s_ref| < 1e-5 (complex64 output, phasor recursion re-seeded every 16)."""
    rng = np.random.default_rng(1)
    antennas = load_antenna_array(all_elements=True)
    freqs = MAROON_FREQS_HZ if equidistant else np.sort(rng.uniform(72e9, 82e9, 24))
    points = rng.uniform([-0.1, -0.1, 0.25], [0.1, 0.1, 0.55], (3, 3))
    amplitudes = rng.normal(size=3) + 1j * rng.normal(size=3)
    frame = simulate_frame(points, amplitudes, antennas.tx_m, antennas.rx_m, freqs)
    reference = _float64_frame(points, amplitudes, antennas.tx_m, antennas.rx_m, freqs)
    assert frame.shape == (96, 96, len(freqs)) and frame.dtype == np.complex64
    assert np.max(np.abs(frame - reference)) / np.max(np.abs(reference)) < 1e-5


def test_axis_order_is_rx_then_tx():
    """xr[rx, tx]: a point near Rx element 10 and far from the Tx columns is loudest along that Rx row."""
    antennas = load_antenna_array(all_elements=True)
    point = antennas.rx_m[10] + [0.0, 0.0, 0.01]
    frame = simulate_frame(point[None], np.ones(1), antennas.tx_m, antennas.rx_m, np.array([77e9]))
    power = np.abs(frame[:, :, 0]) ** 2
    assert np.argmax(power.sum(axis=1)) == 10


@pytest.mark.parametrize("object_name", list(FULL_CATALOGUE))
def test_catalogue_solids_are_closed_and_outward(object_name):
    """Just outside every triangle is empty space and just inside is solid (occupancy by ray parity)."""
    for part in build_scene(object_name, 0.4).parts:
        normals, areas = triangle_normals(part.tris_m)
        centres = part.tris_m.mean(axis=1)[areas > 1e-7]
        normals = normals[areas > 1e-7]
        vertices, triangles = indexed(part.tris_m)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(vertices.astype(np.float32), triangles.astype(np.uint32))
        outside = scene.compute_occupancy((centres + 2e-4 * normals).astype(np.float32)).numpy()
        inside = scene.compute_occupancy((centres - 2e-4 * normals).astype(np.float32)).numpy()
        assert outside.max() == 0 and inside.min() == 1


def test_samples_cover_visible_surface_at_quarter_wavelength():
    """Plate: only the 12x12 cm front face is sampled, fully, with neighbours <= 0.9 mm apart; of two objects at
    different depths both fronts are sampled."""
    samples = visible_samples([p.tris_m for p in build_scene("01_plate", 0.3).parts], 0.9e-3)
    assert np.allclose(samples.points_m[:, 2], 0.30) and np.allclose(samples.normals, [0, 0, -1])
    assert samples.areas_m2.sum() == pytest.approx(0.12 ** 2, rel=1e-9)
    nearest_m = cKDTree(samples.points_m).query(samples.points_m, k=2)[0][:, 1]
    assert nearest_m.max() <= 0.9e-3
    behind = visible_samples([p.tris_m for p in build_scene("08_two_objects", 0.3).parts], 0.9e-3)
    for part, front_z_m in ((0, 0.262), (1, 0.345)):                   # near plate, far box: both seen
        assert behind.points_m[behind.part == part, 2].min() == pytest.approx(front_z_m)


def test_occluded_surface_is_not_sampled():
    front = extrude_strip([-0.05, 0.05], [0.30, 0.30], [0.304, 0.304], 0.10)
    hidden = extrude_strip([-0.02, 0.02], [0.40, 0.40], [0.404, 0.404], 0.04)
    samples = visible_samples([front, hidden], 0.9e-3)
    assert len(samples.part) > 0 and np.all(samples.part == 0)


def test_noise_power_follows_snr():
    noise = noise_frame((96, 96, 128), object_power=2.0, snr_db=10.0, rng=np.random.default_rng(0))
    assert noise.dtype == np.complex64
    assert np.mean(np.abs(noise) ** 2) == pytest.approx(0.2, rel=0.02)


def test_frame_files_layout(synth_root):
    capture = synth_root / "01_plate" / "30"
    radar = capture / RADAR_DIR
    for suffix in ("", "_emptyfiltered"):
        frame = _load(radar / "calibrated_data" / f"000000{suffix}.npy")
        assert set(frame) == {"xr", "fvec", "number_of_measurements", "timestamp_us"}
        assert frame["xr"].shape == (96, 96, 128) and frame["xr"].dtype == np.complex64
        assert frame["fvec"].dtype == np.float64 and np.array_equal(frame["fvec"], MAROON_FREQS_HZ)
        assert frame["number_of_measurements"] == 1
        assert frame["timestamp_us"].shape == (1,) and frame["timestamp_us"].dtype == np.int64
    text = (radar / "calibration.json").read_text()
    calibration = json.loads(text)
    assert list(calibration) == sorted(calibration)
    volume = calibration["000000"]["volume"]
    assert volume["grid_size"] == [301, 301, 201]
    assert volume["bb_min"] == [float(np.float32(v)) for v in (-0.15, -0.15, 0.2)]
    assert volume["bb_max"] == [float(np.float32(v)) for v in (0.15, 0.15, 0.4)]
    grid = RadarGrid(tuple(volume["bb_min"]), tuple(volume["bb_max"]), tuple(volume["grid_size"]))
    assert np.array_equal(np.array(calibration["000000"]["depth"]["intrinsics"]), grid.intrinsics())
    assert calibration["000000"]["amplitude"] == {"amplitude_filter_threshold_dB": 14,
                                                  "amplitude_filter_kernel_size": 1}
    assert (calibration["frequency_low_ghz"], calibration["frequency_high_ghz"],
            calibration["frequency_points"]) == (72, 82, 128)
    metadata = json.loads((capture / "metadata.json").read_text())
    assert metadata["distance_meters"] == 0.3 and metadata["labels"] == ["metal plate"]
    assert metadata["mask_bb"] == {"zmin": 0.26, "zmax": 0.7}           # MAROON's viewer defaults at 30 cm
    alignment = {k: np.array(v) for k, v in json.loads((capture / "alignment.json").read_text()).items()}
    assert all(m.shape == (4, 4) and np.array_equal(m[3], [0, 0, 0, 1]) for m in alignment.values())
    photo2radar = alignment["photogrammetry2radar"]
    assert np.allclose(photo2radar[:3, :3] @ photo2radar[:3, :3].T, np.eye(3))
    angle_deg = np.degrees(np.arccos((np.trace(photo2radar[:3, :3]) - 1) / 2))
    assert 20 < angle_deg < 90 and np.linalg.norm(photo2radar[:3, 3]) > 0.01
    assert np.allclose(alignment["photogrammetry2realsense"],
                       np.linalg.inv(alignment["realsense2radar"]) @ photo2radar)


def test_ground_truth_mesh_lands_at_the_distance(synth_root):
    capture = synth_root / "01_plate" / "30"
    lines = (capture / "photogrammetry" / "mesh_masked_smoothed.obj").read_text().splitlines()
    vertices = np.array([[float(v) for v in line.split()[1:]] for line in lines if line.startswith("v ")])
    photo2radar = np.array(json.loads((capture / "alignment.json").read_text())["photogrammetry2radar"])
    radar = vertices @ photo2radar[:3, :3].T + photo2radar[:3, 3]
    assert radar[:, 2].min() == pytest.approx(0.30, abs=1e-6)
    assert np.allclose(radar[:, :2].min(axis=0), -0.06) and np.allclose(radar[:, :2].max(axis=0), 0.06)


def test_plate_focuses_at_its_depth(synth_root):
    """Coherent back-projection along the plate axis peaks at the plate (z = 0.30 m): the 10 GHz range main lobe
    is about +-1.3 cm wide, so 2 cm off is > 2.5x weaker (first range sidelobe) and 3 cm off > 8x weaker."""
    frame = _load(synth_root / "01_plate" / "30" / RADAR_DIR / "calibrated_data" / "000000_emptyfiltered.npy")
    antennas = load_antenna_array()
    z_m = np.array([0.30, 0.28, 0.32, 0.27, 0.33, 0.295, 0.305])
    points = np.column_stack([np.zeros_like(z_m), np.zeros_like(z_m), z_m])
    power = np.abs(correlate_reference(frame["xr"][1:95, 1:95], frame["fvec"], antennas.tx_m, antennas.rx_m,
                                       np.vstack([points, [0.03, -0.02, 0.30]]), sum_freqs=True))
    assert np.argmax(power[:7]) == 0
    assert power[0] > 2.5 * max(power[1], power[2]) and power[0] > 8 * max(power[3], power[4])
    assert power[7] > 0.5 * power[0]                       # still on the plate, off-centre


def test_clutter_only_in_raw_frame(synth_root):
    folder = synth_root / "03_sphere" / "30" / RADAR_DIR / "calibrated_data"
    raw, filtered = _load(folder / "000000.npy")["xr"], _load(folder / "000000_emptyfiltered.npy")["xr"]
    config = SynthConfig()
    object_power = np.mean(np.abs(filtered) ** 2) / (1 + 10 ** (-config.snr_db / 10))
    clutter_db = 10 * np.log10(np.mean(np.abs(raw - filtered) ** 2) / object_power)
    assert clutter_db == pytest.approx(config.clutter_to_signal_db, abs=0.5)


def _files(root):
    return {p: p.stat().st_mtime_ns for p in root.rglob("*") if p.is_file()}


def test_deterministic_by_seed(tmp_path):
    for name in ("a", "b"):
        ensure_capture(tmp_path / name, "03_sphere", 30, FAST)
    ensure_capture(tmp_path / "c", "03_sphere", 30, SynthConfig(frequency_points=16, seed=1))
    rel = "03_sphere/30/radar_72.0_82.0_16/calibrated_data/000000.npy"
    a, b, c = (_load(tmp_path / n / rel)["xr"] for n in "abc")
    assert np.array_equal(a, b) and not np.array_equal(a, c)
    for rel in ("03_sphere/30/realsense/depth/000000.png", "03_sphere/30/realsense/mask/000000.png",
                "03_sphere/30/photogrammetry/mesh_masked_smoothed.obj", "03_sphere/30/alignment.json"):
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()


def test_cache_skips_unchanged_and_regenerates_changed(tmp_path):
    first = generate_catalogue(tmp_path, [30], ["08_two_objects", "05_steps"], FAST)
    assert [r.status for r in first] == ["generated", "generated"]
    before = _files(tmp_path)
    again = generate_catalogue(tmp_path, [30], ["08_two_objects", "05_steps"], FAST)
    assert [r.status for r in again] == ["cached", "cached"] and _files(tmp_path) == before
    changed = ensure_capture(tmp_path, "05_steps", 30, SynthConfig(frequency_points=16, snr_db=20.0))
    assert changed.status == "generated"
    after = _files(tmp_path)
    steps = [p for p in before if "05_steps" in p.parts]
    assert all(after[p] == before[p] for p in before if "08_two_objects" in p.parts)
    assert all(after[p] != before[p] for p in steps)
    manifest = json.loads((tmp_path / "synth_manifest.json").read_text())["captures"]
    assert manifest["05_steps/30"]["config"]["snr_db"] == 20.0


def test_interrupted_write_leaves_no_capture(tmp_path, monkeypatch):
    def fail(*args, **kwargs):
        raise RuntimeError("interrupted")

    monkeypatch.setattr(writer, "write_metadata", fail)
    with pytest.raises(RuntimeError):
        ensure_capture(tmp_path, "08_two_objects", 30, FAST)
    assert os.listdir(tmp_path / "08_two_objects") == []
    # the root was claimed (manifest first), but the unfinished capture is not recorded
    assert json.loads((tmp_path / "synth_manifest.json").read_text()) == {"captures": {}}


def test_expected_files_exist(tmp_path):
    capture = ensure_capture(tmp_path, "08_two_objects", 30, SynthConfig(frequency_points=16, frames=2)).path
    names = {str(p.relative_to(capture)) for p in capture.rglob("*") if p.is_file()}
    expected = {"metadata.json", "alignment.json", "radar_72.0_82.0_16/calibration.json",
                "realsense/calibration.json", "realsense/timestamps.txt",
                "photogrammetry/mesh_masked_smoothed.obj",
                # what MAROON's reference loader looks for beside our ground truth (synth/camera/photogrammetry.py)
                "photogrammetry/mesh_masked.obj", "photogrammetry/cams.xml",
                "photogrammetry/depth/synthetic_cam0.tif", "photogrammetry/rgb/synthetic_cam0.jpg"}
    for i in ("000000", "000001"):
        expected |= {f"radar_72.0_82.0_16/calibrated_data/{i}.npy",
                     f"radar_72.0_82.0_16/calibrated_data/{i}_emptyfiltered.npy",
                     f"realsense/rgb/{i}.jpg", f"realsense/depth/{i}.png", f"realsense/mask/{i}.png"}
    assert names == expected
    frames = [_load(capture / f"radar_72.0_82.0_16/calibrated_data/00000{i}.npy") for i in (0, 1)]
    assert all(f["number_of_measurements"] == 2 for f in frames)
    assert frames[1]["timestamp_us"][0] > frames[0]["timestamp_us"][0]
    assert not np.array_equal(frames[0]["xr"], frames[1]["xr"])          # fresh noise per frame
