"""A small raster figure drawn with Pillow: panels with a frame, round-number ticks, lines, a log
axis whose bottom decade stands for exact zeros, and image panels; saved as PNG.

Why not matplotlib for a run's figure: importing ``matplotlib.figure`` costs 0.4-0.5 s of CPU and
building and drawing the ticks of nine axes another 0.3-0.5 s, as much as the whole march of
``paper_pendulum`` (issue 19 asks the figure to cost at most a fifth of a warm run). The lines
arrive already reduced to their min/max envelope per pixel column (``plotting.envelope``), so
what a figure library would add is axes, ticks and text, which this module draws directly: one
Pillow image, one FreeType font, no layout engine. The other figures of the package (grids,
comparisons, periodic orbits) stay with matplotlib; they are drawn once per study, not per run.
"""

from __future__ import annotations

import math

import numpy as np
from PIL import Image, ImageDraw, ImageFont

WHITE, INK, FRAME, GRID = (255, 255, 255), (20, 20, 20), (90, 90, 90), (232, 232, 232)
# Line colours, one per component (cycled): distinguishable on white and in grey print.
COLORS = ((31, 119, 180), (230, 120, 20), (44, 150, 44), (200, 40, 40), (140, 90, 180),
          (120, 80, 60), (220, 100, 180), (110, 110, 110))
TICK = 4  # tick length in pixels


def font(size: int):
    """Pillow's built-in FreeType font at ``size`` pixels (Pillow >= 10.1), else its bitmap
    font."""
    try:
        return ImageFont.load_default(size=size)
    except (TypeError, OSError, ImportError):  # an older Pillow, or one built without FreeType
        return ImageFont.load_default()


def nice_ticks(low: float, high: float, count: int = 4) -> np.ndarray:
    """Round values in ``[low, high]``, 1, 2 or 5 times a power of ten apart: the largest such
    step that gives at least ``count`` intervals."""
    if not (math.isfinite(low) and math.isfinite(high)) or high <= low:
        return np.array([low]) if math.isfinite(low) else np.zeros(0)
    raw = (high - low) / count
    power = 10.0 ** math.floor(math.log10(raw))
    step = max(m * power for m in (1, 2, 5) if m * power <= raw * (1 + 1e-9))
    ticks = np.arange(math.ceil(low / step - 1e-9), math.floor(high / step + 1e-9) + 1) * step
    return np.where(np.abs(ticks) < step * 1e-9, 0.0, ticks)


def tick_labels(ticks: np.ndarray) -> tuple[list[str], str]:
    """Labels of equally spaced ticks and an offset to add to them (``""`` if none): integers,
    fixed decimals down to the step, short scientific notation for very large or small values,
    and, when the ticks differ only far behind the point (a step constant to 1e-12), their
    differences from a round value written once as the offset."""
    if ticks.size == 0:
        return [], ""
    step = float(np.min(np.diff(ticks))) if ticks.size > 1 else max(abs(float(ticks[0])), 1.0)
    largest = float(np.max(np.abs(ticks)))
    if ticks.size > 1 and step < 1e-4 * largest:
        offset = float(f"{float(ticks[0]):.{max(1, math.ceil(math.log10(largest / step)) - 1)}g}")
        deltas = np.where(np.abs(ticks - offset) < 1e-3 * step, 0.0, ticks - offset)
        return [f"{d:+.2g}" if d else "0" for d in deltas], f"{offset:.12g} +"
    if largest >= 1e6 or (step < 1e-4 and largest > 0):
        return [f"{v:.2g}" for v in ticks], ""
    decimals = max(0, -math.floor(math.log10(step) + 1e-9))
    return [f"{v:.{decimals}f}" for v in ticks], ""


class Canvas:
    """A white RGB image with a text helper that places text by an anchor on its box (the same
    on FreeType and bitmap fonts)."""

    def __init__(self, width: int, height: int, font_size: int = 13):
        self.image = Image.new("RGB", (width, height), WHITE)
        self.draw = ImageDraw.Draw(self.image)
        self.font = font(font_size)
        self.small = font(max(font_size - 2, 8))

    def text(self, x: float, y: float, text: str, anchor: str = "lt", *, small=False,
             fill=INK) -> tuple[int, int, int, int]:
        """Draw ``text`` with its box's point ``anchor`` (horizontal l/m/r, vertical t/m/b) at
        ``(x, y)``; return the box."""
        face = self.small if small else self.font
        left, top, right, bottom = self.draw.textbbox((0, 0), text, font=face)
        width, height = right - left, bottom - top
        x0 = x - {"l": 0, "m": width / 2, "r": width}[anchor[0]] - left
        y0 = y - {"t": 0, "m": height / 2, "b": height}[anchor[1]] - top
        self.draw.text((x0, y0), text, font=face, fill=fill)
        return (int(x0 + left), int(y0 + top), int(x0 + right), int(y0 + bottom))

    def vertical_text(self, x: float, y: float, text: str) -> None:
        """``text`` turned a quarter left, centred at ``(x, y)``."""
        left, top, right, bottom = self.draw.textbbox((0, 0), text, font=self.font)
        label = Image.new("L", (right - left + 2, bottom - top + 2), 0)
        ImageDraw.Draw(label).text((1 - left, 1 - top), text, font=self.font, fill=255)
        label = label.rotate(90, expand=True)
        position = (int(x - label.width / 2), int(y - label.height / 2))
        self.image.paste(Image.new("RGB", label.size, INK), position, label)

    def save(self, path) -> None:
        # a low zlib level: the image is mostly white and compresses well at any level
        self.image.save(path, format="PNG", compress_level=3)


