"""Generator configuration, fixed layout constants and per-capture seeding.

Every knob of the synthetic captures lives in `SynthConfig`; its fields (plus `GENERATOR_VERSION`) form the cache
key of a capture, so any change regenerates exactly the captures it affects.
"""
from __future__ import annotations

import dataclasses
import hashlib
import json
import zlib
from dataclasses import dataclass

import numpy as np

from methods.domain.radar import C_M_PER_S, MAROON_F_HIGH_GHZ, MAROON_F_LOW_GHZ, MAROON_N_FREQS

GENERATOR_VERSION = "9"          # bump when the generator's output changes for an unchanged config
F_LOW_GHZ, F_HIGH_GHZ = MAROON_F_LOW_GHZ, MAROON_F_HIGH_GHZ
QUARTER_WAVELENGTH_M = C_M_PER_S / (F_HIGH_GHZ * 1e9) / 4.0   # 0.914 mm at 82 GHz
DISTANCE_RANGE_CM = (20, 60)   # every catalogue part inside the radar volume and MAROON's mask_bb (zmax 0.70 m)


@dataclass(frozen=True)
class SynthConfig:
    """All generator settings. Lengths in metres unless the name says otherwise; angles in degrees."""

    seed: int = 0
    frames: int = 1                          # frames per capture (radar; RealSense as many when static)
    motion: str = "static"                   # static | lateral | approach: the object's trajectory (motion.py)
    motion_speed_m_s: float = 0.05           # speed of a moving object
    radar_period_s: float = 0.1              # time between radar frames of a moving sequence (RealSense: 30 Hz)
    frequency_points: int = MAROON_N_FREQS   # linspace(72 GHz, 82 GHz, frequency_points)
    # radar scene model
    sample_spacing_m: float = 0.9e-3         # surface samples at most this far apart (<= lambda/4 at 82 GHz)
    reflectivity_exponent: float = 1.0       # amplitude ~ area * cos(theta_inc)^q
    roughness_m: float = 0.1e-3              # std of per-sample displacement along the normal (phase jitter)
    snr_db: float = 10.0                     # per-sample SNR relative to the mean object signal power of a frame
    clutter: bool = True                     # add empty-room clutter to the raw frame
    clutter_to_signal_db: float = 0.0        # mean clutter power / mean object signal power
    clutter_points: int = 6                  # static point scatterers at 0.8-1.0 x the wall distance
    # RealSense D435-like depth camera
    focal_px: float = 615.0
    principal_point_px: tuple[float, float] = (321.3, 242.6)
    camera_position_m: tuple[float, float, float] = (0.0, 0.10, 0.0)   # radar space, above the array centre
    camera_pitch_deg: float = 14.0           # tilted down: optical axis crosses y = 0 at z = 0.40 m
    depth_noise: bool = True                 # stereo noise, steep-slope/edge holes, dropouts
    disparity_sigma_px: float = 0.15         # sigma_z = z^2 * disparity_sigma / (f * baseline)
    stereo_baseline_m: float = 0.05
    max_incidence_deg: float = 78.0          # steeper surfaces return no depth
    edge_jump_m: float = 0.02                # depth discontinuity that punches holes ...
    edge_hole_px: int = 2                    # ... this many pixels wide
    dropout_fraction: float = 0.002          # random isolated invalid pixels
    extrinsic_error_mm: float = 0.0          # camera pose error used for rendering (stored pose stays nominal)
    extrinsic_error_deg: float = 0.0
    background_wall: bool = True
    wall_distance_m: float = 1.0             # wall behind the objects (depth background, radar clutter plane)
    # Effects of the realistic preset (bench/synth/README.md, "Effects"); every default below is the ideal generator.
    # depth camera (D435 active stereo)
    # translucent plastic seen behind its surface, specular-metal holes/outliers
    camera_materials: bool = False
    edge_fattening_px: int = 0               # foreground spreads this far over depth edges (mixed and flying pixels)
    flying_pixel_fraction: float = 0.3       # share of the edge band given a depth between the two sides
    slant_bias_px: float = 0.0               # disparity bias * tan(incidence): depth bias on slanted surfaces
    depth_scale_error: float = 0.0           # camera depth reads (1 + this) x the true Z (data sheet: |error| <= 2 %)
    extrinsic_tail_dof: float = 0.0          # 0: calibration error of exactly the set size; > 0: per-axis Student-t
    depth_focal_px: float = 0.0              # focal length of the stereo pair (px); 0: focal_px (colour-aligned)
    noise_angle_exponent: float = 0.0        # disparity noise grows as 1 / cos(incidence)^this
    min_depth_m: float = 0.0                 # no depth nearer than this (the stereo search range's min-Z)
    edge_ramp: bool = False                  # mixed pixels across depth edges as the window's ramp (not random)
    camera_holes: bool = False               # contiguous holes: specular highlights and dark (IR-absorbing) parts
    hole_correlation_px: float = 4.0         # size of the blobs of the random field that shapes those holes
    ir_return_floor: float = 0.05            # albedo * cos(inc) * (0.3 m / Z)^2 below this: no match (dark holes)
    ir_multipath: bool = False               # mirrored infrared inside concave objects (virtual-image depth)
    mask_errors: bool = False                # segmentation mask as a segmenter draws it (shift, bleed, erosion)
    mask_shift_px: float = 1.0               # misregistration of the mask against the depth, per capture
    mask_bleed_px: int = 1                   # mask spreads onto the background by this many pixels
    # radar
    radar_materials: bool = False            # Fresnel reflection and roughness of each part's material (materials.py)
    scattering: str = "cosine"               # "cosine": area * cos^q law; "specular": lobe around the mirror direction
    element_exponent: float = 0.0            # element pattern cos(theta)^q (amplitude, per antenna, off the +z axis)
    transmission: bool = False               # back walls of partly transmissive parts (plastic shells) scatter too
    multipath: bool = False                  # second-order echoes (object parts, object and mount)
    channel_amplitude_db: float = 0.0        # per-channel (tx and rx) calibration residual, std of the gain in dB
    channel_phase_deg: float = 0.0           # ... and of the phase in degrees
    clutter_model: str = "points"            # "points": today's point clutter; "scene": wall image + the object's mount
    wall_reflection: float = 0.25            # |Gamma| of the back wall at 77 GHz (plasterboard, ITU-R P.2040-3)
    mount: bool = False                      # a wooden post below the object (seen by both sensors, not ground truth)
    # "snr": snr_db per sample; "datasheet": thermal noise k T F B vs link budget
    noise_model: str = "snr"
    tx_power_dbm: float = 0.0                # per transmitter (datasheet model)
    element_gain_dbi: float = 6.0            # per antenna element
    noise_figure_db: float = 12.0            # receiver
    if_bandwidth_hz: float = 1.0e6           # 1 / dwell per frequency step and transmitter
    amplitude_scale: float = 1.0             # calibrated-frame scale: multiplies every radar sample (synth/README.md)
    # ground truth (photogrammetry mesh to radar registration residual)
    gt_registration_mm: float = 0.0
    gt_registration_deg: float = 0.0
    gt_smoothing_steps: int = 0              # Laplacian steps on the mesh (MAROON's reference: 30; photogrammetry.py)
    gt_mesh_subdivisions: int = 0            # midpoint subdivisions before smoothing (1: ~1.25 mm vertex spacing)

    def validate(self) -> None:
        """Raise ValueError with a one-line message for settings that cannot produce a valid capture."""
        checks = [
            (self.frames >= 1, "frames must be >= 1"),
            (2 <= self.frequency_points <= 512, "frequency_points must be in 2..512"),
            (0 < self.sample_spacing_m <= QUARTER_WAVELENGTH_M + 1e-12,
             f"sample_spacing_m must be in (0, {QUARTER_WAVELENGTH_M:.5f}] (a quarter wavelength at 82 GHz)"),
            (self.roughness_m >= 0, "roughness_m must be >= 0"),
            (np.isfinite(self.snr_db), "snr_db must be finite"),
            (self.clutter_points >= 1, "clutter_points must be >= 1"),
            (self.disparity_sigma_px >= 0 and self.stereo_baseline_m > 0, "depth noise parameters must be positive"),
            (0 < self.max_incidence_deg <= 90, "max_incidence_deg must be in (0, 90]"),
            (self.wall_distance_m >= 1.0, "wall_distance_m must be >= 1.0 m (clutter and wall behind every object)"),
            (self.scattering in ("cosine", "specular"), "scattering must be 'cosine' or 'specular'"),
            (self.clutter_model in ("points", "scene"), "clutter_model must be 'points' or 'scene'"),
            (self.noise_model in ("snr", "datasheet"), "noise_model must be 'snr' or 'datasheet'"),
            (self.edge_fattening_px >= 0 and 0 <= self.flying_pixel_fraction <= 1,
             "edge_fattening_px must be >= 0 and flying_pixel_fraction in [0, 1]"),
            (min(self.channel_amplitude_db, self.channel_phase_deg, self.element_exponent,
                 self.gt_registration_mm, self.gt_registration_deg) >= 0, "effect strengths must be >= 0"),
            (0 <= self.wall_reflection <= 1, "wall_reflection must be in [0, 1]"),
            (self.amplitude_scale > 0 and self.if_bandwidth_hz > 0, "amplitude_scale and if_bandwidth_hz must be > 0"),
            (min(self.extrinsic_tail_dof, self.depth_focal_px, self.noise_angle_exponent, self.min_depth_m,
                 self.mask_shift_px, self.mask_bleed_px, self.ir_return_floor) >= 0
             and self.hole_correlation_px > 0, "camera error settings must be >= 0"),
            (self.extrinsic_tail_dof == 0 or self.extrinsic_tail_dof > 2,
             "extrinsic_tail_dof must be 0 (fixed size) or > 2 (a Student-t with a finite variance)"),
            (self.gt_smoothing_steps >= 0 and 0 <= self.gt_mesh_subdivisions <= 2,
             "gt_smoothing_steps must be >= 0 and gt_mesh_subdivisions in 0..2"),
        ]
        for ok, message in checks:
            if not ok:
                raise ValueError(message)

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)


