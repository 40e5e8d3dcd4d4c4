"""The metrics' fast paths against plain references on fresh random inputs: the grid triangulation as masks against
a per-quad loop of the rule as written (methods.domain.lattice's doc), the KD-tree's nearest distances against brute
force where the radar points lie centimetres off a ground-truth lattice surface (the sliding-midpoint tree's case),
the GPU's nearest points (a CUDA sweep's) against both, and which devices use which."""
from __future__ import annotations

import numpy as np
import pytest

from methods.domain.lattice import lattice_triangles, triangulated_vertices
from metrics.chamfer import PointSet, distances_m, nearest_distances_m

from devices import CUDA


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
    return distances_m(src[:, None, :] - dst[None, :, :]).min(axis=1)


def test_c_s_and_off_err_from_one_query_equal_two_queries_and_brute_force():
    from metrics.evaluate import _chamfers_cm

    rng = np.random.default_rng()
    x, y = np.meshgrid(np.arange(-0.04, 0.04, 1e-3), np.arange(-0.03, 0.03, 1e-3))
    for _ in range(5):
        keep = rng.random(x.size) < 0.7
        gt = PointSet(np.column_stack([x.ravel(), y.ravel(), 0.3 + 0.1 * x.ravel() ** 2])[keep])
        radar = np.column_stack([x.ravel(), y.ravel(), 0.3 + rng.uniform(-0.05, 0.1, x.size)])
        radar = radar[rng.random(x.size) < 0.5]
        off = rng.random(len(radar)) < rng.uniform(0.05, 0.6)
        c_g_cm, c_s_cm, off_err_cm = _chamfers_cm(radar, off, gt, gt)
        distances_m = _brute_nearest_m(radar, gt.points_m)
        assert c_s_cm == float(np.mean(distances_m)) * 100.0
        assert c_g_cm == float(np.mean(_brute_nearest_m(gt.points_m, radar))) * 100.0
        assert off_err_cm == float(np.mean(_brute_nearest_m(radar[off], gt.points_m))) * 100.0
        assert off_err_cm == float(np.mean(nearest_distances_m(radar[off], gt))) * 100.0   # the query it replaces
        other = PointSet(gt.points_m[::2])                  # the faithful profile: C_s to other points, off_err not
        c_g_cm, c_s_cm, off_err_cm = _chamfers_cm(radar, off, other, gt)
        assert c_s_cm == float(np.mean(_brute_nearest_m(radar, other.points_m))) * 100.0
        assert c_g_cm == float(np.mean(_brute_nearest_m(other.points_m, radar))) * 100.0
        assert off_err_cm == float(np.mean(distances_m[off])) * 100.0
    none = np.zeros(0, dtype=bool)
    assert all(np.isnan(_chamfers_cm(np.zeros((0, 3)), none, gt, gt)))
    c_g_cm, c_s_cm, off_err_cm = _chamfers_cm(radar[:5], np.zeros(5, dtype=bool), gt, gt)
    assert np.isfinite(c_g_cm) and np.isfinite(c_s_cm) and np.isnan(off_err_cm)
    c_g_cm, c_s_cm, off_err_cm = _chamfers_cm(radar, off, PointSet(np.zeros((0, 3))), gt)   # no reference points
    assert np.isnan(c_g_cm) and np.isnan(c_s_cm)
    assert off_err_cm == float(np.mean(_brute_nearest_m(radar[off], gt.points_m))) * 100.0


