"""What MAROON's reference viewer expects of a capture folder (MAROON_FORMAT.md 1-4, 8), checked without reading
more than names and, for `cams.xml`, its bytes (bounded): so a user knows whether the reference code would read the
capture too, and whether it would write into it (the viewer migrates and completes some files on first use).

Our reader needs less (bench.maroon.reader); an unmet expectation is information, not a problem of the capture.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from bench.maroon import reader as maroon
from bench.maroon import safe_io
from methods.domain.errors import DatasetError

REFERENCE_RADAR_FOLDER = "radar_72.0_82.0_128"     # built by the viewer from its config (72, 82 GHz, 128 points)
MESH_STEMS = ("mesh_masked", "mesh")               # the viewer's choice with masks on, then its fallback


@dataclass(frozen=True)
class Expectation:
    what: str          # the expectation, in words
    met: bool
    why: str = ""      # when not met: what is missing or different


def _metadata(capture_dir: Path) -> list[Expectation]:
    try:
        metadata = maroon.read_metadata(capture_dir)
    except DatasetError as err:
        return [Expectation("metadata.json readable", False, str(err))]
    bb = metadata.raw.get("mask_bb", {}) if isinstance(metadata.raw.get("mask_bb", {}), dict) else {}
    needed = ["zmax"] + (["zmin"] if metadata.distance_m == 0.3 else [])
    missing = [key for key in needed if key not in bb]
    return [
        Expectation("metadata.json holds the mask_bb bounds the viewer would otherwise write into it", not missing,
                    f"no mask_bb.{', mask_bb.'.join(missing)}: the viewer adds its default and rewrites the file"),
        Expectation("no legacy mask_3d_threshold", "mask_3d_threshold" not in metadata.raw,
                    "the viewer migrates it into mask_bb.zmax (overriding a given zmax) and rewrites the file"),
    ]


def _radar(capture_dir: Path) -> list[Expectation]:
    folder = capture_dir / REFERENCE_RADAR_FOLDER
    if not folder.is_dir():
        others = sorted(p.name for p in capture_dir.glob("radar_*") if p.is_dir())
        return [Expectation(f"radar folder {REFERENCE_RADAR_FOLDER}/", False,
                            f"found {', '.join(others) or 'none'}; the viewer's default config builds that name")]
    out = [Expectation(f"radar folder {REFERENCE_RADAR_FOLDER}/", True)]
    try:
        frames = maroon.list_radar_frames(folder)
    except DatasetError as err:
        return out + [Expectation("radar frames 000000..N-1", False, str(err))]
    contiguous = frames == list(range(len(frames)))
    out.append(Expectation("radar frames 000000..N-1 (the loader reads 0..number_of_measurements-1)", contiguous,
                           f"frames {frames[0]:06d}..{frames[-1]:06d} with gaps or an offset" if frames else "none"))
    try:
        grids = maroon.read_radar_grids(folder)
        has_volume = bool(frames) and frames[-1] in grids
        why = f"no 'volume' entry for frame {frames[-1]:06d}: the viewer falls back to its configured grid" \
            if frames else "no frame"
    except DatasetError as err:
        has_volume, why = False, str(err)
    out.append(Expectation("calibration.json has the last frame's 'volume' grid", has_volume, why))
    return out


def _realsense(capture_dir: Path) -> list[Expectation]:
    folder = capture_dir / "realsense"
    jpgs = sorted(p.stem for p in (folder / "rgb").glob("*.jpg")) if (folder / "rgb").is_dir() else []
    if not jpgs:
        return [Expectation("realsense/rgb/NNNNNN.jpg (the viewer counts them to find the last frame)", False,
                            "no rgb/*.jpg")]
    last = f"{len(jpgs) - 1:06d}"                   # the viewer evaluates frame count - 1
    missing = [f"realsense/{sub}/{last}.png" for sub in ("depth", "mask")
               if not (folder / sub / f"{last}.png").is_file()]
    if not (folder / "calibration.json").is_file():
        missing.append("realsense/calibration.json")
    return [Expectation("realsense/rgb/NNNNNN.jpg (the viewer counts them to find the last frame)", True),
            Expectation(f"realsense depth, mask and calibration of its last frame {last}", not missing,
                        f"missing {', '.join(missing)}")]


def _photogrammetry(capture_dir: Path) -> list[Expectation]:
    folder = capture_dir / "photogrammetry"
    out = []
    if (folder / "mesh_smoothed_cleaned.ply").is_file():
        stem = "mesh_smoothed_cleaned"
        out.append(Expectation("photogrammetry mesh", True))
    else:
        stem = next((s for s in MESH_STEMS if (folder / f"{s}.obj").is_file()), None)
        out.append(Expectation("photogrammetry/mesh_masked.obj or mesh.obj", stem is not None,
                               "neither exists: the viewer finds no ground truth"))
        if stem is not None:
            out.append(Expectation(f"photogrammetry/{stem}_smoothed.obj", (folder / f"{stem}_smoothed.obj").is_file(),
                                   "missing: the viewer smooths the mesh and writes it into the dataset"))
    names = sorted(p.stem for p in (folder / "depth").glob("*.tif")) if (folder / "depth").is_dir() else []
    out.append(Expectation("photogrammetry/depth/*.tif", bool(names), "none: the viewer's photogrammetry loader "
                           "fails and no metric is computed"))
    if names:
        no_rgb = [n for n in names if not ((folder / "rgb" / f"{n}.jpg").is_file()
                                           or (folder / "rgb" / f"{n}.JPG").is_file())]
        out.append(Expectation("photogrammetry/rgb/<camera>.jpg for every depth image", not no_rgb,
                               f"missing for {', '.join(no_rgb[:3])}{' ...' if len(no_rgb) > 3 else ''}"))
        out.append(_cams_xml(folder, names))
    return out


def _cams_xml(folder: Path, names: list[str]) -> Expectation:
    what = "photogrammetry/cams.xml names every depth image's camera"
    path = folder / "cams.xml"
    if not path.is_file():
        return Expectation(what, False, "no cams.xml")
    try:
        text = safe_io.read_bytes(path, "json").decode("utf-8", errors="replace")
    except DatasetError as err:
        return Expectation(what, False, str(err))
    labels = set(re.findall(r'<camera\b[^>]*\blabel="([^"]*)"', text))
    unnamed = [n for n in names if n not in labels]
    return Expectation(what, not unnamed, f"no camera labelled {', '.join(unnamed[:3])}")


def reference_expectations(capture_dir: Path) -> list[Expectation]:
    """Every expectation of the reference viewer about `capture_dir` (a `<root>/<object>/<distance>` folder)."""
    capture_dir = Path(capture_dir)
    with safe_io.use_root(capture_dir):
        return _metadata(capture_dir) + _radar(capture_dir) + _realsense(capture_dir) + _photogrammetry(capture_dir)
