"""Which frames of a capture to evaluate, and which RealSense frame goes with each radar frame.

Frame selection (`dataset.frame`): an integer (a frame index; negative = counted from the end, -1 = the last
frame, MAROON's default), `all`, a slice `start:stop[:step]` over the capture's sorted frame list (Python's rules,
e.g. `0:10`, `-5:`, `::2`), or a list of integers (`[0,3,5]`). On MAROON and the synthetic captures frames are
numbered 0..N-1, so a slice over the list is a slice over the indices.

Pairing: each radar frame is paired with the RealSense frame nearest in time. Radar time: the frame file's
`timestamp_us[0]` (microseconds); RealSense time: `realsense/timestamps.txt` (`NNNNNN <timestamp_ns>` lines after a
header), shifted by `temporal_alignment.json` `realsense2radar.shift_seconds` where that file exists
(MAROON_FORMAT.md 3.1). Without both times the rule is MAROON's: the last RealSense frame. The pairing records the
RealSense index and its offset (RealSense time - radar time, seconds; NaN for the 'last' rule).
"""
from __future__ import annotations

import bisect
import math
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from bench.maroon import safe_io
from bench.maroon.jsonio import read_json
from methods.domain.errors import DatasetError

_SLICE = re.compile(r"^\s*(-?\d+)?\s*:\s*(-?\d+)?\s*(?::\s*(-?\d+)?\s*)?$")
_LIST = re.compile(r"^\s*\[\s*(-?\d+\s*(,\s*-?\d+\s*)*)?\]\s*$")
TIMESTAMPS_FILE = "timestamps.txt"
TEMPORAL_ALIGNMENT_FILE = "temporal_alignment.json"


def parse_frame_spec(spec) -> int | str | slice | tuple[int, ...]:
    """A `dataset.frame` value as an int, 'all', a slice or a tuple of ints; ValueError (one line) otherwise.

    Accepts what Hydra hands over: int, str ('all', '0:10', '[0,3,5]', '7') or a list of ints."""
    if isinstance(spec, bool):
        raise ValueError(f"dataset.frame must be an integer, 'all', a range like 0:10 or a list like [0,3,5], "
                         f"got {spec!r}")
    if isinstance(spec, (int, slice)) or spec == "all":
        return spec
    if isinstance(spec, Sequence) and not isinstance(spec, str):
        values = list(spec)
        if values and all(isinstance(v, int) and not isinstance(v, bool) for v in values):
            return tuple(values)
    if isinstance(spec, str):
        text = spec.strip()
        if text == "all":
            return "all"
        if re.fullmatch(r"-?\d+", text):
            return int(text)
        if (match := _SLICE.match(text)) and ":" in text:
            start, stop, step = (None if g is None else int(g) for g in match.groups())
            if step == 0:
                raise ValueError(f"dataset.frame={spec}: the step of a range must not be 0")
            return slice(start, stop, step)
        if _LIST.match(text):
            return tuple(int(v) for v in text.strip()[1:-1].split(",") if v.strip())
    raise ValueError(f"dataset.frame must be an integer, 'all', a range like 0:10 or a list like [0,3,5], "
                     f"got {spec!r}")


def select_frames(available: Sequence[int], spec, where: Path) -> list[int]:
    """The frame indices `spec` (see parse_frame_spec) picks from the sorted `available` indices.

    An integer or list entry >= 0 is a frame index that must exist; a negative one counts from the end. A slice
    or 'all' picks what exists (an empty result is an error). `where` names the folder in errors."""
    spec = parse_frame_spec(spec)
    available = list(available)
    if spec == "all":
        return available
    if isinstance(spec, slice):
        picked = available[spec]
        if not picked:
            raise DatasetError(where, f"frame range {_slice_text(spec)} selects none of the {len(available)} frames")
        return picked
    picked = []
    for value in (spec,) if isinstance(spec, int) else spec:
        if value < 0:
            if -value > len(available):
                raise DatasetError(where, f"frame {value} not present ({len(available)} frames)")
            value = available[value]
        elif value not in available:
            raise DatasetError(where, f"frame {value} not present (have {_frame_list(available)})")
        picked.append(value)
    if not picked:
        raise DatasetError(where, "the frame list is empty")
    return picked


