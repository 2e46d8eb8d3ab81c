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
RINGS = (0.9, 1.4, 2.0, 2.8, 3.8, 5.0, 6.5, 8.0)  # candidate distances from the anchor, in label heights
DIRECTIONS = 24


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
    _arrays: tuple[np.ndarray, ...] | None = None  # segments and circles as arrays (made at the first query)

    def hits(self, boxes: np.ndarray) -> np.ndarray:
        """How many obstacles each of ``boxes`` (K × (x0, y0, x1, y1)) meets."""
        if self._arrays is None:
            self._arrays = _stack(self)
        sa, sb, sw, cc, cr = self._arrays
        boxes = np.asarray(boxes, float).reshape(-1, 4)
        n = np.count_nonzero(_box_circles(boxes, cc, cr + PAD), axis=1)
        n += np.count_nonzero(_box_segments(boxes, sa, sb, sw + PAD), axis=1)
        centres = 0.5 * (boxes[:, :2] + boxes[:, 2:])
        for poly in self.polygons:
            n += _inside(centres, poly)
        if self.boxes:
            b = np.array(self.boxes)
            n += np.count_nonzero(
                (boxes[:, None, 0] < b[None, :, 2] + PAD)
                & (b[None, :, 0] < boxes[:, None, 2] + PAD)
                & (boxes[:, None, 1] < b[None, :, 3] + PAD)
                & (b[None, :, 1] < boxes[:, None, 3] + PAD),
                axis=1,
            )
        return n


def _stack(obs: Obstacles) -> tuple[np.ndarray, ...]:
    seg = obs.segments
    a = np.array([s[0] for s in seg]).reshape(-1, 2)
    b = np.array([s[1] for s in seg]).reshape(-1, 2)
    w = np.array([s[2] for s in seg], float)
    c = np.array([x[0] for x in obs.circles]).reshape(-1, 2)
    r = np.array([x[1] for x in obs.circles], float)
    return a, b, w, c, r


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
        textcoords="offset points",  # not pixels: the offset must hold at any dpi (an SVG or PDF is saved at 72)
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
    phi = math.pi / 4 + 2 * math.pi * np.arange(DIRECTIONS) / DIRECTIONS  # up and to the right first
    best, best_hits = None, math.inf
    for ring in RINGS:
        r = ring * max(h, 8.0) + 0.3 * w
        c = a + r * np.column_stack([np.cos(phi), np.sin(phi)])
        boxes = np.column_stack([c[:, 0] - w / 2, c[:, 1] - h / 2, c[:, 0] + w / 2, c[:, 1] + h / 2])
        hits = obs.hits(boxes)
        k = int(np.argmin(hits))  # the first of the least crowded
        if hits[k] < best_hits:
            best, best_hits = (c[k] - a, boxes[k]), int(hits[k])
        if best_hits == 0:
            break
    offset, box = best
    art.xyann = tuple(float(x) * 72.0 / ax.figure.dpi for x in offset)
    obs.boxes.append(box)
    return art


def _box_circles(boxes: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """(K, M): whether box k meets circle m."""
    x0, y0, x1, y1 = (boxes[:, i, None] for i in range(4))
    dx = np.maximum(np.maximum(x0 - c[None, :, 0], 0.0), c[None, :, 0] - x1)
    dy = np.maximum(np.maximum(y0 - c[None, :, 1], 0.0), c[None, :, 1] - y1)
    return dx * dx + dy * dy < r[None, :] ** 2


def _box_segments(boxes: np.ndarray, a: np.ndarray, b: np.ndarray, grow: np.ndarray) -> np.ndarray:
    """(K, N): whether segment n meets box k grown by ``grow[n]`` (Liang–Barsky clipping, all at once)."""
    lo = boxes[:, None, :2] - grow[None, :, None]
    hi = boxes[:, None, 2:] + grow[None, :, None]
    d = np.broadcast_to(b - a, lo.shape)
    a = np.broadcast_to(a, lo.shape)
    t0, t1 = np.zeros(lo.shape[:2]), np.ones(lo.shape[:2])
    ok = np.ones(lo.shape[:2], bool)
    for axis in (0, 1):
        for p, q in ((-d[..., axis], a[..., axis] - lo[..., axis]), (d[..., axis], hi[..., axis] - a[..., axis])):
            zero = p == 0
            ok &= ~(zero & (q < 0))
            t = q / np.where(zero, 1.0, p)
            t0 = np.where(~zero & (p < 0), np.maximum(t0, t), t0)
            t1 = np.where(~zero & (p > 0), np.minimum(t1, t), t1)
    return ok & (t0 <= t1)


def _inside(points: np.ndarray, poly: np.ndarray) -> np.ndarray:
    """Whether each point lies inside the polygon (even-odd rule)."""
    x, y = poly[None, :, 0], poly[None, :, 1]
    xj, yj = np.roll(poly[:, 0], 1)[None, :], np.roll(poly[:, 1], 1)[None, :]
    px, py = points[:, 0, None], points[:, 1, None]
    dy = np.where(yj - y == 0, 1e-300, yj - y)
    crossing = ((y > py) != (yj > py)) & (px < (xj - x) * (py - y) / dy + x)
    return np.count_nonzero(crossing, axis=1) % 2 == 1
