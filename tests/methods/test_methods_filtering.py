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


def _keep_mask_by_definition(magnitude, threshold_db):
    finite = np.isfinite(magnitude) & (magnitude > 0)
    if not finite.any():
        return finite
    return finite & (magnitude >= np.max(magnitude[finite]) * 10.0 ** (-threshold_db / 20.0))


@pytest.mark.parametrize("seed", range(20))
def test_fast_keep_mask_is_the_definition_on_random_maps_with_nan_zero_and_inf(seed):
    """The one-pass rule (NaN-skipping maximum, one comparison) keeps exactly the pixels the definition keeps, also
    with zeros, negative values, -Inf, +Inf (the general rule then), all-NaN maps and float32 maps."""
    rng = np.random.default_rng(seed)
    magnitude = rng.lognormal(0.0, 2.0, size=(31, 29)).astype(np.float32 if seed % 2 else np.float64)
    for value, share in ((np.nan, 0.3), (0.0, 0.05), (-1.0, 0.02), (-np.inf, 0.01 * (seed % 3 == 0)),
                         (np.inf, 0.002 * (seed % 5 == 0))):
        magnitude[rng.random(magnitude.shape) < share] = value
    if seed == 7:
        magnitude[:] = np.nan
    for threshold_db in (0.0, 6.0, 14.0, 300.0):
        assert np.array_equal(keep_mask(magnitude, threshold_db), _keep_mask_by_definition(magnitude, threshold_db))
