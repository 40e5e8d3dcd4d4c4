"""QAR50 antenna layout: reading the Tx/Rx files and the one place where the x-mirror is applied.

The files (MAROON_FORMAT.md 2.3) hold 96 rows `x,y,z` in metres in the *file frame*, whose x axis points to the
left of the radar frame. Radar space is the file frame with x negated. Rows 0 and 95 are off-grid corner elements
that the reference code drops, so the data axes of a frame (`xr[rx, tx, f]`, sliced `[1:95]`) match rows 1..94.
"""
from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np

from bench.maroon import safe_io
from methods.domain.antennas import AntennaArray
from methods.domain.errors import DatasetError

N_STORED = 96          # rows in Tx.dat / Rx.dat and size of the stored frame axes
USED = slice(1, 95)    # elements used for imaging (94 per side)


def file_to_radar_space(xyz_file_m: np.ndarray) -> np.ndarray:
    """Map antenna coordinates from the Tx/Rx file frame to radar space (x mirrored). The only x-mirror."""
    xyz_radar_m = np.array(xyz_file_m, dtype=np.float64, copy=True)
    xyz_radar_m[:, 0] *= -1.0
    return xyz_radar_m


def read_antenna_file(path: str | Path) -> np.ndarray:
    """Read a QAR50 `Tx.dat`/`Rx.dat` CSV (header `x,y,z`, 96 rows, metres) in its file frame."""
    path = Path(path)
    data = safe_io.read_bytes(path, "text", roots=())      # user configuration: no dataset root applies
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError:
        raise DatasetError(path, "antenna file is not UTF-8 text") from None
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    if not lines or [h.strip().lower() for h in lines[0].split(",")] != ["x", "y", "z"]:
        raise DatasetError(path, "antenna file must start with the header line 'x,y,z'")
    try:
        xyz_m = np.array([[float(v) for v in line.split(",")] for line in lines[1:]], dtype=np.float64)
    except ValueError:
        raise DatasetError(path, "antenna file has a row that is not three comma-separated numbers") from None
    if xyz_m.shape != (N_STORED, 3):
        raise DatasetError(path, f"antenna file must have {N_STORED} rows of x,y,z, found shape {xyz_m.shape}")
    if not np.all(np.isfinite(xyz_m)) or np.max(np.abs(xyz_m)) > 1.0:
        raise DatasetError(path, "antenna coordinates must be finite and in metres (|value| <= 1 m)")
    return xyz_m


def _packaged(name: str) -> Path:
    return Path(str(resources.files("bench.maroon") / "qar50" / name))


def load_antenna_array(tx_path: str | Path | None = None, rx_path: str | Path | None = None,
                       all_elements: bool = False) -> AntennaArray:
    """Antenna positions in radar space; the packaged QAR50 layout unless paths are given.

    `all_elements=False` keeps rows 1..94 (the imaging array, matching sliced frames); `True` keeps all 96, which
    is what the synthetic generator needs to write full 96x96 frames.
    """
    tx = file_to_radar_space(read_antenna_file(tx_path or _packaged("Tx.dat")))
    rx = file_to_radar_space(read_antenna_file(rx_path or _packaged("Rx.dat")))
    if not all_elements:
        tx, rx = tx[USED], rx[USED]
    return AntennaArray(tx_m=tx, rx_m=rx)
