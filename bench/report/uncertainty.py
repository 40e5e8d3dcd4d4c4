"""How sure a table's numbers are: bootstrap confidence intervals of means over captures and paired comparisons
of two rows on the same captures (SciPy's `bootstrap` and `permutation_test`; nothing hand-made).

* `mean_interval`: the mean of per-capture values and its 95 % bootstrap interval (percentile method, resampling
  captures). With a handful of captures such an interval is too narrow rather than too wide: read it as a lower
  bound on the uncertainty. One capture: no interval (NaN).
* `paired`: row A against row B on the captures both count: in how many A is lower (better), the mean difference
  A - B, and the two-sided p-value of a paired permutation test (the sign of each capture's difference flipped at
  random: exact, all 2^n sign patterns, for up to 13 captures). p-values are per comparison, not corrected for the
  number of comparisons a table makes.
Results are reproducible: a fixed seed. `mean_intervals` and `paired_all` give the same numbers for many rows or
pairs with one SciPy call per number of captures (each call's resamples and sign patterns depend only on that
number and the seed, so a batch draws exactly what each call alone draws): a table's 84 intervals and 364
comparisons cost ~0.05 s instead of ~0.8 s.
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
    return mean_intervals([values])[0]


def mean_intervals(rows) -> list[Interval]:
    """`mean_interval` of each of `rows` (sequences of values), bootstrapped together per number of finite values."""
    finite = [np.asarray(values, dtype=float) for values in rows]
    finite = [values[np.isfinite(values)] for values in finite]
    found: list[Interval | None] = [None] * len(finite)
    batches: dict[int, list[int]] = {}
    for index, values in enumerate(finite):
        if values.size == 0:
            found[index] = Interval(np.nan, np.nan, np.nan, 0)
        elif values.size == 1 or np.ptp(values) == 0:
            mean = float(values.mean())
            low = high = np.nan if values.size == 1 else mean
            found[index] = Interval(mean, low, high, int(values.size))
        else:
            batches.setdefault(values.size, []).append(index)
    for n, indices in batches.items():
        batch = np.stack([finite[index] for index in indices])
        interval = stats.bootstrap((batch,), _row_means, confidence_level=CONFIDENCE, n_resamples=RESAMPLES,
                                   method="percentile", axis=-1, rng=np.random.default_rng(SEED)).confidence_interval
        for index, low, high in zip(indices, np.atleast_1d(interval.low), np.atleast_1d(interval.high), strict=True):
            found[index] = Interval(float(finite[index].mean()), float(low), float(high), n)
    return found


def p_text(value: float) -> str:
    """A p-value as text: two significant digits, 'n/a' where there is none (fewer than two captures)."""
    return "n/a" if not np.isfinite(value) else f"{value:.2g}"


def _mean_difference(a, b, axis=-1):
    return np.mean(a - b, axis=axis)


# The statistics of a batch (rows stacked along a batch axis) evaluated row by row, as each row's own call
# evaluates it: NumPy sums a 3-d array's last axis in another order than a 2-d one's, which moves the last digit.
def _row_means(batch, axis=-1):
    """`stats.bootstrap`'s statistic of a batch: (k, n) values or (k, resamples, n) resamples, rows first."""
    return np.stack([np.mean(row, axis=axis) for row in batch])


def _row_mean_differences(a, b, axis=-1):
    """`stats.permutation_test`'s statistic of a batch: (k, n) pairs or (permutations, k, n), rows second."""
    rows = a.ndim - 2
    row = (slice(None),) * rows
    return np.stack([_mean_difference(a[(*row, j)], b[(*row, j)], axis) for j in range(a.shape[rows])], axis=rows)


def paired(a, b) -> Paired:
    """Row A against row B on the captures where both are finite (same order of captures in `a` and `b`)."""
    return paired_all([(a, b)])[0]


def paired_all(pairs) -> list[Paired]:
    """`paired` of each (a, b) of `pairs`, the permutation tests run together per number of common captures."""
    kept = []
    for a, b in pairs:
        a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
        both = np.isfinite(a) & np.isfinite(b)
        kept.append((a[both], b[both]))
    p_values = [np.nan] * len(kept)
    batches: dict[int, list[int]] = {}
    for index, (a, b) in enumerate(kept):
        if not np.any(a - b):
            p_values[index] = 1.0 if a.size else np.nan
        elif a.size >= 2:
            batches.setdefault(a.size, []).append(index)
    for indices in batches.values():
        a, b = (np.stack([kept[index][side] for index in indices]) for side in (0, 1))
        found = stats.permutation_test((a, b), _row_mean_differences, permutation_type="samples", vectorized=True,
                                       n_resamples=RESAMPLES, alternative="two-sided", axis=-1,
                                       rng=np.random.default_rng(SEED)).pvalue
        for index, p_value in zip(indices, np.atleast_1d(found), strict=True):
            p_values[index] = float(p_value)
    results = []
    for (a, b), p_value in zip(kept, p_values, strict=True):
        if a.size == 0:
            results.append(Paired(0, 0, 0, np.nan, np.nan))
            continue
        diff = a - b
        results.append(Paired(int(a.size), int((diff < 0).sum()), int((diff > 0).sum()), float(diff.mean()),
                              p_value))
    return results
