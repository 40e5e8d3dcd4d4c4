"""Reader for MAROON captures (`root/object/distance`, MAROON_FORMAT.md). Read-only: it never writes.

Every problem raises a DatasetError that names the file and says what is wrong. Reference-code behaviour that is
kept: the last frame is the default, radar frames 96x96 are sliced to the 94x94 imaging array, the grid comes
from the frame's `volume` entry, the viewer's `mask_bb` defaults are applied (in memory only), the RealSense depth
is read with the `rgb` intrinsics. Behaviour that is not kept: nothing is migrated or written back.

Hostile input is bounded (bench.maroon.limits, bench.maroon.safe_io): only regular files inside the capture's dataset
root are
opened, each within its kind's size limit; every size the data declares (array shapes, image pixels, grid pixels
and voxels, the erosion kernel, JSON depth and number lengths) is checked before anything is allocated. Folder
names: a distance folder is named with ASCII digits only (a superscript or other Unicode digit is not one); object
and distance folders whose names are not UTF-8 or hold control characters (a newline) cannot be written into
results.csv and file names faithfully, so discovery skips them with a warning naming them (escaped), and reading
one directly is a DatasetError.
"""
from __future__ import annotations

import logging
import math
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from bench.maroon import safe_io
from bench.maroon.alignment import read_alignment
from bench.maroon.antennas import N_STORED, USED, load_antenna_array
from bench.maroon.frames import Pairing, pair_nearest, realsense_times_s, select_frames, timing_files
from bench.maroon.images import read_binary_mask, read_uint16_png
from bench.maroon.jsonio import read_json
from bench.maroon.limits import Limits, current_limits, too_large, use_limits
from bench.maroon.safe_pickle import load_pickled_dict
from methods.domain.antennas import AntennaArray
from methods.domain.capture import CameraIntrinsics, Capture, DepthFrame, Mesh, Metadata, RadarFrame, RadarGrid
from methods.domain.errors import DatasetError, display_path
from methods.domain.radar import radar_folder_name

RADAR_FOLDER = radar_folder_name()          # radar_72.0_82.0_128
MESH_CANDIDATES = ("mesh_masked_smoothed.obj", "mesh_masked.obj", "mesh_smoothed.obj", "mesh.obj")
# MAROON's configured reconstruction grid, used only when calibration.json has no entry for a frame (2.5, 7).
CONFIG_GRID = RadarGrid(bb_min_m=(-0.15, -0.15, 0.25), bb_max_m=(0.15, 0.15, 0.40), size=(301, 301, 151))
PARTS = ("radar", "realsense", "mesh")
POSES_FOLDER = "poses"         # photogrammetry/poses/NNNNNN.json: a moving object's pose per radar frame
MIN_FREQ_STEP_HZ = 1e6        # the smallest frequency step of a sweep (MAROON: 78.7 MHz)
MIN_GRID_STEP_M = 1e-6         # a grid step below 1 um is no radar grid (and breaks MAROON's intrinsics)
MAX_MESH_COORDINATE = 1e6      # |vertex| in the mesh file's units (metres or millimetres): beyond is no object
_FRAME_FILE = re.compile(r"^([0-9]{6})\.npy$")
_IMAGE_FILE = re.compile(r"^([0-9]{6})\.png$")
_DISTANCE = re.compile(r"^[0-9]{1,6}$")          # ASCII digits only: '³' or '٣' is not a distance
_FRAME_KEY = re.compile(r"^[0-9]{1,9}$")
log = logging.getLogger("bench")
_MASK_BB_KEYS = ("xmin", "xmax", "ymin", "ymax", "zmin", "zmax")


# ----------------------------------------------------------------------------------------------- discovery
def name_problem(name: str) -> str | None:
    """Why a folder name cannot name a capture in results and file names (None: it can)."""
    try:
        name.encode("utf-8")
    except UnicodeEncodeError:
        return "its name is not valid UTF-8"
    if not name.isprintable():
        return "its name holds control characters (e.g. a newline)"
    return None


def is_distance_folder(path: Path) -> bool:
    """A distance folder: a directory named with ASCII digits (centimetres)."""
    return bool(_DISTANCE.match(path.name)) and path.is_dir()


