"""Warp kernels that build a new frame's tensor-core operand on the device (launched by
`methods.backends.warp.frames`), reproducing the host tables of `FrameInputs` from the raw frame (R, T, F) vec2f:

* `signal_gain`: per frequency the largest |Re| or |Im| of the scaled samples (block maxima, then an atomic max; the
  exact float32 values the host's complex64 product gives, so the maximum is the host's);
* `tx_half_table`: the fp16 operand M_h^T of `correlate_tiles_tx_halves`, (F, 2, 96, TC2_KP): per Tx half h row j
  and column i the entry of M = [[Sr, Si], [-Si, Sr]] / gain (M's row i, column h * 48 + j of the [Re] half or
  96 + h * 48 + j - 48 of the [Im] half), the TC2_PAD columns zero; S padded with zeros to 96 x 96. Each entry is
  the host's float64 quotient rounded to fp16 (through float32 where Warp converts: a tie may round apart, 1 fp16
  ulp; tests/methods/backends/test_gpu_tables.py). The thread of entry (f, 0, 0, 0) writes the gain the kernel used (1
  where a
  frequency's samples are all zero);
* `tx_split_table`: the same entries and their scaled fp16 residuals, the operand of `correlate_tiles_tx_split`.
"""
from __future__ import annotations

import warp as wp

from methods.backends.warp.kernels.correlation import TC2_HALF, TC3_SCALE, TC_ANT, TC_K

GAIN_BLOCKS = 16      # blocks per frequency of `signal_gain`
GAIN_BLOCK_DIM = 256  # their threads (94 x 94 samples: ~4 loads each)


@wp.kernel(enable_backward=False)
def signal_gain(signal: wp.array3d(dtype=wp.vec2f), scale: wp.float32, gain_raw: wp.array(dtype=wp.float32)):
    """gain_raw[f] = max over (r, t) of max(|Re|, |Im|) of signal[r, t, f] * scale (gain_raw zeroed before);
    launch_tiled over (F, GAIN_BLOCKS) blocks of GAIN_BLOCK_DIM: each thread takes the maximum of a strided share,
    its block reduces them (tile_max) and one atomic max per block combines the blocks (one atomic per sample on F
    addresses cost 25 us per frequency pair on the H100; 2048 lanes' atomics on one address still 16 us)."""
    f, blk, lane = wp.tid()
    n_tx = signal.shape[1]
    m = wp.float32(0.0)
    for e in range(blk * wp.block_dim() + lane, signal.shape[0] * n_tx, GAIN_BLOCKS * wp.block_dim()):
        s = signal[e // n_tx, e % n_tx, f] * scale
        m = wp.max(m, wp.max(wp.abs(s[0]), wp.abs(s[1])))
    block_max = wp.tile_max(wp.tile(m))
    if lane == 0:
        wp.atomic_max(gain_raw, f, wp.tile_extract(block_max, 0))


def launch_tables(signal: wp.array, scale, gain_raw: wp.array, gain: wp.array, mat: wp.array, device) -> None:
    """A raw frame's (R, T, F) tensor-core operand into `mat` and its gains into `gain` (F,): `signal_gain` into
    gain_raw (F,), then `tx_half_table` for `mat` (F, 2, 96, TC2_KP) or `tx_split_table` for (F, 4, 96, TC2_KP)."""
    gain_raw.zero_()
    wp.launch_tiled(signal_gain, dim=[signal.shape[2], GAIN_BLOCKS], inputs=[signal, scale, gain_raw],
                    block_dim=GAIN_BLOCK_DIM, device=device)
    wp.launch(tx_split_table if mat.shape[1] == 4 else tx_half_table, dim=mat.shape,
              inputs=[signal, scale, gain_raw, gain, mat], device=device)


@wp.func
def table_quotient(signal: wp.array3d(dtype=wp.vec2f), scale: wp.float32, f: int, h: int, j: int, i: int,
                   g: wp.float64) -> wp.float64:
    """Entry (h, j, i < TC_K) of M_h^T before its rounding: M's row i, column of row j of Tx half h, over gain g."""
    col = h * TC2_HALF + j
    if j >= TC2_HALF:
        col = TC_ANT + h * TC2_HALF + j - TC2_HALF
    ri = i % TC_ANT
    ci = col % TC_ANT
    v = wp.float64(0.0)
    if ri < signal.shape[0] and ci < signal.shape[1]:
        s = signal[ri, ci, f] * scale
        re = wp.float64(s[0])
        im = wp.float64(s[1])
        if i < TC_ANT:
            v = re
            if col >= TC_ANT:
                v = im
        else:
            v = -im
            if col >= TC_ANT:
                v = re
    return v / g


@wp.func
def table_gain(gain_raw: wp.array(dtype=wp.float32), gain: wp.array(dtype=wp.float32), f: int, first: bool
               ) -> wp.float64:
    """Frequency f's gain (1 where its samples are all zero), written to gain[f] by its `first` entry's thread."""
    g = wp.float64(gain_raw[f])
    if g <= wp.float64(0.0):
        g = wp.float64(1.0)
    if first:
        gain[f] = wp.float32(g)
    return g


@wp.kernel(enable_backward=False)
def tx_half_table(signal: wp.array3d(dtype=wp.vec2f), scale: wp.float32, gain_raw: wp.array(dtype=wp.float32),
                  gain: wp.array(dtype=wp.float32), mat_h: wp.array4d(dtype=wp.float16)):
    """One fp16 entry (f, h, j, i) of M_h^T (module doc)."""
    f, h, j, i = wp.tid()
    g = table_gain(gain_raw, gain, f, h == 0 and j == 0 and i == 0)
    if i >= TC_K:
        mat_h[f, h, j, i] = wp.float16(0.0)
        return
    mat_h[f, h, j, i] = wp.float16(wp.float32(table_quotient(signal, scale, f, h, j, i, g)))


@wp.kernel(enable_backward=False)
def tx_split_table(signal: wp.array3d(dtype=wp.vec2f), scale: wp.float32, gain_raw: wp.array(dtype=wp.float32),
                   gain: wp.array(dtype=wp.float32), mat_hl: wp.array4d(dtype=wp.float16)):
    """One fp16 entry (f, 2 h + part, j, i) of `correlate_tiles_tx_split`'s operand: part 0 the entry of M_h^T
    (`tx_half_table`'s value), part 1 its residual (quotient - hi) * TC3_SCALE."""
    f, slot, j, i = wp.tid()
    g = table_gain(gain_raw, gain, f, slot == 0 and j == 0 and i == 0)
    if i >= TC_K:
        mat_hl[f, slot, j, i] = wp.float16(0.0)
        return
    q = table_quotient(signal, scale, f, slot // 2, j, i, g)
    hi = wp.float16(wp.float32(q))
    if slot % 2 == 0:
        mat_hl[f, slot, j, i] = hi
    else:
        mat_hl[f, slot, j, i] = wp.float16(wp.float32((q - wp.float64(wp.float32(hi))) * wp.float64(TC3_SCALE)))


@wp.kernel(enable_backward=False)
def flag_nonfinite(signal: wp.array3d(dtype=wp.vec2f), flag: wp.array(dtype=wp.int32)):
    """flag[0] = 1 where a sample of the raw frame (R, T, F) is NaN or Inf (flag zeroed before; every writer writes
    the same 1, so no atomic is needed)."""
    r, t, f = wp.tid()
    s = signal[r, t, f]
    if not (wp.isfinite(s[0]) and wp.isfinite(s[1])):
        flag[0] = 1
