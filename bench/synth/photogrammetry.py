"""The rest of a synthetic `photogrammetry/` folder: what MAROON's reference loader opens besides the ground-truth
mesh (MAROON_FORMAT.md 4.1-4.2), so that its viewer reads our captures too.

Beside `mesh_masked_smoothed.obj` (the ground truth every reader uses) we write:
* `mesh_masked.obj`: the mesh the reference looks for before it takes `<stem>_smoothed.obj`. Our ground truth
  is exact geometry, not a noisy reconstruction, so this is the same mesh (the reference only checks that it
  exists while the smoothed file is present; it would smooth and write it otherwise);
* one virtual camera `synthetic_cam0` looking along the photogrammetry frame's +z at the object from
  CAMERA_STANDOFF_M in front of it: `depth/synthetic_cam0.tif` (float32 z-depth in the mesh's units, metres,
  0 = no surface, rendered by Open3D's ray caster), `rgb/synthetic_cam0.jpg` (the depth shaded to grey) and a
  minimal Metashape-style `cams.xml` with that camera: its sensor (resolution, focal length f in pixels, cx/cy as
  offsets from the image centre, Metashape's convention) and its 4x4 camera-to-chunk transform (row-major).
The radar metrics never use the camera: the reference reads it only to size a mask. Our reader ignores all of it.
"""
from __future__ import annotations

import shutil
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
from PIL import Image

CAMERA_LABEL = "synthetic_cam0"
IMAGE_SIZE_PX = (320, 240)        # width, height
FOCAL_PX = 400.0
CAMERA_STANDOFF_M = 0.30          # camera distance in front of the mesh's nearest point along +z
GT_MESH_NAME = "mesh_masked_smoothed.obj"
UNSMOOTHED_MESH_NAME = "mesh_masked.obj"


def camera_to_photo(vertices_m: np.ndarray) -> np.ndarray:
    """4x4 camera -> photogrammetry-frame transform: the camera axes are the frame's axes (x right, y down in the
    image = +y of the frame, z forward), centred on the mesh in x and y, CAMERA_STANDOFF_M before its front."""
    lo, hi = vertices_m.min(axis=0), vertices_m.max(axis=0)
    pose = np.eye(4)
    pose[:3, 3] = [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2] - CAMERA_STANDOFF_M]
    return pose


def render_depth_m(vertices_m: np.ndarray, triangles: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """(height, width) float32 z-depth (m) of the mesh seen by the pinhole camera at `pose`; 0 = no surface."""
    import open3d as o3d

    width, height = IMAGE_SIZE_PX
    in_camera = (vertices_m - pose[:3, 3]) @ pose[:3, :3]          # p_cam = R^T (p - t)
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(in_camera.astype(np.float32)),
                        o3d.core.Tensor(np.asarray(triangles, dtype=np.uint32)))
    cols, rows = np.meshgrid(np.arange(width), np.arange(height))
    rays = np.zeros((height, width, 6), dtype=np.float32)
    rays[..., 3] = (cols - width / 2) / FOCAL_PX                    # direction with z = 1: t_hit is the z-depth
    rays[..., 4] = (rows - height / 2) / FOCAL_PX
    rays[..., 5] = 1.0
    t_hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy()
    return np.where(np.isfinite(t_hit), t_hit, 0.0).astype(np.float32)


def cams_xml(pose: np.ndarray) -> str:
    """A minimal Metashape camera export naming CAMERA_LABEL with its sensor and camera-to-chunk transform."""
    width, height = IMAGE_SIZE_PX
    document = ElementTree.Element("document", version="1.5.0")
    chunk = ElementTree.SubElement(document, "chunk", label="synthetic", enabled="true")
    sensor = ElementTree.SubElement(ElementTree.SubElement(chunk, "sensors"), "sensor", id="0",
                                    label="synthetic pinhole", type="frame")
    ElementTree.SubElement(sensor, "resolution", width=str(width), height=str(height))
    calibration = ElementTree.SubElement(sensor, "calibration", type="frame", **{"class": "adjusted"})
    ElementTree.SubElement(calibration, "resolution", width=str(width), height=str(height))
    for name, value in (("f", FOCAL_PX), ("cx", 0.0), ("cy", 0.0)):
        ElementTree.SubElement(calibration, name).text = repr(float(value))
    camera = ElementTree.SubElement(ElementTree.SubElement(chunk, "cameras"), "camera", id="0", sensor_id="0",
                                    label=CAMERA_LABEL)
    ElementTree.SubElement(camera, "transform").text = " ".join(repr(float(v)) for v in pose.ravel())
    ElementTree.indent(document)
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ElementTree.tostring(document, encoding="unicode") + "\n"


def write_loader_files(folder: Path, vertices_m: np.ndarray, triangles: np.ndarray) -> None:
    """Write the module's files into `folder` (the capture's photogrammetry/, holding GT_MESH_NAME already)."""
    shutil.copyfile(folder / GT_MESH_NAME, folder / UNSMOOTHED_MESH_NAME)
    pose = camera_to_photo(vertices_m)
    depth_m = render_depth_m(vertices_m, triangles, pose)
    (folder / "depth").mkdir(exist_ok=True)
    (folder / "rgb").mkdir(exist_ok=True)
    Image.fromarray(depth_m).save(folder / "depth" / f"{CAMERA_LABEL}.tif")
    seen = depth_m > 0
    grey = np.zeros(depth_m.shape, dtype=np.uint8)
    if seen.any():                                  # nearer = brighter, background black
        near, far = float(depth_m[seen].min()), float(depth_m[seen].max())
        grey[seen] = (230 - 180 * (depth_m[seen] - near) / max(far - near, 1e-9)).astype(np.uint8)
    Image.fromarray(np.repeat(grey[..., None], 3, axis=-1)).save(folder / "rgb" / f"{CAMERA_LABEL}.jpg", quality=90)
    (folder / "cams.xml").write_text(cams_xml(pose))
