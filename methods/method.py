"""The method interface: what a radar imaging method declares, and the one call the harness makes.

A method is one class in one file (the built-ins: methods/bp.py, fsk.py, fsk3.py, mm2fsk.py, mm3fsk.py;
a worked example outside the package: examples/prior_only.py):

    class MyMethod(Method):
        name = "mine"                     # the results' `method` column
        label = "Mine"                    # its rows' label in tables and plots
        n_freqs = 2                       # frequencies per configuration (None: any number)
        priors = ("realsense",)           # accepted: "none", "scalar", "realsense", "photogrammetry"
        params = {"threshold_db": 14.0}   # parameters and their defaults; others are refused
        def run(self, frame, prior, backend, timer) -> Reconstruction: ...

`MyMethod(**params)` checks the parameters; `run` gets the `Frame` (the radar frame at the configuration's
frequencies, antennas, grid, region of interest), the prior (None, a scalar depth in metres, or a
`methods.prior.image.Prior`), the `methods.backends.Backend` to correlate on, and a `StageTimer`; it returns a
`Reconstruction`. The harness finds a method by the `_target_` of its Hydra config (configs/method/), e.g.
`python -m bench method=custom method._target_=mypkg.mymethod.MyMethod`.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from methods.backends.base import Backend
from methods.domain.antennas import AntennaArray
from methods.domain.capture import RadarGrid
from methods.domain.errors import UsageError
from methods.domain.samples import FrameSamples
from methods.ops.filtering import DEFAULT_THRESHOLD_DB
from methods.ops.timing import StageTimer
from methods.prior.image import Prior
from methods.reconstruction import Reconstruction
from methods.skips.roi import Roi
from methods.skips.settings import SkipSettings

PRIOR_KINDS = ("none", "scalar", "realsense", "photogrammetry")
_INTERFACE_CHECKED: set[type] = set()
SENSOR_PRIORS = ("realsense", "photogrammetry")


class MethodError(UsageError):
    """A method that cannot be used as asked: unknown parameters, a frequency count or prior it does not accept, or
    a class that breaks the interface. The message is one line naming the method."""


@dataclass(frozen=True)
class Frame:
    """What a method reconstructs from: one radar frame at the configuration's frequencies, and where to look.

    samples the frame's samples at those frequencies (methods.domain.samples.FrameSamples; an array (n_rx, n_tx, F)
    is wrapped) and `signal` the same as an array (n_rx, n_tx, F) complex, taken on first use; freqs_hz (F,)
    ascending as selected, antennas in radar space (m), grid the pixel (and BP's voxel) grid, roi the region the
    capture allows (methods.skips.roi; the whole grid when the skips say so), skips the computation shortcuts asked
    for (methods.skips.settings), threshold_db the depth filter (dB below the strongest pixel's magnitude, None = off;
    methods.ops.filtering), name the capture's name (for messages)."""

    samples: FrameSamples
    freqs_hz: np.ndarray
    antennas: AntennaArray
    grid: RadarGrid
    roi: Roi
    skips: SkipSettings
    threshold_db: float | None = DEFAULT_THRESHOLD_DB
    name: str = ""

    def __post_init__(self) -> None:
        if not isinstance(self.samples, FrameSamples):
            object.__setattr__(self, "samples", FrameSamples(self.samples))

    @property
    def signal(self) -> np.ndarray:
        """The samples (n_rx, n_tx, F) as an array (a backend that stages them itself gathers from `samples`)."""
        return self.samples.array()


class Method:
    """Base class of every method (module doc). Subclasses set the class attributes and implement `run`."""

    name: ClassVar[str]
    label: ClassVar[str]
    n_freqs: ClassVar[int | None] = None
    priors: ClassVar[tuple[str, ...]] = ("none",)
    params: ClassVar[Mapping[str, Any]] = {}
    #: the harness keeps a sensor prior on the backend's device (it only passes it on to `backend.depth_at_prior`)
    device_prior: ClassVar[bool] = False
    #: `run` computes BP volumes (the warm-up compiles the volume kernels too)
    uses_volume: ClassVar[bool] = False

    def __init__(self, **params):
        if type(self) not in _INTERFACE_CHECKED:          # once per class (~10 us a call on the H100's host)
            check_interface(type(self))
            _INTERFACE_CHECKED.add(type(self))
        unknown = set(params) - set(self.params)
        if unknown:
            raise MethodError(f"unknown parameter(s) {', '.join(sorted(unknown))} for {self.name}; "
                              f"allowed: {', '.join(sorted(self.params)) or 'none'}")
        self.given = frozenset(params)
        self.values = {**self.params, **params}

    def check(self, n_freqs: int, freq: object, prior: str | float | None) -> None:
        """Refuse a configuration this method cannot run: `n_freqs` frequencies (named `freq`) and the parsed
        prior (None, a scalar in metres, or a sensor name)."""
        if self.n_freqs is not None and n_freqs != self.n_freqs:
            raise MethodError(f"{self.name} needs a {self.n_freqs}-frequency configuration, but freq={freq!r} "
                              f"selects {n_freqs} frequencies")
        kind = prior_kind(prior)
        if kind in self.priors or (kind == "none" and "scalar" in self.priors):
            return
        if kind in SENSOR_PRIORS:
            raise MethodError(f"{self.name} uses a scalar prior (a depth in metres); for prior={prior!r} use "
                              f"method='mm2fsk' or another method that accepts a per-pixel prior")
        if set(self.priors) <= set(SENSOR_PRIORS):
            raise MethodError(f"{self.name} needs a per-pixel prior: prior="
                              f"{' or '.join(repr(p) for p in self.priors)}, got {prior!r}")
        raise MethodError(f"{self.name} accepts the priors {', '.join(self.priors)}, got {prior!r}")

    def warm_up(self, freqs_hz: np.ndarray, antennas: AntennaArray, grid: RadarGrid, skips: SkipSettings,
                prior: str | float | None) -> None:
        """Build, before the timed `run`, what it would otherwise build once per process and configuration
        (`reconstruct` calls it beside `Backend.warm_up`; nothing by default). `prior`: the parsed prior."""

    def run(self, frame: Frame, prior: Prior | float | None, backend: Backend, timer: StageTimer
            ) -> Reconstruction:
        raise NotImplementedError


def prior_kind(prior: str | float | None) -> str:
    """'none', 'scalar' or the sensor name of a parsed prior."""
    if prior is None:
        return "none"
    return prior if isinstance(prior, str) else "scalar"


def check_interface(cls: type) -> None:
    """Raise MethodError when `cls` is not a usable Method (the attributes of the module doc, a `run`)."""
    if not (isinstance(cls, type) and issubclass(cls, Method)):
        raise MethodError(f"{getattr(cls, '__qualname__', cls)!r} is not a methods.method.Method subclass")
    where = f"{cls.__module__}.{cls.__qualname__}"
    for attr, kind in (("name", str), ("label", str)):
        if not isinstance(getattr(cls, attr, None), kind) or not getattr(cls, attr):
            raise MethodError(f"{where} must set `{attr}` (a non-empty string)")
    if cls.n_freqs is not None and (not isinstance(cls.n_freqs, int) or cls.n_freqs < 1):
        raise MethodError(f"{where}.n_freqs must be a positive integer or None, got {cls.n_freqs!r}")
    bad = [p for p in cls.priors if p not in PRIOR_KINDS]
    if not cls.priors or bad:
        raise MethodError(f"{where}.priors must name some of {', '.join(PRIOR_KINDS)}, got {cls.priors!r}")
    if not isinstance(cls.params, Mapping):
        raise MethodError(f"{where}.params must be a mapping of parameter names to defaults")
    if cls.run is Method.run:
        raise MethodError(f"{where} must implement run(frame, prior, backend, timer)")