@pytest.mark.parametrize("threads", [2, 3, 16])
def test_queries_in_interleaved_chunks_on_the_pool_equal_one_query_and_brute_force(monkeypatch, threads):
    from scipy.spatial import cKDTree

    from metrics import chamfer

    monkeypatch.setattr(chamfer, "QUERY_THREADS", threads)
    rng = np.random.default_rng()
    x, y = np.meshgrid(np.arange(-0.05, 0.05, 1e-3), np.arange(-0.04, 0.04, 1e-3))
    surface = np.column_stack([x.ravel(), y.ravel(), 0.3 + 0.2 * x.ravel() ** 2])
    surface = surface[rng.random(len(surface)) < 0.8]
    for points in (3, chamfer.MIN_CHUNK_POINTS * 2 - 1, chamfer.MIN_CHUNK_POINTS * 2 + 7, 5000):   # around the
        assert chamfer._chunks(points, threads) >= 1                                        # one-chunk threshold
        queries = surface[rng.choice(len(surface), points, replace=False)] if points <= len(surface) else \
            surface[rng.choice(len(surface), points)]
        queries = queries + np.column_stack([rng.normal(0, 3e-3, (points, 2)), rng.uniform(-0.03, 0.1, points)])
        one_query = cKDTree(surface).query(queries, k=1, workers=1)[0]
        got = nearest_distances_m(queries, PointSet(surface))
        assert got.dtype == np.float64 and np.array_equal(got, one_query)
        assert np.array_equal(got, _brute_nearest_m(queries, surface))
        to_surface, to_queries = chamfer.nearest_both_ways_m(queries, PointSet(surface))
        assert np.array_equal(to_surface, one_query)
        assert np.array_equal(to_queries, _brute_nearest_m(surface, queries))
    assert chamfer._chunks(chamfer.MIN_CHUNK_POINTS * 2 + 7, threads) == 2          # the threshold is exercised
    assert chamfer._chunks(chamfer.MIN_CHUNK_POINTS * 2 - 1, threads) == 1


def test_queries_run_on_the_cores_the_process_may_use_not_the_hosts(monkeypatch):
    import threading

    from methods.domain import host
    from metrics import chamfer

    calls = []
    points = PointSet(np.random.default_rng().random((50, 3)))

    class Tree:
        def query(self, src, k, workers):
            calls.append((workers, threading.current_thread() is threading.main_thread()))
            return np.zeros(len(src)), None

    points._tree = Tree()
    monkeypatch.setattr(host.os, "sched_getaffinity", lambda pid: {0, 3, 5}, raising=False)
    monkeypatch.setattr(host.os, "cpu_count", lambda: 224)
    nearest_distances_m(np.zeros((100 * chamfer.MIN_CHUNK_POINTS, 3)), points)
    assert chamfer._POOL[0][0] == 3                                   # the pool's threads: the process's cores
    assert calls == [(1, False)] * 3                                  # one-thread queries, on pool threads
    calls.clear()
    nearest_distances_m(np.zeros((4, 3)), points)                     # too few points to hand over
    monkeypatch.setattr(chamfer, "QUERY_THREADS", 1)                 # a scoring worker's setting
    nearest_distances_m(np.zeros((100 * chamfer.MIN_CHUNK_POINTS, 3)), points)
    assert calls == [(1, True), (1, True)]


def test_radar_points_from_bounds_per_axis_equal_the_pixel_points_inside_mask_bb():
    from methods.domain.capture import RadarGrid
    from metrics.evaluate import _pixel_points_m, _radar_points
    from metrics.masks import inside_mask_bb

    rng = np.random.default_rng()
    grid = RadarGrid((-0.15, -0.12, 0.2), (0.15, 0.12, 0.4), (31, 25, 11))
    for _ in range(20):
        depth_m = 0.3 + rng.normal(0, 0.05, grid.image_shape)
        for value in (np.nan, 0.0, np.inf, -np.inf):
            depth_m[rng.random(depth_m.shape) < 0.05] = value
        bounds = {"xmin": -0.1, "xmax": 0.08, "ymin": -0.05, "ymax": 0.11, "zmin": 0.28, "zmax": 0.33}
        mask_bb_m = {key: value + rng.normal(0, 0.01) for key, value in bounds.items() if rng.random() < 0.7}
        used = rng.random(depth_m.shape) < 0.8
        points_m = _pixel_points_m(grid, np.nan_to_num(depth_m))        # the former way: every pixel's point
        valid = np.isfinite(depth_m) & (depth_m != 0)
        source_mask = valid & inside_mask_bb(points_m.reshape(-1, 3), mask_bb_m).reshape(valid.shape)
        got_valid, got_source, got_points = _radar_points(depth_m, used, grid, mask_bb_m)
        np.testing.assert_array_equal(got_valid, valid)
        np.testing.assert_array_equal(got_source, source_mask)
        expected = points_m[used & source_mask]
        assert got_points.shape == expected.shape and got_points.dtype == np.float64
        assert np.array_equal(got_points, expected)


