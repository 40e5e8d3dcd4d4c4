"""Frame sequences (issue 13 item 3): frame selection, time pairing, moving synthetic sequences with per-frame
ground truth, per-frame rows through `python -m bench`, tables that average a capture's frames first."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from bench.harness.store import capture_files
from bench.maroon import reader
from bench.maroon.frames import pair_nearest, parse_frame_spec, realsense_times_s, select_frames
from bench.report.tables import caption, summarise
from methods.domain.errors import DatasetError

SEQUENCE = {"frames": 3, "motion": "approach", "motion_speed_m_s": 0.1, "frequency_points": 16}


@pytest.mark.parametrize("spec, expected", [
    (-1, [11]), ("all", list(range(12))), ("0:10", list(range(10))), ("::4", [0, 4, 8]), ("-2:", [10, 11]),
    ("[0,3,5]", [0, 3, 5]), ([1, -1], [1, 11]), ("7", [7]), (0, [0]),
])
def test_frame_specs_select_from_the_sorted_frame_list(spec, expected):
    assert select_frames(range(12), spec, Path("x")) == expected


@pytest.mark.parametrize("spec", ["abc", "1:2:0", True, "[a]", 1.5, "1..3"])
def test_bad_frame_specs_are_one_line_value_errors(spec):
    with pytest.raises(ValueError, match="dataset.frame"):
        parse_frame_spec(spec)


@pytest.mark.parametrize("spec, message", [(12, "frame 12 not present"), (-13, "frame -13 not present"),
                                           ("20:30", "selects none"), ("[3,40]", "frame 40 not present")])
def test_frames_that_do_not_exist_name_the_folder(spec, message):
    with pytest.raises(DatasetError, match=message):
        select_frames(range(12), spec, Path("calibrated_data"))


def test_pairing_takes_the_nearest_time_and_maroons_last_frame_without_times():
    times = {0: 0.90, 1: 1.02, 2: 1.10}
    nearest = pair_nearest(1.0, [0, 1, 2], times)
    assert (nearest.realsense_frame, nearest.rule) == (1, "nearest") and nearest.offset_s == pytest.approx(0.02)
    assert pair_nearest(0.0, [0, 1, 2], times).realsense_frame == 0
    assert pair_nearest(9.0, [0, 1, 2], times).realsense_frame == 2
    assert pair_nearest(0.96, [0, 1, 2], times).realsense_frame == 0          # a tie goes to the earlier frame
    for missing in (pair_nearest(None, [0, 1, 2], times), pair_nearest(1.0, [0, 1, 2], None)):
        assert missing.realsense_frame == 2 and missing.rule == "last" and np.isnan(missing.offset_s)


def test_temporal_alignment_shifts_the_realsense_clock(tmp_path):
    realsense = tmp_path / "realsense"
    realsense.mkdir()
    (realsense / "timestamps.txt").write_text("filename absolute_system[ns]\n000000 1000000000\n000001 2000000000\n")
    assert realsense_times_s(realsense) == {0: 1.0, 1: 2.0}
    (tmp_path / "temporal_alignment.json").write_text(json.dumps({"realsense2radar": {"shift_seconds": -0.25}}))
    assert realsense_times_s(realsense) == {0: 0.75, 1: 1.75}
    (realsense / "timestamps.txt").write_text("filename x\n000000 12abc\n")
    with pytest.raises(DatasetError, match="line 2"):
        realsense_times_s(realsense)


@pytest.fixture(scope="module")
def sequence(synth_capture):
    """A plate approaching the array at 0.1 m/s: 3 radar frames 0.1 s apart, RealSense at 30 Hz."""
    return synth_capture("01_plate", 30, **SEQUENCE)


def test_a_moving_sequence_has_both_clocks_and_a_pose_per_radar_frame(sequence):
    captures = [reader.read_capture(sequence, frame=i) for i in range(3)]
    radar_s = np.array([c.radar.timestamp_s for c in captures])
    assert np.allclose(np.diff(radar_s), 0.1, atol=1e-5)
    times = realsense_times_s(sequence / "realsense")
    assert len(times) == 7 and np.allclose(np.diff(sorted(times.values())), 1 / 30, atol=1e-6)
    for capture in captures:                   # each radar frame gets the RealSense frame 7 ms after it
        pairing = reader.realsense_pairing(sequence / "realsense", capture.radar.timestamp_s)
        assert capture.realsense.index == pairing.realsense_frame
        assert pairing.offset_s == pytest.approx(0.007, abs=1e-5)
    # the mesh pose follows the object: -1 cm in z per frame (0.1 m/s x 0.1 s), nothing else
    shifts = [c.transforms["photogrammetry2radar"][:3, 3] - captures[1].transforms["photogrammetry2radar"][:3, 3]
              for c in captures]
    assert np.allclose(shifts, [[0, 0, 0.01], [0, 0, 0], [0, 0, -0.01]], atol=1e-9)
    # the RealSense depth sees it move too: the plate's median depth in the mask shrinks by ~1 cm per radar frame
    depth_mm = [np.median(c.realsense.depth_mm[c.realsense.mask & (c.realsense.depth_mm > 0)]) for c in captures]
    assert np.allclose(np.diff(depth_mm), -10, atol=2)


def test_the_store_key_covers_the_paired_realsense_frame_and_the_pose(sequence):
    files = {p.relative_to(sequence).as_posix() for p in capture_files(sequence, 1, ("radar", "realsense", "mesh"),
                                                                        False)}
    assert {"realsense/depth/000003.png", "realsense/mask/000003.png", "realsense/timestamps.txt",
            "photogrammetry/poses/000001.json"} <= files
    assert not any(name.startswith("realsense/depth/") and name != "realsense/depth/000003.png" for name in files)


def test_frame_all_gives_one_row_per_frame_scored_against_that_frames_ground_truth(sequence, tmp_path):
    out = tmp_path / "run"
    result = subprocess.run([sys.executable, "-m", "bench", "dataset=maroon", f"dataset.root={sequence.parent.parent}",
                             "dataset.frame=all", "method=mm2fsk", "freq=d10", "prior=realsense",
                             f"store.dir={tmp_path / 'store'}", f"hydra.run.dir={out}"],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    assert "1 capture (3 frames), 3 computed" in result.stdout
    rows = pd.read_csv(out / "results.csv")
    assert list(rows.frame) == [0, 1, 2] and list(rows.realsense_frame) == [0, 3, 6]
    assert (rows.pairing == "nearest").all() and np.allclose(rows.realsense_offset_ms, 7.0, atol=0.01)
    # the plate moved 2 cm: with a static ground truth the first and last frame would be off by ~1 cm
    assert (rows.P_cm < 0.2).all()
    depth_m = [np.nanmedian(np.where(d > 0, d, np.nan)) for d in
               (np.asarray(__import__("PIL.Image").Image.open(out / "depth" / f"01_plate_30_{i:06d}.png"))
                for i in range(3))]
    assert np.allclose(np.diff(depth_m), -10, atol=2)                       # millimetres
    bad = subprocess.run([sys.executable, "-m", "bench", "dataset=maroon", f"dataset.root={sequence.parent.parent}",
                          "dataset.frame=5:9", "store.dir=null", f"hydra.run.dir={tmp_path / 'bad'}"],
                         capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "frame range 5:9 selects none of the 3 frames" in bad.stderr


def _frame_rows(frames_per_capture: dict[str, list[float]], failed: tuple = ()) -> pd.DataFrame:
    return pd.DataFrame([{"object": obj, "distance": 30, "frame": i, "method": "mm2fsk", "freq": "d10",
                          "prior": "realsense", "grid": "g", "runtime_ms": 10.0 * (i + 1), "timing": "alone",
                          "C_g_cm": v, "C_s_cm": v, "P_cm": v, "P_e_cm": v, "off_pct": 0.0, "off_px": 0,
                          "off_err_cm": float("nan"), "failure": "no valid pixels" if (obj, i) in failed else ""}
                         for obj, values in frames_per_capture.items() for i, v in enumerate(values)])


def test_tables_average_each_captures_frames_first():
    rows = _frame_rows({"01_plate": [1.0, 1.0, 1.0, 1.0], "03_sphere": [3.0]})
    assert "2 captures (01_plate, 03_sphere) at 30 cm, 5 frames, each capture's frames averaged first" in \
        caption("table3", rows.assign(device="cpu"))
    summary = summarise(rows)
    line = summary.iloc[0]
    assert line.captures == 2 and line.ok == 2 and line.failed == 0
    assert line.P_cm == pytest.approx(2.0)                  # (1 + 3) / 2, not (4 x 1 + 3) / 5
    assert line.runtime_ms == pytest.approx((25.0 + 10.0) / 2)
    failed = summarise(_frame_rows({"01_plate": [1.0, 1.0], "03_sphere": [3.0]}, failed={("01_plate", 1)})).iloc[0]
    assert failed.ok == 1 and failed.failed == 1 and failed.P_cm == pytest.approx(3.0)