def discover_captures(root: str | Path) -> list[Path]:
    """All capture folders `root/<object>/<distance>` (distance a number of centimetres, ASCII digits), sorted.

    Folders whose names cannot be written into results (not UTF-8, control characters) are skipped with a warning
    (logger `bench`); a folder named with non-ASCII digits is no distance folder and is skipped with a warning too.
    """
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(root, "dataset root is not a directory")
    captures, skipped = [], 0
    for obj in sorted(root.iterdir()):
        if obj.name.startswith((".", "00_")) or not obj.is_dir():
            continue
        distances = []
        for folder in sorted(obj.iterdir(), key=lambda p: p.name):
            if _DISTANCE.match(folder.name) and folder.is_dir():
                distances.append(folder)
            elif (folder.name.isdigit() or folder.name.isnumeric()) and folder.is_dir():
                skipped += 1
                log.warning("%s: skipped, not a distance folder (its name must be ASCII digits, in cm)",
                            display_path(folder))
        problem = name_problem(obj.name) if distances else None
        if problem is not None:
            skipped += len(distances)
            log.warning("%s: skipped, %s", display_path(obj), problem)
            continue
        captures.extend(distances)
    if not captures:
        hint = f"; {skipped} folder(s) skipped, see the warnings" if skipped else ""
        raise DatasetError(root, f"no captures found (expected folders <object>/<distance_cm>/{hint})")
    return captures


# ------------------------------------------------------------------------------------------------ metadata
def _number(path: Path, value, what: str) -> float:
    """A finite real number from JSON (int or float, not bool or string), as float."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DatasetError(path, f"{what} must be a number, found {_short(value)}")
    try:
        number = float(value)
    except OverflowError:
        raise DatasetError(path, f"{what} is too large for a float ({len(str(value))} digits)") from None
    if not math.isfinite(number):
        raise DatasetError(path, f"{what} must be a finite number, found {number}")
    return number


def _short(value) -> str:
    """A value for a message, at most 60 characters (a hostile file may hold megabytes in one value)."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 64:
        return f"an integer of {value.bit_length()} bits"
    text = repr(value) if isinstance(value, (str, int, float, bool)) or value is None else type(value).__name__
    return text if len(text) <= 60 else text[:57] + "..."


def read_metadata(capture_dir: Path) -> Metadata:
    """metadata.json, with the viewer's `mask_bb` defaults applied in memory (never written back)."""
    path = capture_dir / "metadata.json"
    raw = read_json(path)
    if "distance_meters" not in raw:
        raise DatasetError(path, "missing key 'distance_meters'")
    distance_m = _number(path, raw["distance_meters"], "distance_meters")
    if not 0.0 < distance_m < 10.0:
        raise DatasetError(path, f"distance_meters must be in metres (0-10), found {distance_m}")
    erosion = raw.get("mask_erosion", 0)
    if isinstance(erosion, bool) or not isinstance(erosion, int) or erosion < 0:
        raise DatasetError(path, f"mask_erosion must be a non-negative integer, found {_short(erosion)}")
    if erosion > current_limits().mask_erosion:
        raise DatasetError(path, too_large("mask_erosion", erosion, "mask_erosion"))
    bb = raw.get("mask_bb", {})
    if not isinstance(bb, dict) or set(bb) - set(_MASK_BB_KEYS):
        raise DatasetError(path, f"mask_bb must be a dict with keys among {', '.join(_MASK_BB_KEYS)}")
    mask_bb_m = {key: _number(path, value, f"mask_bb.{key}") for key, value in bb.items()}
    if "mask_3d_threshold" in raw:  # legacy form of mask_bb.zmax (section 8): ours keeps zmax when both are given
        legacy_zmax_m = _number(path, raw["mask_3d_threshold"], "mask_3d_threshold")
        mask_bb_m.setdefault("zmax", legacy_zmax_m)
    if distance_m == 0.3 and "zmin" not in mask_bb_m:
        mask_bb_m["zmin"] = 0.26
    mask_bb_m.setdefault("zmax", 0.7)
    for axis in "xyz":
        low, high = mask_bb_m.get(f"{axis}min"), mask_bb_m.get(f"{axis}max")
        if low is not None and high is not None and low >= high:
            raise DatasetError(path, f"mask_bb.{axis}min ({low}) must be below {axis}max ({high})")
    labels = raw.get("labels", [])
    calibration = raw.get("calibration")
    if isinstance(calibration, str) and (not calibration or name_problem(calibration) or "/" in calibration
                                         or calibration in (".", "..")):
        raise DatasetError(path, f"calibration must name a folder of 00_registration, found {_short(calibration)}")
    return Metadata(distance_m=distance_m, mask_erosion=erosion, mask_bb_m=mask_bb_m,
                    calibration=calibration if isinstance(calibration, str) else None,
                    labels=tuple(str(label) for label in labels) if isinstance(labels, list) else (), raw=raw)


