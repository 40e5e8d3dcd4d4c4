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
its arrays, and an interrupted sweep loses no finished cell. HDF5 never writes to disk itself: a cell's file is
built in memory and written by Python, and the run's `arrays.h5` is appended through a file object that keeps a
failed write from HDF5 (`_DeferredWriteErrors`); HDF5 that sees a failed write (a full disk, a file-size limit)
ends the process in a segmentation fault, where here the write ends in one OSError naming the file, its partial
file removed. The arrays are compressed before HDF5 sees them (bench.harness.h5chunks: gzip + shuffle chunks made by
zlib on any thread, written with `write_direct_chunk`), so HDF5 only places them.

The store is a trust boundary (anything may have been written into it): a cell is read only from regular files
inside the store, its row must be a JSON object of the expected fields for this key, its HDF5 file may hold no
external or soft link, virtual dataset or externally stored dataset (each could serve another file's data), and
its arrays must be 2-D floats of its pixel grid. A cell that fails any check is computed again, with a warning
naming its file. The code version (bench.harness.codeversion) covers every module of the compute path.

Layout: `<store>/cells/<key>.json` (the results row), `<store>/cells/<key>.h5` (depth_m, magnitude, gt_depth_m on
the cell's pixel grid, metres / linear), `<store>/digests/<hash of the stamp>` (a file's sha256).
"""
from __future__ import annotations

import contextlib
import hashlib
import io
import json
import logging
import math
import os
import re
import time
from pathlib import Path

import h5py
import numpy as np

from bench.harness import atomic, h5chunks
from bench.harness.codeversion import code_version  # noqa: F401 -- part of a cell's key (bench.harness.app)
from bench.maroon import reader as maroon
from bench.maroon import safe_io
from bench.maroon.jsonio import loads_bounded
from methods.domain.errors import DatasetError

log = logging.getLogger("bench")
ARRAY_NAMES = ("depth_m", "magnitude", "gt_depth_m")
_SHA256_HEX = re.compile(r"[0-9a-f]{64}")
ROW_FIELDS = {"key": str, "object": str, "distance": int, "frame": int, "method": str, "valid_px": int,
              "runtime_ms": (int, float), "timing": str}        # what the app reads of a stored row, and its type
ROW_NUMBERS = ("C_g_cm", "C_s_cm", "P_cm", "P_e_cm")            # numbers where present (NaN: no score)
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
        text = _read_digest(cached, self._roots())
        if text is not None:
            self._digests[stamp] = text
            return text
        digest, hashed = _sha256_file(path, roots=())
        after = os.stat(path)
        unchanged = _stamp(path, before) == _stamp(path, hashed) == _stamp(path, after)
        settled = time.time_ns() - max(after.st_mtime_ns, after.st_ctime_ns) > RACY_S * 1e9
        if unchanged and settled:
            with contextlib.suppress(OSError):      # a digest not kept on disk is hashed again next time
                cached.parent.mkdir(parents=True, exist_ok=True)
                atomic.write_bytes(cached, digest.encode())
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
        """(row, arrays `names`, array attributes) of a finished cell, or None: none stored, or one that fails a
        check (module doc; a warning names its file, and the cell is computed again)."""
        row_path = self.cells / f"{key}.json"
        if not os.path.lexists(row_path):
            return None
        try:
            row = self._row(key)
            with self._open_cell(key) as h5:
                arrays = {name: h5[name][()] for name in names}
                attrs = dict(h5.attrs)
        except (DatasetError, OSError) as err:
            log.warning("store cell %s is not usable, computing it again: %s", key, " ".join(str(err).split()))
            return None
        return row, arrays, attrs

    def _row(self, key: str) -> dict:
        """The stored row of `key`, checked (DatasetError naming its file otherwise)."""
        path = self.cells / f"{key}.json"
        row = loads_bounded(path, safe_io.read_bytes(path, "json", self._roots()))
        if not isinstance(row, dict):
            raise DatasetError(path, f"a row must be a JSON object, found {type(row).__name__}")
        for field, kind in ROW_FIELDS.items():
            if not isinstance(row.get(field), kind) or isinstance(row.get(field), bool):
                raise DatasetError(path, f"field {field!r} must be {_type_names(kind)}, found {row.get(field)!r:.40}")
        if row["key"] != key:
            raise DatasetError(path, f"holds the row of another cell ({row['key']:.16})")
        bad = [name for name in ROW_NUMBERS if name in row and not _is_number(row[name])]
        if bad or row["valid_px"] < 0 or not math.isfinite(row["runtime_ms"]) or row["runtime_ms"] < 0:
            raise DatasetError(path, f"field(s) {', '.join(bad or ['valid_px', 'runtime_ms'])} out of range")
        return row

    def _roots(self) -> tuple[Path, ...]:
        return (Path(os.path.realpath(self.root)),)

    def open_h5(self, path: Path) -> h5py.File:
        """An HDF5 file of the store (a cell, a kept ground truth or mesh: bench.harness.captures), read into memory
        from a regular file inside the store, holding only hard links to datasets stored in it (`check_links`); a
        DatasetError naming the file otherwise."""
        try:
            h5 = h5py.File(io.BytesIO(safe_io.read_bytes(path, "frame", self._roots())), "r")
        except OSError as err:            # not HDF5, truncated
            raise DatasetError(path, f"unreadable HDF5 ({' '.join(str(err).split())})") from None
        try:
            check_links(path, h5)
        except BaseException:
            h5.close()
            raise
        return h5

    def _open_cell(self, key: str) -> h5py.File:
        """The cell's HDF5 file (`open_h5`), its arrays 2-D floats of the grid in its attributes."""
        path = self.cells / f"{key}.h5"
        h5 = self.open_h5(path)
        try:
            _check_cell(path, h5)
        except BaseException:
            h5.close()
            raise
        return h5

    def put(self, key: str, row: dict, arrays: dict[str, np.ndarray], attrs: dict) -> None:
        """Arrays (with `attrs`, e.g. the pixel grid) first, then the row, each atomically (module doc)."""
        self.cells.mkdir(parents=True, exist_ok=True)
        atomic.write_bytes(self.cells / f"{key}.h5", cell_image(arrays, attrs))
        atomic.write_bytes(self.cells / f"{key}.json", json.dumps(row, default=float).encode())

    def copy_arrays(self, key: str, path: Path, group: str, attrs: dict) -> None:
        """Add (or replace) `group` in the HDF5 file `path` holding the cell's arrays as `write_arrays` writes
        them, copied as stored: the compressed chunks are copied, not decompressed and compressed again (~1 ms
        instead of ~30 ms per capture on the 2-core machine). The cell is checked again as it is read."""
        with self._open_cell(key) as source:
            copy_cell(source, path, group, attrs)


def cell_image(arrays: dict, attrs: dict) -> bytes:
    """A cell's HDF5 file as bytes: the arrays (or `compress_arrays`' of them) as `write_arrays` writes them, with
    `attrs`."""
    image = io.BytesIO()
    with h5py.File(image, "w") as h5:
        _fill(h5, "/", arrays, attrs)
    return image.getvalue()


def copy_cell(source: h5py.File, path: Path, group: str, attrs: dict) -> None:
    """Add (or replace) `group` in the HDF5 file `path` with the arrays of the cell `source` (a store's cell, or a
    `cell_image` opened), their compressed chunks copied as they are, and `attrs`."""
    def add(h5: h5py.File) -> None:
        node = _replace_group(h5, group)
        for name in ARRAY_NAMES:
            source.copy(source[name], node, name=name)
        node.attrs.update(attrs)

    _update_h5(Path(path), add)


def _read_digest(path: Path, roots: tuple[Path, ...]) -> str | None:
    """A cached digest: the sha256 hex in the regular file `path` inside `roots` (at most 65 bytes read), else None
    (missing or not one: the file is hashed again and the entry rewritten)."""
    try:
        with safe_io.open_checked(path, "text", roots) as (handle, _):
            text = handle.read(65).decode("ascii", errors="replace")
    except DatasetError:
        return None
    return text if _SHA256_HEX.fullmatch(text) else None


def _type_names(kind) -> str:
    return " or ".join(k.__name__ for k in (kind if isinstance(kind, tuple) else (kind,)))


def _is_number(value) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def check_links(path: Path, h5: h5py.File) -> None:
    """DatasetError naming `path` where a top-level entry of `h5` is not a hard link, or a dataset is virtual or
    stored externally: each could serve another file's data (a file of the store, or kept beside it, is read only
    when it holds its own data)."""
    for name in h5:
        link = h5.get(name, getlink=True)
        if not isinstance(link, h5py.HardLink):
            raise DatasetError(path, f"{name!r} is a {type(link).__name__} (it could serve another file's data)")
        node = h5[name]
        if isinstance(node, h5py.Dataset) and (node.is_virtual or node.external):
            raise DatasetError(path, f"{name!r} is a {'virtual' if node.is_virtual else 'externally stored'} dataset "
                                     "(it could serve another file's data)")


def _check_cell(path: Path, h5: h5py.File) -> None:
    """DatasetError naming `path` unless the cell's HDF5 (its links checked) holds only what `Store.put` writes
    (module doc)."""
    attrs = dict(h5.attrs)
    try:
        bb_min, bb_max = (np.asarray(attrs[k], dtype=np.float64) for k in ("bb_min_m", "bb_max_m"))
        size = np.asarray(attrs["grid_size"])
        ok = bb_min.shape == bb_max.shape == size.shape == (3,) and np.isfinite(bb_min).all() and \
            np.isfinite(bb_max).all() and np.issubdtype(size.dtype, np.integer) and (size > 0).all()
    except (KeyError, TypeError, ValueError):
        ok = False
    if not ok:
        raise DatasetError(path, "its grid attributes (bb_min_m, bb_max_m, grid_size) are missing or invalid")
    shape = (int(size[1]), int(size[0]))
    for name in ARRAY_NAMES:
        node = h5.get(name)
        if not isinstance(node, h5py.Dataset) or node.dtype.kind != "f" or node.shape != shape:
            found = "missing" if node is None else getattr(node, "shape", type(node).__name__)
            raise DatasetError(path, f"{name!r} must be a float array of the grid's {shape[0]} x {shape[1]} pixels, "
                                     f"found {found}")


class _DeferredWriteErrors:
    """An unbuffered file for h5py's file-object driver that keeps the first failed write (or truncate, flush)
    from HDF5 and lets it go on writing into nothing: `error` holds it after the file is closed (module doc: HDF5
    that sees a failed write ends in a segmentation fault)."""

    def __init__(self, handle):
        self.handle, self.error = handle, None

    def _guard(self, name: str, *args, result=None):
        if self.error is None:
            try:
                return getattr(self, f"_{name}")(*args)
            except OSError as err:
                self.error = err
        return result

    def _write(self, data) -> int:
        view = memoryview(data).cast("B")
        done = 0
        while done < len(view):            # an unbuffered file may write a part (the last bytes below a limit)
            done += self.handle.write(view[done:]) or 0
        return done

    def _truncate(self, size=None):
        return self.handle.truncate(size)

    def _flush(self) -> None:
        self.handle.flush()

    def write(self, data) -> int:
        return self._guard("write", data, result=memoryview(data).nbytes)

    def truncate(self, size=None):
        return self._guard("truncate", size, result=size)

    def flush(self) -> None:
        self._guard("flush")

    def __getattr__(self, name: str):
        return getattr(self.handle, name)


def _update_h5(path: Path, edit) -> None:
    """Open (or create) the HDF5 file `path`, `edit(h5)` it, close it; a failed write is one OSError naming `path`
    and the partial file is removed (a later reader never sees it). A file that is not HDF5 (a run killed while
    writing it) is started anew."""
    exists = path.is_file()
    try:
        with open(path, "r+b" if exists else "w+b", buffering=0) as handle:   # unbuffered: a seek never flushes
            guarded = _DeferredWriteErrors(handle)
            try:
                h5 = h5py.File(guarded, "a")
            except OSError:                  # not an HDF5 file: what a killed writer left
                log.warning("%s is not a readable HDF5 file (a run killed while writing it?): writing it anew", path)
                handle.truncate(0)
                h5 = h5py.File(guarded, "w")
            with h5:
                edit(h5)
        if guarded.error is not None:
            raise guarded.error
    except OSError as err:
        path.unlink(missing_ok=True)
        raise OSError(f"{path}: cannot write ({err.strerror or err}); the partial file was removed") from None


def _replace_group(h5: h5py.File, group: str) -> h5py.Group:
    if group != "/" and group in h5:
        del h5[group]
    return h5.require_group(group)


def compress_arrays(arrays: dict[str, np.ndarray], pool=None) -> dict:
    """A capture's arrays compressed as `write_arrays` stores them (bench.harness.h5chunks; on `pool`'s threads
    where given), for `write_arrays` or `cell_image` in any thread; the ground truth's depth map, the same in every
    cell of a capture, compressed once for them."""
    return h5chunks.compress_arrays(arrays, repeated=("gt_depth_m",), pool=pool)


def _fill(h5: h5py.File, group: str, arrays: dict, attrs: dict | None) -> None:
    node = _replace_group(h5, group)
    for name, values in compress_arrays(arrays).items():
        h5chunks.write(node, name, values)
    node.attrs.update(attrs or {})


def write_arrays(path: Path, group: str, arrays: dict, attrs: dict | None = None) -> None:
    """Add (or replace) `group` in the HDF5 file `path` with gzip + shuffle compressed datasets (dtype kept; arrays,
    or what `compress_arrays` made of them) and attributes; a failed write is one OSError naming `path`
    (`_update_h5`)."""
    _update_h5(Path(path), lambda h5: _fill(h5, group, arrays, attrs))
