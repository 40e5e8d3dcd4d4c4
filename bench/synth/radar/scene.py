"""The radar frames of one capture: the object's echo, static clutter, channel residuals and noise.

`frames` composes the signal model (radar_model) with the effects a `SynthConfig` switches on. With the ideal
settings it is exactly the original generator (same random draws in the same order): cosine-law point samples,
point clutter scaled to `clutter_to_signal_db`, noise at `snr_db` per sample.
"""
from __future__ import annotations

from collections.abc import Iterator

import numpy as np

from bench.maroon.antennas import load_antenna_array
from bench.synth.config import SynthConfig, frequencies_hz
from bench.synth.materials import MATERIALS
from bench.synth.radar import multipath
from bench.synth.radar.model import (
    channel_gains,
    clutter_frame,
    material_amplitudes,
    noise_frame,
    roughen,
    roughen_by_part,
    simulate_frame,
    surface_amplitudes,
    thermal_noise,
    wall_frame,
)
from bench.synth.sampling import SurfaceSamples, back_wall_samples, visible_samples
from bench.synth.scenes import Scene


def _ideal_object(scene: Scene, config: SynthConfig, antennas, freqs, rng, device: str) -> np.ndarray:
    samples = visible_samples([p.tris_m for p in scene.parts], config.sample_spacing_m)
    reflectivity = np.array([p.reflectivity for p in scene.parts])
    amplitudes = surface_amplitudes(samples, reflectivity, config)
    return simulate_frame(roughen(samples, config, rng), amplitudes, antennas.tx_m, antennas.rx_m, freqs,
                          device=device)


LOBE_CUTOFF = 1e-2   # samples whose lobe gain towards every antenna is below this reach no pair above 1e-4: skipped
                     # (a shell's flanks facing sideways)


def _simulate(samples: SurfaceSamples, amplitudes: np.ndarray, points_m: np.ndarray, lobe_rad: np.ndarray | None,
              config: SynthConfig, antennas, freqs, device: str) -> np.ndarray:
    lobes = None if lobe_rad is None else lobe_rad[samples.part]
    return simulate_frame(points_m, amplitudes, antennas.tx_m, antennas.rx_m, freqs,
                          None if lobe_rad is None else samples.normals, lobes, config.element_exponent, LOBE_CUTOFF,
                          device)


def object_frame(scene: Scene, config: SynthConfig, antennas, freqs, rng, device: str = "cpu") -> np.ndarray:
    """The echo of every part of the scene (mount included), complex64 (n_rx, n_tx, F), model units; the sums on
    `device` (bench.synth.radar.leg_sum)."""
    realistic = (config.radar_materials or config.scattering != "cosine" or config.element_exponent
                 or config.transmission or config.multipath)
    if not realistic:
        return _ideal_object(scene, config, antennas, freqs, rng, device)
    materials = [MATERIALS[p.material] for p in scene.parts]
    part_tris = [p.tris_m for p in scene.parts]
    if config.radar_materials:
        reflection = np.array([m.reflection for m in materials])
        roughness_m = np.array([m.roughness_m for m in materials])
    else:
        reflection = np.array([p.reflectivity for p in scene.parts])
        roughness_m = np.full(len(materials), config.roughness_m)
    lobe_rad = np.deg2rad([m.lobe_deg for m in materials]) if config.scattering == "specular" else None
    front = visible_samples(part_tris, config.sample_spacing_m)
    frame = _simulate(front, material_amplitudes(front, reflection, config),
                      roughen_by_part(front, roughness_m, rng), lobe_rad, config, antennas, freqs, device)
    if config.multipath:          # second order: object parts and object and mount (bench.synth.radar.multipath)
        lobes = lobe_rad if lobe_rad is not None else np.full(len(materials), np.pi)
        antennas_m = np.concatenate([antennas.rx_m, antennas.tx_m])
        pairs = multipath.bounce_pairs(part_tris, front, reflection, lobes, antennas_m)
        frame += multipath.simulate_pairs(pairs, antennas.tx_m, antennas.rx_m, freqs, config.element_exponent,
                                          device)
    if config.transmission:
        through = np.array([m.transmission for m in materials])
        back = back_wall_samples(part_tris, [t > 0 for t in through], config.sample_spacing_m)
        if len(back.areas_m2):
            amplitudes = material_amplitudes(back, reflection * through, config)
            frame += _simulate(back, amplitudes, roughen_by_part(back, roughness_m, rng), lobe_rad, config,
                               antennas, freqs, device)
    return frame


def frames(scene: Scene, config: SynthConfig, rng: np.random.Generator,
           device: str = "cpu") -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Yield (raw, emptyfiltered) complex64 (96, 96, F) per frame; the scene is static, noise is per frame. The
    radar sums run on `device` ("cpu": NumPy, the default and the demo's; "cuda", "warp-cpu": Warp)."""
    antennas = load_antenna_array(all_elements=True)
    freqs = frequencies_hz(config)
    obj = object_frame(scene, config, antennas, freqs, rng, device)
    power = float(np.mean(np.abs(obj) ** 2))
    if not config.clutter:
        clutter = np.zeros_like(obj)
    elif config.clutter_model == "points":
        clutter = clutter_frame(antennas.tx_m, antennas.rx_m, freqs, config, power, rng, device)
    else:
        clutter = wall_frame(antennas.tx_m, antennas.rx_m, freqs, config)
    gains = None
    if config.channel_amplitude_db or config.channel_phase_deg:
        gains = channel_gains(obj.shape[0], obj.shape[1], config, rng)
        obj, clutter = obj * gains, clutter * gains
    scale = np.float32(config.amplitude_scale)
    for _ in range(config.frames):
        if config.noise_model == "snr":
            noise = noise_frame(obj.shape, power, config.snr_db, rng)
        else:
            noise = thermal_noise(obj.shape, config, rng)
        if scale != 1:
            yield (obj + clutter + noise) * scale, (obj + noise) * scale
        else:
            yield obj + clutter + noise, obj + noise