def alignment_path(capture_dir: Path, metadata: Metadata) -> Path:
    """alignment.json of the capture, else `<root>/00_registration/<metadata.calibration>/alignment.json`."""
    local = capture_dir / "alignment.json"
    if local.exists() or local.is_symlink() or metadata.calibration is None:
        return local
    fallback = capture_dir.parent.parent / "00_registration" / metadata.calibration / "alignment.json"
    return fallback if fallback.is_file() else local


# --------------------------------------------------------------------------------------------------- radar
def find_radar_folder(capture_dir: Path) -> Path:
    """`radar_72.0_82.0_128`, or the only `radar_*` folder of the capture."""
    preferred = capture_dir / RADAR_FOLDER
    if preferred.is_dir():
        return preferred
    folders = sorted(p for p in capture_dir.glob("radar_*") if p.is_dir())
    if len(folders) == 1:
        return folders[0]
    if not folders:
        raise DatasetError(capture_dir, f"no radar folder (expected {RADAR_FOLDER}/)")
    raise DatasetError(capture_dir, f"several radar folders and none named {RADAR_FOLDER}: "
                                    f"{', '.join(p.name for p in folders)}")


def list_radar_frames(radar_dir: Path) -> list[int]:
    """Indices of the raw frames `calibrated_data/NNNNNN.npy`, sorted."""
    data_dir = radar_dir / "calibrated_data"
    if not data_dir.is_dir():
        raise DatasetError(data_dir, "folder is missing")
    frames = sorted(int(m.group(1)) for p in data_dir.iterdir() if (m := _FRAME_FILE.match(p.name)))
    if not frames:
        raise DatasetError(data_dir, "no frame files NNNNNN.npy")
    return frames


def _parse_grid(path: Path, key: str, entry) -> RadarGrid:
    """A `volume` entry: bb_min, bb_max (3 numbers each, metres) and grid_size (3 integers) within the limits."""
    if not isinstance(entry, dict) or not all(name in entry for name in ("bb_min", "bb_max", "grid_size")):
        raise DatasetError(path, f"'{key}' needs bb_min, bb_max (3 numbers) and grid_size (3 integers)")
    bounds = {}
    for name in ("bb_min", "bb_max", "grid_size"):
        values = entry[name]
        if not isinstance(values, list) or len(values) != 3:
            raise DatasetError(path, f"'{key}' {name} must be a list of 3 numbers, found {_short(values)}")
        bounds[name] = values
    bb_min = [_number(path, v, f"'{key}' bb_min") for v in bounds["bb_min"]]
    bb_max = [_number(path, v, f"'{key}' bb_max") for v in bounds["bb_max"]]
    size = bounds["grid_size"]
    if not all(isinstance(n, int) and not isinstance(n, bool) and n >= 1 for n in size):
        raise DatasetError(path, f"'{key}' grid_size must be positive integers, found "
                                 f"[{', '.join(_short(n) for n in size)}]")
    if size[0] < 2 or size[1] < 2:
        raise DatasetError(path, f"'{key}' grid_size {size} must have nx, ny >= 2")
    limits = current_limits()
    if size[0] * size[1] > limits.grid_pixels:
        raise DatasetError(path, too_large(f"'{key}' grid_size {size}: nx * ny", size[0] * size[1], "grid_pixels"))
    if math.prod(size) > limits.grid_voxels:
        raise DatasetError(path, too_large(f"'{key}' grid_size {size}: nx * ny * nz", math.prod(size),
                                           "grid_voxels"))
    for axis, n, low, high in zip("xyz", size, bb_min, bb_max, strict=False):
        if (n > 1 and not high > low) or (n == 1 and high < low):
            raise DatasetError(path, f"'{key}' {axis} range [{low}, {high}] is empty for {n} samples")
        if max(abs(low), abs(high)) > 10.0:
            raise DatasetError(path, f"'{key}' {axis} bounds must be in metres (|value| <= 10)")
        if n > 1 and (high - low) / (n - 1) < MIN_GRID_STEP_M:
            raise DatasetError(path, f"'{key}' {axis} step {(high - low) / (n - 1):.3g} m is below "
                                     f"{MIN_GRID_STEP_M:g} m (bounds in metres?)")
    if bb_min[2] <= 0.0:
        raise DatasetError(path, f"'{key}' z range must lie in front of the array (z > 0), found zmin {bb_min[2]}")
    return RadarGrid(bb_min_m=tuple(bb_min), bb_max_m=tuple(bb_max), size=tuple(size))


