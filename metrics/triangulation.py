"""MAROON's grid triangulation as a point selector (MAROON_FORMAT.md 5.2).

A 2x2 quad (p00 p01 / p10 p11) of valid points yields triangle (p00, p10, p01) when |z00 - z10| <= t and
|z10 - z01| <= t, and triangle (p11, p01, p10) when |z11 - z01| <= t and |z01 - z10| <= t. Only vertices of at
least one triangle enter the metrics (isolated pixels and one-pixel lines drop out). Quads with three valid points:
the reference code tests the wrong pixels there (a bug); the sound default forms the one triangle of the three
valid vertices when its depth jumps are within t, the faithful option forms none.
"""
from __future__ import annotations

import numpy as np


def triangulated_vertices(depth_m: np.ndarray, threshold_m: float = 0.01, three_valid_quads: bool = True
                          ) -> np.ndarray:
    """(ny, nx) bool: pixels that are a vertex of at least one triangle; `depth_m` NaN = invalid."""
    z = np.asarray(depth_m, dtype=np.float64)
    valid = np.isfinite(z) & (np.abs(np.nan_to_num(z)) >= 1e-3)
    z = np.where(valid, z, 0.0)
    z00, z01, z10, z11 = z[:-1, :-1], z[:-1, 1:], z[1:, :-1], z[1:, 1:]
    v00, v01, v10, v11 = valid[:-1, :-1], valid[:-1, 1:], valid[1:, :-1], valid[1:, 1:]

    def close(a, b):
        return np.abs(a - b) <= threshold_m

    used = np.zeros_like(valid)
    corners = {"00": (slice(None, -1), slice(None, -1)), "01": (slice(None, -1), slice(1, None)),
               "10": (slice(1, None), slice(None, -1)), "11": (slice(1, None), slice(1, None))}

    def mark(tri_ok, names):
        for name in names:
            used[corners[name]] |= tri_ok

    all4 = v00 & v01 & v10 & v11
    mark(all4 & close(z00, z10) & close(z10, z01), ("00", "10", "01"))
    mark(all4 & close(z11, z01) & close(z01, z10), ("11", "01", "10"))
    if three_valid_quads:
        for missing, (a, b, c) in {"00": ("01", "10", "11"), "01": ("00", "10", "11"),
                                   "10": ("00", "01", "11"), "11": ("00", "01", "10")}.items():
            zs = {"00": z00, "01": z01, "10": z10, "11": z11}
            vs = {"00": v00, "01": v01, "10": v10, "11": v11}
            ok = ~vs[missing] & vs[a] & vs[b] & vs[c]
            ok &= close(zs[a], zs[b]) & close(zs[b], zs[c]) & close(zs[a], zs[c])
            mark(ok, (a, b, c))
    return used
