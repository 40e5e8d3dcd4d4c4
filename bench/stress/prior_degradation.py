"""Prior degradation: how RealSense noise, holes and extrinsic calibration error break MM-2FSK.

Scene: the catalogue's 12 x 12 cm metal plate (`01_plate`) at 0.40 m. Radar: its visible surface samples through
the generator's signal model, noise-free (this experiment isolates the prior). Prior: the generator's D435-like
depth camera (`bench.synth.camera.depth`) renders the scene with one knob of `SynthConfig` changed, the frame
is back-projected with the nominal extrinsics (`realsense2radar`) and rasterised (`methods.prior.priors`), so a pose
error (`extrinsic_error_mm` / `_deg`, random direction per repetition) becomes a prior error as on a real rig.
Knobs: `disparity_sigma_px` (stereo noise, sigma_z = z^2 sigma / (f b): 5.2 mm per pixel at 0.40 m),
`dropout_fraction` (random holes; reported as the hole fraction of the object mask), `extrinsic_error_mm`,
`extrinsic_error_deg`. Pixels: 51 x 51 over +-5 cm (2 mm), all on the plate.

Per row: prior coverage and the 95th percentile |prior - truth| (also / dd_max), and MM-2FSK's yield = the
fraction of object pixels with a depth within dd_max / 2 of the truth, and success_rate = the same among the
valid pixels. A knob value breaks a configuration when the mean yield falls below BREAK_YIELD; `break_points`
gives the first such value per knob and its cause: 'wrap' when the valid pixels fail (success_rate below
BREAK_YIELD: the prior error passed dd_max), 'dropped' when the valid ones are right but too few pixels have
a depth (no prior there, or the -14 dB filter removed them: a prior far off defocuses its pixel).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from bench.stress.scenes import antennas, config_freqs_hz, dd_max_m, pixel_grid
from bench.synth import SynthConfig, build_scene, simulate_frame
from bench.synth.camera import depth as depth_camera
from bench.synth.radar.model import surface_amplitudes
from bench.synth.sampling import visible_samples
from methods.domain.capture import CameraIntrinsics, DepthFrame, RadarGrid
from methods.mm2fsk import reconstruct_mm2fsk
from methods.prior.priors import realsense_prior_m
from metrics.groundtruth import rasterise_depth_m

OBJECT, DISTANCE_M = "01_plate", 0.40
CONFIGS = ("d05", "d4", "d10")
BREAK_YIELD = 0.9
KNOBS = {
    "disparity_sigma_px": (0.0, 0.15, 0.3, 0.6, 1.2, 2.4, 4.8),
    "dropout_fraction": (0.0, 0.1, 0.5, 0.9, 0.99, 0.999, 0.9999),
    "extrinsic_error_mm": (0.0, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0),
    "extrinsic_error_deg": (0.0, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0),
}


@dataclasses.dataclass(frozen=True)
class Scene:
    """Radar frames per configuration, the pixel grid, the true depth on it and the synthetic scene."""

    signals: dict[str, np.ndarray]
    grid: RadarGrid
    truth_m: np.ndarray
    scene: object


def build(configs=CONFIGS) -> Scene:
    """The plate scene: noise-free two-frequency frames per configuration and the true depth map."""
    scene = build_scene(OBJECT, DISTANCE_M)
    config = SynthConfig()
    samples = visible_samples([p.tris_m for p in scene.parts], config.sample_spacing_m)
    amplitudes = surface_amplitudes(samples, np.array([p.reflectivity for p in scene.parts]), config)
    array = antennas()
    signals = {c: simulate_frame(samples.points_m, amplitudes, array.tx_m, array.rx_m, config_freqs_hz(c))
               for c in configs}
    grid = pixel_grid(0.05, 51, DISTANCE_M)
    tris = scene.tris_m
    truth_m = rasterise_depth_m(tris.reshape(-1, 3), np.arange(len(tris) * 3).reshape(-1, 3), grid)
    return Scene(signals, grid, truth_m, scene)


def render_prior(scene: Scene, config: SynthConfig, rng: np.random.Generator) -> tuple[np.ndarray, float]:
    """(prior (ny, nx) m on the grid, hole fraction of the object mask) for one rendered depth frame."""
    nominal = depth_camera.nominal_pose(config)
    render = depth_camera.render(scene.scene, depth_camera.perturbed_pose(nominal, config, rng), config, rng)
    k = depth_camera.intrinsics(config)
    intrinsics = CameraIntrinsics(**{name: k[name] for name in ("fx", "fy", "cx", "cy", "width", "height")})
    mask = render.mask > 0
    depth = DepthFrame(0, render.depth_mm, mask, intrinsics, 0.001, path=None)
    holes = float(np.mean(render.depth_mm[mask] == 0)) if mask.any() else 1.0
    return realsense_prior_m(depth, nominal.realsense2radar(), scene.grid), holes


def degradation_rows(scene: Scene, knobs=KNOBS, repetitions: int = 3, seed: int = 0) -> list[dict]:
    """One row per (knob, value, repetition, configuration); see the module doc."""
    array = antennas()
    has_truth = np.isfinite(scene.truth_m)
    rows = []
    for knob, values in knobs.items():
        for value in values:
            config = dataclasses.replace(SynthConfig(), **{knob: value})
            for rep in range(repetitions):
                prior_m, holes = render_prior(scene, config, np.random.default_rng([seed, rep]))
                covered = has_truth & np.isfinite(prior_m)
                prior_err_m = np.abs(prior_m - scene.truth_m)[covered]
                p95_m = float(np.percentile(prior_err_m, 95)) if covered.any() else np.nan
                for name, signal in scene.signals.items():
                    rec = reconstruct_mm2fsk(signal, config_freqs_hz(name), array, scene.grid, prior_m)
                    dd_max = dd_max_m(name)
                    correct = rec.valid & has_truth & (np.abs(np.nan_to_num(rec.depth_m) - scene.truth_m) < dd_max / 2)
                    rows.append({"knob": knob, "value": value, "rep": rep, "config": name, "dd_max_m": dd_max,
                                 "hole_fraction": holes, "prior_coverage": float(covered.sum() / has_truth.sum()),
                                 "prior_err_p95_m": p95_m, "prior_err_p95_ratio": p95_m / dd_max,
                                 "valid_fraction": float(rec.valid[has_truth].mean()),
                                 "success_rate": float(correct.sum() / max((rec.valid & has_truth).sum(), 1)),
                                 "yield": float(correct.sum() / has_truth.sum())})
    return rows


def break_points(rows: list[dict]) -> list[dict]:
    """Per (knob, configuration): the first knob value whose mean yield < BREAK_YIELD (NaN: it never breaks in
    the sweep) and the last value before it, each with its mean prior p95 error / dd_max."""
    out = []
    for knob, config in dict.fromkeys((r["knob"], r["config"]) for r in rows):
        mine = [r for r in rows if r["knob"] == knob and r["config"] == config]
        values = sorted({r["value"] for r in mine})
        mean_yield = [np.mean([r["yield"] for r in mine if r["value"] == v]) for v in values]
        mean_p95 = [np.mean([r["prior_err_p95_ratio"] for r in mine if r["value"] == v]) for v in values]
        mean_success = [np.mean([r["success_rate"] for r in mine if r["value"] == v]) for v in values]
        broken = next((i for i, y in enumerate(mean_yield) if y < BREAK_YIELD), None)
        held = len(values) - 1 if broken is None else broken - 1
        out.append({"knob": knob, "config": config, "dd_max_m": mine[0]["dd_max_m"],
                    "last_held_value": values[held] if held >= 0 else np.nan,
                    "last_held_p95_ratio": mean_p95[held] if held >= 0 else np.nan,
                    "break_value": np.nan if broken is None else values[broken],
                    "break_yield": np.nan if broken is None else mean_yield[broken],
                    "break_p95_ratio": np.nan if broken is None else mean_p95[broken],
                    "cause": "" if broken is None else ("wrap" if mean_success[broken] < BREAK_YIELD else "dropped")})
    return out
