"""bench.report.pictures and bench.report.html: point clouds and PLY files that hold the depth maps' geometry, signed
errors,
the renderer chosen at run time, and the HTML page opened in a real headless browser (Debian's chromium).

The sweep root is built here in miniature (two cells, two captures, 41 x 41 pixels), so nothing is reconstructed.
"""
from __future__ import annotations

import json
import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest
import yaml

from bench.harness.store import write_arrays
from bench.report import html, pictures

GRID = {"bb_min_m": [-0.10, -0.10, 0.2], "bb_max_m": [0.10, 0.10, 0.4], "grid_size": [41, 41, 21]}
CELLS = (("mm2fsk", "d10", "realsense"), ("2fsk", "d05", "none"))
CAPTURES = (("01_plate", 30), ("03_sphere", 30))


def _arrays(rng: np.random.Generator, offset_m: float) -> dict[str, np.ndarray]:
    """A 10 x 10 cm plate at 0.30 m; the reconstruction is offset by `offset_m` with a hole and a false positive."""
    gt = np.full((41, 41), np.nan)
    gt[10:31, 10:31] = 0.30
    depth = gt + offset_m + rng.normal(0, 1e-4, gt.shape)
    depth[15:18, 15:18] = np.nan                   # a hole: "no depth"
    depth[2, 2] = 0.35                             # depth where there is no surface
    magnitude = np.where(np.isfinite(depth), rng.uniform(0.2, 1.0, gt.shape), 0.0)
    return {"depth_m": depth, "magnitude": magnitude, "gt_depth_m": gt}


@pytest.fixture(scope="module")
def sweep_root(tmp_path_factory):
    """A finished sweep root as bench.report.merge leaves it: jobs with rows, arrays.h5 and .hydra/ configs."""
    root = tmp_path_factory.mktemp("sweep")
    rng = np.random.default_rng(7)
    for number, (method, freq, prior) in enumerate(CELLS):
        job = root / f"{number}_{method}_{freq}_{prior}"
        (job / ".hydra").mkdir(parents=True)
        rows = []
        for k, (object_name, distance) in enumerate(CAPTURES):
            stem = f"{object_name}_{distance}_000000"
            write_arrays(job / "arrays.h5", stem, _arrays(rng, 0.002 if number == 0 else -0.01), GRID)
            failed = method == "2fsk" and k == 1
            rows.append({"object": object_name, "distance": distance, "frame": 0, "method": method, "freq": freq,
                         "prior": prior, "grid": "from_capture", "metrics": "sound", "f_GHz": "81 82",
                         "C_g_cm": 0.1 + k, "C_s_cm": 0.2 + k, "P_cm": np.nan if failed else 0.3 + k,
                         "P_e_cm": np.nan if failed else 0.25 + k, "off_pct": 1.0, "off_err_cm": 2.0,
                         "off_px": 1, "failure": "P_cm: no point to compare" if failed else "",
                         "valid_px": 400, "runtime_ms": 50.0 * (number + 1), "device": "cpu", "timing": "alone",
                         "hostname": "testhost", "code_version": "0.1.0+abc123", "key": f"k{number}{k}"})
        pd.DataFrame(rows).to_csv(job / "results.csv", index=False)
        config = {"dataset": {"root": str(root / "no-dataset"), "frame": -1}, "method": {"name": method},
                  "freq": {"name": freq}, "prior": {"name": prior}, "report": {"table": "table3"}}
        (job / ".hydra" / "config.yaml").write_text(yaml.safe_dump(config))
        (job / ".hydra" / "overrides.yaml").write_text(yaml.safe_dump([f"cell={method}_{freq}"]))
    return root


