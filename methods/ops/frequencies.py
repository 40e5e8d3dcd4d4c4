"""Frequency configurations of the paper (Table I, plus BP_max and 3FSK) and their selection in a frame.

A configuration lists target frequencies in GHz; the nearest frequencies present in the frame are used
(DESIGN.md section 3), so with the MAROON sweep `linspace(72, 82, 128)` GHz `d05` selects indices 120 and 127.
"""
from __future__ import annotations

import numpy as np

from methods.domain.errors import UsageError
from methods.ops.correlate import C_M_PER_S

CONFIGS_GHZ: dict[str, tuple[float, ...] | None] = {
    "d05": (81.45, 82.00),
    "d1": (80.98, 82.00),
    "d2": (79.95, 82.00),
    "d4": (77.91, 82.00),
    "d8": (73.97, 82.00),
    "d10": (72.00, 82.00),
    "full": None,  # every frequency of the frame (BP_max)
    "d05_d10": (72.00, 81.45, 82.00),
    "d1_d10": (72.00, 80.98, 82.00),
    "d2_d10": (72.00, 79.95, 82.00),
}


def config_targets_ghz(name: str) -> tuple[float, ...] | None:
    """Target frequencies (GHz) of a named configuration; None for `full` (all frequencies)."""
    if name not in CONFIGS_GHZ:
        raise UsageError(f"unknown frequency configuration {name!r}; choose one of {', '.join(CONFIGS_GHZ)}")
    return CONFIGS_GHZ[name]


def select_frequencies(freqs_hz: np.ndarray, targets_ghz: tuple[float, ...] | list[float]) -> np.ndarray:
    """Indices (ascending) of the frame frequencies nearest to each target; error if a target lies outside the
    frame's band (by more than half its largest frequency step: the nearest frequency would be another one) or two
    targets share one frame frequency."""
    freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
    targets_hz = np.asarray(targets_ghz, dtype=np.float64) * 1e9
    slack_hz = 0.5 * float(np.diff(freqs_hz).max(initial=0.0))
    outside = [t for t in targets_hz if not freqs_hz.min() - slack_hz <= t <= freqs_hz.max() + slack_hz]
    if outside:
        raise UsageError(f"target frequency {outside[0] / 1e9:g} GHz lies outside the frame's band "
                         f"{freqs_hz.min() / 1e9:.3f}-{freqs_hz.max() / 1e9:.3f} GHz")
    indices = np.argmin(np.abs(freqs_hz[None, :] - targets_hz[:, None]), axis=1)
    if len(np.unique(indices)) != len(indices):
        chosen = ", ".join(f"{t:.3f} GHz -> {freqs_hz[i] / 1e9:.3f} GHz" for t, i in zip(targets_ghz, indices,
                                                                                         strict=False))
        raise UsageError(f"two target frequencies map to the same frame frequency ({chosen}); "
                         "the frame's frequency sweep is too coarse for this configuration")
    return np.sort(indices)


def config_indices(freqs_hz: np.ndarray, name: str) -> np.ndarray:
    """Indices of the frame frequencies used by configuration `name` (all of them for `full`)."""
    targets_ghz = config_targets_ghz(name)
    if targets_ghz is None:
        return np.arange(len(freqs_hz))
    return select_frequencies(freqs_hz, targets_ghz)


def max_unambiguous_depth_m(delta_f_hz: float) -> float:
    """Maximum unambiguous depth correction c / (4 delta_f) in metres (paper eq. 8): +-13.6 cm at 0.55 GHz."""
    return C_M_PER_S / (4.0 * delta_f_hz)