def _no_trees(monkeypatch):
    """Building or querying a KD-tree fails: what still works did not use one."""
    from metrics import chamfer

    def refuse(*args, **kwargs):
        raise AssertionError("a KD-tree was used")

    monkeypatch.setattr(chamfer, "_build_tree", refuse)
    monkeypatch.setattr(chamfer, "_submit", refuse)


@pytest.mark.parametrize("device", [CUDA])
def test_a_cuda_sweeps_chamfers_on_the_gpu_equal_the_kd_trees(device, monkeypatch):
    from metrics.evaluate import _chamfers_cm

    rng = np.random.default_rng()
    x, y = np.meshgrid(np.arange(-0.06, 0.06, 1e-3), np.arange(-0.05, 0.05, 1e-3))
    for _ in range(4):
        keep = rng.random(x.size) < 0.8
        gt = PointSet(np.column_stack([x.ravel(), y.ravel(), 0.3 + 0.2 * x.ravel() ** 2])[keep])
        other = PointSet(gt.points_m[::2])                          # the faithful profile: C_s to other points
        radar = np.column_stack([x.ravel(), y.ravel(), 0.3 + rng.uniform(-0.05, 0.1, x.size)])
        radar = radar[rng.random(x.size) < rng.uniform(0.02, 1.0)]
        off = rng.random(len(radar)) < rng.uniform(0.05, 0.6)
        expected = [_chamfers_cm(radar, off, gt, gt), _chamfers_cm(radar, off, other, gt)]
        with monkeypatch.context() as patched:
            _no_trees(patched)
            got = [_chamfers_cm(radar, off, gt, gt, device), _chamfers_cm(radar, off, other, gt, device)]
            assert np.array_equal(nearest_distances_m(radar, gt, device), _brute_nearest_m(radar, gt.points_m))
            assert np.array_equal(nearest_distances_m(radar, PointSet(np.zeros((0, 3))), device),
                                  np.full(len(radar), np.inf))               # as cKDTree answers without points
        assert got == expected and all(np.isfinite(expected[0]))


def test_a_sweep_off_cuda_keeps_the_kd_tree_and_never_imports_warp():
    import subprocess
    import sys

    code = """
import sys
import numpy as np
from metrics.chamfer import PointSet, nearest_both_ways_m, nearest_distances_m, on_gpu
points = PointSet(np.random.default_rng().random((40, 3)))
for device in ("cpu", "warp-cpu", "auto"):
    assert not on_gpu(device)
    nearest_distances_m(np.zeros((5, 3)), points, device)
    nearest_both_ways_m(np.ones((7, 3)), points, device)
assert points._tree is not None and points._device is None
assert not [name for name in sys.modules if name.split(".")[0] == "warp" or "backends.warp" in name], "Warp imported"
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    assert done.returncode == 0, done.stderr


def test_cuda_asked_without_warp_falls_back_to_the_kd_tree(monkeypatch):
    import sys

    from metrics import chamfer

    rng = np.random.default_rng()
    points, queries = PointSet(rng.random((300, 3))), rng.random((50, 3))
    monkeypatch.setitem(sys.modules, "methods.backends.warp.runtime", None)     # Warp not installed
    monkeypatch.setattr(chamfer, "_cuda_seen", chamfer._cuda_seen.__wrapped__)  # asked anew, not cached
    assert not chamfer.on_gpu("cuda")
    assert np.array_equal(nearest_distances_m(queries, points, "cuda"), _brute_nearest_m(queries, points.points_m))
    assert points._device is None


def test_cuda_asked_where_warp_sees_no_gpu_falls_back_to_the_kd_tree(monkeypatch):
    pytest.importorskip("warp")
    from methods.backends.warp import runtime
    from metrics import chamfer

    rng = np.random.default_rng()
    points, queries = PointSet(rng.random((300, 3))), rng.random((50, 3))
    monkeypatch.setattr(runtime, "cuda_available", lambda: False)
    monkeypatch.setattr(chamfer, "_cuda_seen", chamfer._cuda_seen.__wrapped__)
    assert not chamfer.on_gpu("cuda")
    to_points, to_queries = chamfer.nearest_both_ways_m(queries, points, "cuda")
    assert np.array_equal(to_points, _brute_nearest_m(queries, points.points_m))
    assert np.array_equal(to_queries, _brute_nearest_m(points.points_m, queries))
    assert points._device is None
