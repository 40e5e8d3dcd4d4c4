"""Loading MAROON frame files (`np.save` of a dict, i.e. a pickle inside .npy) without executing anything, in
bounded memory and time.

Every step is bounded before it runs (limits: bench.maroon.limits):
1. the file is a checked regular file within `frame_bytes` (bench.maroon.safe_io);
2. the .npy header is parsed by a strict parser of its one-line dict (never `literal_eval`), at most
   `npy_header_bytes` long; it must declare a 0-d object array (a pickled object);
3. the pickle's opcodes are scanned before anything is built: only data, container, memo, GLOBAL/REDUCE/BUILD
   opcodes are admitted (no persistent ids, extensions, INST/OBJ/NEWOBJ, out-of-band buffers), at most
   `pickle_opcodes` of them, memo indices below that count (the C unpickler would size its memo by the index),
   frames and lengths within the file;
4. the unpickler resolves only the globals numpy needs, and each resolves to a checking stand-in, never to the
   real callable: arrays are admitted only as numpy pickles them (`_reconstruct` + state, or `_frombuffer`) with a
   plain numeric dtype (bool, int, uint, float, complex; no void, sub-array, structured, object or string dtype),
   a shape of at most `array_elements` elements and exactly the bytes that shape needs (so the array is C- or
   F-contiguous, with no zero or negative strides and no more data than the file holds); `numpy.ndarray` cannot be
   called; scalars and dtypes are checked the same way;
5. the decoded object is walked once: containers nested at most `pickle_depth` deep, no cycles, and shared
   references may not expand it much beyond what the file holds (at most twice its opcodes and bytes: a
   "billion laughs" pickle is refused); only dicts with string keys, lists, tuples, strings, bytes, numbers,
   None and the arrays above remain.
Anything else ends in a DatasetError naming the file.
"""
from __future__ import annotations

import io
import math
import pickle
import pickletools
import re
from pathlib import Path

import numpy as np

from bench.maroon import safe_io
from bench.maroon.limits import current_limits, too_large
from methods.domain.errors import DatasetError

_MAGIC = b"\x93NUMPY"
_HEADER_ITEM = re.compile(r"\s*'([a-z_]+)'\s*:\s*('[^'\\]*'|True|False|\([0-9,\s]*\))\s*(?:,|$)")
_OBJECT_DESCRS = {"|O", "<O", ">O", "=O", "O"}
_NUMERIC_SPEC = re.compile(r"^[biufc][0-9]{1,2}$")
_ALLOWED_OPCODES = {
    "PROTO", "FRAME", "STOP", "INT", "BININT", "BININT1", "BININT2", "LONG", "LONG1", "LONG4", "STRING",
    "BINSTRING", "SHORT_BINSTRING", "BINBYTES", "SHORT_BINBYTES", "BINBYTES8", "BYTEARRAY8", "UNICODE",
    "SHORT_BINUNICODE", "BINUNICODE", "BINUNICODE8", "NONE", "NEWTRUE", "NEWFALSE", "FLOAT", "BINFLOAT",
    "EMPTY_LIST", "APPEND", "APPENDS", "LIST", "EMPTY_TUPLE", "TUPLE", "TUPLE1", "TUPLE2", "TUPLE3", "EMPTY_DICT",
    "DICT", "SETITEM", "SETITEMS", "POP", "DUP", "MARK", "POP_MARK", "GET", "BINGET", "LONG_BINGET", "PUT",
    "BINPUT", "LONG_BINPUT", "MEMOIZE", "GLOBAL", "STACK_GLOBAL", "REDUCE", "BUILD",
}
_PUT_OPCODES = {"PUT", "BINPUT", "LONG_BINPUT"}
_MAX_NDIM = 32


class _Refused(Exception):
    """A value the frame format does not admit (becomes a DatasetError naming the file)."""


# ------------------------------------------------------------------------------------------ checked stand-ins
class _Placeholder:
    """Base of what the admitted globals build: plain Python objects that numpy never sees unchecked."""

    __slots__ = ()

    def __setstate__(self, state):
        raise _Refused(f"a {type(self).__name__[1:]} cannot take a state")


