"""Per-capture work outside the methods, done once per capture and process, not once per cell: reading (each part
of a frame read once) and the ground truth (ray casts, silhouettes, KD-tree). With a result store, the parsed mesh
is kept there by the content of its file (`<store>/meshes/`), so later sweeps need no Open3D to read it.

The ground truth (its rasters, the costly part: two ray casts of the mesh, and what is derived from them: points,
silhouettes, the reference profile's splat) is also kept on disk under the result store,
`<store>/ground_truth/<key>.h5`, keyed like the store's cells by the content of the files it comes from (metadata,
alignment, mesh, the frame's pose, the radar calibration's grid) and the code version: a later sweep (another
experiment on the same captures) reads its arrays instead of importing Open3D, reading the mesh, casting rays and
deriving them, and needs no mesh at all unless its prior is the photogrammetry one. A sweep without a result store
keeps both in `store.cache` instead (bench.harness.app._kept_inputs; the user's cache folder by default). A kept
file is checked as it is read and ignored, with a warning naming it, when it fails a check (`_read_kept`).
"""
from __future__ import annotations

import collections
import dataclasses
import functools
import io
import json
import logging
import os
from collections.abc import Callable
from pathlib import Path

import h5py
import numpy as np

from bench.harness import atomic
from bench.harness.store import Store, code_version
from bench.maroon import reader
from bench.maroon.antennas import load_antenna_array
from methods.domain.capture import Capture, Mesh
from methods.domain.errors import DatasetError
from metrics.evaluate import (
    GroundTruth,
    ground_truth_arrays,
    ground_truth_from_arrays,
    ground_truth_from_rasters,
    ground_truth_rasters_m,
)

#: MiB of arrays each of the two caches below may hold: a sweep reads each capture frame once and builds its ground
#: truth once while its frames fit, whatever its number of cells. A synthetic capture frame holds ~12 MiB (radar 8.6,
#: RealSense 0.9, mesh 2.3) and its ground truth ~2 MiB: the 81 captures of the full synthetic catalogue at three
#: distances fit. (16 frames each, as before, made every cell of a sweep over more captures read and score them
#: anew: Table II over 81 captures on the H100 host spent 19.5 s reading and 7.7 s on ground truths in 40.7 s.)
KEPT_MIB = 1024
log = logging.getLogger("bench")
#: the arrays of a kept ground truth (metrics.evaluate.ground_truth_arrays) and their numpy dtype kinds
GROUND_TRUTH_ARRAYS = {"depth_m": "f", "reference_depth_m": "f", "points_m": "f", "silhouette": "b",
                       "eroded_silhouette": "b", "reference_points_m": "f", "reference_splat_mm": "f"}



def held_bytes(value) -> int:
    """Bytes of the NumPy arrays `value` holds in dataclass fields, tuples, lists and dict values (each array
    once)."""
    seen, total, todo = set(), 0, [value]
    while todo:
        item = todo.pop()
        if isinstance(item, np.ndarray):
            if id(item) not in seen:
                seen.add(id(item))
                total += item.nbytes
        elif dataclasses.is_dataclass(item) and not isinstance(item, type):
            todo.extend(getattr(item, f.name) for f in dataclasses.fields(item))
        elif isinstance(item, (tuple, list)):
            todo.extend(item)
        elif isinstance(item, dict):
            todo.extend(item.values())
    return total


