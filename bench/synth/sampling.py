"""Surface samples for the radar model: fine sub-triangles of the surface visible from the array.

Triangles facing the array centre are split by longest-edge bisection until every edge is at most 1.5x the sample
spacing, which keeps neighbouring centroids less than one spacing apart; each centroid is a scatterer weighted by
its sub-triangle area. Samples hidden behind other surfaces (ray cast from the array centre) are dropped.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bench.synth.meshes import indexed, triangle_normals

EDGE_PER_SPACING = 1.5


@dataclass(frozen=True)
class SurfaceSamples:
    """Scatterer positions (K, 3) m, unit outward normals (K, 3), areas (K,) m^2, part index (K,)."""

    points_m: np.ndarray
    normals: np.ndarray
    areas_m2: np.ndarray
    part: np.ndarray


def bisect_triangles(tris_m: np.ndarray, max_edge_m: float) -> np.ndarray:
    """Split triangles at the midpoint of their longest edge until no edge exceeds `max_edge_m` (winding kept)."""
    done, todo = [], tris_m
    while len(todo):
        edges = np.linalg.norm(todo[:, [1, 2, 0]] - todo, axis=2)     # edge k joins corner k and k+1
        small = edges.max(axis=1) <= max_edge_m
        done.append(todo[small])
        todo, edges = todo[~small], edges[~small]
        longest = edges.argmax(axis=1)
        order = (longest[:, None] + np.arange(3)) % 3                  # cyclic shift: longest edge = corners 0-1
        todo = np.take_along_axis(todo, order[:, :, None], axis=1)
        mid = 0.5 * (todo[:, 0] + todo[:, 1])
        todo = np.concatenate([np.stack([todo[:, 0], mid, todo[:, 2]], 1),
                               np.stack([mid, todo[:, 1], todo[:, 2]], 1)])
    return np.concatenate(done)


def visible_samples(part_tris_m: list[np.ndarray], spacing_m: float,
                    viewpoint_m=(0.0, 0.0, 0.0)) -> SurfaceSamples:
    """Samples of all parts' surfaces that face `viewpoint_m` and are not occluded (any part can occlude)."""
    import open3d as o3d  # here only: the signal model (`simulate_frame`) must import without Open3D

    viewpoint_m = np.asarray(viewpoint_m, dtype=np.float64)
    scene = o3d.t.geometry.RaycastingScene()
    vertices, triangles = indexed(np.concatenate(part_tris_m))
    scene.add_triangles(vertices.astype(np.float32), triangles.astype(np.uint32))
    chunks = []
    for index, tris in enumerate(part_tris_m):
        normals, _ = triangle_normals(tris)
        facing = np.einsum("ij,ij->i", normals, viewpoint_m - tris.mean(axis=1)) > 0
        fine = bisect_triangles(tris[facing], EDGE_PER_SPACING * spacing_m)
        fine_normals, fine_areas = triangle_normals(fine)
        centroids = fine.mean(axis=1)
        chunks.append((centroids, fine_normals, fine_areas, np.full(len(fine), index)))
    points, normals, areas, part = (np.concatenate(c) for c in zip(*chunks, strict=False))
    to_point = points - viewpoint_m
    distance = np.linalg.norm(to_point, axis=1)
    rays = np.concatenate([np.broadcast_to(viewpoint_m, points.shape), to_point / distance[:, None]], 1)
    t_hit = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
    keep = t_hit >= distance - 2e-4                                   # nothing hit before the sample itself
    return SurfaceSamples(points[keep], normals[keep], areas[keep], part[keep])


def back_wall_samples(part_tris_m: list[np.ndarray], transmissive: list[bool], spacing_m: float,
                      viewpoint_m=(0.0, 0.0, 0.0)) -> SurfaceSamples:
    """Samples of the far side of partly transmissive parts (a plastic shell's back wall), seen through the near side.

    Triangles of a transmissive part that face away from `viewpoint_m` are sampled with their normals reversed
    (the inner surface the wave meets); a sample is kept unless an opaque part lies before it on the ray.
    """
    import open3d as o3d

    viewpoint_m = np.asarray(viewpoint_m, dtype=np.float64)
    opaque = [tris for tris, clear in zip(part_tris_m, transmissive, strict=False) if not clear]
    chunks = []
    for index, (tris, clear) in enumerate(zip(part_tris_m, transmissive, strict=False)):
        if not clear:
            continue
        normals, _ = triangle_normals(tris)
        away = np.einsum("ij,ij->i", normals, viewpoint_m - tris.mean(axis=1)) < 0
        fine = bisect_triangles(tris[away], EDGE_PER_SPACING * spacing_m)
        fine_normals, fine_areas = triangle_normals(fine)
        chunks.append((fine.mean(axis=1), -fine_normals, fine_areas, np.full(len(fine), index)))
    if not chunks:
        return SurfaceSamples(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=np.int64))
    points, normals, areas, part = (np.concatenate(c) for c in zip(*chunks, strict=False))
    if not opaque:
        return SurfaceSamples(points, normals, areas, part)
    scene = o3d.t.geometry.RaycastingScene()
    vertices, triangles = indexed(np.concatenate(opaque))
    scene.add_triangles(vertices.astype(np.float32), triangles.astype(np.uint32))
    to_point = points - viewpoint_m
    distance = np.linalg.norm(to_point, axis=1)
    rays = np.concatenate([np.broadcast_to(viewpoint_m, points.shape), to_point / distance[:, None]], 1)
    t_hit = scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))["t_hit"].numpy()
    keep = t_hit >= distance - 2e-4
    return SurfaceSamples(points[keep], normals[keep], areas[keep], part[keep])
