"""Stepped-frequency MIMO radar signal model.

    s[rx, tx, f] = sum_k a_k exp(-j 2 pi f (|p_k - tx| + |p_k - rx|) / c) / (|p_k - tx| |p_k - rx|)

Per frequency the sum is a matrix product S_f = (A_f * a)^T B_f with A_f[k, rx] = exp(-j k_f |p_k - rx|) / |p_k - rx|
and B_f[k, tx] likewise. Phases are formed in float64 and reduced modulo one cycle; for equidistant frequencies the
phasors advance by one complex64 multiply per step and are re-formed exactly every `RESEED_STEPS` frequencies.
"""
from __future__ import annotations

import numpy as np
from threadpoolctl import threadpool_limits

from bench.synth.config import C_M_PER_S, SynthConfig
from bench.synth.sampling import SurfaceSamples

RESEED_STEPS = 16       # exact phasors every 16 frequencies bound the complex64 recursion error to ~1e-6
CHUNK_POINTS = 4096     # scatterers per block (bounds memory to ~100 MB)


def _exact_phasors(path_m: np.ndarray, freq_hz: float) -> np.ndarray:
    """exp(-j 2 pi f path / c) as complex64: phase reduced modulo one cycle in float64, then float32 cos/sin."""
    cycles = path_m * (freq_hz / C_M_PER_S)
    cycles -= np.rint(cycles)
    angle = (cycles * (-2.0 * np.pi)).astype(np.float32)
    parts = np.empty(angle.shape + (2,), dtype=np.float32)
    np.cos(angle, out=parts[..., 0])
    np.sin(angle, out=parts[..., 1])
    return parts.view(np.complex64)[..., 0]


def simulate_frame(points_m: np.ndarray, amplitudes: np.ndarray, tx_m: np.ndarray, rx_m: np.ndarray,
                   freqs_hz: np.ndarray) -> np.ndarray:
    """Frame of point scatterers: complex64 (n_rx, n_tx, F) indexed [rx, tx, f].

    points_m (K, 3) radar space, amplitudes (K,) complex (reflectivity, without path loss), tx_m (n_tx, 3),
    rx_m (n_rx, 3), freqs_hz (F,). Path loss 1 / (|p - tx| |p - rx|) is applied here.
    """
    points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    amplitudes = np.asarray(amplitudes, dtype=np.complex128).reshape(-1)
    tx_m, rx_m = np.asarray(tx_m, dtype=np.float64), np.asarray(rx_m, dtype=np.float64)
    freqs_hz = np.asarray(freqs_hz, dtype=np.float64)
    out = np.zeros((len(freqs_hz), len(rx_m), len(tx_m)), dtype=np.complex64)
    # numpy's OpenBLAS workers busy-wait: on shared cores these many small (96 x K) @ (K x 96) products run
    # 2-6x faster single-threaded (measured)
    with threadpool_limits(limits=1, user_api="blas"):
        for start in range(0, len(points_m), CHUNK_POINTS):
            chunk = slice(start, start + CHUNK_POINTS)
            _accumulate(out, points_m[chunk], amplitudes[chunk], rx_m, tx_m, freqs_hz)
    return np.ascontiguousarray(out.transpose(1, 2, 0))


def _accumulate(out: np.ndarray, points_m: np.ndarray, amplitudes: np.ndarray, rx_m: np.ndarray, tx_m: np.ndarray,
                freqs_hz: np.ndarray) -> None:
    """Add the contributions of a block of scatterers to out[f, rx, tx]."""
    n_rx = len(rx_m)
    steps_hz = np.diff(freqs_hz)
    equidistant = len(steps_hz) > 0 and np.allclose(steps_hz, steps_hz[0], rtol=1e-9, atol=1e-3)
    reseed = RESEED_STEPS if equidistant else 1
    dist_m = np.linalg.norm(points_m[:, None, :] - np.concatenate([rx_m, tx_m])[None], axis=2)  # (k, n_rx + n_tx)
    weight = (1.0 / dist_m).astype(np.complex64)
    weight[:, :n_rx] *= amplitudes[:, None].astype(np.complex64)
    step = _exact_phasors(dist_m, steps_hz[0]) if equidistant else None
    for n, freq_hz in enumerate(freqs_hz):
        if n % reseed == 0:
            phasor = _exact_phasors(dist_m, freq_hz)
            phasor *= weight
        else:
            phasor *= step
        out[n] += phasor[:, :n_rx].T @ phasor[:, n_rx:]             # columns: A = rx part, B = tx part


def surface_amplitudes(samples: SurfaceSamples, reflectivity: np.ndarray, config: SynthConfig,
                       viewpoint_m=(0.0, 0.0, 0.0)) -> np.ndarray:
    """Scatterer amplitude a_k = reflectivity * area * cos(theta_inc)^q, incidence seen from the array centre."""
    to_view = np.asarray(viewpoint_m, dtype=np.float64) - samples.points_m
    cos_inc = np.einsum("ij,ij->i", samples.normals, to_view) / np.linalg.norm(to_view, axis=1)
    return reflectivity[samples.part] * samples.areas_m2 * np.clip(cos_inc, 0.0, 1.0) ** config.reflectivity_exponent


def roughen(samples: SurfaceSamples, config: SynthConfig, rng: np.random.Generator) -> np.ndarray:
    """Scatterer positions displaced along the normal by N(0, roughness_m): a per-sample phase jitter."""
    if config.roughness_m == 0:
        return samples.points_m
    return samples.points_m + samples.normals * rng.normal(0.0, config.roughness_m, len(samples.areas_m2))[:, None]


def clutter_frame(tx_m: np.ndarray, rx_m: np.ndarray, freqs_hz: np.ndarray, config: SynthConfig,
                  object_power: float, rng: np.random.Generator) -> np.ndarray:
    """Empty-room response: `clutter_points` static point scatterers behind the object (x, y within +-0.4 m,
    z between 0.8 and 1.0 x the back-wall distance), random complex amplitudes, scaled so that their mean power is
    `clutter_to_signal_db` relative to the mean object power."""
    n = config.clutter_points
    points_m = np.column_stack([rng.uniform(-0.4, 0.4, n), rng.uniform(-0.4, 0.4, n),
                                rng.uniform(0.8, 1.0, n) * config.wall_distance_m])
    clutter = simulate_frame(points_m, rng.normal(size=n) + 1j * rng.normal(size=n), tx_m, rx_m, freqs_hz)
    scale = np.sqrt(object_power * 10.0 ** (config.clutter_to_signal_db / 10.0) / np.mean(np.abs(clutter) ** 2))
    return (clutter * scale).astype(np.complex64)


def noise_frame(shape: tuple[int, ...], object_power: float, snr_db: float, rng: np.random.Generator) -> np.ndarray:
    """Circular complex Gaussian noise with power object_power / 10^(snr_db / 10) per sample, complex64."""
    sigma = np.sqrt(object_power / 10.0 ** (snr_db / 10.0) / 2.0)
    return (rng.normal(0.0, sigma, shape) + 1j * rng.normal(0.0, sigma, shape)).astype(np.complex64)
