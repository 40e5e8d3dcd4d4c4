"""Arrays compressed into HDF5 gzip + shuffle chunks by zlib in Python, written with `write_direct_chunk`.

HDF5's own filter pipeline compresses a chunk with the interpreter lock held by h5py and pays its filter and chunk
cache machinery per chunk (~14 ms for a capture's three 301 x 301 float64 maps on the 2-core development machine,
of which zlib ~7.7 ms). Here each chunk is shuffled by NumPy (bytes of equal significance together, as HDF5's
shuffle filter does) and deflated by zlib at `LEVEL` with the run-length strategy `STRATEGY` (28 % less time than
the default strategy on the maps, the same size; with the default strategy the bytes are those HDF5's deflate filter
writes: tests/bench/harness/test_h5chunks.py compares them). zlib releases the interpreter lock, so a capture's
arrays compress on several threads where there are cores (`compress_arrays`). Two shortcuts, both exact:

* a chunk whose elements are all one bit pattern (a map's NaN background: ~40 % of the chunks) is compressed once
  per pattern and chunk shape and its bytes kept (`_constant`);
* an array equal, bit for bit, to one compressed lately (the ground truth's depth map, the same in every cell of a
  capture) reuses its chunks (`_recent`; candidates found by a sample of its elements, then compared whole).

Chunks are bands of whole rows of about CHUNK_BYTES (h5py's auto chunks were 38 x 38 squares: 192 chunks for a
capture, 40 % of them constant; bands of 20 rows: 48, as large a share constant, ~25 % less zlib time). A partial
last band is padded with zeros, as HDF5 pads it. What a reader gets back (values, dtype, shape, the gzip and shuffle
filters) is what `create_dataset(..., compression="gzip", compression_opts=LEVEL, shuffle=True)` writes; only the
chunk shape differs.
"""
from __future__ import annotations

import dataclasses
import threading
import zlib
from collections import OrderedDict
from concurrent.futures import Executor

import h5py
import numpy as np

LEVEL = 1               # gzip level 1: a cell's mostly-NaN maps shrink 13x as with the default 4, in 2/3 of its time
STRATEGY = zlib.Z_RLE   # runs only: 28 % less zlib time than the default strategy on a capture's maps, the same size
CHUNK_BYTES = 48 << 10  # a chunk's size before compression: bands of rows (301 x 301 float64: 20 rows, 16 chunks)
RECENT_ARRAYS = 16      # arrays kept for a repeat: a run's ground truths (Table III: 8 captures a cell), twice over
_KINDS = "fiu"          # numeric dtypes in native byte order go this way; anything else through h5py's own filters
_lock = threading.Lock()
_constant: dict[tuple, bytes] = {}
_recent: OrderedDict[tuple, list[tuple[np.ndarray, list[bytes]]]] = OrderedDict()


@dataclasses.dataclass(frozen=True)
class Compressed:
    """An array as HDF5 chunks: its shape and dtype, the chunk shape, each chunk's deflated bytes (C order of the
    chunk grid)."""

    shape: tuple[int, ...]
    dtype: np.dtype
    chunks: tuple[int, ...]
    data: list[bytes]


def supported(values: np.ndarray) -> bool:
    """Whether `values` is compressed here (else h5py's own filters write it: `write`)."""
    return values.ndim >= 1 and values.size > 0 and values.dtype.kind in _KINDS and values.dtype.isnative


