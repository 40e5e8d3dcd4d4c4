"""The batched intervals and paired tests give, bit for bit, what one SciPy call per row or pair gives."""
import numpy as np
import pytest
from scipy import stats

from bench.report import uncertainty


def _one_interval(values) -> tuple:
    """The interval as one `stats.bootstrap` call per row computes it (the code before batching)."""
    values = np.asarray(values, dtype=float)
    values = values[np.isfinite(values)]
    if values.size < 2 or np.ptp(values) == 0:
        return None
    found = stats.bootstrap((values,), np.mean, confidence_level=uncertainty.CONFIDENCE,
                            n_resamples=uncertainty.RESAMPLES, method="percentile",
                            rng=np.random.default_rng(uncertainty.SEED)).confidence_interval
    return float(values.mean()), float(found.low), float(found.high), int(values.size)


def _one_p_value(a, b) -> float | None:
    """The p-value as one `stats.permutation_test` call per pair computes it (the code before batching)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    both = np.isfinite(a) & np.isfinite(b)
    a, b = a[both], b[both]
    if a.size < 2 or not np.any(a - b):
        return None
    return float(stats.permutation_test((a, b), lambda x, y, axis=-1: np.mean(x - y, axis=axis),
                                        permutation_type="samples", vectorized=True,
                                        n_resamples=uncertainty.RESAMPLES, alternative="two-sided",
                                        rng=np.random.default_rng(uncertainty.SEED)).pvalue)


def _rows(seed: int, n_rows: int, n: int) -> np.ndarray:
    """Per-capture values as a table has them: positive, of several scales, some NaN (not counted), a tie."""
    rng = np.random.default_rng(seed)
    rows = rng.gamma(2.0, rng.uniform(0.05, 5.0, (n_rows, 1)), (n_rows, n))
    rows[rng.random((n_rows, n)) < 0.15] = np.nan
    rows[0] = rows[1]                         # a tie: the pair's differences are all zero
    rows[2, :] = 0.7                          # no spread: the interval is the mean itself
    return rows


@pytest.mark.parametrize("n", [1, 2, 5, 8, 13, 15])
def test_batched_intervals_equal_one_call_per_row(n):
    rows = _rows(n, 9, n)
    batched = uncertainty.mean_intervals(rows)
    for values, interval in zip(rows, batched, strict=True):
        expected = _one_interval(values)
        if expected is None:
            finite = values[np.isfinite(values)]
            assert interval.n == finite.size
            continue
        assert (interval.mean, interval.low, interval.high, interval.n) == expected      # bit for bit
    assert uncertainty.mean_interval(rows[3]) == batched[3]


@pytest.mark.parametrize("n", [2, 4, 8, 13, 14])      # 14 captures: 2^14 sign patterns, random ones (seeded)
def test_batched_paired_tests_equal_one_call_per_pair(n):
    rows = _rows(100 + n, 7, n)
    pairs = [(rows[i], rows[j]) for i in range(len(rows)) for j in range(i + 1, len(rows))]
    batched = uncertainty.paired_all(pairs)
    checked = 0
    for (a, b), result in zip(pairs, batched, strict=True):
        expected = _one_p_value(a, b)
        if expected is not None:
            assert result.p_value == expected                                               # bit for bit
            checked += 1
        both = np.isfinite(a) & np.isfinite(b)
        assert result.n == both.sum() and result.a_better == (a[both] < b[both]).sum()
    assert checked >= len(pairs) // 2
    assert batched[0].p_value == 1.0                  # rows 0 and 1 are equal
    assert uncertainty.paired(*pairs[5]) == batched[5]
