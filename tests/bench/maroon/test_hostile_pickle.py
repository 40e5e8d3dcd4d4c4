"""Hostile pickled frames and .npy headers: each ends in one DatasetError naming the frame file, within bounded
memory and time, without running anything; plain frames in any numeric dtype, order and protocol still load.

Cases by construction (bench/stress/hostile_inputs.py) plus properties (hypothesis): byte mutations of a real frame,
random opcode streams, every dtype family, shared-reference fan-outs."""
from __future__ import annotations

import io
import pickle
import struct
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

from bench.maroon import reader
from bench.maroon.limits import Limits, use_limits
from bench.maroon.safe_pickle import load_pickled_dict
from bench.stress import hostile_inputs as hi
from methods.domain.errors import DatasetError

from hostile_tools import bounded, copy_capture, frame_file, tree_digest

PROPERTY = settings(max_examples=60, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])
CASES = {**{name: build for name, build in hi.PICKLE_CASES.items()},
         **{name: (lambda data=data: data) for name, data in hi.npy_header_cases().items()}}


@pytest.fixture(scope="module")
def source_capture(synth_capture):
    return synth_capture("01_plate", 30, frequency_points=16)


@pytest.fixture(scope="module")
def real_frame_bytes(source_capture) -> bytes:
    return frame_file(source_capture).read_bytes()


def _load(path: Path, seconds: float = 20.0):
    with bounded(seconds):
        return load_pickled_dict(path)


@pytest.mark.parametrize("case", sorted(CASES))
def test_hostile_frame_ends_in_one_error_naming_the_file(case, tmp_path):
    path = tmp_path / "000000.npy"
    path.write_bytes(CASES[case]())
    with pytest.raises(DatasetError) as info:
        _load(path)
    assert info.value.path == path and "\n" not in str(info.value), str(info.value)


def test_malicious_pickle_never_runs_through_the_whole_reader(source_capture, tmp_path):
    capture = copy_capture(source_capture, tmp_path / "root")
    marker = tmp_path / "pwned"
    frame_file(capture).write_bytes(hi.os_system_frame(str(marker)))
    before = tree_digest(tmp_path / "root")
    with pytest.raises(DatasetError, match="refused to load 'posix.system'"), bounded():
        reader.read_capture(capture)
    assert not marker.exists() and tree_digest(tmp_path / "root") == before


@pytest.mark.parametrize("case, message", [
    ("billion_laughs", "billion laughs"), ("deep_nesting_stack", "nesting depth"),
    ("deep_nesting_memo", "nesting depth"), ("cyclic_list", "cyclic"), ("huge_memo_index", "memo index"),
    ("void_scalar_out_of_bounds", "not a plain numeric dtype"), ("subarray_dtype", "not a plain numeric dtype"),
    ("zero_stride_ndarray_call", "numpy.ndarray directly"), ("array_shape_2e12", "array_elements"),
    ("long_decimal_5000_digits", "4300 decimal digits"), ("header_nested_parentheses", "npy_header_bytes"),
])
def test_the_message_says_what_is_wrong(case, message, tmp_path):
    path = tmp_path / "000000.npy"
    path.write_bytes(CASES[case]())
    with pytest.raises(DatasetError, match=message):
        _load(path)


def test_limits_are_configurable(real_frame_bytes, tmp_path):
    path = tmp_path / "000000.npy"
    path.write_bytes(real_frame_bytes)
    assert set(_load(path)) == {"xr", "fvec", "number_of_measurements", "timestamp_us"}
    with use_limits(Limits(array_elements=1000)), pytest.raises(DatasetError, match="array_elements"):
        _load(path)
    with use_limits(Limits(frame_bytes=1000)), pytest.raises(DatasetError, match="frame_bytes"):
        _load(path)


# ---------------------------------------------------------------------------------------------- properties
@PROPERTY
@given(edits=st.lists(st.tuples(st.integers(min_value=0), st.integers(0, 255), st.sampled_from("sid")),
                      min_size=1, max_size=8),
       cut=st.one_of(st.none(), st.integers(min_value=0)))
def test_mutated_real_frames_load_plainly_or_fail_cleanly(real_frame_bytes, tmp_path, edits, cut):
    """Set, insert or delete bytes anywhere in a real frame (header, opcodes, array data), maybe truncate it."""
    data = bytearray(real_frame_bytes)
    for position, value, kind in edits:
        position %= len(data)
        if kind == "s":
            data[position] = value
        elif kind == "i":
            data.insert(position, value)
        else:
            del data[position]
    if cut is not None:
        data = data[: cut % (len(data) + 1)]
    path = tmp_path / "000000.npy"
    path.write_bytes(bytes(data))
    try:
        frame = _load(path)
    except DatasetError as err:
        assert err.path == path
        return
    _assert_plain(frame)


def _assert_plain(value, depth: int = 0) -> None:
    assert depth <= Limits().pickle_depth
    if isinstance(value, np.ndarray):
        assert value.dtype.kind in "biufc" and value.dtype.fields is None
        assert value.flags.c_contiguous or value.flags.f_contiguous
        assert value.base is None or value.flags.owndata or value.size == 0 or all(s > 0 for s in value.strides)
    elif isinstance(value, dict):
        assert all(isinstance(k, str) for k in value)
        for item in value.values():
            _assert_plain(item, depth + 1)
    elif isinstance(value, (list, tuple)):
        for item in value:
            _assert_plain(item, depth + 1)
    else:
        assert value is None or isinstance(value, (bool, int, float, complex, str, bytes, bytearray, np.generic))


