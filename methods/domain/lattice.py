"""MAROON's grid triangulation of a depth image (MAROON_FORMAT.md 5.2), as triangles and as a point selector.

A point is valid when its depth is finite and |z| >= 1e-3 (in the image's units). A 2x2 quad (p00 p01 / p10 p11;
first digit = row offset, second = column offset) with four valid corners yields triangle (p00, p10, p01) when
|z00 - z10| <= t and |z10 - z01| <= t, and triangle (p11, p01, p10) when |z11 - z01| <= t and |z01 - z10| <= t.
Only vertices of at least one triangle enter the metrics (isolated pixels and one-pixel lines drop out).

Quads with exactly three valid corners, two rules:
* 'sound' (default): the one triangle of the three valid corners, when all three of its depth jumps are <= t;
* 'maroon' (the reference's quirk): the branch is chosen by the validity of the *image's* corner pixels (0, 0),
  (0, 1), (1, 0), (1, 1) (row, column) instead of the quad's own corners: the first invalid one of them, in that
  order, names the corner taken as missing, and the triangle of the other three is formed when those three are
  valid and its two checked jumps are <= t (missing 00: (11, 10, 01) checking 11-10 and 10-01; missing 01:
  (00, 10, 11) checking 00-10 and 10-11; missing 10: (00, 01, 11) checking 00-01 and 01-11; missing 11:
  (00, 10, 01) checking 00-10 and 10-01). The image's top-left pixel is almost always invalid, so in practice a
  three-valid quad yields a triangle only where its own missing corner is p00.
`threshold=None` checks no depth jump (every valid corner triple is connected).
"""
from __future__ import annotations

import numpy as np

RULES = ("sound", "maroon")

# (corner names of the triangle, the pairs whose depth jump is checked) per missing corner, MAROON's branches
_MAROON_THREE = {"00": (("11", "10", "01"), (("11", "10"), ("10", "01"))),
                 "01": (("00", "10", "11"), (("00", "10"), ("10", "11"))),
                 "10": (("00", "01", "11"), (("00", "01"), ("01", "11"))),
                 "11": (("00", "10", "01"), (("00", "10"), ("10", "01")))}
_FULL_QUAD = ((("00", "10", "01"), (("00", "10"), ("10", "01"))),
              (("11", "01", "10"), (("11", "01"), ("01", "10"))))
_CORNERS = {"00": (slice(None, -1), slice(None, -1)), "01": (slice(None, -1), slice(1, None)),
            "10": (slice(1, None), slice(None, -1)), "11": (slice(1, None), slice(1, None))}


def valid_points(depth: np.ndarray) -> np.ndarray:
    """(H, W) bool: finite depth with |z| >= 1e-3 (MAROON's validity; 0 and NaN are invalid)."""
    z = np.asarray(depth, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return np.isfinite(z) & (np.abs(z) >= 1e-3)


def _picks(depth: np.ndarray, threshold: float | None, rule: str, quads: np.ndarray | None,
           valid: np.ndarray | None) -> list[tuple[np.ndarray, tuple[str, str, str]]]:
    """The triangles of `depth` as (H-1, W-1) bool quad selections, each with its corner names, in the order
    `lattice_triangles` lists them (arguments as there)."""
    if rule not in RULES:
        raise ValueError(f"unknown triangulation rule {rule!r}; choose one of {', '.join(RULES)}")
    z = np.asarray(depth, dtype=np.float64)
    valid = valid_points(z) if valid is None else np.asarray(valid, dtype=bool)
    z = np.where(valid, z, 0.0)
    zs = {name: z[sl] for name, sl in _CORNERS.items()}
    vs = {name: valid[sl] for name, sl in _CORNERS.items()}
    region = np.ones_like(vs["00"]) if quads is None else np.asarray(quads, dtype=bool)
    n_valid = vs["00"].astype(np.int8) + vs["01"] + vs["10"] + vs["11"]
    jumps_ok: dict[frozenset, np.ndarray] = {}       # each edge's check once: the rules share edges

    def close(pairs):
        ok = region.copy()
        if threshold is not None:
            for a, b in pairs:
                edge = frozenset((a, b))
                if edge not in jumps_ok:
                    jumps_ok[edge] = np.abs(zs[a] - zs[b]) <= threshold
                ok &= jumps_ok[edge]
        return ok

    picks = []
    four = n_valid == 4
    for corners, pairs in _FULL_QUAD:
        picks.append((four & close(pairs), corners))
    three = n_valid == 3
    if rule == "sound":
        for missing in ("00", "01", "10", "11"):
            corners = tuple(name for name in ("00", "01", "10", "11") if name != missing)
            pairs = ((corners[0], corners[1]), (corners[1], corners[2]), (corners[0], corners[2]))
            picks.append((three & ~vs[missing] & close(pairs), corners))
    else:
        image_corner_valid = {"00": valid[0, 0], "01": valid[0, 1], "10": valid[1, 0], "11": valid[1, 1]}
        missing = next((name for name in ("00", "01", "10", "11") if not image_corner_valid[name]), None)
        if missing is not None:
            corners, pairs = _MAROON_THREE[missing]
            ok = three & close(pairs)
            for name in corners:
                ok &= vs[name]
            picks.append((ok, corners))
    return picks


def lattice_triangles(depth: np.ndarray, threshold: float | None, rule: str = "sound",
                      quads: np.ndarray | None = None, valid: np.ndarray | None = None) -> np.ndarray:
    """(T, 3) flat pixel indices (row * W + col) of the triangles of `depth` (H, W; NaN or 0 = invalid).

    threshold: largest depth jump along a checked edge (same units as `depth`), None = no check; rule: 'sound' or
    'maroon' (three-valid quads, module doc); quads: optional (H-1, W-1) bool restricting the quads considered;
    valid: optional (H, W) validity replacing `valid_points(depth)`.
    """
    if rule not in RULES:
        raise ValueError(f"unknown triangulation rule {rule!r}; choose one of {', '.join(RULES)}")
    if min(np.shape(depth)) < 2:
        return np.zeros((0, 3), dtype=np.int64)
    height, width = np.shape(depth)
    ids = {name: np.arange(height * width).reshape(height, width)[sl] for name, sl in _CORNERS.items()}
    return np.concatenate([np.column_stack([ids[name][sel] for name in corners])
                           for sel, corners in _picks(depth, threshold, rule, quads, valid)])


def triangulated_vertices(depth_m: np.ndarray, threshold_m: float = 0.01, rule: str = "sound") -> np.ndarray:
    """(ny, nx) bool: pixels that are a vertex of at least one triangle; `depth_m` NaN (or 0) = invalid."""
    depth_m = np.asarray(depth_m, dtype=np.float64)
    used = np.zeros(depth_m.shape, dtype=bool)
    if min(depth_m.shape) < 2:
        return used
    for selected, corners in _picks(depth_m, threshold_m, rule, None, None):   # masks, no triangle index lists
        for name in corners:
            used[_CORNERS[name]] |= selected
    return used
