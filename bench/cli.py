"""Shared command-line behaviour: a user mistake ends in one line `error: <what>: <what is wrong>` on stderr and a
non-zero exit, never a traceback.

* `run_guarded(main)` runs an entry point: a DatasetError (bad data), a UserError (bad argument or path), a
  UsageError (a request the methods refuse), an
  OSError naming a file (cannot read or write it) or an unusable device -> one line on stderr, exit 2;
  Ctrl-C -> `interrupted`, exit 130; a closed stdout (`python -m bench.report.tables table3 | head -1`) -> nothing
  more is
  written and the exit code is 141 (128 + SIGPIPE, what the shell reports for a tool killed by a closed pipe, so
  `set -o pipefail` treats us like `cat`). Anything else is a bug and keeps its traceback.
* `ArgumentParser`: argparse whose errors are one line (`error: <message> (see <prog> --help)`, exit 2).
* Argument checks that fail before any work is done: `existing_path`, `output_dir`, `output_file`,
  `check_creatable_dir`, `positive_int`, `resolve_device`.

Nothing here imports Hydra, pandas or Open3D (the GPU benchmarks use it on a bare machine).
"""
from __future__ import annotations

import argparse
import os
import sys
from collections.abc import Callable
from pathlib import Path

from methods.domain.errors import DatasetError, UsageError

EXIT_USER_ERROR = 2
EXIT_INTERRUPTED = 130
EXIT_CLOSED_PIPE = 141          # 128 + SIGPIPE


class UserError(Exception):
    """A bad command-line argument, option value or path: `what` (the option or path) and `problem` (a sentence)."""

    def __init__(self, what: str | Path, problem: str):
        self.what, self.problem = str(what), problem
        super().__init__(f"{self.what}: {problem}")


def error_line(err: BaseException) -> str | None:
    """The one-line message (without `error: `) for an error a user can fix, or None for a bug."""
    from methods.backends import DeviceUnavailableError

    if isinstance(err, (DatasetError, UserError, UsageError)):
        return str(err)
    if isinstance(err, DeviceUnavailableError):
        return f"device={err.device}: {err.problem} (use device=cpu or device=auto)"
    if isinstance(err, OSError) and not isinstance(err, BrokenPipeError) and (err.filename or err.args):
        if err.filename is None:          # raised by our code with a message that names the path
            return str(err)
        target = f"{err.filename} -> {err.filename2}" if err.filename2 else str(err.filename)
        return f"{target}: {err.strerror or err}"
    return None


def fail(message: str, code: int = EXIT_USER_ERROR) -> None:
    """Print `error: <message>` (one line) on stderr and exit with `code`."""
    print(f"error: {' '.join(str(message).split())}", file=sys.stderr, flush=True)
    sys.exit(code)


def exit_on_closed_stdout() -> None:
    """After a BrokenPipeError on stdout: point stdout at /dev/null (so the interpreter's final flush cannot raise
    again) and exit quietly with 141 (Python docs, signal module, 'Note on SIGPIPE')."""
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):       # stdout without a file descriptor (e.g. replaced by a test harness)
        pass
    sys.exit(EXIT_CLOSED_PIPE)


def run_guarded(main: Callable[[], int | None]) -> None:
    """Run an entry point's `main` and exit with its code; user errors end in one line (module docstring)."""
    try:
        code = main()
        sys.stdout.flush()                # a closed pipe shows here, not in the interpreter's final flush
    except BrokenPipeError:
        exit_on_closed_stdout()
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        sys.exit(EXIT_INTERRUPTED)
    except Exception as err:              # noqa: BLE001 -- re-raised unless it is a user's mistake
        message = error_line(err)
        if message is None:
            raise
        fail(message)
    sys.exit(code or 0)


class ArgumentParser(argparse.ArgumentParser):
    """argparse with one-line errors: `error: <message> (see <prog> --help)` on stderr, exit 2 (no usage dump)."""

    def error(self, message: str) -> None:   # type: ignore[override]
        fail(f"{message} (see {self.prog} --help)")


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a whole number") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be at least 1, got {value}")
    return value


def existing_path(path: str | Path, kind: str, what: str) -> Path:
    """`path` if it exists and is a `kind` ("file", "dir" or "any"), else a UserError naming it as `what`."""
    path = Path(path)
    if not path.exists():
        raise UserError(path, f"{what} does not exist")
    if kind == "dir" and not path.is_dir():
        raise UserError(path, f"{what} is not a directory")
    if kind == "file" and not path.is_file():
        raise UserError(path, f"{what} is not a file")
    if not os.access(path, os.R_OK):
        raise UserError(path, f"{what} is not readable (permission denied)")
    return path


def output_dir(path: str | Path) -> Path:
    """Create the output directory `path` (and its parents) before any work, so a bad --out fails at once."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise UserError(path, "output directory is a file")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except (FileExistsError, NotADirectoryError):
        raise UserError(path, "cannot create the output directory: a parent is a file") from None
    except OSError as err:
        raise UserError(path, f"cannot create the output directory ({err.strerror or err})") from None
    if not os.access(path, os.W_OK | os.X_OK):
        raise UserError(path, "output directory is not writable (permission denied)")
    return path


def check_creatable_dir(path: str | Path, what: str) -> None:
    """Without creating anything: `path` is a writable directory, or the nearest existing folder above it is one
    (so that it can be created); else a UserError naming `what` (e.g. `hydra.run.dir=/x`)."""
    path = Path(path).absolute()
    existing = next(p for p in (path, *path.parents) if p.exists())
    if not existing.is_dir():
        raise UserError(what, f"cannot create a directory there: {existing} is a file")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise UserError(what, f"cannot create or write there: {existing} is not writable")


def output_file(path: str | Path) -> Path:
    """An output file `path`: its folder is created (as by `output_dir`); a folder at `path` is a UserError."""
    path = Path(path)
    if path.is_dir():
        raise UserError(path, "output file is a directory")
    output_dir(path.parent)
    return path


def resolve_device(device: str, option: str = "--device ") -> str:
    """methods.backends.resolve_device, with an unusable device as a UserError that spells `option`
    (`"--device "` for argparse, `"device="` for Hydra overrides)."""
    from methods.backends import DEVICES, DeviceUnavailableError
    from methods.backends import resolve_device as resolve

    if device not in DEVICES:
        raise UserError(f"{option}{device}", f"unknown device (choose from {', '.join(DEVICES)})")
    try:
        return resolve(device)
    except DeviceUnavailableError as err:
        raise UserError(f"{option}{device}", f"{err.problem} (use {option}cpu or {option}auto)") from None
    except ImportError as err:            # warp-lang missing from the environment
        raise UserError(f"{option}{device}", f"Warp cannot be imported ({err})") from None
