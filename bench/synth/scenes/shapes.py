"""Solid primitives of the catalogue in radar space (metres): boxes, solids of revolution with a vertical or
horizontal axis, extruded profiles. Each returns a closed triangle soup with outward winding (bench.synth.meshes)."""
from __future__ import annotations

import numpy as np

from bench.synth.meshes import extrude_strip, revolve, rotation_matrix, transform

AXIS_Z_TO_Y = rotation_matrix([1, 0, 0], -90.0)      # revolve() builds about z; this stands the solid upright
AXIS_Z_TO_X = rotation_matrix([0, 1, 0], 90.0)


def box(x_m: tuple[float, float], y_m: tuple[float, float], z_m: tuple[float, float]) -> np.ndarray:
    """Axis-aligned box over the given (low, high) ranges."""
    solid = extrude_strip(np.asarray(x_m), [z_m[0]] * 2, [z_m[1]] * 2, y_m[1] - y_m[0])
    return solid + [0.0, 0.5 * (y_m[0] + y_m[1]), 0.0]


def slab(width_m: float, height_m: float, thickness_m: float, front_z_m: float, centre_x_m: float = 0.0,
         centre_y_m: float = 0.0) -> np.ndarray:
    """Box facing the radar: x in centre +- width/2, y in centre +- height/2, z from front to front + thickness."""
    return box((centre_x_m - width_m / 2, centre_x_m + width_m / 2),
               (centre_y_m - height_m / 2, centre_y_m + height_m / 2), (front_z_m, front_z_m + thickness_m))


def profile_solid(x_m, z_front_m, z_back_m, height_m: float, centre_y_m: float = 0.0) -> np.ndarray:
    """A profile between a front and a back polyline in the (x, z) plane extruded over `height_m` in y."""
    return extrude_strip(x_m, z_front_m, z_back_m, height_m) + [0.0, centre_y_m, 0.0]


def upright(profile_rz_m, centre_m, segments: int = 96) -> np.ndarray:
    """Solid of revolution of an (r, axial) profile with its axis vertical (axial = +y), centred at `centre_m`."""
    return transform(revolve(np.asarray(profile_rz_m, float), segments), AXIS_Z_TO_Y, centre_m)


def facing(profile_rz_m, centre_m, segments: int = 96) -> np.ndarray:
    """Solid of revolution with its axis along z (axial = +z, away from the radar), centred at `centre_m`."""
    return revolve(np.asarray(profile_rz_m, float), segments) + np.asarray(centre_m, float)


def lying(profile_rz_m, centre_m, segments: int = 96) -> np.ndarray:
    """Solid of revolution with its axis along x (horizontal, across the view), centred at `centre_m`."""
    return transform(revolve(np.asarray(profile_rz_m, float), segments), AXIS_Z_TO_X, centre_m)


def cylinder_profile(radius_m: float, length_m: float) -> list[tuple[float, float]]:
    """(r, axial) profile of a solid cylinder centred on the origin."""
    h = length_m / 2
    return [(0.0, -h), (radius_m, -h), (radius_m, h), (0.0, h)]


def tube_profile(inner_m: float, outer_m: float, length_m: float) -> list[tuple[float, float]]:
    """(r, axial) closed loop of an open tube (no caps) centred on the origin."""
    h = length_m / 2
    return [(inner_m, -h), (outer_m, -h), (outer_m, h), (inner_m, h), (inner_m, -h)]


def cup_profile(radius_m: float, height_m: float, wall_m: float, bottom_m: float) -> list[tuple[float, float]]:
    """(r, axial) profile of a cup centred on the origin: closed at axial -height/2, open at +height/2."""
    h = height_m / 2
    return [(0.0, -h), (radius_m, -h), (radius_m, h), (radius_m - wall_m, h), (radius_m - wall_m, -h + bottom_m),
            (0.0, -h + bottom_m)]


def rotated(tris_m: np.ndarray, axis, angle_deg: float, about_m) -> np.ndarray:
    """`tris_m` rotated by `angle_deg` about `axis` through the point `about_m`."""
    about_m = np.asarray(about_m, float)
    return transform(tris_m - about_m, rotation_matrix(axis, angle_deg), about_m)
