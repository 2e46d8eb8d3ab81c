"""Drawings of a mechanism at one instant (SVG, PDF) and its links as parts for fabrication (DXF).

* :func:`figure` draws the mechanism at time t to scale: ground pivots hatched, links as bars and plates,
  pins, slider blocks on their rails (a ground guide) or in their slots (a moving guide), tracer points, a scale
  bar, and on request every link's length dimensioned; then the joint, link and slider names, each placed clear
  of the geometry and of the names before it (:mod:`.labels`). Titles and names are drawn as written (never
  parsed as math, control characters dropped). SVG and PDF through matplotlib (text stays text in the SVG; no
  date in either, so a drawing is the same file every time).
* :func:`write_dxf` (:mod:`.parts`) writes each link as a part to cut: its outline, pivot holes, slots, and on
  an engrave layer its name and tracer points; and the mechanism's centre lines at time t. Needs ezdxf
  (``pip install vloop[export]``).

Positions come from the mechanism's own Result at t (solved for that one instant), slider blocks turned
by their θ columns; every length is in the file's units.
"""

from __future__ import annotations

import math
import warnings
from pathlib import Path
from typing import Any

import numpy as np

from ..compiler import compile_system
from ..core.solver import solve
from ..files.schema import show
from ..model import Mechanism
from ..result import Result
from .geometry import BLOCK_SIZE
from .labels import clean, obstacles, place
from .parts import DXF_UNITS, HOLE, ExportError, sizes, write_dxf

FORMATS = ("svg", "pdf", "dxf")
PIN = 0.012  # pin radius in a drawing, fraction of the mechanism's size
__all__ = ["DXF_UNITS", "FORMATS", "HOLE", "ExportError", "configuration", "export", "figure", "options", "write_dxf"]


def time_at(mech: Mechanism, at: Any) -> float:
    """``at`` [s] as a time within the file's run (a number or its text); ExportError otherwise."""
    t0, t1 = float(mech.times[0]), float(mech.times[-1])
    try:
        t = float(at) if not isinstance(at, bool) else math.nan
    except (TypeError, ValueError, OverflowError):
        raise ExportError(f"{mech.name}: --at {show(at)} is not a time in seconds", entry="at") from None
    if not math.isfinite(t):
        raise ExportError(f"{mech.name}: --at {show(at)} is not a finite time in seconds", entry="at")
    if not t0 <= t <= t1:
        raise ExportError(
            f"{mech.name}: --at {show(at)} is outside the run: give a time from {t0:g} to {t1:g} s", entry="at"
        )
    return t + 0.0


def configuration(mech: Mechanism, at: Any) -> Result:
    """The mechanism at time ``at`` [s] within its run: a Result of that one sample (MotionError where the motion
    cannot reach it)."""
    return solve(compile_system(mech), np.array([time_at(mech, at)]))


def options(
    mech: Mechanism, fmt: str, pin: Any = None, width: Any = None, kerf: Any = None, dimensions: bool = False
) -> dict[str, Any]:
    """The options of ``fmt`` from their text (the command line's), checked before any work: ``pin``, ``width``,
    ``kerf`` for parts (dxf), ``dimensions`` for drawings (svg, pdf)."""
    if fmt == "dxf":
        if dimensions:
            raise ExportError("--dimensions is for drawings (--format svg or pdf)", entry="dimensions")
        p, w, k = sizes(mech, _number("--pin", pin), _number("--width", width), _number("--kerf", kerf) or 0.0)
        return {"pin": p, "width": w, "kerf": k}
    given = [n for n, v in (("--pin", pin), ("--width", width), ("--kerf", kerf)) if v is not None]
    if given:
        raise ExportError(f"{', '.join(given)}: for parts (--format dxf), not drawings", entry=given[0].lstrip("-"))
    return {"dimensions": bool(dimensions)}


