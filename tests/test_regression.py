"""Regression on metric values: a subset of the committed synthetic benchmark (results/<table>/results.csv) is
recomputed on the test fixture's captures (the same generator, preset, config and seeds as the benchmark's:
`results_root`) and compared.

Tolerance per metric: |new - baseline| <= max(0.05 cm, 10 % of the baseline). BLAS and libm differ in the last
bits across machines; that moves phases by ~1e-6 rad, which can flip a pixel at the edge of the dB filter, the
1 cm triangulation threshold or a 2FSK ambiguity. One flipped pixel among the ~10^3-10^4 compared ones changes a
mean by far less than 0.05 cm, and for the large means of ambiguous methods (several cm) by far less than 10 %;
real changes to a method or metric (a sign, a unit, a shifted grid) move the values by much more.
When a change is meant: `bash run.sh demo --update-results` regenerates the baselines (docs/guide/baselines.md).
"""
from __future__ import annotations

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from bench.harness.app import CONFIG_DIR, run
from bench.report.tables import METRICS_CM, RESULTS_DIR

ABS_TOL_CM = 0.05
REL_TOL = 0.10
CASES = [("table2", ["method=mm2fsk", "freq=d05", "prior=photogrammetry"]), ("table3", ["cell=mm2fsk_d10"]),
         ("table3", ["cell=2fsk_d05"]), ("table3", ["cell=3fsk_d05_d10"]), ("table3", ["cell=bp_d05"])]


@pytest.mark.parametrize("table, overrides", CASES, ids=[" ".join(o) for _, o in CASES])
def test_metrics_match_the_committed_baseline(results_root, tmp_path, table, overrides):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", overrides=["dataset=maroon", f"dataset.root={results_root}",
                                                      "store.dir=null", *overrides])
    new = pd.DataFrame(run(cfg, tmp_path)).set_index("object")
    baseline = pd.read_csv(RESULTS_DIR / table / "results.csv")
    baseline = baseline[(baseline.method == cfg.method.name) & (baseline.freq == cfg.freq.name)
                        & (baseline.prior == cfg.prior.name) & baseline.object.isin(new.index)].set_index("object")
    assert sorted(baseline.index) == sorted(new.index), f"{table}: baseline lacks {cfg.method.name} {cfg.freq.name}"
    for metric in METRICS_CM:
        tolerance = (baseline[metric].abs() * REL_TOL).clip(lower=ABS_TOL_CM)
        drift = (new[metric] - baseline[metric]).abs()
        same_nan = new[metric].isna() & baseline[metric].isna()
        assert ((drift <= tolerance) | same_nan).all(), f"{metric} drifted: new {new[metric].to_dict()}, " \
                                           f"baseline {baseline[metric].to_dict()}"