class Kept:
    """The least recently used entries, as many as fit in `limit_mib` MiB of arrays (`held_bytes`; the newest entry
    is kept whatever its size)."""

    def __init__(self, limit_mib: float | None = None):
        self.limit_bytes = (KEPT_MIB if limit_mib is None else limit_mib) * 2**20
        self._entries: collections.OrderedDict = collections.OrderedDict()    # key -> (value, bytes)

    def __contains__(self, key) -> bool:
        return key in self._entries

    def __len__(self) -> int:
        return len(self._entries)

    def get(self, key, default=None):
        """The value kept under `key` (now the most recently used), else `default`."""
        if key not in self._entries:
            return default
        self._entries.move_to_end(key)
        return self._entries[key][0]

    def pop(self, key, default=None):
        entry = self._entries.pop(key, None)
        return default if entry is None else entry[0]

    def put(self, key, value) -> None:
        """Keep `value` under `key` as the most recently used; drop the least recently used beyond the limit."""
        self._entries[key] = (value, held_bytes(value))
        self._entries.move_to_end(key)
        total = sum(size for _, size in self._entries.values())
        while len(self._entries) > 1 and total > self.limit_bytes:
            total -= self._entries.popitem(last=False)[1][1]

    def values(self) -> list:
        return [value for value, _ in self._entries.values()]


# (frame key) -> (Capture, parts read, its ground truth's disk keys by (store root, grid): `kept_key`)
_CAPTURES = Kept()
_GROUND_TRUTHS = Kept()


def read(capture_dir: Path, frame: int, parts: tuple[str, ...], empty_filtered: bool,
         antenna_files: tuple[str | None, str | None], store: Store | None = None) -> Capture:
    """The capture frame with `parts`, each part read once per process: a worker (or the basic launcher's one
    process) runs many cells on the same captures, BP needing radar and mesh and MM-2FSK the RealSense frame too,
    so a later cell reads only the parts no earlier cell read (the RealSense frame paired with the cached radar
    frame's time, as read_capture pairs it). With a store, a mesh file parsed once is kept there (`kept_mesh`)."""
    key = (capture_dir, frame, empty_filtered, antenna_files)
    cached, have, keys = _CAPTURES.pop(key, (None, (), {}))
    missing = tuple(part for part in parts if part not in have)
    if missing:
        paired = None
        if "realsense" in missing and cached is not None and cached.radar is not None \
                and (capture_dir / "realsense").is_dir():
            paired = reader.realsense_pairing(capture_dir / "realsense", cached.radar.timestamp_s).realsense_frame
        new = reader.read_capture(capture_dir, frame=frame, parts=missing, empty_filtered=empty_filtered,
                                  antennas=load_antenna_array(*antenna_files), realsense_frame=paired,
                                  mesh_reader=None if store is None else functools.partial(kept_mesh, store))
        if cached is not None:
            new = dataclasses.replace(cached, notes=cached.notes + new.notes,
                                      transforms=new.transforms if "mesh" in missing else cached.transforms,
                                      **{part: getattr(new, part) for part in missing})
        cached, have = new, have + missing
    _CAPTURES.put(key, (cached, have, keys))
    return dataclasses.replace(cached, **{part: None for part in reader.PARTS if part not in parts})


def kept_mesh(store: Store, path: Path) -> Mesh:
    """The mesh file `path` parsed (bench.maroon.reader.read_mesh: Open3D and its checks) the first time its
    content is seen, then read back from `<store>/meshes/<key>.h5` (key: the file's sha256 and the code version;
    vertices, triangles as parsed): a sweep whose prior is the photogrammetry mesh then neither imports Open3D nor
    parses the OBJ. A kept file that fails a check (`_mesh_arrays`) is not used: a warning names it, and the OBJ is
    parsed and kept anew."""
    key = store.key({"mesh": store.file_digest(path), "code": code_version()})   # a new reader parses it anew
    kept = store.root / "meshes" / f"{key}.h5"
    arrays = _read_kept(store, kept, key, _mesh_arrays, "parsing the mesh file again")
    if arrays is not None:
        return Mesh(vertices=arrays["vertices"], triangles=arrays["triangles"], path=path)
    mesh = reader.read_mesh(path)
    _keep(kept, {"vertices": mesh.vertices, "triangles": mesh.triangles}, key)
    return mesh