class _Dtype(_Placeholder):
    """numpy.dtype(spec, align, copy) + BUILD(state) of a plain numeric (or the wrapper's object) dtype."""

    __slots__ = ("spec", "byteorder")

    def __init__(self, spec, align=False, copy=False, *rest):
        if rest or not isinstance(spec, str) or not (_NUMERIC_SPEC.match(spec) or spec == "O8"):
            raise _Refused(f"dtype {str(spec)[:40]!r} is not a plain numeric dtype")
        self.spec, self.byteorder = spec, "="

    def __setstate__(self, state):
        if not isinstance(state, tuple) or len(state) not in (8, 9) or state[0] not in (3, 4):
            raise _Refused("malformed dtype state")
        _, byteorder, subarray, names, fields = state[:5]
        if subarray is not None or names is not None or fields is not None:
            raise _Refused("sub-array and structured dtypes are not admitted")
        if byteorder not in ("<", ">", "|", "="):
            raise _Refused("malformed dtype byte order")
        self.byteorder = byteorder

    @property
    def is_object(self) -> bool:
        return self.spec == "O8"

    def resolve(self) -> np.dtype:
        dtype = np.dtype(self.spec)
        if self.byteorder in "<>" and dtype.itemsize > 1:
            dtype = dtype.newbyteorder(self.byteorder)
        if dtype.kind not in "biufc" or dtype.fields is not None or dtype.subdtype is not None:
            raise _Refused(f"dtype {dtype} is not a plain numeric dtype")
        return dtype


def _numeric(dtype) -> np.dtype:
    if not isinstance(dtype, _Dtype) or dtype.is_object:
        raise _Refused("arrays and scalars must have a plain numeric dtype")
    return dtype.resolve()


def _element_count(shape) -> int:
    if not isinstance(shape, tuple) or len(shape) > _MAX_NDIM or not all(
            isinstance(n, int) and not isinstance(n, bool) and n >= 0 for n in shape):
        raise _Refused("malformed array shape")
    count = math.prod(shape)
    if count > current_limits().array_elements:
        raise _Refused(too_large(f"an array of shape {shape}: its element count", count, "array_elements"))
    return count


def _array_from_bytes(data, dtype: np.dtype, shape: tuple, fortran: bool) -> np.ndarray:
    count = _element_count(shape)
    if not isinstance(data, (bytes, bytearray)):
        raise _Refused("array data must be bytes")
    if len(data) != count * dtype.itemsize:
        raise _Refused(f"an array of shape {shape} and dtype {dtype} needs {count * dtype.itemsize} bytes, "
                       f"the file gives {len(data)}")
    return np.frombuffer(data, dtype=dtype, count=count).reshape(shape, order="F" if fortran else "C").copy(order="K")


class _Array(_Placeholder):
    """numpy's `_reconstruct(ndarray, (0,), b'b')` + BUILD(state): the state is checked, then copied."""

    __slots__ = ("value", "wrapped")

    def __init__(self):
        self.value, self.wrapped = None, None

    def __setstate__(self, state):
        if self.value is not None or self.wrapped is not None:
            raise _Refused("an array's state was set twice")
        if not isinstance(state, tuple) or len(state) not in (4, 5):
            raise _Refused("malformed array state")
        if len(state) == 5:
            if state[0] != 1:
                raise _Refused("malformed array state")
            state = state[1:]
        shape, dtype, fortran, data = state
        if not isinstance(fortran, bool):
            raise _Refused("malformed array state")
        if isinstance(dtype, _Dtype) and dtype.is_object:      # the 0-d object array np.save wraps the dict in
            if shape != () or not isinstance(data, list) or len(data) != 1:
                raise _Refused("object arrays are not admitted (only the 0-d wrapper of the frame dict)")
            self.wrapped = (data[0],)
            return
        self.value = _array_from_bytes(data, _numeric(dtype), shape, fortran)


class _Value(_Placeholder):
    """An already checked value (numpy scalar, complex number, protocol-5 array)."""

    __slots__ = ("value",)

    def __init__(self, value):
        self.value = value


class _NdarrayType(_Placeholder):
    """Stands for `numpy.ndarray` as the subtype argument of `_reconstruct`; calling it is refused."""

    __slots__ = ()

    def __call__(self, *args, **kwargs):
        raise _Refused("calling numpy.ndarray directly (arbitrary buffers, strides and offsets) is not admitted")


_NDARRAY = _NdarrayType()


def _reconstruct(subtype, shape, typecode):
    if subtype is not _NDARRAY or shape != (0,) or typecode != b"b":
        raise _Refused("malformed array reconstruction")
    return _Array()


def _scalar(dtype, data=None):
    dtype = _numeric(dtype)
    if not isinstance(data, bytes) or len(data) != dtype.itemsize:
        raise _Refused(f"a {dtype} scalar needs {dtype.itemsize} bytes")
    return _Value(np.frombuffer(data, dtype=dtype)[0])


def _frombuffer(data, dtype, shape, order):
    if order not in ("C", "F"):
        raise _Refused("malformed array order")
    return _Value(_array_from_bytes(data, _numeric(dtype), shape, order == "F"))


def _complex(real=0.0, imag=0.0):
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in (real, imag)):
        raise _Refused("complex() takes two real numbers here")
    return _Value(complex(real, imag))


