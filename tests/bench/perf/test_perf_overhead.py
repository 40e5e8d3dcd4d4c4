"""Sweep overhead (issue 13 item 5): captures read once and ground truth built once per process, the rest timed."""
from __future__ import annotations

from bench.perf.overhead import STAGES, measure


def test_later_cells_reuse_the_read_captures_and_ground_truth(synth_root, tmp_path, monkeypatch):
    from bench.harness import captures

    # empty process caches: other tests of this process may have read the capture already
    monkeypatch.setattr(captures, "_CAPTURES", type(captures._CAPTURES)())
    monkeypatch.setattr(captures, "_GROUND_TRUTHS", type(captures._GROUND_TRUTHS)())
    rows = measure(synth_root, ["mm2fsk_d10", "mm2fsk_d05"], ["01_plate/30"], "cpu", None, use_store=True,
                   work=tmp_path)
    first, second, total = rows
    assert first["read_s"] > 0 and first["ground_truth_s"] > 0 and first["frames"] == 1
    assert second["read_s"] == 0 and second["ground_truth_s"] == 0         # served from the process's caches
    for row in (first, second):
        assert row["method_s"] >= row["method_warm_s"] > 0 and row["store_key_s"] > 0 and row["outputs_s"] > 0
        assert all(row[f"{s}_s"] >= 0 for s in STAGES) and row["other_s"] >= 0     # other_s: the wall's rest
    assert total["cell"] == "total" and total["frames"] == 2


def test_a_capture_part_is_read_once_per_process(synth_root, monkeypatch):
    """BP's cell reads radar and mesh, MM-2FSK's then only the RealSense frame (paired like read_capture pairs)."""
    import numpy as np

    from bench.harness import captures
    from bench.maroon import reader

    asked = []
    read = reader.read_capture
    monkeypatch.setattr(reader, "read_capture", lambda *a, **k: asked.append(k["parts"]) or read(*a, **k))
    monkeypatch.setattr(captures, "_CAPTURES", type(captures._CAPTURES)())
    capture_dir = synth_root / "01_plate" / "30"
    first = captures.read(capture_dir, -1, ("radar", "mesh"), False, (None, None))
    both = captures.read(capture_dir, -1, ("radar", "mesh", "realsense"), False, (None, None))
    again = captures.read(capture_dir, -1, ("radar", "mesh"), False, (None, None))
    assert asked == [("radar", "mesh"), ("realsense",)]
    assert first.realsense is None and again.realsense is None and both.radar is first.radar
    direct = read(capture_dir, parts=("radar", "mesh", "realsense"))
    assert both.realsense.index == direct.realsense.index
    np.testing.assert_array_equal(both.realsense.depth_mm, direct.realsense.depth_mm)
    np.testing.assert_array_equal(both.transforms["photogrammetry2radar"], direct.transforms["photogrammetry2radar"])