def _mesh_arrays(path: Path, h5: h5py.File) -> dict[str, np.ndarray]:
    """A kept mesh's arrays as `read_mesh` returned them: (N, 3) finite float64 vertices, (M, 3) integer triangles
    indexing them; DatasetError naming `path` otherwise."""
    vertices, triangles = (_dataset(path, h5, name, kind) for name, kind in (("vertices", "f"), ("triangles", "i")))
    if vertices.ndim != 2 or vertices.shape[1] != 3 or not len(vertices) or not np.isfinite(vertices).all():
        raise DatasetError(path, f"'vertices' must be N x 3 finite numbers, found {vertices.shape}")
    if triangles.ndim != 2 or triangles.shape[1] != 3 or not len(triangles) or triangles.min() < 0 \
            or triangles.max() >= len(vertices):
        raise DatasetError(path, f"'triangles' must be M x 3 indices of the {len(vertices)} vertices")
    return {"vertices": vertices.astype(np.float64, copy=False), "triangles": triangles.astype(np.int64, copy=False)}


def _ground_truth_arrays(path: Path, h5: h5py.File, shape: tuple[int, int]) -> dict[str, np.ndarray]:
    """A kept ground truth's arrays (metrics.evaluate.ground_truth_arrays): float64 depth maps of the grid's `shape`
    (NaN = no surface, else finite), a finite float64 splat of that shape, boolean silhouettes of that shape, finite
    float64 N x 3 points; DatasetError naming `path` otherwise."""
    arrays = {name: _dataset(path, h5, name, kind) for name, kind in GROUND_TRUTH_ARRAYS.items()}
    for name, values in arrays.items():
        kind = GROUND_TRUTH_ARRAYS[name]
        if name.endswith("points_m"):
            ok = values.ndim == 2 and values.shape[1] == 3 and values.dtype == np.float64 and np.isfinite(values).all()
            wanted = "float64 N x 3 points"
        else:
            ok = values.shape == shape and values.dtype == (np.bool_ if kind == "b" else np.float64) and (
                kind == "b" or not np.isinf(values).any()) and (name != "reference_splat_mm" or
                                                                np.isfinite(values).all())
            wanted = f"{'boolean' if kind == 'b' else 'float64'} map of {shape[0]} x {shape[1]} pixels"
        if not ok:
            raise DatasetError(path, f"{name!r} must be a {wanted}, found {values.dtype} {values.shape}")
    return arrays


def _dataset(path: Path, h5: h5py.File, name: str, kind: str) -> np.ndarray:
    """Dataset `name` of numpy dtype kind `kind` ('f', 'b'; 'i': signed or unsigned integers), read whole."""
    node = h5.get(name)
    if not isinstance(node, h5py.Dataset) or node.dtype.kind not in (kind, "u" if kind == "i" else kind):
        raise DatasetError(path, f"{name!r} is missing or not an array of "
                                 f"{ {'f': 'numbers', 'b': 'booleans', 'i': 'indices'}[kind]}")
    return node[()]


def _read_kept(store: Store, path: Path, key: str, arrays: Callable, instead: str, *args) -> dict | None:
    """The arrays of a file kept under `key` (`arrays(path, h5, *args)` checks and returns them), or None where
    there is none or it is not usable (read through `Store.open_h5`: a regular file inside the store, of hard links
    only; written for this `key`; its arrays as checked): then a warning names the file and what is done
    `instead`. A file of the store is never trusted (it may hold anything: a killed writer's bytes, another key's
    arrays, links to other files)."""
    if not os.path.lexists(path):
        return None
    try:
        with store.open_h5(path) as h5:
            made_by = h5.attrs.get("key")
            if made_by != key:
                raise DatasetError(path, f"was written for another key ({str(made_by)[:16]}), not {key[:16]}")
            return arrays(path, h5, *args)
    except (DatasetError, OSError) as err:
        log.warning("kept file %s is not usable, %s: %s", path, instead, " ".join(str(err).split()))
        return None


def _remember(key, gt: GroundTruth) -> GroundTruth:
    _GROUND_TRUTHS.put(key, gt)
    return gt


