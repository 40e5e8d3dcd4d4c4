"""Second-order multipath: echoes that bounce twice on the scene (object parts, object and mount) before returning.

Rays from the array centre that a surface sample reflects specularly are traced (Open3D ray casting) to the next
surface they meet; where the doubly reflected ray heads back towards the array, the pair (first sample p1, second
point p2) is one bistatic scatterer:

    s[rx, tx, f] += a exp(-j k (|tx - p1| + |p1 - p2| + |p2 - rx|)) g(rx) / (|tx - p1| |p2 - rx|)   (and tx <-> rx)

the reverse path (tx -> p2 -> p1 -> rx) by reciprocity. The first bounce is summed over the samples (the same
0.9 mm samples as the direct echo, so the sum forms the stationary point for every transmitter); the second bounce
is its stationary-phase value on a surface much larger than its Fresnel zone (as the model's image source of a
plate: lambda / (2 R)), which gives the amplitude a = Gamma1 Gamma2 A1 R2 / (|p1 - p2| + R2) with R2 = |p2| (the
unfolded path's spreading), times the second surface's quasi-specular lobe g around the doubly reflected ray and
the element pattern of both legs. Physical optics with one reflection point per pair (the classical
shooting-and-bouncing-rays picture of dihedrals and concave shells: Ling, Chou and Lee, IEEE TAP 37(2) 1989);
rays traced from the array centre only, so a pair whose geometry changes across the 14 cm aperture is represented by
the centre's path (the Fermat path length is stationary, so the phase error is second order in the offset).
"""
from __future__ import annotations

import dataclasses
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import numpy as np
from threadpoolctl import threadpool_limits

from bench.synth.meshes import indexed
from bench.synth.radar.model import CHUNK_POINTS, PARTIAL_SUMS, RESEED_STEPS, exact_phasors
from bench.synth.sampling import SurfaceSamples

LOBE_CUTOFF = 1e-2      # as radar_scene.LOBE_CUTOFF
MAX_HOP_M = 0.3          # the second surface within this distance of the first (the scene's extent)
SURFACE_OFFSET_M = 1e-4  # rays start this far off the surface (no self-hit)


@dataclass(frozen=True)
class BouncePairs:
    """Bistatic scatterers of the double bounce: first (K, 3) and second (K, 3) points in m, hop |p1 - p2| (K,) m,
    amplitude (K,) (model units, without path loss), the doubly reflected direction (K, 3) and the second surface's
    lobe half-width (K,) rad."""

    first_m: np.ndarray
    second_m: np.ndarray
    hop_m: np.ndarray
    amplitude: np.ndarray
    outgoing: np.ndarray
    lobe_rad: np.ndarray


def bounce_pairs(part_tris_m: list[np.ndarray], samples: SurfaceSamples, reflection: np.ndarray,
                 lobe_rad: np.ndarray, antennas_m: np.ndarray | None = None,
                 viewpoint_m=(0.0, 0.0, 0.0)) -> BouncePairs:
    """Trace the specular reflection of the ray viewpoint -> sample for every sample facing the viewpoint; keep the
    pairs whose ray meets the front of a surface within MAX_HOP_M and leaves it towards the array (-z), and, given
    the antennas, whose lobe reaches one of them (`_audible`)."""
    import open3d as o3d

    viewpoint_m = np.asarray(viewpoint_m, dtype=np.float64)
    vertices, triangles = indexed(np.concatenate(part_tris_m))
    part_of_triangle = np.repeat(np.arange(len(part_tris_m)), [len(t) for t in part_tris_m])
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(vertices.astype(np.float32), triangles.astype(np.uint32))
    incoming = samples.points_m - viewpoint_m
    incoming /= np.linalg.norm(incoming, axis=1, keepdims=True)
    cos_in = np.einsum("ij,ij->i", incoming, samples.normals)
    reflected = incoming - 2.0 * cos_in[:, None] * samples.normals
    starts = samples.points_m + SURFACE_OFFSET_M * samples.normals
    rays = np.concatenate([starts, reflected], axis=1).astype(np.float32)
    hit = scene.cast_rays(o3d.core.Tensor(rays))
    t_m = hit["t_hit"].numpy().astype(np.float64)
    normal2 = hit["primitive_normals"].numpy().astype(np.float64)
    ok = (cos_in < 0) & np.isfinite(t_m) & (t_m < MAX_HOP_M) & (np.einsum("ij,ij->i", reflected, normal2) < 0)
    index = np.flatnonzero(ok)
    ids = hit["primitive_ids"].numpy().astype(np.int64)[index]
    first, direction, normal2, hop = samples.points_m[index], reflected[index], normal2[index], t_m[index]
    second = starts[index] + hop[:, None] * direction
    outgoing = direction - 2.0 * np.einsum("ij,ij->i", direction, normal2)[:, None] * normal2
    back = outgoing[:, 2] < 0
    part1, part2 = samples.part[index][back], part_of_triangle[ids][back]
    first, second, hop, outgoing = first[back], second[back], hop[back], outgoing[back]
    range2 = np.linalg.norm(second - viewpoint_m, axis=1)
    amplitude = reflection[part1] * reflection[part2] * samples.areas_m2[index][back] * range2 / (hop + range2)
    pairs = BouncePairs(first, second, hop, amplitude, outgoing, lobe_rad[part2])
    return _audible(pairs, antennas_m) if antennas_m is not None else pairs


