"""Fast paths of the per-frame CPU budget (issue 13 item 2) against the plain computation they replace."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bench.perf import frames as perf_frames
from methods.prior.priors import realsense_prior_m


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_prior_on_the_valid_pixels_bounding_box_equals_the_whole_image(seed):
    """The prior works on the bounding box of the valid depth pixels; two isolated valid pixels in opposite image
    corners (no triangle, so no prior of their own) make the box the whole image: the priors must be identical."""
    rng = np.random.default_rng(seed)
    pieces = list(perf_frames.MASKED_OBJECTS.values())[seed % len(perf_frames.MASKED_OBJECTS)]
    depth = perf_frames._masked_depth_frame(pieces, rng)
    noisy = np.where(depth.depth_mm > 0, depth.depth_mm.astype(int) + rng.integers(-3, 4, depth.depth_mm.shape), 0)
    depth = dataclasses.replace(depth, depth_mm=noisy.astype(np.uint16))
    whole_mm, whole_mask = depth.depth_mm.copy(), depth.mask.copy()
    whole_mm[0, 0] = whole_mm[-1, -1] = 300
    whole_mask[0, 0] = whole_mask[-1, -1] = True
    whole = dataclasses.replace(depth, depth_mm=whole_mm, mask=whole_mask)
    grid = perf_frames.GRID
    for fill in (False, True):
        boxed = realsense_prior_m(depth, perf_frames.REALSENSE2RADAR, grid, fill_holes=fill)
        reference = realsense_prior_m(whole, perf_frames.REALSENSE2RADAR, grid, fill_holes=fill)
        assert np.isfinite(boxed).sum() > 5000
        np.testing.assert_array_equal(boxed, reference)