def test_point_cloud_and_ply_hold_the_depth_maps_geometry(sweep_root, tmp_path):
    pytest.importorskip("open3d")
    import open3d as o3d

    cell = pictures.read_arrays(sweep_root / "0_mm2fsk_d10_realsense" / "arrays.h5", "01_plate_30_000000")
    points, index = pictures.points_m(cell.depth_m, cell.x_m, cell.y_m)
    assert len(points) == np.isfinite(cell.depth_m).sum()
    row, col = 20, 30                        # pixel centres: x from bb_min (5 mm steps), row 0 = +y
    at = np.flatnonzero((index[:, 0] == row) & (index[:, 1] == col))[0]
    np.testing.assert_allclose(points[at], [-0.10 + 0.005 * col, 0.10 - 0.005 * row, cell.depth_m[row, col]])
    ply = pictures.write_ply(tmp_path / "cloud.ply", points, np.full((len(points), 3), 0.5))
    read = o3d.io.read_point_cloud(str(ply))
    np.testing.assert_allclose(np.asarray(read.points), points, atol=1e-12)


def test_ply_files_are_open3ds_bytes_and_a_cloud_of_no_points_is_one(tmp_path):
    """write_ply writes what Open3D's writer writes (apart from the comment line naming the writer) on fresh random
    points and colours, ties at half a colour step and colours beyond 0..1 included; Open3D refuses an empty cloud,
    write_ply writes one that Open3D reads back."""
    o3d = pytest.importorskip("open3d")
    seed = int(np.random.default_rng().integers(1 << 31))
    print(f"seed {seed}")
    rng = np.random.default_rng(seed)
    points = rng.normal(0.0, 0.2, (500, 3))
    colours = np.concatenate([rng.uniform(-0.2, 1.2, (480, 3)), rng.integers(0, 255, (20, 3)) / 255 + 0.5 / 255])
    for given in (colours, None):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
        if given is not None:
            cloud.colors = o3d.utility.Vector3dVector(given)
        assert o3d.io.write_point_cloud(str(tmp_path / "open3d.ply"), cloud)
        ours = pictures.write_ply(tmp_path / "ours.ply", points, given).read_bytes()
        theirs = (tmp_path / "open3d.ply").read_bytes().replace(b"Created by Open3D", b"Created by mm2fsk-bench")
        assert ours == theirs
    empty = pictures.write_ply(tmp_path / "empty.ply", np.zeros((0, 3)), np.zeros((0, 3)))
    assert len(o3d.io.read_point_cloud(str(empty)).points) == 0 and b"element vertex 0\n" in empty.read_bytes()


def test_an_error_map_shows_each_pixel_in_its_colour_or_category():
    """map_rgb as the panels and depth-error figures use it: the error's colour, grey without depth, black for depth
    without ground truth, white outside the map (here a 3 x 2 map in a window twice its width)."""
    import matplotlib

    from bench.report import sheet

    depth = np.array([[0.313, np.nan, 0.30], [0.293, 0.30, 0.32]])   # errors off the colour map's bin edges
    truth = np.array([[0.30, 0.30, np.nan], [0.30, 0.30, 0.30]])
    cell = pictures.CaptureArrays(depth, truth, np.ones_like(depth), np.array([-0.01, 0.0, 0.01]),
                                  np.array([0.005, -0.005]))
    cmap = matplotlib.colormaps["RdBu_r"]
    rgb = pictures.map_rgb(pictures.signed_error_cm(cell), cell.extent_cm, (-3.0, 3.0), (-1.0, 1.0),
                           sheet.Box(0, 0, 6, 2), cmap, -2.0, 2.0, pictures.no_error_categories(cell))
    expected = lambda error_cm: np.array(cmap((error_cm + 2.0) / 4.0, bytes=True)[:3])   # noqa: E731
    np.testing.assert_array_equal(rgb[0, 1:4], [expected(1.3), [154, 154, 154], [0, 0, 0]])   # #9a9a9a, black
    np.testing.assert_array_equal(rgb[1, 1:4], [expected(-0.7), expected(0.0), expected(2.0)])
    assert (rgb[:, 0] == 255).all() and (rgb[:, 4:] == 255).all()                    # 1 cm pixels, map 3 cm wide


