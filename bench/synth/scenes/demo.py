"""The demo's eight objects (the first catalogue; the demo and the committed results use them): flat, tilted, curved,
translucent, stepped, concave, rippled and two-part, in metal, wood, plastic and cardboard."""
from __future__ import annotations

import numpy as np

from bench.synth.meshes import extrude_strip, revolve, rotation_matrix, transform
from bench.synth.scenes.parts import Part
from bench.synth.scenes.shapes import slab

METAL_RGB, WOOD_RGB, CARDBOARD_RGB = (170, 175, 185), (190, 140, 80), (200, 170, 120)


def plate(d_m: float) -> tuple[Part, ...]:
    return (Part(slab(0.12, 0.12, 0.004, d_m), 1.0, METAL_RGB, "metal"),)


def tilted_plate(d_m: float) -> tuple[Part, ...]:
    centred = slab(0.12, 0.12, 0.004, -0.002)
    return (Part(transform(centred, rotation_matrix([0, 1, 0], 28.0), [0, 0, d_m]), 1.0, METAL_RGB, "metal"),)


def sphere(d_m: float) -> tuple[Part, ...]:
    radius_m = 0.05
    theta = np.linspace(0.0, np.pi, 49)
    ball = revolve(np.stack([radius_m * np.sin(theta), -radius_m * np.cos(theta)], 1))
    return (Part(ball + [0.0, 0.0, d_m + 0.03], 0.35, WOOD_RGB, "wood"),)


def bottle(d_m: float) -> tuple[Part, ...]:
    profile = [(0, -0.08), (0.035, -0.08), (0.035, 0.035), (0.03, 0.05), (0.014, 0.065), (0.014, 0.08), (0, 0.08)]
    body = revolve(np.asarray(profile), segments=96)               # axis along z
    standing = transform(body, rotation_matrix([1, 0, 0], -90.0), [0.0, 0.0, d_m + 0.02])  # axis along +y
    return (Part(standing, 0.5, (90, 160, 90), "plastic"),)


def steps(d_m: float) -> tuple[Part, ...]:
    x = np.array([-0.075, -0.025, -0.025, 0.025, 0.025, 0.075])
    front = d_m + np.array([-0.03, -0.03, 0.0, 0.0, 0.03, 0.03])
    return (Part(extrude_strip(x, front, np.full(6, d_m + 0.06), 0.10), 0.6, (200, 170, 120), "wood"),)


def bowl(d_m: float) -> tuple[Part, ...]:
    inner_m, wall_m = 0.06, 0.005
    rim_z = d_m - 0.03                                             # opening faces the radar, bottom at rim + 6 cm
    t = np.linspace(0.0, np.pi / 2, 33)
    outer = np.stack([(inner_m + wall_m) * np.sin(t[::-1]), rim_z + (inner_m + wall_m) * np.cos(t[::-1])], 1)
    inner = np.stack([inner_m * np.sin(t), rim_z + inner_m * np.cos(t)], 1)
    return (Part(revolve(np.concatenate([outer, inner])), 0.7, (220, 220, 230), "plastic"),)


def corrugated(d_m: float) -> tuple[Part, ...]:
    x = np.linspace(-0.07, 0.07, 57)
    front = d_m + 0.005 * np.sin(2 * np.pi * x / 0.03)
    return (Part(extrude_strip(x, front, front + 0.003, 0.12), 1.0, (160, 160, 170), "cardboard"),)


def two_objects(d_m: float) -> tuple[Part, ...]:
    # the near plate's front sits 3.8 cm before d: at 30 cm that is 26.2 cm, inside MAROON's default mask_bb
    # (zmin 0.26 m) with 2 mm to spare, and still in front of 2FSK Δ0.5's window (from 26.4 cm)
    near = slab(0.07, 0.09, 0.004, d_m - 0.038, centre_x_m=-0.045)
    far = slab(0.06, 0.09, 0.04, d_m + 0.045, centre_x_m=0.045)
    return Part(near, 1.0, METAL_RGB, "metal"), Part(far, 0.5, CARDBOARD_RGB, "cardboard")


OBJECTS = {
    "01_plate": ("metal plate", plate),
    "02_tilted_plate": ("tilted metal plate", tilted_plate),
    "03_sphere": ("wood ball", sphere),
    "04_bottle": ("bottle", bottle),
    "05_steps": ("step box", steps),
    "06_bowl": ("bowl", bowl),
    "07_corrugated": ("corrugated sheet", corrugated),
    "08_two_objects": ("plate and box", two_objects),
}
