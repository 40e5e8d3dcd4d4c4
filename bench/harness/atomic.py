"""Output files written whole or not at all, and write errors (a full disk, a file-size limit, a folder that is
read-only or gone) as one OSError naming the file, which the command line prints as one line (bench.cli)."""
from __future__ import annotations

import os
from pathlib import Path


def write_bytes(path: Path, data: bytes) -> None:
    """`data` into `path` through a temp file and `os.replace`: `path` is the old file or the new one, never a part;
    on a failed write the temp file is removed."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except OSError as err:
        tmp.unlink(missing_ok=True)
        raise OSError(f"{path}: cannot write ({err.strerror or err}); nothing was kept") from None


def append_bytes(path: Path, data: bytes) -> None:
    """Append `data` to the existing file `path` whole: a failed or partial write (the last bytes below a limit)
    is cut off again, so the file ends where it ended before."""
    try:
        descriptor = os.open(path, os.O_WRONLY | os.O_APPEND)
    except OSError as err:
        raise OSError(f"{path}: cannot append ({err.strerror or err})") from None
    try:
        size = os.fstat(descriptor).st_size
        view, done = memoryview(data), 0
        try:
            while done < len(view):
                done += os.write(descriptor, view[done:])
        except OSError as err:
            os.ftruncate(descriptor, size)
            raise OSError(f"{path}: cannot append ({err.strerror or err}); the file is as it was") from None
    finally:
        os.close(descriptor)
