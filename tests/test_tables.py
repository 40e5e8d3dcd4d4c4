"""Table I from the frequency grid matches the paper; the Hydra frequency configs match the methods' table."""
from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from bench.tables import table1
from methods.frequencies import CONFIGS_GHZ

PAPER_TABLE1 = {  # config: (f1_GHz, f2_GHz, dd_max_cm), paper Table I
    "d05": (81.45, 82.00, 13.60), "d1": (80.98, 82.00, 7.32), "d2": (79.95, 82.00, 3.66),
    "d4": (77.91, 82.00, 1.83), "d8": (73.97, 82.00, 0.93), "d10": (72.00, 82.00, 0.75),
}


def test_table1_matches_the_paper_to_two_decimals():
    table = table1().set_index("config")
    assert list(table.columns) == ["delta_f_GHz", "f1_GHz", "f2_GHz", "dd_max_cm"]
    for name, (f1, f2, dd_max) in PAPER_TABLE1.items():
        assert round(table.loc[name, "f1_GHz"], 2) == pytest.approx(f1)
        assert round(table.loc[name, "f2_GHz"], 2) == pytest.approx(f2)
        assert round(table.loc[name, "dd_max_cm"], 2) == pytest.approx(dd_max)


@pytest.mark.parametrize("name", sorted(CONFIGS_GHZ))
def test_frequency_config_files_match_the_table(name):
    path = Path(__file__).parents[1] / "configs" / "freq" / f"{name}.yaml"
    config = yaml.safe_load(path.read_text())
    assert config["name"] == name
    expected = CONFIGS_GHZ[name]
    assert config["f_ghz"] == (None if expected is None else list(expected))
