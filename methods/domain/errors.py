"""The one error type for bad dataset input: it names the file and says what is wrong."""
from __future__ import annotations

from pathlib import Path


def display_path(path: str | Path) -> str:
    """`path` as one printable line: bytes that are not UTF-8 as \\xNN, control characters (a newline in a folder
    name) escaped like Python string literals, everything else (accents, CJK) unchanged."""
    text = str(path).encode("utf-8", "surrogateescape").decode("utf-8", "backslashreplace")
    return "".join(char if char.isprintable() else ascii(char)[1:-1] for char in text)


class DatasetError(Exception):
    """A dataset file is missing or malformed.

    `path` is the offending file (or folder), `problem` a sentence saying what is wrong with it.
    Command-line entry points print `str(err)` and exit non-zero instead of showing a traceback; `str(err)` is one
    line whatever the file's name (display_path).
    """

    def __init__(self, path: str | Path, problem: str):
        self.path = Path(path)
        self.problem = problem
        super().__init__(f"{display_path(self.path)}: {problem}")
