"""Paper-style pictures of a sweep (MM-2FSK paper Figs. 4-5) and the per-capture panel; PLY export.

Per capture (`<object>_<distance>_<frame>`), from the jobs' `arrays.h5` (depth_m, magnitude, gt_depth_m on the
capture's metric grid):

* `point_clouds/<stem>.png`: one column per cell; rows: a perspective view, a side view (depth z against y) and a
  top view (x against depth z). The radar points (valid pixels) are coloured by the residual phasor magnitude in dB
  relative to the capture's strongest pixel (the quantity the -14 dB filter thresholds, as in the paper), the
  ground-truth surface (the mesh rasterised on the same grid) is drawn in grey beneath them. The perspective view
  comes from Open3D's offscreen renderer where it runs (it needs a Vulkan driver, e.g. Debian's
  `mesa-vulkan-drivers`), else from matplotlib, projecting the points through the same camera (chosen at run time,
  `renderer()`); side and top views are orthographic projections drawn by matplotlib, with axes in cm.
* `point_clouds/<stem>/<cell>.ply` (radar points, magnitude colours) and `<stem>/ground_truth.ply`: metres, radar
  space (x right, y up, z away from the array).
* `panels/<stem>.png`: ground truth and (where the dataset can be read) the RealSense prior, then one row per cell:
  depth, magnitude and the signed depth error (depth - ground truth, diverging colours: red = behind the surface,
  blue = in front), "no depth" in grey and depth where there is no ground truth in black; every map on the same
  window, one colour bar per quantity beside the legend.

The figures have fixed layouts (margins in inches): about half the CPU of matplotlib's constrained layout, which
measured every tick label twice (docs/measurements/sweep.md, 2026-11-26 04:30).
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

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402  (after choosing the file-only backend)
import numpy as np  # noqa: E402
from matplotlib.colors import ListedColormap  # noqa: E402
from matplotlib.patches import Patch  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from bench.report import keyed  # noqa: E402

SIGNED_ERROR_LIMIT_CM = 2.0      # colour range of the signed error: +-2 cm, beyond saturates (arrows on the bar)
MAGNITUDE_RANGE_DB = 20.0        # magnitude colours span the strongest pixel down to -20 dB (the filter keeps -14)
NO_DEPTH_COLOUR = "#9a9a9a"      # grey: distinct from white (zero error) and from both ends of the diverging map
NO_TRUTH_COLOUR = "#000000"      # black: the method returned depth where the ground truth has no surface
GT_COLOUR = "#b8b8b8"
CELLS_PER_ROW = 4                # point-cloud columns per row of a figure: about 1200 px wide, legible in a browser
RENDERERS = ("open3d", "matplotlib")
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
    return level_db, plt.get_cmap("plasma")((level_db + MAGNITUDE_RANGE_DB) / MAGNITUDE_RANGE_DB)[:, :3]


def write_ply(path: Path, points: np.ndarray, colours: np.ndarray | None = None) -> Path:
    """A point cloud in metres (and RGB colours 0..1) as binary PLY (Open3D)."""
    import open3d as o3d

    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64)))
    if colours is not None:
        cloud.colors = o3d.utility.Vector3dVector(np.asarray(colours, np.float64))
    path.parent.mkdir(parents=True, exist_ok=True)
    if not o3d.io.write_point_cloud(str(path), cloud):
        raise OSError(f"{path}: Open3D could not write the point cloud")
    return path


@functools.lru_cache(maxsize=1)
def _open3d_renders() -> bool:
    """Whether Open3D's offscreen renderer runs here, probed in a child process (a missing driver can abort it)."""
    try:
        probe = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, timeout=120)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return probe.returncode == 0


