"""What a run writes, made cheap without changing it (issue 13 item 5): results.csv grows by appended lines
(bench.harness.results.ResultsCsv) with the same rows as a whole rewrite, and the rows of finished frames survive an
interruption of a long sequence; the store's compressed arrays are copied into arrays.h5, so a run with the store,
its cached re-run and a run without it write the same files; the depth preview's colours are matplotlib's."""
from __future__ import annotations

import json
import subprocess
import sys

import h5py
import numpy as np
import pandas as pd
import pytest

from bench.harness.results import MEASURED_COLUMNS, ResultsCsv, write_results

FRAMES = 10


def test_appended_rows_read_back_as_the_rewritten_table(tmp_path):
    rng = np.random.default_rng()
    rows = []
    for i in range(25):
        row = {"object": "01_plate", "distance": 30, "frame": i, "method": "mm2fsk", "P_cm": rng.random(),
               "roi_px": None if i % 3 else int(rng.integers(1000)), "failure": "" if i % 4 else "no valid, pixel"}
        if i >= 7:
            row["t_search_ms"] = rng.random()       # a column appearing mid-run: the header is rewritten
        if i == 11:
            row["C_g_cm"] = float("nan")
        rows.append(row)
    appended = ResultsCsv(tmp_path / "appended.csv")
    for row in rows:
        appended.add(row)
    write_results(tmp_path / "whole.csv", rows)
    pd.testing.assert_frame_equal(pd.read_csv(tmp_path / "appended.csv"), pd.read_csv(tmp_path / "whole.csv"))


def test_one_rows_lines_are_pandas_own():
    """`csv_lines` (a run's rows without pandas) against pandas' `to_csv` of a one-row table, on fresh random values
    of every kind it writes; another kind is left to pandas (None)."""
    from bench.harness.results import csv_lines

    rng = np.random.default_rng()
    kinds = [lambda: None, lambda: float("nan"), lambda: np.float32("nan"), lambda: bool(rng.integers(2)),
             lambda: np.bool_(rng.integers(2)), lambda: int(rng.integers(-10**12, 10**12)), lambda: 2**70,
             lambda: np.int32(rng.integers(-1000, 1000)), lambda: np.int64(rng.integers(-10**15, 10**15)),
             lambda: float(rng.standard_normal() * 10.0 ** rng.integers(-20, 20)), lambda: float(rng.integers(100)),
             lambda: np.float64(rng.random()) * 10.0 ** rng.integers(-8, 18), lambda: np.float32(rng.random()),
             lambda: np.float32(rng.standard_normal() * 1e6), lambda: float("inf"), lambda: -0.0,
             lambda: "", lambda: "plain", lambda: 'a, "quoted"\nvalue', lambda: np.str_("x,y")]
    for _ in range(300):
        columns = [f"c{i}" for i in range(int(rng.integers(1, 8)))]
        row = {c: kinds[int(rng.integers(len(kinds)))]() for c in columns}
        for header in (True, False):
            assert csv_lines(columns, row, header) == pd.DataFrame([row], columns=columns).to_csv(header=header,
                                                                                                   index=False)
    assert csv_lines(["a"], {"a": [1, 2]}, True) is None


JOB_PATH = """
import sys
import numpy as np
import hydra_plugins.mm2fsk_bench.inprocess, hydra_plugins.mm2fsk_bench.slurm, hydra_plugins.mm2fsk_bench.sweeper
import bench.harness.app, bench.harness.summary, bench.report.merge, bench.harness.validate
from pathlib import Path
from bench.harness.results import ResultsCsv, write_depth
from methods.domain.capture import RadarGrid
root = Path(sys.argv[1])
rows = ResultsCsv(root / "job" / "results.csv")
(root / "job").mkdir()
for i in range(3):
    rows.add({"object": "01_plate", "distance": 30, "frame": i, "method": "mm2fsk", "P_cm": 0.1 * i, "roi_px": None})
depth = np.random.default_rng().random((9, 9))
depth[0, 0] = np.nan
write_depth(root / "job", "01_plate_30_0", depth, RadarGrid((-0.1, -0.1, 0.2), (0.1, 0.1, 0.4), (9, 9, 5)))
bench.harness.summary.colliding_jobs(root)
print(*sorted(m for m in sys.argv[2:] if m in sys.modules))
"""


