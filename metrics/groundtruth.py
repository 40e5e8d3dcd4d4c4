"""Ground-truth depth on the radar pixel grid: the mesh in radar space cast orthographically along +z.

MAROON rasterises the mesh with its orthographic K and keeps the nearest fragment (4.2); an orthographic ray per
pixel centre `(grid_x[j], grid_y[ny-1-i])` along +z with the first hit is the same z-buffered rasterisation, done
by Open3D's ray caster (a well-kept library, exact for this projection).
"""
from __future__ import annotations

import numpy as np

from methods.domain.capture import RadarGrid


def rasterise_depth_m(vertices_m: np.ndarray, triangles: np.ndarray, grid: RadarGrid,
                      xy_m: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
    """(ny, nx) depth z in metres of the nearest surface under each pixel centre; NaN where none.

    `xy_m` replaces the pixel centres by other sample positions (each (ny, nx), metres).
    """
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(np.asarray(vertices_m, dtype=np.float32)),
                        o3d.core.Tensor(np.asarray(triangles, dtype=np.uint32)))
    x_m, y_m = grid.pixel_xy_m() if xy_m is None else xy_m
    z0_m = float(np.min(vertices_m[:, 2])) - 1.0                 # start every ray in front of the mesh
    rays = np.zeros(x_m.shape + (6,), dtype=np.float32)
    rays[..., 0], rays[..., 1], rays[..., 2], rays[..., 5] = x_m, y_m, z0_m, 1.0
    t_hit = scene.cast_rays(o3d.core.Tensor(rays))["t_hit"].numpy().astype(np.float64)
    return np.where(np.isfinite(t_hit), z0_m + t_hit, np.nan)
