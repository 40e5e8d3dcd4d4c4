"""Scenes built in memory, no files and no Open3D: the one place the tests, the stress suite and the benchmarks
build analytic radar frames, depth-camera frames and Captures.

`simulate`: S[r, t, f] = sum_k a_k exp(-j 2 pi f (|p_k - rx_r| + |p_k - tx_t|) / c) with the packaged QAR50
antennas and no path loss (the generator's model with path loss and lobes is `bench.synth.simulate_frame`);
`make_capture` wraps a frame (and optionally a depth frame, mesh, transforms) as a `Capture`; `CAMERA`,
`realsense2radar` and `plane_depth_frame` give a RealSense-like depth image of a plane.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from bench.maroon.antennas import load_antenna_array
from methods.domain.antennas import AntennaArray
from methods.domain.capture import CameraIntrinsics, Capture, DepthFrame, Mesh, Metadata, RadarFrame, RadarGrid
from methods.domain.radar import MAROON_FREQS_HZ
from methods.ops.correlate import C_M_PER_S

ANTENNAS = load_antenna_array()
TABLE1_FREQS_HZ = MAROON_FREQS_HZ[[0, 25, 75, 101, 114, 120, 127]]   # every frequency of Table I and 3FSK


def simulate(points_m: np.ndarray, amplitudes: np.ndarray, freqs_hz: np.ndarray,
             antennas: AntennaArray = ANTENNAS) -> np.ndarray:
    """complex64 (n_rx, n_tx, F) of point scatterers (K, 3) with complex amplitudes (K,)."""
    points_m = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    d_rx_m = np.linalg.norm(points_m[:, None] - antennas.rx_m[None], axis=2)    # (K, R)
    d_tx_m = np.linalg.norm(points_m[:, None] - antennas.tx_m[None], axis=2)    # (K, T)
    out = np.empty((len(antennas.rx_m), len(antennas.tx_m), len(freqs_hz)), dtype=np.complex64)
    for i, f in enumerate(freqs_hz):
        k = 2.0 * np.pi * f / C_M_PER_S
        out[:, :, i] = (np.exp(-1j * k * d_rx_m) * amplitudes[:, None]).T @ np.exp(-1j * k * d_tx_m)
    return out


def plate_points_m(z_m: float, half_size_m: float = 0.03, spacing_m: float = 0.001,
                   centre_xy_m: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Scatterers (K, 3) on a square plate facing the array at depth z_m (spacing < lambda/2: no grating lobes)."""
    axis = np.arange(-half_size_m, half_size_m + spacing_m / 2, spacing_m)
    x, y = np.meshgrid(axis + centre_xy_m[0], axis + centre_xy_m[1])
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z_m)])


def add_noise(signal: np.ndarray, snr_db: float, seed: int = 0) -> np.ndarray:
    """Complex white Gaussian noise at `snr_db` per sample relative to the mean signal power."""
    rng = np.random.default_rng(seed)
    sigma = np.sqrt(np.mean(np.abs(signal) ** 2) / 10 ** (snr_db / 10) / 2)
    noise = rng.normal(0, sigma, signal.shape) + 1j * rng.normal(0, sigma, signal.shape)
    return (signal + noise).astype(np.complex64)


def square_grid(half_xy_m: float, n_xy: int, z_lo_m: float = 0.25, z_hi_m: float = 0.45, n_z: int = 201
                ) -> RadarGrid:
    """Square x/y pixel grid over +-half_xy_m (row 0 = +y) with a z range for BP, metres."""
    return RadarGrid((-half_xy_m, -half_xy_m, z_lo_m), (half_xy_m, half_xy_m, z_hi_m), (n_xy, n_xy, n_z))


def make_capture(signal: np.ndarray, freqs_hz: np.ndarray, grid: RadarGrid, *, realsense: DepthFrame | None = None,
                 mesh: Mesh | None = None, transforms: dict[str, np.ndarray] | None = None, name: str = "scene",
                 distance_cm: int = 30, mask_erosion: int = 0) -> Capture:
    """An in-memory Capture holding one radar frame (and optionally a depth frame / mesh)."""
    frame = RadarFrame(index=0, signal=signal, freqs_hz=np.asarray(freqs_hz, dtype=np.float64), timestamp_s=None,
                       grid=grid, path=Path("memory"))
    metadata = Metadata(distance_m=distance_cm / 100, mask_erosion=mask_erosion, mask_bb_m={}, calibration=None,
                        labels=(), raw={})
    return Capture(root=Path("memory"), object_name=name, distance_cm=distance_cm, metadata=metadata,
                   transforms=transforms or {}, antennas=ANTENNAS, radar_frames=[0], radar=frame,
                   realsense=realsense, mesh=mesh)


# A RealSense-like camera a few cm above the array centre looking along +z (camera y down = radar -y),
# tilted 3 degrees about x. realsense2radar maps camera millimetres to radar metres.
CAMERA = CameraIntrinsics(fx=615.0, fy=615.0, cx=320.0, cy=240.0, width=640, height=480)


def realsense2radar(tilt_deg: float = 3.0, offset_m: tuple[float, float, float] = (0.01, 0.08, -0.02)
                    ) -> np.ndarray:
    """4x4 camera (mm, x right, y down) -> radar (m, y up) transform, tilted `tilt_deg` about x."""
    a = np.deg2rad(tilt_deg)
    rot_x = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    matrix = np.eye(4)
    matrix[:3, :3] = rot_x @ np.diag([1.0, -1.0, 1.0]) * 1e-3
    matrix[:3, 3] = offset_m
    return matrix


def plane_depth_frame(z0_m: float, slope_x: float, slope_y: float, cam2radar: np.ndarray,
                      depth_scale_m: float = 0.001, mask: np.ndarray | None = None) -> DepthFrame:
    """Depth image (uint16, units of depth_scale_m) seeing the radar-space plane z = z0 + sx x + sy y."""
    rot_m_per_mm, t_m = cam2radar[:3, :3], cam2radar[:3, 3]
    normal = np.array([-slope_x, -slope_y, 1.0])
    # plane in camera mm: (R^T n) . p_mm = (z0 - n.t); ray p_mm = Z (x_n, y_n, 1)
    n_cam = rot_m_per_mm.T @ normal
    rhs = z0_m - normal @ t_m
    cols, rows = np.meshgrid(np.arange(CAMERA.width), np.arange(CAMERA.height))
    rays = np.stack([(cols - CAMERA.cx) / CAMERA.fx, (rows - CAMERA.cy) / CAMERA.fy, np.ones(cols.shape)], -1)
    z_mm = rhs / (rays @ n_cam)
    depth = np.round(z_mm * 1e-3 / depth_scale_m).astype(np.uint16)
    return DepthFrame(index=0, depth_mm=depth, mask=mask, intrinsics=CAMERA, depth_scale_m=depth_scale_m,
                      path=Path("memory"))
