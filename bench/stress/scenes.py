"""Analytic in-memory stress scenes: a point target and a flat plate as radar frames on the packaged antennas.

Frames follow the generator's signal model (`bench.synth.simulate_frame`, path loss included) at frequencies
picked from the MAROON sweep `linspace(72, 82, 128)` GHz by the named configurations of `methods.ops.frequencies`.
"""
from __future__ import annotations

import numpy as np

from bench.synth import simulate_frame
from bench.synth.memory import ANTENNAS
from methods.domain.antennas import AntennaArray
from methods.domain.capture import RadarGrid
from methods.domain.radar import MAROON_FREQS_HZ
from methods.ops.frequencies import config_indices, max_unambiguous_depth_m

TABLE1_CONFIGS = ("d05", "d1", "d2", "d4", "d8", "d10")
THREE_FREQ_CONFIGS = ("d05_d10", "d1_d10", "d2_d10")


def antennas() -> AntennaArray:
    """The packaged QAR50 imaging array (94 tx, 94 rx), radar space."""
    return ANTENNAS


def config_freqs_hz(config: str) -> np.ndarray:
    """The frequencies (Hz, ascending) that configuration `config` selects from the MAROON sweep."""
    return MAROON_FREQS_HZ[config_indices(MAROON_FREQS_HZ, config)]


def dd_max_m(config: str) -> float:
    """Maximum unambiguous depth correction (m) of a configuration: c / (4 df) of its smallest neighbour step."""
    return max_unambiguous_depth_m(float(np.min(np.diff(config_freqs_hz(config)))))


def frame(points_m: np.ndarray, freqs_hz: np.ndarray) -> np.ndarray:
    """complex64 (n_rx, n_tx, F) of unit-amplitude point scatterers (K, 3), metres."""
    points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    array = antennas()
    return simulate_frame(points_m, np.ones(len(points_m), np.complex64), array.tx_m, array.rx_m, freqs_hz)


def pixel_grid(half_xy_m: float, n_xy: int, z_m: float) -> RadarGrid:
    """Square n_xy x n_xy pixel grid over +-half_xy_m (row 0 = +y) with a z range of +-5 cm around z_m."""
    return RadarGrid((-half_xy_m, -half_xy_m, z_m - 0.05), (half_xy_m, half_xy_m, z_m + 0.05), (n_xy, n_xy, 11))


def noise_power(signal: np.ndarray, snr_db: float) -> float:
    """Per-sample complex noise power giving `snr_db` relative to the mean signal power of `signal`."""
    return float(np.mean(np.abs(signal) ** 2)) / 10.0 ** (snr_db / 10.0)
