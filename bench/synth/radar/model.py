"""Stepped-frequency MIMO radar signal model.

    s[rx, tx, f] = sum_k a_k exp(-j 2 pi f (|p_k - tx| + |p_k - rx|) / c) / (|p_k - tx| |p_k - rx|)

Per frequency the sum is a matrix product S_f = (A_f * a)^T B_f with A_f[k, rx] = exp(-j k_f |p_k - rx|) / |p_k - rx|
and B_f[k, tx] likewise, computed on spatially compact blocks of scatterers at a few node frequencies and
interpolated to all (bench.synth.radar.leg_sum, bench.synth.radar.frequency_nodes).
"""
from __future__ import annotations

import numpy as np

from bench.synth.config import C_M_PER_S, SynthConfig
from bench.synth.radar.leg_sum import leg_sum, row_chunks
from bench.synth.sampling import SurfaceSamples


def simulate_frame(points_m: np.ndarray, amplitudes: np.ndarray, tx_m: np.ndarray, rx_m: np.ndarray,
                   freqs_hz: np.ndarray, normals: np.ndarray | None = None, lobe_rad: np.ndarray | None = None,
                   element_exponent: float = 0.0, min_lobe_gain: float = 0.0, device: str = "cpu") -> np.ndarray:
    """Frame of point scatterers: complex64 (n_rx, n_tx, F) indexed [rx, tx, f].

    points_m (K, 3) radar space, amplitudes (K,) complex (reflectivity, without path loss), tx_m (n_tx, 3),
    rx_m (n_rx, 3), freqs_hz (F,). Path loss 1 / (|p - tx| |p - rx|) is applied here, and per leg (scatterer to
    one antenna) the optional gains of `leg_gains`: the quasi-specular lobe (normals (K, 3), lobe_rad (K,)) and the
    element pattern cos(theta)^element_exponent. Scatterers whose lobe gain towards every antenna is below
    `min_lobe_gain` are skipped. `device`: "cpu" sums with NumPy (bench.synth.radar.leg_sum), "cuda" or "warp-cpu"
    forms the legs and sums on that Warp device (bench.synth.radar.warp_sum).
    """
    points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    amplitudes = np.asarray(amplitudes, dtype=np.complex128).reshape(-1)
    tx_m, rx_m = np.asarray(tx_m, dtype=np.float64), np.asarray(rx_m, dtype=np.float64)
    antennas_m = np.concatenate([rx_m, tx_m])
    n_rx = len(rx_m)
    if normals is not None and min_lobe_gain > 0:
        # lobe gain exp(-theta^2 / (2 lobe^2)) >= min_lobe_gain  <=>  cos(theta) >= cos(lobe sqrt(2 ln(1 / min)))
        limit_rad = np.asarray(lobe_rad) * np.sqrt(2.0 * np.log(1.0 / min_lobe_gain))
        cos_limit = np.where(limit_rad < np.pi, np.cos(np.minimum(limit_rad, np.pi)), -np.inf)
    if device != "cpu":         # the same legs and sums on a Warp device (bench.synth.radar.warp_sum)
        from bench.synth.radar import warp_sum

        lobes = (normals, lobe_rad) if normals is not None else (None, None)
        rows = warp_sum.Rows(warp_sum.Side(points_m, *lobes, amplitudes), warp_sum.Side(points_m, *lobes),
                             element_exponent, cos_limit if normals is not None and min_lobe_gain > 0 else None)
        return warp_sum.frame(rows, points_m, rx_m, tx_m, freqs_hz, device)

    def legs(rows: np.ndarray):
        # every pass below runs over cache-sized chunks of antennas (row_chunks); all gains in float32 (the weights
        # are complex64), the values those of whole-array passes
        points = points_m[rows]
        dist_m = leg_distances(points, antennas_m)                               # (n_rx + n_tx, k)
        chunks = row_chunks(*dist_m.shape)
        weight = np.empty(dist_m.shape, dtype=np.float32)       # path loss, times the gains of leg_gains
        for r in chunks:
            np.reciprocal(dist_m[r], dtype=np.float32, out=weight[r])
        gain = None
        if normals is not None:            # the lobe from dot products: cos = (a.n - p.n) / |a - p|
            facet = normals[rows]
            dot, along = antennas_m @ facet.T, np.einsum("kc,kc->k", points, facet)
            gain = np.empty(dist_m.shape, dtype=np.float32)
            for r in chunks:
                dot[r] -= along
                gain[r] = dot[r]
                gain[r] *= weight[r]
            if min_lobe_gain > 0:
                audible = gain.max(axis=0) >= cos_limit[rows]
                if not audible.all():
                    rows, points, dist_m = rows[audible], points[audible], dist_m[:, audible]
                    weight, gain = weight[:, audible], gain[:, audible]
                    chunks = row_chunks(*dist_m.shape)
            lobe = lobe_rad[rows].astype(np.float32)
            for r in chunks:           # exp(-(theta / lobe)^2 / 2)
                angle = gain[r]
                np.arccos(np.clip(angle, -1.0, 1.0, out=angle), out=angle)
                angle /= lobe
                angle *= angle
                angle *= np.float32(-0.5)
                np.exp(angle, out=angle)
        if element_exponent:
            if gain is None:
                gain = np.ones(dist_m.shape, dtype=np.float32)
            for r in chunks:           # cos(angle off +z)^q = ((p_z - a_z) / |p - a|)^q
                element = (points[:, 2] - antennas_m[r, 2:]).astype(np.float32)
                element *= weight[r]
                np.clip(element, 0.0, 1.0, out=element)
                if element_exponent != 1:
                    element **= np.float32(element_exponent)
                gain[r] *= element
        complex_weight = np.empty(dist_m.shape, dtype=np.complex64)
        for r in chunks:
            if gain is not None:
                weight[r] *= gain[r]
            complex_weight[r] = weight[r]
        complex_weight[:n_rx] *= amplitudes[rows].astype(np.complex64)
        return dist_m, complex_weight

    return leg_sum(legs, points_m, n_rx, len(tx_m), freqs_hz)


