"""What one run writes: rows of results.csv and the per-capture depth PNG + JSON (DESIGN.md section 3)."""
from __future__ import annotations

import csv
import functools
import io
import json
import os
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from bench.harness import atomic
from bench.maroon.images import png_bytes
from methods.domain.capture import RadarGrid

if TYPE_CHECKING:
    import pandas as pd

#: what a run measures rather than computes (two runs of one cell differ in them): runtimes and their conditions
MEASURED_COLUMNS = ["runtime_ms", "runtime_runs", "cpu_ms", "call_ms", "load_1m", "others_cores", "timing"]
RESULT_COLUMNS = ["object", "distance", "frame", "method", "freq", "prior", "f_GHz", "C_g_cm", "C_s_cm", "P_cm",
                  "P_e_cm", "valid_px", "runtime_ms", "device", "timing"]


def depth_to_png_mm(depth_m: np.ndarray) -> np.ndarray:
    """Depth in metres (NaN = invalid) to uint16 millimetres, rounded, 0 = invalid, clipped to 1..65535 (a depth
    that rounds to 0 mm or below: 0)."""
    depth_mm = np.rint(depth_m * 1000.0)
    np.clip(depth_mm, 0, 65535, out=depth_mm)     # NaN stays NaN; a finite depth rounded to >= 1 mm stays >= 1
    depth_mm[~np.isfinite(depth_m)] = 0
    return depth_mm.astype(np.uint16)


PREVIEW_COLORMAP, NO_DEPTH_GREY = "viridis", "#9a9a9a"
#: matplotlib's viridis as 8-bit RGB, entry i of 256 (`colormaps["viridis"](np.arange(256), bytes=True)[:, :3]`):
#: a run does not import matplotlib for its previews (0.1-0.25 s of a sweep's process, docs/measurements/sweep.md);
#: tests/bench/harness/test_run_outputs.py compares the previews with matplotlib's own colour map
PREVIEW_RGB_HEX = (
    "44015444025544035745055845065a45085b46095c460b5e460c5f460e61470f6247116347126547146647156747166947186a48196b"
    "481a6c481c6e481d6f481e70482071482172482273482374472575472676472777472878472a79472b7a472c7b462d7c462f7c46307d"
    "46317e45327f45347f453580453681443781443982433a83433b83433c84423d84423e854240854141864142864043874044873f4587"
    "3f47883e48883e49893d4a893d4b893d4c893c4d8a3c4e8a3b508a3b518a3a528b3a538b39548b39558b38568b38578c37588c37598c"
    "365a8c365b8c355c8c355d8c345e8d345f8d33608d33618d32628d32638d31648d31658d31668d30678d30688d2f698d2f6a8d2e6b8e"
    "2e6c8e2e6d8e2d6e8e2d6f8e2c708e2c718e2c728e2b738e2b748e2a758e2a768e2a778e29788e29798e287a8e287a8e287b8e277c8e"
    "277d8e277e8e267f8e26808e26818e25828e25838d24848d24858d24868d23878d23888d23898d22898d228a8d228b8d218c8d218d8c"
    "218e8c208f8c20908c20918c1f928c1f938b1f948b1f958b1f968b1e978a1e988a1e998a1e998a1e9a891e9b891e9c891e9d881e9e88"
    "1e9f881ea0871fa1871fa2861fa38620a48520a58521a68521a78422a78423a88323a98224aa8225ab8126ac8127ad8028ae7f29af7f"
    "2ab07e2bb17d2cb17d2eb27c2fb37b30b47a32b57a33b67935b77836b87738b97639b9763bba753dbb743ebc7340bd7242be7144be70"
    "45bf6f47c06e49c16d4bc26c4dc26b4fc36951c46853c56755c66657c66559c7645bc8625ec96160c96062ca5f64cb5d67cc5c69cc5b"
    "6bcd596dce5870ce5672cf5574d05477d05279d1517cd24f7ed24e81d34c83d34b86d44988d5478bd5468dd64490d64392d74195d73f"
    "97d83e9ad83c9dd93a9fd938a2da37a5da35a7db33aadb32addc30afdc2eb2dd2cb5dd2bb7dd29bade27bdde26bfdf24c2df22c5df21"
    "c7e01fcae01ecde01dcfe11cd2e11bd4e11ad7e219dae218dce218dfe318e1e318e4e318e7e419e9e419ece41aeee51bf1e51cf3e51e"
    "f6e61ff8e621fae622fde724"
)


@functools.cache
def _preview_colours() -> np.ndarray:
    """The preview colour map as a table of 257 RGBA entries packed in uint32: its 256 colours, then the grey of
    'no depth'."""
    table = np.zeros((257, 4), np.uint8)
    table[:256, :3] = np.frombuffer(bytes.fromhex(PREVIEW_RGB_HEX), dtype=np.uint8).reshape(-1, 3)
    table[256, :3] = np.frombuffer(bytes.fromhex(NO_DEPTH_GREY[1:]), dtype=np.uint8)
    return table.view(np.uint32).reshape(-1)


def preview_rgb(scaled: np.ndarray) -> np.ndarray:
    """(H, W, 3) uint8 colours of values in [0, 1] (NaN = no depth), picked from the colour map's table as
    matplotlib's `Colormap.__call__` picks them (entry floor(x N), x = 1 the last), without its masked-array
    passes (~20 ms per 301 x 301 image on the 2-core machine); one 4-byte entry a pixel (an RGB row of the table a
    pixel took 3x as long)."""
    table = _preview_colours()
    index = np.minimum(scaled * (len(table) - 1), len(table) - 2)
    index[np.isnan(index)] = len(table) - 1
    rgba = table[index.astype(np.intp)].view(np.uint8).reshape(*scaled.shape, 4)
    return np.ascontiguousarray(rgba[..., :3])