_OPCODES = [b"N", b"\x88", b"\x89", b"K\x01", b"K\xff", b"J\x00\x00\x00\x80", b"]", b")", b"}", b"(", b"a", b"e",
            b"t", b"l", b"d", b"s", b"u", b"0", b"1", b"2", b"\x94", b"h\x00", b"h\x01", b"h\x05", b"\x85", b"\x86",
            b"\x87", b"R", b"b", b"\x8c\x02xr", b"C\x08" + b"\0" * 8, b"G" + b"\0" * 8, b"q\x00", b"q\x07",
            b"\x93", b"c", b"\x8c\x05numpy", b"\x8c\x07ndarray", b"\x8c\x05dtype", b"\x8c\x02c8",
            b"\x8c\x16numpy._core.multiarray", b"\x8c\x0c_reconstruct", b"\x8c\x06scalar", b"Q", b"\x81", b"\x92"]


@PROPERTY
@given(ops=st.lists(st.sampled_from(_OPCODES), max_size=60))
def test_random_opcode_streams_fail_cleanly(tmp_path, ops):
    """Any sequence of (admitted and refused) opcodes, globals included, between PROTO 4 and STOP."""
    path = tmp_path / "000000.npy"
    path.write_bytes(hi.npy_pickle(b"\x80\x04" + b"".join(ops) + b"."))
    try:
        frame = _load(path)
    except DatasetError as err:
        assert err.path == path
        return
    _assert_plain(frame)


_DTYPES = st.sampled_from(["?", "i1", "<i2", ">i4", "<i8", "u1", ">u2", "<u8", "<f2", ">f4", "<f8", "<c8", ">c16",
                           "U3", "S2", "O", "M8[D]", "m8[s]", "V4", "f4,i4", "(2,)f8"])


@PROPERTY
@given(dtype=_DTYPES, shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=4),
       order=st.sampled_from("CF"), protocol=st.sampled_from([2, 3, 4, 5]), data=st.data())
def test_numeric_arrays_round_trip_and_nothing_else_is_admitted(tmp_path, dtype, shape, order, protocol, data):
    dtype = np.dtype(dtype)
    if dtype.kind in "biufc" and dtype.fields is None:
        values = data.draw(hnp.arrays(dtype, shape))
    else:
        values = np.zeros(shape, dtype=dtype)
    values = np.asfortranarray(values) if order == "F" else np.ascontiguousarray(values)
    holder = np.empty((), dtype=object)
    holder[()] = {"xr": values}
    path = tmp_path / "000000.npy"
    path.write_bytes(hi.npy_pickle(pickle.dumps(holder, protocol=protocol)))
    dtype = values.dtype                          # a sub-array dtype becomes plain f8 with a longer shape
    numeric = dtype.kind in "biufc" and dtype.fields is None and dtype.subdtype is None
    if not numeric:
        with pytest.raises(DatasetError):
            _load(path)
        return
    loaded = _load(path)["xr"]
    assert loaded.dtype == values.dtype and loaded.shape == values.shape
    assert loaded.tobytes(order="C") == values.tobytes(order="C")            # bit-exact, NaN payloads included
    assert loaded.flags.c_contiguous or loaded.flags.f_contiguous


@PROPERTY
@given(levels=st.integers(1, 30), fan_out=st.integers(1, 12))
def test_shared_references_load_only_when_the_expansion_stays_near_the_file(tmp_path, levels, fan_out):
    path = tmp_path / "000000.npy"
    payload = hi.billion_laughs_pickle(levels, fan_out)
    path.write_bytes(hi.npy_pickle(payload))
    leaves = fan_out ** levels
    try:
        frame = _load(path, seconds=10.0)
    except DatasetError as err:
        assert "billion laughs" in err.problem or "nesting depth" in err.problem, err.problem
        assert leaves > len(payload) or levels > Limits().pickle_depth - 1
        return
    assert leaves <= 2 * len(payload) + 64           # admitted: at most twice the opcodes
    _assert_plain(frame)


def test_numpy_1x_module_names_still_load(tmp_path):
    """Frames written by numpy 1.x name `numpy.core.multiarray`; they are the same plain arrays."""
    holder = np.empty((), dtype=object)
    holder[()] = {"xr": np.arange(6, dtype=np.complex64).reshape(2, 3), "n": np.int64(3)}
    payload = pickle.dumps(holder, protocol=2).replace(b"numpy._core", b"numpy.core")
    path = tmp_path / "000000.npy"
    path.write_bytes(hi.npy_pickle(payload))
    frame = _load(path)
    assert frame["xr"].shape == (2, 3) and frame["n"] == 3


def test_header_parser_accepts_what_numpy_writes_in_every_version(tmp_path):
    for version in (1, 2, 3):
        holder = np.empty((), dtype=object)
        holder[()] = {"fvec": np.linspace(72e9, 82e9, 4)}
        buffer = io.BytesIO()
        np.lib.format.write_array(buffer, holder, version=(version, 0), allow_pickle=True)
        path = tmp_path / f"v{version}.npy"
        path.write_bytes(buffer.getvalue())
        assert np.array_equal(_load(path)["fvec"], np.linspace(72e9, 82e9, 4))


def test_a_header_longer_than_its_file_is_refused(tmp_path):
    path = tmp_path / "000000.npy"
    path.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", 4000) + b"{'descr'")
    with pytest.raises(DatasetError, match="truncated header"):
        _load(path)