def leg_distances(points_m: np.ndarray, antennas_m: np.ndarray) -> np.ndarray:
    """|p_k - a_e| (E, K) m as sqrt(|a|^2 + |p|^2 - 2 a.p): a matrix product; in float64 the cancellation costs
    ~1e-16 m at these ranges (a phase error ~1e-13 rad). The rest in place, in cache-sized chunks (row_chunks)."""
    distance = antennas_m @ points_m.T
    antenna_sq, point_sq = np.einsum("ec,ec->e", antennas_m, antennas_m), np.einsum("kc,kc->k", points_m, points_m)
    for rows in row_chunks(*distance.shape):
        cross = distance[rows]
        cross *= 2.0
        np.subtract(np.add.outer(antenna_sq[rows], point_sq), cross, out=cross)
        np.maximum(cross, 0.0, out=cross)
        np.sqrt(cross, out=cross)
    return distance


def leg_gains(points_m: np.ndarray, antennas_m: np.ndarray, normals: np.ndarray | None = None,
              lobe_rad: np.ndarray | None = None, element_exponent: float = 0.0) -> np.ndarray:
    """Amplitude gain (K, E) of each scatterer-antenna leg.

    Quasi-specular lobe: exp(-theta^2 / (2 lobe^2)) with theta the angle between the facet normal and the direction
    to the antenna. The product of the two legs is exp(-theta_b^2 / lobe^2) exp(-|theta_t - theta_r|^2 / (4 lobe^2)):
    the lobe around the bisector of the transmit and receive directions (theta_b = (theta_t + theta_r) / 2, small
    angles) times a bistatic-angle factor, the separable form that keeps the pair sum a matrix product.
    Element pattern: cos(angle of the leg off the array normal +z)^element_exponent.
    """
    to_antenna = antennas_m[None] - points_m[:, None, :]                       # (K, E, 3)
    distance = np.linalg.norm(to_antenna, axis=2)
    gain = np.ones(distance.shape)
    if normals is not None:
        cos_leg = np.einsum("kec,kc->ke", to_antenna, normals) / distance
        theta = np.arccos(np.clip(cos_leg, -1.0, 1.0))
        gain *= np.exp(-0.5 * (theta / lobe_rad[:, None]) ** 2)
    if element_exponent:
        gain *= np.clip(-to_antenna[..., 2] / distance, 0.0, 1.0) ** element_exponent
    return gain


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
                  object_power: float, rng: np.random.Generator, device: str = "cpu") -> np.ndarray:
    """Empty-room response: `clutter_points` static point scatterers behind the object (x, y within +-0.4 m,
    z between 0.8 and 1.0 x the back-wall distance), random complex amplitudes, scaled so that their mean power is
    `clutter_to_signal_db` relative to the mean object power."""
    n = config.clutter_points
    points_m = np.column_stack([rng.uniform(-0.4, 0.4, n), rng.uniform(-0.4, 0.4, n),
                                rng.uniform(0.8, 1.0, n) * config.wall_distance_m])
    clutter = simulate_frame(points_m, rng.normal(size=n) + 1j * rng.normal(size=n), tx_m, rx_m, freqs_hz,
                             device=device)
    scale = np.sqrt(object_power * 10.0 ** (config.clutter_to_signal_db / 10.0) / np.mean(np.abs(clutter) ** 2))
    return (clutter * scale).astype(np.complex64)


def noise_frame(shape: tuple[int, ...], object_power: float, snr_db: float, rng: np.random.Generator) -> np.ndarray:
    """Circular complex Gaussian noise with power object_power / 10^(snr_db / 10) per sample, complex64."""
    sigma = np.sqrt(object_power / 10.0 ** (snr_db / 10.0) / 2.0)
    return (rng.normal(0.0, sigma, shape) + 1j * rng.normal(0.0, sigma, shape)).astype(np.complex64)


