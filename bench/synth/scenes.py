"""The object catalogue: each entry builds its meshes in radar space for a given distance.

Radar space: metres, x right, y up, z from the array to the object. Every object keeps its visible surface within
about +-6 cm of z = distance and inside the +-0.15 m pixel grid; sizes are 8-16 cm. Materials (bench.synth.materials)
span MAROON's objects: metal (plate, tilted plate, the near plate of 08), plastic shells (bottle, bowl), wood (ball,
step block), cardboard (corrugated sheet, the far box of 08); foam (|Gamma| 0.007) is defined but used by no object.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from bench.synth.meshes import extrude_strip, revolve, rotation_matrix, transform


@dataclass(frozen=True)
class Part:
    """One solid of a scene: closed triangle soup in radar space plus its material."""

    tris_m: np.ndarray           # (T, 3, 3) float64, outward winding
    reflectivity: float          # relative radar amplitude reflectivity (metal = 1), ideal generator
    colour_rgb: tuple[int, int, int]
    material: str = "metal"      # bench.synth.materials.MATERIALS key, used by the realistic effects
    ground_truth: bool = True    # False for the mount: seen by both sensors, not in the mesh or the object mask


@dataclass(frozen=True)
class Scene:
    """The objects of one capture; `label` goes into metadata.json `labels`."""

    name: str
    label: str
    parts: tuple[Part, ...]

    @property
    def tris_m(self) -> np.ndarray:
        """Triangles of the ground truth (the object's parts, without the mount)."""
        return np.concatenate([p.tris_m for p in self.parts if p.ground_truth])

    def with_mount(self) -> Scene:
        """This scene standing on a wooden post (2 x 2 cm) from its lowest point down to y = -0.30 m."""
        tris = self.tris_m
        bottom_y, centre = tris[..., 1].min(), tris.reshape(-1, 3).mean(axis=0)
        post = extrude_strip(np.array([-0.01, 0.01]) + centre[0], [centre[2] - 0.01] * 2, [centre[2] + 0.01] * 2,
                             bottom_y + 0.30)
        post = post + [0.0, 0.5 * (bottom_y - 0.30), 0.0]         # extrusion is centred on y = 0
        return Scene(self.name, self.label, self.parts + (Part(post, 0.2, (120, 90, 60), "wood", False),))


def _slab(width_m: float, height_m: float, thickness_m: float, front_z_m: float, centre_x_m: float = 0.0):
    """Box facing the radar: x in centre +- width/2, y in +-height/2, z from front to front + thickness."""
    x = np.array([-width_m / 2, width_m / 2]) + centre_x_m
    return extrude_strip(x, [front_z_m] * 2, [front_z_m + thickness_m] * 2, height_m)


def _plate(d_m: float) -> tuple[Part, ...]:
    return (Part(_slab(0.12, 0.12, 0.004, d_m), 1.0, (170, 175, 185), "metal"),)


def _tilted_plate(d_m: float) -> tuple[Part, ...]:
    slab = _slab(0.12, 0.12, 0.004, -0.002)                       # centred on the origin
    return (Part(transform(slab, rotation_matrix([0, 1, 0], 28.0), [0, 0, d_m]), 1.0, (170, 175, 185), "metal"),)


def _sphere(d_m: float) -> tuple[Part, ...]:
    radius_m = 0.05
    theta = np.linspace(0.0, np.pi, 49)
    ball = revolve(np.stack([radius_m * np.sin(theta), -radius_m * np.cos(theta)], 1))
    return (Part(ball + [0.0, 0.0, d_m + 0.03], 0.35, (190, 140, 80), "wood"),)


def _bottle(d_m: float) -> tuple[Part, ...]:
    profile = [(0, -0.08), (0.035, -0.08), (0.035, 0.035), (0.03, 0.05), (0.014, 0.065), (0.014, 0.08), (0, 0.08)]
    body = revolve(np.asarray(profile), segments=96)               # axis along z
    upright = transform(body, rotation_matrix([1, 0, 0], -90.0), [0.0, 0.0, d_m + 0.02])  # axis along +y
    return (Part(upright, 0.5, (90, 160, 90), "plastic"),)


def _steps(d_m: float) -> tuple[Part, ...]:
    x = np.array([-0.075, -0.025, -0.025, 0.025, 0.025, 0.075])
    front = d_m + np.array([-0.03, -0.03, 0.0, 0.0, 0.03, 0.03])
    return (Part(extrude_strip(x, front, np.full(6, d_m + 0.06), 0.10), 0.6, (200, 170, 120), "wood"),)


def _bowl(d_m: float) -> tuple[Part, ...]:
    inner_m, wall_m = 0.06, 0.005
    rim_z = d_m - 0.03                                             # opening faces the radar, bottom at rim + 6 cm
    t = np.linspace(0.0, np.pi / 2, 33)
    outer = np.stack([(inner_m + wall_m) * np.sin(t[::-1]), rim_z + (inner_m + wall_m) * np.cos(t[::-1])], 1)
    inner = np.stack([inner_m * np.sin(t), rim_z + inner_m * np.cos(t)], 1)
    return (Part(revolve(np.concatenate([outer, inner])), 0.7, (220, 220, 230), "plastic"),)


def _corrugated(d_m: float) -> tuple[Part, ...]:
    x = np.linspace(-0.07, 0.07, 57)
    front = d_m + 0.005 * np.sin(2 * np.pi * x / 0.03)
    return (Part(extrude_strip(x, front, front + 0.003, 0.12), 1.0, (160, 160, 170), "cardboard"),)


def _two_objects(d_m: float) -> tuple[Part, ...]:
    near = _slab(0.07, 0.09, 0.004, d_m - 0.045, centre_x_m=-0.045)
    far = _slab(0.06, 0.09, 0.04, d_m + 0.045, centre_x_m=0.045)
    # the far box is cardboard, not foam: the near plate lies in front of MAROON's default mask_bb (zmin 0.26 m),
    # so with a foam box (|Gamma| 0.007) no radar point of this capture would be scored
    return Part(near, 1.0, (170, 175, 185), "metal"), Part(far, 0.5, (200, 170, 120), "cardboard")


CATALOGUE: dict[str, tuple[str, Callable[[float], tuple[Part, ...]]]] = {
    "01_plate": ("metal plate", _plate),
    "02_tilted_plate": ("tilted metal plate", _tilted_plate),
    "03_sphere": ("wood ball", _sphere),
    "04_bottle": ("bottle", _bottle),
    "05_steps": ("step box", _steps),
    "06_bowl": ("bowl", _bowl),
    "07_corrugated": ("corrugated sheet", _corrugated),
    "08_two_objects": ("plate and box", _two_objects),
}


def build_scene(object_name: str, distance_m: float) -> Scene:
    """The named catalogue object placed at `distance_m` in radar space; KeyError names the valid objects."""
    if object_name not in CATALOGUE:
        raise KeyError(f"unknown object {object_name!r}; known: {', '.join(CATALOGUE)}")
    label, build = CATALOGUE[object_name]
    return Scene(object_name, label, build(distance_m))
