"""The metrics' fast paths against plain references on fresh random inputs: the grid triangulation as masks against
a per-quad loop of the rule as written (methods.domain.lattice's doc), the KD-tree's nearest distances against brute
force where the radar points lie centimetres off a ground-truth lattice surface (the sliding-midpoint tree's case)."""
from __future__ import annotations

import numpy as np
import pytest

from methods.domain.lattice import lattice_triangles, triangulated_vertices
from metrics.chamfer import PointSet, nearest_distances_m


def _loop_vertices(z: np.ndarray, t: float, rule: str) -> np.ndarray:
    """The rule per quad in plain Python (module doc of methods.domain.lattice): which pixels are vertices."""
    valid = np.isfinite(z) & (np.abs(np.nan_to_num(z)) >= 1e-3)
    used = np.zeros(z.shape, dtype=bool)
    close = lambda a, b: abs(z[a] - z[b]) <= t                      # noqa: E731
    first_missing = next((c for c in ((0, 0), (0, 1), (1, 0), (1, 1)) if not valid[c]), None)
    for i in range(z.shape[0] - 1):
        for j in range(z.shape[1] - 1):
            p = {"00": (i, j), "01": (i, j + 1), "10": (i + 1, j), "11": (i + 1, j + 1)}
            ok = {name: valid[pixel] for name, pixel in p.items()}
            triangles = []
            if all(ok.values()):
                if close(p["00"], p["10"]) and close(p["10"], p["01"]):
                    triangles.append(("00", "10", "01"))
                if close(p["11"], p["01"]) and close(p["01"], p["10"]):
                    triangles.append(("11", "01", "10"))
            elif sum(ok.values()) == 3 and rule == "sound":
                a, b, c = (name for name in p if ok[name])
                if close(p[a], p[b]) and close(p[b], p[c]) and close(p[a], p[c]):
                    triangles.append((a, b, c))
            elif sum(ok.values()) == 3 and first_missing is not None:    # 'maroon': the image's corner decides
                missing = f"{first_missing[0]}{first_missing[1]}"
                corners = {"00": ("11", "10", "01"), "01": ("00", "10", "11"), "10": ("00", "01", "11"),
                           "11": ("00", "10", "01")}[missing]
                if all(ok[name] for name in corners) and close(p[corners[0]], p[corners[1]]) \
                        and close(p[corners[1]], p[corners[2]]):
                    triangles.append(corners)
            for triangle in triangles:
                for name in triangle:
                    used[p[name]] = True
    return used


@pytest.mark.parametrize("rule", ["sound", "maroon"])
def test_triangulated_vertices_match_the_rule_per_quad(rule):
    rng = np.random.default_rng()
    for _ in range(20):
        z = 0.3 + rng.normal(0, 0.008, (13, 17))                   # jumps around the 1 cm threshold
        z[rng.random(z.shape) < rng.uniform(0.05, 0.5)] = np.nan
        z[rng.random(z.shape) < 0.05] = 0.0
        expected = _loop_vertices(z, 0.01, rule)
        np.testing.assert_array_equal(triangulated_vertices(z, 0.01, rule), expected)
        from_triangles = np.zeros(z.size, dtype=bool)
        from_triangles[lattice_triangles(z, 0.01, rule).ravel()] = True
        np.testing.assert_array_equal(from_triangles.reshape(z.shape), expected)


def test_nearest_distances_off_a_lattice_surface_match_brute_force():
    rng = np.random.default_rng()
    x, y = np.meshgrid(np.arange(-0.06, 0.06, 1e-3), np.arange(-0.05, 0.05, 1e-3))
    surface = np.column_stack([x.ravel(), y.ravel(), 0.3 + 0.2 * (x.ravel() ** 2 + y.ravel() ** 2)])
    queries = surface[rng.choice(len(surface), 300, replace=False)].copy()
    queries[:, 2] += rng.uniform(-0.02, 0.15, len(queries))          # wrapped depths land cm off the surface
    brute = np.sqrt(np.min(((queries[:, None, :] - surface[None, :, :]) ** 2).sum(axis=2), axis=1))
    np.testing.assert_allclose(nearest_distances_m(queries, PointSet(surface)), brute, rtol=1e-12, atol=0)
