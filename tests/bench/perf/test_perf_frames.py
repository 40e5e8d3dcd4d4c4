"""bench.perf.frames (issue 13 item 1): catalogue-like masked scenes, a new frame per call, median and p90."""
from __future__ import annotations

import numpy as np
import pytest

from bench.perf import frames as perf_frames
from methods import reconstruct
from methods.prior.priors import realsense_prior_m


@pytest.fixture(scope="module")
def captures():
    return perf_frames.masked_captures()


def test_masked_objects_are_partly_visible_and_need_the_hull_fill(captures):
    for capture in captures:
        depth = capture.realsense
        assert 0.05 < depth.mask.mean() < 0.3                        # partly visible, masked
        assert np.count_nonzero(depth.mask & (depth.depth_mm == 0)) > 100   # holes inside the object
        args = (depth, capture.transforms["realsense2radar"], capture.radar.grid)
        open_px = np.isfinite(realsense_prior_m(*args, fill_holes=False)).sum()
        filled_px = np.isfinite(realsense_prior_m(*args, fill_holes=True)).sum()
        assert filled_px > open_px + 300 and filled_px < 0.2 * capture.radar.grid.size[0] ** 2


def test_a_new_frame_is_new_data_of_the_same_scene(captures):
    rng = np.random.default_rng(1)
    capture = captures[1]
    fresh = perf_frames.new_frame(capture, rng)
    assert fresh.radar.signal is not capture.radar.signal and fresh.realsense.depth_mm is not capture.realsense.depth_mm
    ratio = fresh.radar.signal / capture.radar.signal
    assert np.allclose(ratio, ratio.flat[0], atol=1e-5) and abs(abs(ratio.flat[0]) - 1) < 1e-6
    assert abs(np.angle(ratio.flat[0])) > 1e-3                        # rotated by a random phase
    valid = capture.realsense.depth_mm > 0
    step = fresh.realsense.depth_mm.astype(int) - capture.realsense.depth_mm.astype(int)
    assert set(np.unique(step[valid])) in ({1}, {-1}) and not step[~valid].any()
    # MM-2FSK is blind to a global phase; a 1 mm prior shift moves the depth of nearly every pixel by far less
    # than a millimetre (a few edge pixels, whose correlation is defocused, move more)
    same = reconstruct(capture, "mm2fsk", "d10", prior="realsense")
    new = reconstruct(fresh, "mm2fsk", "d10", prior="realsense")
    both = same.valid & new.valid
    assert both.sum() > 0.95 * same.valid.sum()
    change_m = np.abs(new.depth_m[both] - same.depth_m[both])
    assert np.median(change_m) < 2e-4 and np.mean(change_m < 1e-3) > 0.95


def test_time_case_reports_new_and_repeated_median_and_p90(captures):
    row = perf_frames.time_case(captures, "mm2fsk", "d10", "realsense", "cpu", repeat=3, bp_nz=2)
    for mode in ("new", "repeated"):
        for what in ("total", "wall"):
            median, p90 = row[f"{mode}_{what}_median_ms"], row[f"{mode}_{what}_p90_ms"]
            assert 0 < median <= p90
    assert row["new_prior_ms"] > 0 and row["new_correlate_ms"] > 0 and row["calls"] == 3
    assert row["scene"] == "disc+notched_plate+two_objects" and row["valid_px"] > 1000