def renderer() -> str:
    """'open3d' where its offscreen renderer runs, else 'matplotlib'; `BENCH_RENDERER=open3d|matplotlib` forces
    one (open3d where it cannot run is an error, not a silent fallback)."""
    forced = os.environ.get("BENCH_RENDERER", "").strip().lower()
    if forced and forced not in RENDERERS:
        raise ValueError(f"BENCH_RENDERER={forced!r}: choose one of {', '.join(RENDERERS)}")
    if forced == "matplotlib":
        return forced
    if _open3d_renders():
        return "open3d"
    if forced == "open3d":
        raise RuntimeError("BENCH_RENDERER=open3d, but Open3D's offscreen renderer does not run here (it needs a "
                           "Vulkan driver, e.g. apt-get install libvulkan1 mesa-vulkan-drivers)")
    return "matplotlib"


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


def _draw_perspective_matplotlib(ax, points: np.ndarray, colours: np.ndarray, gt_points: np.ndarray) -> None:
    """The perspective view of render_open3d (same camera) drawn by matplotlib on 2D axes: the ground truth (grey),
    then the radar points over it, each painted far to near. (2D axes: matplotlib's 3D axes cost about a third of
    the figure.)"""
    centre, eye = _perspective_camera(gt_points)
    for xyz, rgb, size in ((gt_points, np.array([matplotlib.colors.to_rgb(GT_COLOUR)]), 0.2),
                           (points, colours, 0.6)):
        if len(xyz):
            plane, depth = project(xyz, centre, eye)
            order = np.argsort(-depth, kind="stable")
            ax.scatter(plane[order, 0], plane[order, 1], s=size, c=rgb if len(rgb) == 1 else rgb[order],
                       rasterized=True)
    ax.set_aspect("equal")
    ax.set_axis_off()


