"""Paper-style pictures of a sweep (MM-2FSK paper Figs. 4-5) and the per-capture panel; PLY export.

Per capture (`<object>_<distance>_<frame>`), from the jobs' `arrays.h5` (depth_m, magnitude, gt_depth_m on the
capture's metric grid):

* `point_clouds/<stem>.png`: one column per cell; rows: a perspective view, a side view (depth z against y) and a
  top view (x against depth z). The radar points (valid pixels) are coloured by the residual phasor magnitude in dB
  relative to the capture's strongest pixel (the quantity the -14 dB filter thresholds, as in the paper), the
  ground-truth surface (the mesh rasterised on the same grid) is drawn in grey beneath them. The perspective view
  comes from Open3D's offscreen renderer where it runs (it needs a Vulkan driver, e.g. Debian's
  `mesa-vulkan-drivers`), else from a z-buffered splat of the points projected through the same camera (chosen at
  run time, `renderer()`); side and top views are orthographic splats, with axes in cm.
* `point_clouds/<stem>/<cell>.ply` (radar points, magnitude colours) and `<stem>/ground_truth.ply`: metres, radar
  space (x right, y up, z away from the array).
* `panels/<stem>.png`: ground truth and (where the dataset can be read) the RealSense prior, then one row per cell:
  depth, magnitude and the signed depth error (depth - ground truth, diverging colours: red = behind the surface,
  blue = in front), "no depth" in grey and depth where there is no ground truth in black; every map on the same
  window, one colour bar per quantity beside the legend.

Both figures are drawn straight into pixels (bench.report.sheet: every view an array, one canvas, matplotlib's
font, tick positions and colour maps): about a tenth of the CPU of matplotlib axes, whose ticks, title layout and
per-point scatter paths cost 4-5 s per capture (docs/measurements/sweep.md, 2026-11-26 06:40).
"""
from __future__ import annotations

import contextlib
import functools
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import h5py
import matplotlib
import numpy as np
from PIL import Image

from bench.report import keyed, sheet
from methods.domain.host import usable_cores

SIGNED_ERROR_LIMIT_CM = 2.0      # colour range of the signed error: +-2 cm, beyond saturates (arrows on the bar)
MAGNITUDE_RANGE_DB = 20.0        # magnitude colours span the strongest pixel down to -20 dB (the filter keeps -14)
NO_DEPTH_COLOUR = "#9a9a9a"      # grey: distinct from white (zero error) and from both ends of the diverging map
NO_TRUTH_COLOUR = "#000000"      # black: the method returned depth where the ground truth has no surface
GT_COLOUR = "#b8b8b8"
CELLS_PER_ROW = 4                # point-cloud columns per row of a figure: about 1200 px wide, legible in a browser
RENDERERS = ("open3d", "splat")
POINT_CLOUD_DPI, PANEL_DPI = 100, 90
# Dots of 3 x 3 pixels (radar) and 5 pixels (a cross; the ground truth beneath): what matplotlib's scatter markers
# (s = 0.2-0.6 pt^2 and a 1.5 pt edge, ~2-2.3 pt across) covered at 100 dpi.
RADAR_RADIUS_PX, GT_RADIUS_PX = 1.5, 1.0
_PROBE = """
import numpy as np, open3d as o3d
r = o3d.visualization.rendering.OffscreenRenderer(32, 32)
assert np.asarray(r.render_to_image()).shape == (32, 32, 3)
"""


@dataclass(frozen=True)
class CaptureArrays:
    """One cell's arrays for one capture on the metric grid: depth and ground truth in metres (NaN = none),
    magnitude linear; x_m (nx,) and y_m (ny,) are the pixel centres (row 0 = +y)."""
    depth_m: np.ndarray
    gt_depth_m: np.ndarray
    magnitude: np.ndarray
    x_m: np.ndarray
    y_m: np.ndarray

    @property
    def extent_cm(self) -> tuple[float, float, float, float]:
        """imshow extent (left, right, bottom, top) in cm, pixel edges half a step beyond the centres."""
        dx, dy = _step(self.x_m), _step(self.y_m)
        return (100 * (self.x_m[0] - dx / 2), 100 * (self.x_m[-1] + dx / 2),
                100 * (self.y_m[-1] - dy / 2), 100 * (self.y_m[0] + dy / 2))


