"""bench.perf.fill: MM-2FSK with each prior fill on the same captures: a row per fill and configuration with its
metrics, and a comparison row whose numbers describe the two fills' real difference on these captures."""
from __future__ import annotations

import numpy as np


def test_perf_fill_rows_compare_the_fills_on_the_same_frames(synth_root, tmp_path):
    from bench.perf import fill as perf_fill
    from methods.prior.priors import FILLS

    captures = perf_fill._captures(synth_root)[:1]
    rows = perf_fill.compare_fills(captures, ["d10"], "cpu", repeat=1)
    by_fill = {row["fill"]: row for row in rows}
    assert set(FILLS) <= set(by_fill)
    for fill in FILLS:
        assert by_fill[fill]["ok"] == 1 and by_fill[fill]["prior_ms_median"] > 0
        assert all(np.isfinite(by_fill[fill][m]) for m in perf_fill.METRICS)
    comparison = by_fill[" vs ".join(FILLS)]
    assert 0.0 <= comparison["depth_agree_0.1mm_pct_worst"] <= 100.0
    assert comparison["prior_px_in_one_only"] >= 0 and comparison["prior_max_diff_mm"] >= 0.0
    perf_fill.write_rows(rows, tmp_path / "perf_fill.csv")
    assert (tmp_path / "perf_fill.csv").read_text().startswith("fill,freq,device")