def test_a_jobs_process_leaves_the_merges_modules_to_the_merge(tmp_path):
    """What a sweep's process loads (its launcher, sweeper and callbacks, the app) and what a job does besides its
    method and metrics (rows appended, depth files and previews written, the end's identity check) import neither
    pandas nor matplotlib nor SciPy's statistics: only the merge (its worker process) needs them (0.3-0.5 s of
    imports; docs/measurements/sweep.md)."""
    result = subprocess.run([sys.executable, "-c", JOB_PATH, str(tmp_path), "pandas", "matplotlib", "scipy.stats"],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == []
    assert (tmp_path / "job" / "depth_preview" / "01_plate_30_0.png").is_file()
    assert len((tmp_path / "job" / "results.csv").read_text().splitlines()) == 4


@pytest.fixture(scope="module")
def long_sequence(synth_capture):
    """A static plate seen in FRAMES radar frames (16 frequencies: cheap)."""
    return synth_capture("01_plate", 30, frames=FRAMES, frequency_points=16)


def _config(root, store):
    from hydra import compose, initialize_config_dir

    from bench.harness.app import CONFIG_DIR

    with initialize_config_dir(config_dir=str(CONFIG_DIR), version_base="1.3"):
        return compose(config_name="config", overrides=[
            "method=mm2fsk", "freq=d10", "prior=realsense", "dataset=maroon", f"dataset.root={root}",
            "dataset.frame=all", f"store.dir={store}"])


def test_rows_of_finished_frames_survive_an_interruption_and_the_rerun_completes_them(long_sequence, tmp_path,
                                                                                       monkeypatch):
    from bench.harness import app

    cfg = _config(long_sequence.parent.parent, tmp_path / "store")
    write_depth, written = app.write_depth, []

    def interrupted_at_frame_7(out_dir, stem, *args):
        if len(written) == 7:
            raise KeyboardInterrupt                   # Ctrl-C (or a killed job) while the 8th frame is written
        written.append(stem)
        return write_depth(out_dir, stem, *args)

    monkeypatch.setattr(app, "write_depth", interrupted_at_frame_7)
    with pytest.raises(KeyboardInterrupt):
        app.run(cfg, tmp_path / "run")
    kept = pd.read_csv(tmp_path / "run" / "results.csv")
    assert list(kept.frame) == list(range(7)) and kept.P_cm.notna().all()
    monkeypatch.setattr(app, "write_depth", write_depth)
    rows = app.run(cfg, tmp_path / "run")                  # the same run directory: the file starts anew
    table = pd.read_csv(tmp_path / "run" / "results.csv")
    assert list(table.frame) == list(range(FRAMES))
    assert [r["cached"] for r in rows] == [True] * 8 + [False] * (FRAMES - 8)    # frame 7 was stored, not written
    pd.testing.assert_frame_equal(table.iloc[:7].drop(columns="cached"), kept.drop(columns="cached"))
    np.testing.assert_allclose(table.P_cm, [r["P_cm"] for r in rows], rtol=1e-15)


def test_preview_colours_are_matplotlibs():
    from matplotlib import colormaps

    from bench.harness.results import NO_DEPTH_GREY, PREVIEW_COLORMAP, preview_rgb

    rng = np.random.default_rng()
    scaled = rng.random((60, 70))
    scaled[rng.random(scaled.shape) < 0.3] = np.nan
    scaled.flat[:4] = [0.0, 1.0, np.nextafter(1.0, 0.0), 0.5]
    scaled.flat[4:260] = (np.arange(256) + rng.random(256)) / 256      # every entry of the table
    reference = colormaps[PREVIEW_COLORMAP].with_extremes(bad=NO_DEPTH_GREY)(np.ma.masked_invalid(scaled),
                                                                             bytes=True)[..., :3]
    np.testing.assert_array_equal(preview_rgb(scaled), reference)


def _written(run_dir):
    """Everything a run wrote, the store's key and the cached flag left out."""
    rows = pd.read_csv(run_dir / "results.csv").drop(columns=["key", "cached"])
    with h5py.File(run_dir / "arrays.h5", "r") as h5:
        arrays = {f"{stem}/{name}": (h5[stem][name][()], h5[stem][name].dtype, h5[stem][name].compression)
                  for stem in h5 for name in h5[stem]}
        attrs = {stem: {k: np.asarray(v).tolist() for k, v in h5[stem].attrs.items() if k != "key"} for stem in h5}
    files = {p.relative_to(run_dir).as_posix(): p.read_bytes() for folder in ("depth", "depth_preview")
             for p in sorted((run_dir / folder).iterdir())}
    return rows, arrays, attrs, files


@pytest.mark.parametrize("cell", ["mm2fsk_d10", "2fsk_d05"])
def test_runs_with_and_without_the_store_write_the_same_files(synth_root, tmp_path, cell):
    from hydra import compose, initialize_config_dir

    from bench.harness import app

    def run(name, store):
        with initialize_config_dir(config_dir=str(app.CONFIG_DIR), version_base="1.3"):
            cfg = compose(config_name="config", overrides=[
                f"cell={cell}", "dataset=maroon", f"dataset.root={synth_root}", f"store.dir={store}"])
        app.run(cfg, tmp_path / name)
        return _written(tmp_path / name)

    plain = run("plain", "null")
    stored, cached = run("stored", tmp_path / "store"), run("cached", tmp_path / "store")
    for other in (stored, cached):
        pd.testing.assert_frame_equal(other[0].drop(columns=[c for c in other[0] if c.startswith("t_")]
                                                    + MEASURED_COLUMNS),
                                      plain[0].drop(columns=[c for c in plain[0] if c.startswith("t_")]
                                                    + MEASURED_COLUMNS))
        assert other[1].keys() == plain[1].keys() and other[2] == plain[2] and other[3] == plain[3]
        for name, (values, dtype, compression) in plain[1].items():
            np.testing.assert_array_equal(other[1][name][0], values)
            assert other[1][name][1:] == (dtype, compression)
    pd.testing.assert_frame_equal(cached[0], stored[0])               # the cached rows are the stored ones
    info = json.loads(plain[3]["depth/01_plate_30_000000.json"])
    assert info["grid_size"][:2] == [301, 301]


def _pillows_depth_files(depth_m):
    """The depth PNG's and the preview's pixels and the preview's range as main wrote them before (Pillow's encoder,
    the former millimetre formula, one percentile call a bound, matplotlib's colours)."""
    import io

    from matplotlib import colormaps
    from PIL import Image

    from bench.harness.results import NO_DEPTH_GREY, PREVIEW_COLORMAP

    with np.errstate(all="ignore"):
        depth_mm = np.where(np.isfinite(depth_m), np.rint(depth_m * 1000.0), 0.0)
        depth_mm = np.where(depth_mm > 0, np.clip(depth_mm, 1, 65535), 0).astype(np.uint16)
    valid = depth_m[np.isfinite(depth_m)]
    low, high = (float(np.percentile(valid, 1)), float(np.percentile(valid, 99))) if valid.size else (0.0, 1.0)
    with np.errstate(all="ignore"):
        scaled = np.clip((depth_m - low) / max(high - low, 1e-6), 0.0, 1.0)
    colours = colormaps[PREVIEW_COLORMAP].with_extremes(bad=NO_DEPTH_GREY)
    rgb = colours(np.ma.masked_invalid(scaled), bytes=True)[..., :3]
    decoded = []
    for pixels in (depth_mm, rgb):
        image = io.BytesIO()
        Image.fromarray(pixels).save(image, format="PNG", compress_level=1)
        decoded.append(np.asarray(Image.open(image)))
    return decoded[0], decoded[1], (low, high)


def test_depth_files_hold_the_pixels_and_range_pillow_wrote(tmp_path):
    """write_depth's own PNG encoder (rows unfiltered), the one-call percentiles and the 4-byte colour lookup: the
    same decoded pixels, modes and preview range as Pillow's encoding of main's former arrays, on fresh random maps
    (NaN shares 0-100 %, +-inf, negative and beyond-65.535 m depths, odd shapes)."""
    from PIL import Image

    from bench.harness.results import write_depth
    from methods.domain.capture import RadarGrid

    rng = np.random.default_rng()
    for i, (shape, nan_share) in enumerate([((301, 301), 0.9), ((301, 301), 0.97), ((17, 300), 0.0), ((1, 1), 0.0),
                                            ((40, 3), 1.0), ((64, 65), 0.5)]):
        depth_m = 0.25 + 0.05 * rng.standard_normal(shape)
        depth_m[rng.random(shape) < nan_share] = np.nan
        if depth_m.size > 10:
            depth_m.flat[rng.choice(depth_m.size, 6, replace=False)] = [np.inf, -np.inf, -0.2, 70.0, 0.0004, 0.0005]
        grid = RadarGrid((-0.15, -0.15, 0.2), (0.15, 0.15, 0.4), (shape[1], shape[0], 201))
        with np.errstate(all="ignore"):
            write_depth(tmp_path, f"c{i}", depth_m, grid)
        depth_png, preview, (low, high) = _pillows_depth_files(depth_m)
        written = Image.open(tmp_path / "depth" / f"c{i}.png")
        assert written.mode == "I;16" and np.array_equal(np.asarray(written), depth_png), i
        written = Image.open(tmp_path / "depth_preview" / f"c{i}.png")
        assert written.mode == "RGB" and np.array_equal(np.asarray(written), preview), i
        info = json.loads((tmp_path / "depth" / f"c{i}.json").read_text())["preview"]
        assert (info["vmin_m"], info["vmax_m"]) == (low, high), i


def test_png_bytes_decode_to_the_array_in_any_reader_mode():
    import io

    from PIL import Image

    from bench.maroon.images import png_bytes

    rng = np.random.default_rng()
    for shape, dtype, mode in [((301, 301), np.uint16, "I;16"), ((3, 700), np.uint16, "I;16"),
                               ((1, 1), np.uint8, "L"), ((45, 31), np.uint8, "L"), ((301, 301, 3), np.uint8, "RGB"),
                               ((2, 5, 3), np.uint8, "RGB")]:
        values = rng.integers(0, np.iinfo(dtype).max, shape, dtype, endpoint=True)
        values[: shape[0] // 2] = 0                                              # runs, as a map's empty rows
        image = Image.open(io.BytesIO(png_bytes(values)))
        image.load()                                                             # checks the CRCs and the stream
        assert image.mode == mode and np.array_equal(np.asarray(image), values), (shape, dtype)
    for bad in (np.zeros((4, 4), np.float32), np.zeros((4, 4, 4), np.uint8), np.zeros((4, 4, 3), np.uint16),
                np.zeros((0, 4), np.uint8), np.zeros(4, np.uint8)):
        with pytest.raises(ValueError):
            png_bytes(bad)
