"""What one run writes: rows of results.csv and the per-capture depth PNG + JSON (DESIGN.md section 3)."""
from __future__ import annotations

import functools
import io
import json
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pandas as pd

from bench.harness import atomic
from bench.maroon.images import PNG_COMPRESS_LEVEL, write_uint16_png
from methods.domain.capture import RadarGrid

#: what a run measures rather than computes (two runs of one cell differ in them): runtimes and their conditions
MEASURED_COLUMNS = ["runtime_ms", "runtime_runs", "cpu_ms", "call_ms", "load_1m", "others_cores", "timing"]
RESULT_COLUMNS = ["object", "distance", "frame", "method", "freq", "prior", "f_GHz", "C_g_cm", "C_s_cm", "P_cm",
                  "P_e_cm", "valid_px", "runtime_ms", "device", "timing"]


def depth_to_png_mm(depth_m: np.ndarray) -> np.ndarray:
    """Depth in metres (NaN = invalid) to uint16 millimetres, rounded, 0 = invalid, clipped to 1..65535."""
    depth_mm = np.where(np.isfinite(depth_m), np.rint(depth_m * 1000.0), 0.0)
    depth_mm = np.where(depth_mm > 0, np.clip(depth_mm, 1, 65535), 0)
    return depth_mm.astype(np.uint16)


PREVIEW_COLORMAP, NO_DEPTH_GREY = "viridis", "#9a9a9a"


@functools.cache
def _preview_colours() -> tuple[np.ndarray, np.ndarray]:
    """The preview colour map as a table: (N, 3) uint8 RGB of its N entries, and the grey of 'no depth'."""
    from matplotlib import colormaps  # not pyplot: a run pays ~0.5 s for the colour map only

    cmap = colormaps[PREVIEW_COLORMAP].with_extremes(bad=NO_DEPTH_GREY)
    return cmap(np.arange(cmap.N), bytes=True)[:, :3], cmap(np.nan, bytes=True)[:3]


