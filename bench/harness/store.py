"""Result store: one row + one HDF5 file of arrays per cell, keyed by content, configuration and code version.

A cell is (capture frame, method, frequencies, prior, grid, parameters, device, code version). Its key is the
sha256 of all of that, where the capture enters through the sha256 of the files the reader actually opens (frame,
calibration, metadata, alignment, RealSense frame, mesh) and the antenna files.

File digests are cached under `<store>/digests/` by a stamp of (real path, device, inode, size, mtime_ns,
ctime_ns), so hashing costs one `stat` per file after the first time (3.6 us; hashing the content instead costs
11.6 ms per 9.4 MB frame, per cell, on the 2-core development machine). Size and mtime alone are not enough: a
file rewritten in place with the same size and its mtime set back (`touch -r`, `os.utime`, `cp -p`) would be served
stale. The ctime cannot be set by user tools (the kernel sets it to the current time on every write, chmod or
utime), and a file replaced by rename gets a new inode, so any change gives a new stamp. Racy writes (git's "racy
clean" problem: a change within the same clock tick as the hashing) are excluded by not caching a digest whose
file changed less than RACY_S seconds before it was hashed, or changed while it was hashed. Assumes a file system
that keeps ctime (local file systems and NFS do); `Store(root, verify=True)` hashes the content on every lookup
instead (for file systems that do not).
Writes are atomic (temp file + `os.replace`) and the row is written after its arrays: a row on disk always has
its arrays, and an interrupted sweep loses no finished cell.

Layout: `<store>/cells/<key>.json` (the results row), `<store>/cells/<key>.h5` (depth_m, magnitude, gt_depth_m on
the cell's pixel grid, metres / linear), `<store>/digests/<hash of the stamp>` (a file's sha256).
"""
from __future__ import annotations

import functools
import hashlib
import json
import os
import time
from importlib.metadata import version
from pathlib import Path

import h5py
import numpy as np

from bench.maroon import reader as maroon
from bench.maroon import safe_io

PACKAGE_ROOT = Path(__file__).resolve().parents[2]
CODE_DIRS = ("methods", "metrics", "bench/maroon")   # every .py file in these: the data layer shapes results too
CODE_FILES = ("bench/harness/grids.py",)
ARRAY_NAMES = ("depth_m", "magnitude", "gt_depth_m")
RACY_S = 1.0            # a digest is cached only for files unchanged for this long before hashing (see above)
_KIND_BY_SUFFIX = {".npy": "frame", ".json": "json", ".png": "image", ".obj": "mesh", ".ply": "mesh"}


def file_kind(path: Path) -> str:
    """The bench.maroon.safe_io kind (size limit) of a file the reader opens, by its suffix."""
    return _KIND_BY_SUFFIX.get(path.suffix.lower(), "text")


