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
    leg_gains,
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


def _ideal_object(scene: Scene, config: SynthConfig, antennas, freqs, rng) -> np.ndarray:
    samples = visible_samples([p.tris_m for p in scene.parts], config.sample_spacing_m)
    reflectivity = np.array([p.reflectivity for p in scene.parts])
    amplitudes = surface_amplitudes(samples, reflectivity, config)
    return simulate_frame(roughen(samples, config, rng), amplitudes, antennas.tx_m, antennas.rx_m, freqs)


LOBE_CUTOFF = 1e-2   # samples whose lobe gain towards every antenna is below this reach no pair above 1e-4


def _audible(samples: SurfaceSamples, lobe_rad: np.ndarray, antennas_m: np.ndarray) -> np.ndarray:
    """Mask of the samples whose quasi-specular lobe gain towards some antenna is at least LOBE_CUTOFF: the others
    (a shell's flanks facing sideways) add at most 1e-4 of a facing sample's amplitude per pair and are skipped."""
    keep = np.empty(len(samples.areas_m2), dtype=bool)
    for start in range(0, len(keep), 4096):
        block = slice(start, start + 4096)
        gain = leg_gains(samples.points_m[block], antennas_m, samples.normals[block], lobe_rad[samples.part[block]])
        keep[block] = gain.max(axis=1) >= LOBE_CUTOFF
    return keep


def _simulate(samples: SurfaceSamples, amplitudes: np.ndarray, points_m: np.ndarray, lobe_rad: np.ndarray | None,
              config: SynthConfig, antennas, freqs) -> np.ndarray:
    if lobe_rad is None:
        return simulate_frame(points_m, amplitudes, antennas.tx_m, antennas.rx_m, freqs, None, None,
                              config.element_exponent)
    keep = _audible(samples, lobe_rad, np.concatenate([antennas.rx_m, antennas.tx_m]))
    return simulate_frame(points_m[keep], amplitudes[keep], antennas.tx_m, antennas.rx_m, freqs,
                          samples.normals[keep], lobe_rad[samples.part[keep]], config.element_exponent)


def object_frame(scene: Scene, config: SynthConfig, antennas, freqs, rng) -> np.ndarray:
    """The echo of every part of the scene (mount included), complex64 (n_rx, n_tx, F), model units."""
    realistic = (config.radar_materials or config.scattering != "cosine" or config.element_exponent
                 or config.transmission or config.multipath)
    if not realistic:
        return _ideal_object(scene, config, antennas, freqs, rng)
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
                      roughen_by_part(front, roughness_m, rng), lobe_rad, config, antennas, freqs)
    if config.multipath:          # second order: object parts and object and mount (bench.synth.radar.multipath)
        lobes = lobe_rad if lobe_rad is not None else np.full(len(materials), np.pi)
        antennas_m = np.concatenate([antennas.rx_m, antennas.tx_m])
        pairs = multipath.bounce_pairs(part_tris, front, reflection, lobes, antennas_m)
        frame += multipath.simulate_pairs(pairs, antennas.tx_m, antennas.rx_m, freqs, config.element_exponent)
    if config.transmission:
        through = np.array([m.transmission for m in materials])
        back = back_wall_samples(part_tris, [t > 0 for t in through], config.sample_spacing_m)
        if len(back.areas_m2):
            amplitudes = material_amplitudes(back, reflection * through, config)
            frame += _simulate(back, amplitudes, roughen_by_part(back, roughness_m, rng), lobe_rad, config,
                               antennas, freqs)
    return frame


def frames(scene: Scene, config: SynthConfig, rng: np.random.Generator) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Yield (raw, emptyfiltered) complex64 (96, 96, F) per frame; the scene is static, noise is per frame."""
    antennas = load_antenna_array(all_elements=True)
    freqs = frequencies_hz(config)
    obj = object_frame(scene, config, antennas, freqs, rng)
    power = float(np.mean(np.abs(obj) ** 2))
    if not config.clutter:
        clutter = np.zeros_like(obj)
    elif config.clutter_model == "points":
        clutter = clutter_frame(antennas.tx_m, antennas.rx_m, freqs, config, power, rng)
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