def read_radar_grids(radar_dir: Path) -> dict[int, RadarGrid]:
    """Per-frame pixel/voxel grids from the radar calibration.json (`volume`, or legacy `depth` bounds)."""
    path = radar_dir / "calibration.json"
    data = read_json(path)
    grids = {}
    for key, entry in data.items():
        if not _FRAME_KEY.match(key):
            continue
        if not isinstance(entry, dict):
            raise DatasetError(path, f"entry '{key}' must be a dict")
        depth = entry.get("depth")
        volume = entry.get("volume") or (depth if isinstance(depth, dict) and "bb_min" in depth else None)
        if volume is not None:
            grids[int(key)] = _parse_grid(path, key, volume)
    return grids


def _check_frequencies(path: Path, freqs) -> np.ndarray:
    freqs_hz = np.asarray(freqs)
    if freqs_hz.ndim != 1 or freqs_hz.size == 0 or not np.issubdtype(freqs_hz.dtype, np.number) \
            or np.iscomplexobj(freqs_hz):
        raise DatasetError(path, f"'fvec' must be a non-empty 1-D real array, found {freqs_hz.dtype} {freqs_hz.shape}")
    freqs_hz = freqs_hz.astype(np.float64)
    if not np.all(np.isfinite(freqs_hz)):
        raise DatasetError(path, "'fvec' has NaN or Inf entries")
    if freqs_hz.max() < 1e6:
        raise DatasetError(path, f"'fvec' must be in Hz; its maximum {freqs_hz.max():g} looks like GHz")
    if freqs_hz.min() < 1e9 or freqs_hz.max() > 1e12:
        raise DatasetError(path,
                           f"'fvec' must lie in 1 GHz - 1 THz (in Hz), found {freqs_hz.min():g}-{freqs_hz.max():g}")
    if freqs_hz.size > 1 and not np.all(np.diff(freqs_hz) > 0):
        raise DatasetError(path, "'fvec' must be strictly increasing")
    if freqs_hz.size > 1 and np.diff(freqs_hz).min() < MIN_FREQ_STEP_HZ:
        i = int(np.argmin(np.diff(freqs_hz)))
        raise DatasetError(path, f"'fvec' has two frequencies {freqs_hz[i + 1] - freqs_hz[i]:.3g} Hz apart (at "
                                 f"{freqs_hz[i] / 1e9:.6f} GHz); steps below {MIN_FREQ_STEP_HZ:g} Hz are no sweep "
                                 "steps (their depth ambiguity exceeds 75 m)")
    return freqs_hz


def read_radar_frame(radar_dir: Path, index: int, grid: RadarGrid, empty_filtered: bool = False) -> RadarFrame:
    """One raw frame, validated, sliced to the 94x94 imaging array, cast to complex64."""
    name = f"{index:06d}_emptyfiltered.npy" if empty_filtered else f"{index:06d}.npy"
    path = radar_dir / "calibrated_data" / name
    if not (path.exists() or path.is_symlink()):
        raise DatasetError(path, "frame file is missing")
    frame = load_pickled_dict(path)
    for key in ("xr", "fvec"):
        if key not in frame:
            raise DatasetError(path, f"frame dict has no '{key}' (keys: {', '.join(sorted(frame))})")
    xr = frame["xr"]
    if not isinstance(xr, np.ndarray) or not np.iscomplexobj(xr):
        raise DatasetError(path, f"'xr' must be a complex array, found {getattr(xr, 'dtype', type(xr).__name__)}")
    freqs_hz = _check_frequencies(path, frame["fvec"])
    n_used = USED.stop - USED.start
    if xr.ndim != 3 or xr.shape[:2] not in ((N_STORED, N_STORED), (n_used, n_used)):
        raise DatasetError(path, f"'xr' must be (96, 96, F) or (94, 94, F) [rx, tx, f], found {xr.shape}")
    if xr.shape[2] != freqs_hz.size:
        raise DatasetError(path, f"'xr' has {xr.shape[2]} frequencies but 'fvec' has {freqs_hz.size}")
    if xr.shape[0] == N_STORED:
        xr = xr[USED, USED, :]
    signal = np.ascontiguousarray(xr, dtype=np.complex64)
    if not np.all(np.isfinite(signal.view(np.float32))):
        raise DatasetError(path, "'xr' has NaN or Inf values (or values beyond float32's range)")
    largest = float(np.abs(signal.view(np.float32)).max(initial=0.0))
    if largest > current_limits().signal_abs:
        raise DatasetError(path, too_large("the largest real or imaginary part of 'xr' (the methods' float32 sums "
                                           "would overflow)", largest, "signal_abs"))
    timestamp_s = None
    stamps = frame.get("timestamp_us")
    if stamps is not None:
        stamps = np.atleast_1d(np.asarray(stamps))
        if stamps.size and np.issubdtype(stamps.dtype, np.number) and np.isfinite(stamps[0]):
            timestamp_s = float(stamps[0]) * 1e-6
    return RadarFrame(index=index, signal=signal, freqs_hz=freqs_hz, timestamp_s=timestamp_s, grid=grid, path=path)