def preview_rgb(scaled: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 colours of values in [0, 1] (NaN = no depth), picked from the colour map's table as
    matplotlib's `Colormap.__call__` picks them (entry floor(x N), x = 1 the last), without its masked-array
    passes (~20 ms per 301 x 301 image on the 2-core machine)."""
    table, grey = _preview_colours()
    index = scaled * len(table)
    bad = np.isnan(index)
    index[bad] = 0
    index[index == len(table)] = len(table) - 1
    rgb = np.take(table, index.astype(np.intp), axis=0)
    rgb[bad] = grey
    return rgb


def write_depth_preview(path: Path, depth_m: np.ndarray) -> tuple[float, float]:
    """A colour-mapped 8-bit view of a depth map for image viewers (the 16-bit PNG shows as black there):
    viridis from the 1st to the 99th percentile of the valid depths, grey where there is no depth. Returns that
    range in metres."""
    from PIL import Image

    valid = depth_m[np.isfinite(depth_m)]
    low_m, high_m = (float(np.percentile(valid, 1)), float(np.percentile(valid, 99))) if valid.size else (0.0, 1.0)
    scaled = np.clip((depth_m - low_m) / max(high_m - low_m, 1e-6), 0.0, 1.0)
    path.parent.mkdir(parents=True, exist_ok=True)
    image = io.BytesIO()
    Image.fromarray(preview_rgb(scaled)).save(image, format="PNG", compress_level=PNG_COMPRESS_LEVEL)
    atomic.write_bytes(path, image.getvalue())
    return low_m, high_m


def write_depth(out_dir: Path, stem: str, depth_m: np.ndarray, grid: RadarGrid) -> Path:
    """`out_dir/depth/<stem>.png` (MAROON radar layout: row 0 = +y, column 0 = xmin) and `<stem>.json`, and a
    colour-mapped preview `out_dir/depth_preview/<stem>.png` (its depth range in the JSON)."""
    depth_dir = out_dir / "depth"
    depth_dir.mkdir(parents=True, exist_ok=True)
    png = depth_dir / f"{stem}.png"
    image = io.BytesIO()
    write_uint16_png(image, depth_to_png_mm(depth_m))
    atomic.write_bytes(png, image.getvalue())
    low_m, high_m = write_depth_preview(out_dir / "depth_preview" / f"{stem}.png", depth_m)
    info = {"bb_min": list(grid.bb_min_m), "bb_max": list(grid.bb_max_m), "grid_size": list(grid.size),
            "units": "uint16 millimetres, 0 = invalid, row 0 = +y, column 0 = xmin",
            "preview": {"file": f"../depth_preview/{stem}.png", "colormap": "viridis", "vmin_m": low_m,
                        "vmax_m": high_m, "no_depth": "grey"}}
    atomic.write_bytes(depth_dir / f"{stem}.json", json.dumps(info, indent=2).encode())
    return png


def write_results(path: Path, rows: list[dict]) -> pd.DataFrame:
    """Write rows atomically (temp file + rename) with the contract columns first."""
    table = pd.DataFrame(rows)
    for column in RESULT_COLUMNS:
        if column not in table:
            table[column] = np.nan
    table = table[RESULT_COLUMNS + [c for c in table.columns if c not in RESULT_COLUMNS]]
    atomic.write_bytes(path, table.to_csv(index=False).encode())
    return table


class ResultsCsv:
    """`results.csv` growing by one appended line per row as a run finishes captures, so a sequence of N frames
    costs O(N) (rewriting the whole table after every frame cost O(N^2)) and an interruption loses no finished row.

    The file is (re)written whole, atomically (`write_results`), only for the first row and when a row brings a
    column the header lacks (columns in `write_results`' order); every other row is one appended line in the
    header's column order (missing values empty), which a killed process either made or did not, and which a failed
    write (full disk, file-size limit) cuts off again (bench.harness.atomic.append_bytes): the file always parses,
    and a line cut by a crash between two write calls is refused by the merge (bench.report.merge).
    Values are formatted by pandas as in `write_results` (an integer column holding empty cells is written
    '12' here, '12.0' there: the same number read back).
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        self.rows: list[dict] = []
        self.columns: list[str] | None = None

    def add(self, row: dict) -> None:
        self.rows.append(row)
        if self.columns is None or not row.keys() <= set(self.columns):
            self.columns = list(write_results(self.path, self.rows).columns)
            return
        atomic.append_bytes(self.path, pd.DataFrame([row], columns=self.columns).to_csv(header=False, index=False)
                            .encode())


_DEFERRED: list[tuple[BackgroundWriter, Path, Callable[[], None]]] = []


def defer(writer: BackgroundWriter, out_dir: Path, then: Callable[[], None]) -> None:
    """Let `writer` (the outputs of the run in `out_dir`) finish while the process goes on (the next job of a
    basic launcher's sweep); `finish_deferred` waits for it, then calls `then` (the run's clean-up)."""
    _DEFERRED.append((writer, out_dir, then))


def finish_deferred() -> None:
    """Wait for the deferred writers; the first error is raised here, noted with the run whose outputs failed (the
    caller is the next job, or the end of the sweep)."""
    while _DEFERRED:
        writer, out_dir, then = _DEFERRED.pop(0)
        try:
            writer.close()
        except Exception as err:
            err.add_note(f"while writing the outputs of the run in {out_dir}")
            raise
        finally:
            then()


class BackgroundWriter:
    """Output files written on one background thread, in the order given, while the caller computes the next
    capture (PNG compression, HDF5 and file writes release the interpreter lock). `close` waits for them; the first
    error a write raised is raised by the next `submit` or by `close`, so a failed write still fails the run."""

    def __init__(self):
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="outputs")
        self._pending: list[Future] = []

    def submit(self, function, *args) -> None:
        self._pending = [future for future in self._pending if not (future.done() and future.result() is None)]
        self._pending.append(self._pool.submit(function, *args))

    def close(self) -> None:
        try:
            for future in self._pending:
                future.result()
        finally:
            self._pool.shutdown(wait=True)
