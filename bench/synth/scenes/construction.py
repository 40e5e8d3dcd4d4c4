"""Construction objects: a brick, a grooved concrete block, a steel angle facing the radar (a dihedral), a PVC
pipe, a plasterboard offcut, a rebar mesh, a trapezoidal metal sheet and a thin metal rod."""
from __future__ import annotations

import numpy as np

from bench.synth.scenes.parts import Part
from bench.synth.scenes.shapes import box, cylinder_profile, lying, profile_solid, rotated, slab, tube_profile, upright

METAL_RGB = (170, 175, 185)


def brick(d_m: float) -> tuple[Part, ...]:
    block = slab(0.12, 0.07, 0.06, d_m)
    return (Part(rotated(block, [0, 1, 0], 10.0, (0.0, 0.0, d_m + 0.03)), 0.5, (170, 80, 60), "brick"),)


def concrete_block(d_m: float) -> tuple[Part, ...]:
    """A concrete block with two 3.5 cm wide, 3 cm deep grooves open towards the radar."""
    x = [-0.07, -0.0475, -0.0475, -0.0125, -0.0125, 0.0125, 0.0125, 0.0475, 0.0475, 0.07]
    front = d_m + np.array([0, 0, 0.03, 0.03, 0, 0, 0.03, 0.03, 0, 0])
    return (Part(profile_solid(x, front, np.full(10, d_m + 0.06), 0.10), 0.6, (150, 150, 145), "concrete"),)


def steel_angle(d_m: float) -> tuple[Part, ...]:
    """A 4 x 4 cm steel angle, 4 mm thick, its inside (a 90 degree dihedral) towards the radar."""
    x = np.array([-0.04, 0.0, 0.04])
    front = d_m + 0.04 - np.abs(x)
    return (Part(profile_solid(x, front, front + 0.004 * np.sqrt(2), 0.12), 1.0, METAL_RGB, "metal"),)


def pvc_pipe(d_m: float) -> tuple[Part, ...]:
    """A grey PVC pipe lying across the view: 5 cm outer diameter, 2.5 mm wall, 14 cm long."""
    return (Part(lying(tube_profile(0.0225, 0.025, 0.14), (0.0, 0.0, d_m + 0.025)), 0.5, (120, 125, 130),
                 "opaque_plastic"),)


def plasterboard(d_m: float) -> tuple[Part, ...]:
    board = slab(0.14, 0.10, 0.0125, d_m)
    return (Part(rotated(board, [0, 1, 0], -15.0, (0.0, 0.0, d_m + 0.00625)), 0.4, (230, 230, 225),
                 "plasterboard"),)


def rebar_mesh(d_m: float) -> tuple[Part, ...]:
    """Three vertical 10 mm bars in front of three horizontal ones, 4 cm apart."""
    vertical = tuple(box((x - 0.005, x + 0.005), (-0.06, 0.06), (d_m, d_m + 0.01)) for x in (-0.04, 0.0, 0.04))
    horizontal = tuple(box((-0.06, 0.06), (y - 0.005, y + 0.005), (d_m + 0.01, d_m + 0.02))
                       for y in (-0.04, 0.0, 0.04))
    return tuple(Part(bar, 1.0, (110, 90, 80), "metal") for bar in vertical + horizontal)


def trapezoid_sheet(d_m: float) -> tuple[Part, ...]:
    """A trapezoidal roofing sheet, 1 mm steel: 1.5 cm ribs every 5 cm, crests 1.5 cm wide."""
    period, depth = 0.05, 0.015
    x = np.concatenate([np.array([0.0, 0.015, 0.025, 0.04]) + k * period for k in range(3)]) - 0.07
    front = d_m + np.tile([0.0, 0.0, depth, depth], 3)
    return (Part(profile_solid(x, front, front + 0.001, 0.10), 1.0, METAL_RGB, "metal"),)


def metal_rod(d_m: float) -> tuple[Part, ...]:
    """A thin object: an 8 mm steel rod standing upright, 14 cm tall."""
    return (Part(upright(cylinder_profile(0.004, 0.14), (0.0, 0.0, d_m + 0.004), segments=32), 1.0, METAL_RGB,
                 "metal"),)


OBJECTS = {
    "20_brick": ("brick", brick),
    "21_concrete_block": ("concrete block", concrete_block),
    "22_steel_angle": ("steel angle", steel_angle),
    "23_pvc_pipe": ("PVC pipe", pvc_pipe),
    "24_plasterboard": ("plasterboard", plasterboard),
    "25_rebar_mesh": ("rebar mesh", rebar_mesh),
    "26_trapezoid_sheet": ("trapezoidal sheet", trapezoid_sheet),
    "27_metal_rod": ("metal rod", metal_rod),
}
