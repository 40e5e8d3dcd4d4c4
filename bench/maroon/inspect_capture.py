"""`python -m bench.maroon.inspect_capture DIR`: what each capture holds and what is missing or wrong, and which of
MAROON's
reference-viewer expectations it meets (bench.maroon.reference_check; information only). Exit 1 on any problem."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.cli import ArgumentParser, run_guarded
from bench.maroon import reader
from bench.maroon.reference_check import reference_expectations
from methods.domain.capture import Capture
from methods.domain.errors import DatasetError
from methods.domain.transforms import apply_transform


def _radar_lines(capture: Capture) -> list[str]:
    frame = capture.radar
    f_ghz = frame.freqs_hz / 1e9
    step_mhz = np.median(np.diff(frame.freqs_hz)) / 1e6 if f_ghz.size > 1 else 0.0
    g = frame.grid
    return [
        f"radar      {frame.path.parent.parent.name}: frames {_ranges(capture.radar_frames)}, "
        f"reading {frame.index:06d}",
        f"  signal   {'x'.join(map(str, frame.signal.shape))} [rx, tx, f] complex64, "
        f"|s| max {np.abs(frame.signal).max():.3g}",
        f"  fvec     {f_ghz.size} frequencies {f_ghz[0]:.3f}-{f_ghz[-1]:.3f} GHz, step {step_mhz:.2f} MHz",
        f"  grid     x [{g.bb_min_m[0]:+.3f}, {g.bb_max_m[0]:+.3f}] y [{g.bb_min_m[1]:+.3f}, {g.bb_max_m[1]:+.3f}] "
        f"z [{g.bb_min_m[2]:.3f}, {g.bb_max_m[2]:.3f}] m, {g.size[0]}x{g.size[1]}x{g.size[2]}",
    ]


def _realsense_lines(capture: Capture) -> list[str]:
    depth = capture.realsense
    k = depth.intrinsics
    valid = depth.depth_mm > 0
    mask = "no mask" if depth.mask is None else f"mask {100 * depth.mask.mean():.1f}% of pixels"
    lines = [f"realsense  {depth.path.name}: {k.width}x{k.height} uint16 mm, valid {100 * valid.mean():.1f}%, {mask}",
             f"  rgb K    fx {k.fx:.1f} fy {k.fy:.1f} cx {k.cx:.1f} cy {k.cy:.1f}"]
    if valid.any():
        lines[0] += f", depth {depth.depth_mm[valid].min()}-{depth.depth_mm[valid].max()} mm"
    return lines


def _mesh_lines(capture: Capture) -> list[str]:
    mesh = capture.mesh
    line = f"mesh       {mesh.path.name}: {len(mesh.vertices)} vertices, {len(mesh.triangles)} triangles"
    to_radar = capture.transforms.get("photogrammetry2radar")
    if to_radar is not None:
        z_m = apply_transform(to_radar, mesh.vertices)[:, 2]
        line += f", radar z {z_m.min():.3f}-{z_m.max():.3f} m"
    return [line]


def _ranges(indices: list[int]) -> str:
    return f"{indices[0]:06d}" if len(indices) == 1 else f"{indices[0]:06d}..{indices[-1]:06d} ({len(indices)})"


def inspect_capture(capture_dir: Path) -> tuple[list[str], list[str]]:
    """Lines describing what was found, and lines naming each problem."""
    found, problems = [], []
    try:
        capture = reader.read_capture(capture_dir, parts=())
    except DatasetError as err:
        return found, [str(err)]
    md = capture.metadata
    found.append(f"metadata   distance {md.distance_m:.2f} m, mask_erosion {md.mask_erosion}, mask_bb {md.mask_bb_m}")
    found.append(f"transforms {', '.join(sorted(capture.transforms)) or 'none'}")
    for needed in ("realsense2radar", "photogrammetry2radar"):
        if needed not in capture.transforms:
            problems.append(f"{reader.alignment_path(capture_dir, md)}: no '{needed}' transform")
    for part, describe in (("radar", _radar_lines), ("realsense", _realsense_lines), ("mesh", _mesh_lines)):
        try:
            loaded = reader.read_capture(capture_dir, parts=(part,))
        except DatasetError as err:
            problems.append(str(err))
            continue
        if getattr(loaded, part) is not None:
            found.extend(describe(loaded))
        problems.extend(note for note in loaded.notes if "missing" in note)
    try:
        radar_dir = reader.find_radar_folder(capture_dir)
        declared = reader.declared_frame_count(radar_dir, capture.radar_frames[0])
        if declared is not None and declared != len(capture.radar_frames):
            problems.append(f"{radar_dir}: number_of_measurements says {declared} frames, "
                            f"{len(capture.radar_frames)} frame files found")
    except DatasetError as err:
        problems.append(str(err))
    return found + _reference_lines(capture_dir), list(dict.fromkeys(problems))


def _reference_lines(capture_dir: Path) -> list[str]:
    """Which of MAROON's reference-viewer expectations the capture meets (information, not problems)."""
    expectations = reference_expectations(capture_dir)
    unmet = [e for e in expectations if not e.met]
    lines = [f"reference  {len(expectations) - len(unmet)}/{len(expectations)} of the MAROON viewer's expectations "
             f"met{'' if unmet else ' (it would read this capture)'}"]
    return lines + [f"  not met  {e.what}: {e.why}" for e in unmet]


def main() -> int:
    parser = ArgumentParser(prog="python -m bench.maroon.inspect_capture", description=__doc__)
    parser.add_argument("root", type=Path, help="dataset root (holding <object>/<distance>/) or one capture folder")
    args = parser.parse_args()
    root = args.root
    captures = [root] if root.name.isdigit() and (root / "metadata.json").exists() else reader.discover_captures(root)
    n_bad = 0
    for capture_dir in captures:
        found, problems = inspect_capture(capture_dir)
        n_bad += bool(problems)
        print(f"{capture_dir.parent.name}/{capture_dir.name}  {'PROBLEMS' if problems else 'ok'}")
        for line in found:
            print(f"  {line}")
        for line in problems:
            print(f"  !! {line}")
    print(f"{len(captures)} capture(s), {len(captures) - n_bad} ok, {n_bad} with problems")
    return 1 if n_bad else 0


if __name__ == "__main__":
    run_guarded(main)
