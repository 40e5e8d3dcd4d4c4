"""bench.report.placement: the scalar prior's windows from the frame's frequencies, where a capture's surface sits
against
them, and the catalogue's placement (some objects inside 2FSK's windows around the 0.40 m prior, some not)."""
from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from bench.report import agreement
from bench.report.placement import placement, windows_m
from bench.synth import CATALOGUE
from bench.synth.config import C_M_PER_S, SynthConfig, frequencies_hz
from bench.synth.scenes import build_scene


def test_windows_are_the_prior_plus_minus_c_over_four_delta_f():
    freqs_hz = frequencies_hz(SynthConfig())                         # the 128-frequency grid
    windows = windows_m(freqs_hz)
    step_hz = freqs_hz[1] - freqs_hz[0]
    assert windows["d05"] == pytest.approx((0.40 - C_M_PER_S / (4 * 7 * step_hz), 0.40 + C_M_PER_S / (4 * 7 * step_hz)))
    assert windows["d05"] == pytest.approx((0.264, 0.536), abs=1e-3)     # the 0.551 GHz pair
    near, far = windows_m(freqs_hz, ("d1",), prior_m=0.5)["d1"]
    assert near + far == pytest.approx(1.0) and 0.06 < far - 0.5 < 0.08


def _depth_range_m(name: str) -> tuple[float, float]:
    z = build_scene(name, 0.30).tris_m[..., 2]
    return float(z.min()), float(z.max())


def test_the_catalogue_at_30_cm_has_objects_inside_and_outside_each_scalar_prior_window():
    """The paper's setting: 2FSK from 0.40 m on objects at about 30 cm. Δ0.5's window holds most objects and not the
    near plate of 08; Δ1's holds no part of the flat plate and the far step of 05."""
    windows = windows_m(frequencies_hz(SynthConfig()))
    ranges = {name: _depth_range_m(name) for name in CATALOGUE}
    for config in ("d05", "d1"):
        near, far = windows[config]
        inside = [n for n, (lo, hi) in ranges.items() if lo >= near and hi <= far]
        touching = [n for n, (lo, hi) in ranges.items() if hi >= near and lo <= far]
        outside = [n for n in ranges if n not in inside]
        assert outside and (inside if config == "d05" else touching), (config, ranges)
    assert "08_two_objects" not in [n for n, (lo, hi) in ranges.items() if lo >= windows["d05"][0]]
    assert "05_steps" in [n for n, (lo, hi) in ranges.items() if hi >= windows["d1"][0]]


def test_placement_of_a_plate_at_30_cm_and_its_cells_p(synth_capture):
    capture = synth_capture("01_plate", 30, frequency_points=16)
    rows = agreement.cells_of_sweeps(None, pd.DataFrame([
        {"object": "01_plate", "distance": 30, "method": "2fsk", "freq": "d05", "P_cm": 0.3},
        {"object": "01_plate", "distance": 30, "method": "2fsk", "freq": "d1", "P_cm": 13.5}]))
    line = placement(capture.parent.parent, ["01_plate"], rows).iloc[0]
    assert 29.9 < line["surface near cm"] <= line["median cm"] <= line["far cm"] < 30.5
    shares = {c.split()[1]: line[c] for c in line.index if c.startswith("in ")}
    assert shares["Δ0.5"] == 1.0 and shares["Δ1.0"] == 0.0
    assert line["2FSK Δ0.5 P cm"] == 0.3 and line["2FSK Δ1.0 P cm"] == 13.5
    assert np.isnan(line["3FSK(Δ0.5, Δ10.0) P cm"])                   # no row of that cell


def test_from_results_with_the_captures_adds_the_measured_sections(synth_capture, tmp_path):
    capture = synth_capture("01_plate", 30, frequency_points=16)
    rows = pd.DataFrame([{"object": "01_plate", "distance": 30, "frame": 0, "method": "mm2fsk", "freq": "d10",
                          "prior": "realsense", "grid": "from_capture",
                          **{k: 0.2 for k in ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm")}}])
    table2 = rows.assign(prior="photogrammetry")
    path = agreement.write_from_sweeps(table2, rows, tmp_path / "a.md", "realistic", capture.parent.parent)
    text = path.read_text()
    assert "## Placement against the scalar prior's windows" in text and "| 01_plate | 30." in text
    assert "## The RealSense prior against the ground truth" in text
    bare = agreement.write_from_sweeps(table2, rows, tmp_path / "b.md", "realistic").read_text()
    assert "Placement" not in bare