def material_amplitudes(samples: SurfaceSamples, reflection: np.ndarray, config: SynthConfig,
                        viewpoint_m=(0.0, 0.0, 0.0)) -> np.ndarray:
    """a_k = Fresnel reflection of the sample's part * area; with `scattering="cosine"` also the cosine law."""
    if config.scattering == "cosine":
        return surface_amplitudes(samples, reflection, config, viewpoint_m)
    return reflection[samples.part] * samples.areas_m2


def roughen_by_part(samples: SurfaceSamples, roughness_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Scatterer positions displaced along the normal by N(0, roughness of the sample's part)."""
    sigma = roughness_m[samples.part]
    return samples.points_m + samples.normals * (rng.normal(size=len(sigma)) * sigma)[:, None]


def channel_gains(n_rx: int, n_tx: int, config: SynthConfig, rng: np.random.Generator) -> np.ndarray:
    """Per-channel calibration residual as a (n_rx, n_tx, 1) complex64 factor g_rx * g_tx: log-normal gain with
    `channel_amplitude_db` std and a phase with `channel_phase_deg` std, independently per antenna."""
    def one(n):
        db = rng.normal(0.0, config.channel_amplitude_db, n)
        phase = np.deg2rad(rng.normal(0.0, config.channel_phase_deg, n))
        return 10.0 ** (db / 20.0) * np.exp(1j * phase)
    return (one(n_rx)[:, None, None] * one(n_tx)[None, :, None]).astype(np.complex64)


def wall_frame(tx_m: np.ndarray, rx_m: np.ndarray, freqs_hz: np.ndarray, config: SynthConfig) -> np.ndarray:
    """The back wall z = wall_distance_m as its image source: s = Gamma lambda / (j L) exp(-j k L), L = |tx - rx'|
    (times the element pattern of both legs)
    with rx' the receiver mirrored in the wall (the stationary-phase value of the model's surface integral; a large
    plate at R gives lambda / (2 R), which is what PLATE_AMPLITUDE_SCALE refers to). Complex64 (n_rx, n_tx, F)."""
    mirrored = np.asarray(rx_m, dtype=np.float64).copy()
    mirrored[:, 2] = 2.0 * config.wall_distance_m - mirrored[:, 2]
    offset_m = mirrored[:, None, :] - np.asarray(tx_m, dtype=np.float64)[None]
    path_m = np.linalg.norm(offset_m, axis=2)
    # both legs leave and reach the array at the angle of the image path: the element pattern applies twice
    element = (offset_m[..., 2] / path_m) ** (2.0 * config.element_exponent)
    wavelength_m = C_M_PER_S / freqs_hz
    cycles = path_m[..., None] / wavelength_m
    cycles -= np.rint(cycles)
    return (config.wall_reflection * element[..., None] * wavelength_m / (1j * path_m[..., None])
            * np.exp(-2j * np.pi * cycles)).astype(np.complex64)


def point_amplitude(rcs_m2: float, freq_hz: float) -> float:
    """Model amplitude of a point scatterer of radar cross-section rcs_m2: lambda sqrt(rcs / (4 pi)) (a flat plate of
    area A, rcs 4 pi A^2 / lambda^2, gives A: the model's unit)."""
    return C_M_PER_S / freq_hz * np.sqrt(rcs_m2 / (4.0 * np.pi))


def thermal_noise_sigma(config: SynthConfig) -> float:
    """Per-sample noise std (per real part) in model units from the datasheet link budget.

    Received power of a model sample s is P_r = P_t G_t G_r |s|^2 / (4 pi)^2 (the radar equation with the model's
    units; see point_amplitude); thermal noise k T0 F B. So sigma_s = sqrt(k T0 F B (4 pi)^2 / (P_t G_t G_r)).
    """
    k_t0_w_per_hz = 1.380649e-23 * 290.0
    noise_w = k_t0_w_per_hz * 10.0 ** (config.noise_figure_db / 10.0) * config.if_bandwidth_hz
    link = 1e-3 * 10.0 ** (config.tx_power_dbm / 10.0) * 10.0 ** (2.0 * config.element_gain_dbi / 10.0)
    return float(np.sqrt(noise_w * (4.0 * np.pi) ** 2 / link / 2.0))


def thermal_noise(shape: tuple[int, ...], config: SynthConfig, rng: np.random.Generator) -> np.ndarray:
    """Circular complex Gaussian thermal noise (model units, before amplitude_scale), complex64."""
    sigma = thermal_noise_sigma(config)
    return (rng.normal(0.0, sigma, shape) + 1j * rng.normal(0.0, sigma, shape)).astype(np.complex64)
