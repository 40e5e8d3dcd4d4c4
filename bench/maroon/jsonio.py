"""Reading JSON dataset files with bounded size, depth and number length, and errors that name the file.

Before parsing: the file is a checked regular file within `json_bytes` (bench.maroon.safe_io), UTF-8, and its nesting of
arrays and objects is measured by a linear scan (strings skipped) and refused beyond `json_depth`. While parsing,
every number literal longer than `json_number_chars` is refused (Python refuses integers of more than 4300 digits
with a ValueError of its own, and a 400-digit integer overflows a float later). See bench.maroon.limits.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from bench.maroon import safe_io
from bench.maroon.limits import current_limits, too_large
from methods.domain.errors import DatasetError

_QUOTE = ord('"')
_OPENS, _CLOSES = (ord("["), ord("{")), (ord("]"), ord("}"))


class _NumberTooLong(ValueError):
    pass


def nesting_depth(data: bytes) -> int:
    """Deepest nesting of `[`/`{` outside strings (linear time, vectorised; unbalanced text gives a bound)."""
    # escaped backslashes first, then escaped quotes (same length): every quote left delimits a string
    codes = np.frombuffer(data.replace(b"\\\\", b"__").replace(b'\\"', b"__"), dtype=np.uint8)
    if codes.size == 0:
        return 0
    quotes = np.flatnonzero(codes == _QUOTE)
    toggles = np.zeros(codes.size, dtype=np.uint8)
    toggles[quotes[quotes + 1 < codes.size] + 1] = 1         # a string starts after its opening quote ...
    inside = np.bitwise_xor.accumulate(toggles).view(bool)
    inside[quotes] = True                                    # ... and quotes themselves are no brackets
    steps = ((codes == _OPENS[0]) | (codes == _OPENS[1])).view(np.int8) \
        - ((codes == _CLOSES[0]) | (codes == _CLOSES[1])).view(np.int8)
    steps[inside] = 0
    return int(np.cumsum(steps[np.flatnonzero(steps)], dtype=np.int32).max(initial=0))


def _bounded(convert, limit: int):
    def parse(literal: str):
        if len(literal) > limit:
            raise _NumberTooLong(too_large("a number literal's length in characters", len(literal),
                                           "json_number_chars"))
        return convert(literal)
    return parse


def loads_bounded(path: Path, data: bytes):
    """Parse `data` (the bytes of `path`) under the limits; DatasetError naming `path` on any problem."""
    limits = current_limits()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        raise DatasetError(path, f"is not UTF-8 text (byte {err.start})") from None
    depth = nesting_depth(data)
    if depth > limits.json_depth:
        raise DatasetError(path, too_large("the nesting depth of its arrays and objects", depth, "json_depth"))
    try:
        return json.loads(text, parse_int=_bounded(int, limits.json_number_chars),
                          parse_float=_bounded(float, limits.json_number_chars))
    except json.JSONDecodeError as err:
        raise DatasetError(path, f"invalid JSON at line {err.lineno} column {err.colno}: {err.msg}") from None
    except _NumberTooLong as err:
        raise DatasetError(path, str(err)) from None
    except (ValueError, OverflowError, RecursionError, MemoryError) as err:
        raise DatasetError(path, f"invalid JSON: {type(err).__name__}: {err}") from None


def read_json(path: Path, kind: type = dict):
    """Parse a JSON file whose top level must be of type `kind`."""
    path = Path(path)
    data = loads_bounded(path, safe_io.read_bytes(path, "json"))
    if not isinstance(data, kind):
        raise DatasetError(path, f"top level must be a JSON {kind.__name__}, found {type(data).__name__}")
    return data