def capture_hash(config: SynthConfig, object_name: str, distance_cm: int, device: str = "cpu") -> str:
    """Cache key of one capture: generator version + full config + object + distance, + the device of the radar
    sums where it is not the default "cpu" (so that the keys of NumPy captures stay what they were)."""
    payload = {"version": GENERATOR_VERSION, "config": config.to_dict(), "object": object_name,
               "distance_cm": int(distance_cm)}
    if device != "cpu":
        payload["device"] = device
    return hashlib.sha256(json.dumps(payload, sort_keys=True).encode()).hexdigest()[:16]


def capture_rng(config: SynthConfig, object_name: str, distance_cm: int, stream: str) -> np.random.Generator:
    """Independent deterministic random stream per (global seed, object, distance, purpose)."""
    words = [config.seed, zlib.crc32(object_name.encode()), int(distance_cm), zlib.crc32(stream.encode())]
    return np.random.default_rng(np.random.SeedSequence(words))


def frequencies_hz(config: SynthConfig) -> np.ndarray:
    """The stepped frequencies of a frame, float64 Hz (the `fvec` written to every frame)."""
    return np.linspace(F_LOW_GHZ * 1e9, F_HIGH_GHZ * 1e9, config.frequency_points)


PLATE_REFERENCE_DISTANCE_M = 0.30
# Calibrated QAR frames are referenced to a metal-plate measurement, so a plate at the reference distance reads about
# unity; our unscaled model gives a large plate |s| = lambda / (2 R) (its image source), hence this factor (~154).
PLATE_AMPLITUDE_SCALE = 2.0 * PLATE_REFERENCE_DISTANCE_M / (C_M_PER_S / (0.5 * (F_LOW_GHZ + F_HIGH_GHZ) * 1e9))

