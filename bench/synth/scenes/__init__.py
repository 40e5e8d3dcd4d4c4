"""The object catalogue: each entry builds its parts in radar space for a given distance.

Radar space: metres, x right, y up, z from the array to the object. Every part of every object lies within
z in [d - 3.8 cm, d + 9 cm] and |x|, |y| <= 13 cm (inside the radar volume d +- 10 cm, +-15 cm, and MAROON's default
`mask_bb`: zmin 0.26 m at 30 cm, zmax 0.70 m; tests/bench/synth/test_catalogue.py checks every distance).
Families: `demo` (the eight objects the demo and the committed results use), `household` and `construction`
(bench/synth/README.md, "Catalogue"). `CATALOGUE` is the demo's eight; `FULL_CATALOGUE` every object;
`CATALOGUES` names both (`python -m bench.synth --catalogue full`).
"""
from __future__ import annotations

from collections.abc import Callable

from bench.synth.scenes import construction, demo, household
from bench.synth.scenes.parts import Part, Scene

Builder = Callable[[float], tuple[Part, ...]]

CATALOGUE: dict[str, tuple[str, Builder]] = dict(demo.OBJECTS)
FULL_CATALOGUE: dict[str, tuple[str, Builder]] = {**demo.OBJECTS, **household.OBJECTS, **construction.OBJECTS}
CATALOGUES: dict[str, dict[str, tuple[str, Builder]]] = {"demo": CATALOGUE, "full": FULL_CATALOGUE}


def build_scene(object_name: str, distance_m: float) -> Scene:
    """The named catalogue object placed at `distance_m` in radar space; KeyError names the valid objects."""
    if object_name not in FULL_CATALOGUE:
        raise KeyError(f"unknown object {object_name!r}; known: {', '.join(FULL_CATALOGUE)}")
    label, build = FULL_CATALOGUE[object_name]
    return Scene(object_name, label, build(distance_m))


__all__ = ["CATALOGUE", "CATALOGUES", "FULL_CATALOGUE", "Part", "Scene", "build_scene"]
