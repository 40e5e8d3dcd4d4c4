"""Household objects: a tin can, a mug with its handle, a cup and a pan open towards the radar, a book, an open
shoebox, a cutting board, a black bottle, a foam insert, toy blocks and a dish rack of thin bars."""
from __future__ import annotations

from bench.synth.scenes.parts import Part
from bench.synth.scenes.shapes import box, cup_profile, cylinder_profile, facing, profile_solid, rotated, slab, upright

METAL_RGB, WOOD_RGB, CARDBOARD_RGB = (170, 175, 185), (190, 140, 80), (200, 170, 120)
WHITE_RGB, BLACK_RGB = (230, 230, 225), (30, 30, 35)


def _open_towards_radar(profile):
    """A cup profile mirrored along its axis: the open end towards -z (the radar) once `facing` places it."""
    return [(r, -a) for r, a in profile]


def tin_can(d_m: float) -> tuple[Part, ...]:
    return (Part(upright(cylinder_profile(0.038, 0.11), (0.0, 0.0, d_m + 0.038)), 1.0, METAL_RGB, "metal"),)


def mug(d_m: float) -> tuple[Part, ...]:
    body = upright(cup_profile(0.04, 0.09, 0.004, 0.005), (-0.01, 0.0, d_m + 0.04))   # open at the top (+y)
    z = (d_m + 0.035, d_m + 0.045)
    handle = (box((0.028, 0.047), (0.02, 0.028), z), box((0.047, 0.055), (-0.028, 0.028), z),
              box((0.028, 0.047), (-0.028, -0.02), z))
    return (Part(body, 0.5, WHITE_RGB, "opaque_plastic"),) + tuple(
        Part(bar, 0.5, WHITE_RGB, "opaque_plastic") for bar in handle)


def cup_open(d_m: float) -> tuple[Part, ...]:
    """A translucent plastic cup on its side, its opening towards the radar (rim at d - 3 cm, bottom at d + 5 cm)."""
    cup = facing(_open_towards_radar(cup_profile(0.035, 0.08, 0.002, 0.003)), (0.0, 0.0, d_m + 0.01))
    return (Part(cup, 0.5, (210, 215, 225), "plastic"),)


def pan(d_m: float) -> tuple[Part, ...]:
    """A metal pan facing the radar (concave, rim at d - 1.25 cm) with a flat handle to the right."""
    dish = facing(_open_towards_radar(cup_profile(0.065, 0.025, 0.003, 0.003)), (-0.02, 0.0, d_m))
    handle = box((0.045, 0.125), (-0.01, 0.01), (d_m + 0.004, d_m + 0.012))
    return Part(dish, 1.0, METAL_RGB, "metal"), Part(handle, 1.0, BLACK_RGB, "black_plastic")


def book(d_m: float) -> tuple[Part, ...]:
    block = slab(0.10, 0.14, 0.025, d_m)
    return (Part(rotated(block, [0, 1, 0], 20.0, (0.0, 0.0, d_m + 0.0125)), 0.5, (150, 60, 50), "cardboard"),)


def shoebox(d_m: float) -> tuple[Part, ...]:
    """A cardboard box open towards the radar: five 3 mm walls, 12 x 9 x 7 cm (corners are trihedral reflectors)."""
    w, h, depth, t = 0.06, 0.045, 0.07, 0.003
    walls = (box((-w, w), (-h, h), (d_m + depth - t, d_m + depth)),
             box((-w, -w + t), (-h, h), (d_m, d_m + depth - t)), box((w - t, w), (-h, h), (d_m, d_m + depth - t)),
             box((-w + t, w - t), (h - t, h), (d_m, d_m + depth - t)),
             box((-w + t, w - t), (-h, -h + t), (d_m, d_m + depth - t)))
    return tuple(Part(wall, 0.5, CARDBOARD_RGB, "cardboard") for wall in walls)


def cutting_board(d_m: float) -> tuple[Part, ...]:
    board = slab(0.14, 0.10, 0.015, d_m)
    return (Part(rotated(board, [1, 0, 0], 20.0, (0.0, 0.0, d_m + 0.0075)), 0.35, WOOD_RGB, "wood"),)


def black_bottle(d_m: float) -> tuple[Part, ...]:
    profile = [(0, -0.075), (0.03, -0.075), (0.03, 0.03), (0.02, 0.05), (0.012, 0.06), (0.012, 0.075), (0, 0.075)]
    return (Part(upright(profile, (0.0, 0.0, d_m + 0.03)), 0.5, BLACK_RGB, "black_plastic"),)


def foam_insert(d_m: float) -> tuple[Part, ...]:
    """A packaging insert of expanded polystyrene with a 2 cm step."""
    solid = profile_solid([-0.06, 0.0, 0.0, 0.06], [d_m, d_m, d_m + 0.02, d_m + 0.02], [d_m + 0.05] * 4, 0.09)
    return (Part(solid, 0.05, WHITE_RGB, "foam"),)


def toy_blocks(d_m: float) -> tuple[Part, ...]:
    """Three 4 cm wooden cubes at different heights and depths (a scene of separate parts)."""
    centres = ((-0.045, -0.02, d_m - 0.01), (0.0, 0.025, d_m + 0.02), (0.045, -0.02, d_m + 0.005))
    return tuple(Part(slab(0.04, 0.04, 0.04, z, x, y), 0.35, colour, "wood")
                 for (x, y, z), colour in zip(centres, ((200, 60, 50), (60, 120, 200), (230, 200, 60)), strict=True))


def dish_rack(d_m: float) -> tuple[Part, ...]:
    """Fine structure: seven 8 mm metal bars 1.6 cm apart in front of two cross bars (thinner bars vanish from a
    ground truth smoothed as MAROON's is: tests/bench/synth/test_catalogue.py)."""
    bars = tuple(box((x - 0.004, x + 0.004), (-0.055, 0.055), (d_m, d_m + 0.004))
                 for x in (-0.048, -0.032, -0.016, 0.0, 0.016, 0.032, 0.048))
    cross = tuple(box((-0.06, 0.06), (y - 0.004, y + 0.004), (d_m + 0.004, d_m + 0.008)) for y in (-0.04, 0.04))
    return tuple(Part(bar, 1.0, METAL_RGB, "metal") for bar in bars + cross)


OBJECTS = {
    "09_tin_can": ("tin can", tin_can),
    "10_mug": ("mug", mug),
    "11_cup_open": ("plastic cup", cup_open),
    "12_pan": ("pan", pan),
    "13_book": ("book", book),
    "14_shoebox": ("open shoebox", shoebox),
    "15_cutting_board": ("cutting board", cutting_board),
    "16_black_bottle": ("black bottle", black_bottle),
    "17_foam_insert": ("foam insert", foam_insert),
    "18_toy_blocks": ("toy blocks", toy_blocks),
    "19_dish_rack": ("dish rack", dish_rack),
}