def _sha256_file(path: Path, roots: tuple[Path, ...] | None = None) -> tuple[str, os.stat_result]:
    """sha256 of a checked regular file (bench.maroon.safe_io) and the fstat of the descriptor that was hashed."""
    digest = hashlib.sha256()
    with safe_io.open_checked(path, file_kind(path), roots) as (handle, _):
        info = os.fstat(handle.fileno())
        for block in iter(lambda: handle.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest(), info


def _stamp(path: Path, info: os.stat_result) -> bytes:
    return (f"{os.path.realpath(path)}\0{info.st_dev}\0{info.st_ino}\0{info.st_size}\0{info.st_mtime_ns}\0"
            f"{info.st_ctime_ns}").encode()


def _atomic_write_bytes(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


@functools.cache
def code_version() -> str:
    """`<package version>+<sha256 prefix of the methods/, metrics/ and reader sources>`; hashed once per process
    (the code a process runs is what it imported: 2-12 ms saved per cell)."""
    files = sorted(p for d in CODE_DIRS for p in (PACKAGE_ROOT / d).rglob("*.py"))
    files += [PACKAGE_ROOT / f for f in CODE_FILES]
    digest = hashlib.sha256()
    for path in files:
        digest.update(path.relative_to(PACKAGE_ROOT).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    return f"{version('mm2fsk-bench')}+{digest.hexdigest()[:12]}"


def capture_files(capture_dir: Path, frame: int, parts: tuple[str, ...], empty_filtered: bool,
                  realsense_frame: int | None = None) -> list[Path]:
    """The files `maroon.read_capture` opens for this frame and these parts (the reader lists them:
    `maroon.files_read`), each checked as the reader checks it (regular file inside the dataset root, within its
    size limit: bench.maroon.safe_io)."""
    with safe_io.use_root(capture_dir) as roots:
        files = maroon.files_read(capture_dir, frame, parts, empty_filtered, realsense_frame)
        for path in files:
            safe_io.file_size(path, file_kind(path), roots)
    return files


class Store:
    """Cells under `root` (created on first write)."""

    def __init__(self, root: str | Path, verify: bool = False):
        self.root = Path(root)
        self.cells = self.root / "cells"
        self.verify = verify
        self._digests: dict[bytes, str] = {}     # stamp -> digest found or cached by this Store: no file read

    def file_digest(self, path: Path) -> str:
        """sha256 of a file's bytes, cached by its stamp (path, device, inode, size, mtime_ns, ctime_ns; module
        doc); with `verify`, always hashed."""
        path = Path(path)
        if self.verify:
            return _sha256_file(path, roots=())[0]
        try:
            before = os.stat(path)
        except OSError:
            return _sha256_file(path, roots=())[0]           # raises the DatasetError naming the file
        stamp = _stamp(path, before)
        if stamp in self._digests:
            return self._digests[stamp]
        cached = self.root / "digests" / hashlib.sha256(stamp).hexdigest()[:32]
        if cached.is_file():
            self._digests[stamp] = cached.read_text()
            return self._digests[stamp]
        digest, hashed = _sha256_file(path, roots=())
        after = os.stat(path)
        unchanged = _stamp(path, before) == _stamp(path, hashed) == _stamp(path, after)
        settled = time.time_ns() - max(after.st_mtime_ns, after.st_ctime_ns) > RACY_S * 1e9
        if unchanged and settled:
            cached.parent.mkdir(parents=True, exist_ok=True)
            _atomic_write_bytes(cached, digest.encode())
            self._digests[stamp] = digest
        return digest

    def capture_digest(self, files: list[Path]) -> str:
        """sha256 over the names and contents of `files` (names relative to their common capture folder)."""
        digest = hashlib.sha256()
        for path in files:
            digest.update(f"{path.name}\0{self.file_digest(path)}\0".encode())
        return digest.hexdigest()

    @staticmethod
    def key(description: dict) -> str:
        """sha256 (hex) of a JSON-serialisable description of a cell."""
        return hashlib.sha256(json.dumps(description, sort_keys=True, default=str).encode()).hexdigest()

    def get(self, key: str, names: tuple[str, ...] = ARRAY_NAMES) -> tuple[dict, dict[str, np.ndarray], dict] | None:
        """(row, arrays `names`, array attributes) of a finished cell, or None."""
        row_path = self.cells / f"{key}.json"
        if not row_path.is_file():
            return None
        with h5py.File(self.cells / f"{key}.h5", "r") as h5:
            arrays = {name: h5[name][()] for name in names}
            attrs = dict(h5.attrs)
        return json.loads(row_path.read_text()), arrays, attrs

    def put(self, key: str, row: dict, arrays: dict[str, np.ndarray], attrs: dict) -> None:
        """Arrays (with `attrs`, e.g. the pixel grid) first, then the row, each atomically."""
        self.cells.mkdir(parents=True, exist_ok=True)
        h5_path = self.cells / f"{key}.h5"
        tmp = h5_path.with_name(f".{h5_path.name}.{os.getpid()}.tmp")
        write_arrays(tmp, "/", arrays, attrs)
        os.replace(tmp, h5_path)
        _atomic_write_bytes(self.cells / f"{key}.json", json.dumps(row, default=float).encode())

    def copy_arrays(self, key: str, path: Path, group: str, attrs: dict) -> None:
        """Add (or replace) `group` in the HDF5 file `path` holding the cell's arrays as `write_arrays` writes
        them, copied as stored: the compressed chunks are copied, not decompressed and compressed again (~1 ms
        instead of ~30 ms per capture on the 2-core machine)."""
        with h5py.File(self.cells / f"{key}.h5", "r") as source, h5py.File(path, "a") as h5:
            if group in h5:
                del h5[group]
            node = h5.require_group(group)
            for name in ARRAY_NAMES:
                source.copy(source[name], node, name=name)
            node.attrs.update(attrs)


def write_arrays(path: Path, group: str, arrays: dict[str, np.ndarray], attrs: dict | None = None) -> None:
    """Add (or replace) `group` in the HDF5 file `path` with compressed datasets (dtype kept) and attributes."""
    with h5py.File(path, "a") as h5:
        if group != "/" and group in h5:
            del h5[group]
        node = h5.require_group(group)
        for name, values in arrays.items():
            # gzip level 1: a cell's mostly-NaN maps shrink 13x as with the default level 4, in 2/3 of its time
            node.create_dataset(name, data=np.asarray(values), compression="gzip", compression_opts=1, shuffle=True)
        node.attrs.update(attrs or {})
