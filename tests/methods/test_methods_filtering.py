"""Depth filter: keep pixels within threshold_db of the strongest, the rest (and unevaluated ones) NaN."""
from __future__ import annotations

import numpy as np
import pytest

from methods.ops.filtering import filter_depth, keep_mask


def test_threshold_is_relative_to_the_maximum_in_db_of_linear_magnitude():
    magnitude = np.array([[10.0, 10 * 10 ** (-13.9 / 20), 10 * 10 ** (-14.1 / 20)], [0.0, np.nan, 5.5]])
    depth_m = np.full(magnitude.shape, 0.3)
    filtered = filter_depth(depth_m, magnitude)                     # default 14 dB
    assert np.isfinite(filtered).tolist() == [[True, True, False], [False, False, True]]
    assert keep_mask(magnitude * 1e-6).tolist() == keep_mask(magnitude).tolist()   # scale-free
    assert keep_mask(magnitude, threshold_db=6.0).tolist() == [[True, False, False], [False, False, True]]


def test_threshold_none_keeps_every_evaluated_pixel_and_negative_is_refused():
    magnitude = np.array([1.0, 1e-9, np.nan])
    assert keep_mask(magnitude, threshold_db=None).tolist() == [True, True, False]
    assert keep_mask(np.full(3, np.nan)).tolist() == [False, False, False]
    with pytest.raises(ValueError, match="below the maximum"):
        keep_mask(magnitude, threshold_db=-3.0)