def _subsample(points: np.ndarray, *arrays: np.ndarray, at_most: int = 8000) -> tuple[np.ndarray, ...]:
    """Every k-th point so that at most `at_most` are drawn (matplotlib scatter cost), same rows of `arrays`."""
    step = max(1, -(-len(points) // at_most))
    return (points[::step], *(a[::step] for a in arrays))


def point_cloud_figure(cells: list[tuple[str, CaptureArrays]], stem: str, path: Path, ply_dir: Path | None = None,
                       use: str | None = None) -> Path:
    """Figs. 4-5 for one capture: per cell a perspective, side and top view of the radar points (magnitude
    colours) over the ground truth (grey), CELLS_PER_ROW cells side by side; writes PLY files into `ply_dir` when
    given. `use`: the renderer of the
    perspective view (default `renderer()`)."""
    use = use or renderer()
    truth = next(cell for _, cell in cells)
    gt_points, _ = points_m(truth.gt_depth_m, truth.x_m, truth.y_m)
    if ply_dir is not None:
        write_ply(ply_dir / stem / "ground_truth.ply", gt_points, np.tile(matplotlib.colors.to_rgb(GT_COLOUR),
                                                                          (len(gt_points), 1)))
    ncols = min(len(cells), CELLS_PER_ROW)
    blocks = -(-len(cells) // ncols)
    width_in, height_in = 2.6 * ncols + 1.2, 8.4 * blocks
    fig = plt.figure(figsize=(width_in, height_in))
    grid = _fixed_grid(fig, 3 * blocks, ncols, left_in=0.6, right_in=1.1, top_in=0.75, bottom_in=0.7,
                       hspace=0.45, wspace=0.12)
    gt_shown = _subsample(gt_points)[0]
    clouds = [points_m(c.depth_m, c.x_m, c.y_m)[0] for _, c in cells]
    x_cm, y_cm, z_cm = (_window_cm(gt_points, clouds, axis) for axis in range(3))
    for number, (label, cell) in enumerate(cells):
        block, col = divmod(number, ncols)
        points, index = points_m(cell.depth_m, cell.x_m, cell.y_m)
        level_db, colours = _magnitude_colours(cell, index)
        if ply_dir is not None:
            write_ply(ply_dir / stem / f"{_file_name(label)}.ply", points, colours)
        shown, shown_colours = _subsample(points, colours)
        ax = fig.add_subplot(grid[3 * block, col])
        if use == "open3d":
            ax.imshow(render_open3d(shown, shown_colours, gt_shown))
            ax.set_axis_off()
        else:
            _draw_perspective_matplotlib(ax, shown, shown_colours, gt_shown)
        ax.set_title(f"{label}\n{len(points)} points", fontsize=8)
        side, top = fig.add_subplot(grid[3 * block + 1, col]), fig.add_subplot(grid[3 * block + 2, col])
        side.scatter(gt_shown[:, 2] * 100, gt_shown[:, 1] * 100, s=0.3, c=GT_COLOUR, rasterized=True)
        side.scatter(shown[:, 2] * 100, shown[:, 1] * 100, s=0.5, c=shown_colours, rasterized=True)
        side.set(xlabel="z, depth (cm)", xlim=z_cm, ylim=y_cm, title="side view (array left)")
        top.scatter(gt_shown[:, 0] * 100, gt_shown[:, 2] * 100, s=0.3, c=GT_COLOUR, rasterized=True)
        top.scatter(shown[:, 0] * 100, shown[:, 2] * 100, s=0.5, c=shown_colours, rasterized=True)
        top.set(xlabel="x (cm)", xlim=x_cm, ylim=z_cm, title="top view (array below)")
        for view, ylabel in ((side, "y (cm)"), (top, "z, depth (cm)")):
            view.title.set_fontsize(8)
            view.tick_params(labelsize=7, labelleft=col == 0)   # every column has the same limits
            view.xaxis.label.set_fontsize(7)
            if col == 0:
                view.set_ylabel(ylabel, fontsize=7)
    bar = plt.cm.ScalarMappable(plt.Normalize(-MAGNITUDE_RANGE_DB, 0), cmap="plasma")
    fig.colorbar(bar, cax=fig.add_axes((1 - 0.85 / width_in, 0.25, 0.15 / width_in, 0.5)),
                 label="residual phasor magnitude (dB re strongest pixel)")
    fig.legend(handles=[Patch(color=GT_COLOUR, label="ground truth")], loc="lower left", fontsize=8)
    renderer_note = "Open3D offscreen" if use == "open3d" else "matplotlib"
    fig.suptitle(f"{stem}: radar point clouds over the ground truth (grey), coloured by magnitude; "
                 f"perspective view by {renderer_note}", fontsize=9, y=1 - 0.15 / height_in, va="top")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def _fixed_grid(fig, rows: int, cols: int, left_in: float, right_in: float, top_in: float, bottom_in: float,
                hspace: float, wspace: float):
    """A GridSpec over `fig` with margins in inches. The layout is fixed rather than constrained: matplotlib's
    constrained layout measured every tick label of these figures twice and was about 40 % of their cost."""
    width_in, height_in = fig.get_size_inches()
    return fig.add_gridspec(rows, cols, left=left_in / width_in, right=1 - right_in / width_in,
                            bottom=bottom_in / height_in, top=1 - top_in / height_in, hspace=hspace, wspace=wspace)


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


def capture_panel(cells: list[tuple[str, CaptureArrays]], stem: str, path: Path,
                  prior_m: np.ndarray | None = None) -> Path:
    """Per capture: ground truth and prior on top, then per cell depth, magnitude (dB) and signed error (cm); every
    map on the same x, y window, one colour bar per quantity (top right, with the legend)."""
    arrays = [cell for _, cell in cells]
    truth = arrays[0]
    xlim, ylim = crop_cm(arrays)
    depth_cm = np.concatenate([a.depth_m[np.isfinite(a.depth_m)] for a in arrays] +
                              [truth.gt_depth_m[np.isfinite(truth.gt_depth_m)]]) * 100
    depth_range = (np.percentile(depth_cm, 1), np.percentile(depth_cm, 99)) if depth_cm.size else (20.0, 40.0)
    depth_map = plt.get_cmap("viridis").with_extremes(bad=NO_DEPTH_COLOUR)
    level_map = plt.get_cmap("plasma").with_extremes(bad=NO_DEPTH_COLOUR)
    error_map = plt.get_cmap("RdBu_r").with_extremes(bad=NO_DEPTH_COLOUR)
    overlay_map = ListedColormap([NO_DEPTH_COLOUR, NO_TRUTH_COLOUR])
    fig = plt.figure(figsize=(10.5, 3.0 * (len(cells) + 1) + 0.6))
    axes = _fixed_grid(fig, len(cells) + 1, 3, left_in=0.7, right_in=0.2, top_in=0.5, bottom_in=0.5,
                       hspace=0.25, wspace=0.1).subplots(squeeze=False)   # not shared: 45 linked axes cost more

    def show(ax, image, cmap, vmin, vmax, title):
        drawn = ax.imshow(image, extent=truth.extent_cm, cmap=cmap, vmin=vmin, vmax=vmax, interpolation="nearest")
        ax.set_title(title, fontsize=8)
        ax.tick_params(labelsize=7)
        return drawn

    depth_drawn = show(axes[0, 0], truth.gt_depth_m * 100, depth_map, *depth_range, "ground truth depth")
    if prior_m is not None:
        show(axes[0, 1], prior_m * 100, depth_map, *depth_range, "RealSense prior (MM-2FSK)")
    else:
        axes[0, 1].set_axis_off()
        axes[0, 1].text(0.5, 0.5, "prior not available\n(dataset not readable here)", ha="center",
                        transform=axes[0, 1].transAxes, fontsize=8)
    for row, (label, cell) in enumerate(cells, start=1):
        show(axes[row, 0], cell.depth_m * 100, depth_map, *depth_range, f"{label}: depth")
        valid = np.isfinite(cell.depth_m)
        reference = np.abs(cell.magnitude[valid]).max() if valid.any() else 1.0
        level = np.where(valid, magnitude_db(cell.magnitude, reference or 1.0), np.nan)
        level_drawn = show(axes[row, 1], level, level_map, -MAGNITUDE_RANGE_DB, 0, f"{label}: magnitude")
        error_drawn = show(axes[row, 2], signed_error_cm(cell), error_map, -SIGNED_ERROR_LIMIT_CM,
                           SIGNED_ERROR_LIMIT_CM, f"{label}: depth - ground truth")
        axes[row, 2].imshow(no_error_categories(cell), extent=truth.extent_cm, cmap=overlay_map, vmin=0, vmax=1,
                            interpolation="nearest")
    for (row, col), ax in np.ndenumerate(axes):       # one window for every map: labels on the outer axes only
        ax.set(xlim=xlim, ylim=ylim)
        ax.tick_params(labelleft=col == 0, labelbottom=row == len(cells))
        if col == 0:
            ax.set_ylabel("y (cm)", fontsize=7)
        if row == len(cells):
            ax.set_xlabel("x (cm)", fontsize=7)
    key = axes[0, 2]
    key.set_axis_off()
    key.legend(handles=[Patch(color=NO_DEPTH_COLOUR, label="no depth (filtered or not returned)"),
                        Patch(color=NO_TRUTH_COLOUR, label="depth where the ground truth has no surface"),
                        Patch(color=error_map(1.0), label="error > 0: behind the surface"),
                        Patch(color=error_map(0.0), label="error < 0: in front of it")],
               loc="upper center", fontsize=7, frameon=False, borderaxespad=0)
    for number, (drawn, bar_label, extend) in enumerate((
            (depth_drawn, "depth z (cm)", "neither"),
            (level_drawn if cells else depth_drawn, "magnitude (dB re strongest pixel)", "min"),
            (error_drawn if cells else depth_drawn, f"signed error (cm), saturates at ±{SIGNED_ERROR_LIMIT_CM:g}",
             "both"))):
        bar = fig.colorbar(drawn, cax=key.inset_axes((0.05, 0.52 - 0.24 * number, 0.9, 0.05)),
                           orientation="horizontal", extend=extend)
        bar.set_label(bar_label, fontsize=7)
        bar.ax.tick_params(labelsize=7)
        bar.ax.xaxis.set_major_locator(MaxNLocator(5))
    fig.suptitle(f"{stem}: depth, magnitude and signed error per method (x, y in cm, radar space)", fontsize=9,
                 y=1 - 0.1 / fig.get_size_inches()[1], va="top")
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _capture_pictures(runs: list[tuple[str, Path]], stem: str, out_dir: Path, prior_m: np.ndarray | None,
                      ply: bool, use: str) -> dict[str, Path]:
    """Both figures (and the PLY files) of one capture; runs in a worker process of sweep_pictures."""
    cells = [(label, arrays) for label, path in runs if (arrays := read_arrays(path, stem)) is not None]
    files = picture_files(out_dir, stem)
    return {"point_clouds": point_cloud_figure(cells, stem, files["point_clouds"],
                                               out_dir / "point_clouds" if ply else None, use=use),
            "panel": capture_panel(cells, stem, files["panel"], prior_m)}


def _key(runs: list[tuple[str, Path]], stem: str, prior_m: np.ndarray | None, ply: bool, use: str) -> str:
    """Content key of one capture's pictures: the cells' labels and arrays, the prior, the options and this code."""
    parts = [stem, ply, use, Path(__file__)]
    for label, path in runs:
        arrays = read_arrays(path, stem)
        if arrays is not None:
            parts += [label, arrays.depth_m, arrays.gt_depth_m, arrays.magnitude, arrays.x_m, arrays.y_m]
    return keyed.digest(*parts, prior_m if prior_m is not None else "no prior")


def picture_files(out_dir: Path, stem: str) -> dict[str, Path]:
    """Where the pictures of capture `stem` go under `out_dir`."""
    return {"point_clouds": out_dir / "point_clouds" / f"{stem}.png", "panel": out_dir / "panels" / f"{stem}.png"}


def sweep_pictures(runs: list[tuple[str, Path]], out_dir: Path, priors: dict[str, np.ndarray] | None = None,
                   ply: bool = True, workers: int | None = None) -> dict[str, dict[str, Path]]:
    """Point-cloud figures (+ PLY) and panels of every capture of the runs ((label, arrays.h5) pairs) under
    `out_dir/point_clouds/` and `out_dir/panels/`; returns {stem: {"point_clouds": png, "panel": png}}. A capture
    whose inputs (arrays, labels, prior, options, this module) are unchanged since it was drawn is not redrawn
    (bench.report.keyed); the others are drawn in `workers` processes (default: one per CPU core)."""
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor

    from bench.progress import bar

    use = renderer()
    stems = capture_stems([path for _, path in runs])
    keys = keyed.Keys(out_dir)
    wanted = {stem: _key(runs, stem, (priors or {}).get(stem), ply, use) for stem in stems}
    stale = [stem for stem in stems if not keys.fresh(stem, wanted[stem], list(picture_files(out_dir, stem).values()))]
    written = {stem: picture_files(out_dir, stem) for stem in stems}
    if not stale:
        return written
    workers = max(1, min(len(stale), workers or os.cpu_count() or 1))
    with bar(len(stale), f"pictures ({use}, {len(stems) - len(stale)} unchanged)", unit="capture") as progress, \
            ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn")) as pool:
        futures = {stem: pool.submit(_capture_pictures, runs, stem, out_dir, (priors or {}).get(stem), ply, use)
                   for stem in stale}
        for stem, future in futures.items():
            written[stem] = future.result()
            keys.record(stem, wanted[stem])
            progress.update()
    return written
