"""Arrays compressed into HDF5 chunks in Python (bench.harness.h5chunks) read back as HDF5's own gzip + shuffle
filters wrote them: every value bit for bit (NaN payloads, -0.0, infinities), dtype, shape, filters and attributes,
on fresh random maps; with zlib's default strategy the chunks are HDF5's own bytes; constant chunks and a repeated
ground truth are compressed once, and an array that only looks like a kept one is compressed anew."""
from __future__ import annotations

import io
import os
import zlib

import h5py
import numpy as np
import pytest

from bench.harness import h5chunks, store
from bench.harness.store import ARRAY_NAMES, cell_image, compress_arrays, copy_cell, write_arrays

from hostile_tools import REPO

ATTRS = {"bb_min_m": [-0.15, -0.15, 0.2], "bb_max_m": [0.15, 0.15, 0.4], "grid_size": [301, 301, 201], "key": "k"}


def _map(rng, shape, nan_share: float, dtype=np.float64) -> np.ndarray:
    """A depth-like map: a smooth surface in a blob, NaN around it (`nan_share` of the pixels), odd bit patterns."""
    values = (0.3 + 0.01 * rng.standard_normal(shape)).astype(dtype)
    if values.dtype.kind == "f" and values.size:
        flat = values.reshape(-1)
        order = np.argsort(np.abs(np.linspace(-1, 1, flat.size)) + 0.2 * rng.random(flat.size))
        flat[order[int(round((1 - nan_share) * flat.size)):]] = np.nan      # NaN outside a central run
        odd = rng.choice(flat.size, size=min(flat.size, 12), replace=False)
        flat[odd[:3]] = [-0.0, np.inf, -np.inf][: len(odd[:3])]
        bits = flat.view(f"u{flat.itemsize}")
        high = np.array(1 << (8 * flat.itemsize - 1), bits.dtype)            # the sign bit
        bits[odd[3:6]] |= high                                              # -NaN, -x
        quiet = np.array(np.nan, dtype).view(bits.dtype)
        bits[odd[6:9]] = quiet | np.array(5, bits.dtype)                  # NaNs with a payload
    return values


def _hdf5s_own(path, group: str, arrays: dict, attrs: dict) -> None:
    """What store.write_arrays wrote before: h5py's own gzip level 1 + shuffle filters, h5py's auto chunks."""
    with h5py.File(path, "a") as h5:
        node = h5.require_group(group)
        for name, values in arrays.items():
            node.create_dataset(name, data=values, compression="gzip", compression_opts=1, shuffle=True)
        node.attrs.update(attrs)


def _read(path) -> dict:
    with h5py.File(path, "r") as h5:
        out = {}
        for group in h5:
            out[group] = {"attrs": {k: np.asarray(v).tolist() for k, v in h5[group].attrs.items()}}
            for name, node in h5[group].items():
                values = node[()]
                out[group][name] = (values.dtype.str, values.shape, node.compression, node.compression_opts,
                                    node.shuffle, np.asarray(values).tobytes())
    return out


def _cases(rng) -> dict[str, dict[str, np.ndarray]]:
    shapes = [(301, 301), (64, 48), (1, 5), (41, 3000), (7,), (3, 4, 5), (130, 20)]
    cases = {}
    for i, shape in enumerate(shapes):
        cases[f"g{i}"] = {"depth_m": _map(rng, shape, rng.choice([0.0, 0.5, 0.9, 0.97])),
                          "magnitude": _map(rng, shape, 1.0 if i == 2 else 0.86) * 1e3,
                          "gt_depth_m": _map(rng, shape, 0.9)}
    cases["dtypes"] = {"f32": _map(rng, (50, 301), 0.9, np.float32), "i16": rng.integers(-9, 9, (33, 17), np.int16),
                       "u8": rng.integers(0, 3, (20, 20), np.uint8), "i64": rng.integers(-2**62, 2**62, (9, 9)),
                       "bool": rng.random((6, 6)) < 0.5, "big_endian": _map(rng, (8, 9), 0.5).astype(">f8"),
                       "empty": np.zeros((0, 4))}
    cases["constant"] = {f"nan{i}": np.full(shape, np.nan) for i, shape in enumerate(shapes)}   # one pattern, any shape
    cases["constant"].update(zeros=np.zeros((301, 301)), ones=np.ones((301, 301)), minus_nan=-np.full((45, 9), np.nan))
    return cases


