"""The error types of a user's mistake: bad dataset input (`DatasetError`, naming the file) and a request the
caller can fix (`UsageError`). Command lines print either as one line; any other exception is a bug and keeps
its traceback (bench.cli.run_guarded)."""
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


class UsageError(ValueError):
    """A request the caller can fix: an unknown configuration, method, prior or parameter, a combination a method
    does not accept, or a capture that lacks what was asked of it. One line; a ValueError for older callers."""


class NonFiniteSignal(UsageError):
    """A radar frame with NaN or Inf samples, found where a backend checks the samples it uploads (the caller names
    the capture: methods.api)."""
