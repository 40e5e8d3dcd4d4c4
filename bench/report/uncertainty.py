"""How sure a table's numbers are: bootstrap confidence intervals of means over captures and paired comparisons
of two rows on the same captures (SciPy's `bootstrap` and `permutation_test`; nothing hand-made).

* `mean_interval`: the mean of per-capture values and its 95 % bootstrap interval (percentile method, resampling
  captures). With a handful of captures such an interval is too narrow rather than too wide: read it as a lower
  bound on the uncertainty. One capture: no interval (NaN).
* `paired`: row A against row B on the captures both count: in how many A is lower (better), the mean difference
  A - B, and the two-sided p-value of a paired permutation test (the sign of each capture's difference flipped at
  random: exact, all 2^n sign patterns, for up to 13 captures). p-values are per comparison, not corrected for the
  number of comparisons a table makes.
Results are reproducible: a fixed seed.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

CONFIDENCE = 0.95
RESAMPLES = 9999
SEED = 0


@dataclass(frozen=True)
class Interval:
    mean: float
    low: float
    high: float
    n: int


@dataclass(frozen=True)
class Paired:
    n: int               # captures both rows count
    a_better: int        # captures where A's value is lower
    b_better: int
    mean_diff: float     # mean of A - B
    p_value: float       # two-sided paired permutation test of mean(A - B) = 0


def mean_interval(values) -> Interval:
    """Mean of the finite `values` and its bootstrap interval (CONFIDENCE, percentile method, RESAMPLES)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size == 0:
        return Interval(np.nan, np.nan, np.nan, 0)
    mean = float(values.mean())
    if values.size == 1 or np.ptp(values) == 0:
        low = high = np.nan if values.size == 1 else mean
        return Interval(mean, low, high, int(values.size))
    found = stats.bootstrap((values,), np.mean, confidence_level=CONFIDENCE, n_resamples=RESAMPLES,
                            method="percentile", rng=np.random.default_rng(SEED))
    return Interval(mean, float(found.confidence_interval.low), float(found.confidence_interval.high),
                    int(values.size))


def p_text(value: float) -> str:
    """A p-value as text: two significant digits, 'n/a' where there is none (fewer than two captures)."""
    return "n/a" if not np.isfinite(value) else f"{value:.2g}"


def _mean_difference(a, b, axis=-1):
    return np.mean(a - b, axis=axis)


def paired(a, b) -> Paired:
    """Row A against row B on the captures where both are finite (same order of captures in `a` and `b`)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    both = np.isfinite(a) & np.isfinite(b)
    a, b = a[both], b[both]
    if a.size == 0:
        return Paired(0, 0, 0, np.nan, np.nan)
    diff = a - b
    if a.size < 2 or not np.any(diff):
        p_value = 1.0 if not np.any(diff) else np.nan
    else:
        p_value = float(stats.permutation_test((a, b), _mean_difference, permutation_type="samples",
                                               vectorized=True, n_resamples=RESAMPLES, alternative="two-sided",
                                               rng=np.random.default_rng(SEED)).pvalue)
    return Paired(int(a.size), int((diff < 0).sum()), int((diff > 0).sum()), float(diff.mean()), p_value)