def _number(name: str, text: Any) -> float | None:
    if text is None:
        return None
    try:
        value = float(text) if not isinstance(text, bool) else math.nan
    except (TypeError, ValueError, OverflowError):
        raise ExportError(f"{name} {show(text)}: not a number", entry=name.lstrip("-")) from None
    if not math.isfinite(value):
        raise ExportError(f"{name} {show(text)}: not a finite number", entry=name.lstrip("-"))
    return value


def export(
    mech: Mechanism,
    folder: str | Path,
    at: Any,
    fmt: str,
    *,
    pin: Any = None,
    width: Any = None,
    kerf: Any = 0.0,
    dimensions: bool = False,
) -> Path:
    """Write ``folder/<name>.svg|pdf`` (the drawing at ``at`` [s], link lengths dimensioned if ``dimensions``) or
    ``folder/<name>.dxf`` (parts with pin diameter ``pin``, link ``width`` and ``kerf``, and the assembly);
    returns the path. ``folder`` should be an OutputSet's stage (the CLI's), so the file appears whole or not."""
    from ..files.options import folder_path, instance
    from ..files.output import ensure_folder

    instance(mech, "mech", Mechanism, "a Mechanism (vloop.load)")
    if fmt not in FORMATS:
        raise ExportError(f"{mech.name}: --format {show(fmt)}: one of {', '.join(FORMATS)}", entry="format")
    folder = ensure_folder(folder_path(folder))
    if fmt == "dxf":
        sizes(mech, pin, width, kerf)  # before the solve: a bad size is one line
    res = configuration(mech, at)
    path = Path(folder) / f"{_file_name(mech.name)}.{fmt}"
    if fmt == "dxf":
        write_dxf(mech, res, path, hole=pin, width=width, kerf=kerf)
    else:
        write_drawing(mech, res, path, dimensions=dimensions)
    return path


def _file_name(name: str) -> str:
    from ..files.output import safe_folder_name

    return safe_folder_name(name)


# ---------------------------------------------------------------- the drawing


def write_drawing(mech: Mechanism, res: Result, path: str | Path, dimensions: bool = False) -> Path:
    """The drawing of :func:`figure` as SVG or PDF (by the suffix), the same bytes for the same mechanism."""
    import matplotlib

    path = Path(path)
    fig = figure(mech, res, dimensions=dimensions)
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "vloop", "pdf.compression": 6}):
        meta = dict.fromkeys(("Date", "Creator", "Format", "Type") if path.suffix == ".svg" else ("CreationDate",))
        with warnings.catch_warnings():  # a name's character the font lacks is drawn as a box, not warned about
            warnings.filterwarnings("ignore", message="Glyph .* missing", category=UserWarning)
            fig.savefig(path, format=path.suffix[1:], metadata=meta, bbox_inches="tight")  # no date: the same bytes
    return path


def figure(mech: Mechanism, res: Result, k: int = 0, dimensions: bool = False) -> Any:
    """A matplotlib Figure of the mechanism at sample ``k`` of ``res``, to scale (lengths in the file's units),
    with a scale bar; every link's length dimensioned if ``dimensions``; names placed clear of the geometry."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 5.0))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    pos = {n: (float(res[f"{n}.x"][k]), float(res[f"{n}.y"][k])) for n in mech.tracked_points}
    size = mech.scale
    _draw_ground(ax, mech, pos, size)
    _draw_links(ax, mech, pos)
    _draw_sliders(ax, mech, res, k, pos, size)
    _draw_pins(ax, mech, pos, size)
    notes = _dimension_lines(ax, mech, pos) if dimensions else []
    _scale_bar(ax, mech)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.margins(0.08)
    ax.set_xlim(*ax.get_xlim())
    ax.set_ylim(*ax.get_ylim())
    ax.axis("off")
    title = f"{clean(mech.title or mech.name)} — t = {float(res.t[k]):g} s ({clean(mech.units)})"
    ax.set_title(title, fontsize=10, parse_math=False)
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="Glyph .* missing", category=UserWarning)
        _names(ax, mech, pos, notes)
    return fig


def _names(ax: Any, mech: Mechanism, pos: dict, notes: list[tuple[str, tuple[float, float]]]) -> None:
    """Every name (and dimension), each at the nearest place clear of the geometry and of the names before it."""
    ax.apply_aspect()
    renderer = ax.figure.canvas.get_renderer()
    obs = obstacles(ax)
    for text, at in notes:
        place(ax, text, at, obs, renderer, fontsize=7, color="0.3")
    for j in mech.tracked_points:
        place(ax, j, pos[j], obs, renderer, fontsize=9)
    for name, lk in mech.links.items():
        if not lk.ground:
            place(ax, name, _link_anchor(mech, name, pos), obs, renderer, fontsize=8, style="italic", color="#0072B2")
    for name, sl in mech.sliders.items():
        place(ax, name, pos[sl.joint], obs, renderer, fontsize=8, style="italic", color="#D55E00")


def _members(mech: Mechanism, name: str) -> list[str]:
    return [*mech.links[name].joints, *(p for p, pt in mech.points.items() if pt.link == name)]


def _link_anchor(mech: Mechanism, name: str, pos: dict) -> tuple[float, float]:
    """Where a link's name is sought from: a bar's middle, a plate's centre."""
    xy = np.array([pos[m] for m in _members(mech, name)])
    c = xy.mean(axis=0)
    return float(c[0]), float(c[1])


