"""Hostile file contents, built byte by byte: pickled frames, .npy headers, JSON texts and PNG headers that
declare far more than they hold, nest without end or call what they must not. Used by tests/test_hostile_*.py.

Every builder returns bytes (never touching the disk), so a test can write them into a private copy of a
capture and check that the reader ends in one DatasetError naming the file, within bounded memory and time.
"""
from __future__ import annotations

import io
import os
import pickle
import struct
import zlib

import numpy as np

_NPY_OBJECT_HEADER = "{'descr': '|O', 'fortran_order': False, 'shape': (), }"


# ------------------------------------------------------------------------------------------------ .npy files
def npy_with_header(header: str, payload: bytes, version: int = 1) -> bytes:
    """A .npy file: magic, version, `header` (padded as numpy does) and `payload`."""
    text = header.encode("latin1")
    if version == 1:
        pad = -(10 + len(text) + 1) % 64
        return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(text) + pad + 1) + text + b" " * pad + b"\n" + payload
    pad = -(12 + len(text) + 1) % 64
    return b"\x93NUMPY" + bytes([version, 0]) + struct.pack("<I", len(text) + pad + 1) + text + b" " * pad + \
        b"\n" + payload


def npy_pickle(payload: bytes) -> bytes:
    """A frame file whose pickle is exactly `payload` (as np.save writes it, minus numpy's own pickling)."""
    return npy_with_header(_NPY_OBJECT_HEADER, payload)


def npy_object(obj) -> bytes:
    """What `np.save(path, obj)` writes for a Python object (a 0-d object array around it)."""
    holder = np.empty((), dtype=object)
    holder[()] = obj
    buffer = io.BytesIO()
    np.save(buffer, holder, allow_pickle=True)
    return buffer.getvalue()


class Reduces:
    """Pickles as `function(*args)` (optionally with BUILD state): how an attacker spells any call."""

    def __init__(self, function, args, state=None):
        self.function, self.args, self.state = function, args, state

    def __reduce__(self):
        return (self.function, self.args) if self.state is None else (self.function, self.args, self.state)


def _frame_with(xr) -> dict:
    return {"xr": xr, "fvec": np.linspace(72e9, 82e9, 16), "number_of_measurements": 1,
            "timestamp_us": np.array([0])}


def _op_unicode(text: str) -> bytes:
    data = text.encode()
    return b"\x8c" + bytes([len(data)]) + data          # SHORT_BINUNICODE


def _dict_xr(value_ops: bytes) -> bytes:
    """Protocol-4 pickle of {'xr': <value built by value_ops>}."""
    return b"\x80\x04}" + _op_unicode("xr") + value_ops + b"s."    # EMPTY_DICT, key, value, SETITEM, STOP


def deep_list_pickle(depth: int) -> bytes:
    """{'xr': [[[...]]]} nested `depth` deep, built on the unpickler's stack (EMPTY_LIST x depth, APPEND)."""
    return _dict_xr(b"]" * depth + b"a" * (depth - 1))


def memo_chain_pickle(depth: int) -> bytes:
    """{'xr': [[[...]]]} nested `depth` deep with a bounded stack: each level appends the previous one (memo)."""
    ops = [b"]", b"\x94"]                                         # EMPTY_LIST, MEMOIZE (index 0)
    for level in range(depth):
        ops += [b"0", b"]", b"h" + bytes([level % 256]) if level < 256 else b"j" + struct.pack("<I", level),
                b"a", b"\x94"]                                   # POP, EMPTY_LIST, GET prev, APPEND, MEMOIZE
    # MEMOIZE numbers memo entries 0, 1, 2, ...: level k's list is entry k + 1
    return _dict_xr(b"".join(ops))


def billion_laughs_pickle(levels: int = 24, fan_out: int = 10) -> bytes:
    """{'xr': L_levels} where L_k = [L_{k-1}] * fan_out through memo references: fan_out ** levels leaves."""
    ops = [_op_unicode("lol"), b"\x94"]                           # memo 0: 'lol'
    for level in range(levels):
        get = b"h" + bytes([level]) if level < 256 else b"j" + struct.pack("<I", level)
        ops += [b"0", b"]", b"(" + get * fan_out + b"e", b"\x94"]   # POP, EMPTY_LIST, MARK, GET x n, APPENDS, memo
    return _dict_xr(b"".join(ops))


def cyclic_list_frame() -> bytes:
    cycle: list = []
    cycle.append(cycle)
    return npy_object(_frame_with(cycle))


def cyclic_dict_frame() -> bytes:
    frame = _frame_with(None)
    frame["self"] = frame
    return npy_object(frame)


def huge_memo_index_pickle() -> bytes:
    """LONG_BINPUT 0xFFFFFFF0: the C unpickler would grow its memo to that many entries (64 GiB)."""
    return b"\x80\x04}r" + struct.pack("<I", 0xFFFFFFF0) + b"."


