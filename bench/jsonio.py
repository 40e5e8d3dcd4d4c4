"""Reading JSON dataset files with errors that name the file."""
from __future__ import annotations

import json
from pathlib import Path

from bench.errors import DatasetError


def read_json(path: Path, kind: type = dict):
    """Parse a JSON file whose top level must be of type `kind`."""
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        raise DatasetError(path, "file is missing") from None
    except (OSError, UnicodeDecodeError) as err:
        raise DatasetError(path, f"cannot read file ({err})") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as err:
        raise DatasetError(path, f"invalid JSON at line {err.lineno} column {err.colno}: {err.msg}") from None
    if not isinstance(data, kind):
        raise DatasetError(path, f"top level must be a JSON {kind.__name__}, found {type(data).__name__}")
    return data
