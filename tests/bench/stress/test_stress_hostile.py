"""Stress suite, hostile input: every degenerate or malicious case ends in a clear error naming the file or an
explicit all-invalid result; no traceback, no RuntimeWarning, no changed dataset, no executed pickle."""
from __future__ import annotations

import pytest

from bench.stress import hostile

ALL_INVALID = {"all_zero_frame", "empty_mask", "memory_prior_outside_grid"}
NOTHING_COMPARABLE = {"one_pixel_object"}                       # one valid pixel, no metric triangle
VALUE_ERRORS = {"memory_nan_signal", "memory_freqs_in_ghz", "mesh_missing"}


@pytest.fixture(scope="module")
def source_capture(synth_capture):
    return synth_capture("01_plate", 30, frequency_points=16)


@pytest.mark.parametrize("case", hostile.CASES)
def test_hostile_case_ends_cleanly(case, source_capture, tmp_path):
    row = hostile.run_case(case, source_capture, tmp_path)
    assert row["runtime_warnings"] == 0 and row["dataset_unchanged"] and not row["pickle_executed"], row
    if case in ALL_INVALID:
        assert row["outcome"] == "all-invalid" and row["valid_px"] == 0 and row["invalid_reason"], row
    elif case in NOTHING_COMPARABLE:
        assert row["outcome"] == "nothing-comparable" and row["valid_px"] == 1, row
    elif case in VALUE_ERRORS:
        assert row["outcome"] == "error" and row["message"].startswith(("ValueError: ", "UsageError: ")), row
    else:                                                        # a DatasetError naming the file in the capture
        assert row["outcome"] == "error" and row["message"].startswith(f"DatasetError: {tmp_path / case}"), row