def test_a_cell_without_any_depth_still_gets_its_views_and_an_empty_ply(sweep_root, tmp_path):
    stem = "01_plate_30_000000"
    cells = [(job.name, pictures.read_arrays(job / "arrays.h5", stem)) for job in sorted(sweep_root.glob("*_*"))]
    label, cell = cells[1]
    cells[1] = (label, pictures.CaptureArrays(np.full_like(cell.depth_m, np.nan), cell.gt_depth_m,
                                              np.zeros_like(cell.magnitude), cell.x_m, cell.y_m))
    pictures.point_cloud_figure(cells, stem, tmp_path / "cloud.png", tmp_path / "ply", use="splat")
    pictures.capture_panel(cells, stem, tmp_path / "panel.png")
    assert b"element vertex 0\n" in (tmp_path / "ply" / stem / f"{pictures._file_name(label)}.ply").read_bytes()
    assert (tmp_path / "cloud.png").stat().st_size > 0 and (tmp_path / "panel.png").stat().st_size > 0


def test_signed_error_keeps_the_direction_of_a_wrap():
    behind = pictures.CaptureArrays(np.array([[0.32]]), np.array([[0.30]]), np.ones((1, 1)), np.zeros(1), np.zeros(1))
    assert pictures.signed_error_cm(behind)[0, 0] == pytest.approx(2.0)
    in_front = pictures.CaptureArrays(np.array([[0.27]]), np.array([[0.30]]), np.ones((1, 1)), np.zeros(1),
                                      np.zeros(1))
    assert pictures.signed_error_cm(in_front)[0, 0] == pytest.approx(-3.0)


