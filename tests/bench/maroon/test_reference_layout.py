"""The synthetic photogrammetry folder holds what MAROON's reference loader reads (MAROON_FORMAT.md 4.1-4.2), and
bench.maroon.inspect_capture reports which of the reference viewer's expectations a capture meets
(bench.maroon.reference_check)."""
from __future__ import annotations

import json
import shutil
from xml.etree import ElementTree

import numpy as np
import pytest
from PIL import Image

from bench.maroon import reader as maroon
from bench.maroon.inspect_capture import inspect_capture
from bench.maroon.reference_check import reference_expectations
from methods.domain.transforms import apply_transform


@pytest.fixture(scope="module")
def plate_dir(synth_root):
    return synth_root / "01_plate" / "30"


def _camera(photo_dir, label):
    """(f, cx, cy, width, height, 4x4 camera->chunk) of `label` from cams.xml, read the Metashape way: the chunk's
    cameras name their sensor, whose calibration holds f (px), cx/cy (offsets from the image centre), resolution."""
    chunk = ElementTree.parse(photo_dir / "cams.xml").getroot().findall("chunk")[0]
    camera = next(c for c in chunk.find("cameras").findall("camera") if c.get("label") == label)
    sensor = next(s for s in chunk.find("sensors").findall("sensor") if s.get("id") == camera.get("sensor_id"))
    calib = sensor.find("calibration")
    resolution = calib.find("resolution")
    pose = np.array(camera.find("transform").text.split(), dtype=float).reshape(4, 4)
    return (float(calib.find("f").text), float(calib.find("cx").text), float(calib.find("cy").text),
            int(resolution.get("width")), int(resolution.get("height")), pose)


def test_photogrammetry_folder_has_the_loader_files_and_a_consistent_camera(plate_dir):
    import open3d as o3d

    photo = plate_dir / "photogrammetry"
    smoothed, masked = (maroon.read_mesh(photo / name) for name in ("mesh_masked_smoothed.obj", "mesh_masked.obj"))
    np.testing.assert_array_equal(masked.vertices, smoothed.vertices)
    labels = sorted(p.stem for p in (photo / "depth").glob("*.tif"))
    assert labels
    for label in labels:
        assert (photo / "rgb" / f"{label}.jpg").is_file()
        f_px, cx, cy, width, height, pose = _camera(photo, label)
        depth_m = np.asarray(Image.open(photo / "depth" / f"{label}.tif"))
        assert depth_m.dtype == np.float32 and depth_m.shape == (height, width)
        rows, cols = np.nonzero(depth_m > 0)
        assert len(rows) > 100
        # every depth pixel back-projected through the camera lies on the ground-truth mesh
        z = depth_m[rows, cols].astype(float)
        in_camera = np.column_stack([(cols - width / 2 - cx) / f_px * z, (rows - height / 2 - cy) / f_px * z, z])
        in_photo = apply_transform(pose, in_camera)
        scene = o3d.t.geometry.RaycastingScene()
        scene.add_triangles(o3d.core.Tensor(smoothed.vertices.astype(np.float32)),
                            o3d.core.Tensor(smoothed.triangles.astype(np.uint32)))
        distance_m = scene.compute_distance(o3d.core.Tensor(in_photo.astype(np.float32))).numpy()
        assert distance_m.max() < 1e-4


def test_reference_check_on_a_synthetic_capture_and_on_broken_copies(plate_dir, tmp_path):
    assert all(e.met for e in reference_expectations(plate_dir)), reference_expectations(plate_dir)
    copy = tmp_path / "01_plate" / "30"
    shutil.copytree(plate_dir, copy)
    (copy / "photogrammetry" / "mesh_masked.obj").unlink()
    (copy / "photogrammetry" / "cams.xml").write_text("<document><chunk/></document>")
    metadata = json.loads((copy / "metadata.json").read_text())
    metadata["mask_3d_threshold"] = 0.5
    (copy / "metadata.json").write_text(json.dumps(metadata))
    radar = next(copy.glob("radar_*"))
    radar.rename(copy / "radar_72.0_82.0_16")
    unmet = {e.what for e in reference_expectations(copy) if not e.met}
    assert unmet == {"photogrammetry/mesh_masked.obj or mesh.obj", "no legacy mask_3d_threshold",
                     "radar folder radar_72.0_82.0_128/", "photogrammetry/cams.xml names every depth image's camera"}
    found, problems = inspect_capture(copy)
    assert not problems                                   # our reader still reads all of it
    total = len(reference_expectations(copy))
    assert f"reference  {total - 4}/{total} of the MAROON viewer's expectations met" in found
    assert any(line.startswith("  not met  no legacy mask_3d_threshold: the viewer migrates") for line in found)
