"""Plain typed objects that the reader returns; nothing downstream of these opens files.

Conventions (DESIGN.md section 4): radar space in metres, x right, y up, z from the array to the object; images
are (rows, cols) with row 0 = +y for radar images; optical images use the OpenCV camera frame (x right, y down).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from methods.domain.antennas import AntennaArray


@dataclass(frozen=True)
class RadarGrid:
    """Voxel-centre grid of a radar frame (calibration.json `volume`): `linspace(bb_min, bb_max, size)` per axis."""

    bb_min_m: tuple[float, float, float]
    bb_max_m: tuple[float, float, float]
    size: tuple[int, int, int]  # (nx, ny, nz)

    @property
    def x_m(self) -> np.ndarray:
        return np.linspace(self.bb_min_m[0], self.bb_max_m[0], self.size[0])

    @property
    def y_m(self) -> np.ndarray:
        return np.linspace(self.bb_min_m[1], self.bb_max_m[1], self.size[1])

    @property
    def z_m(self) -> np.ndarray:
        return np.linspace(self.bb_min_m[2], self.bb_max_m[2], self.size[2])

    @property
    def image_shape(self) -> tuple[int, int]:
        """(ny, nx): radar images have row 0 = ymax, column 0 = xmin."""
        return self.size[1], self.size[0]

    def pixel_xy_m(self) -> tuple[np.ndarray, np.ndarray]:
        """Radar-space x and y of every pixel centre, each (ny, nx), row 0 = +y (MAROON_FORMAT.md 2.4)."""
        return np.meshgrid(self.x_m, self.y_m[::-1])

    def intrinsics(self) -> np.ndarray:
        """MAROON's orthographic 4x4 'intrinsics' K (MAROON_FORMAT.md 2.4), half-voxel quirk included."""
        (xmin, ymin, _), (xmax, ymax, _) = self.bb_min_m, self.bb_max_m
        nx, ny, _ = self.size
        hx, hy = (xmax - xmin) / (2 * (nx - 1)), (ymax - ymin) / (2 * (ny - 1))
        bx, bigx, by, bigy = xmin - hx, xmax + hx, ymin - hy, ymax + hy
        return np.array([
            [(nx - 1) / (bigx - bx), 0.0, 0.0, -bx * (nx - 1) / (bigx - bx)],
            [0.0, -(ny - 1) / (bigy - by), 0.0, (ny - 1) * bigy / (bigy - by)],
            [0.0, 0.0, 1000.0, 0.0],
            [0.0, 0.0, 0.0, 1.0],
        ])


@dataclass(frozen=True)
class RadarFrame:
    """One calibrated SFCW MIMO frame: `signal[rx, tx, f]` (94x94xF complex64), frequencies in Hz."""

    index: int
    signal: np.ndarray       # (n_rx, n_tx, F) complex64, already sliced to the imaging array
    freqs_hz: np.ndarray     # (F,) float64, strictly increasing
    timestamp_s: float | None
    grid: RadarGrid
    path: Path


@dataclass(frozen=True)
class CameraIntrinsics:
    """Pinhole intrinsics in pixels (librealsense convention, no +0.5 offset)."""

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int


@dataclass(frozen=True)
class DepthFrame:
    """RealSense depth aligned to the colour camera: uint16 millimetres, 0 = invalid; mask True = object."""

    index: int
    depth_mm: np.ndarray            # (H, W) uint16
    mask: np.ndarray | None         # (H, W) bool, None when the capture has no mask
    intrinsics: CameraIntrinsics    # the `rgb` intrinsics (depth is colour-aligned)
    depth_scale_m: float            # calibration.json capture.scale, metres per unit (0.001 expected)
    path: Path


@dataclass(frozen=True)
class Mesh:
    """Triangle mesh in its file frame (photogrammetry space)."""

    vertices: np.ndarray   # (V, 3) float64
    triangles: np.ndarray  # (T, 3) int64
    path: Path


@dataclass(frozen=True)
class Metadata:
    """metadata.json of a capture; `mask_bb_m` holds only the bounds present in the file (radar space)."""

    distance_m: float
    mask_erosion: int
    mask_bb_m: dict[str, float]
    calibration: str | None
    labels: tuple[str, ...]
    raw: dict


@dataclass
class Capture:
    """Everything the methods and metrics need for one `root/object/distance` capture.

    Optional parts are None when the capture lacks them; `notes` says why, in words naming the file.
    """

    root: Path
    object_name: str
    distance_cm: int
    metadata: Metadata
    transforms: dict[str, np.ndarray]        # 'src2dst' -> 4x4 float64, p_dst = M @ [p_src; 1]
    antennas: AntennaArray
    radar_frames: list[int]                  # available frame indices
    radar: RadarFrame | None = None
    realsense: DepthFrame | None = None
    mesh: Mesh | None = None
    notes: list[str] = field(default_factory=list)

    @property
    def name(self) -> str:
        return f"{self.object_name}/{self.distance_cm}"

    @property
    def path(self) -> Path:
        return self.root / self.object_name / str(self.distance_cm)
