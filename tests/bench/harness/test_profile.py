"""The profile switch: `profile=faithful` sets every faithful item at once, `profile=sound` is the default."""
from __future__ import annotations

import numpy as np
from hydra import compose, initialize_config_dir

from bench.harness.app import CONFIG_DIR
from methods.ops.correlate import C_M_PER_S


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


def test_the_profile_reaches_the_methods_and_the_prior():
    from bench.harness.app import _method, _prior_options

    sound, faithful = _compose(), _compose("profile=faithful")
    assert _method(sound).values["filter_quantity"] == "mean"
    assert _method(faithful).values["filter_quantity"] == "first"
    assert _method(_compose("profile=faithful", "method=2fsk", "prior=none")).values["filter_quantity"] == "first"
    assert "filter_quantity" not in _method(_compose("profile=faithful", "method=bp", "prior=none")).values
    fill = sound.prior.fill
    assert _prior_options(sound) == {"faithful": False, "max_jump_mm": 10.0, "fill": fill}
    assert _prior_options(faithful) == {"faithful": True, "max_jump_mm": 10.0, "fill": fill}
    assert _prior_options(_compose("prior.max_jump_mm=null")) == {"faithful": False, "max_jump_mm": None, "fill": fill}
    assert _prior_options(_compose("prior.fill=scanline"))["fill"] == "scanline"
    assert _prior_options(_compose("prior=none")) == {"faithful": False}


def test_an_unknown_prior_fill_is_one_error_line():
    import pytest

    from bench import cli
    from bench.harness.app import _prior_options

    with pytest.raises(cli.UserError, match="delaunay, scanline"):
        _prior_options(_compose("prior.fill=nearest"))


def test_faithful_filter_keeps_pixels_by_the_first_frequencys_magnitude():
    """Two scatterers 3.1 mm apart in depth interfere differently at the two frequencies, so |c1| and the mean
    phasor rank pixels differently; the kept pixels must be exactly those the definition picks, computed here from
    a float64 direct sum over the antenna pairs."""
    from bench.synth.memory import ANTENNAS, MAROON_FREQS_HZ, simulate, square_grid
    from methods.mm2fsk import reconstruct_mm2fsk
    from methods.ops.frequencies import config_indices

    freqs_hz = MAROON_FREQS_HZ[config_indices(MAROON_FREQS_HZ, "d10")]
    points_m = np.array([[0.004, -0.002, 0.300], [-0.006, 0.003, 0.3031], [0.001, 0.008, 0.2985]])
    signal = simulate(points_m, np.array([1.0, 0.8, 0.6]), freqs_hz)
    grid = square_grid(0.012, 25)                          # 25 x 25 pixels of 1 mm
    prior_m = np.full(grid.image_shape, 0.30)
    x_m, y_m = grid.pixel_xy_m()
    pixels_m = np.stack([x_m, y_m, prior_m], axis=-1).reshape(-1, 3)
    tau = (np.linalg.norm(pixels_m[:, None] - ANTENNAS.rx_m[None], axis=2)[:, :, None]
           + np.linalg.norm(pixels_m[:, None] - ANTENNAS.tx_m[None], axis=2)[:, None, :])   # (N, R, T) metres
    phasors = np.stack([np.einsum("rt,nrt->n", signal[:, :, k].astype(np.complex128),
                                  np.exp(2j * np.pi * f * tau / C_M_PER_S)) for k, f in enumerate(freqs_hz)])
    for quantity, magnitude in (("first", np.abs(phasors[0])), ("mean", np.abs(phasors.mean(axis=0)))):
        ratio_db = (20 * np.log10(magnitude / magnitude.max())).reshape(grid.image_shape)
        rec = reconstruct_mm2fsk(signal, freqs_hz, ANTENNAS, grid, prior_m, threshold_db=6.0,
                                 filter_quantity=quantity)
        clear = np.abs(ratio_db + 6.0) > 0.01                     # away from the threshold (float32 kernels)
        np.testing.assert_array_equal(rec.valid[clear], ratio_db[clear] >= -6.0)
    kept_first = (20 * np.log10(np.abs(phasors[0]) / np.abs(phasors[0]).max()) >= -6.0)
    kept_mean = (20 * np.log10(np.abs(phasors.mean(0)) / np.abs(phasors.mean(0)).max()) >= -6.0)
    assert (kept_first != kept_mean).sum() > 5                     # the two definitions differ on this scene
