"""Synthetic RealSense frames: geometry against the ground-truth mesh, noise model, file formats."""
from __future__ import annotations

import json

import numpy as np
import open3d as o3d
import pytest
from PIL import Image

from bench.synth import SynthConfig, build_scene
from bench.synth.camera.depth import _cast, nominal_pose
from bench.synth.meshes import indexed


def _read_capture_points(capture):
    """Back-project masked valid depth pixels with the stored intrinsics and realsense2radar (radar metres)."""
    intr = json.loads((capture / "realsense" / "calibration.json").read_text())["rgb"]
    depth = np.asarray(Image.open(capture / "realsense" / "depth" / "000000.png")).astype(np.float64)
    mask = np.asarray(Image.open(capture / "realsense" / "mask" / "000000.png")) > 0
    v, u = np.nonzero(mask & (depth > 0))
    z_mm = depth[v, u]
    cam_mm = np.column_stack([(u - intr["cx"]) * z_mm / intr["fx"], (v - intr["cy"]) * z_mm / intr["fy"], z_mm])
    m = np.array(json.loads((capture / "alignment.json").read_text())["realsense2radar"])
    return cam_mm @ m[:3, :3].T + m[:3, 3], z_mm / 1000.0


def _mesh_distance_m(capture, points_m):
    """Unsigned distance from radar-space points to the ground-truth OBJ mapped by photogrammetry2radar."""
    lines = (capture / "photogrammetry" / "mesh_masked_smoothed.obj").read_text().splitlines()
    vertices = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith("v ")])
    faces = np.array([[int(x) - 1 for x in ln.split()[1:]] for ln in lines if ln.startswith("f ")])
    p2r = np.array(json.loads((capture / "alignment.json").read_text())["photogrammetry2radar"])
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles((vertices @ p2r[:3, :3].T + p2r[:3, 3]).astype(np.float32), faces.astype(np.uint32))
    return scene.compute_distance(points_m.astype(np.float32)).numpy().astype(np.float64)


@pytest.mark.parametrize("object_name", ["02_tilted_plate", "03_sphere"])
def test_rays_follow_integer_pixel_backprojection(object_name):
    """Unquantised Z through pixel (u, v) back-projects with X = (u - cx) Z / fx onto the surface (< 20 um);
    a +0.5 pixel convention would miss by ~100 um on these slanted surfaces."""
    config = SynthConfig()
    scene, pose = build_scene(object_name, 0.3), nominal_pose(config)
    z_m, _, geometry, _ = _cast(scene, pose, config)
    v, u = np.nonzero(geometry == 0)
    cx, cy = config.principal_point_px
    cam = np.column_stack([(u - cx) / config.focal_px, (v - cy) / config.focal_px, np.ones(len(u))]) * z_m[v, u, None]
    radar = cam @ pose.rotation.T + pose.position_m
    vertices, triangles = indexed(scene.tris_m)
    raycaster = o3d.t.geometry.RaycastingScene()
    raycaster.add_triangles(vertices.astype(np.float32), triangles.astype(np.uint32))
    assert np.max(raycaster.compute_distance(radar.astype(np.float32)).numpy()) < 2e-5


def test_noise_free_depth_lies_on_mesh(synth_capture):
    capture = synth_capture("03_sphere", 30, frequency_points=16, depth_noise=False)
    points, _ = _read_capture_points(capture)
    assert len(points) > 10_000
    assert np.max(_mesh_distance_m(capture, points)) < 1e-3            # millimetre quantisation only


def test_depth_noise_matches_stereo_sigma(synth_capture):
    """Plate front at z = 0.30 m, disparity sigma 1 px: the rms of (z - 0.30) over the back-projected points is
    sigma_z = z^2 sigma_d / (f b) times ~0.95 (the optical axis is tilted by ~15 deg against radar z)."""
    config = SynthConfig(frequency_points=16, disparity_sigma_px=1.0, dropout_fraction=0.0)
    capture = synth_capture("01_plate", 30, frequency_points=16, disparity_sigma_px=1.0, dropout_fraction=0.0)
    points, z_m = _read_capture_points(capture)
    sigma_m = z_m ** 2 * config.disparity_sigma_px / (config.focal_px * config.stereo_baseline_m)
    ratio = np.sqrt(np.mean((points[:, 2] - 0.30) ** 2)) / np.sqrt(np.mean(sigma_m ** 2))
    assert 0.85 < ratio < 1.05


def test_extrinsic_error_shifts_points_but_not_stored_pose(synth_capture):
    nominal = synth_capture("03_sphere", 30, frequency_points=16, depth_noise=False)
    shifted = synth_capture("03_sphere", 30, frequency_points=16, depth_noise=False, extrinsic_error_mm=5.0)
    alignment = [json.loads((c / "alignment.json").read_text())["realsense2radar"] for c in (nominal, shifted)]
    assert alignment[0] == alignment[1]
    distance = _mesh_distance_m(shifted, _read_capture_points(shifted)[0])
    assert 1e-3 < np.mean(distance) and np.max(distance) < 5.6e-3


def test_realsense_files(synth_root):
    folder = synth_root / "01_plate" / "30" / "realsense"
    depth_png, mask_png = Image.open(folder / "depth" / "000000.png"), Image.open(folder / "mask" / "000000.png")
    assert depth_png.mode in ("I;16", "I;16B", "I") and depth_png.size == (640, 480)
    depth, mask = np.asarray(depth_png), np.asarray(mask_png)
    assert mask.dtype == np.uint8 and set(np.unique(mask)) == {0, 255}
    rgb = np.asarray(Image.open(folder / "rgb" / "000000.jpg"))
    assert rgb.shape == (480, 640, 3) and rgb.dtype == np.uint8
    on_object = mask > 0
    assert 0.05 < on_object.mean() < 0.6
    assert np.median(depth[on_object & (depth > 0)]) == pytest.approx(300 + 0.0, abs=40)
    assert np.median(depth[~on_object & (depth > 0)]) > 950                    # the background wall
    assert 0 < np.mean(depth[on_object] == 0) < 0.2                           # edge holes and dropouts
    calibration = json.loads((folder / "calibration.json").read_text())
    assert calibration["capture"]["scale"] == 0.001 and calibration["rgb"] == calibration["depth"]
    assert {"fx", "fy", "cx", "cy", "width", "height", "fps"} <= set(calibration["rgb"])
    lines = (folder / "timestamps.txt").read_text().splitlines()
    assert lines[0] == "filename absolute_system[ns]" and lines[1].split()[0] == "000000"
