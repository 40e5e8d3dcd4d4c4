"""Depth of the strongest sample along z: argmax + 3-point parabola on the dB values (MAROON_FORMAT.md 6.2)."""
from __future__ import annotations

import numpy as np


def peak_depth_m(magnitude: np.ndarray, z_first_m: np.ndarray | float, dz_m: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """Parabola-refined depth and max projection from |V| profiles (K, ...) sampled at z_first + k dz.

    Returns (depth_m, max_projection), each of the trailing shape of `magnitude`.
    """
    n_z = magnitude.shape[0]
    k_best = np.argmax(magnitude, axis=0)

    def pick(k: np.ndarray) -> np.ndarray:
        return np.take_along_axis(magnitude, np.clip(k, 0, n_z - 1)[None], axis=0)[0]

    peak = pick(k_best)
    tiny = np.finfo(np.float32).tiny
    db_minus, db_0, db_plus = (20.0 * np.log10(np.maximum(pick(k_best + s), tiny).astype(np.float64))
                               for s in (-1, 0, 1))
    curvature = db_minus - 2.0 * db_0 + db_plus
    safe = np.where(curvature < 0, curvature, -1.0)
    offset = np.where(curvature < 0, 0.5 * (db_minus - db_plus) / safe, 0.0)
    return z_first_m + (k_best + offset) * dz_m, peak.astype(np.float64)
