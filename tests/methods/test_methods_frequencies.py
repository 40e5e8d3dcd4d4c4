"""Frequency configurations (paper Table I + 3FSK + full) and their selection from a frame's sweep."""
from __future__ import annotations

import numpy as np
import pytest

from methods.domain.radar import MAROON_FREQS_HZ
from methods.ops.frequencies import (
    CONFIGS_GHZ,
    config_indices,
    config_targets_ghz,
    max_unambiguous_depth_m,
    select_frequencies,
)


@pytest.mark.parametrize("name, indices, dd_max_cm", [
    ("d05", [120, 127], 13.60), ("d1", [114, 127], 7.32), ("d2", [101, 127], 3.66),
    ("d4", [75, 127], 1.83), ("d8", [25, 127], 0.93), ("d10", [0, 127], 0.75),
])
def test_two_frequency_configs_select_table1_indices_and_ranges(name, indices, dd_max_cm):
    selected = config_indices(MAROON_FREQS_HZ, name)
    assert selected.tolist() == indices
    delta_f_hz = np.diff(MAROON_FREQS_HZ[selected])[0]
    assert max_unambiguous_depth_m(delta_f_hz) * 100 == pytest.approx(dd_max_cm, abs=0.005)


@pytest.mark.parametrize("name, indices", [("d05_d10", [0, 120, 127]), ("d1_d10", [0, 114, 127]),
                                           ("d2_d10", [0, 101, 127])])
def test_three_frequency_configs(name, indices):
    assert config_indices(MAROON_FREQS_HZ, name).tolist() == indices


def test_full_selects_every_frequency_and_unknown_names_are_refused():
    assert config_indices(MAROON_FREQS_HZ, "full").tolist() == list(range(128))
    assert config_targets_ghz("full") is None
    assert set(CONFIGS_GHZ) >= {"d05", "d1", "d2", "d4", "d8", "d10", "full", "d05_d10", "d1_d10", "d2_d10"}
    with pytest.raises(ValueError, match="unknown frequency configuration 'd3'"):
        config_indices(MAROON_FREQS_HZ, "d3")


def test_nearest_present_frequency_is_used_and_collisions_are_refused():
    freqs_hz = np.array([72.0, 75.0, 80.0, 82.0]) * 1e9
    assert select_frequencies(freqs_hz, (81.45, 72.4)).tolist() == [0, 3]     # ascending, nearest
    with pytest.raises(ValueError, match="same frame frequency"):
        select_frequencies(freqs_hz, (81.45, 82.00))                        # both -> 82 GHz


def test_a_target_outside_the_frames_band_is_refused_naming_the_frame():
    from pathlib import Path

    from methods.api import frequency_indices

    freqs_hz = np.array([72.0, 75.0, 80.0, 82.0]) * 1e9
    assert select_frequencies(freqs_hz, (83.0, 72.0)).tolist() == [0, 3]     # within half the largest step (2.5 GHz)
    for targets in ((-82.0, 72.0), (90.0, 72.0), (72.0, 68.0)):             # negative or beyond the band
        with pytest.raises(ValueError, match="lies outside the frame's band 72.000-82.000 GHz"):
            select_frequencies(freqs_hz, targets)
    with pytest.raises(ValueError, match=r"^/data/01_plate/30/radar/000000\.npy: two target frequencies"):
        frequency_indices(freqs_hz, [81.45, 82.0], Path("/data/01_plate/30/radar/000000.npy"))
    with pytest.raises(ValueError, match="^unknown frequency configuration"):   # a setting, not the frame's fault
        frequency_indices(freqs_hz, "d3", Path("/data/01_plate/30/radar/000000.npy"))
