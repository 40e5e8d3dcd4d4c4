"""Column-separable back-projection for few frequencies on Warp devices (kernels: `columns_kernels`).

`plan` groups the transmitters into columns (equal x and z; QAR50: two columns of 45 at x = +-70.5 mm, and two
of 2 end elements at +-72 mm, which are small and taken directly) and chooses the rho step of the tables.

Error bound (per table term, relative to |S|): 4-point Lagrange interpolation at step h errs by at most
h^4 max|phi^(4)| (9/16) / 4! where the fourth derivative of exp(j phi(rho)) is bounded by
|phi'|^4 + 6 phi'^2 |phi''| + 4 |phi'| |phi'''| + 3 phi''^2 + |phi''''|, phi(rho) = k (sqrt(rho^2 + a) - g(rho)),
a in the row's range of squared y offsets of the column and g the mean of its ends. `plan` evaluates these
derivatives over the rows, columns and the grid's rho range at the largest wavenumber and takes the step whose
bound is `term_tol`; the image error is a weighted mean of term errors, so its relative L2 error stays below the
bound. Measured on random frames: the bound is ~20x pessimistic (term_tol 1e-3: ~1.5e-5 relative L2, 1e-4: ~3e-6,
at the float32 floor); TERM_TOL = 1e-4 keeps the image within 1e-4 of the float64 sum with a wide margin
(tests/methods/backends/test_gpu_columns.py, docs/measurements/formation.md).

Cost: per voxel and frequency one receive phasor and one 4-tap lookup per receiver and table column (QAR50:
2 x 94) plus the directly taken transmitters, against 94 x 94 pair terms; the tables cost rows x F x R x T x n_rho
multiply-adds. Measured on the H100 (paper grid, two frequencies, volume + peak): 65 ms against 37 ms for the
tensor-core kernel, whose fp16 operands err by ~1.8e-4; so the tensor cores stay the default there and this kernel
is the accurate alternative (`volume(..., method="columns")`; docs/measurements/formation.md).
"""
from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import warp as wp

from methods.backends.warp.frames import BufferPool, FrameInputs, vec2_of
from methods.backends.warp.kernels import columns as kernels
from methods.domain.radar import C_M_PER_S

TERM_TOL = 1e-4              # default per-term interpolation bound (relative; measured image error ~3e-6)
MIN_TABLE_COLUMN = 8         # transmitters a column needs to go to the table (fewer: taken directly)
MAX_RHO_SAMPLES = 1 << 14    # longer tables: the layout does not suit the plan
LAGRANGE4_CONST = (9.0 / 16.0) / 24.0
GATHER_BLOCK = 128            # gather threads per block (H100: 128 and 64 equal, 256 1.5x slower)


@dataclass(frozen=True)
class ColumnPlan:
    """Transmitter columns and rho sampling of one array, grid and frequency set."""

    cols_xz_m: np.ndarray        # (C, 2) table columns' (x, z)
    table_tx: np.ndarray         # (Tq,) transmitter indices of the table columns, column by column
    col_start: np.ndarray        # (C + 1,) int: column c holds table_tx[col_start[c]:col_start[c + 1]]
    small_tx: np.ndarray         # (Ts,) transmitter indices taken directly
    a_lo: np.ndarray             # (ny, C) smallest squared y offset of a row from the column's transmitters, m^2
    a_hi: np.ndarray             # (ny, C) largest, m^2
    rho0_m: float                # first rho sample
    rho_step_m: float            # h
    n_rho: int                   # samples per table row
    term_bound: float            # the bound above at this step

    @property
    def table_tx_col(self) -> np.ndarray:
        """(Tq,) column index of each table transmitter."""
        return np.repeat(np.arange(len(self.cols_xz_m)), np.diff(self.col_start))