MAX_DECLARED_FRAMES = 10 ** 9      # frames one capture may declare (MAROON's have 1-300)


def declared_frame_count(radar_dir: Path, first_frame: int) -> int | None:
    """`number_of_measurements` of the first frame file (the reference loader reads it from frame 0)."""
    path = radar_dir / "calibrated_data" / f"{first_frame:06d}.npy"
    with safe_io.use_root(radar_dir.parent):
        count = load_pickled_dict(path).get("number_of_measurements")
    count = count.item() if isinstance(count, np.generic) else count
    if not isinstance(count, int) or isinstance(count, bool):
        return None
    if not 0 <= count <= MAX_DECLARED_FRAMES:     # a huge integer cannot even be printed (Python's 4300 digits)
        digits = int(count.bit_length() * 0.30103)
        found = str(count) if abs(count) < 10 ** 30 else f"an integer of about {digits} digits"
        raise DatasetError(path, f"number_of_measurements must be 0..{MAX_DECLARED_FRAMES:,}, found {found}")
    return count


# ----------------------------------------------------------------------------------------------- realsense
def _intrinsics(path: Path, entry) -> CameraIntrinsics:
    try:
        values = {k: entry[k] for k in ("fx", "fy", "cx", "cy", "width", "height")}
    except (KeyError, TypeError):
        raise DatasetError(path, "'rgb' needs fx, fy, cx, cy, width, height") from None
    for key, value in values.items():
        _number(path, value, f"rgb.{key}")
    if values["fx"] <= 0 or values["fy"] <= 0 or values["width"] < 1 or values["height"] < 1:
        raise DatasetError(path, "rgb focal lengths and image size must be positive")
    if not all(1e-3 <= values[k] <= 1e6 for k in ("fx", "fy")) or not all(abs(values[k]) <= 1e6 for k in ("cx", "cy")):
        raise DatasetError(path, "rgb focal lengths must lie in 1e-3..1e6 pixels and cx, cy within 1e6 pixels")
    return CameraIntrinsics(fx=float(values["fx"]), fy=float(values["fy"]), cx=float(values["cx"]),
                            cy=float(values["cy"]), width=int(values["width"]), height=int(values["height"]))


def list_depth_frames(realsense_dir: Path) -> list[int]:
    """Indices of `depth/NNNNNN.png`, sorted."""
    depth_dir = realsense_dir / "depth"
    if not depth_dir.is_dir():
        raise DatasetError(depth_dir, "folder is missing")
    frames = sorted(int(m.group(1)) for p in depth_dir.iterdir() if (m := _IMAGE_FILE.match(p.name)))
    if not frames:
        raise DatasetError(depth_dir, "no depth images NNNNNN.png")
    return frames


def read_realsense(realsense_dir: Path, index: int = -1) -> tuple[DepthFrame, list[str]]:
    """Depth (uint16 mm, colour-aligned), mask and `rgb` intrinsics of one RealSense frame; plus notes."""
    notes = []
    frames = list_depth_frames(realsense_dir)
    index = frames[index] if index < 0 else index
    calibration_path = realsense_dir / "calibration.json"
    calibration = read_json(calibration_path)
    intrinsics = _intrinsics(calibration_path, calibration.get("rgb"))
    scale = calibration.get("capture", {}).get("scale", 0.001) if isinstance(calibration.get("capture"),
                                                                             dict) else 0.001
    scale_m = _number(calibration_path, scale, "capture.scale")
    depth_path = realsense_dir / "depth" / f"{index:06d}.png"
    depth = read_uint16_png(depth_path)
    if depth.shape != (intrinsics.height, intrinsics.width):
        raise DatasetError(depth_path, f"depth image is {depth.shape[1]}x{depth.shape[0]} but calibration.json rgb "
                                       f"says {intrinsics.width}x{intrinsics.height}")
    if not math.isclose(scale_m, 0.001, rel_tol=1e-6):
        if not 0.0 < scale_m < 1.0:
            raise DatasetError(calibration_path, f"capture.scale must be metres per unit in (0, 1), found {scale_m}")
        notes.append(f"{calibration_path}: capture.scale is {scale_m}, depth converted to millimetres")
        depth_mm = np.rint(depth * (scale_m * 1000.0))
        if depth_mm.max(initial=0) > 65535:
            raise DatasetError(depth_path, "depth exceeds 65535 mm after applying capture.scale")
        depth = depth_mm.astype(np.uint16)
    mask_path = realsense_dir / "mask" / f"{index:06d}.png"
    mask = None
    if mask_path.exists() or mask_path.is_symlink():        # a FIFO or a dangling link is refused, not skipped
        mask = read_binary_mask(mask_path)
        if mask.shape != depth.shape:
            raise DatasetError(mask_path, f"mask is {mask.shape[1]}x{mask.shape[0]}, depth is "
                                          f"{depth.shape[1]}x{depth.shape[0]}")
    else:
        notes.append(f"{mask_path}: no mask, the whole depth image is used")
    return DepthFrame(index=index, depth_mm=depth, mask=mask, intrinsics=intrinsics, depth_scale_m=0.001,
                      path=depth_path), notes


