"""run.sh's set-up installs open3d-cpu without the packages it declares but never imports (ipywidgets, nbformat,
ConfigArgParse, and with them IPython and jedi): the parts of Open3D we use must work without them."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _left_out() -> tuple[str, ...]:
    """The module names of what run.sh leaves out, and of what only they bring in (IPython is optional for dash:
    it imports it where present)."""
    listed = re.search(r"unused = \{(.*)\}", (REPO / "run.sh").read_text()).group(1)
    return (*(name.strip(" '\"") for name in listed.split(",")), "IPython", "jedi", "jupyter_core", "traitlets")


USES_OPEN3D = """
import importlib.abc, sys
class Absent(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in sys.argv[2:]:
            raise ModuleNotFoundError(f"No module named {name!r} (left out by run.sh)")
sys.meta_path.insert(0, Absent())

import numpy as np
import open3d as o3d
scene = o3d.t.geometry.RaycastingScene()                                  # ground truth by ray casting
mesh = o3d.geometry.TriangleMesh.create_box()
scene.add_triangles(o3d.t.geometry.TriangleMesh.from_legacy(mesh))
rays = o3d.core.Tensor([[0.5, 0.5, -1.0, 0.0, 0.0, 1.0]], dtype=o3d.core.Dtype.Float32)
assert abs(scene.cast_rays(rays)["t_hit"].numpy()[0] - 1.0) < 1e-6
o3d.io.write_triangle_mesh(sys.argv[1] + "/box.obj", mesh)                    # mesh and point-cloud I/O
assert len(o3d.io.read_triangle_mesh(sys.argv[1] + "/box.obj").vertices) == 8
cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.eye(3)))
o3d.io.write_point_cloud(sys.argv[1] + "/cloud.ply", cloud)
assert len(o3d.io.read_point_cloud(sys.argv[1] + "/cloud.ply").points) == 3
assert o3d.visualization.rendering.OffscreenRenderer                     # the renderer's class (drawing: test_report)
print("ok", *sorted(m for m in sys.argv[2:] if m in sys.modules))
"""


def test_open3d_works_without_what_run_sh_leaves_out(tmp_path):
    pytest.importorskip("open3d")
    left_out = _left_out()
    assert {"ipywidgets", "nbformat", "configargparse"} <= set(left_out)
    result = subprocess.run([sys.executable, "-c", USES_OPEN3D, str(tmp_path), *left_out], capture_output=True,
                            text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["ok"]