def write_depth_preview(path: Path, depth_m: np.ndarray) -> tuple[float, float]:
    """A colour-mapped 8-bit view of a depth map for image viewers (the 16-bit PNG shows as black there):
    viridis from the 1st to the 99th percentile of the valid depths, grey where there is no depth. Returns that
    range in metres."""
    valid = depth_m[np.isfinite(depth_m)]
    low_m, high_m = (float(q) for q in np.percentile(valid, [1, 99])) if valid.size else (0.0, 1.0)
    scaled = np.clip((depth_m - low_m) / max(high_m - low_m, 1e-6), 0.0, 1.0)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic.write_bytes(path, png_bytes(preview_rgb(scaled)))
    return low_m, high_m


def write_depth(out_dir: Path, stem: str, depth_m: np.ndarray, grid: RadarGrid) -> Path:
    """`out_dir/depth/<stem>.png` (MAROON radar layout: row 0 = +y, column 0 = xmin) and `<stem>.json`, and a
    colour-mapped preview `out_dir/depth_preview/<stem>.png` (its depth range in the JSON)."""
    depth_dir = out_dir / "depth"
    depth_dir.mkdir(parents=True, exist_ok=True)
    png = depth_dir / f"{stem}.png"
    atomic.write_bytes(png, png_bytes(depth_to_png_mm(depth_m)))
    low_m, high_m = write_depth_preview(out_dir / "depth_preview" / f"{stem}.png", depth_m)
    info = {"bb_min": list(grid.bb_min_m), "bb_max": list(grid.bb_max_m), "grid_size": list(grid.size),
            "units": "uint16 millimetres, 0 = invalid, row 0 = +y, column 0 = xmin",
            "preview": {"file": f"../depth_preview/{stem}.png", "colormap": "viridis", "vmin_m": low_m,
                        "vmax_m": high_m, "no_depth": "grey"}}
    atomic.write_bytes(depth_dir / f"{stem}.json", json.dumps(info, indent=2).encode())
    return png


def write_results(path: Path, rows: list[dict]) -> pd.DataFrame:
    """Write rows atomically (temp file + rename) with the contract columns first."""
    import pandas as pd  # here: a run's own rows are written without pandas (`ResultsCsv`), ~0.1-0.2 s of import

    table = pd.DataFrame(rows)
    for column in RESULT_COLUMNS:
        if column not in table:
            table[column] = np.nan
    table = table[RESULT_COLUMNS + [c for c in table.columns if c not in RESULT_COLUMNS]]
    atomic.write_bytes(path, table.to_csv(index=False).encode())
    return table


def _field(value) -> str | None:
    """One value of a one-row table as pandas' `to_csv` writes it (the column's dtype is the value's own: a NumPy
    float32 in its own shortest digits, a Python float as float64, NaN and None empty), or None for any other kind
    of value (the caller lets pandas write the row)."""
    if value is None:
        return ""
    if isinstance(value, bool | np.bool_):
        return str(bool(value))
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        return "" if np.isnan(value) else str(value if isinstance(value, np.floating) else np.float64(value))
    if isinstance(value, str):
        return str(value)
    return None


def csv_lines(columns: list[str], row: dict, header: bool) -> str | None:
    """`pd.DataFrame([row], columns=columns).to_csv(header=header, index=False)` without pandas (tested equal on
    every kind `_field` writes), or None where a value is of another kind."""
    fields = [_field(row.get(column)) for column in columns]
    if any(field is None for field in fields):
        return None
    text = io.StringIO()
    writer = csv.writer(text, lineterminator=os.linesep)    # pandas' defaults: ',', '"' doubled, minimal quoting
    if header:
        writer.writerow(columns)
    writer.writerow(fields)
    return text.getvalue()


class ResultsCsv:
    """`results.csv` growing by one appended line per row as a run finishes captures, so a sequence of N frames
    costs O(N) (rewriting the whole table after every frame cost O(N^2)) and an interruption loses no finished row.

    The file is (re)written whole, atomically, only for the first row and when a row brings a column the header
    lacks (`write_results`: columns in its order); every other row is one appended line in the header's column
    order (missing values empty), which a killed process either made or did not, and which a failed write (full
    disk, file-size limit) cuts off again (bench.harness.atomic.append_bytes): the file always parses, and a line
    cut by a crash between two write calls is refused by the merge (bench.report.merge).
    Values are formatted as pandas formats them in `write_results` (an integer column holding empty cells is written
    '12' here, '12.0' there: the same number read back); one row is formatted without pandas (`csv_lines`), so that
    a run does not import it.
    """

    def __init__(self, path: Path):
        self.path = Path(path)
        self.rows: list[dict] = []
        self.columns: list[str] | None = None

    def add(self, row: dict) -> None:
        self.rows.append(row)
        if self.columns is None:
            columns = RESULT_COLUMNS + [c for c in row if c not in RESULT_COLUMNS]
            text = csv_lines(columns, row, header=True)
            if text is not None:             # `write_results([row])`'s bytes
                atomic.write_bytes(self.path, text.encode())
                self.columns = columns
                return
        if self.columns is None or not row.keys() <= set(self.columns):
            self.columns = list(write_results(self.path, self.rows).columns)
            return
        text = csv_lines(self.columns, row, header=False)
        if text is None:
            import pandas as pd

            text = pd.DataFrame([row], columns=self.columns).to_csv(header=False, index=False)
        atomic.append_bytes(self.path, text.encode())


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
