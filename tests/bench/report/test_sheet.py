"""bench.report.sheet: splats against a plain per-point z-buffer, maps resampled by nearest pixel, tick positions
and labels against matplotlib's own axes, and a drawn figure holding its views where its boxes say."""
from __future__ import annotations

import matplotlib
import numpy as np
import pytest

from bench.report import sheet

matplotlib.use("Agg")


def _seeded():
    seed = int(np.random.default_rng().integers(1 << 31))              # fresh inputs each run, the seed printed
    print(f"seed {seed}")
    return np.random.default_rng(seed)


def test_a_splat_puts_each_point_at_its_pixel():
    rng = _seeded()
    col, row = rng.uniform(-5, 45, 300), rng.uniform(-5, 35, 300)     # some outside the 40 x 30 tile: clipped
    rgb = rng.integers(0, 255, (300, 3), dtype=np.uint8)
    _, on_pixel, count = np.unique(np.floor(col) + 1000 * np.floor(row), return_inverse=True, return_counts=True)
    lone = np.flatnonzero(count[on_pixel] == 1)
    tile = sheet.splat(np.zeros((30, 40, 3), np.uint8), col, row, rng.uniform(size=300), rgb, radius_px=0.0)
    inside = (col >= 0) & (col < 40) & (row >= 0) & (row < 30)
    for k in lone[inside[lone]]:                                        # a point alone on its pixel shows its colour
        np.testing.assert_array_equal(tile[int(row[k]), int(col[k])], rgb[k])
    painted = np.zeros((30, 40), bool)
    painted[np.floor(row[inside]).astype(int), np.floor(col[inside]).astype(int)] = True
    assert (tile.any(axis=2) <= painted).all()                          # nothing painted elsewhere


@pytest.mark.parametrize("radius_px", [0.0, 1.0, 1.5, 2.5])
def test_the_nearest_point_wins_where_dots_overlap(radius_px):
    """Against a plain z-buffer: every point visits its disc's pixels, keeping the nearest (ties: the earlier)."""
    rng = _seeded()
    n, height, width = 400, 12, 15                                      # crowded: most pixels hold several dots
    col, row = rng.uniform(0, width, n), rng.uniform(0, height, n)
    distance = rng.permutation(n).astype(float)                         # distinct distances: one right answer
    rgb = rng.integers(1, 255, (n, 3), dtype=np.uint8)
    tile = sheet.splat(np.zeros((height, width, 3), np.uint8), col, row, distance, rgb, radius_px)
    nearest = np.full((height, width), np.inf)
    expected = np.zeros((height, width, 3), np.uint8)
    reach = int(radius_px)
    for k in range(n):
        for dy in range(-reach, reach + 1):
            for dx in range(-reach, reach + 1):
                y, x = int(np.floor(row[k])) + dy, int(np.floor(col[k])) + dx
                if dx * dx + dy * dy <= radius_px ** 2 and 0 <= y < height and 0 <= x < width \
                        and distance[k] < nearest[y, x]:
                    nearest[y, x], expected[y, x] = distance[k], rgb[k]
    np.testing.assert_array_equal(tile, expected)


def test_a_map_resampled_to_its_own_window_and_size_is_itself_and_upsampled_repeats_pixels():
    rng = _seeded()
    values = rng.normal(size=(7, 9))
    extent = (-4.5, 4.5, -3.5, 3.5)                                     # 1 unit pixels, row 0 at the top
    same, inside = sheet.map_pixels(values, extent, (-4.5, 4.5), (-3.5, 3.5), 9, 7)
    np.testing.assert_array_equal(same, values)
    assert inside.all()
    up, _ = sheet.map_pixels(values, extent, (-4.5, 4.5), (-3.5, 3.5), 27, 21)
    np.testing.assert_array_equal(up, np.kron(values, np.ones((3, 3))))
    wide, inside = sheet.map_pixels(values, extent, (-9.0, 9.0), (-3.5, 3.5), 18, 7)   # a window twice as wide
    assert np.isnan(wide[:, :4]).all() and np.isnan(wide[:, -5:]).all() and not inside[:, :4].any()
    np.testing.assert_array_equal(wide[:, 4:13], values)


def test_ticks_and_labels_are_those_of_a_matplotlib_axis():
    import matplotlib.pyplot as plt

    rng = _seeded()
    fig = plt.figure(figsize=(4, 4), dpi=100)
    try:
        for _ in range(25):
            length_px, label_pt = int(rng.integers(60, 400)), float(rng.choice([7, 8, 10]))
            lo = float(rng.uniform(-50, 50))
            hi = lo + float(10 ** rng.uniform(0, 2))                    # spans 1 to 100: no offset notation
            ax = fig.add_axes((0.05, 0.05, length_px / 400, length_px / 400))
            ax.tick_params(labelsize=label_pt)
            ax.set_xlim(lo, hi)
            ax.set_ylim(lo, hi)
            fig.canvas.draw()
            for axis, ticks, labels in (("x", ax.get_xticks(), ax.get_xticklabels()),
                                        ("y", ax.get_yticks(), ax.get_yticklabels())):
                shown = (ticks >= lo) & (ticks <= hi)
                mine = sheet.tick_values(lo, hi, length_px * 72 / 100, label_pt, axis)
                np.testing.assert_allclose(mine, ticks[shown], rtol=0, atol=1e-9 * (hi - lo))
                assert sheet.tick_labels(mine) == [t.get_text() for t, s in zip(labels, shown, strict=True) if s]
            ax.remove()
    finally:
        plt.close(fig)


def test_a_figure_holds_its_views_where_its_boxes_say(tmp_path):
    from PIL import Image

    page = sheet.Sheet(300, 200, dpi=100)
    boxes = sheet.grid(sheet.Box(40, 30, 240, 140), 1, 2, hspace=0.2, wspace=0.6)   # room for the labels
    red = np.zeros((boxes[0][0].height, boxes[0][0].width, 3), np.uint8)
    red[..., 0] = 255
    page.paste(red, boxes[0][0])
    page.axes(boxes[0][1], (0.0, 1.0), (0.0, 1.0), title="a title", xlabel="x", ylabel="y")
    image = np.asarray(Image.open(page.save(tmp_path / "sheet.png")).convert("RGB"))
    assert image.shape == (200, 300, 3)
    box = boxes[0][0]
    np.testing.assert_array_equal(image[box.top:box.bottom, box.left:box.right], red)
    framed = boxes[0][1]
    assert (image[framed.top - 1, framed.left:framed.right] == 0).all()   # the frame's top edge, black
    assert (image[framed.top + 1:framed.bottom - 1, framed.left + 1:framed.right - 1] == 255).all()   # empty inside
    assert (image[:framed.top - 2, framed.left:framed.right] < 128).any()   # the title above it