def _encode(text, encoding="utf-8"):
    """`_codecs.encode(str, 'latin1')`: how protocol 2 spells bytes (numpy arrays pickled with protocol 2)."""
    if not isinstance(text, str) or encoding not in ("latin1", "latin-1"):
        raise _Refused("_codecs.encode is admitted only as protocol 2's spelling of bytes")
    return text.encode("latin1")


def _empty_bytes(*args):
    """`bytes()`: how protocol 2 spells b''."""
    if args:
        raise _Refused("bytes() is admitted only without arguments (protocol 2's b'')")
    return b""


# (module, name) pairs that may be looked up, and what they resolve to; `numpy.core` (numpy 1.x) = `numpy._core`,
# `__builtin__` (protocols 0-2) = `builtins`.
_GLOBALS = {
    ("numpy._core.multiarray", "_reconstruct"): _reconstruct,
    ("numpy._core.multiarray", "scalar"): _scalar,
    ("numpy._core.numeric", "_frombuffer"): _frombuffer,
    ("numpy", "ndarray"): _NDARRAY,
    ("numpy", "dtype"): _Dtype,
    ("builtins", "complex"): _complex,
    ("_codecs", "encode"): _encode,
    ("builtins", "bytes"): _empty_bytes,
}


class _RestrictedUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        canonical = module.replace("numpy.core", "numpy._core", 1) if module.startswith("numpy.core") else module
        canonical = "builtins" if canonical == "__builtin__" else canonical          # protocol 0-2 names
        found = _GLOBALS.get((canonical, name))
        if found is None:
            raise pickle.UnpicklingError(f"refused to load '{module[:60]}.{name[:60]}' (only plain arrays, numbers, "
                                         "strings, lists and dicts are admitted)")
        return found

    def persistent_load(self, pid):
        raise pickle.UnpicklingError("persistent ids are not admitted")


# ------------------------------------------------------------------------------------------------ the steps
def _npy_payload(path: Path, raw: bytes) -> bytes:
    """The bytes after a .npy header that declares a 0-d object array (DatasetError otherwise)."""
    limits = current_limits()
    if raw[:6] != _MAGIC or len(raw) < 10:
        raise DatasetError(path, "not a valid .npy file (no NUMPY magic)")
    major = raw[6]
    if major == 1:
        length, start = int.from_bytes(raw[8:10], "little"), 10
    elif major in (2, 3):
        length, start = int.from_bytes(raw[8:12], "little"), 12
    else:
        raise DatasetError(path, f"not a valid .npy file (unsupported format version {major}.{raw[7]})")
    if length > limits.npy_header_bytes:
        raise DatasetError(path, too_large("the .npy header's length in bytes", length, "npy_header_bytes"))
    if start + length > len(raw):
        raise DatasetError(path, "not a valid .npy file (truncated header)")
    try:
        header = raw[start:start + length].decode("utf-8" if major == 3 else "latin1").strip()
    except UnicodeDecodeError:
        raise DatasetError(path, "not a valid .npy file (header is not text)") from None
    items, pos = {}, 0
    inner = header[1:-1] if header.startswith("{") and header.endswith("}") else None
    while inner is not None and pos < len(inner.rstrip()):
        match = _HEADER_ITEM.match(inner, pos)
        if match is None:
            inner = None
            break
        items[match.group(1)] = match.group(2)
        pos = match.end()
    if inner is None or set(items) != {"descr", "fortran_order", "shape"}:
        raise DatasetError(path, "not a valid .npy file (its header is not a plain {'descr', 'fortran_order', "
                                 "'shape'} dict)")
    descr, shape = items["descr"].strip("'"), items["shape"]
    if descr not in _OBJECT_DESCRS or shape.replace(" ", "") != "()":
        raise DatasetError(path, f"expected a pickled dict (0-d object array), found a {descr[:40]} array of shape "
                                 f"{shape[:60]}")
    return raw[start + length:]


def _scan_opcodes(payload: bytes) -> int:
    """The number of opcodes; refuses opcodes outside the admitted set, too many opcodes, large memo indices and
    frames beyond the data (genops itself refuses lengths beyond the data and over-long decimal literals)."""
    limits = current_limits()
    count = 0
    try:
        for opcode, arg, pos in pickletools.genops(io.BytesIO(payload)):
            count += 1
            if count > limits.pickle_opcodes:
                raise _Refused(too_large("the pickle's opcode count", count, "pickle_opcodes"))
            if opcode.name not in _ALLOWED_OPCODES:
                raise _Refused(f"pickle opcode {opcode.name} is not admitted")
            if opcode.name in _PUT_OPCODES and not (isinstance(arg, int) and 0 <= arg < limits.pickle_opcodes):
                raise _Refused(f"memo index {arg} at byte {pos} is out of range")
            if opcode.name == "FRAME" and arg > len(payload) - pos:
                raise _Refused(f"a frame of {arg} bytes at byte {pos} runs past the end of the file")
    except ValueError as err:
        if "integer string conversion" in str(err):
            raise _Refused("an integer literal of more than 4300 decimal digits") from None
        raise _Refused(f"malformed opcodes ({str(err)[:160]})") from None
    return count


