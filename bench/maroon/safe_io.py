"""Opening dataset files safely: regular files only, inside the dataset, no larger than their kind's limit.

* Only regular files are read: a FIFO (which would block forever), a character or block device (`/dev/zero`
  never ends), a socket or a directory is refused. The type is checked with `stat` before opening and again with
  `fstat` on the opened descriptor (opened non-blocking, so even a FIFO swapped in between cannot hang).
* Symbolic links may point anywhere inside the dataset root, never outside it. The root of a capture
  `<root>/<object>/<distance>` is `<root>`, taken both as given and as the grandparent of the capture folder's real
  path (so a capture folder that is itself a link to another disk still reads); `use_root` sets it for a block and
  `maroon.read_capture` does so. Outside such a block (a file read on its own) links are followed without this
  check, but the other checks hold.
* A file larger than the limit of its kind (`bench.maroon.limits`) is refused before any byte is read, and a read never
  returns more than that many bytes (a file growing meanwhile is refused too).
"""
from __future__ import annotations

import contextlib
import contextvars
import os
import stat
from collections.abc import Iterator
from pathlib import Path

from bench.maroon.limits import current_limits, too_large
from methods.domain.errors import DatasetError

KINDS = {"frame": "frame_bytes", "json": "json_bytes", "image": "image_bytes", "mesh": "mesh_bytes",
         "text": "text_bytes"}
_ROOTS: contextvars.ContextVar[tuple[Path, ...]] = contextvars.ContextVar("bench_dataset_roots", default=())
_TYPES = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"), (stat.S_ISDIR, "a directory"))


def capture_roots(capture_dir: str | Path) -> tuple[Path, ...]:
    """The dataset roots of a capture folder `<root>/<object>/<distance>` (see the module doc)."""
    capture_dir = Path(capture_dir).absolute()
    roots = {Path(os.path.realpath(capture_dir.parent.parent)), Path(os.path.realpath(capture_dir)).parent.parent}
    return tuple(sorted(roots))


@contextlib.contextmanager
def use_root(capture_dir: str | Path) -> Iterator[tuple[Path, ...]]:
    """Within the block, files must resolve inside the dataset root of `capture_dir`."""
    token = _ROOTS.set(capture_roots(capture_dir))
    try:
        yield _ROOTS.get()
    finally:
        _ROOTS.reset(token)


def _kind_of(mode: int) -> str | None:
    return next((name for test, name in _TYPES if test(mode)), None) if not stat.S_ISREG(mode) else None


def checked_path(path: str | Path, roots: tuple[Path, ...] | None = None) -> Path:
    """The real path of `path` after the root check (DatasetError naming `path` if it leaves the root)."""
    path = Path(path)
    real = Path(os.path.realpath(path))
    roots = _ROOTS.get() if roots is None else roots
    if roots and not any(real == root or real.is_relative_to(root) for root in roots):
        raise DatasetError(path, f"is a symbolic link to {real}, outside the dataset root {roots[0]}")
    return real


def file_size(path: str | Path, kind: str, roots: tuple[Path, ...] | None = None) -> int:
    """Size in bytes of a dataset file after every check of `open_checked`, without opening it."""
    real = checked_path(path, roots)
    try:
        info = os.stat(real)
    except FileNotFoundError:
        raise DatasetError(path, "file is missing") from None
    except OSError as err:
        raise DatasetError(path, f"cannot read file ({err.strerror or err})") from None
    _check_stat(path, info, kind)
    return info.st_size


def _check_stat(path: Path, info: os.stat_result, kind: str) -> None:
    other = _kind_of(info.st_mode)
    if other is not None:
        raise DatasetError(path, f"is {other}, not a regular file")
    if not stat.S_ISREG(info.st_mode):
        raise DatasetError(path, "is not a regular file")
    limit_name = KINDS[kind]
    if info.st_size > getattr(current_limits(), limit_name):
        raise DatasetError(path, too_large(f"the {kind} file's size in bytes", info.st_size, limit_name))


@contextlib.contextmanager
def open_checked(path: str | Path, kind: str, roots: tuple[Path, ...] | None = None):
    """A binary file object of a checked regular dataset file (see the module doc); yields (file, size)."""
    path = Path(path)
    real = checked_path(path, roots)
    file_size(path, kind, roots)
    try:
        fd = os.open(real, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0))
    except FileNotFoundError:
        raise DatasetError(path, "file is missing") from None
    except OSError as err:
        raise DatasetError(path, f"cannot open file ({err.strerror or err})") from None
    try:
        info = os.fstat(fd)
        _check_stat(path, info, kind)           # the same file we checked, not one swapped in meanwhile
        os.set_blocking(fd, True)
        handle = os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise
    with handle:
        yield handle, info.st_size


def read_bytes(path: str | Path, kind: str, roots: tuple[Path, ...] | None = None) -> bytes:
    """All bytes of a checked regular dataset file (never more than its kind's limit, nor than its size)."""
    path = Path(path)
    with open_checked(path, kind, roots) as (handle, size):
        try:
            data = handle.read(size + 1)               # allocates what the file holds, not what the limit allows
        except OSError as err:
            raise DatasetError(path, f"cannot read file ({err.strerror or err})") from None
    if len(data) != size:
        raise DatasetError(path, f"file changed while it was read ({size} bytes expected, {len(data)} read)")
    return data
