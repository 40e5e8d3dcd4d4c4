"""The per-pixel depth prior a method receives: an image (ny, nx) in metres on the radar grid, NaN = no prior,
held on the host or on a backend's device (methods.backends.warp.prior.DevicePrior)."""
from __future__ import annotations

import numpy as np

from methods.domain.capture import RadarGrid


class Prior:
    """A per-pixel prior on `grid`. `n_covered` pixels have one; `host_m()` is the (ny, nx) image in metres
    (NaN = no prior) on the host; `device_resident` says whether it lives on a backend's device."""

    grid: RadarGrid
    n_covered: int
    shape: tuple[int, int]
    device_resident = False
    takes_roi = False       # `Backend.depth_at_prior` restricts its pixels to a region of interest itself

    def host_m(self) -> np.ndarray:
        raise NotImplementedError

    def __array__(self, dtype=None, copy=None):
        image = self.host_m()
        return image if dtype is None else image.astype(dtype)


class HostPrior(Prior):
    """A prior image held in host memory (the CPU functions of `methods.prior.priors`)."""

    def __init__(self, image_m: np.ndarray, grid: RadarGrid):
        self.image_m, self.grid, self.shape = image_m, grid, image_m.shape
        self.n_covered = int(np.isfinite(image_m).sum())

    def host_m(self) -> np.ndarray:
        return self.image_m
