"""Loading MAROON frame files (`np.save` of a dict, i.e. a pickle inside .npy) without executing anything.

The .npy header is parsed by numpy; the pickled payload goes through an unpickler that resolves only the globals
needed to rebuild plain numpy arrays, numpy scalars, dtypes and complex numbers. Anything else (a class, a
function, `os.system`, ...) is refused with a DatasetError naming the file, before it is called.
"""
from __future__ import annotations

import importlib
import io
import pickle
from pathlib import Path

import numpy as np

from bench.errors import DatasetError

# (module, name) pairs that may be looked up; `numpy.core` (files written by numpy 1.x) maps to `numpy._core`.
_ALLOWED_GLOBALS = {
    ("numpy._core.multiarray", "_reconstruct"),
    ("numpy._core.multiarray", "scalar"),
    ("numpy._core.numeric", "_frombuffer"),
    ("numpy", "ndarray"),
    ("numpy", "dtype"),
    ("builtins", "complex"),
}


class _RestrictedUnpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        canonical = module.replace("numpy.core", "numpy._core", 1) if module.startswith("numpy.core") else module
        if (canonical, name) not in _ALLOWED_GLOBALS:
            raise pickle.UnpicklingError(f"refused to load '{module}.{name}' (only plain arrays, numbers, strings, "
                                         "lists and dicts are admitted)")
        return getattr(importlib.import_module(canonical), name)


def _check_plain(value, where: str) -> None:
    """Admit only numpy arrays of numbers/strings, numpy scalars, numbers, strings, lists, tuples and dicts."""
    if isinstance(value, np.ndarray):
        if value.dtype.hasobject:
            raise ValueError(f"{where} is an object array")
    elif isinstance(value, dict):
        for key, item in value.items():
            if not isinstance(key, str):
                raise ValueError(f"{where} has a non-string key {key!r}")
            _check_plain(item, f"{where}[{key!r}]")
    elif isinstance(value, (list, tuple)):
        for i, item in enumerate(value):
            _check_plain(item, f"{where}[{i}]")
    elif not isinstance(value, (bool, int, float, complex, str, bytes, np.generic)) and value is not None:
        raise ValueError(f"{where} has type {type(value).__name__}")


def load_pickled_dict(path: str | Path) -> dict:
    """Read a MAROON frame `.npy` (0-d object array wrapping a dict) safely; returns the plain dict."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise DatasetError(path, f"cannot read frame file ({err.strerror or err})") from None
    stream = io.BytesIO(raw)
    try:
        version = np.lib.format.read_magic(stream)
        read_header = {(1, 0): np.lib.format.read_array_header_1_0,
                       (2, 0): np.lib.format.read_array_header_2_0}.get(version)
        if read_header is None:
            raise ValueError(f"unsupported .npy format version {version}")
        shape, _, dtype = read_header(stream)
    except (ValueError, EOFError, SyntaxError, TypeError) as err:
        raise DatasetError(path, f"not a valid .npy file ({err})") from None
    if not (dtype.hasobject and shape == ()):
        raise DatasetError(path, f"expected a pickled dict (0-d object array), found a {dtype} array of shape {shape}")
    try:
        value = _RestrictedUnpickler(stream).load()
        if isinstance(value, np.ndarray) and value.shape == () and value.dtype.hasobject:
            value = value.item()
        if not isinstance(value, dict):
            raise ValueError(f"the pickled object is a {type(value).__name__}, not a dict")
        _check_plain(value, "frame")
    except pickle.UnpicklingError as err:
        raise DatasetError(path, f"unsafe or invalid pickle: {err}") from None
    except (ValueError, TypeError, EOFError, AttributeError, IndexError, KeyError, MemoryError,
            OverflowError, ImportError) as err:
        raise DatasetError(path, f"malformed pickled frame: {err}") from None
    return value
