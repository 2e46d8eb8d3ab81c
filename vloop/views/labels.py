"""Labels placed clear of a drawing's geometry, in display coordinates (pixels).

Once the geometry is drawn and the axes' limits are fixed, every line and patch of the axes is an obstacle
(a line as segments as thick as it is drawn, a circle as a circle, a polygon as its outline and inside); each
label then takes the first of its candidate places — around its anchor, nearest first — whose box meets no
obstacle and no label placed before it, and becomes an obstacle itself. A label that finds no clear place
takes the least crowded one. Text is drawn as written (``parse_math=False``: ``$5 and $10`` is not math) and
without control characters (:func:`clean`).
"""

from __future__ import annotations

import math
import unicodedata
from dataclasses import dataclass, field
from typing import Any

import numpy as np

PAD = 2.0  # px between a label's box and anything else
RINGS = (0.9, 1.4, 2.0, 2.8, 3.8, 5.0)  # candidate distances from the anchor, in label heights
DIRECTIONS = 16


def clean(text: str) -> str:
    """``text`` without control, surrogate, private-use or non-characters (an SVG must stay well-formed XML)."""
    keep = []
    for ch in str(text):
        cat = unicodedata.category(ch)
        if cat in ("Cc", "Cs", "Co", "Cn") or (0xFDD0 <= ord(ch) <= 0xFDEF) or (ord(ch) & 0xFFFE) == 0xFFFE:
            continue
        keep.append(ch)
    return "".join(keep)


@dataclass
class Obstacles:
    """Shapes in pixels: segments (a, b, half width), circles (centre, radius), polygons, label boxes."""

    segments: list[tuple[np.ndarray, np.ndarray, float]] = field(default_factory=list)
    circles: list[tuple[np.ndarray, float]] = field(default_factory=list)
    polygons: list[np.ndarray] = field(default_factory=list)
    boxes: list[np.ndarray] = field(default_factory=list)  # (x0, y0, x1, y1)

    def hits(self, box: np.ndarray) -> int:
        """How many obstacles ``box`` (x0, y0, x1, y1) meets."""
        n = sum(_box_circle(box, c, r + PAD) for c, r in self.circles)
        n += sum(_box_segment(box, a, b, hw + PAD) for a, b, hw in self.segments)
        n += sum(_box_polygon(box, p) for p in self.polygons)
        n += sum(_box_box(box, b) for b in self.boxes)
        return n


def obstacles(ax: Any, skip: tuple[str, ...] = ("label",)) -> Obstacles:
    """Every line and patch of ``ax`` (artists whose gid is in ``skip`` excepted), in pixels."""
    from matplotlib.patches import Circle

    obs = Obstacles()
    px = ax.figure.dpi / 72.0
    for line in ax.lines:
        if line.get_gid() in skip or not line.get_visible():
            continue
        xy = line.get_transform().transform(np.column_stack(line.get_data()))
        hw = 0.5 * line.get_linewidth() * px
        obs.segments += [(xy[i], xy[i + 1], hw) for i in range(len(xy) - 1)]
    for patch in ax.patches:
        if patch.get_gid() in skip:
            continue
        if isinstance(patch, Circle):
            c = patch.get_transform().transform(np.array([[0.0, 0.0], [1.0, 0.0]]))  # unit circle in its transform
            obs.circles.append((c[0], float(np.linalg.norm(c[1] - c[0])) + 0.5 * patch.get_linewidth() * px))
        else:
            verts = patch.get_transform().transform(patch.get_path().vertices)
            obs.polygons.append(verts)
            hw = 0.5 * patch.get_linewidth() * px
            obs.segments += [(verts[i], verts[i + 1], hw) for i in range(len(verts) - 1)]
    return obs


def place(ax: Any, text: str, anchor: tuple[float, float], obs: Obstacles, renderer: Any, **style: Any) -> Any:
    """Annotate ``text`` near ``anchor`` (data coordinates) at the nearest clear place; returns the Text artist."""
    art = ax.annotate(
        clean(text),
        anchor,
        xytext=(0, 0),
        textcoords="offset pixels",
        ha="center",
        va="center",
        annotation_clip=False,
        parse_math=False,
        gid="label",
        **style,
    )
    bb = art.get_window_extent(renderer)
    w, h = bb.width, bb.height
    a = ax.transData.transform(anchor)
    best, best_hits = None, math.inf
    for ring in RINGS:
        r = ring * max(h, 8.0) + 0.5 * w * 0.6
        for k in range(DIRECTIONS):
            phi = math.pi / 4 + 2 * math.pi * k / DIRECTIONS  # up and to the right first
            c = a + r * np.array([math.cos(phi), math.sin(phi)])
            box = np.array([c[0] - w / 2, c[1] - h / 2, c[0] + w / 2, c[1] + h / 2])
            hits = obs.hits(box)
            if hits < best_hits:
                best, best_hits = (c - a, box), hits
            if hits == 0:
                break
        if best_hits == 0:
            break
    offset, box = best
    art.xyann = (float(offset[0]), float(offset[1]))
    obs.boxes.append(box)
    return art


def _box_box(a: np.ndarray, b: np.ndarray) -> bool:
    return bool(a[0] < b[2] + PAD and b[0] < a[2] + PAD and a[1] < b[3] + PAD and b[1] < a[3] + PAD)


def _box_circle(box: np.ndarray, c: np.ndarray, r: float) -> bool:
    dx = max(box[0] - c[0], 0.0, c[0] - box[2])
    dy = max(box[1] - c[1], 0.0, c[1] - box[3])
    return dx * dx + dy * dy < r * r


def _box_segment(box: np.ndarray, a: np.ndarray, b: np.ndarray, grow: float) -> bool:
    """Whether segment a-b meets the box grown by ``grow`` (Liang–Barsky clipping)."""
    x0, y0, x1, y1 = box[0] - grow, box[1] - grow, box[2] + grow, box[3] + grow
    d = b - a
    t0, t1 = 0.0, 1.0
    for p, q in ((-d[0], a[0] - x0), (d[0], x1 - a[0]), (-d[1], a[1] - y0), (d[1], y1 - a[1])):
        if p == 0:
            if q < 0:
                return False
            continue
        t = q / p
        if p < 0:
            t0 = max(t0, t)
        else:
            t1 = min(t1, t)
        if t0 > t1:
            return False
    return True


def _box_polygon(box: np.ndarray, poly: np.ndarray) -> bool:
    """Whether the box's centre lies inside the polygon (its edges are segments of their own)."""
    cx, cy = 0.5 * (box[0] + box[2]), 0.5 * (box[1] + box[3])
    x, y = poly[:, 0], poly[:, 1]
    xj, yj = np.roll(x, 1), np.roll(y, 1)
    cross = ((y > cy) != (yj > cy)) & (cx < (xj - x) * (cy - y) / np.where(yj - y == 0, 1e-300, yj - y) + x)
    return bool(np.count_nonzero(cross) % 2)
