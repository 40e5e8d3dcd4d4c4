"""4x4 homogeneous transforms between MAROON's frames (radar, realsense, photogrammetry, ...): MAROON's rule for
finding one, and applying one to points. bench.maroon.alignment reads them from a capture's alignment file."""
from __future__ import annotations

import numpy as np


def transform_between(transforms: dict[str, np.ndarray], src: str, dst: str) -> np.ndarray:
    """The 4x4 map from frame `src` to `dst` by MAROON's rule: direct key, else via the radar frame.

    Raises KeyError naming the missing transforms.
    """
    if src == dst:
        return np.eye(4)
    direct = transforms.get(f"{src}2{dst}")
    if direct is not None:
        return direct
    to_radar = {name: transforms.get(f"{name}2radar") for name in (src, dst)}
    if src == "radar" and to_radar[dst] is not None:
        return np.linalg.inv(to_radar[dst])
    if dst == "radar" and to_radar[src] is not None:
        return to_radar[src]
    if src != "radar" and dst != "radar" and to_radar[src] is not None and to_radar[dst] is not None:
        return np.linalg.inv(to_radar[dst]) @ to_radar[src]
    raise KeyError(f"no transform from '{src}' to '{dst}': need '{src}2{dst}' or '{src}2radar' and '{dst}2radar'")


def apply_transform(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Map (N, 3) points with a 4x4 homogeneous matrix (column-vector convention), float64."""
    points = np.asarray(points, dtype=np.float64)
    out = np.empty((len(points), 3))
    for i in range(3):  # three fused column sums: numpy's (N, 3) @ (3, 3) is ~10x slower for large N
        out[:, i] = matrix[i, 0] * points[:, 0] + matrix[i, 1] * points[:, 1] + matrix[i, 2] * points[:, 2]
        out[:, i] += matrix[i, 3]
    return out