def test_the_splat_perspective_is_a_pinhole_view_from_the_open3d_camera():
    seed = int(np.random.default_rng().integers(1 << 31))              # fresh inputs each run, the seed printed
    print(f"seed {seed}")
    rng = np.random.default_rng(seed)
    surface = rng.uniform([-0.05, -0.05, 0.28], [0.05, 0.05, 0.32], (200, 3))
    centre, eye = pictures._perspective_camera(surface)
    plane, depth = pictures.project(np.vstack([centre, centre + [0.01, 0, 0], centre + [0, 0.01, 0]]), centre, eye)
    np.testing.assert_allclose(plane[0], 0.0, atol=1e-12)              # the camera looks at the centre
    assert plane[1, 0] > 0 and plane[2, 1] > 0                          # x to the right, y up, as in radar space
    np.testing.assert_allclose(depth[0], np.linalg.norm(centre - eye), rtol=1e-12)
    points = rng.uniform([-0.1, -0.1, 0.2], [0.1, 0.1, 0.4], (500, 3))
    plane, depth = pictures.project(points, centre, eye)
    rays, forward = points - eye, (centre - eye) / np.linalg.norm(centre - eye)
    angle = np.arccos(np.clip(rays @ forward / np.linalg.norm(rays, axis=1), -1, 1))   # float64 reference
    np.testing.assert_allclose(np.hypot(*plane.T), np.tan(angle), rtol=1e-9, atol=1e-12)
    far_plane, far_depth = pictures.project(eye + 2 * rays, centre, eye)   # twice as far along the same rays
    np.testing.assert_allclose(far_plane, plane, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(far_depth, 2 * depth, rtol=1e-12)


def test_renderer_is_chosen_at_run_time(monkeypatch):
    monkeypatch.setattr(pictures, "_open3d_renders", lambda: False)
    monkeypatch.delenv("BENCH_RENDERER", raising=False)
    assert pictures.renderer() == "splat"
    monkeypatch.setenv("BENCH_RENDERER", "open3d")
    with pytest.raises(RuntimeError, match="offscreen renderer does not run here"):
        pictures.renderer()
    monkeypatch.setattr(pictures, "_open3d_renders", lambda: True)
    assert pictures.renderer() == "open3d"
    monkeypatch.setenv("BENCH_RENDERER", "splat")
    assert pictures.renderer() == "splat"
    monkeypatch.setenv("BENCH_RENDERER", "matplotlib")
    with pytest.raises(ValueError, match="choose one of open3d, splat"):
        pictures.renderer()


@pytest.mark.parametrize("use", ["splat", "open3d"])
def test_both_renderers_draw_the_point_clouds(sweep_root, tmp_path, use):
    if use == "open3d":
        pytest.importorskip("open3d")
        if not pictures._open3d_renders():
            pytest.skip("Open3D's offscreen renderer does not run here (needs a Vulkan driver: apt-get install "
                        "libvulkan1 mesa-vulkan-drivers); the splat case covers the fallback")
    from PIL import Image

    stem = "01_plate_30_000000"
    cells = [(job.name, pictures.read_arrays(job / "arrays.h5", stem)) for job in sorted(sweep_root.glob("*_*"))]
    png = pictures.point_cloud_figure(cells, stem, tmp_path / "cloud.png", tmp_path / "ply", use=use)
    image = np.asarray(Image.open(png).convert("RGB"))
    assert image.std() > 10                              # not blank
    assert sorted(p.name for p in (tmp_path / "ply" / stem).iterdir()) == sorted(
        ["ground_truth.ply", *(f"{name}.ply" for name, _ in cells)])


def _chromium() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def _rendered(page) -> tuple[str, str]:
    """(DOM after load, browser log) of a page opened in headless chromium."""
    proc = subprocess.run([_chromium(), "--headless=new", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr",
                           "--v=0", "--virtual-time-budget=5000", "--dump-dom", page.as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    return proc.stdout, proc.stderr


@pytest.mark.skipif(_chromium() is None, reason="needs Debian's headless browser: apt-get install chromium "
                                                "(not installed here, so the page is checked as text only)")
def test_report_renders_in_a_real_browser(sweep_root, tmp_path):
    page = html.write_report([sweep_root], tmp_path / "report.html")
    text = page.read_text()
    assert "http://" not in text and "https://" not in text          # nothing from the network
    dom, log = _rendered(page)
    for header in ("Verdict", "Table III", "Means over captures", "Spread across captures", "Per object: P (cm)",
                   "Runtime against error", "Pictures per capture", "Cells: configuration and code version"):
        assert header in dom, header
    assert "1/2" in dom and "failed: P_cm: no point to compare" in dom        # failure counts, per object
    assert "0.1.0+abc123" in dom and "cell=mm2fsk_d10" in dom               # code version, overrides
    found = re.search(r'data-images="(\d+)" data-images-loaded="(\d+)"', dom)
    assert found, "the page's load check did not run"
    total, loaded = map(int, found.groups())
    assert total == 1 + 2 * len(CAPTURES) and loaded == total              # the plot, 2 pictures per capture
    assert not re.search(r"CONSOLE.*(Uncaught|Error)", log), log[-2000:]
    broken = tmp_path / "broken.html"                                     # the check can fail: a missing image
    broken.write_text(re.sub(r'src="[^"]+"', 'src="missing.png"', text, count=1))
    total, loaded = map(int, re.search(r'data-images="(\d+)" data-images-loaded="(\d+)"',
                                       _rendered(broken)[0]).groups())
    assert loaded == total - 1


def test_report_opens_with_a_verdict_links_its_images_and_redraws_only_what_changed(sweep_root, tmp_path):
    root = shutil.copytree(sweep_root, tmp_path / "sweep")
    page = html.write_report([root], tmp_path / "report.html")
    text = page.read_text()
    assert text.index("Verdict") < text.index("Means over captures")
    assert "P: 2FSK Δ0.5, 0.30 cm over 1 of 2 captures; tied with MM-2FSK Δ10.0" in text   # the one both reconstructed
    assert "2FSK Δ0.5 (1 of 2): 03_sphere 30: P_cm: no point to compare" in text
    assert "03_sphere 30 cm (not in the means)" in text
    sources = re.findall(r'<img alt="[^"]*" src="([^"]+)"', text)
    assert len(sources) == 1 + 2 * len(CAPTURES) and "data:" not in text
    assert all((tmp_path / source).is_file() for source in sources)          # relative to the page
    assert page.stat().st_size < 200_000
    pictures_drawn = {p: p.stat().st_mtime_ns for p in (root / "pictures").rglob("*.png")}
    plot = root / "runtime_vs_error.png"
    plot_drawn = plot.stat().st_mtime_ns
    html.write_report([root], tmp_path / "report.html")
    assert {p: p.stat().st_mtime_ns for p in pictures_drawn} == pictures_drawn   # unchanged inputs: none redrawn
    assert plot.stat().st_mtime_ns == plot_drawn
    rows = pd.read_csv(root / "results.csv")                              # merged by the first report
    rows.loc[(rows.method == "mm2fsk") & (rows.object == "01_plate"), "P_cm"] = 0.31   # the plot changes, not a picture
    rows.to_csv(root / "results.csv", index=False)
    html.write_report([root], tmp_path / "report.html")
    assert {p: p.stat().st_mtime_ns for p in pictures_drawn} == pictures_drawn
    assert plot.stat().st_mtime_ns != plot_drawn
    assert "P: 2FSK Δ0.5, 0.30 cm over 1 of 2 captures; better than the runner-up MM-2FSK Δ10.0 (0.31 cm)" in \
        (tmp_path / "report.html").read_text()
    write_arrays(root / "0_mm2fsk_d10_realsense" / "arrays.h5", "03_sphere_30_000000",   # one capture's arrays change
                 _arrays(np.random.default_rng(8), 0.004), GRID)
    html.write_report([root], tmp_path / "report.html")
    redrawn = {p for p in pictures_drawn if p.stat().st_mtime_ns != pictures_drawn[p]}
    assert {p.name for p in redrawn} == {"03_sphere_30_000000.png"} and len(redrawn) == 2   # its two figures only


def test_report_cli_mistakes_are_one_line(tmp_path):
    import sys

    proc = subprocess.run([sys.executable, "-m", "bench.report", str(tmp_path)], capture_output=True, text=True)
    assert proc.returncode == 2
    assert proc.stderr.strip() == f"error: {tmp_path}: not a sweep root: no results.csv and no <job>/results.csv"


def test_depth_preview_beside_the_16_bit_data_is_viewable(tmp_path):
    from PIL import Image

    from bench.harness.results import write_depth
    from methods.domain.capture import RadarGrid

    depth = np.tile(np.linspace(0.25, 0.35, 50), (40, 1))         # depth grows to the right
    depth[:5] = np.nan
    write_depth(tmp_path, "cap", depth, RadarGrid((-0.1, -0.1, 0.2), (0.1, 0.1, 0.4), (50, 40, 21)))
    preview = np.asarray(Image.open(tmp_path / "depth_preview" / "cap.png").convert("RGB")).astype(float)
    assert preview.shape == (40, 50, 3)
    assert (preview[:5] == preview[0, 0]).all() and len(set(preview[0, 0])) == 1     # no depth: one grey
    luminance = preview[20] @ [0.299, 0.587, 0.114]
    assert luminance[-1] - luminance[0] > 100 and np.all(np.diff(luminance) >= -1)    # viridis: far = bright
    info = json.loads((tmp_path / "depth" / "cap.json").read_text())["preview"]
    assert info["vmin_m"] == pytest.approx(np.percentile(depth[5:], 1))
    assert np.asarray(Image.open(tmp_path / "depth" / "cap.png")).dtype == np.uint16   # the data is unchanged


def test_console_entry_points_run_the_python_m_commands():
    import sys
    from pathlib import Path

    bin_dir = Path(sys.executable).parent
    if not (bin_dir / "mm2fsk-tables").exists():
        pytest.skip("console scripts not installed in this environment (pip install -e . installs them)")
    table = subprocess.run([str(bin_dir / "mm2fsk-tables"), "table1"], capture_output=True, text=True, timeout=120)
    assert table.returncode == 0 and "| d05 | 0.55 |" in table.stdout
    completion = subprocess.run([str(bin_dir / "mm2fsk-bench"), "-sc", "install=bash"], capture_output=True,
                                text=True, timeout=120)
    assert completion.returncode == 0 and completion.stdout.rstrip().endswith("hydra_bash_completion mm2fsk-bench")


def test_progress_bars_are_quiet_when_output_is_not_a_terminal(capsys):
    from bench.progress import bar

    with bar(3, "steps") as progress:          # pytest captures stderr: not a terminal
        progress.update(3)
    assert progress.disable and capsys.readouterr().err == ""
