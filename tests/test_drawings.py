"""Drawings (SVG, PDF): names clear of the geometry, a scale bar to scale, dimensions on request, any title.

Checked on the figure's own artists, independently of the placement code: each name's rendered box (matplotlib's
``get_window_extent``) against the bars' and rails' drawn strokes (points sampled along each segment at half a
pixel, the stroke's half width around them), the pins' and tracer points' circles, the slider blocks' and ground
symbols' outlines, and the other names' boxes. The scale bar's drawn length, in data units, is the number it is
labelled with; each dimension is the link's stated length. Titles with ``$`` signs, control characters and
characters outside XML are written as given (or without the characters XML cannot carry): the SVG parses as XML,
no warning is raised.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import warnings
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import vloop
from vloop.views.export import configuration, export, figure

from .conftest import MECHANISMS

STEMS = ["eightbar", "jansen_pair", "whitworth_quick_return", "sixbar_watt2", "slider_crank_offset"]


def _boxes(fig) -> list[tuple[str, np.ndarray]]:
    r = fig.canvas.get_renderer()
    ax = fig.axes[0]
    out = []
    for t in ax.texts:
        if t.get_gid() == "label":
            bb = t.get_window_extent(r)
            out.append((t.get_text(), np.array([bb.x0, bb.y0, bb.x1, bb.y1])))
    return out


def _strokes(ax) -> list[tuple[np.ndarray, float]]:
    """Every drawn line and patch outline as points half a pixel apart, with its half stroke width [px]."""
    from matplotlib.patches import Circle

    px = ax.figure.dpi / 72
    out = []
    shapes = [
        (ln.get_transform().transform(np.column_stack(ln.get_data())), ln.get_linewidth())
        for ln in ax.lines
        if ln.get_gid() != "scalebar"
    ]
    for p in ax.patches:
        verts = p.get_transform().transform(p.get_path().vertices)
        if isinstance(p, Circle):  # the whole disc: a pin's circle or a tracer point's dot
            c = p.get_transform().transform([[0, 0], [1, 0]])
            rad = np.hypot(*(c[1] - c[0]))
            g = np.linspace(-rad, rad, 15)
            xx, yy = np.meshgrid(g, g)
            keep = xx**2 + yy**2 <= rad**2
            out.append((np.column_stack([xx[keep], yy[keep]]) + c[0], 0.5 * p.get_linewidth() * px))
        shapes.append((verts, p.get_linewidth()))
    for xy, lw in shapes:
        pts = [xy[0]]
        for a, b in itertools.pairwise(xy):
            n = max(1, math.ceil(np.hypot(*(b - a)) / 0.5))
            pts += [a + (b - a) * k / n for k in range(1, n + 1)]
        out.append((np.array(pts), 0.5 * lw * px))
    return out


@pytest.mark.parametrize(
    ("stem", "dimensions"),
    [("eightbar", False), ("jansen_pair", True)]
    + [
        pytest.param(s, d, marks=pytest.mark.slow)
        for s, d in [*((s, False) for s in STEMS[1:]), ("sixbar_watt2", True)]
    ],
)
def test_names_clear_of_bars_pins_blocks_and_each_other(stem: str, dimensions: bool) -> None:
    mech = vloop.load(MECHANISMS / f"{stem}.toml")
    fig = figure(mech, configuration(mech, 0.5), dimensions=dimensions)
    fig.canvas.draw()
    boxes = _boxes(fig)
    names = {n for n, _ in boxes}
    assert set(mech.tracked_points) | set(mech.sliders) | {n for n, lk in mech.links.items() if not lk.ground} <= names
    strokes = _strokes(fig.axes[0])
    pts = np.concatenate([p for p, _ in strokes])
    hw = np.concatenate([np.full(len(p), w) for p, w in strokes])
    for name, box in boxes:
        inside = (
            (pts[:, 0] > box[0] - hw)
            & (pts[:, 0] < box[2] + hw)
            & (pts[:, 1] > box[1] - hw)
            & (pts[:, 1] < box[3] + hw)
        )
        assert not inside.any(), (name, box, pts[inside][:3])
    for i, (a, ba) in enumerate(boxes):
        for b, bb in boxes[i + 1 :]:
            overlap = ba[0] < bb[2] and bb[0] < ba[2] and ba[1] < bb[3] and bb[1] < ba[3]
            assert not overlap, (a, b)


def test_scale_bar_is_drawn_to_scale_and_dimensions_are_the_stated_lengths() -> None:
    mech = vloop.load(MECHANISMS / "sixbar_watt2.toml")
    ax = figure(mech, configuration(mech, 0.5), dimensions=True).axes[0]
    (bar,) = [ln for ln in ax.lines if ln.get_gid() == "scalebar" and np.ptp(ln.get_xdata()) > 0]
    (label,) = [t for t in ax.texts if t.get_gid() == "scalebar"]
    value, unit = label.get_text().split()
    assert unit == mech.units and float(value) == pytest.approx(np.ptp(bar.get_xdata()), rel=1e-12)
    assert float(value) / 10 ** math.floor(math.log10(float(value))) in (1, 2, 5)
    dims = sorted(float(t.get_text()) for t in ax.texts if t.get_gid() == "label" and t.get_text()[0].isdigit())
    want = []
    for lk in mech.links.values():
        if not lk.ground:
            js = lk.joints
            pairs = [(js[0], js[1])] if len(js) == 2 else list(zip(js, js[1:] + js[:1], strict=True))
            want += [math.dist(mech.joints[a], mech.joints[b]) for a, b in pairs]
    assert dims == pytest.approx(sorted(float(f"{w:.4g}") for w in want), rel=1e-12)


@pytest.mark.parametrize(
    "title",
    [
        "price $5 and $10, bell \x07 escape \x1b end \ufffe\uffff",
        "emoji 🦾 and 漢字 \ud800 < & >",
        pytest.param("$\\frac{1}{0}$ units $", marks=pytest.mark.slow),
        pytest.param("a < b & c > d \"q\" 'r'", marks=pytest.mark.slow),
    ],
)
def test_any_title_is_drawn_as_written_and_the_svg_is_xml(title: str, tmp_path: Path) -> None:
    mech = vloop.load(MECHANISMS / "fourbar_textbook_example.toml")
    mech = dataclasses.replace(mech, title=title, units="mm $x$")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        svg = export(mech, tmp_path, 0.2, "svg")
        if "$" in title:
            assert export(mech, tmp_path, 0.2, "pdf").read_bytes()[:5] == b"%PDF-"
    root = ET.fromstring(svg.read_text(encoding="utf-8"))
    words = " ".join("".join(t.itertext()) for t in root.iter("{http://www.w3.org/2000/svg}text"))
    kept = "".join(c for c in title if c.isprintable() and not 0xD800 <= ord(c) <= 0xDFFF and ord(c) & 0xFFFE != 0xFFFE)
    assert kept.strip() in words and "mm $x$" in words
