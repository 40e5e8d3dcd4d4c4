"""Drawn files redrawn only when what they show changed: a content key per output (SHA-256 of its inputs and of the
code that draws it), kept in `.keys.json` beside the outputs, like the result store keys its rows.

    keys = Keys(folder)
    key = digest(arrays, labels, module_source(pictures))
    if not keys.fresh("01_plate_30_000000", key, [png]):
        draw(...); keys.record("01_plate_30_000000", key)
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

FILE_NAME = ".keys.json"


def digest(*parts) -> str:
    """SHA-256 over the parts: arrays (dtype, shape and bytes), bytes, files (their bytes) and anything else as
    its repr() (pass arrays as parts of their own: the repr of a container of arrays abbreviates them)."""
    sha = hashlib.sha256()
    for part in parts:
        if isinstance(part, np.ndarray):
            sha.update(f"{part.dtype}{part.shape}".encode())
            sha.update(np.ascontiguousarray(part).tobytes())
        elif isinstance(part, bytes):
            sha.update(part)
        elif isinstance(part, Path):
            sha.update(part.read_bytes())
        else:
            sha.update(repr(part).encode())
        sha.update(b"\0")
    return sha.hexdigest()


def module_source(module) -> Path:
    """The file of a module, for `digest`: a change to the drawing code redraws."""
    return Path(module.__file__)


class Keys:
    """The keys of the outputs in one folder (`<folder>/.keys.json`); an unreadable file counts as empty."""

    def __init__(self, folder: Path):
        self.path = Path(folder) / FILE_NAME
        try:
            self.keys = json.loads(self.path.read_text())
        except (OSError, ValueError):
            self.keys = {}
        if not isinstance(self.keys, dict):
            self.keys = {}

    def fresh(self, name: str, key: str, outputs: list[Path]) -> bool:
        """Whether `name` was drawn from `key` and every one of its `outputs` is still there."""
        return self.keys.get(name) == key and all(Path(p).is_file() for p in outputs)

    def record(self, name: str, key: str) -> None:
        """Note that `name` was drawn from `key` (written at once, atomically)."""
        self.keys[name] = key
        self.path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.path.with_name(f"{FILE_NAME}.tmp")
        tmp.write_text(json.dumps(self.keys, indent=1, sort_keys=True))
        os.replace(tmp, self.path)
