"""The antenna array of a radar frame (radar space, metres; the QAR50 files are read by bench.maroon.antennas)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class AntennaArray:
    """Antenna positions in radar space, metres. `tx_m[t]` belongs to frame axis 1, `rx_m[r]` to axis 0."""

    tx_m: np.ndarray  # (n_tx, 3) float64
    rx_m: np.ndarray  # (n_rx, 3) float64

    @property
    def n_pairs(self) -> int:
        return len(self.tx_m) * len(self.rx_m)