# -------------------------------------------------------------------------------------------- photogrammetry
def find_mesh(photogrammetry_dir: Path) -> Path:
    """The ground-truth mesh: `mesh_masked_smoothed.obj`, then mesh_masked, mesh_smoothed, mesh (.obj)."""
    for name in MESH_CANDIDATES:
        candidate = photogrammetry_dir / name
        if candidate.exists() or candidate.is_symlink():   # a FIFO or a link is refused by read_mesh, not skipped
            return candidate
    raise DatasetError(photogrammetry_dir, f"no mesh file (looked for {', '.join(MESH_CANDIDATES)})")


def _obj_face_lines(path: Path) -> int | None:
    """Number of face lines (`f ...`) of an OBJ file, None for other formats: Open3D skips broken faces silently.
    Streamed in blocks through the checked opener (a regular file inside the dataset, within `mesh_bytes`)."""
    if path.suffix.lower() != ".obj":
        return None
    count, tail = 0, b"\n"                     # a leading "f " counts like one after a newline
    with safe_io.open_checked(path, "mesh") as (handle, _):
        for block in iter(lambda: handle.read(1 << 24), b""):
            data = tail + block
            count += data.count(b"\nf ")           # the 2-byte tail cannot hold a whole match counted before
            tail = data[-2:]
    return count


def read_mesh(path: Path) -> Mesh:
    """A triangle mesh via Open3D (imported here only, so the methods never need it).

    The file passes the checks of bench.maroon.safe_io first (regular, inside the dataset, within `mesh_bytes`) and
    Open3D
    reads its real path; vertices must be finite and within 1e6 of the origin (metres or millimetres), and at least
    one triangle must have a nonzero area (degenerate triangles alone cover no pixel)."""
    import open3d as o3d

    real = safe_io.checked_path(path)
    safe_io.file_size(path, "mesh")
    faces = _obj_face_lines(path)
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    mesh = o3d.io.read_triangle_mesh(str(real))
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    triangles = np.asarray(mesh.triangles, dtype=np.int64)
    if len(vertices) == 0 or len(triangles) == 0:
        raise DatasetError(path, "mesh has no vertices or no triangles (missing, empty or unreadable OBJ)")
    if not np.all(np.isfinite(vertices)):
        raise DatasetError(path, "mesh has non-finite vertex coordinates")
    largest = float(np.abs(vertices).max())
    if largest > MAX_MESH_COORDINATE:
        raise DatasetError(path, f"mesh vertex coordinates reach {largest:.3g}; at most {MAX_MESH_COORDINATE:g} "
                                 "(metres or millimetres) are plausible")
    if triangles.min() < 0 or triangles.max() >= len(vertices):
        raise DatasetError(path, "mesh has triangle indices outside its vertex list")
    corners = vertices[triangles]
    doubled_area = np.linalg.norm(np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0]), axis=1)
    if not np.any(doubled_area > 0.0):
        raise DatasetError(path, f"all {len(triangles)} triangles of the mesh are degenerate (zero area)")
    if faces is not None and len(triangles) < faces:
        raise DatasetError(path, f"mesh file has {faces} face lines but only {len(triangles)} triangles could be "
                                 "read (truncated or malformed faces)")
    return Mesh(vertices=vertices, triangles=triangles, path=path)