def long_decimal_pickle(digits: int = 5000) -> bytes:
    """Protocol-0 LONG with `digits` decimal digits (Python refuses int() of > 4300 digits)."""
    return b"(dp0\nVxr\np1\nL" + b"9" * digits + b"L\ns."


def huge_bytes_length_pickle() -> bytes:
    """BINBYTES8 that declares 2**60 bytes and holds 8."""
    return _dict_xr(b"\x8e" + struct.pack("<Q", 1 << 60) + b"12345678")


def huge_frame_opcode_pickle() -> bytes:
    """A FRAME opcode declaring 2**62 bytes."""
    return b"\x80\x04\x95" + struct.pack("<Q", 1 << 62) + b"}."


def void_scalar_frame() -> bytes:
    """A numpy scalar of a structured void dtype with a field beyond its bytes (crashed numpy: SIGSEGV)."""
    forged = Reduces(np.dtype, ("V8", False, True), (3, "|", None, ("a",), {"a": (np.dtype("<f8"), 1 << 20)}, 8, 1, 16))
    return npy_object(_frame_with(Reduces(np._core.multiarray.scalar, (forged, b"\0" * 8))))


def subarray_dtype_frame() -> bytes:
    """An array state whose dtype is a (1000, 1000) sub-array of complex128: the shape claims 843 GiB."""
    state = (1, (96, 96, 12), np.dtype(("c16", (1000, 1000))), False, b"\0" * 64)
    return npy_object(_frame_with(Reduces(np._core.multiarray._reconstruct, (np.ndarray, (0,), b"b"), state)))


def structured_array_frame() -> bytes:
    xr = np.zeros((96, 96, 16), dtype=[("re", "<f4"), ("im", "<f4")])
    return npy_object(_frame_with(xr))


def zero_stride_frame() -> bytes:
    """numpy.ndarray called directly on 16 bytes with stride 0: a (2**32,) complex128 view (64 GiB)."""
    return npy_object(_frame_with(Reduces(np.ndarray, ((1 << 32,), np.dtype("c16"), b"\0" * 16, 0, (0,)))))


def negative_stride_frame() -> bytes:
    return npy_object(_frame_with(Reduces(np.ndarray, ((4,), np.dtype("c16"), b"\0" * 64, 48, (-16,)))))


def short_array_data_frame() -> bytes:
    """A numpy array state whose shape needs 1.2 MB but which carries 64 bytes."""
    state = (1, (96, 96, 16), np.dtype("c8"), False, b"\0" * 64)
    return npy_object(_frame_with(Reduces(np._core.multiarray._reconstruct, (np.ndarray, (0,), b"b"), state)))


def huge_shape_frame() -> bytes:
    """An array state whose shape claims 2**40 elements."""
    state = (1, (1 << 20, 1 << 20), np.dtype("c8"), False, b"\0" * 64)
    return npy_object(_frame_with(Reduces(np._core.multiarray._reconstruct, (np.ndarray, (0,), b"b"), state)))


def string_array_frame() -> bytes:
    return npy_object(_frame_with(np.array(["a", "b"])))


def datetime_array_frame() -> bytes:
    return npy_object(_frame_with(np.array(["2020-01-01"], dtype="M8[D]")))


def persistent_id_pickle() -> bytes:
    return b"\x80\x04}" + _op_unicode("xr") + _op_unicode("x") + b"Qs."      # BINPERSID


def os_system_frame(marker: str) -> bytes:
    return npy_object(_frame_with(Reduces(os.system, (f"touch {marker}",))))


def eval_global_pickle() -> bytes:
    return b"\x80\x04}" + _op_unicode("xr") + b"cbuiltins\neval\n" + _op_unicode("1") + b"\x85Rs."