# D435 in Intel's recommended 848 x 480 depth mode (MAROON does not state its mode): the stereo pair's focal length
# from the data sheet's 87 deg horizontal field of view, and its min-Z, which scales with the horizontal resolution
# (tuning guide), from the data sheet's ~0.28 m at 1280 x 720.
D435_DEPTH_FOCAL_PX = 424.0 / float(np.tan(np.radians(87.0 / 2)))          # 447 px
D435_MIN_Z_M = 0.28 * 848 / 1280                                          # 0.186 m

# Every effect of the realistic preset, with the settings that switch it off (back to the ideal generator's).
EFFECTS: dict[str, dict] = {
    "camera calibration residual": {"extrinsic_error_mm": 0.0, "extrinsic_error_deg": 0.0},
    "camera materials": {"camera_materials": False},
    "camera edge pixels": {"edge_fattening_px": 0},
    "camera slant bias": {"slant_bias_px": 0.0},
    "camera depth scale": {"depth_scale_error": 0.0},
    "radar materials": {"radar_materials": False},
    "specular scattering": {"scattering": "cosine"},
    "element pattern": {"element_exponent": 0.0},
    "transmission": {"transmission": False},
    "channel residual": {"channel_amplitude_db": 0.0, "channel_phase_deg": 0.0},
    "scene clutter": {"clutter_model": "points"},
    "mount": {"mount": False},
    "datasheet noise": {"noise_model": "snr"},
    "ground-truth registration": {"gt_registration_mm": 0.0, "gt_registration_deg": 0.0},
    "ground-truth smoothing": {"gt_smoothing_steps": 0, "gt_mesh_subdivisions": 0},
    "camera calibration tail": {"extrinsic_tail_dof": 0.0},
    "camera noise model": {"depth_focal_px": 0.0, "noise_angle_exponent": 0.0},
    "camera minimum range": {"min_depth_m": 0.0},
    "camera edge ramps": {"edge_ramp": False},
    "camera contiguous holes": {"camera_holes": False},
    "camera IR multipath": {"ir_multipath": False},
    "camera segmentation mask": {"mask_errors": False},
    "second-order multipath": {"multipath": False},
}
# Effects modelled but off in the realistic preset, with the settings that switch them on (none today).
OPT_IN_EFFECTS: dict[str, dict] = {}

