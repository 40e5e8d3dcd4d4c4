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


def _brute_nearest_m(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """float64 nearest distances summed in the KD-tree's order ((dx^2 + dy^2) + dz^2): equal to it bit for bit."""
    d = src[:, None, :] - dst[None, :, :]
    return np.sqrt((d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2]).min(axis=1)


def test_c_s_and_off_err_from_one_query_equal_two_queries_and_brute_force():
    from metrics.evaluate import _c_s_and_off_err_cm

    rng = np.random.default_rng()
    x, y = np.meshgrid(np.arange(-0.04, 0.04, 1e-3), np.arange(-0.03, 0.03, 1e-3))
    for _ in range(5):
        keep = rng.random(x.size) < 0.7
        gt = PointSet(np.column_stack([x.ravel(), y.ravel(), 0.3 + 0.1 * x.ravel() ** 2])[keep])
        radar = np.column_stack([x.ravel(), y.ravel(), 0.3 + rng.uniform(-0.05, 0.1, x.size)])
        radar = radar[rng.random(x.size) < 0.5]
        off = rng.random(len(radar)) < rng.uniform(0.05, 0.6)
        c_s_cm, off_err_cm = _c_s_and_off_err_cm(radar, off, gt, gt)
        distances_m = _brute_nearest_m(radar, gt.points_m)
        assert c_s_cm == float(np.mean(distances_m)) * 100.0
        assert off_err_cm == float(np.mean(_brute_nearest_m(radar[off], gt.points_m))) * 100.0
        assert off_err_cm == float(np.mean(nearest_distances_m(radar[off], gt))) * 100.0   # the query it replaces
        other = PointSet(gt.points_m[::2])                  # the faithful profile: C_s to other points, off_err not
        c_s_cm, off_err_cm = _c_s_and_off_err_cm(radar, off, other, gt)
        assert c_s_cm == float(np.mean(_brute_nearest_m(radar, other.points_m))) * 100.0
        assert off_err_cm == float(np.mean(distances_m[off])) * 100.0
    none = np.zeros(0, dtype=bool)
    assert all(np.isnan(_c_s_and_off_err_cm(np.zeros((0, 3)), none, gt, gt)))
    c_s_cm, off_err_cm = _c_s_and_off_err_cm(radar[:5], np.zeros(5, dtype=bool), gt, gt)
    assert np.isfinite(c_s_cm) and np.isnan(off_err_cm)


def test_queries_run_on_the_cores_the_process_may_use_not_the_hosts(monkeypatch):
    from methods.domain import host
    from metrics import chamfer

    threads = []
    points = PointSet(np.random.default_rng().random((50, 3)))

    class Tree:
        def query(self, src, k, workers):
            threads.append(workers)
            return np.zeros(len(src)), None

    points._tree = Tree()
    monkeypatch.setattr(host.os, "sched_getaffinity", lambda pid: {0, 3, 5}, raising=False)
    monkeypatch.setattr(host.os, "cpu_count", lambda: 224)
    nearest_distances_m(np.zeros((4, 3)), points)
    monkeypatch.setattr(chamfer, "QUERY_THREADS", 1)                 # a scoring worker's setting
    nearest_distances_m(np.zeros((4, 3)), points)
    assert threads == [3, 1]