class _Walk:
    """Turns the stand-ins into plain values, refusing cycles, deep nesting and shared-reference expansion."""

    def __init__(self, opcode_budget: int, byte_budget: int, depth_limit: int):
        self.visits, self.bytes = 0, 0
        self.opcode_budget, self.byte_budget, self.depth_limit = opcode_budget, byte_budget, depth_limit
        self.on_path: set[int] = set()
        self.done: dict[int, tuple[object, int, int]] = {}   # id -> (plain value, visits, bytes)

    def _charge(self, nbytes: int, visits: int = 1) -> None:
        self.visits += visits
        self.bytes += nbytes
        if self.visits > self.opcode_budget or self.bytes > self.byte_budget:
            raise _Refused("shared references expand the frame far beyond the file's size (a 'billion laughs' "
                           "pickle)")

    def plain(self, value, where: str, depth: int = 0):
        if depth > self.depth_limit:
            raise _Refused(too_large(f"the nesting depth of containers in {where}", depth, "pickle_depth"))
        if isinstance(value, _Array):
            if value.value is None:
                raise _Refused(f"{where} is an object array or an array without data")
            self._charge(value.value.nbytes)
            return value.value
        if isinstance(value, _Value):
            self._charge(getattr(value.value, "nbytes", 16))
            return value.value
        if isinstance(value, _Placeholder):
            raise _Refused(f"{where} is a {type(value).__name__[1:]}, not data")
        if isinstance(value, (bool, float, complex)) or value is None:
            self._charge(8)
            return value
        if isinstance(value, int):
            self._charge(value.bit_length() // 8 + 8)
            return value
        if isinstance(value, (str, bytes, bytearray)):
            self._charge(len(value))
            return value
        if not isinstance(value, (dict, list, tuple)):
            raise _Refused(f"{where} has type {type(value).__name__}")
        key = id(value)
        if key in self.on_path:
            raise _Refused(f"{where} contains itself (a cyclic reference)")
        if key in self.done:                      # a shared container: built once, its whole size charged again
            out, visits, nbytes = self.done[key]
            self._charge(nbytes, visits)
            return out
        visits_before, bytes_before = self.visits, self.bytes
        self._charge(8 * len(value))
        self.on_path.add(key)
        try:
            if isinstance(value, dict):
                out = {}
                for item_key, item in value.items():
                    if not isinstance(item_key, str):
                        raise _Refused(f"{where} has a non-string key")
                    inner = f"{where}[{item_key[:40]!r}]" if depth < 2 else where
                    out[item_key] = self.plain(item, inner, depth + 1)
            else:
                out = type(value)(self.plain(item, f"{where}[{i}]" if depth < 2 else where, depth + 1)
                                  for i, item in enumerate(value))
        finally:
            self.on_path.discard(key)
        self.done[key] = (out, self.visits - visits_before, self.bytes - bytes_before)
        return out


def load_pickled_dict(path: str | Path) -> dict:
    """Read a MAROON frame `.npy` (0-d object array wrapping a dict) safely; returns the plain dict."""
    path = Path(path)
    limits = current_limits()
    raw = safe_io.read_bytes(path, "frame")
    payload = _npy_payload(path, raw)
    try:
        opcodes = _scan_opcodes(payload)
        value = _RestrictedUnpickler(io.BytesIO(payload)).load()
        if isinstance(value, _Array) and value.wrapped is not None:
            value = value.wrapped[0]
        if not isinstance(value, dict):
            raise _Refused(f"the pickled object is a {type(value).__name__.lstrip('_')}, not a dict")
        walk = _Walk(opcode_budget=2 * opcodes + 64,
                     byte_budget=2 * len(raw) + 65536, depth_limit=limits.pickle_depth)
        return walk.plain(value, "frame")
    except (pickle.UnpicklingError, _Refused) as err:
        raise DatasetError(path, f"unsafe or invalid pickle: {err}") from None
    except RecursionError:
        raise DatasetError(path, "malformed pickled frame: nested too deeply") from None
    except (ValueError, TypeError, EOFError, AttributeError, IndexError, KeyError, MemoryError,
            OverflowError, ImportError, UnicodeDecodeError) as err:
        raise DatasetError(path, f"malformed pickled frame: {type(err).__name__}: {str(err)[:200]}") from None