def _draw_ground(ax: Any, mech: Mechanism, pos: dict, size: float) -> None:
    """A hatched ground symbol under every ground pivot that carries a moving body."""
    from matplotlib.patches import Polygon

    r = PIN * size
    for j in mech.links[mech.ground].joints:
        if len(mech.bodies_at(j)) < 2:
            continue
        x, y = pos[j]
        ax.add_patch(Polygon([(x, y), (x - 2 * r, y - 3 * r), (x + 2 * r, y - 3 * r)], closed=True, fc="0.85", ec="k"))
        ax.plot([x - 3 * r, x + 3 * r], [y - 3 * r, y - 3 * r], color="k", lw=1.2)
        for i in range(6):
            u = x - 3 * r + i * 1.2 * r
            ax.plot([u, u - r], [y - 3 * r, y - 4 * r], color="k", lw=0.6)


def _draw_links(ax: Any, mech: Mechanism, pos: dict) -> None:
    """Binary links as bars, links with more members (joints and tracer points) as plates."""
    from matplotlib.patches import Polygon

    for name, lk in mech.links.items():
        if lk.ground:
            continue
        members = _members(mech, name)
        xy = np.array([pos[m] for m in members])
        if len(members) == 2:
            ax.plot(xy[:, 0], xy[:, 1], color="#0072B2", lw=3, solid_capstyle="round", zorder=2)
        elif len(members) > 2:
            c = xy.mean(axis=0)
            order = np.argsort(np.arctan2(xy[:, 1] - c[1], xy[:, 0] - c[0]))
            ax.add_patch(Polygon(xy[order], closed=True, fc="#56B4E9", ec="#0072B2", alpha=0.5, lw=2, zorder=2))


def _draw_sliders(ax: Any, mech: Mechanism, res: Result, k: int, pos: dict, size: float) -> None:
    """Each block on its axis; a ground guide as a hatched rail, a moving guide's slot as a line along the axis."""
    from matplotlib.patches import Rectangle
    from matplotlib.transforms import Affine2D

    w, h = BLOCK_SIZE[0] * size, BLOCK_SIZE[1] * size
    for name, sl in mech.sliders.items():
        x, y = pos[sl.joint]
        th = float(res[f"{name}.theta"][k])
        u, n = np.array([math.cos(th), math.sin(th)]), np.array([-math.sin(th), math.cos(th)])
        p = np.array([x, y])
        if sl.guide == mech.ground:
            rail = np.array([p - 2.5 * w * u, p + 2.5 * w * u]) - h / 2 * n
            ax.plot(rail[:, 0], rail[:, 1], color="k", lw=1.2, zorder=1)
            for i in range(11):
                a = rail[0] + (rail[1] - rail[0]) * i / 10
                ax.plot([a[0], a[0] - 0.3 * h * (u + n)[0]], [a[1], a[1] - 0.3 * h * (u + n)[1]], color="k", lw=0.6)
        else:
            slot = np.array([p - 2 * w * u, p + 2 * w * u])
            ax.plot(slot[:, 0], slot[:, 1], color="#0072B2", lw=1, ls="--", zorder=1)
        block = Rectangle((-w / 2, -h / 2), w, h, fc="#E69F00", ec="k", lw=1, zorder=3)
        block.set_transform(Affine2D().rotate(th).translate(x, y) + ax.transData)
        ax.add_patch(block)