# ------------------------------------------------------------------------------------------------- capture
def read_capture(capture_dir: str | Path, *, frame: int = -1, parts: tuple[str, ...] = PARTS,
                 empty_filtered: bool = False, antennas: AntennaArray | None = None,
                 limits: Limits | None = None, realsense_frame: int | None = None,
                 mesh_reader: Callable[[Path], Mesh] | None = None) -> Capture:
    """Read one capture folder `root/object/distance` into a Capture.

    `frame` is the radar frame index (-1 = last, as MAROON evaluates); `parts` chooses what to load. The radar is
    required when asked for; a missing RealSense or photogrammetry folder leaves that part None with a note,
    while a present but malformed file raises. The RealSense frame is `realsense_frame`, or by default the one
    nearest in time to the radar frame (bench.maroon.frames; MAROON's last frame without timestamps). A moving object's
    mesh pose at the radar frame (`photogrammetry/poses/NNNNNN.json`, written by the synthetic sequences) replaces
    `photogrammetry2radar`. Every file must lie inside the capture's dataset root (bench.maroon.safe_io) and within
    `limits` (default: bench.maroon.limits.current_limits()). `mesh_reader` reads the mesh file (default
    `read_mesh`; the harness passes one that keeps parsed meshes by content, bench.harness.captures).
    """
    capture_dir = Path(capture_dir)
    unknown = set(parts) - set(PARTS)
    if unknown:
        raise ValueError(f"unknown capture parts {sorted(unknown)}; choose from {PARTS}")
    if not capture_dir.is_dir():
        raise DatasetError(capture_dir, "capture folder does not exist")
    if not _DISTANCE.match(capture_dir.name):
        raise DatasetError(capture_dir, "capture folder name must be the distance in centimetres in ASCII digits "
                                        "(e.g. 30)")
    for folder in (capture_dir.absolute().parent, capture_dir):
        problem = name_problem(folder.name)
        if problem is not None:
            raise DatasetError(folder, f"cannot name a capture in results: {problem}")
    with use_limits(limits), safe_io.use_root(capture_dir):
        return _read_capture(capture_dir, frame, parts, empty_filtered, antennas, realsense_frame,
                             mesh_reader or read_mesh)


def _check_erosion_kernel(capture_dir: Path, metadata: Metadata, grid: RadarGrid) -> None:
    """The P_e / silhouette kernel in pixels of the metric grid (metrics.masks) within `erosion_kernel_px`."""
    from metrics.masks import erosion_kernel_mm, kernel_px_for_pitch  # (scipy.ndimage: imported when needed)

    pitch_mm = 1000.0 * min((hi - lo) / (n - 1) for lo, hi, n in zip(grid.bb_min_m[:2], grid.bb_max_m[:2],
                                                                       grid.size[:2], strict=False))
    kernel_px = kernel_px_for_pitch(erosion_kernel_mm(metadata.mask_erosion), pitch_mm)
    if kernel_px > current_limits().erosion_kernel_px:
        raise DatasetError(capture_dir / "metadata.json", too_large(
            f"mask_erosion {metadata.mask_erosion} on the {grid.size[0]}x{grid.size[1]} grid of {pitch_mm:.3g} mm "
            "pixels gives an erosion kernel whose size in pixels", kernel_px, "erosion_kernel_px"))


def _read_capture(capture_dir: Path, frame: int, parts: tuple[str, ...], empty_filtered: bool,
                  antennas: AntennaArray | None, realsense_frame: int | None = None,
                  mesh_reader: Callable[[Path], Mesh] = read_mesh) -> Capture:
    metadata = read_metadata(capture_dir)
    align_path = alignment_path(capture_dir, metadata)
    if not (align_path.exists() or align_path.is_symlink()):
        raise DatasetError(align_path, "alignment.json is missing (and no 00_registration fallback was found)")
    radar_dir = find_radar_folder(capture_dir)
    frames = list_radar_frames(radar_dir)
    capture = Capture(root=capture_dir.parent.parent, object_name=capture_dir.parent.name,
                      distance_cm=int(capture_dir.name), metadata=metadata, transforms=read_alignment(align_path),
                      antennas=antennas or load_antenna_array(), radar_frames=frames)
    if align_path.parent != capture_dir:
        capture.notes.append(f"alignment from fallback {align_path}")
    index = select_frames(frames, frame, radar_dir / "calibrated_data")[0] if isinstance(frame, int) else None
    if index is None:
        raise ValueError(f"read_capture reads one frame; frame must be an integer, got {frame!r}")
    pose_path = capture_dir / "photogrammetry" / POSES_FOLDER / f"{index:06d}.json"
    if "mesh" in parts and (pose_path.parent.is_dir() or pose_path.parent.is_symlink()):
        capture.transforms["photogrammetry2radar"] = frame_pose(pose_path)
    if "radar" in parts:
        grids = read_radar_grids(radar_dir)
        grid = grids.get(index)
        if grid is None:
            grid = CONFIG_GRID
            capture.notes.append(f"{radar_dir / 'calibration.json'}: no volume entry for frame {index:06d}; "
                                 "using MAROON's configured grid")
        _check_erosion_kernel(capture_dir, metadata, grid)
        capture.radar = read_radar_frame(radar_dir, index, grid, empty_filtered)
    if "realsense" in parts:
        if (capture_dir / "realsense").is_dir():
            if realsense_frame is None:
                stamp_s = None if capture.radar is None else capture.radar.timestamp_s
                realsense_frame = realsense_pairing(capture_dir / "realsense", stamp_s).realsense_frame
            capture.realsense, notes = read_realsense(capture_dir / "realsense", realsense_frame)
            capture.notes.extend(notes)
        else:
            capture.notes.append(f"{capture_dir / 'realsense'}: missing, no RealSense prior")
    if "mesh" in parts:
        if (capture_dir / "photogrammetry").is_dir():
            capture.mesh = mesh_reader(find_mesh(capture_dir / "photogrammetry"))
        else:
            capture.notes.append(f"{capture_dir / 'photogrammetry'}: missing, no ground truth")
    return capture


