"""A scene's parts: closed triangle soups in radar space with the material each sensor sees."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bench.synth.meshes import extrude_strip


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