def _draw_pins(ax: Any, mech: Mechanism, pos: dict, size: float) -> None:
    """Pins as open circles, tracer points as dots."""
    from matplotlib.patches import Circle

    r = PIN * size
    for j in mech.tracked_points:
        x, y = pos[j]
        if j in mech.points:
            ax.add_patch(Circle((x, y), 0.5 * r, fc="k", zorder=4))
        else:
            ax.add_patch(Circle((x, y), r, fc="white", ec="k", lw=1.2, zorder=4))


def _dimension_lines(ax: Any, mech: Mechanism, pos: dict) -> list[tuple[str, tuple[float, float]]]:
    """Each link's lengths (a bar's, a plate's sides between its joints) as dimension lines beside it, offset
    away from the link's (or, for a bar, the mechanism's) centre; returns the values and where to write them."""
    centre = np.mean([pos[j] for j in mech.joints], axis=0)
    off = 0.08 * mech.scale
    notes = []
    for lk in mech.links.values():
        if lk.ground or len(lk.joints) < 2:
            continue
        xy = {j: np.asarray(pos[j]) for j in lk.joints}
        inside = np.mean(list(xy.values()), axis=0) if len(xy) > 2 else centre
        pairs = list(zip(lk.joints, lk.joints[1:] + lk.joints[:1], strict=True))[: 1 if len(xy) == 2 else None]
        for a, b in pairs:
            p, q = xy[a], xy[b]
            d = q - p
            n = np.array([-d[1], d[0]]) / max(float(np.hypot(*d)), 1e-300)
            if n @ ((p + q) / 2 - inside) < 0:
                n = -n
            p2, q2 = p + off * n, q + off * n
            for e in (p, q):
                ax.plot(
                    [e[0] + 0.15 * off * n[0], e[0] + 1.15 * off * n[0]],
                    [e[1] + 0.15 * off * n[1], e[1] + 1.15 * off * n[1]],
                    color="0.55",
                    lw=0.5,
                )
            ax.plot([p2[0], q2[0]], [p2[1], q2[1]], color="0.35", lw=0.7, marker="|", markersize=6, markevery=[0, 1])
            notes.append((f"{float(np.hypot(*d)):.4g}", (float((p2 + q2)[0] / 2), float((p2 + q2)[1] / 2))))
    return notes


def scale_length(span: float) -> float:
    """A round length (1, 2 or 5 times a power of ten) of at most a quarter of ``span``."""
    target = span / 4
    power = 10.0 ** math.floor(math.log10(target))
    return max(m * power for m in (1, 2, 5) if m * power <= target * (1 + 1e-12))


def _scale_bar(ax: Any, mech: Mechanism) -> None:
    """A bar of a round length below the drawing's left end, its length written under it (to scale)."""
    lim = ax.dataLim
    span = max(lim.width, lim.height, mech.scale)
    length = scale_length(span)
    x0, y = lim.x0, lim.y0 - 0.12 * span
    tick = 0.015 * span
    ax.plot([x0, x0 + length], [y, y], color="k", lw=1.5, gid="scalebar", solid_capstyle="butt")
    for x in (x0, x0 + length):
        ax.plot([x, x], [y - tick, y + tick], color="k", lw=1.0, gid="scalebar")
    ax.text(
        x0 + length / 2,
        y - 2 * tick,
        f"{length:g} {clean(mech.units)}",
        ha="center",
        va="top",
        fontsize=8,
        parse_math=False,
        gid="scalebar",
    )
