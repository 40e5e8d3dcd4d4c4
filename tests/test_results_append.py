"""results.csv grows by appended lines (bench.results.ResultsCsv): the same rows as a whole rewrite, and the rows of
finished frames survive an interruption of a long sequence (issue 13 item 5)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from bench.results import ResultsCsv, write_results

FRAMES = 10


def test_appended_rows_read_back_as_the_rewritten_table(tmp_path):
    rng = np.random.default_rng()
    rows = []
    for i in range(25):
        row = {"object": "01_plate", "distance": 30, "frame": i, "method": "mm2fsk", "P_cm": rng.random(),
               "roi_px": None if i % 3 else int(rng.integers(1000)), "failure": "" if i % 4 else "no valid, pixel"}
        if i >= 7:
            row["t_search_ms"] = rng.random()       # a column appearing mid-run: the header is rewritten
        if i == 11:
            row["C_g_cm"] = float("nan")
        rows.append(row)
    appended = ResultsCsv(tmp_path / "appended.csv")
    for row in rows:
        appended.add(row)
    write_results(tmp_path / "whole.csv", rows)
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "appended.csv"), pd.read_csv(tmp_path / "whole.csv"))


@pytest.fixture(scope="module")
def long_sequence(synth_capture):
    """A static plate seen in FRAMES radar frames (16 frequencies: cheap)."""
    return synth_capture("01_plate", 30, frames=FRAMES, frequency_points=16)


def _config(root, store):
    from hydra import compose, initialize_config_dir

    from bench.app import CONFIG_DIR

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=[
            "method=mm2fsk", "freq=d10", "prior=realsense", "dataset=maroon", f"dataset.root={root}",
            "dataset.frame=all", f"store.dir={store}"])


def test_rows_of_finished_frames_survive_an_interruption_and_the_rerun_completes_them(long_sequence, tmp_path,
                                                                                       monkeypatch):
    from bench import app

    cfg = _config(long_sequence.parent.parent, tmp_path / "store")
    write_depth, written = app.write_depth, []

    def interrupted_at_frame_7(out_dir, stem, *args):
        if len(written) == 7:
            raise KeyboardInterrupt                   # Ctrl-C (or a killed job) while the 8th frame is written
        written.append(stem)
        return write_depth(out_dir, stem, *args)

    monkeypatch.setattr(app, "write_depth", interrupted_at_frame_7)
    with pytest.raises(KeyboardInterrupt):
        app.run(cfg, tmp_path / "run")
    kept = pd.read_csv(tmp_path / "run" / "results.csv")
    assert list(kept.frame) == list(range(7)) and kept.P_cm.notna().all()
    monkeypatch.setattr(app, "write_depth", write_depth)
    rows = app.run(cfg, tmp_path / "run")                  # the same run directory: the file starts anew
    table = pd.read_csv(tmp_path / "run" / "results.csv")
    assert list(table.frame) == list(range(FRAMES))
    assert [r["cached"] for r in rows] == [True] * 8 + [False] * (FRAMES - 8)    # frame 7 was stored, not written
    pd.testing.assert_frame_equal(table.iloc[:7].drop(columns="cached"), kept.drop(columns="cached"))
    np.testing.assert_allclose(table.P_cm, [r["P_cm"] for r in rows], rtol=1e-15)
