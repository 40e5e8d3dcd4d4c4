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
from dataclasses import dataclass

import numpy as np

from bench.synth.meshes import indexed
from bench.synth.radar.leg_sum import leg_sum, row_chunks
from bench.synth.radar.model import leg_distances
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


AUDIBLE_ROWS = 8192       # pairs per chunk of `_audible` (a (rows, antennas) float64 array: 12 MB)


def _audible(pairs: BouncePairs, antennas_m: np.ndarray) -> BouncePairs:
    """The pairs whose doubly reflected lobe reaches some antenna with a gain of at least LOBE_CUTOFF (the others add
    less than 1e-2 of their amplitude to any sample, as radar_scene skips the direct echo's sideways samples).
    The cosines come from matrix products (leg_distances), in chunks: the (pairs, antennas, 3) differences cost
    ~2 s for a concave shell's pairs on two cores."""
    best_cos = np.empty(len(pairs.hop_m))
    for start in range(0, len(best_cos), AUDIBLE_ROWS):
        rows = slice(start, start + AUDIBLE_ROWS)
        second, outgoing = pairs.second_m[rows], pairs.outgoing[rows]
        cos_lobe = (antennas_m @ outgoing.T - np.einsum("kc,kc->k", second, outgoing)) / leg_distances(second,
                                                                                                        antennas_m)
        best_cos[rows] = cos_lobe.max(axis=0)
    best = np.arccos(np.clip(best_cos, -1.0, 1.0))
    keep = np.exp(-0.5 * (best / pairs.lobe_rad) ** 2) >= LOBE_CUTOFF
    return BouncePairs(*(getattr(pairs, f.name)[keep] for f in dataclasses.fields(BouncePairs)))


def _legs(points_m: np.ndarray, antennas_m: np.ndarray, element_exponent: float) -> tuple[np.ndarray, np.ndarray]:
    """Distances (E, K) m and element-pattern gains (E, K) of the legs point -> antenna (in cache-sized chunks)."""
    distance = leg_distances(points_m, antennas_m)
    if not element_exponent:
        return distance, np.ones_like(distance)
    element = np.empty_like(distance)
    for r in row_chunks(*distance.shape):
        np.subtract(points_m[:, 2], antennas_m[r, 2:], out=element[r])
        element[r] /= distance[r]
        np.clip(element[r], 0.0, 1.0, out=element[r])
        if element_exponent != 1:           # x ** 1 is x
            element[r] **= element_exponent
    return distance, element


def _first_leg(pairs: BouncePairs, rows: np.ndarray, antennas_m: np.ndarray, element_exponent: float):
    """Path (E, k) m and weight (E, k) complex64 of the leg antenna -> p1 -> p2 (the hop rides on p1's leg)."""
    distance, element = _legs(pairs.first_m[rows], antennas_m, element_exponent)
    weight = np.empty(distance.shape, dtype=np.complex64)
    for r in row_chunks(*distance.shape):
        element[r] /= distance[r]
        weight[r] = element[r]
        distance[r] += pairs.hop_m[rows]
    return distance, weight


def _second_leg(pairs: BouncePairs, rows: np.ndarray, antennas_m: np.ndarray, element_exponent: float):
    """Path (E, k) m and weight (E, k) complex64 of the leg p2 -> antenna: the second surface's lobe around the
    doubly reflected ray and the pair's amplitude."""
    second, outgoing = pairs.second_m[rows], pairs.outgoing[rows]
    distance, element = _legs(second, antennas_m, element_exponent)
    dot, along = antennas_m @ outgoing.T, np.einsum("kc,kc->k", second, outgoing)
    lobe_rad, amplitude = pairs.lobe_rad[rows], pairs.amplitude[rows]
    weight = np.empty(distance.shape, dtype=np.complex64)
    for r in row_chunks(*distance.shape):
        lobe = dot[r]                   # cos = (a.o - p.o) / |a - p|, then exp(-(theta / lobe)^2 / 2)
        lobe -= along
        lobe /= distance[r]
        np.arccos(np.clip(lobe, -1.0, 1.0, out=lobe), out=lobe)
        lobe /= lobe_rad
        lobe **= 2
        lobe *= -0.5
        np.exp(lobe, out=lobe)
        gain = element[r]               # element * lobe / distance * amplitude
        gain *= lobe
        gain /= distance[r]
        gain *= amplitude
        weight[r] = gain
    return distance, weight


def simulate_pairs(pairs: BouncePairs, tx_m: np.ndarray, rx_m: np.ndarray, freqs_hz: np.ndarray,
                   element_exponent: float = 0.0, device: str = "cpu") -> np.ndarray:
    """The double-bounce echo of `pairs`, both directions, complex64 (n_rx, n_tx, F) in the direct echo's units.

    Rows 0..K-1 are the forward paths (tx -> p1 -> p2 -> rx), rows K..2K-1 the reverse ones (bench.synth.radar.leg_sum).
    `device` as model.simulate_frame's.
    """
    tx_m, rx_m = np.asarray(tx_m, float), np.asarray(rx_m, float)
    n_pairs = len(pairs.hop_m)

    def legs(rows: np.ndarray):
        forward, reverse = rows[rows < n_pairs], rows[rows >= n_pairs] - n_pairs
        rx = [_second_leg(pairs, forward, rx_m, element_exponent), _first_leg(pairs, reverse, rx_m, element_exponent)]
        tx = [_first_leg(pairs, forward, tx_m, element_exponent), _second_leg(pairs, reverse, tx_m, element_exponent)]
        path_m, weight = (np.concatenate([np.concatenate([a[i], b[i]], axis=1) for a, b in (rx, tx)]) for i in (0, 1))
        return path_m, weight

    # a row is placed by its receive-leg and transmit-leg points, so that a block's legs span little
    positions = np.block([[pairs.second_m, pairs.first_m], [pairs.first_m, pairs.second_m]])
    if device != "cpu":         # the same legs and sums on a Warp device (bench.synth.radar.warp_sum)
        from bench.synth.radar import warp_sum

        second = warp_sum.Side(pairs.second_m, pairs.outgoing, pairs.lobe_rad, pairs.amplitude)
        first = warp_sum.Side(pairs.first_m, added_m=pairs.hop_m)
        rows = warp_sum.Rows(warp_sum.joined(second, first), warp_sum.joined(first, second), element_exponent)
        return warp_sum.frame(rows, positions, rx_m, tx_m, freqs_hz, device)
    return leg_sum(legs, positions, len(rx_m), len(tx_m), freqs_hz)
