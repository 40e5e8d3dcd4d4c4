"""Work in proportion to the object, not the grid: run a pass only at the pixels the depth filter can keep.

The filter (methods.ops.filtering) keeps a pixel iff its magnitude m >= G 10^(-thr/20), G the maximum over the
evaluated pixels. The pass runs first on a lattice of every `step`-th pixel (1/step^2 of them); a lattice pixel
whose magnitude is within thr + margin_db of the lattice maximum marks its neighbourhood (one step + a margin in
x and y; methods.skips.settings.SkipSettings.lattice_px); the pass then runs on the marked pixels. Pixels left out are
invalid (NaN depth and magnitude).

When it equals the full pass: every pixel the full pass keeps is evaluated (then its value and G are the full
pass's: the pixel of G is kept, so it is evaluated). That holds when no kept pixel lies farther than
the neighbourhood from a lattice pixel within margin_db of its magnitude, i.e. when the magnitude image varies
slowly against the lattice step: its lateral resolution (~4 mm for the QAR50 aperture at 30 cm, ~lambda z / (2 D))
spans several 1 mm pixels, so a lattice of 3 mm with a 10 dB margin rarely misses a kept pixel (measured: 0-7 of
800-14500 kept pixels for 3FSK on the catalogue, none for 2FSK; 6 dB lost up to 12). Measured by
`bench.perf.correlate --section skips` and tested on small grids. Steps and margins are set in metres and converted to
the
grid's pixels, so a coarse grid (pixels >= the lattice step) runs the full pass.
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from methods.skips.roi import dilate, lattice

Pass = Callable[[np.ndarray], dict[str, np.ndarray]]   # pixels (ny, nx) bool -> values (n,) per name, "magnitude"


def _images(shape: tuple[int, int], parts: list[tuple[np.ndarray, dict[str, np.ndarray]]]) -> dict[str, np.ndarray]:
    """Scatter per-pixel values of (mask, values) parts into NaN-filled images (ny, nx) per name."""
    out: dict[str, np.ndarray] = {}
    for mask, values in parts:
        for name, v in values.items():
            if name not in out:
                out[name] = np.full(shape, np.nan, dtype=np.float64)
            out[name][mask] = v
    return out


def run_where_kept(pixels: np.ndarray, run: Pass, threshold_db: float | None, step_px: int, margin_db: float,
                   radius_px: int, enabled: bool = True) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Run `run` on the ROI `pixels` (ny, nx) - all of them, or (enabled, a threshold set) the lattice of every
    `step_px`-th pixel first and then the pixels within `radius_px` of a marked one (module doc). Returns (the pixels
    evaluated, images (ny, nx) per value name, NaN where
    not evaluated)."""
    if not enabled or threshold_db is None or step_px <= 1 or not pixels.any():
        return pixels, _images(pixels.shape, [(pixels, run(pixels))])
    grid_lattice = lattice(pixels, step_px)
    on_lattice = run(grid_lattice)
    magnitude = np.asarray(on_lattice["magnitude"], dtype=np.float64)
    peak = np.max(magnitude) if magnitude.size else 0.0
    marked = np.zeros_like(pixels)
    marked[grid_lattice] = magnitude >= peak * 10.0 ** (-(threshold_db + margin_db) / 20.0)
    rest = dilate(marked, radius_px) & pixels & ~grid_lattice
    parts = [(grid_lattice, on_lattice)]
    if rest.any():
        parts.append((rest, run(rest)))
    return grid_lattice | rest, _images(pixels.shape, parts)