def _audible(pairs: BouncePairs, antennas_m: np.ndarray) -> BouncePairs:
    """The pairs whose doubly reflected lobe reaches some antenna with a gain of at least LOBE_CUTOFF (the others add
    less than 1e-2 of their amplitude to any sample, as radar_scene skips the direct echo's sideways samples)."""
    to_antenna = antennas_m[None] - pairs.second_m[:, None, :]
    cos_lobe = np.einsum("kec,kc->ke", to_antenna, pairs.outgoing) / np.linalg.norm(to_antenna, axis=2)
    best = np.arccos(np.clip(cos_lobe.max(axis=1), -1.0, 1.0))
    keep = np.exp(-0.5 * (best / pairs.lobe_rad) ** 2) >= LOBE_CUTOFF
    return BouncePairs(*(getattr(pairs, f.name)[keep] for f in dataclasses.fields(BouncePairs)))


def _legs(points_m: np.ndarray, antennas_m: np.ndarray, element_exponent: float) -> tuple[np.ndarray, np.ndarray]:
    """Distances (K, E) m and element-pattern gains (K, E) of the legs point -> antenna."""
    to_antenna = antennas_m[None] - points_m[:, None, :]
    distance = np.linalg.norm(to_antenna, axis=2)
    gain = np.clip(-to_antenna[..., 2] / distance, 0.0, 1.0) ** element_exponent if element_exponent else 1.0
    return distance, gain * np.ones_like(distance)


def simulate_pairs(pairs: BouncePairs, tx_m: np.ndarray, rx_m: np.ndarray, freqs_hz: np.ndarray,
                   element_exponent: float = 0.0) -> np.ndarray:
    """The double-bounce echo of `pairs`, both directions, complex64 (n_rx, n_tx, F) in the direct echo's units
    (blocks of pairs on two threads with single-threaded BLAS, as radar_model.simulate_frame)."""
    tx_m, rx_m = np.asarray(tx_m, float), np.asarray(rx_m, float)
    outs = [np.zeros((len(freqs_hz), len(rx_m), len(tx_m)), dtype=np.complex64) for _ in range(PARTIAL_SUMS)]
    starts = range(0, len(pairs.hop_m), CHUNK_POINTS)

    def accumulate(k: int) -> None:
        for start in starts[k::PARTIAL_SUMS]:
            _accumulate_pairs(outs[k], pairs, slice(start, start + CHUNK_POINTS), tx_m, rx_m, freqs_hz,
                              element_exponent)

    with threadpool_limits(limits=1, user_api="blas"), ThreadPoolExecutor(PARTIAL_SUMS) as pool:
        list(pool.map(accumulate, range(PARTIAL_SUMS)))
    return np.ascontiguousarray(sum(outs[1:], outs[0]).transpose(1, 2, 0))


def _accumulate_pairs(out: np.ndarray, pairs: BouncePairs, block: slice, tx_m: np.ndarray, rx_m: np.ndarray,
                      freqs_hz: np.ndarray, element_exponent: float) -> None:
    """Add a block of pairs to out[f, rx, tx]: forward (tx -> p1 -> p2 -> rx) and reverse paths."""
    first, second, hop = pairs.first_m[block], pairs.second_m[block], pairs.hop_m[block]
    legs = {}
    for name, antennas_m in (("rx", rx_m), ("tx", tx_m)):
        dist1, element1 = _legs(first, antennas_m, element_exponent)
        dist2, element2 = _legs(second, antennas_m, element_exponent)
        cos_lobe = np.einsum("kec,kc->ke", antennas_m[None] - second[:, None, :], pairs.outgoing[block]) / dist2
        lobe = np.exp(-0.5 * (np.arccos(np.clip(cos_lobe, -1.0, 1.0)) / pairs.lobe_rad[block, None]) ** 2)
        legs[name] = ((dist1 + hop[:, None], (element1 / dist1).astype(np.complex64)),     # the hop rides on p1's leg
                      (dist2, (element2 * lobe / dist2 * pairs.amplitude[block, None]).astype(np.complex64)))
    steps_hz = np.diff(freqs_hz)
    equidistant = len(steps_hz) > 0 and np.allclose(steps_hz, steps_hz[0], rtol=1e-9, atol=1e-3)
    reseed = RESEED_STEPS if equidistant else 1
    phasors = [[None, None], [None, None]]             # [rx, tx] x [p1, p2]
    steps = [[exact_phasors(path, steps_hz[0]) if equidistant else None for path, _ in legs[name]]
             for name in ("rx", "tx")]
    for n, freq_hz in enumerate(freqs_hz):
        for a, name in enumerate(("rx", "tx")):
            for b, (path, weight) in enumerate(legs[name]):
                if n % reseed == 0:
                    phasors[a][b] = exact_phasors(path, freq_hz) * weight
                else:
                    phasors[a][b] *= steps[a][b]
        (rx1, rx2), (tx1, tx2) = phasors
        out[n] += rx2.T @ tx1 + rx1.T @ tx2
