"""The brute-force nearest neighbours on a Warp device (methods.backends.warp.nearest) against SciPy's cKDTree and a
float64 brute force on the host, on fresh random lattice surfaces: the nearest index is the host's (the lowest of
exactly tied points, which lattice symmetry makes many of), and the distance of each found pair, computed on the
host with the KD-tree's formula (metrics.chamfer.distances_m), equals cKDTree's query bit for bit; both directions,
sizes around the slices' and blocks' boundaries, one-point and empty sets."""
from __future__ import annotations

import pickle

import numpy as np
import pytest
from scipy.spatial import cKDTree

from metrics.chamfer import distances_m

from devices import CUDA

STEP_M = 2.0 ** -10        # ~1 mm, exact in float64: lattice coordinates and half steps are exact, so are their ties


def _wp_device(device: str) -> str:
    return "cpu" if device == "warp-cpu" else "cuda:0"


def _lowest_nearest(queries: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Index of each query's nearest point by the host's float64 brute force (the first of exact ties)."""
    found = []
    for first in range(0, len(queries), 256):
        d = queries[first:first + 256, None, :] - points[None, :, :]
        found.append(np.argmin((d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2], axis=1))
    return np.concatenate(found)


def _surface(rng: np.random.Generator, nx: int, ny: int, curved: bool) -> np.ndarray:
    """A lattice surface of STEP_M pitch with random holes: curved (z inexact) or on the lattice in z too."""
    x, y = np.meshgrid(np.arange(nx) * STEP_M - 0.05, np.arange(ny) * STEP_M - 0.04)
    x, y = x.ravel(), y.ravel()
    z = 0.3 + 0.2 * (x * x + 0.5 * y * y) if curved else np.round((0.3 + 0.05 * x) / STEP_M) * STEP_M
    surface = np.column_stack([x, y, z])
    return surface[rng.random(len(surface)) < rng.uniform(0.6, 1.0)]


def _queries(rng: np.random.Generator, surface: np.ndarray, n: int) -> np.ndarray:
    """n radar-like points: on the surface, half a step between lattice points (exact ties), or centimetres off."""
    queries = surface[rng.integers(0, len(surface), n)].copy()
    kind = rng.integers(0, 3, n)
    queries[kind == 1, :2] += STEP_M / 2 * rng.choice([-1, 1], ((kind == 1).sum(), 2)) * rng.integers(0, 2, (
        (kind == 1).sum(), 2))
    queries[kind == 2] += np.column_stack([rng.normal(0, 3e-3, ((kind == 2).sum(), 2)),
                                           rng.uniform(-0.03, 0.1, (kind == 2).sum())])
    return queries


def _check(queries: np.ndarray, points: np.ndarray, found: np.ndarray, lowest: bool = True) -> None:
    assert found.shape == (len(queries),)
    if lowest:
        np.testing.assert_array_equal(found, _lowest_nearest(queries, points))
    expected = cKDTree(points).query(queries, k=1, workers=1)[0]
    assert np.array_equal(distances_m(queries - points[found]), expected)


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
@pytest.mark.parametrize("curved", [False, True])
def test_nearest_indices_are_the_hosts_and_their_distances_scipys(device, curved, monkeypatch):
    from methods.backends.warp import nearest

    rng = np.random.default_rng()
    wp_device = _wp_device(device)
    monkeypatch.setattr(nearest, "TARGET_THREADS", 2048)          # many slices on small sets too (Warp-CPU's time)
    surface = _surface(rng, 40, 30, curved)
    ties = 0
    for n_queries, n_points in [(1, 1), (1, 900), (255, 63), (256, 64), (257, 65), (700, 129), (300, len(surface)),
                                (2047, 500), (5, len(surface))]:
        n_points = min(n_points, len(surface))                 # holes may leave fewer than asked for
        points = surface[rng.choice(len(surface), n_points, replace=False)]
        queries = _queries(rng, surface, n_queries)
        slice_points, n_slices = nearest.slices(n_queries, n_points)
        assert (n_slices - 1) * slice_points < n_points <= n_slices * slice_points      # no slice empty
        a, b = nearest.DevicePoints(queries, wp_device), nearest.DevicePoints(points, wp_device)
        to_b, to_a = nearest.nearest_indices((a, b), (b, a))
        _check(queries, points, to_b)
        _check(points, queries, to_a)
        d = queries[:, None, :] - points[None, :, :]
        d2 = (d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1]) + d[..., 2] * d[..., 2]
        ties += int(((d2 == d2.min(axis=1, keepdims=True)).sum(axis=1) > 1).sum())
    assert curved or ties > 0                                       # the lattice's exact ties were exercised


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_empty_sets_and_what_a_search_needs(device):
    from methods.backends.warp import nearest

    wp_device = _wp_device(device)
    none, one = nearest.DevicePoints(np.zeros((0, 3)), wp_device), nearest.DevicePoints(np.ones((1, 3)), wp_device)
    assert [len(found) for found in nearest.nearest_indices((none, one), (none, none))] == [0, 0]
    (found,) = nearest.nearest_indices((one, one))
    assert found.tolist() == [0]
    with pytest.raises(ValueError, match="no points"):
        nearest.nearest_indices((one, none))


@pytest.mark.parametrize("device", [CUDA])
def test_table_sized_sets_with_the_default_slices(device):
    from methods.backends.warp import nearest

    rng = np.random.default_rng()
    surface = _surface(rng, 140, 110, curved=True)                 # ~10-15 k ground-truth points
    for n_queries in (500, 4096, 20_000):
        queries = _queries(rng, surface, n_queries)
        a, b = nearest.DevicePoints(queries), nearest.DevicePoints(surface)
        to_b, to_a = nearest.nearest_indices((a, b), (b, a))
        _check(queries, surface, to_b, lowest=n_queries <= 500)
        _check(surface, queries, to_a, lowest=False)


@pytest.mark.parametrize("device", ["warp-cpu", CUDA])
def test_a_point_sets_device_copy_is_made_once_and_not_pickled(device, monkeypatch):
    from methods.backends.warp import nearest
    from metrics.chamfer import PointSet

    monkeypatch.setattr(nearest.DevicePoints.__init__, "__defaults__", (_wp_device(device),))
    points = PointSet(np.random.default_rng().random((20, 3)))
    assert points.device_points is points.device_points and len(points.device_points) == 20
    again = pickle.loads(pickle.dumps(points))
    assert again._device is None and np.array_equal(again.points_m, points.points_m)
