"""The one error type for bad dataset input: it names the file and says what is wrong."""
from __future__ import annotations

from pathlib import Path


class DatasetError(Exception):
    """A dataset file is missing or malformed.

    `path` is the offending file (or folder), `problem` a sentence saying what is wrong with it.
    Command-line entry points print `str(err)` and exit non-zero instead of showing a traceback.
    """

    def __init__(self, path: str | Path, problem: str):
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{self.path}: {problem}")
