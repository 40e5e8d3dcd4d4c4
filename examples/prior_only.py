"""A method of your own in one file: the prior-only baseline, the depth camera's depth resampled to the radar
grid (the prior every MM method starts from) and no radar at all: the lower bar every table should show.

Run it beside the built-ins, without editing the package (from the repository root, where `examples` imports):

    python -m bench method=custom method._target_=examples.prior_only.PriorOnly prior=realsense freq=d10

Its rows join sweeps, the result store (this file's source is part of the cache key), tables and plots under
its `label`. What a method declares and receives: methods/method.py.
"""
from __future__ import annotations

import numpy as np

from methods import Frame, Method, Reconstruction


class PriorOnly(Method):
    """Depth = the sensor prior on the radar pixel grid (NaN where it has none or outside the region of
    interest); magnitude 1 where there is a depth, so the depth filter keeps every such pixel."""

    name = "prior_only"
    label = "Prior only"
    n_freqs = None                                  # any configuration: no radar frequency is used
    priors = ("realsense", "photogrammetry")
    params = {}

    def run(self, frame: Frame, prior, backend, timer) -> Reconstruction:
        with timer.stage("depth"):
            depth_m = np.where(frame.roi.pixels, prior.host_m(), np.nan)
            magnitude = np.where(np.isfinite(depth_m), 1.0, np.nan)
        return Reconstruction(depth_m=depth_m, magnitude=magnitude, freqs_hz=np.asarray(frame.freqs_hz),
                              timings_ms=timer.finish(), grid=frame.grid, method=self.name,
                              extra={"roi_px": int(np.isfinite(depth_m).sum())})
