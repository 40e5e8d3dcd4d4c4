"""bench.perf.stream (issue 13 item 4): frames per second through read, method and metrics, serial and overlapped."""
from __future__ import annotations

import argparse

import pytest

from bench.perf.stream import stream

SEQUENCE = {"frames": 3, "motion": "approach", "motion_speed_m_s": 0.1, "frequency_points": 16}  # as test_frames


def test_streaming_reads_computes_and_scores_every_frame_in_both_schedules(synth_capture):
    capture_dir = synth_capture("01_plate", 30, **SEQUENCE)
    args = argparse.Namespace(method="mm2fsk", freq="d10", prior="realsense", device="cpu", passes=1,
                              no_metrics=False)
    rows = stream(capture_dir, args)
    assert [row["schedule"] for row in rows] == ["serial", "overlapped"]
    for row in rows:
        assert row["frames"] == 3 and row["fps_median"] > 0 and row["fps_min"] <= row["fps_median"]
        assert row["read_ms"] > 0 and row["method_ms"] > 0 and row["metrics_ms"] > 0
        # each frame is scored against the ground truth at its own pose: the moving plate stays at ~mm error
        assert row["P_cm_mean"] < 0.2
        # a pass cannot be faster than its frames' method time (the stages are measured inside the pass)
        assert row["frame_ms_median"] >= 0.9 * row["method_ms"]
    assert rows[0]["P_cm_mean"] == pytest.approx(rows[1]["P_cm_mean"])      # same frames, same results