def test_arrays_read_back_as_hdf5s_own_filters_wrote_them(tmp_path):
    rng = np.random.default_rng()
    cases = _cases(rng)
    for group, arrays in cases.items():
        write_arrays(tmp_path / "new.h5", group, arrays, ATTRS)
        _hdf5s_own(tmp_path / "old.h5", group, arrays, ATTRS)
    new, old = _read(tmp_path / "new.h5"), _read(tmp_path / "old.h5")
    assert new.keys() == old.keys() == cases.keys()
    for group in cases:
        assert new[group] == old[group], group
        for name, values in cases[group].items():                     # and what went in, bit for bit
            assert new[group][name][5] == np.ascontiguousarray(values).tobytes(), (group, name)
    with h5py.File(tmp_path / "new.h5") as h5:                            # bands of rows where compressed here
        assert h5["g0/depth_m"].chunks == h5chunks.chunk_shape((301, 301), 8) == (20, 301)
        assert h5["g3/depth_m"].chunks == (2, 3000)
        for group, arrays in cases.items():          # each chunk inflates to a whole chunk (what HDF5 expects)
            for name, values in arrays.items():
                node = h5[group][name]
                if h5chunks.supported(values):
                    rows = node.chunks[0]
                    for start in range(0, values.shape[0], rows):
                        _, data = node.id.read_direct_chunk((start,) + (0,) * (values.ndim - 1))
                        assert len(zlib.decompress(data)) == rows * values[0].nbytes, (group, name, start)


def test_a_cells_image_and_its_copy_into_arrays_h5_hold_the_same(tmp_path):
    rng = np.random.default_rng()
    arrays = _cases(rng)["g0"]
    image = cell_image(compress_arrays(arrays), ATTRS)
    with h5py.File(io.BytesIO(image), "r") as source:
        copy_cell(source, tmp_path / "arrays.h5", "c", ATTRS)
    _hdf5s_own(tmp_path / "old.h5", "c", arrays, ATTRS)
    assert _read(tmp_path / "arrays.h5") == _read(tmp_path / "old.h5")


def test_chunks_are_hdf5s_own_bytes_with_zlibs_default_strategy(tmp_path, monkeypatch):
    """The shuffle, the padding of a partial last band and the deflate framing are HDF5's: with the strategy HDF5's
    deflate filter uses, every chunk is byte for byte the one HDF5 writes for the same chunk shape."""
    monkeypatch.setattr(h5chunks, "STRATEGY", zlib.Z_DEFAULT_STRATEGY)
    rng = np.random.default_rng()
    for shape, dtype in [((301, 301), np.float64), ((245, 77), np.float32), ((9, 5, 3), np.int32)]:
        values = _map(rng, shape, 0.8, dtype) if np.dtype(dtype).kind == "f" else rng.integers(-99, 99, shape, dtype)
        ours = h5chunks.compress(values)
        assert shape[0] % ours.chunks[0] or len(shape) == 3                # a partial last band in the 2-D cases
        with h5py.File(tmp_path / f"{len(shape)}{np.dtype(dtype).str[1:]}.h5", "w") as h5:
            theirs = h5.create_dataset("x", data=values, chunks=ours.chunks, compression="gzip",
                                       compression_opts=h5chunks.LEVEL, shuffle=True)
            for index, data in enumerate(ours.data):
                mask, stored = theirs.id.read_direct_chunk((index * ours.chunks[0],) + (0,) * (len(shape) - 1))
                assert mask == 0 and stored == data, (shape, index)