class Panel:
    """A rectangle of the canvas with data limits: maps data to pixels and draws on it."""

    def __init__(self, canvas: Canvas, box: tuple[int, int, int, int], xlim, ylim,
                 *, log: bool = False):
        self.canvas, self.box, self.log = canvas, box, log
        self.xlim = _widened(*xlim)
        self.ylim = (math.log10(ylim[0]), math.log10(ylim[1])) if log else _widened(*ylim)

    @property
    def width(self) -> int:
        return self.box[2] - self.box[0]

    def px(self, x) -> np.ndarray:
        left, _, right, _ = self.box
        low, high = self.xlim
        return left + (np.asarray(x, float) - low) / (high - low) * (right - left)

    def py(self, y) -> np.ndarray:
        _, top, _, bottom = self.box
        y = np.asarray(y, float)
        if self.log:
            y = np.log10(np.maximum(y, 10.0 ** self.ylim[0]))
        low, high = self.ylim
        return bottom - (y - low) / (high - low) * (bottom - top)

    def line(self, x, y, color, width: int = 1) -> None:
        """A polyline through the finite points, broken where a value is not finite."""
        xs, ys = self.px(x), self.py(y)
        finite = np.isfinite(xs) & np.isfinite(ys)
        breaks = np.flatnonzero(np.diff(finite.astype(np.int8))) + 1
        for run in np.split(np.arange(xs.size), breaks):
            if run.size and finite[run[0]]:
                points = np.column_stack([xs[run], ys[run]]).ravel().tolist()
                if run.size == 1:
                    points += points
                self.canvas.draw.line(points, fill=color, width=width)

    def dot(self, x: float, y: float, color, radius: int = 3) -> None:
        cx, cy = float(self.px(x)), float(self.py(y))
        self.canvas.draw.ellipse((cx - radius, cy - radius, cx + radius, cy + radius),
                                 fill=color)

    def image(self, rgb: np.ndarray) -> None:
        """An ``(rows, columns, 3)`` uint8 image over the whole panel, row 0 at the top,
        scaled to the panel by repeating pixels (no smoothing)."""
        left, top, right, bottom = self.box
        picture = Image.fromarray(rgb, "RGB").resize((right - left, bottom - top),
                                                      Image.NEAREST)
        self.canvas.image.paste(picture, (left, top))

    def frame(self, *, x_labels: bool = True, y_ticks=None, y_labels=None, grid=True) -> None:
        """Frame, ticks and their labels: round-number ticks on a linear axis, the given ones
        (``y_ticks`` with ``y_labels``) otherwise."""
        draw, (left, top, right, bottom) = self.canvas.draw, self.box
        x_ticks = nice_ticks(*self.xlim)
        if y_ticks is None:
            y_ticks = nice_ticks(*self.ylim, count=3)
            y_labels, offset = tick_labels(y_ticks)
            if offset:
                self.canvas.text(left + 2, top + 2, offset, "lt", small=True)
        for value in x_ticks:
            x = float(self.px(value))
            if grid:
                draw.line((x, top, x, bottom), fill=GRID)
            draw.line((x, bottom, x, bottom + TICK), fill=FRAME)
        for value, label in zip(y_ticks, y_labels, strict=True):
            y = float(self.py(value))
            if grid:
                draw.line((left, y, right, y), fill=GRID)
            draw.line((left - TICK, y, left, y), fill=FRAME)
            self.canvas.text(left - TICK - 2, y, label, "rm", small=True)
        if x_labels:
            x_labels, offset = tick_labels(x_ticks)
            if offset:
                self.canvas.text(right, bottom + TICK + 16, offset, "rt", small=True)
            for value, label in zip(x_ticks, x_labels, strict=True):
                self.canvas.text(float(self.px(value)), bottom + TICK + 2, label, "mt",
                                 small=True)
        draw.rectangle(self.box, outline=FRAME)

    def legend(self, names, colors) -> None:
        """Short line samples and names in the panel's top right corner, on white."""
        x, y = self.box[2] - 6, self.box[1] + 4
        for name, color in reversed(list(zip(names, colors, strict=True))):
            box = self.canvas.text(x, y, name, "rt", small=True)
            self.canvas.draw.rectangle((box[0] - 22, box[1] - 1, box[2] + 1, box[3] + 1),
                                       fill=WHITE)
            self.canvas.text(x, y, name, "rt", small=True)
            middle = (box[1] + box[3]) / 2
            self.canvas.draw.line((box[0] - 19, middle, box[0] - 4, middle), fill=color,
                                  width=2)
            x = box[0] - 30


def _widened(low: float, high: float) -> tuple[float, float]:
    """Limits with a little room, and a span even when all values are equal."""
    if not (math.isfinite(low) and math.isfinite(high)):
        return (0.0, 1.0)
    if high <= low:
        half = max(abs(low) * 0.05, 1e-12)
        return (low - half, high + half)
    pad = 0.04 * (high - low)
    return (low - pad, high + pad)


def colormap(values: np.ndarray) -> np.ndarray:
    """Values in ``[0, 1]`` (NaN: white) to RGB on a ramp from light yellow-green through teal
    to dark blue: few visits light, many dark."""
    stops = np.array([[0.0, 225, 232, 120], [0.35, 90, 190, 140], [0.7, 40, 110, 160],
                      [1.0, 35, 30, 90]])
    clipped = np.clip(np.nan_to_num(values, nan=0.0), 0.0, 1.0)
    rgb = np.stack([np.interp(clipped, stops[:, 0], stops[:, k]) for k in (1, 2, 3)], axis=-1)
    rgb[np.isnan(values)] = WHITE
    return rgb.astype(np.uint8)
