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

`smoothed_mesh` is the ground truth's smoothing (SynthConfig `gt_smoothing_steps`): MAROON's reference builds
`mesh_masked_smoothed.obj` from the Metashape mesh by pymeshlab's coordinate Laplacian smoothing, 30 steps
(MAROON_FORMAT.md 4.2), which rounds edges and flattens ripples of the reconstructed surface; we apply the same
number of uniform-weight Laplacian steps to the exact mesh refined by `gt_mesh_subdivisions` midpoint subdivisions
(1: ~1.25 mm vertex spacing, standing for the dense MVS mesh's; the smoothing's reach scales with that spacing, an
assumption: Metashape's spacing for these captures is not published). `mesh_masked.obj` stays a copy of the file
we write (the reference only checks it exists).
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


def smoothed_mesh(tris_m: np.ndarray, steps: int, subdivisions: int = 1) -> np.ndarray:
    """The closed triangle soup `tris_m` (T, 3, 3) m refined by `subdivisions` midpoint subdivisions (4x the
    triangles each) and smoothed by `steps` uniform Laplacian steps, each moving every vertex to the mean of itself
    and its neighbours across every face it shares with them (VCG's coordinate Laplacian with uniform weights).
    Returns a soup of the same winding; `steps=0` and `subdivisions=0` return `tris_m` itself."""
    from scipy import sparse

    from bench.synth.meshes import indexed

    if steps == 0 and subdivisions == 0:
        return tris_m
    vertices, triangles = indexed(tris_m)
    for _ in range(subdivisions):
        edges = np.sort(np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]), axis=1)
        unique, index = np.unique(edges, axis=0, return_inverse=True)
        mids = len(vertices) + index.reshape(3, -1).T              # (T, 3): midpoints of edges 01, 12, 20
        vertices = np.concatenate([vertices, vertices[unique].mean(axis=1)])
        a, b, c = triangles.T
        ab, bc, ca = mids.T
        triangles = np.concatenate([np.stack(t, 1) for t in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    rows = triangles[:, [0, 1, 1, 2, 2, 0]].ravel()
    cols = triangles[:, [1, 0, 2, 1, 0, 2]].ravel()
    adjacency = sparse.csr_matrix((np.ones(len(rows)), (rows, cols)), shape=(len(vertices),) * 2)
    degree = np.asarray(adjacency.sum(axis=1)).ravel()
    for _ in range(steps):
        vertices = (vertices + adjacency @ vertices) / (1.0 + degree)[:, None]
    return vertices[triangles]


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
