"""Who may write into a dataset root, and one writer at a time.

The generator writes only into a root it owns: one that holds its manifest (`synth_manifest.json`). An empty or
missing root is claimed by creating the manifest first, atomically and already whole (a hard link to a written
temp file), before anything else is written, so a concurrent job never sees generator output without the manifest,
nor a manifest not yet written. Any other content (e.g. the real MAROON dataset) makes the root foreign and it is
never written. The generator's own hidden leftovers (temp folders
`<object>/.<distance>.tmp-<pid>-<token>` and `.old-` folders of a crashed run, lock and temp files) never make a
root look foreign; they are removed by the next writer, judged by the lock, not by process ids (is_leftover).

Writers serialise on an exclusive flock of `<root>/.synth.lock`: parallel sweep jobs that all ask for the same
captures wait for the first one and then find them cached.

A manifest is trusted only if it accounts for what is on disk (verify_manifest, run under the lock on entering
`exclusive`, where no generator is between writing a capture and recording it): a manifest forged into a real
dataset grants no permission to write there.
"""
from __future__ import annotations

import contextlib
import fcntl
import json
import os
import re
import secrets
import stat
from collections.abc import Callable, Iterator
from pathlib import Path

from methods.domain.errors import DatasetError

MANIFEST_NAME = "synth_manifest.json"
LOCK_NAME = ".synth.lock"
TEMP_FOLDER = re.compile(r"^\.(\d+)\.(tmp|old)-(\d+)-[0-9a-f]+$")   # groups: distance_cm, kind, pid


class ForeignRootError(DatasetError):
    """The root holds data the generator did not write: it is read as it is, never written."""


def _generator_entry(path: Path) -> bool:
    """True for what the generator may leave in a root before (or without) a finished capture."""
    if path.name == MANIFEST_NAME or path.name.startswith(".synth"):      # manifest, lock, manifest temp files
        return True
    # an object folder holding nothing but hidden temp folders (e.g. of a crashed first run)
    return path.is_dir() and not path.name.startswith(".") and all(
        TEMP_FOLDER.match(entry.name) for entry in path.iterdir())


def holds_foreign_data(root: Path) -> bool:
    """True when `root` (an existing folder without a manifest) holds anything but generator leftovers."""
    return any(not _generator_entry(entry) for entry in root.iterdir())


def claim(root: Path) -> None:
    """Make sure the generator owns `root` (created if missing); ForeignRootError when it holds other data."""
    if root.exists() and not root.is_dir():
        raise DatasetError(root, "dataset root is not a directory")
    root.mkdir(parents=True, exist_ok=True)
    manifest = root / MANIFEST_NAME
    if manifest.is_file():
        return
    # A concurrent generator creates its manifest before any content, so content seen before a manifest appears
    # is foreign only if there is still no manifest after the scan.
    if holds_foreign_data(root) and not manifest.is_file():
        raise ForeignRootError(root, f"holds data the generator did not write (no {MANIFEST_NAME}); not writing")
    # Written whole to a temp file, then linked into place: link fails if the name exists, so the claim is
    # atomic and no process ever reads a manifest that is created but not yet written.
    tmp = root / f".{MANIFEST_NAME}.{secrets.token_hex(8)}.claim"     # unique on a file system shared by hosts
    with open(tmp, "x") as handle:
        handle.write(json.dumps({"captures": {}}))
    try:
        os.link(tmp, manifest)
    except FileExistsError:          # another process claimed it first: it is the generator's all the same
        pass
    except OSError:                  # a file system without hard links: exclusive create, then write
        _create_exclusive(manifest)
    finally:
        tmp.unlink(missing_ok=True)