def test_constant_chunks_and_a_repeated_ground_truth_are_compressed_once(monkeypatch):
    rng = np.random.default_rng()
    monkeypatch.setattr(h5chunks, "_constant", {})
    monkeypatch.setattr(h5chunks, "_recent", type(h5chunks._recent)())
    deflated = []
    real = h5chunks._deflate
    monkeypatch.setattr(h5chunks, "_deflate", lambda block: deflated.append(block.shape) or real(block))
    background = np.full((301, 301), np.nan)
    first = h5chunks.compress(background)
    assert len(first.data) == 16 and len(deflated) == 2         # 15 whole bands and the padded last one
    gt = _map(rng, (301, 301), 0.9)
    arrays = {"depth_m": _map(rng, (301, 301), 0.9), "magnitude": _map(rng, (301, 301), 0.9), "gt_depth_m": gt}
    once = compress_arrays(arrays)
    deflated.clear()
    again = compress_arrays({**arrays, "gt_depth_m": gt.copy()})
    assert again["gt_depth_m"].data == once["gt_depth_m"].data
    assert len(deflated) < 2 * 16                           # depth_m and magnitude anew (less their NaN bands)
    # an array equal to the kept one in every sampled element but not in one other: compressed anew, its own values
    step = gt.size // 64
    lookalike = gt.copy()
    lookalike.flat[step // 2] = 123.0
    assert h5chunks._fingerprint(lookalike) == h5chunks._fingerprint(gt)
    deflated.clear()
    compressed = compress_arrays({"gt_depth_m": lookalike})["gt_depth_m"]
    assert deflated and compressed.data != once["gt_depth_m"].data


@pytest.mark.parametrize("threads", [0, 3])
def test_arrays_compressed_on_threads_are_those_compressed_here(tmp_path, threads):
    from concurrent.futures import ThreadPoolExecutor

    rng = np.random.default_rng()
    arrays = {name: _map(rng, (301, 301), 0.9) for name in ARRAY_NAMES}
    with ThreadPoolExecutor(threads or 1) as pool:
        compressed = compress_arrays(arrays, pool if threads else None)
    store.write_arrays(tmp_path / "a.h5", "c", compressed, ATTRS)
    store.write_arrays(tmp_path / "b.h5", "c", arrays, ATTRS)
    assert _read(tmp_path / "a.h5") == _read(tmp_path / "b.h5")


def test_a_failed_write_of_compressed_chunks_is_one_oserror_and_no_partial_file(tmp_path):
    """The chunks are placed through the same guarded file object (bench.harness.store._update_h5): a file-size limit
    (the failed write of a full disk) in the middle of a capture's arrays ends in one OSError naming arrays.h5, the
    partial file removed; the process lives on (HDF5 that sees a failed write ends in a segmentation fault)."""
    import subprocess
    import sys

    script = f"""
import resource, numpy as np
from bench.harness.store import ARRAY_NAMES, compress_arrays, write_arrays
rng = np.random.default_rng()
arrays = {{name: rng.random((301, 301)) for name in ARRAY_NAMES}}
compressed = compress_arrays(arrays)
resource.setrlimit(resource.RLIMIT_FSIZE, (1_000_000, 1_000_000))
path = "{tmp_path}/arrays.h5"
try:
    for group in range(4):                     # ~2 MB of random maps a capture: the second one crosses the limit
        write_arrays(path, f"c{{group}}", compressed if group % 2 else arrays)
except OSError as err:
    print("error:", err)
"""
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [str(REPO), os.environ.get("PYTHONPATH")]))}
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120, env=env)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"error: {tmp_path}/arrays.h5: cannot write (File too large); the partial file " \
                                  "was removed", proc.stdout
    assert not (tmp_path / "arrays.h5").exists()
