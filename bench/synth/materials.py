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
    "metal": Material(None, 0.02e-3, 15.0, 0.0, 0.05, 0.01),
    "plastic": Material(2.35, 0.05e-3, 15.0, 6e-3, 0.01, 0.0, True),
    "wood": Material(1.99, 0.2e-3, 25.0, 0.5e-3, 0.0, 0.0),
    "cardboard": Material(1.9, 0.3e-3, 30.0, 0.5e-3, 0.0, 0.0, True),
    "foam": Material(1.03, 0.5e-3, 40.0, 1.5e-3, 0.0, 0.0, True),
}