def protocol5_frame(short: bool = False) -> bytes:
    """A frame pickled with protocol 5 (`_frombuffer`); `short` cuts the buffer to half the bytes its shape needs."""
    xr = np.zeros((96, 96, 4), dtype=np.complex64)
    payload = pickle.dumps(_frame_with(xr), protocol=5)
    if short:
        payload = payload.replace(xr.tobytes(), xr.tobytes()[: xr.nbytes // 2])
        payload = payload.replace(struct.pack("<Q", xr.nbytes), struct.pack("<Q", xr.nbytes // 2))
    return npy_pickle(payload)


def build_on_dict_pickle() -> bytes:
    return b"\x80\x04}}b."                                        # EMPTY_DICT, EMPTY_DICT, BUILD


def pickle_array_state_twice() -> bytes:
    state = (1, (2,), np.dtype("f8"), False, b"\0" * 16)
    single = pickle.dumps(_frame_with(Reduces(np._core.multiarray._reconstruct, (np.ndarray, (0,), b"b"), state)),
                          protocol=4)
    marker = pickle.dumps(state, protocol=4)[2:-1]
    return npy_pickle(single.replace(b"b", b"b", 1)) if marker not in single else npy_pickle(single)


PICKLE_CASES = {
    "cyclic_list": cyclic_list_frame,
    "cyclic_dict": cyclic_dict_frame,
    "deep_nesting_stack": lambda: npy_pickle(deep_list_pickle(100_000)),
    "deep_nesting_memo": lambda: npy_pickle(memo_chain_pickle(100_000)),
    "billion_laughs": lambda: npy_pickle(billion_laughs_pickle()),
    "huge_memo_index": lambda: npy_pickle(huge_memo_index_pickle()),
    "long_decimal_5000_digits": lambda: npy_pickle(long_decimal_pickle()),
    "bytes8_length_2e60": lambda: npy_pickle(huge_bytes_length_pickle()),
    "frame_opcode_2e62": lambda: npy_pickle(huge_frame_opcode_pickle()),
    "void_scalar_out_of_bounds": void_scalar_frame,
    "subarray_dtype": subarray_dtype_frame,
    "structured_array": structured_array_frame,
    "zero_stride_ndarray_call": zero_stride_frame,
    "negative_stride_ndarray_call": negative_stride_frame,
    "array_data_too_short": short_array_data_frame,
    "array_shape_2e12": huge_shape_frame,
    "string_array": string_array_frame,
    "datetime_array": datetime_array_frame,
    "persistent_id": lambda: npy_pickle(persistent_id_pickle()),
    "global_eval": lambda: npy_pickle(eval_global_pickle()),
    "protocol5_short_buffer": lambda: protocol5_frame(short=True),
    "build_on_dict": lambda: npy_pickle(build_on_dict_pickle()),
}


# ------------------------------------------------------------------------------------------------ npy headers
def npy_header_cases() -> dict[str, bytes]:
    nested = "{'descr': '|O', 'fortran_order': False, 'shape': " + "(" * 3000 + ")" * 3000 + ", }"
    unary = "{'descr': '|O', 'fortran_order': False, 'shape': (" + "-" * 3000 + "1,), }"
    within = "{'descr': '|O', 'fortran_order': False, 'shape': " + "(" * 1800 + ")" * 1800 + ", }"
    return {
        "header_nested_parentheses": npy_with_header(nested, b""),
        "header_nested_within_length_limit": npy_with_header(within, b""),
        "header_unary_chain": npy_with_header(unary, b""),
        "header_length_2e31": b"\x93NUMPY\x02\x00" + struct.pack("<I", 1 << 31) + b"{",
        "header_numeric_huge_shape": npy_with_header("{'descr': '<c16', 'fortran_order': False, "
                                                     "'shape': (100000000000,), }", b""),
        "header_structured_descr": npy_with_header("{'descr': [('a', '<f8')], 'fortran_order': False, "
                                                   "'shape': (), }", b""),
        "header_extra_key": npy_with_header("{'descr': '|O', 'fortran_order': False, 'shape': (), "
                                            "'x': __import__('os'), }", b""),
        "header_version_9": b"\x93NUMPY\x09\x00" + b"\x10\x00" + b" " * 16,
    }


# --------------------------------------------------------------------------------------------------- JSON
def json_cases() -> dict[str, bytes]:
    return {
        "json_deep_100k": b"[" * 100_000 + b"]" * 100_000,
        "json_deep_objects": b'{"a":' * 20_000 + b"1" + b"}" * 20_000,
        "json_int_400_digits": b'{"distance_meters": ' + b"9" * 400 + b"}",
        "json_int_5000_digits": b'{"distance_meters": ' + b"9" * 5000 + b"}",
        "json_float_400_digits": b'{"distance_meters": 0.' + b"3" * 400 + b"}",
        "json_not_utf8": b'{"distance_meters": 0.3, "labels": ["\xff\xfe"]}',
    }


# ---------------------------------------------------------------------------------------------------- PNG
def _png_chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def png_declaring(width: int, height: int, bit_depth: int = 16, colour_type: int = 0) -> bytes:
    """A PNG whose header declares width x height but whose data is a few bytes (a decompression bomb header)."""
    ihdr = struct.pack(">IIBBBBB", width, height, bit_depth, colour_type, 0, 0, 0)
    idat = zlib.compress(b"\0" * 1024)
    return b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", idat) + _png_chunk(b"IEND", b"")


def png_bomb(width: int, height: int) -> bytes:
    """A real zero-filled 8-bit PNG of width x height, compressed (about 1/1000 of its pixel bytes)."""
    row = b"\0" * (width + 1)
    compressor = zlib.compressobj(9)
    data = b"".join(compressor.compress(row) for _ in range(height)) + compressor.flush()
    ihdr = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + _png_chunk(b"IHDR", ihdr) + _png_chunk(b"IDAT", data) + _png_chunk(b"IEND", b"")