def _step(values: np.ndarray) -> float:
    return float(abs(values[1] - values[0])) if len(values) > 1 else 1e-3


def read_arrays(h5_path: Path, stem: str) -> CaptureArrays | None:
    """The capture `stem` of one job's arrays.h5, or None where that job has no such capture."""
    with h5py.File(h5_path, "r") as h5:
        if stem not in h5:
            return None
        group = h5[stem]
        (nx, ny, _), lo, hi = group.attrs["grid_size"], group.attrs["bb_min_m"], group.attrs["bb_max_m"]
        return CaptureArrays(group["depth_m"][()], group["gt_depth_m"][()], group["magnitude"][()],
                             np.linspace(lo[0], hi[0], int(nx)), np.linspace(hi[1], lo[1], int(ny)))


def capture_stems(h5_paths: list[Path]) -> list[str]:
    """Every capture found in any of the files, sorted."""
    stems = set()
    for path in h5_paths:
        with h5py.File(path, "r") as h5:
            stems.update(h5)
    return sorted(stems)


def points_m(depth_m: np.ndarray, x_m: np.ndarray, y_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(N, 3) radar-space points (x, y, depth) of the finite pixels of a depth map, and their (row, col) indices."""
    rows, cols = np.nonzero(np.isfinite(depth_m))
    return np.column_stack([x_m[cols], y_m[rows], depth_m[rows, cols]]), np.column_stack([rows, cols])


def magnitude_db(magnitude: np.ndarray, reference: float) -> np.ndarray:
    """20 log10(magnitude / reference), -inf where the magnitude is 0."""
    with np.errstate(divide="ignore"):
        return 20.0 * np.log10(np.abs(magnitude) / reference)


def _magnitude_colours(cell: CaptureArrays, index: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Magnitude (dB below the capture's strongest valid pixel) of the points and their RGB colours (0..1)."""
    values = np.abs(cell.magnitude[index[:, 0], index[:, 1]])
    reference = values.max() if values.size and values.max() > 0 else 1.0
    level_db = np.clip(magnitude_db(values, reference), -MAGNITUDE_RANGE_DB, 0.0)
    return level_db, matplotlib.colormaps["plasma"]((level_db + MAGNITUDE_RANGE_DB) / MAGNITUDE_RANGE_DB)[:, :3]


def write_ply(path: Path, points: np.ndarray, colours: np.ndarray | None = None) -> Path:
    """A point cloud in metres (and RGB colours 0..1) as binary little-endian PLY in Open3D's layout: x, y, z as
    doubles, then red, green, blue as bytes (rounded half up, as Open3D writes them). Written here rather than by
    Open3D, whose import costs ~0.6 s per drawing process and which refuses a cloud of no points."""
    points = np.asarray(points, np.float64).reshape(-1, 3)
    fields, header = [("xyz", "<f8", (3,))], [f"property double {axis}" for axis in "xyz"]
    if colours is not None:
        fields.append(("rgb", "u1", (3,)))
        header += [f"property uchar {channel}" for channel in ("red", "green", "blue")]
    records = np.empty(len(points), dtype=fields)
    records["xyz"] = points
    if colours is not None:
        records["rgb"] = np.floor(np.clip(np.asarray(colours, np.float64), 0.0, 1.0) * 255.0 + 0.5)
    header = ["ply", "format binary_little_endian 1.0", "comment Created by mm2fsk-bench",
              f"element vertex {len(points)}", *header, "end_header", ""]
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes("\n".join(header).encode("ascii") + records.tobytes())
    return path


@functools.lru_cache(maxsize=1)
def _probe() -> subprocess.Popen | None:
    """The child process probing Open3D's offscreen renderer (a missing driver can abort it), started once per
    process; None where it cannot start."""
    try:
        return subprocess.Popen([sys.executable, "-c", _PROBE], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    except OSError:
        return None


def probe_renderer() -> None:
    """Start the renderer's probe now, so that it runs beside what this process does before drawing (about 0.6 s
    of another core: it imports Open3D)."""
    if os.environ.get("BENCH_RENDERER", "").strip().lower() != "splat":
        _probe()


@functools.lru_cache(maxsize=1)
def _open3d_renders() -> bool:
    """Whether Open3D's offscreen renderer runs here (the probe's verdict, waited for)."""
    probe = _probe()
    if probe is None:
        return False
    try:
        return probe.wait(timeout=120) == 0
    except subprocess.TimeoutExpired:
        probe.kill()
        probe.wait()
        return False


def renderer() -> str:
    """'open3d' where its offscreen renderer runs, else 'splat'; `BENCH_RENDERER=open3d|splat` forces one (open3d
    where it cannot run is an error, not a silent fallback)."""
    forced = os.environ.get("BENCH_RENDERER", "").strip().lower()
    if forced and forced not in RENDERERS:
        raise ValueError(f"BENCH_RENDERER={forced!r}: choose one of {', '.join(RENDERERS)}")
    if forced == "splat":
        return forced
    if _open3d_renders():
        return "open3d"
    if forced == "open3d":
        raise RuntimeError("BENCH_RENDERER=open3d, but Open3D's offscreen renderer does not run here (it needs a "
                           "Vulkan driver, e.g. apt-get install libvulkan1 mesa-vulkan-drivers)")
    return "splat"


def _perspective_camera(gt_points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(centre, eye) in metres: looking at the object from the array side, raised and to the left (as Fig. 5)."""
    centre = gt_points.mean(axis=0) if len(gt_points) else np.array([0.0, 0.0, 0.3])
    size = float(np.ptp(gt_points, axis=0).max()) if len(gt_points) else 0.2
    return centre, centre + np.array([-0.9, 0.6, -1.6]) * max(size, 0.05)


@contextlib.contextmanager
def _native_output_discarded():
    """Discard what native code writes to the process's stdout and stderr (file descriptors 1 and 2) meanwhile."""
    sys.stdout.flush()
    sys.stderr.flush()
    saved, null = (os.dup(1), os.dup(2)), os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(null, 1)
        os.dup2(null, 2)
        yield
    finally:
        os.dup2(saved[0], 1)
        os.dup2(saved[1], 2)
        for fd in (*saved, null):
            os.close(fd)


@functools.lru_cache(maxsize=1)
def _offscreen(size_px: int):
    """One Open3D offscreen renderer per process (creating one costs about a second). Its creation prints windowing
    and driver lines from C++ (GLFW fallback, Vulkan device) into the user's console: discarded; a failure still
    raises."""
    from open3d.visualization import rendering

    with _native_output_discarded():
        return rendering.OffscreenRenderer(size_px, size_px)


def render_open3d(points: np.ndarray, colours: np.ndarray, gt_points: np.ndarray, size_px: int = 360) -> np.ndarray:
    """(size_px, size_px, 3) uint8 perspective render of the radar points over the grey ground truth (Open3D)."""
    import open3d as o3d
    from open3d.visualization import rendering

    renderer_ = _offscreen(size_px)
    scene = renderer_.scene
    scene.clear_geometry()
    scene.set_background([1.0, 1.0, 1.0, 1.0])
    grey = np.tile(matplotlib.colors.to_rgb(GT_COLOUR), (len(gt_points), 1))
    for name, xyz, rgb, point_size in (("truth", gt_points, grey, 1.5), ("radar", points, colours, 3.0)):
        if len(xyz) == 0:
            continue
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(xyz, np.float64)))
        cloud.colors = o3d.utility.Vector3dVector(np.asarray(rgb, np.float64))
        material = rendering.MaterialRecord()
        material.shader, material.point_size = "defaultUnlit", point_size
        scene.add_geometry(name, cloud, material)
    centre, eye = _perspective_camera(gt_points)
    renderer_.setup_camera(35.0, centre, eye, [0.0, 1.0, 0.0])
    return np.asarray(renderer_.render_to_image())


def project(points: np.ndarray, centre: np.ndarray, eye: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pinhole projection of (N, 3) radar-space points seen from `eye` looking at `centre` with y up (the camera
    render_open3d sets up): (N, 2) image-plane coordinates (x to the right, y up; tangents of the view angles) and
    the (N,) distances along the view direction."""
    forward = (centre - eye) / np.linalg.norm(centre - eye)
    right = np.cross([0.0, 1.0, 0.0], forward)
    right /= np.linalg.norm(right)
    up = np.cross(forward, right)
    relative = np.asarray(points, np.float64) - eye
    depth = relative @ forward
    return np.column_stack([relative @ right, relative @ up]) / depth[:, None], depth


def _rgb8(colours: np.ndarray) -> np.ndarray:
    """RGB colours 0..1 as uint8."""
    return np.round(np.asarray(colours, np.float64) * 255).astype(np.uint8)


def _blank(box: sheet.Box) -> np.ndarray:
    return np.full((box.height, box.width, 3), 255, np.uint8)


def _equal_window(lo: np.ndarray, hi: np.ndarray, aspect: float, margin: float = 0.05
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The window (lo, hi) around the (x, y) range lo..hi plus `margin` of it on each side, widened along one axis so
    that width / height = `aspect` (equal scales, centred)."""
    span = np.maximum(hi - lo, 1e-9) * (1 + 2 * margin)
    span = np.maximum(span, [span[1] * aspect, span[0] / aspect])
    middle = (lo + hi) / 2
    return middle - span / 2, middle + span / 2


def perspective_pixels(points: np.ndarray, colours: np.ndarray, gt_points: np.ndarray, box: sheet.Box) -> np.ndarray:
    """(box.height, box.width, 3) uint8: the perspective view of render_open3d's camera as a splat (`sheet.splat`):
    the ground truth in grey, then the radar points over it (RGB 0..1 `colours`), nearer points over farther ones
    within each, on equal scales with a margin of 5 % around every point."""
    centre, eye = _perspective_camera(gt_points)
    grey = _rgb8([matplotlib.colors.to_rgb(GT_COLOUR)])
    layers = [(*project(xyz, centre, eye), rgb, radius)
              for xyz, rgb, radius in ((gt_points, np.repeat(grey, len(gt_points), 0), GT_RADIUS_PX),
                                       (points, _rgb8(colours), RADAR_RADIUS_PX)) if len(xyz)]
    tile = _blank(box)
    if not layers:
        return tile
    plane = np.vstack([layer[0] for layer in layers])
    lo, hi = _equal_window(plane.min(axis=0), plane.max(axis=0), box.width / box.height)
    for xy, depth, rgb, radius in layers:
        sheet.splat(tile, sheet.to_pixels(xy[:, 0], lo[0], hi[0], box.width),
                    sheet.to_pixels(xy[:, 1], lo[1], hi[1], box.height, downwards=True), depth, rgb, radius)
    return tile


def orthographic_pixels(layers: list[tuple[np.ndarray, np.ndarray, float]], axes: tuple[int, int], xlim: tuple,
                        ylim: tuple, box: sheet.Box) -> np.ndarray:
    """(box.height, box.width, 3) uint8: the (N, 3) point sets of `layers` ((points m, RGB uint8, dot radius px),
    later layers over earlier ones) projected onto the coordinates `axes` (0 x, 1 y, 2 depth z) over the window
    xlim x ylim (cm). Within a layer the point nearer the viewer wins, the viewer on the negative side of the third
    coordinate (as the two axes lie: the side view (z, y) is seen from -x, the top view (x, z) from -y)."""
    tile = _blank(box)
    (across, up), along = axes, 3 - sum(axes)
    for points, rgb, radius in layers:
        if len(points):
            sheet.splat(tile, sheet.to_pixels(100 * points[:, across], *xlim, box.width),
                        sheet.to_pixels(100 * points[:, up], *ylim, box.height, downwards=True), points[:, along],
                        rgb, radius)
    return tile


def point_cloud_figure(cells: list[tuple[str, CaptureArrays]], stem: str, path: Path, ply_dir: Path | None = None,
                       use: str | None = None) -> Path:
    """Figs. 4-5 for one capture: per cell a perspective, side and top view of the radar points (magnitude
    colours) over the ground truth (grey), CELLS_PER_ROW cells side by side; writes PLY files into `ply_dir` when
    given. `use`: the renderer of the perspective view (default `renderer()`); the side and top views are splats
    on axes in cm, the same window in every column."""
    use = use or renderer()
    truth = next(cell for _, cell in cells)
    gt_points, _ = points_m(truth.gt_depth_m, truth.x_m, truth.y_m)
    gt_colours = np.tile(matplotlib.colors.to_rgb(GT_COLOUR), (len(gt_points), 1))
    if ply_dir is not None:
        write_ply(ply_dir / stem / "ground_truth.ply", gt_points, gt_colours)
    gt_layer = (gt_points, _rgb8(gt_colours), GT_RADIUS_PX)
    ncols = min(len(cells), CELLS_PER_ROW)
    blocks = -(-len(cells) // ncols)
    dpi = POINT_CLOUD_DPI
    width, height = round((2.6 * ncols + 1.2) * dpi), round(8.4 * blocks * dpi)
    page = sheet.Sheet(width, height, dpi)
    boxes = sheet.grid(sheet.Box(round(0.6 * dpi), round(0.75 * dpi), width - round(1.7 * dpi),
                                 height - round(1.45 * dpi)), 3 * blocks, ncols, hspace=0.45, wspace=0.12)
    clouds = [points_m(c.depth_m, c.x_m, c.y_m) for _, c in cells]
    x_cm, y_cm, z_cm = (_window_cm(gt_points, [points for points, _ in clouds], axis) for axis in range(3))
    for number, ((label, cell), (points, index)) in enumerate(zip(cells, clouds, strict=True)):
        block, col = divmod(number, ncols)
        _, colours = _magnitude_colours(cell, index)
        if ply_dir is not None:
            write_ply(ply_dir / stem / f"{_file_name(label)}.ply", points, colours)
        view = boxes[3 * block][col]
        if use == "open3d":
            view = view.fit(1.0)
            rendered = Image.fromarray(render_open3d(points, colours, gt_points)).resize((view.width, view.height))
            page.paste(np.asarray(rendered.convert("RGB")), view)
        else:
            page.paste(perspective_pixels(points, colours, gt_points, view), view)
        page.text((view.left + view.width / 2, view.top - page.px(sheet.TITLE_PAD_PT)),
                  f"{label}\n{len(points)} points", 8, anchor="ms")
        layers = [gt_layer, (points, _rgb8(colours), RADAR_RADIUS_PX)]
        for row, axes, xlim, ylim, title, xlabel, ylabel in (
                (1, (2, 1), z_cm, y_cm, "side view (array left)", "z, depth (cm)", "y (cm)"),
                (2, (0, 2), x_cm, z_cm, "top view (array below)", "x (cm)", "z, depth (cm)")):
            view = boxes[3 * block + row][col]
            page.paste(orthographic_pixels(layers, axes, xlim, ylim, view), view)
            page.axes(view, xlim, ylim, title=title, xlabel=xlabel, ylabel=ylabel if col == 0 else None,
                      y_labels=col == 0)       # every column has the same limits
    page.colorbar(sheet.Box(width - round(0.85 * dpi), round(0.25 * height), round(0.15 * dpi), round(0.5 * height)),
                  matplotlib.colormaps["plasma"], -MAGNITUDE_RANGE_DB, 0.0,
                  "residual phasor magnitude (dB re strongest pixel)")
    page.legend((page.px(4), height - page.px(24)), [(GT_COLOUR, "ground truth")], 8, frame=True)
    renderer_note = "Open3D offscreen" if use == "open3d" else "a z-buffered splat"
    page.text((width / 2, round(0.15 * dpi)), f"{stem}: radar point clouds over the ground truth (grey), coloured by "
              f"magnitude; perspective view by {renderer_note}", 9, anchor="mt")
    return page.save(path)


def _window_cm(gt_points: np.ndarray, clouds: list[np.ndarray], axis: int, margin_cm: float = 2.0
               ) -> tuple[float, float]:
    """Range (cm) of one coordinate over the ground truth and every radar point (wraps stay visible), plus a margin;
    the same for every column so that the cells compare at a glance."""
    values = [c[:, axis] for c in (gt_points, *clouds) if len(c)]
    if not values:
        return (20.0, 40.0) if axis == 2 else (-15.0, 15.0)
    values_cm = np.concatenate(values) * 100
    return float(values_cm.min() - margin_cm), float(values_cm.max() + margin_cm)


def _file_name(label: str) -> str:
    """A cell label as a file name: 'MM-2FSK Δ10.0' -> 'MM-2FSK_d10.0'."""
    return "".join(ch if ch.isalnum() or ch in "-._" else "_" for ch in label.replace("Δ", "d")).strip("_")


def signed_error_cm(cell: CaptureArrays) -> np.ndarray:
    """depth - ground truth in cm (positive: the radar put the surface behind the truth); NaN where either is."""
    return (cell.depth_m - cell.gt_depth_m) * 100.0


def no_error_categories(cell: CaptureArrays) -> np.ndarray:
    """Masked overlay: NaN where an error is drawn, 0 = no depth, 1 = depth without ground truth."""
    overlay = np.full(cell.depth_m.shape, np.nan)
    overlay[~np.isfinite(cell.depth_m)] = 0
    overlay[np.isfinite(cell.depth_m) & ~np.isfinite(cell.gt_depth_m)] = 1
    return overlay


def crop_cm(cells: list[CaptureArrays], margin_cm: float = 1.0) -> tuple[tuple, tuple]:
    """x and y ranges (cm) around every pixel with a depth or a ground truth in any cell, plus a margin."""
    x_cm, y_cm = [], []
    for cell in cells:
        rows, cols = np.nonzero(np.isfinite(cell.depth_m) | np.isfinite(cell.gt_depth_m))
        x_cm.append(cell.x_m[cols] * 100)
        y_cm.append(cell.y_m[rows] * 100)
    x_cm, y_cm = np.concatenate(x_cm), np.concatenate(y_cm)
    if x_cm.size == 0:
        left, right, bottom, top = cells[0].extent_cm
        return (left, right), (bottom, top)
    return (x_cm.min() - margin_cm, x_cm.max() + margin_cm), (y_cm.min() - margin_cm, y_cm.max() + margin_cm)


def map_rgb(image: np.ndarray, extent_cm: tuple, xlim: tuple, ylim: tuple, view: sheet.Box, cmap, vmin: float,
            vmax: float, overlay: np.ndarray | None = None) -> np.ndarray:
    """(view.height, view.width, 3) uint8: a map (row 0 at the top of `extent_cm`) in the window xlim x ylim (cm)
    by nearest pixel, coloured by `cmap` over vmin..vmax; white outside the map. `overlay` (no_error_categories):
    no depth in grey and depth without ground truth in black, painted over the colours where it says so."""
    values, inside = sheet.map_pixels(image, extent_cm, xlim, ylim, view.width, view.height)
    rgb = sheet.colours(values, cmap, vmin, vmax)
    if overlay is not None:
        categories, _ = sheet.map_pixels(overlay, extent_cm, xlim, ylim, view.width, view.height)
        for category, colour in enumerate((NO_DEPTH_COLOUR, NO_TRUTH_COLOUR)):
            rgb[categories == category] = _rgb8(matplotlib.colors.to_rgb(colour))
    rgb[~inside] = sheet.WHITE
    return rgb


def capture_panel(cells: list[tuple[str, CaptureArrays]], stem: str, path: Path,
                  prior_m: np.ndarray | None = None) -> Path:
    """Per capture: ground truth and prior on top, then per cell depth, magnitude (dB) and signed error (cm); every
    map on the same x, y window (equal scales, nearest pixel), one colour bar per quantity (top right, with the
    legend)."""
    arrays = [cell for _, cell in cells]
    truth = arrays[0]
    xlim, ylim = crop_cm(arrays)
    depth_cm = np.concatenate([a.depth_m[np.isfinite(a.depth_m)] for a in arrays] +
                              [truth.gt_depth_m[np.isfinite(truth.gt_depth_m)]]) * 100
    depth_range = (np.percentile(depth_cm, 1), np.percentile(depth_cm, 99)) if depth_cm.size else (20.0, 40.0)
    depth_map = matplotlib.colormaps["viridis"].with_extremes(bad=NO_DEPTH_COLOUR)
    level_map = matplotlib.colormaps["plasma"].with_extremes(bad=NO_DEPTH_COLOUR)
    error_map = matplotlib.colormaps["RdBu_r"].with_extremes(bad=NO_DEPTH_COLOUR)
    dpi, last = PANEL_DPI, len(cells)
    width, height = round(10.5 * dpi), round((3.0 * (len(cells) + 1) + 0.6) * dpi)
    page = sheet.Sheet(width, height, dpi)
    boxes = sheet.grid(sheet.Box(round(0.7 * dpi), round(0.5 * dpi), width - round(0.9 * dpi), height - dpi),
                       len(cells) + 1, 3, hspace=0.25, wspace=0.1)
    aspect = (xlim[1] - xlim[0]) / (ylim[1] - ylim[0])

    def show(row: int, col: int, image: np.ndarray, cmap, vmin: float, vmax: float, title: str,
             overlay: np.ndarray | None = None) -> None:
        view = boxes[row][col].fit(aspect)
        page.paste(map_rgb(image, truth.extent_cm, xlim, ylim, view, cmap, vmin, vmax, overlay), view)
        page.axes(view, xlim, ylim, title=title, xlabel="x (cm)" if row == last else None,
                  ylabel="y (cm)" if col == 0 else None, x_labels=row == last, y_labels=col == 0)

    show(0, 0, truth.gt_depth_m * 100, depth_map, *depth_range, "ground truth depth")
    if prior_m is not None:
        show(0, 1, prior_m * 100, depth_map, *depth_range, "RealSense prior (MM-2FSK)")
    else:
        box = boxes[0][1]
        page.text((box.left + box.width / 2, box.top + box.height / 2 - page.px(8)),
                  "prior not available\n(dataset not readable here)", 8)
    for row, (label, cell) in enumerate(cells, start=1):
        show(row, 0, cell.depth_m * 100, depth_map, *depth_range, f"{label}: depth")
        valid = np.isfinite(cell.depth_m)
        reference = np.abs(cell.magnitude[valid]).max() if valid.any() else 1.0
        level = np.where(valid, magnitude_db(cell.magnitude, reference or 1.0), np.nan)
        show(row, 1, level, level_map, -MAGNITUDE_RANGE_DB, 0, f"{label}: magnitude")
        show(row, 2, signed_error_cm(cell), error_map, -SIGNED_ERROR_LIMIT_CM, SIGNED_ERROR_LIMIT_CM,
             f"{label}: depth - ground truth", overlay=no_error_categories(cell))
    key = boxes[0][2]
    page.legend((key.left + round(0.05 * key.width), key.top),
                [(NO_DEPTH_COLOUR, "no depth (filtered or not returned)"),
                 (NO_TRUTH_COLOUR, "depth where the ground truth has no surface"),
                 (matplotlib.colors.to_hex(error_map(1.0)), "error > 0: behind the surface"),
                 (matplotlib.colors.to_hex(error_map(0.0)), "error < 0: in front of it")], 7)
    bars = [(depth_map, *depth_range, "depth z (cm)", "neither")]
    if cells:                    # a panel of the ground truth and prior alone has no magnitude or error maps
        bars += [(level_map, -MAGNITUDE_RANGE_DB, 0.0, "magnitude (dB re strongest pixel)", "min"),
                 (error_map, -SIGNED_ERROR_LIMIT_CM, SIGNED_ERROR_LIMIT_CM,
                  f"signed error (cm), saturates at ±{SIGNED_ERROR_LIMIT_CM:g}", "both")]
    for number, (cmap, vmin, vmax, bar_label, extend) in enumerate(bars):
        bottom = 0.52 - 0.24 * number                      # of the key's height, from its bottom
        bar = sheet.Box(key.left + round(0.05 * key.width), key.top + round((0.95 - bottom) * key.height),
                        round(0.9 * key.width), round(0.05 * key.height))
        page.colorbar(bar, cmap, vmin, vmax, bar_label, vertical=False, extend=extend, size_pt=7, nbins=5)
    page.text((width / 2, round(0.1 * dpi)), f"{stem}: depth, magnitude and signed error per method (x, y in cm, "
              f"radar space)", 9, anchor="mt")
    return page.save(path)


def _capture_pictures(runs: list[tuple[str, Path]], stem: str, out_dir: Path, prior_m: np.ndarray | None,
                      ply: bool, use: str, recorded: str | None) -> tuple[str, bool]:
    """One capture, in a worker process of sweep_pictures: (its content key, whether it was drawn). Both figures
    (and the PLY files) are drawn unless the key equals `recorded`, the key they were last drawn from, and both
    files are there. The arrays are read once, here, for the key and the figures."""
    cells = [(label, arrays) for label, path in runs if (arrays := read_arrays(path, stem)) is not None]
    key = _key(cells, stem, prior_m, ply, use)
    files = picture_files(out_dir, stem)
    if key == recorded and all(path.is_file() for path in files.values()):
        return key, False
    point_cloud_figure(cells, stem, files["point_clouds"], out_dir / "point_clouds" if ply else None, use=use)
    capture_panel(cells, stem, files["panel"], prior_m)
    return key, True


def _key(cells: list[tuple[str, CaptureArrays]], stem: str, prior_m: np.ndarray | None, ply: bool, use: str) -> str:
    """Content key of one capture's pictures: the cells' labels and arrays, the prior, the options and the code
    that draws them (this module and bench.report.sheet)."""
    parts = [stem, ply, use, Path(__file__), keyed.module_source(sheet)]
    for label, arrays in cells:
        parts += [label, arrays.depth_m, arrays.gt_depth_m, arrays.magnitude, arrays.x_m, arrays.y_m]
    return keyed.digest(*parts, prior_m if prior_m is not None else "no prior")


def picture_files(out_dir: Path, stem: str) -> dict[str, Path]:
    """Where the pictures of capture `stem` go under `out_dir`."""
    return {"point_clouds": out_dir / "point_clouds" / f"{stem}.png", "panel": out_dir / "panels" / f"{stem}.png"}


def sweep_pictures(runs: list[tuple[str, Path]], out_dir: Path, priors: dict[str, np.ndarray] | None = None,
                   ply: bool = True, workers: int | None = None) -> dict[str, dict[str, Path]]:
    """Point-cloud figures (+ PLY) and panels of every capture of the runs ((label, arrays.h5) pairs) under
    `out_dir/point_clouds/` and `out_dir/panels/`; returns {stem: {"point_clouds": png, "panel": png}}. Each
    capture goes to one of `workers` spawned processes (default: one per CPU core), which reads its arrays once
    and draws it unless its inputs (arrays, labels, prior, options, the drawing code) are unchanged since it was
    drawn (bench.report.keyed: the keys are computed there, beside the drawing, not here one capture after another).
    """
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from bench.progress import bar

    use = renderer()
    stems = capture_stems([path for _, path in runs])
    keys = keyed.Keys(out_dir)
    written = {stem: picture_files(out_dir, stem) for stem in stems}
    if not stems:
        return written
    workers = max(1, min(len(stems), workers or usable_cores()))
    redrawn = 0
    with bar(len(stems), f"pictures ({use})", unit="capture") as progress, \
            ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {stem: pool.submit(_capture_pictures, runs, stem, out_dir, (priors or {}).get(stem), ply, use,
                                     keys.keys.get(stem)) for stem in stems}
        for stem, future in futures.items():
            key, drawn = future.result()
            if drawn:
                keys.record(stem, key)
                redrawn += 1
            progress.set_postfix_str(f"{progress.n + 1 - redrawn} unchanged", refresh=False)
            progress.update()
    return written
