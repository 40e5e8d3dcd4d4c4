"""Frame sequences of a moving object: a known trajectory, both sensors' timestamps, the object's pose per frame.

`SynthConfig.motion` picks the trajectory: `static` (the default: every frame sees the same scene; radar and
RealSense frames are stamped at the same 30 Hz instants, as before), `lateral` (translation along radar x) or
`approach` (along radar z, towards the array). The object moves at `motion_speed_m_s` and is at its catalogue
position in the middle of the sequence. A moving sequence has radar frames every `radar_period_s` and RealSense
frames at 30 Hz starting REALSENSE_DELAY_S after the first radar frame, over the same span, so each radar frame
has a RealSense frame within half a RealSense period of it but not at the same instant: the prior the pairing
finds (bench.maroon.frames) saw the object up to ~17 ms earlier or later. The ground truth per radar frame is the mesh
moved to where the object was at the radar's timestamp: `photogrammetry/poses/NNNNNN.json` holds that frame's
`photogrammetry2radar` (read by bench.maroon.reader).
"""
from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

MOTIONS = {"static": None, "lateral": (1.0, 0.0, 0.0), "approach": (0.0, 0.0, -1.0)}
REALSENSE_PERIOD_NS = 33_333_333        # 30 Hz
REALSENSE_DELAY_S = 0.007               # the first RealSense frame after the first radar frame
POSES_FOLDER = "poses"                  # bench.maroon.reader.POSES_FOLDER


@dataclass(frozen=True)
class Plan:
    """Timestamps (ns) of the radar and RealSense frames and the object's translation (m, radar space) at each."""

    radar_times_ns: list[int]
    realsense_times_ns: list[int]
    radar_offsets_m: np.ndarray          # (radar frames, 3)
    realsense_offsets_m: np.ndarray      # (RealSense frames, 3)

    @property
    def moving(self) -> bool:
        return bool(np.any(self.radar_offsets_m) or np.any(self.realsense_offsets_m))


def validate(config) -> None:
    """ValueError (one line) for motion settings that cannot make a sequence."""
    if config.motion not in MOTIONS:
        raise ValueError(f"motion must be one of {', '.join(MOTIONS)}, got {config.motion!r}")
    if not 0.0 <= config.motion_speed_m_s <= 1.0:
        raise ValueError("motion_speed_m_s must be in [0, 1] m/s")
    if not 1e-3 <= config.radar_period_s <= 10.0:
        raise ValueError("radar_period_s must be in [0.001, 10] s")


def plan(config, start_ns: int, static_period_ns: int) -> Plan:
    """The frame times and object offsets of a capture with `config.frames` radar frames from `start_ns`."""
    validate(config)
    n = config.frames
    if config.motion == "static":
        times = [start_ns + i * static_period_ns for i in range(n)]
        return Plan(times, list(times), np.zeros((n, 3)), np.zeros((n, 3)))
    radar_ns = [start_ns + round(i * config.radar_period_s * 1e9) for i in range(n)]
    first = radar_ns[0] + round(REALSENSE_DELAY_S * 1e9)
    count = max(1, (radar_ns[-1] + REALSENSE_PERIOD_NS // 2 - first) // REALSENSE_PERIOD_NS + 1)
    realsense_ns = [first + j * REALSENSE_PERIOD_NS for j in range(count)]
    middle_ns = 0.5 * (radar_ns[0] + radar_ns[-1])
    velocity = config.motion_speed_m_s * np.asarray(MOTIONS[config.motion])

    def offsets(times_ns):
        return (np.asarray(times_ns, float) - middle_ns)[:, None] * 1e-9 * velocity[None, :]

    return Plan(radar_ns, realsense_ns, offsets(radar_ns), offsets(realsense_ns))


def moved(scene, offset_m: np.ndarray):
    """The scene with every part translated by `offset_m` (3,) metres."""
    if not np.any(offset_m):
        return scene
    parts = tuple(dataclasses.replace(part, tris_m=part.tris_m + np.asarray(offset_m)) for part in scene.parts)
    return dataclasses.replace(scene, parts=parts)


def translation(offset_m: np.ndarray) -> np.ndarray:
    """4x4 translation by `offset_m` (radar space, metres)."""
    matrix = np.eye(4)
    matrix[:3, 3] = offset_m
    return matrix


def write_poses(capture_dir: Path, plan_: Plan, photogrammetry2radar: np.ndarray) -> None:
    """photogrammetry/poses/NNNNNN.json (alignment.json format) per radar frame of a moving object; nothing for a
    static one."""
    if not plan_.moving:
        return
    folder = capture_dir / "photogrammetry" / POSES_FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    for i, offset in enumerate(plan_.radar_offsets_m):
        pose = translation(offset) @ photogrammetry2radar
        (folder / f"{i:06d}.json").write_text(json.dumps({"photogrammetry2radar": pose.tolist()}, indent=2))


def radar_frames(simulate, scene, config, plan_: Plan, rng: np.random.Generator):
    """Yield (raw, emptyfiltered) per radar frame through the generator's `simulate(scene, config, rng)`.

    Static: one call (the scene simulated once, noise per frame). Moving: one single-frame call per frame with the
    object where it is at that frame's time, each from the same state of `rng`, so clutter, surface roughness and
    the noise draw stay those of the static capture and only the object's position changes between frames."""
    if not plan_.moving:
        yield from simulate(scene, config, rng)
        return
    state = rng.bit_generator.state
    single = dataclasses.replace(config, frames=1)
    for offset in plan_.radar_offsets_m:
        rng.bit_generator.state = state
        yield next(iter(simulate(moved(scene, offset), single, rng)))
