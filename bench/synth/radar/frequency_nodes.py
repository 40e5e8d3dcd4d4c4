"""A block's response at every frequency from its response at a few equidistant node frequencies.

For scatterers whose round-trip paths to one antenna pair lie within +-W of a centre path p0, the pair's response is
s(f) = exp(-j 2 pi f p0 / c) u(f) with u(f) = sum_k a_k exp(-j 2 pi f dp_k / c), |dp_k| <= W: u varies with f no
faster than its largest delay W / c allows, so over the 10 GHz band it is fixed by a few samples. `interpolator`
fits one matrix L (F x M) such that, for every |dp| <= W,

    | exp(-j 2 pi f_n dp / c) - sum_m L[n, m] exp(-j 2 pi g_m dp / c) | <= NODE_ERROR      (f_n targets, g_m nodes)

(regularised least squares on a fine grid of dp; the bound is checked on a 5x finer grid, with L rounded to
complex64 as it is used). By linearity
|u(f_n) - sum_m L[n, m] u(g_m)| <= NODE_ERROR sum_k |a_k|: a bound per unit of scatterer weight, about the rounding
of the complex64 sums themselves. The row sums of |L| are kept <= NODE_GAIN, which bounds how much the nodes' own
complex64 rounding is amplified. Where no M <= MAX_NODE_SHARE F meets both, the nodes are the frequencies themselves
(every frequency computed directly).
"""
from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from bench.synth.config import C_M_PER_S
from bench.synth.radar import fit_cache

NODE_ERROR = 1e-6          # interpolation error per unit scatterer weight (complex64 sums round at ~1e-7 of it)
NODE_GAIN = 6.0            # most that L's rows may amplify the nodes' rounding
MAX_NODE_SHARE = 0.5       # at most this share of the frequencies as nodes: beyond it they save too little (0: direct)
WIDTH_STEP_M = 2.5e-3      # half-widths are rounded up to a multiple of this, so that few fits are made (cached)
_FIT_POINTS = 400          # samples of dp in [-W, W] for the fit (the functions fit hold < 10 cycles over it)
_COARSE_STEP = 5          # the first pass of the check uses every 5th of its points
_RIDGE = 1e-14             # Tikhonov weight relative to the normalised Gram matrix: keeps L small near the knee


def width_bin_m(half_width_m: float) -> float:
    """The half-width rounded up to the cache grid (WIDTH_STEP_M), in metres of round-trip path."""
    return WIDTH_STEP_M * max(1, int(np.ceil(half_width_m / WIDTH_STEP_M - 1e-9)))


def interpolator(freqs_hz: np.ndarray, half_width_m: float) -> tuple[np.ndarray, np.ndarray | None]:
    """(node frequencies (M,) Hz, L (F, M) complex64) for path offsets within +-half_width_m; L is None when the
    nodes are the frequencies themselves (no M <= MAX_NODE_SHARE F meets NODE_ERROR and NODE_GAIN)."""
    freqs = tuple(np.asarray(freqs_hz, dtype=np.float64).tolist())
    return _fit(freqs, width_bin_m(half_width_m), int(MAX_NODE_SHARE * len(freqs)))


@functools.lru_cache(maxsize=128)
def _fit(freqs_hz: tuple[float, ...], half_width_m: float, max_nodes: int) -> tuple[np.ndarray, np.ndarray | None]:
    """_fitted, kept in memory and on disk (bench.synth.radar.fit_cache)."""
    name = fit_cache.key(_SOURCE, freqs_hz, half_width_m, max_nodes)
    kept = fit_cache.load(name)
    if kept is None:
        kept = _fitted(freqs_hz, half_width_m, max_nodes)
        fit_cache.store(name, *kept)
    return kept


_SOURCE = Path(__file__).read_bytes()      # the fitting code: a kept fit is one this code made


def _fitted(freqs_hz: tuple[float, ...], half_width_m: float, max_nodes: int) -> tuple[np.ndarray, np.ndarray | None]:
    freqs = np.asarray(freqs_hz)
    centre_hz = 0.5 * (freqs.min() + freqs.max())
    offsets_m = np.linspace(-half_width_m, half_width_m, _FIT_POINTS)
    check_m = np.linspace(-half_width_m, half_width_m, 5 * _FIT_POINTS + 1)

    def phasors(f_hz, path_m):     # baseband: the centre frequency's phase is common to both sides of the fit
        return np.exp(-2j * np.pi * np.outer(f_hz - centre_hz, path_m) / C_M_PER_S)

    target, target_check = phasors(freqs, offsets_m), phasors(freqs, check_m)
    nyquist = int(2.0 * half_width_m * (freqs.max() - freqs.min()) / C_M_PER_S)    # fewer nodes cannot fit
    for n_nodes in range(max(2, nyquist), max_nodes + 1):
        nodes = np.linspace(freqs.min(), freqs.max(), n_nodes)
        basis = phasors(nodes, offsets_m)
        gram = basis @ basis.conj().T / len(offsets_m)
        rhs = target @ basis.conj().T / len(offsets_m)
        fit = np.linalg.solve(gram.T + _RIDGE * np.eye(n_nodes), rhs.T).T.astype(np.complex64)   # as it is used
        if np.abs(fit).sum(axis=1).max() > NODE_GAIN:
            continue
        # every 5th check point first: most node counts fail there already, at a fifth of the cost (a fit that
        # passes is then checked on every point, so the node count found is the same)
        coarse = slice(None, None, _COARSE_STEP)
        if np.abs(fit @ phasors(nodes, check_m[coarse]) - target_check[:, coarse]).max() > NODE_ERROR:
            continue
        if np.abs(fit @ phasors(nodes, check_m) - target_check).max() <= NODE_ERROR:
            return nodes, fit
    return freqs, None