PRESETS: dict[str, SynthConfig] = {
    "ideal": SynthConfig(),
    "realistic": SynthConfig(
        extrinsic_error_mm=3.0, extrinsic_error_deg=0.5, camera_materials=True, edge_fattening_px=2,
        slant_bias_px=0.3, depth_scale_error=0.01, radar_materials=True, scattering="specular", element_exponent=1.0,
        transmission=True, channel_amplitude_db=0.5, channel_phase_deg=5.0, clutter_model="scene",
        wall_distance_m=2.0, mount=True, noise_model="datasheet", amplitude_scale=PLATE_AMPLITUDE_SCALE,
        gt_registration_mm=1.0, gt_registration_deg=0.2, gt_smoothing_steps=30, gt_mesh_subdivisions=1,
        extrinsic_tail_dof=3.0, depth_focal_px=D435_DEPTH_FOCAL_PX, noise_angle_exponent=1.0,
        min_depth_m=D435_MIN_Z_M, edge_ramp=True, camera_holes=True, ir_multipath=True, mask_errors=True,
        multipath=True),
}
DEFAULT_PRESET = "realistic"     # of the demo, the Hydra app and the committed results


def preset(name: str, **overrides) -> SynthConfig:
    """The named preset (`ideal`, `realistic`) with `overrides` applied; ValueError names the presets."""
    if name not in PRESETS:
        raise ValueError(f"unknown synthetic preset {name!r}; known: {', '.join(PRESETS)}")
    return dataclasses.replace(PRESETS[name], **overrides)
