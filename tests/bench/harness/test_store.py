"""The result store: content keys, atomic cells, cached digests, and a re-run computing only missing cells."""
from __future__ import annotations

import os

import numpy as np
import pandas as pd
from hydra import compose, initialize_config_dir

from bench.harness.app import CONFIG_DIR, run
from bench.harness.results import MEASURED_COLUMNS
from bench.harness.store import Store, capture_files, code_version

ROW = {"key": "abc", "object": "01_plate", "distance": 30, "frame": 0, "method": "bp", "valid_px": 12,
       "runtime_ms": 1.5, "timing": "alone", "P_cm": 0.25}
GRID_ATTRS = {"bb_min_m": [-0.1, -0.1, 0.2], "bb_max_m": [0.1, 0.1, 0.4], "grid_size": [4, 3, 1]}


def test_put_get_round_trip_and_no_partial_cell(tmp_path):
    store = Store(tmp_path)
    arrays = {"depth_m": np.full((3, 4), 0.3), "magnitude": np.ones((3, 4)), "gt_depth_m": np.full((3, 4), np.nan)}
    assert store.get("abc") is None
    store.put("abc", ROW, arrays, GRID_ATTRS)
    row, back, attrs = store.get("abc")
    assert row == ROW and list(attrs["grid_size"]) == [4, 3, 1]
    assert (back["depth_m"] == 0.3).all()
    assert np.isnan(back["gt_depth_m"]).all()
    assert sorted(p.name for p in (tmp_path / "cells").iterdir()) == ["abc.h5", "abc.json"]   # no temp files left


def test_key_depends_on_every_field():
    base = {"method": "bp", "freq": [72.0, 82.0], "capture": "x"}
    keys = {Store.key(base), Store.key({**base, "method": "2fsk"}), Store.key({**base, "freq": [72.0]}),
            Store.key({**base, "capture": "y"})}
    assert len(keys) == 4 and Store.key(dict(reversed(base.items()))) == Store.key(base)


def test_capture_digest_follows_content_and_is_cached_by_stat(tmp_path, synth_root, monkeypatch):
    monkeypatch.setattr("bench.harness.store.RACY_S", 0.0)       # the fixture's files may be younger than a second
    store = Store(tmp_path / "store")
    files = capture_files(synth_root / "01_plate" / "30", -1, ("radar", "mesh", "realsense"), False)
    names = {f.name for f in files}
    assert {"metadata.json", "alignment.json", "calibration.json", "000000.npy", "000000.png"} <= names
    first = store.capture_digest(files)
    assert store.capture_digest(files) == first and len(list((tmp_path / "store" / "digests").iterdir())) == len(files)
    copy = tmp_path / "meta.json"
    copy.write_bytes(files[0].read_bytes())
    assert store.file_digest(copy) == store.file_digest(files[0])
    copy.write_bytes(files[0].read_bytes() + b" ")
    assert store.file_digest(copy) != store.file_digest(files[0])


def test_code_version_names_the_package():
    assert code_version().startswith("0.1.0+") and code_version() == code_version()


def test_rerun_reads_finished_cells_from_the_store(synth_root, tmp_path):
    overrides = ["dataset=maroon", f"dataset.root={synth_root}", "method=mm2fsk", "freq=d10", "prior=photogrammetry",
                 f"store.dir={tmp_path / 'store'}"]
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        cfg = compose(config_name="config", overrides=overrides)
        first = pd.DataFrame(run(cfg, tmp_path / "a"))
        (cell,) = [p for p in (tmp_path / "store" / "cells").glob("*.json") if "03_sphere" in p.read_text()]
        os.remove(cell)                                   # as if the run had been interrupted before this cell
        second = pd.DataFrame(run(cfg, tmp_path / "b"))
        third = pd.DataFrame(run(compose(config_name="config", overrides=[*overrides, "freq=d8"]), tmp_path / "c"))
    assert not first.cached.any() and not third.cached.any()
    assert second.set_index("object").cached.to_dict() == {"01_plate": True, "03_sphere": False}
    pd.testing.assert_frame_equal(first.drop(columns=["cached", *MEASURED_COLUMNS] + [c for c in first
                                                                                      if c.startswith("t_")]),
                                  second.drop(columns=["cached", *MEASURED_COLUMNS] + [c for c in first
                                                                                       if c.startswith("t_")]),
                                  check_like=True)
    assert (tmp_path / "b" / "depth" / "01_plate_30_000000.png").read_bytes() == \
        (tmp_path / "a" / "depth" / "01_plate_30_000000.png").read_bytes()