def frame_pose(path: Path) -> np.ndarray:
    """`photogrammetry2radar` of one radar frame from `photogrammetry/poses/NNNNNN.json` (alignment.json format):
    the pose of a moving object at that frame (synthetic sequences; MAROON's objects stand still)."""
    if not (path.exists() or path.is_symlink()):
        raise DatasetError(path, "pose of this radar frame is missing (the capture has per-frame poses)")
    transforms = read_alignment(path)
    if "photogrammetry2radar" not in transforms:
        raise DatasetError(path, "has no 'photogrammetry2radar' matrix")
    return transforms["photogrammetry2radar"]


def radar_timestamp_s(radar_dir: Path, index: int, empty_filtered: bool = False) -> float | None:
    """Acquisition time (s) of one radar frame, `timestamp_us[0]` of its file (None when absent). Reads the
    whole frame (a pickle); the reader's own path gets it from the RadarFrame instead."""
    name = f"{index:06d}_emptyfiltered.npy" if empty_filtered else f"{index:06d}.npy"
    with safe_io.use_root(radar_dir.parent):
        stamps = load_pickled_dict(radar_dir / "calibrated_data" / name).get("timestamp_us")
    if stamps is None:
        return None
    stamps = np.atleast_1d(np.asarray(stamps))
    if not (stamps.size and np.issubdtype(stamps.dtype, np.number) and np.isfinite(stamps[0])):
        return None
    return float(stamps[0]) * 1e-6


def realsense_pairing(realsense_dir: Path, radar_time_s: float | None) -> Pairing:
    """The RealSense frame nearest in time to a radar frame taken at `radar_time_s` (bench.maroon.frames)."""
    with safe_io.use_root(realsense_dir.parent):
        return pair_nearest(radar_time_s, list_depth_frames(realsense_dir), realsense_times_s(realsense_dir))


def files_read(capture_dir: Path, frame: int, parts: tuple[str, ...], empty_filtered: bool,
               realsense_frame: int | None = None) -> list[Path]:
    """The files `read_capture` opens for this radar frame and these parts (those that exist; the result store
    hashes them). `realsense_frame` None pairs by time like read_capture (reading the radar frame's timestamp
    when the capture has several RealSense frames)."""
    capture_dir = Path(capture_dir)
    metadata = read_metadata(capture_dir)
    files = [capture_dir / "metadata.json", alignment_path(capture_dir, metadata)]
    radar_dir = find_radar_folder(capture_dir)
    index = select_frames(list_radar_frames(radar_dir), frame, radar_dir / "calibrated_data")[0]
    frame_file = radar_dir / "calibrated_data" / (f"{index:06d}_emptyfiltered.npy" if empty_filtered
                                                  else f"{index:06d}.npy")
    if "radar" in parts:
        files += [radar_dir / "calibration.json", frame_file]
    realsense_dir = capture_dir / "realsense"
    if "realsense" in parts and realsense_dir.is_dir():
        if realsense_frame is None:
            depth_frames = list_depth_frames(realsense_dir)
            stamp_s = radar_timestamp_s(radar_dir, index, empty_filtered) if len(depth_frames) > 1 else None
            realsense_frame = realsense_pairing(realsense_dir, stamp_s).realsense_frame
            files += timing_files(realsense_dir) + ([frame_file] if "radar" not in parts else [])
        files += [realsense_dir / "calibration.json", realsense_dir / "depth" / f"{realsense_frame:06d}.png",
                  realsense_dir / "mask" / f"{realsense_frame:06d}.png"]
    if "mesh" in parts and (capture_dir / "photogrammetry").is_dir():
        files.append(find_mesh(capture_dir / "photogrammetry"))
        files.append(capture_dir / "photogrammetry" / POSES_FOLDER / f"{index:06d}.json")
    return [f for f in files if f.exists() or f.is_symlink()]   # a FIFO or dangling link is refused, not skipped
