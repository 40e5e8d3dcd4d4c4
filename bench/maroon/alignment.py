"""alignment.json: 4x4 rigid/scaled transforms between sensor frames and MAROON's lookup rule.

`A2B` maps coordinates in frame A into frame B, column-vector convention `p_B = M @ [p_A; 1]`
(MAROON_FORMAT.md 1.3). Other keys of the file (per-sensor calibration dicts) are ignored.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from bench.maroon.jsonio import read_json
from methods.domain.errors import DatasetError

_TRANSFORM_KEY = re.compile(r"^[a-z]+2[a-z]+$")
MAX_SCALE = 1e6          # singular values of a transform's 3x3 block within [1 / MAX_SCALE, MAX_SCALE]
MAX_TRANSLATION = 1e6    # |translation| in the destination's units


def read_alignment(path: Path) -> dict[str, np.ndarray]:
    """All `src2dst` matrices of an alignment.json as float64 4x4 arrays, validated: 16 finite numbers (not
    strings), bottom row [0, 0, 0, 1], a 3x3 block whose singular values lie in [1e-6, 1e6] (scales between metres
    and millimetres, not 1e300) and a translation within 1e6 (metres or millimetres)."""
    data = read_json(path)
    transforms = {}
    for key, value in data.items():
        if not _TRANSFORM_KEY.match(key) or isinstance(value, dict):
            continue
        flat = None
        if isinstance(value, list) and len(value) == 16:
            flat = value
        elif isinstance(value, list) and len(value) == 4 and all(isinstance(r, list) and len(r) == 4 for r in value):
            flat = [v for row in value for v in row]
        if flat is None:
            raise DatasetError(path, f"'{key}' is not a 4x4 matrix (nested list of 4 rows or 16 numbers)")
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in flat):
            raise DatasetError(path, f"'{key}' entries must be numbers")
        try:
            matrix = np.array(flat, dtype=np.float64).reshape(4, 4)
        except OverflowError:
            raise DatasetError(path, f"'{key}' has an integer too large for a float") from None
        if not np.all(np.isfinite(matrix)):
            raise DatasetError(path, f"'{key}' has non-finite entries")
        if not np.allclose(matrix[3], [0.0, 0.0, 0.0, 1.0], atol=1e-9):
            raise DatasetError(path, f"'{key}' bottom row is {matrix[3].tolist()}, expected [0, 0, 0, 1]")
        scales = np.linalg.svd(matrix[:3, :3], compute_uv=False)
        if not scales.min() > 1e-12 * scales.max():
            raise DatasetError(path, f"'{key}' is singular")
        if scales.max() > MAX_SCALE or scales.min() < 1.0 / MAX_SCALE:
            raise DatasetError(path, f"'{key}' scales lengths by {scales.min():.3g}-{scales.max():.3g}; transforms "
                                     f"between metres and millimetres scale by {1 / MAX_SCALE:g}-{MAX_SCALE:g}")
        if np.abs(matrix[:3, 3]).max() > MAX_TRANSLATION:
            raise DatasetError(path, f"'{key}' translates by {np.abs(matrix[:3, 3]).max():.3g}; at most "
                                     f"{MAX_TRANSLATION:g} (metres or millimetres) is plausible")
        transforms[key] = matrix
    return transforms
