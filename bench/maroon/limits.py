"""Explicit bounds on everything a dataset declares, checked before anything is allocated or parsed.

A MAROON dataset is input of unknown origin: a file may claim any size, an array any shape, a grid any number of
voxels. The reader (bench.maroon.reader and the modules it uses) compares each such claim with one of these limits first
and refuses the file with a DatasetError naming it, so memory and time stay bounded whatever the input.

The defaults leave a wide margin around real MAROON data (a 96 x 96 x 128 complex64 frame is 9.4 MB; images are
640 x 480 to 1920 x 1080; the grids are 301 x 301 x 151-201; mask_erosion is 10-30). Change them with

* the environment variable `BENCH_LIMITS`, e.g. `BENCH_LIMITS="mesh_bytes=2GiB image_pixels=50e6"` (names as
  the fields below, separated by spaces or commas; sizes take KiB/MiB/GiB suffixes); it reaches every entry point
  (`python -m bench`, its parallel workers, `python -m bench.maroon.inspect_capture`);
* in Python: `maroon.read_capture(..., limits=Limits(mesh_bytes=2 << 30))` or `with use_limits(Limits(...)):`.
"""
from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import os
import re
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from methods.domain.errors import DatasetError

KIB, MIB, GIB = 1 << 10, 1 << 20, 1 << 30
ENV_VAR = "BENCH_LIMITS"


@dataclass(frozen=True)
class Limits:
    """Bounds on what a dataset may declare (sizes in bytes, counts in elements)."""

    # files, by kind (bench.maroon.safe_io.KINDS)
    frame_bytes: int = 256 * MIB          # a pickled radar frame .npy (96 x 96 x 512 complex128 is 75 MB)
    json_bytes: int = 16 * MIB            # metadata.json, alignment.json, calibration.json
    image_bytes: int = 256 * MIB          # depth and mask PNGs
    mesh_bytes: int = 512 * MIB           # the photogrammetry mesh (OBJ/PLY)
    text_bytes: int = 1 * MIB             # antenna files Tx.dat / Rx.dat
    # JSON
    json_depth: int = 64                  # nesting of arrays and objects
    json_number_chars: int = 64           # characters of one number literal (-0.15000000596046448 has 20)
    # pickled frames (.npy holding a pickle)
    npy_header_bytes: int = 4096          # the .npy header (numpy writes ~128 bytes)
    pickle_opcodes: int = 1_000_000       # opcodes of the pickle (a frame has a few dozen)
    pickle_depth: int = 32                # nesting of lists, tuples and dicts in the frame
    array_elements: int = 1 << 26         # elements of one array (a 96 x 96 x 512 frame has 4.7e6)
    signal_abs: float = 1e30              # largest |xr| sample: float32 sums over 8836 pairs overflow near 3.8e34
    # images and grids
    image_pixels: int = 4096 * 4096       # width x height of a PNG, from its header, before decoding
    grid_pixels: int = 1024 * 1024        # nx x ny of a calibration grid (MAROON: 301 x 301)
    grid_voxels: int = 1 << 26            # nx x ny x nz (MAROON: 301 x 301 x 201 = 1.8e7)
    mask_erosion: int = 400               # metadata mask_erosion (MAROON: 10-30)
    erosion_kernel_px: int = 64           # the P_e / silhouette kernel in pixels of the metric grid

    def __post_init__(self):
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                raise ValueError(f"limit {field.name} must be a positive number, got {value!r}")


DEFAULT_LIMITS = Limits()
_ACTIVE: contextvars.ContextVar[Limits | None] = contextvars.ContextVar("bench_limits", default=None)
_FROM_ENV: dict[str, Limits] = {}
_SIZE = re.compile(r"^([0-9.eE+]+)\s*(KiB|MiB|GiB|k|M|G)?$")
_UNITS = {None: 1, "KiB": KIB, "MiB": MIB, "GiB": GIB, "k": 1000, "M": 10 ** 6, "G": 10 ** 9}


def parse_limits(text: str, base: Limits = DEFAULT_LIMITS) -> Limits:
    """`base` with the `name=value` settings of `text` (spaces or commas between them); ValueError if malformed."""
    names = {field.name: field.type for field in dataclasses.fields(Limits)}
    changes = {}
    for item in filter(None, re.split(r"[\s,]+", text.strip())):
        name, _, value = item.partition("=")
        if name not in names:
            raise ValueError(f"unknown limit {name!r} (known: {', '.join(names)})")
        match = _SIZE.match(value.strip())
        if not match:
            raise ValueError(f"limit {name} needs a number (e.g. {name}=1e6 or 2GiB), got {value!r}")
        number = float(match.group(1)) * _UNITS[match.group(2)]
        changes[name] = number if name == "signal_abs" else int(number)
    return dataclasses.replace(base, **changes)


def current_limits() -> Limits:
    """The limits in force: `use_limits(...)`, else `$BENCH_LIMITS` over the defaults."""
    active = _ACTIVE.get()
    if active is not None:
        return active
    text = os.environ.get(ENV_VAR, "")
    if text not in _FROM_ENV:
        try:
            _FROM_ENV[text] = parse_limits(text)
        except ValueError as err:
            raise DatasetError(Path(f"${ENV_VAR}"), str(err)) from None
    return _FROM_ENV[text]


@contextlib.contextmanager
def use_limits(limits: Limits | None) -> Iterator[Limits]:
    """Run the block with `limits` (None: keep the limits in force)."""
    if limits is None:
        yield current_limits()
        return
    token = _ACTIVE.set(limits)
    try:
        yield limits
    finally:
        _ACTIVE.reset(token)


def too_large(what: str, value: int | float, name: str) -> str:
    """The sentence of a refusal: `what` is `value`, above the limit `name` (and how to raise it)."""
    limit = getattr(current_limits(), name)
    def text(number):
        return f"{number:.3g}" if isinstance(number, float) else f"{number:,}"
    return f"{what} is {text(value)}, more than the limit {text(limit)} ({ENV_VAR} {name}=... raises it)"
