"""Materials of the catalogue objects: what the radar (72-82 GHz) and the active-stereo camera (850 nm) see.

Radar: the normal-incidence Fresnel amplitude reflection coefficient |(1 - n) / (1 + n)| with n = sqrt(eps_r) from
the relative permittivity at W band; the one-way power transmission through a wall is (1 - Gamma^2)^2 (two
interfaces, loss neglected for thin walls); the surface roughness (m) widens the quasi-specular lobe
(`lobe_deg`: half-width of the return around the mirror direction, standing for the spread of the surface's
slopes at the wavelength scale: the least constrained values here, no W-band measurement of these objects exists;
the ablation of `python -m bench.report.agreement` shows their weight) and jitters the phase.
Permittivities: metal (perfect conductor); PE/PP plastics eps_r 2.3-2.4 and dry wood 1.99 (ITU-R P.2040-3,
Table 3, "wood" valid 0.001-100 GHz); cardboard ~1.9 and expanded polystyrene foam ~1.03 at 77-80 GHz (typical
values of mm-wave material measurements, e.g. the radome / packaging literature); foam is nearly transparent.

Camera (Intel RealSense D435, active IR stereo): translucent plastics scatter the projected pattern below the
surface, so the stereo match lies behind it (`subsurface_bias_m`: 6 mm for white PE/PP; Lourenco and Araujo,
Sensors 22(19) 7378, 2022, measure RealSense depth on translucent objects several mm to cm behind the surface);
specular metal reflects the pattern away (holes,
`dropout_fraction`) or mirrors other surfaces (outliers, `outlier_fraction`); dark and matte surfaces behave.
Construction materials (radar): brick 3.91 (ITU-R P.2040-3 Table 3, stated for 1-40 GHz: extrapolated), concrete
5.24 and plasterboard 2.73 (both stated for 1-100 GHz); opaque and black plastics take PE/PP's 2.35.
Camera, the errors of the realistic preset's camera (bench/synth/README.md, "Depth camera errors"):
* `ir_albedo`: diffuse reflectance at 850 nm; carbon-black pigmented plastic absorbs the near infrared (~0.05, the
  reason black plastics defeat NIR sorting in recycling), other surfaces 0.3-0.8. Weak returns give contiguous holes.
* `highlight_deg`: half-angle around the mirror direction of the projector within which a glossy surface sends the
  IR pattern straight back and saturates the sensor (a contiguous hole, Intel's D400 tuning guide: "specular
  surfaces"); polished/brushed metal 10 deg, glossy plastic 4 deg, matte 0.
* `ir_mirror`: share of the infrared returned specularly: a pixel on a surface that mirrors another part of the scene
  (a concave object: pan, dihedral) sees that part's pattern behind the mirror (the virtual image, depth + hop) with
  this weight; metal 1 (mirror), glossy plastic 0.15, matte 0.
* `mask_erosion_px`: the segmentation (MAROON: Grounded-SAM on the colour image) loses this many pixels along the
  boundary of dark or shiny parts, whose edges have little contrast against a dark background.
The numbers are stated here once and every effect can be switched off in `SynthConfig`.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Material:
    """Radar and depth-camera properties of one material (lengths in metres, angles in degrees)."""

    eps_r: float | None            # relative permittivity at 77 GHz; None = metal (perfect conductor)
    roughness_m: float             # rms surface height: phase jitter and the width of the specular lobe
    lobe_deg: float                # half-width (1/e amplitude) of the quasi-specular lobe around the mirror direction
    subsurface_bias_m: float       # camera depth lies this far behind the surface (translucent materials)
    dropout_fraction: float        # camera pixels lost to specular reflection of the IR pattern
    outlier_fraction: float        # camera pixels that see a mirrored surface: depth off by several cm
    walls_transmit: bool = False   # thin walls with little loss: the far wall shows through (not metal, not solid wood)
    ir_albedo: float = 0.6         # diffuse reflectance at 850 nm (camera holes on dark surfaces)
    highlight_deg: float = 0.0     # specular highlight half-angle: pattern saturates, contiguous hole
    ir_mirror: float = 0.0         # weight of the mirrored pattern (IR multipath inside concave objects)
    mask_erosion_px: int = 0       # segmentation mask pulled in along this part's boundary

    @property
    def reflection(self) -> float:
        """Normal-incidence Fresnel amplitude reflection coefficient (metal = 1)."""
        if self.eps_r is None:
            return 1.0
        n = np.sqrt(self.eps_r)
        return float(abs((1.0 - n) / (1.0 + n)))

    @property
    def transmission(self) -> float:
        """Two-way amplitude transmission through one wall (two interfaces each way; metal = 0)."""
        if self.eps_r is None or not self.walls_transmit:
            return 0.0
        return float((1.0 - self.reflection ** 2) ** 2)


MATERIALS: dict[str, Material] = {
    "metal": Material(None, 0.02e-3, 15.0, 0.0, 0.05, 0.01, ir_albedo=0.5, highlight_deg=10.0, ir_mirror=1.0,
                      mask_erosion_px=2),
    "plastic": Material(2.35, 0.05e-3, 15.0, 6e-3, 0.01, 0.0, True, ir_albedo=0.8, highlight_deg=4.0, ir_mirror=0.15),
    "opaque_plastic": Material(2.35, 0.05e-3, 15.0, 0.0, 0.0, 0.0, True, ir_albedo=0.7, highlight_deg=4.0,
                               ir_mirror=0.15),
    "black_plastic": Material(2.35, 0.05e-3, 15.0, 0.0, 0.0, 0.0, True, ir_albedo=0.05, highlight_deg=4.0,
                              ir_mirror=0.15, mask_erosion_px=2),
    "wood": Material(1.99, 0.2e-3, 25.0, 0.5e-3, 0.0, 0.0, ir_albedo=0.6),
    "cardboard": Material(1.9, 0.3e-3, 30.0, 0.5e-3, 0.0, 0.0, True, ir_albedo=0.7),
    "foam": Material(1.03, 0.5e-3, 40.0, 1.5e-3, 0.0, 0.0, True, ir_albedo=0.9),
    "brick": Material(3.91, 0.5e-3, 40.0, 0.0, 0.0, 0.0, ir_albedo=0.4),
    "concrete": Material(5.24, 0.5e-3, 40.0, 0.0, 0.0, 0.0, ir_albedo=0.5),
    "plasterboard": Material(2.73, 0.3e-3, 30.0, 0.5e-3, 0.0, 0.0, ir_albedo=0.8),
}