def kept_key(store: Store, capture_dir: Path, frame: int, empty_filtered: bool, grid,
             antenna_files: tuple[str | None, str | None] | None = None) -> str | None:
    """The disk key of a frame's ground truth on `grid`: the digest of the files it is made from (metadata,
    alignment, mesh, the frame's pose where the capture has per-frame poses), the grid and the code version; None
    when the capture has no mesh (no ground truth to keep). A static object's frames share it. Worked out once per
    capture frame held in memory (`read` with these `antenna_files`): the files it names (their list comes from the
    capture's metadata, parsed anew each time) are those the held frame was read from, and they are trusted for as
    long as the frame is (every later cell of the process: ~3 ms a row saved)."""
    entry = _CAPTURES.get((capture_dir, frame, empty_filtered, antenna_files))
    memo = (store.root, grid)
    if entry is not None and memo in entry[2]:
        return entry[2][memo]
    files = reader.files_read(capture_dir, frame, ("mesh",), empty_filtered)
    key = None
    if any(path.parent.name == "photogrammetry" for path in files):
        key = store.key({"ground_truth": store.capture_digest(files), "grid": dataclasses.asdict(grid),
                         "code": code_version()})
    if entry is not None:
        entry[2][memo] = key
    return key


def load_kept(store: Store, key: str, capture: Capture) -> GroundTruth | None:
    """The ground truth kept under `key` for this capture frame (its radar part read), or None: none kept, or a
    file that fails a check (`_read_kept`; a warning names it, and the rasters are cast again)."""
    grid = capture.radar.grid
    arrays = _read_kept(store, store.root / "ground_truth" / f"{key}.h5", key, _ground_truth_arrays,
                        "casting the ground truth again", grid.image_shape)
    return None if arrays is None else ground_truth_from_arrays(arrays, grid, capture.metadata)


def ground_truth(capture_dir: Path, capture: Capture, with_mesh: Callable[[], Capture], store: Store | None = None,
                 key: str | None = None) -> GroundTruth | None:
    """The capture's ground truth on its metric grid (the frame's calibration grid), whatever the cell's prior, or
    None without a mesh: from memory (a static object's frames and every cell of a process share it), else from
    the store's kept rasters under `key` (`kept_key`), else cast from the mesh (`with_mesh()` gives the capture
    with its mesh read; the rasters are then kept under `key`)."""
    grid = capture.radar.grid
    memory_key = None if key is None else (capture_dir, grid, key)
    if memory_key in _GROUND_TRUTHS:
        return _GROUND_TRUTHS.get(memory_key)
    gt = None if key is None else load_kept(store, key, capture)
    if gt is None:
        meshed = capture if capture.mesh is not None else with_mesh()
        if meshed.mesh is None:
            return None
        if memory_key is None:          # no store: known by the pose the mesh was read with
            pose = meshed.transforms.get("photogrammetry2radar")
            memory_key = (capture_dir, grid, None if pose is None else pose.tobytes())
            if memory_key in _GROUND_TRUTHS:
                return _GROUND_TRUTHS.get(memory_key)
        rasters = ground_truth_rasters_m(meshed, grid)
        gt = ground_truth_from_rasters(*rasters, grid, meshed.metadata)
        if key is not None:
            _keep(store.root / "ground_truth" / f"{key}.h5", ground_truth_arrays(gt), key)
    return _remember(memory_key, gt)


def _keep(path: Path, arrays: dict[str, np.ndarray], key: str) -> None:
    """Write the arrays, and the `key` they are kept under, whole or not at all (bench.harness.atomic, as the store
    writes its cells). A kept file only saves work: where it cannot be written (a full disk or quota, a read-only
    folder) a warning says so and the run goes on."""
    image = io.BytesIO()
    with h5py.File(image, "w") as h5:
        for name, values in arrays.items():
            h5.create_dataset(name, data=values, compression="gzip", compression_opts=1, shuffle=True)
        h5.attrs["made_by"] = json.dumps({"code": code_version()})
        h5.attrs["key"] = key
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic.write_bytes(path, image.getvalue())
    except OSError as err:
        log.warning("could not keep %s (%s); going on without it", path, err.strerror or err)
