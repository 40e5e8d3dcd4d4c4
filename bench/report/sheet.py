"""Figures drawn straight into pixels: views as RGB arrays pasted onto one canvas, with axes frames, ticks, colour
bars, legends and text drawn by Pillow (matplotlib's own font, tick positions and colour maps).

The report's per-capture pictures have 40-90 small views each. As matplotlib axes, their tick objects, title layout
and per-point scatter paths cost 4-5 s of CPU per capture (docs/measurements/sweep.md, 2026-11-26 06:40); here a
view is an array (points splatted with a depth test, `splat`; a map resampled to its box, `map_pixels`) and a figure
costs about a tenth of a second.

Pixel conventions: a Box is (left, top, width, height) in canvas pixels; inside a view of width w, the data range
(lo, hi) spans columns 0..w (column j covers [lo + j (hi - lo) / w, lo + (j + 1) (hi - lo) / w)), rows run downwards
from the top of the y range.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
from matplotlib.ticker import MaxNLocator
from PIL import Image, ImageDraw, ImageFont

TICK_STEPS = (1, 2, 2.5, 5, 10)         # matplotlib's AutoLocator steps
TICK_LENGTH_PT = 3.5                    # matplotlib's default major tick length and label pad
TITLE_PAD_PT = 6.0                      # matplotlib's axes title pad
WHITE = (255, 255, 255)


@dataclass(frozen=True)
class Box:
    """A rectangle of the canvas in pixels."""
    left: int
    top: int
    width: int
    height: int

    @property
    def right(self) -> int:
        return self.left + self.width

    @property
    def bottom(self) -> int:
        return self.top + self.height

    def fit(self, aspect: float) -> Box:
        """The largest box of width / height = `aspect` centred in this one (equal scales on both axes)."""
        width = min(self.width, round(self.height * aspect))
        height = min(self.height, round(self.width / aspect))
        return Box(self.left + (self.width - width) // 2, self.top + (self.height - height) // 2, max(width, 1),
                   max(height, 1))


def grid(canvas: Box, rows: int, cols: int, hspace: float, wspace: float) -> list[list[Box]]:
    """rows x cols boxes over `canvas` with gaps of `hspace` / `wspace` times a box's height / width (matplotlib's
    GridSpec geometry)."""
    width = canvas.width / (cols + wspace * (cols - 1))
    height = canvas.height / (rows + hspace * (rows - 1))
    return [[Box(round(canvas.left + c * width * (1 + wspace)), round(canvas.top + r * height * (1 + hspace)),
                 round(width), round(height)) for c in range(cols)] for r in range(rows)]


def to_pixels(values: np.ndarray, lo: float, hi: float, size_px: int, downwards: bool = False) -> np.ndarray:
    """Pixel coordinates (float; pixel k covers [k, k + 1)) of data values on an axis spanning (lo, hi) over
    size_px pixels; `downwards`: rows, where hi is at the top."""
    fraction = (np.asarray(values, np.float64) - lo) / (hi - lo)
    return (1.0 - fraction if downwards else fraction) * size_px


def splat(tile: np.ndarray, col_px: np.ndarray, row_px: np.ndarray, distance: np.ndarray, rgb: np.ndarray,
          radius_px: float) -> np.ndarray:
    """Paints points onto `tile` ((h, w, 3) uint8, in place) as discs of `radius_px` around the pixels holding
    (col_px, row_px); where discs overlap, the point with the smallest `distance` (from the viewer) wins; points
    outside the tile are clipped. `rgb`: (N, 3) uint8 colours. Returns the tile."""
    height, width = tile.shape[:2]
    reach = int(np.floor(radius_px))
    dy, dx = np.mgrid[-reach:reach + 1, -reach:reach + 1]
    disc = dx ** 2 + dy ** 2 <= radius_px ** 2
    rows = np.floor(np.asarray(row_px)).astype(np.int64)[:, None] + dy[disc][None, :]
    cols = np.floor(np.asarray(col_px)).astype(np.int64)[:, None] + dx[disc][None, :]
    inside = (rows >= 0) & (rows < height) & (cols >= 0) & (cols < width)
    pixel = (rows * width + cols)[inside]
    point = np.broadcast_to(np.arange(len(rows))[:, None], rows.shape)[inside]
    rank = np.empty(len(rows), np.int64)                                # 0 = the nearest point
    rank[np.argsort(np.asarray(distance), kind="stable")] = np.arange(len(rows))
    order = np.argsort(pixel * len(rows) + rank[point])                 # per pixel, the nearest point first
    pixel, point = pixel[order], point[order]
    first = np.ones(len(pixel), bool)
    first[1:] = pixel[1:] != pixel[:-1]
    tile.reshape(-1, 3)[pixel[first]] = np.asarray(rgb, np.uint8)[point[first]]
    return tile


def map_pixels(values: np.ndarray, extent: tuple[float, float, float, float], xlim: tuple[float, float],
               ylim: tuple[float, float], width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """A map (ny, nx; row 0 at the top of `extent` = (left, right, bottom, top)) resampled to a width x height view
    of the window xlim x ylim by nearest pixel: (values (height, width), NaN outside the map; inside: bool mask of
    the view pixels the map covers)."""
    ny, nx = values.shape
    left, right, bottom, top = extent
    x = xlim[0] + (np.arange(width) + 0.5) / width * (xlim[1] - xlim[0])
    y = ylim[1] - (np.arange(height) + 0.5) / height * (ylim[1] - ylim[0])
    cols = np.floor((x - left) / (right - left) * nx).astype(np.int64)
    rows = np.floor((top - y) / (top - bottom) * ny).astype(np.int64)
    col_ok, row_ok = (cols >= 0) & (cols < nx), (rows >= 0) & (rows < ny)
    out = np.full((height, width), np.nan)
    out[np.ix_(row_ok, col_ok)] = values[np.ix_(rows[row_ok], cols[col_ok])]
    return out, row_ok[:, None] & col_ok[None, :]


def colours(values: np.ndarray, cmap, vmin: float, vmax: float) -> np.ndarray:
    """(..., 3) uint8 colours of `values` under a matplotlib colour map (its bad colour for NaN, its under / over
    colours beyond the range)."""
    with np.errstate(invalid="ignore"):
        return cmap((np.asarray(values, np.float64) - vmin) / (vmax - vmin), bytes=True)[..., :3]


def tick_values(lo: float, hi: float, length_pt: float, label_pt: float, axis: str, nbins: int | None = None
                ) -> np.ndarray:
    """Major tick positions inside (lo, hi) as matplotlib's AutoLocator places them on an axis of length_pt with
    tick labels of label_pt (at most 9 bins, one per 3 label sizes along x, 2 along y), or as MaxNLocator(nbins)."""
    if nbins is None:
        nbins = int(np.clip(np.floor(length_pt / (label_pt * (3 if axis == "x" else 2))), 1, 9))
        values = MaxNLocator(nbins, steps=list(TICK_STEPS)).tick_values(min(lo, hi), max(lo, hi))
    else:                                   # MaxNLocator(nbins) as set on a colour bar: its default steps
        values = MaxNLocator(nbins).tick_values(min(lo, hi), max(lo, hi))
    slack = 1e-9 * abs(hi - lo)
    return values[(values >= min(lo, hi) - slack) & (values <= max(lo, hi) + slack)]


def tick_labels(values: np.ndarray) -> list[str]:
    """Labels with the fewest decimals that write every value exactly, and a true minus sign (as matplotlib)."""
    values = np.asarray(values, np.float64)
    scale = max(1.0, float(np.abs(values).max())) if values.size else 1.0
    decimals = next((d for d in range(7) if np.allclose(values, np.round(values, d), rtol=0, atol=1e-9 * scale)), 6)
    return [f"{np.round(v, decimals) + 0.0:.{decimals}f}".replace("-", "\N{MINUS SIGN}") for v in values]


@functools.cache
def _font(size_px: int) -> ImageFont.FreeTypeFont:
    """DejaVu Sans (matplotlib's default font, shipped with it) at an em of size_px."""
    return ImageFont.truetype(str(Path(matplotlib.get_data_path()) / "fonts" / "ttf" / "DejaVuSans.ttf"), size_px)


class Sheet:
    """A white canvas of width_px x height_px at `dpi` (sizes of text and ticks are given in points, as in
    matplotlib)."""

    def __init__(self, width_px: int, height_px: int, dpi: float):
        self.dpi = dpi
        self.image = Image.new("RGB", (int(width_px), int(height_px)), WHITE)
        self.draw = ImageDraw.Draw(self.image)

    def px(self, points: float) -> int:
        return max(1, round(points * self.dpi / 72))

    def pt(self, pixels: float) -> float:
        return pixels * 72 / self.dpi

    def paste(self, rgb: np.ndarray, box: Box) -> None:
        """An (h, w, 3) uint8 array at the box's top left corner."""
        self.image.paste(Image.fromarray(np.ascontiguousarray(rgb, np.uint8)), (box.left, box.top))

    def text_width(self, text: str, size_pt: float) -> int:
        return int(np.ceil(self.draw.textlength(text, font=_font(self.px(size_pt)))))

    def text(self, xy: tuple[float, float], text: str, size_pt: float, anchor: str = "mm", fill=(0, 0, 0),
             rotated: bool = False) -> None:
        """`text` at xy (pixels) with a Pillow anchor (horizontal l/m/r, vertical t/m/s(baseline)/b of each line;
        several lines stack upwards from xy for a 's' or 'b' anchor, downwards otherwise); `rotated`: turned 90
        degrees anticlockwise, one line, centred at xy."""
        font = _font(self.px(size_pt))
        if rotated:
            left, top, right, bottom = font.getbbox(text)
            stamp = Image.new("L", (right - left + 2, bottom - top + 2), 0)
            ImageDraw.Draw(stamp).text((1 - left, 1 - top), text, fill=255, font=font)
            stamp = stamp.rotate(90, expand=True)
            corner = (round(xy[0] - stamp.width / 2), round(xy[1] - stamp.height / 2))
            self.image.paste(Image.new("RGB", stamp.size, fill), corner, mask=stamp)
            return
        lines = text.split("\n")
        step = round(1.2 * self.px(size_pt))
        upwards = anchor[1] in "sb"
        for number, line in enumerate(reversed(lines) if upwards else lines):
            y = xy[1] - number * step if upwards else xy[1] + number * step
            self.draw.text((xy[0], y), line, fill=fill, font=font, anchor=anchor)

    def axes(self, box: Box, xlim: tuple[float, float], ylim: tuple[float, float], title: str | None = None,
             xlabel: str | None = None, ylabel: str | None = None, x_labels: bool = True, y_labels: bool = True,
             tick_pt: float = 7, title_pt: float = 8) -> None:
        """A frame around the view `box` with outward ticks at AutoLocator's positions for the data window
        xlim x ylim (tick labels where asked), axis labels and a title above."""
        tick, pad, label_px = self.px(TICK_LENGTH_PT), self.px(TICK_LENGTH_PT), self.px(tick_pt)
        self.draw.rectangle((box.left - 1, box.top - 1, box.right, box.bottom), outline=(0, 0, 0))
        widest = 0
        for value, label in _ticks(xlim, self.pt(box.width), tick_pt, "x"):
            x = box.left + round(to_pixels(value, *xlim, box.width))
            self.draw.line(((x, box.bottom), (x, box.bottom + tick)), fill=(0, 0, 0))
            if x_labels:
                self.text((x, box.bottom + tick + pad), label, tick_pt, anchor="mt")
        for value, label in _ticks(ylim, self.pt(box.height), tick_pt, "y"):
            y = box.top + round(to_pixels(value, *ylim, box.height, downwards=True))
            self.draw.line(((box.left - 1 - tick, y), (box.left - 1, y)), fill=(0, 0, 0))
            if y_labels:
                self.text((box.left - 1 - tick - pad, y), label, tick_pt, anchor="rm")
                widest = max(widest, self.text_width(label, tick_pt))
        if xlabel:
            self.text((box.left + box.width / 2, box.bottom + tick + 2 * pad + label_px), xlabel, tick_pt, "mt")
        if ylabel:
            self.text((box.left - 1 - tick - 2 * pad - widest - label_px / 2, box.top + box.height / 2), ylabel,
                      tick_pt, rotated=True)
        if title:
            self.text((box.left + box.width / 2, box.top - self.px(TITLE_PAD_PT)), title, title_pt, anchor="ms")

    def colorbar(self, box: Box, cmap, vmin: float, vmax: float, label: str, vertical: bool = True,
                 extend: str = "neither", size_pt: float = 10, nbins: int | None = None) -> None:
        """A colour bar filling `box` (low values at the bottom or left), with triangles for the colours beyond
        the range where `extend` is 'min', 'max' or 'both', ticks and labels on the right or below, and `label`."""
        length = box.height if vertical else box.width
        ramp = colours(np.linspace(vmin, vmax, length + 1)[:-1] + (vmax - vmin) / length / 2, cmap, vmin, vmax)
        tile = np.repeat(ramp[::-1, None], box.width, 1) if vertical else np.repeat(ramp[None], box.height, 0)
        self.paste(tile, box)
        self.draw.rectangle((box.left - 1, box.top - 1, box.right, box.bottom), outline=(0, 0, 0))
        tip = round(0.05 * length)
        ends = {"min": extend in ("min", "both"), "max": extend in ("max", "both")}
        for end, shown in ends.items():
            if not shown:
                continue
            rgb = tuple(round(255 * c) for c in (cmap.get_under() if end == "min" else cmap.get_over())[:3])
            if vertical:
                base = box.bottom if end == "min" else box.top - 1
                apex = base + tip if end == "min" else base - tip
                shape = ((box.left - 1, base), (box.right, base), ((box.left + box.right) / 2, apex))
            else:
                base = box.left - 1 if end == "min" else box.right
                apex = base - tip if end == "min" else base + tip
                shape = ((base, box.top - 1), (base, box.bottom), (apex, (box.top + box.bottom) / 2))
            self.draw.polygon(shape, fill=rgb, outline=(0, 0, 0))
        tick, pad, label_px = self.px(TICK_LENGTH_PT), self.px(TICK_LENGTH_PT), self.px(size_pt)
        widest = 0
        for value, text in _ticks((vmin, vmax), self.pt(length), size_pt, "y" if vertical else "x", nbins):
            if vertical:
                y = box.top + round(to_pixels(value, vmin, vmax, box.height, downwards=True))
                self.draw.line(((box.right, y), (box.right + tick, y)), fill=(0, 0, 0))
                self.text((box.right + tick + pad, y), text, size_pt, anchor="lm")
                widest = max(widest, self.text_width(text, size_pt))
            else:
                x = box.left + round(to_pixels(value, vmin, vmax, box.width))
                self.draw.line(((x, box.bottom), (x, box.bottom + tick)), fill=(0, 0, 0))
                self.text((x, box.bottom + tick + pad), text, size_pt, anchor="mt")
        if vertical:
            self.text((box.right + tick + 2 * pad + widest + label_px / 2, box.top + box.height / 2), label, size_pt,
                      rotated=True)
        else:
            self.text((box.left + box.width / 2, box.bottom + tick + 2 * pad + label_px), label, size_pt, "mt")

    def legend(self, xy: tuple[int, int], entries: list[tuple[str, str]], size_pt: float, frame: bool = False,
               across: bool = False) -> None:
        """Colour patches and their labels from the top left corner `xy`, one per line (or side by side,
        `across`); entries: (colour, label) with matplotlib colour specifications."""
        size = self.px(size_pt)
        step, patch_w, patch_h = round(1.4 * size), 2 * size, round(0.7 * size)
        left, top = xy
        if frame:
            width = patch_w + size + max(self.text_width(label, size_pt) for _, label in entries) + size
            self.draw.rectangle((left, top, left + width, top + step * len(entries) + size // 2),
                                outline=(204, 204, 204), fill=WHITE)
            left, top = left + size // 2, top + size // 2
        x, y = left, top + step // 2
        for colour, label in entries:
            rgb = tuple(round(255 * c) for c in matplotlib.colors.to_rgb(colour))
            self.draw.rectangle((x, y - patch_h // 2, x + patch_w, y + patch_h // 2), fill=rgb)
            self.text((x + patch_w + size // 2, y), label, size_pt, anchor="lm")
            if across:
                x += patch_w + size // 2 + self.text_width(label, size_pt) + 2 * size
            else:
                y += step

    def legend_width(self, entries: list[tuple[str, str]], size_pt: float) -> int:
        """The width in pixels of `legend(..., across=True)`."""
        size = self.px(size_pt)
        return sum(2 * size + size // 2 + self.text_width(label, size_pt) + 2 * size for _, label in entries) - 2 * size

    def save(self, path: Path) -> Path:
        path.parent.mkdir(parents=True, exist_ok=True)
        self.image.save(path, dpi=(self.dpi, self.dpi))
        return path


def _ticks(limits: tuple[float, float], length_pt: float, label_pt: float, axis: str, nbins: int | None = None
           ) -> list[tuple[float, str]]:
    values = tick_values(*limits, length_pt, label_pt, axis, nbins)
    return list(zip(values, tick_labels(values), strict=True))
