"""The profile switch: `profile=faithful` sets every faithful item at once, `profile=sound` is the default."""
from __future__ import annotations

from hydra import compose, initialize_config_dir

from bench.app import CONFIG_DIR


def _compose(*overrides: str):
    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides))


def test_sound_is_the_default_and_faithful_switches_every_item():
    sound, faithful = _compose(), _compose("profile=faithful")
    assert (sound.profile.name, sound.profile.filter, sound.profile.prior, sound.metrics.faithful) == \
        ("sound", "mean", "sound", False)
    assert (faithful.profile.name, faithful.profile.filter, faithful.profile.prior, faithful.metrics.faithful) == \
        ("faithful", "first", "faithful", True)


def test_the_profile_survives_cells_and_experiments():
    cfg = _compose("profile=faithful", "cell=mm2fsk_d05")
    assert cfg.metrics.faithful and cfg.profile.filter == "first" and cfg.method.name == "mm2fsk"
