"""The result every method returns: a depth map on the radar pixel grid plus what produced it."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from methods.domain.capture import RadarGrid


@dataclass
class Reconstruction:
    """Depth map in metres on `grid`'s pixels, shape (ny, nx), row 0 = +y, column 0 = xmin.

    Invalid pixels are NaN: that is the one rule (the PNG writer turns NaN into 0). `magnitude` is the linear
    quantity the depth filter thresholds (mean residual phasor magnitude; max projection for BP), NaN where a
    pixel was not evaluated. `timings_ms` holds per-stage wall times (e.g. prior, correlate, depth, filter) and
    `total`, excluding file I/O and one-time kernel compilation. The harness sets `device` (the backend's name)
    and `invalid_reason` (why no pixel is valid, None when some is); `extra` holds the method's own diagnostics
    (e.g. `roi_px`, the pixels it evaluated).
    """

    depth_m: np.ndarray                 # (ny, nx) float64, NaN = invalid
    magnitude: np.ndarray               # (ny, nx) float, linear
    freqs_hz: np.ndarray                # (F,) frequencies used
    timings_ms: dict[str, float]
    grid: RadarGrid
    method: str
    extra: dict = field(default_factory=dict)
    device: str = ""
    invalid_reason: str | None = None

    @property
    def valid(self) -> np.ndarray:
        """(ny, nx) bool: pixels with a finite depth."""
        return np.isfinite(self.depth_m)
