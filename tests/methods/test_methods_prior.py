"""Depth prior: back-projection, grid triangulation, orthographic rasterisation and convex-hull hole filling."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from bench.synth.memory import CAMERA, plane_depth_frame, realsense2radar, square_grid
from methods.domain.capture import Mesh
from methods.prior.priors import mesh_prior_m, realsense_prior_m
from methods.prior.raster import fill_convex_hull, rasterize_nearest_z

GRID = square_grid(0.15, 301)            # the paper's 301 x 301 pixels over +-15 cm
PLANE = (0.31, 0.2, -0.15)              # z = z0 + sx x + sy y in radar space, metres


def plane_m(x_m, y_m, z0_m=PLANE[0], sx=PLANE[1], sy=PLANE[2]):
    return z0_m + sx * x_m + sy * y_m


def radar_pixel_of(x_m: float, y_m: float) -> tuple[int, int]:
    """(row, col) of the radar pixel centre nearest to (x, y); row 0 = +y."""
    return int(round((GRID.bb_max_m[1] - y_m) / 0.001)), int(round((x_m - GRID.bb_min_m[0]) / 0.001))


@pytest.mark.parametrize("depth_scale_m, tol_mm", [(1e-4, 0.1), (1e-3, 0.6)])
def test_tilted_plane_depth_image_gives_the_analytic_plane(depth_scale_m, tol_mm):
    # Tolerance: the depth image is quantised to depth_scale_m; a Z error of half a unit moves the point along
    # its ray, changing the radar z by up to 0.5 unit * (1 + |sx| |X/Z| + |sy| |Y/Z|) ~ 0.55 mm for mm units.
    cam2radar = realsense2radar()
    prior_m = realsense_prior_m(plane_depth_frame(*PLANE, cam2radar, depth_scale_m), cam2radar, GRID)
    x_m, y_m = GRID.pixel_xy_m()
    error_mm = np.abs(prior_m - plane_m(x_m, y_m)) * 1e3
    assert np.isfinite(prior_m).sum() > 0.6 * prior_m.size
    assert np.nanmax(error_mm) < tol_mm
    assert np.nanmean(error_mm) < tol_mm / 2


@pytest.mark.parametrize("fill", ["delaunay", "scanline"])
def test_hole_inside_the_hull_is_filled_and_outside_stays_empty(fill):
    cam2radar = realsense2radar()
    rows, cols = np.mgrid[:CAMERA.height, :CAMERA.width]
    mask = (np.abs(cols - 320) < 150) & (np.abs(rows - 240) < 120) & ~((cols > 380) & (rows > 300))   # notch
    frame = plane_depth_frame(*PLANE, cam2radar, mask=mask)
    frame.depth_mm[(cols - 300) ** 2 + (rows - 220) ** 2 < 30 ** 2] = 0                    # a hole
    hole_xyz_m = cam2radar @ np.array([(300 - CAMERA.cx) / CAMERA.fx * 300, (220 - CAMERA.cy) / CAMERA.fy * 300,
                                       300.0, 1.0])          # ~ the hole centre (Z ~ 300 mm)
    notch_xyz_m = cam2radar @ np.array([(420 - CAMERA.cx) / CAMERA.fx * 300, (350 - CAMERA.cy) / CAMERA.fy * 300,
                                        300.0, 1.0])         # inside the notch, within the convex hull
    unfilled = realsense_prior_m(frame, cam2radar, GRID, fill_holes=False)
    filled = realsense_prior_m(frame, cam2radar, GRID, fill=fill)
    x_m, y_m = GRID.pixel_xy_m()
    for xyz in (hole_xyz_m, notch_xyz_m):
        row, col = radar_pixel_of(xyz[0], xyz[1])
        assert np.isnan(unfilled[row, col])
        if fill == "scanline" and xyz is notch_xyz_m:          # no row or column crosses the notch twice
            assert np.isnan(filled[row, col])
            continue
        assert filled[row, col] == pytest.approx(plane_m(x_m[row, col], y_m[row, col]), abs=0.6e-3)
    assert np.isnan(filled[radar_pixel_of(-0.14, 0.14)])                                  # outside the hull
    assert np.isnan(filled[radar_pixel_of(0.12, -0.12)])
    covered = np.isfinite(filled)
    assert np.array_equal(covered & np.isfinite(unfilled), np.isfinite(unfilled))        # filling adds only
    assert np.nanmax(np.abs(filled - plane_m(x_m, y_m))) < 0.6e-3                          # planar fill = plane


def test_rasteriser_is_barycentric_inclusive_and_keeps_the_nearest_surface():
    u = np.array([0.0, 4.0, 0.0, 0.0, 4.0, 0.0])
    v = np.array([0.0, 0.0, 4.0, 0.0, 0.0, 4.0])
    z = np.array([1.0, 2.0, 3.0, 0.5, 0.5, 0.5])
    far = rasterize_nearest_z(u, v, z, np.array([[0, 1, 2]]), (6, 6))
    assert np.isfinite(far).sum() == 15                          # centres with col + row <= 4, edges included
    assert far[1, 2] == pytest.approx(1.0 + 0.25 * 2 + 0.5 * 1)  # plane z = 1 + u/4 + v/2
    both = rasterize_nearest_z(u, v, z, np.array([[0, 1, 2], [3, 4, 5]]), (6, 6))
    assert np.nanmax(both) == 0.5                                # the nearer triangle wins everywhere


def test_fill_convex_hull_interpolates_linearly_and_leaves_outside_empty():
    rows, cols = np.mgrid[:40, :40].astype(float)
    image = 0.3 + 0.001 * cols - 0.002 * rows
    image[(rows - 20) ** 2 + (cols - 20) ** 2 > 15 ** 2] = np.nan       # a disk of data ...
    truth = image.copy()
    image[16:24, 14:26] = np.nan                                         # ... with a hole
    filled = fill_convex_hull(image)
    assert np.allclose(filled[16:24, 14:26], 0.3 + 0.001 * cols[16:24, 14:26] - 0.002 * rows[16:24, 14:26])
    assert np.array_equal(np.isfinite(filled), np.isfinite(truth))       # disk is convex: nothing added outside


def test_photogrammetry_mesh_prior_covers_exactly_the_mesh():
    vertices = np.array([[-0.05, -0.04, 0.30], [0.05, -0.04, 0.32], [0.05, 0.04, 0.32], [-0.05, 0.04, 0.30]])
    mesh = Mesh(vertices=vertices * 1000.0, triangles=np.array([[0, 1, 2], [0, 2, 3]]), path=Path("memory"))
    to_radar = np.diag([1e-3, 1e-3, 1e-3, 1.0])                          # mesh in mm, radar in m
    prior_m = mesh_prior_m(mesh, to_radar, GRID)
    x_m, y_m = GRID.pixel_xy_m()
    assert np.isfinite(prior_m).sum() == 101 * 81                        # inclusive edges, 1 mm pixels
    assert np.nanmax(np.abs(prior_m - (0.31 + 0.2 * x_m))) < 1e-9
    assert np.isfinite(prior_m[radar_pixel_of(0.05, 0.04)]) and np.isnan(prior_m[radar_pixel_of(0.0, 0.05)])


def test_rim_delaunay_fill_matches_a_delaunay_of_all_covered_pixels():
    # The paper triangulates every valid sample; we triangulate only the rim. Same covered set (the convex
    # hull); values differ only where cocircular lattice points let the two triangulations pick different
    # diagonals over a hole (measured here: mean 0.06 mm, max 0.8 mm on a strongly curved surface).
    from scipy.interpolate import LinearNDInterpolator
    rows, cols = np.mgrid[:121, :121].astype(float)
    image = 0.25 + 2e-5 * (cols - 60) ** 2 + 1e-3 * np.sin(rows / 7)       # curved (not a paraboloid of
                                                                            # revolution, where ties cancel)
    image[(cols - 60) ** 2 + (rows - 60) ** 2 > 55 ** 2] = np.nan
    image[(cols > 85) & (rows > 85)] = np.nan                                # a notch, inside the hull
    rng = np.random.default_rng(3)
    for col, row, radius in zip(rng.integers(20, 100, 8), rng.integers(20, 100, 8), rng.integers(2, 8, 8),
                                strict=False):
        image[(cols - col) ** 2 + (rows - row) ** 2 < radius ** 2] = np.nan
    covered = np.isfinite(image)
    everything = LinearNDInterpolator(np.column_stack([cols[covered], rows[covered]]), image[covered])(cols, rows)
    ours = fill_convex_hull(image)
    assert np.array_equal(np.isfinite(ours), np.isfinite(everything))
    filled = ~covered & np.isfinite(ours)
    assert filled.sum() > 500
    assert np.mean(np.abs(ours - everything)[filled]) < 2e-4
    assert np.max(np.abs(ours - everything)[filled]) < 2e-3


def _scanline_by_loops(image: np.ndarray) -> np.ndarray:
    """`raster.fill_scanline` written pixel by pixel (the specification read literally), float64."""
    out = image.copy()
    n_rows, n_cols = image.shape
    covered = np.isfinite(image)
    for r in range(n_rows):
        for c in range(n_cols):
            if covered[r, c]:
                continue
            estimates = []
            for line, k in ((image[r, :], c), (image[:, c], r)):
                lo = [i for i in range(k) if np.isfinite(line[i])]
                hi = [i for i in range(k + 1, len(line)) if np.isfinite(line[i])]
                if lo and hi:
                    lo, hi = lo[-1], hi[0]
                    estimates.append((line[lo] + (line[hi] - line[lo]) * ((k - lo) / (hi - lo)), hi - lo))
            if len(estimates) == 2:
                (z_r, s_r), (z_c, s_c) = estimates
                out[r, c] = (z_r * s_c + z_c * s_r) / (s_r + s_c)
            elif estimates:
                out[r, c] = estimates[0][0]
    return out


def test_scanline_fill_equals_its_pixel_by_pixel_definition_on_random_images():
    from methods.prior.raster import fill_scanline
    rng = np.random.default_rng()
    for _ in range(4):
        shape = tuple(rng.integers(5, 40, 2))
        image = rng.uniform(0.2, 0.4, shape)
        image[rng.random(shape) < rng.uniform(0.2, 0.9)] = np.nan
        expected = _scanline_by_loops(image)
        got = fill_scanline(image)
        assert np.array_equal(np.isfinite(got), np.isfinite(expected))
        assert np.max(np.abs(got - expected), where=np.isfinite(expected), initial=0.0) < 1e-15


def test_scanline_fill_reproduces_a_plane_and_fills_what_delaunay_fills_but_concave_notches():
    from methods.prior.raster import fill_scanline
    rows, cols = np.mgrid[:60, :60].astype(float)
    truth = 0.3 + 0.001 * cols - 0.002 * rows
    image = truth.copy()
    image[(rows - 30) ** 2 + (cols - 30) ** 2 > 25 ** 2] = np.nan        # a disk ...
    image[(cols > 40) & (rows < 20)] = np.nan                             # ... with a notch at its rim
    holes = ((rows - 30) ** 2 + (cols - 25) ** 2 < 6 ** 2) | ((rows - 40) ** 2 + (cols - 40) ** 2 < 3 ** 2)
    image[holes] = np.nan                                                 # ... and two holes
    filled = fill_scanline(image)
    assert np.all(np.isfinite(filled[holes]))
    assert np.max(np.abs(filled - truth), where=np.isfinite(filled), initial=0.0) < 1e-12
    delaunay = fill_convex_hull(image)
    assert not np.any(np.isfinite(filled) & np.isnan(delaunay))          # never beyond the convex hull
    assert np.isnan(filled[5, 50]) and np.isfinite(delaunay[12, 43])     # the notch's far corner stays empty


def test_unknown_fill_is_a_usage_error():
    from methods.domain.errors import UsageError
    frame = plane_depth_frame(*PLANE, realsense2radar())
    with pytest.raises(UsageError, match="scanline"):
        realsense_prior_m(frame, realsense2radar(), GRID, fill="nearest")
