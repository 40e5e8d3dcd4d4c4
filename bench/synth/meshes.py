"""Closed triangle meshes as triangle soups: `tris_m` (T, 3, 3) float64, metres, outward (counter-clockwise) winding.

Solids are built as extrusions of an (x, z) strip along y or as revolutions of an (r, axial) profile, and every
triangle is oriented so that its normal points away from the solid; degenerate triangles are dropped.
"""
from __future__ import annotations

import numpy as np

MAX_SEGMENT_M = 2.5e-3   # longest edge of the tessellation along profiles and extrusions


def triangle_normals(tris_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit normals (T, 3) from the winding and areas (T,) in square metres."""
    cross = np.cross(tris_m[:, 1] - tris_m[:, 0], tris_m[:, 2] - tris_m[:, 0])
    double_area = np.linalg.norm(cross, axis=1)
    return cross / np.maximum(double_area, 1e-300)[:, None], 0.5 * double_area


def _orient(tris_m: np.ndarray, outward: np.ndarray) -> np.ndarray:
    """Swap two corners of every triangle whose normal disagrees with `outward`; drop zero-area triangles."""
    normals, areas = triangle_normals(tris_m)
    tris_m = tris_m.copy()
    flip = np.einsum("ij,ij->i", normals, outward) < 0
    tris_m[flip] = tris_m[flip][:, [0, 2, 1]]
    return tris_m[areas > 1e-12]


def _quads(a, b, c, d) -> np.ndarray:
    """Two triangles per quad a-b-c-d (each (N, 3)) -> (2N, 3, 3)."""
    return np.concatenate([np.stack([a, b, c], axis=1), np.stack([a, c, d], axis=1)])


def _pieces(max_segment_m: float, *polylines: np.ndarray) -> np.ndarray:
    """Per-interval subdivision counts so that no segment of any of the matching polylines exceeds the limit."""
    longest = np.max([np.linalg.norm(np.diff(p, axis=0), axis=1) for p in polylines], axis=0)
    return np.maximum(1, np.ceil(longest / max_segment_m)).astype(int)


def _subdivide(points: np.ndarray, pieces: np.ndarray) -> np.ndarray:
    """Split interval i of a polyline (N, D) into pieces[i] equal parts."""
    out = [points[i] + (points[i + 1] - points[i]) * (np.arange(n) / n)[:, None] for i, n in enumerate(pieces)]
    return np.concatenate(out + [points[-1:]])


def _signed_area(polygon: np.ndarray) -> float:
    """Shoelace area of a closed 2-D polygon (N, 2); positive when counter-clockwise."""
    return 0.5 * float(np.sum(polygon[:, 0] * np.roll(polygon[:, 1], -1) - np.roll(polygon[:, 0], -1) * polygon[:, 1]))


def extrude_strip(x_m, z_front_m, z_back_m, height_m: float, max_segment_m: float = MAX_SEGMENT_M) -> np.ndarray:
    """Solid between a front and a back polyline over the same x samples in the (x, z) plane, extruded in y.

    `z_front_m < z_back_m` pointwise; the solid spans y in [-height/2, height/2]. Vertical steps are expressed by
    repeating an x value. Side walls are tessellated into cells of at most `max_segment_m`. Returns a closed soup.
    """
    x_m, zf, zb = (np.asarray(v, dtype=np.float64) for v in (x_m, z_front_m, z_back_m))
    front, back = np.stack([x_m, zf], 1), np.stack([x_m, zb], 1)
    pieces = _pieces(max_segment_m, front, back)
    front, back = _subdivide(front, pieces), _subdivide(back, pieces)
    right, left = np.stack([front[-1], back[-1]]), np.stack([back[0], front[0]])
    polygon = np.concatenate([front[:-1], _subdivide(right, _pieces(max_segment_m, right))[:-1],
                              back[::-1][:-1], _subdivide(left, _pieces(max_segment_m, left))[:-1]])
    edge = np.roll(polygon, -1, axis=0) - polygon
    outward_xz = np.stack([edge[:, 1], -edge[:, 0]], 1) * np.sign(_signed_area(polygon))
    h = height_m / 2.0
    y_levels = np.linspace(-h, h, int(np.ceil(height_m / max_segment_m)) + 1)

    def lift(xz, y):
        return np.stack([xz[:, 0], np.broadcast_to(y, len(xz)), xz[:, 1]], 1)

    p0, p1 = polygon, np.roll(polygon, -1, axis=0)
    sides = [_quads(lift(p0, y0), lift(p1, y0), lift(p1, y1), lift(p0, y1)) for y0, y1 in zip(y_levels, y_levels[1:],
                                                                                              strict=False)]
    side_out = np.stack([outward_xz[:, 0], np.zeros(len(edge)), outward_xz[:, 1]], 1)
    sides = _orient(np.concatenate(sides), np.tile(side_out, (2 * (len(y_levels) - 1), 1)))
    caps = []
    for y, sign in ((-h, -1.0), (h, 1.0)):
        cap = _quads(lift(front[:-1], y), lift(front[1:], y), lift(back[1:], y), lift(back[:-1], y))
        caps.append(_orient(cap, np.tile([0.0, sign, 0.0], (len(cap), 1))))
    return np.concatenate([sides] + caps)


def revolve(profile_rz_m, segments: int = 96, max_segment_m: float = MAX_SEGMENT_M) -> np.ndarray:
    """Solid of revolution about the z axis from an (r, z) profile that starts and ends on the axis (r = 0)."""
    profile = np.asarray(profile_rz_m, dtype=np.float64)
    profile = _subdivide(profile, _pieces(max_segment_m, profile))
    r, z = profile[:, 0], profile[:, 1]
    orientation = np.sign(_signed_area(profile))                       # loop closed along the axis
    edge = profile[1:] - profile[:-1]
    out_r, out_z = edge[:, 1] * orientation, -edge[:, 0] * orientation
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    n_edges = len(edge)
    phi0 = np.broadcast_to(phi[:-1], (n_edges, segments))
    phi1 = np.broadcast_to(phi[1:], (n_edges, segments))

    def ring(k, ph):
        return np.stack([r[k, None] * np.cos(ph), r[k, None] * np.sin(ph), np.broadcast_to(z[k, None], ph.shape)], -1)

    k0, k1 = np.arange(n_edges), np.arange(1, n_edges + 1)
    corners = [ring(k0, phi0), ring(k0, phi1), ring(k1, phi1), ring(k1, phi0)]
    tris = _quads(*(v.reshape(-1, 3) for v in corners))
    mid = 0.5 * (phi0 + phi1)
    out = np.stack([out_r[:, None] * np.cos(mid), out_r[:, None] * np.sin(mid),
                    np.broadcast_to(out_z[:, None], mid.shape)], -1).reshape(-1, 3)
    return _orient(tris, np.tile(out, (2, 1)))


def rotation_matrix(axis, angle_deg: float) -> np.ndarray:
    """Right-hand rotation about `axis` by `angle_deg` (Rodrigues)."""
    axis = np.asarray(axis, dtype=np.float64)
    axis = axis / np.linalg.norm(axis)
    a = np.deg2rad(angle_deg)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * (k @ k)


def transform(tris_m: np.ndarray, rotation: np.ndarray, translation_m) -> np.ndarray:
    """Apply p -> R p + t to every corner (proper rotations keep the outward winding)."""
    return tris_m @ np.asarray(rotation).T + np.asarray(translation_m, dtype=np.float64)


def indexed(tris_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Merge identical corners: (vertices_m (V, 3) in lexicographic order, triangles (T, 3) int64), as
    np.unique(axis=0) would return them (pandas' sorted group numbers: the same result, ~10x faster)."""
    import pandas as pd

    corners = np.ascontiguousarray(tris_m, dtype=np.float64).reshape(-1, 3)
    inverse = pd.DataFrame(corners).groupby([0, 1, 2], sort=True).ngroup().to_numpy()
    vertices = np.empty((int(inverse.max()) + 1 if len(inverse) else 0, 3))
    vertices[inverse] = corners
    return vertices, inverse.reshape(-1, 3).astype(np.int64)