def chunk_shape(shape: tuple[int, ...], itemsize: int) -> tuple[int, ...]:
    """Bands of whole rows (all further axes whole) of about CHUNK_BYTES."""
    row_bytes = itemsize * int(np.prod(shape[1:], dtype=np.int64))
    return (max(1, min(shape[0], CHUNK_BYTES // max(row_bytes, 1))), *shape[1:])


def _deflate(block: np.ndarray) -> bytes:
    """HDF5's shuffle then deflate filters of one whole chunk (C-contiguous)."""
    planes = block.view(np.uint8).reshape(-1, block.dtype.itemsize).T
    packer = zlib.compressobj(LEVEL, zlib.DEFLATED, 15, 8, STRATEGY)
    return packer.compress(planes.tobytes()) + packer.flush()


def _deflate_chunk(values: np.ndarray, start: int, rows: int) -> bytes:
    block = values[start:start + rows]
    if block.shape[0] < rows:          # the last band, padded with zeros as HDF5 pads a partial edge chunk
        padded = np.zeros((rows, *values.shape[1:]), values.dtype)
        padded[:block.shape[0]] = block
        block = padded
    flat = _bits(block.reshape(-1))
    if flat is None or not (flat == flat[0]).all():
        return _deflate(np.ascontiguousarray(block))
    key = (values.dtype.str, block.shape, flat[:1].tobytes(), LEVEL, STRATEGY)
    data = _constant.get(key)
    if data is None:
        data = _deflate(np.ascontiguousarray(block))
        with _lock:
            if len(_constant) > 256:
                _constant.clear()
            _constant[key] = data
    return data


def _chunks(values: np.ndarray, rows: int) -> list[bytes]:
    return [_deflate_chunk(values, start, rows) for start in range(0, values.shape[0], rows)]


def _bits(values: np.ndarray) -> np.ndarray | None:
    """`values` as unsigned integers of its item size (bit patterns: NaN payloads and -0.0 compared as stored)."""
    return values.view(f"u{values.dtype.itemsize}") if values.dtype.itemsize in (1, 2, 4, 8) else None


def _bits_equal(a: np.ndarray, b: np.ndarray) -> bool:
    bits_a, bits_b = _bits(a), _bits(b)
    if bits_a is None or bits_b is None:
        return a.tobytes() == b.tobytes()
    return bool(np.array_equal(bits_a, bits_b))


def _fingerprint(values: np.ndarray) -> tuple:
    step = max(1, values.size // 64)
    return values.shape, values.dtype.str, values.reshape(-1)[::step].tobytes()


def compress(values: np.ndarray, repeats: bool = False) -> Compressed:
    """`values` (`supported`) as deflated chunks; `repeats`: an array that other calls may pass again (a ground
    truth), kept among the RECENT_ARRAYS for them."""
    values = np.ascontiguousarray(values)
    chunks = chunk_shape(values.shape, values.dtype.itemsize)
    if not repeats:
        return Compressed(values.shape, values.dtype, chunks, _chunks(values, chunks[0]))
    key = _fingerprint(values)
    with _lock:
        candidates = list(_recent.get(key, ()))
    for seen, data in candidates:
        if _bits_equal(seen, values):
            return Compressed(values.shape, values.dtype, chunks, data)
    data = _chunks(values, chunks[0])
    with _lock:
        _recent.setdefault(key, []).append((values.copy(), data))
        _recent.move_to_end(key)
        while sum(len(entries) for entries in _recent.values()) > RECENT_ARRAYS:
            _recent.popitem(last=False)
    return Compressed(values.shape, values.dtype, chunks, data)


def compress_arrays(arrays: dict[str, np.ndarray], repeated: tuple[str, ...] = (), pool: Executor | None = None
                    ) -> dict[str, Compressed | np.ndarray]:
    """Each `supported` array compressed (on `pool`'s threads where given; those named in `repeated` kept for a
    repeat: `compress`), the others (and those compressed already) as they are (`write`)."""
    arrays = {name: v if isinstance(v, Compressed) else np.asarray(v) for name, v in arrays.items()}
    todo = [name for name, v in arrays.items() if not isinstance(v, Compressed) and supported(v)]
    if pool is None:
        return {**arrays, **{name: compress(arrays[name], name in repeated) for name in todo}}
    futures = {name: pool.submit(compress, arrays[name], name in repeated) for name in todo}
    return {**arrays, **{name: future.result() for name, future in futures.items()}}


def write(group: h5py.Group, name: str, values: Compressed | np.ndarray) -> h5py.Dataset:
    """Dataset `name` in `group`: a `Compressed` array's chunks as they are, any other array through h5py's gzip
    and shuffle filters (the same reader-visible layout)."""
    if not isinstance(values, Compressed):
        return group.create_dataset(name, data=values, compression="gzip", compression_opts=LEVEL, shuffle=True)
    dataset = group.create_dataset(name, shape=values.shape, dtype=values.dtype, chunks=values.chunks,
                                   compression="gzip", compression_opts=LEVEL, shuffle=True)
    rest = (0,) * (len(values.shape) - 1)
    for index, data in enumerate(values.data):
        dataset.id.write_direct_chunk((index * values.chunks[0], *rest), data, 0)
    return dataset
