"""bench.perf.skips.cpu: how the depth agreement counts pixels valid in one map only."""
from __future__ import annotations

import numpy as np

from bench.perf.skips.cpu import METRICS, compare


def test_agreement_over_either_map_counts_a_lost_or_gained_pixel_as_wrong():
    full = np.array([0.30, 0.31, 0.32, np.nan, 0.34])
    skip = np.array([0.30005, 0.3102, np.nan, 0.33, 0.34])      # within, off, lost, gained, within
    scores = dict.fromkeys(METRICS, 1.0)
    c = compare(full, skip, scores, scores)
    assert (c.valid_full, c.valid_skip, c.valid_both) == (4, 4, 3)
    assert np.isclose(c.agree_pct, 200 / 3) and np.isclose(c.agree_either_pct, 40.0)