def _slice_text(spec: slice) -> str:
    parts = ["" if v is None else str(v) for v in (spec.start, spec.stop)]
    return ":".join(parts + ([str(spec.step)] if spec.step is not None else []))


def _frame_list(frames: Sequence[int]) -> str:
    return ", ".join(map(str, frames)) if len(frames) <= 8 else f"{frames[0]}..{frames[-1]}, {len(frames)} frames"


@dataclass(frozen=True)
class Pairing:
    """The RealSense frame paired with a radar frame: its index, offset (RealSense - radar time, s; NaN when the
    rule is 'last') and the rule used ('nearest' in time, or MAROON's 'last' frame when times are missing)."""

    realsense_frame: int
    offset_s: float
    rule: str


def timing_files(realsense_dir: Path) -> list[Path]:
    """The files that decide the pairing (those that exist): timestamps.txt and temporal_alignment.json."""
    candidates = [realsense_dir / TIMESTAMPS_FILE, realsense_dir.parent / TEMPORAL_ALIGNMENT_FILE]
    return [p for p in candidates if p.exists() or p.is_symlink()]


def realsense_times_s(realsense_dir: Path) -> dict[int, float] | None:
    """RealSense frame index -> time in seconds on the radar's clock (timestamps.txt plus the
    temporal_alignment.json shift); None when the capture has no timestamps.txt."""
    path = realsense_dir / TIMESTAMPS_FILE
    if not (path.exists() or path.is_symlink()):
        return None
    text = safe_io.read_bytes(path, "text").decode("utf-8", "replace")
    times = {}
    for number, line in enumerate(text.splitlines()[1:], start=2):   # line 1 is the header
        fields = line.split()
        if not fields:
            continue
        if len(fields) < 2 or not re.fullmatch(r"\d{1,9}", fields[0]) or not re.fullmatch(r"\d{1,20}", fields[1]):
            raise DatasetError(path, f"line {number} must be 'NNNNNN <timestamp_ns>', found {line[:60]!r}")
        times[int(fields[0])] = int(fields[1]) * 1e-9
    shift_s = _shift_s(realsense_dir.parent / TEMPORAL_ALIGNMENT_FILE)
    return {index: t + shift_s for index, t in times.items()}


def _shift_s(path: Path) -> float:
    """`realsense2radar.shift_seconds` of temporal_alignment.json (0 when the file or the entry is absent)."""
    if not (path.exists() or path.is_symlink()):
        return 0.0
    entry = read_json(path).get("realsense2radar")
    if entry is None:
        return 0.0
    shift = entry.get("shift_seconds") if isinstance(entry, dict) else None
    if isinstance(shift, bool) or not isinstance(shift, (int, float)) or not math.isfinite(shift) or abs(shift) > 1e6:
        raise DatasetError(path, f"realsense2radar.shift_seconds must be a finite number of seconds, found {shift!r}")
    return float(shift)


def pair_nearest(radar_time_s: float | None, depth_frames: Sequence[int], times_s: dict[int, float] | None
                 ) -> Pairing:
    """The RealSense frame of `depth_frames` (sorted indices) nearest in time to the radar frame (ties: the
    earlier); MAROON's last frame when a time is missing."""
    timed = [i for i in depth_frames if times_s is not None and i in times_s]
    if radar_time_s is None or not timed:
        return Pairing(depth_frames[-1], float("nan"), "last")
    order = sorted(timed, key=lambda i: times_s[i])
    stamps = [times_s[i] for i in order]
    k = bisect.bisect_left(stamps, radar_time_s)
    best = min((j for j in (k - 1, k) if 0 <= j < len(order)), key=lambda j: (abs(stamps[j] - radar_time_s), j))
    return Pairing(order[best], stamps[best] - radar_time_s, "nearest")
