"""The files of one capture, in three parts: radar frames, depth camera, ground truth (and transforms).

Each part builds the scene itself and draws from its own seeded streams (config.capture_rng's purposes "radar",
"camera", "photogrammetry"), and writes files no other part writes: the parts of a capture may be built in any
order, at once, in different processes (bench.synth.workers), and give the same files. Imported where captures are
built; Open3D (ray casting) only when a part runs, so that a process that only schedules the parts
(bench.synth.generate with worker processes) does not load it.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.synth import motion, writer
from bench.synth.camera import photogrammetry
from bench.synth.config import SynthConfig, capture_rng, frequencies_hz
from bench.synth.meshes import rotation_matrix
from bench.synth.radar import scene as radar_scene
from bench.synth.scenes import build_scene

START_TIME_NS = 1_700_000_000_000_000_000
FRAME_PERIOD_NS = 33_333_333          # 30 fps RealSense; radar frames stamped at the same instants
RADAR2WORLD = [[1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 0.0, 1.2], [0.0, 0.0, 1.0, 0.0], [0.0, 0.0, 0.0, 1.0]]


def _rigid(rotation: np.ndarray, translation_m) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3], m[:3, 3] = rotation, translation_m
    return m


def _photogrammetry2radar(rng: np.random.Generator) -> np.ndarray:
    """A random proper rigid map (rotation 25-60 deg about a random axis, translation up to 0.5 m)."""
    return _rigid(rotation_matrix(rng.normal(size=3), rng.uniform(25.0, 60.0)), rng.uniform(-0.5, 0.5, 3))


def _radar_frames(scene, config: SynthConfig, rng: np.random.Generator, device: str = "cpu"):
    """Yield (raw, emptyfiltered) complex64 (96, 96, F) per frame (bench.synth.radar.scene), summed on `device`."""
    return radar_scene.frames(scene, config, rng, device)


def _registration_residual(config: SynthConfig, rng: np.random.Generator) -> np.ndarray:
    """4x4 radar-space error of the photogrammetry mesh's registration: a rotation of exactly `gt_registration_deg`
    about a random axis through the radar origin and a shift of exactly `gt_registration_mm` in a random direction
    (identity when both are 0; no random draw then, so the ideal generator's streams are unchanged)."""
    if not (config.gt_registration_mm or config.gt_registration_deg):
        return np.eye(4)
    axis, direction = rng.normal(size=3), rng.normal(size=3)
    return _rigid(rotation_matrix(axis, config.gt_registration_deg),
                  direction / np.linalg.norm(direction) * config.gt_registration_mm * 1e-3)


def _scene(object_name: str, distance_cm: int, config: SynthConfig):
    scene = build_scene(object_name, distance_cm / 100.0)
    return scene.with_mount() if config.mount else scene


def _write_radar(capture_dir: Path, object_name: str, distance_cm: int, config: SynthConfig, device: str) -> None:
    """The radar frames and the radar calibration, summed on `device`."""
    scene = _scene(object_name, distance_cm, config)
    sequence = motion.plan(config, START_TIME_NS, FRAME_PERIOD_NS)    # frame times, object offsets per frame
    radar_rng = capture_rng(config, object_name, distance_cm, "radar")
    freqs = frequencies_hz(config)
    def simulate(scene_, config_, rng_):
        return _radar_frames(scene_, config_, rng_, device)

    for i, (raw, filtered) in enumerate(motion.radar_frames(simulate, scene, config, sequence, radar_rng)):
        writer.write_radar_frame(capture_dir, i, raw, filtered, freqs, config.frames,
                                 sequence.radar_times_ns[i] // 1000)
    writer.write_radar_calibration(capture_dir, writer.radar_grid(distance_cm / 100.0), config.frames,
                                   config.frequency_points)


def _write_camera(capture_dir: Path, object_name: str, distance_cm: int, config: SynthConfig, device: str) -> None:
    """The RealSense frames (depth, mask, colour), intrinsics and timestamps."""
    from bench.synth.camera import depth as depth_camera  # Open3D: not where captures are only scheduled

    scene = _scene(object_name, distance_cm, config)
    sequence = motion.plan(config, START_TIME_NS, FRAME_PERIOD_NS)
    camera_rng = capture_rng(config, object_name, distance_cm, "camera")
    true_pose = depth_camera.perturbed_pose(depth_camera.nominal_pose(config), config, camera_rng)
    for i, offset_m in enumerate(sequence.realsense_offsets_m):
        frame = depth_camera.render(motion.moved(scene, offset_m), true_pose, config, camera_rng)
        writer.write_realsense_frame(capture_dir, i, frame.depth_mm, frame.mask, frame.rgb)
    writer.write_realsense_meta(capture_dir, depth_camera.intrinsics(config), sequence.realsense_times_ns)


def _write_truth(capture_dir: Path, object_name: str, distance_cm: int, config: SynthConfig, device: str) -> None:
    """The ground-truth mesh, the transforms, metadata.json and a moving object's poses."""
    from bench.synth.camera import depth as depth_camera

    scene = _scene(object_name, distance_cm, config)
    sequence = motion.plan(config, START_TIME_NS, FRAME_PERIOD_NS)
    photo_rng = capture_rng(config, object_name, distance_cm, "photogrammetry")
    photo2radar = _photogrammetry2radar(photo_rng)
    rs2radar = depth_camera.nominal_pose(config).realsense2radar()
    # the mesh is registered with a residual: the stored photogrammetry2radar maps it slightly off the true object
    true_photo2radar = _registration_residual(config, photo_rng) @ photo2radar
    # the mesh as MAROON's pipeline delivers it: reconstructed, then Laplacian-smoothed (photogrammetry.smoothed_mesh)
    truth_m = photogrammetry.smoothed_mesh(scene.tris_m, config.gt_smoothing_steps, config.gt_mesh_subdivisions)
    mesh_photo = (truth_m - true_photo2radar[:3, 3]) @ true_photo2radar[:3, :3]   # R^T (p - t), row vectors
    writer.write_mesh_obj(capture_dir / "photogrammetry" / "mesh_masked_smoothed.obj", mesh_photo)
    writer.write_alignment(capture_dir, {"realsense2radar": rs2radar, "photogrammetry2radar": photo2radar,
                                         "photogrammetry2realsense": np.linalg.inv(rs2radar) @ photo2radar,
                                         "radar2world": np.array(RADAR2WORLD)})
    writer.write_metadata(capture_dir, distance_cm / 100.0, scene.label)
    motion.write_poses(capture_dir, sequence, photo2radar)          # a moving object's ground truth per radar frame


CAPTURE_PARTS = {"radar": _write_radar, "camera": _write_camera, "truth": _write_truth}


def build_part(capture_dir: Path, part: str, object_name: str, distance_cm: int, config: SynthConfig,
               device: str = "cpu") -> None:
    """Write the files of one part (CAPTURE_PARTS) of a capture into the existing folder `capture_dir`."""
    CAPTURE_PARTS[part](capture_dir, object_name, int(distance_cm), config, device)


def build_capture(capture_dir: Path, object_name: str, distance_cm: int, config: SynthConfig,
                  device: str = "cpu") -> None:
    """Write every file of one capture into `capture_dir` (which must not exist yet); the radar sums on `device`
    (generate.RADAR_DEVICES)."""
    capture_dir.mkdir(parents=True)
    for part in CAPTURE_PARTS:
        build_part(capture_dir, part, object_name, distance_cm, config, device)
