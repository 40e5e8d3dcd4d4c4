"""The prior's depth-jump rule (our default and the reference's) and the faithful profile's prior construction,
checked against geometry and against the definitions (MAROON_FORMAT.md 2.4, 4.2, 6.3 step 4)."""
from __future__ import annotations

import numpy as np
from scipy.interpolate import LinearNDInterpolator

from bench.synth.memory import CAMERA, plane_depth_frame, realsense2radar, square_grid
from methods.prior.priors import delaunay_fill, realsense_prior_m

GRID = square_grid(0.15, 301)            # 301 x 301 pixels of 1 mm over +-15 cm


def _step_frame(cam2radar: np.ndarray):
    """A 10 x 10 cm box face at 0.30 m in front of a wall at 0.40 m (radar space), as the camera sees it."""
    wall = plane_depth_frame(0.40, 0.0, 0.0, cam2radar)
    box = plane_depth_frame(0.30, 0.0, 0.0, cam2radar)
    cols, rows = np.meshgrid(np.arange(CAMERA.width), np.arange(CAMERA.height))
    face = (np.abs(cols - CAMERA.cx) < 100) & (np.abs(rows - CAMERA.cy) < 100)
    wall.depth_mm[face] = box.depth_mm[face]
    return wall


def test_depth_jump_rule_invents_no_surface_between_the_box_and_the_wall():
    cam2radar = realsense2radar()
    frame = _step_frame(cam2radar)
    kept = realsense_prior_m(frame, cam2radar, GRID, fill_holes=False)               # default: 10 mm rule
    bridged = realsense_prior_m(frame, cam2radar, GRID, fill_holes=False, max_jump_mm=None)

    def between(prior_m):            # pixels farther than 1 mm from both real surfaces
        return np.isfinite(prior_m) & (np.abs(prior_m - 0.30) > 1e-3) & (np.abs(prior_m - 0.40) > 1e-3)

    # without the rule the triangles joining the box's rim to the wall behind it form a 'curtain' across the
    # parallax of the camera (8 cm above the array): many radar pixels get depths of no real surface
    assert between(bridged).sum() > 500
    assert between(kept).sum() == 0
    assert np.isfinite(kept).sum() > 0.9 * np.isfinite(bridged).sum() - between(bridged).sum()


def test_faithful_prior_samples_at_the_reference_positions():
    cam2radar = realsense2radar()
    slope_x = 0.5
    frame = plane_depth_frame(0.31, slope_x, 0.0, cam2radar, depth_scale_m=1e-4)
    faithful = realsense_prior_m(frame, cam2radar, GRID, faithful=True)
    sound = realsense_prior_m(frame, cam2radar, GRID)
    # MAROON samples column u at x = bx + (u + 0.5) (Bx - bx) / 300 with bx, Bx = -+0.1505 m (half a pixel out)
    u = np.arange(301)
    x_sample_m = -0.1505 + (u + 0.5) * 0.301 / 300
    x_centre_m = -0.15 + 0.001 * u
    cols = slice(280, 301)                                  # the right edge: samples ~1 mm right of the centres
    rows = slice(100, 200)
    for prior_m, x_m in ((faithful, x_sample_m), (sound, x_centre_m)):
        error_mm = 1e3 * np.abs(prior_m[rows, cols] - (0.31 + slope_x * x_m[cols]))
        assert np.isfinite(error_mm).all() and error_mm.max() < 0.1      # depth units of 0.1 mm
    assert np.nanmin(faithful[rows, cols] - sound[rows, cols]) > 0.4e-3  # 0.5 * ~0.95-1.0 mm


def test_faithful_hole_filling_is_the_delaunay_interpolation_of_all_covered_pixels():
    rng = np.random.default_rng(7)
    rows, cols = np.mgrid[:40, :50]
    image = 0.3 + 0.02 * np.sin(cols / 5.0) * np.cos(rows / 7.0)            # a curved surface
    image[rng.random(image.shape) < 0.25] = np.nan                           # a quarter of the pixels missing
    image[10:20, 15:30] = np.nan                                              # and a large hole
    filled = delaunay_fill(image)
    covered = np.isfinite(image)
    r, c = np.nonzero(covered)
    expected = LinearNDInterpolator(np.column_stack([c, r]).astype(float), image[r, c])(cols, rows)
    np.testing.assert_array_equal(filled[covered], image[covered])
    inside = np.isfinite(expected)
    assert np.array_equal(np.isfinite(filled), inside)
    np.testing.assert_allclose(filled[inside], expected[inside], rtol=0, atol=1e-12)
    assert (inside & ~covered).sum() > 150