def _create_exclusive(manifest: Path) -> None:
    try:
        fd = os.open(manifest, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
    except FileExistsError:
        return
    with os.fdopen(fd, "w") as handle:
        handle.write(json.dumps({"captures": {}}))


def verify_manifest(root: Path) -> None:
    """ForeignRootError unless the manifest of `root` accounts for everything on disk: it is a regular file inside
    the root (bounded JSON, bench.maroon.safe_io) of the form {"captures": {"<object>/<distance>": {...}}}, every
    capture
    folder `<object>/<distance>` is one it lists, and nothing else but generator leftovers is there."""
    from bench.maroon.jsonio import loads_bounded
    from bench.maroon.safe_io import read_bytes

    path = root / MANIFEST_NAME
    try:
        captures = loads_bounded(path, read_bytes(path, "json", roots=(Path(os.path.realpath(root)),)))
        captures = captures.get("captures") if isinstance(captures, dict) else None
    except DatasetError as err:
        raise ForeignRootError(root, f"its {MANIFEST_NAME} is not the generator's ({err.problem}); not writing") \
            from None
    if not isinstance(captures, dict):
        raise ForeignRootError(root, f"its {MANIFEST_NAME} lists no captures; not writing")
    for entry in root.iterdir():
        if entry.name == MANIFEST_NAME or entry.name.startswith(".synth"):
            continue
        if entry.name.startswith(".") or not entry.is_dir() or entry.is_symlink():
            raise ForeignRootError(root, f"holds {entry.name!r}, which the generator did not write; not writing")
        for folder in entry.iterdir():
            if not TEMP_FOLDER.match(folder.name) and f"{entry.name}/{folder.name}" not in captures:
                raise ForeignRootError(root, f"holds {entry.name}/{folder.name}, which its {MANIFEST_NAME} does not "
                                             "list (a forged manifest, or a run killed between writing a capture "
                                             "and recording it: delete that folder); not writing")


@contextlib.contextmanager
def exclusive(root: Path, on_wait: Callable[[], None] | None = None) -> Iterator[None]:
    """Hold the root's generator lock (blocking); `on_wait()` is called once if another process holds it. Under
    the lock, the manifest is verified against the disk first (verify_manifest); where no lock file exists yet (no
    generator has worked here, so none is between writing and recording a capture) it is verified before the lock
    file is created, so a foreign root is left without a single new file. The lock file must be a regular file
    (a link or FIFO in its place is refused)."""
    lock_path = root / LOCK_NAME
    if not (lock_path.exists() or lock_path.is_symlink()):
        verify_manifest(root)
    try:
        fd = os.open(lock_path, os.O_WRONLY | os.O_CREAT | os.O_APPEND | os.O_NOFOLLOW | os.O_NONBLOCK, 0o644)
    except OSError as err:
        raise ForeignRootError(root, f"cannot use {LOCK_NAME} as the generator's lock ({err.strerror}); not "
                                     "writing") from None
    if not stat.S_ISREG(os.fstat(fd).st_mode):
        os.close(fd)
        raise ForeignRootError(root, f"its {LOCK_NAME} is not a regular file; not writing")
    with os.fdopen(fd, "a") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if on_wait is not None:
                on_wait()
            fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            verify_manifest(root)
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


CONTENT_LIMIT_BYTES = 1 << 30     # a synthetic capture is ~40 MB; more is not the generator's


def content_digest(folder: Path) -> str | None:
    """sha256 over the relative paths and bytes of every file under `folder` (sorted), or None when the folder
    holds anything the generator never writes (a link, a FIFO, a device, more than CONTENT_LIMIT_BYTES): what
    the manifest records per capture, so that a capture is replaced only while it is still the generator's."""
    import hashlib

    entries, total = [], 0
    for path in sorted(folder.rglob("*")):
        mode = path.lstat().st_mode
        if stat.S_ISDIR(mode):
            continue
        if not stat.S_ISREG(mode):
            return None
        total += path.lstat().st_size
        if total > CONTENT_LIMIT_BYTES:
            return None
        entries.append(path)
    digest = hashlib.sha256()
    for path in entries:
        digest.update(path.relative_to(folder).as_posix().encode() + b"\0")
        with open(path, "rb", opener=lambda name, flags: os.open(name, flags | os.O_NOFOLLOW | os.O_NONBLOCK)) as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                digest.update(block)
        digest.update(b"\0")
    return digest.hexdigest()


def check_replaceable(capture_dir: Path, recorded: dict) -> None:
    """ForeignRootError unless the capture on disk is byte for byte what the manifest says the generator wrote:
    a manifest entry alone (forged, or from a generator that recorded no content) never lets an existing
    capture be overwritten."""
    expected = recorded.get("content") if isinstance(recorded, dict) else None
    if expected is None or content_digest(capture_dir) != expected:
        raise ForeignRootError(capture_dir, "is not byte for byte the capture the generator recorded in "
                                            f"{MANIFEST_NAME} (changed, or not the generator's); not overwriting "
                                            "it (delete the folder to regenerate it)")


def is_leftover(entry: Path) -> bool:
    """Whether `entry` is a generator temp/old folder, hence a leftover of a writer that died. Call it only while
    holding the root's lock (`exclusive`): every writer holds that lock for as long as its temp folder exists, so
    a temp folder seen by the lock holder belongs to no live writer, on this host or any other sharing the file
    system. Process ids are not consulted: they mean nothing on another node and are reused."""
    return TEMP_FOLDER.match(entry.name) is not None