def _columns(tx_m: np.ndarray):
    """Table columns (x, z), their transmitters, and the transmitters of small columns."""
    xz = np.round(tx_m[:, [0, 2]], 9)
    keys, inverse, counts = np.unique(xz, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    big = np.flatnonzero(counts >= MIN_TABLE_COLUMN)
    table_tx = [np.flatnonzero(inverse == c) for c in big]
    small_tx = np.flatnonzero(~np.isin(inverse, big))
    col_start = np.concatenate([[0], np.cumsum([len(t) for t in table_tx])]).astype(np.int32)
    table = np.concatenate(table_tx) if table_tx else np.zeros(0, dtype=np.int64)
    return keys[big], table, col_start, small_tx


def _rho_range_m(cols_xz_m, x_m, z_m) -> tuple[float, float]:
    """Smallest and largest rho = |(x, z) - column| over the grid's box and the columns."""
    lo, hi = np.inf, 0.0
    for cx, cz in cols_xz_m:
        dx = np.array([np.min(x_m) - cx, np.max(x_m) - cx])
        dz = np.array([np.min(z_m) - cz, np.max(z_m) - cz])
        near = np.hypot(0.0 if dx[0] <= 0 <= dx[1] else np.min(np.abs(dx)),
                        0.0 if dz[0] <= 0 <= dz[1] else np.min(np.abs(dz)))
        lo, hi = min(lo, near), max(hi, np.hypot(np.max(np.abs(dx)), np.max(np.abs(dz))))
    return float(lo), float(hi)


def _sqrt_derivatives(rho, a):
    """d^n/drho^n sqrt(rho^2 + a), n = 1..4 (broadcast)."""
    s = np.sqrt(rho * rho + a)
    return rho / s, a / s**3, -3.0 * a * rho / s**5, 3.0 * a * (4.0 * rho * rho - a) / s**7


def fourth_derivative_bound(k_max: float, a_lo, a_hi, rho_lo: float, rho_hi: float) -> float:
    """Largest bound of |d^4/drho^4 exp(j phi)| (module doc) over rows/columns (a_lo, a_hi arrays) and rho."""
    rho = np.linspace(rho_lo, rho_hi, 129)[:, None, None]
    a_lo, a_hi = np.ravel(a_lo)[None, :, None], np.ravel(a_hi)[None, :, None]
    a = a_lo + (a_hi - a_lo) * np.linspace(0.0, 1.0, 9)[None, None, :]
    g = [(u + v) / 2.0 for u, v in zip(_sqrt_derivatives(rho, a_lo), _sqrt_derivatives(rho, a_hi), strict=True)]
    d = [k_max * np.max(np.abs(s - gn), axis=2) for s, gn in zip(_sqrt_derivatives(rho, a), g, strict=True)]
    m4 = d[0]**4 + 6 * d[0]**2 * d[1] + 4 * d[0] * d[2] + 3 * d[1]**2 + d[3]
    return float(m4.max())


def plan(tx_m: np.ndarray, freqs_hz: np.ndarray, x_m: np.ndarray, y_m: np.ndarray, z_m: np.ndarray,
         term_tol: float = TERM_TOL, rho_step_m: float | None = None) -> ColumnPlan | None:
    """ColumnPlan of the transmitters `tx_m` (T, 3) for the grid vectors x_m, y_m (image rows), z_m, or None when
    the layout does not suit (no column of MIN_TABLE_COLUMN transmitters, too many columns or stragglers, or a
    table longer than MAX_RHO_SAMPLES). The rho step is `rho_step_m` if given, else the one whose bound is
    `term_tol`."""
    tx_m = np.asarray(tx_m, dtype=np.float64).reshape(-1, 3)
    cols_xz, table_tx, col_start, small_tx = _columns(tx_m)
    if len(cols_xz) == 0 or len(cols_xz) > kernels.MAX_COLUMNS or len(small_tx) > kernels.MAX_SMALL:
        return None
    y_m = np.asarray(y_m, dtype=np.float64)
    col_of = np.repeat(np.arange(len(cols_xz)), np.diff(col_start))
    dy2 = (y_m[:, None] - tx_m[table_tx, 1][None, :]) ** 2                         # (ny, Tq)
    a_lo = np.stack([dy2[:, col_of == c].min(axis=1) for c in range(len(cols_xz))], axis=1)
    a_hi = np.stack([dy2[:, col_of == c].max(axis=1) for c in range(len(cols_xz))], axis=1)
    rho_lo, rho_hi = _rho_range_m(cols_xz, x_m, z_m)
    k_max = 2.0 * np.pi * float(np.max(freqs_hz)) / C_M_PER_S
    m4 = fourth_derivative_bound(k_max, a_lo, a_hi, rho_lo, rho_hi)
    if rho_step_m is None:
        rho_step_m = (term_tol / (LAGRANGE4_CONST * m4)) ** 0.25
    rho0 = rho_lo - 1.5 * rho_step_m
    n_rho = int(np.ceil((rho_hi - rho0) / rho_step_m)) + 4
    if n_rho > MAX_RHO_SAMPLES:
        return None
    return ColumnPlan(cols_xz, table_tx.astype(np.int32), col_start, small_tx.astype(np.int32), a_lo, a_hi,
                      float(rho0), float(rho_step_m), n_rho, float(LAGRANGE4_CONST * m4 * rho_step_m**4))



@functools.lru_cache(maxsize=16)
def _cached_plan(tx_key: bytes, freqs_key: bytes, x_key: bytes, y_key: bytes, z_key: bytes, term_tol: float
                 ) -> ColumnPlan | None:
    keys = (tx_key, freqs_key, x_key, y_key, z_key)
    tx_m, freqs_hz, x_m, y_m, z_m = (np.frombuffer(k, dtype=np.float64) for k in keys)
    return plan(tx_m.reshape(-1, 3), freqs_hz, x_m, y_m, z_m, term_tol=term_tol)


def cached_plan(tx_m, freqs_hz, x_m, y_m, z_m, term_tol: float = TERM_TOL) -> ColumnPlan | None:
    """`plan`, computed once per array, frequency set, grid and bound (fresh frames reuse it)."""
    keys = [np.ascontiguousarray(a, dtype=np.float64).tobytes() for a in (tx_m, freqs_hz, x_m, y_m, z_m)]
    return _cached_plan(*keys, float(term_tol))


def make_volume_launch(inputs: FrameInputs, buffers: BufferPool, rplan: ColumnPlan, x_m, y_m, z_m, out: wp.array):
    """Function that builds the frame's row tables and gathers every voxel of the grid x_m, y_m (image rows), z_m
    into out (1, nz * ny * nx) vec2f, flat in (z, y, x) order (as `correlation.make_launch` with a grid)."""
    dev = inputs.device
    sig = inputs.sig                                                       # (F, R, T) normalised, host
    n_freqs, n_rx = sig.shape[0], sig.shape[1]
    n_cols, ny = len(rplan.cols_xz_m), len(y_m)

    def f64(a):
        return wp.array(np.ascontiguousarray(a, dtype=np.float64), dtype=wp.float64, device=dev)
    x, y, z = f64(x_m), f64(y_m), f64(z_m)
    a_lo, a_hi = f64(rplan.a_lo), f64(rplan.a_hi)
    tx_y = f64(inputs.tx_m[rplan.table_tx, 1])
    tx_col = wp.array(rplan.table_tx_col.astype(np.int32), dtype=wp.int32, device=dev)
    table_tx = wp.array(rplan.table_tx, dtype=wp.int32, device=dev)
    col_start = wp.array(rplan.col_start.astype(np.int32), dtype=wp.int32, device=dev)
    cycles = f64(inputs.freqs_hz / C_M_PER_S)
    cols = wp.array(rplan.cols_xz_m, dtype=wp.vec2d, device=dev)
    small_tx = wp.array(inputs.tx_m[rplan.small_tx].astype(np.float32).reshape(-1, 3), dtype=wp.vec3f, device=dev)
    small_sig = wp.array(vec2_of(np.ascontiguousarray(sig[:, :, rplan.small_tx])), dtype=wp.vec2f, device=dev)
    phasors = buffers.get("columns.phasors", (ny, n_freqs, len(rplan.table_tx), rplan.n_rho), wp.vec2f)
    table = buffers.get("columns.table", (ny * n_freqs * n_rx * n_cols, rplan.n_rho), wp.vec4f)
    n_voxels = len(x_m) * ny * len(z_m)

    def run():
        wp.launch(kernels.column_phasors, dim=phasors.shape, inputs=[
            y, tx_y, tx_col, a_lo, a_hi, cycles, wp.float64(rplan.rho0_m), wp.float64(rplan.rho_step_m), phasors],
            device=dev)
        wp.launch(kernels.column_table, dim=(ny, n_freqs, n_rx * n_cols, rplan.n_rho),
                  inputs=[inputs.signal, table_tx, col_start, phasors, table], device=dev)
        wp.launch(kernels.column_gather, dim=n_voxels, inputs=[
            x, y, z, inputs.rx, small_tx, small_sig, cols, a_lo, a_hi, inputs.k, cycles,
            wp.float64(rplan.rho0_m), wp.float64(1.0 / rplan.rho_step_m), table, out],
            block_dim=GATHER_BLOCK, device=dev)
        return out
    return run
