"""Drawings of a mechanism at one instant (SVG, PDF) and its links as parts for fabrication (DXF).

* :func:`figure` draws the mechanism at time t to scale: ground pivots hatched, links as bars and plates,
  pins, slider blocks on their rails (a ground guide) or in their slots (a moving guide), tracer points, joint
  and link labels. SVG and PDF through matplotlib (text stays text in the SVG; no date in either, so a drawing
  is the same file every time).
* :func:`write_dxf` writes each link as a part in its own frame — its centre lines between its pivots and a hole
  at every pivot, on a layer of its own (``PART-<link>``), the ground's pivots as a frame template — laid out
  side by side, and the mechanism's centre lines at time t on layer ``ASSEMBLY``; in the file's length units
  (``$INSUNITS``). Needs ezdxf (``pip install vloop[export]``).

Positions come from the mechanism's own Result at t (solved for that one instant), slider blocks turned
by their θ columns; every length is in the file's units.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..compiler import compile_system
from ..core.solver import solve
from ..errors import VloopError
from ..files.schema import show
from ..model import Mechanism
from ..result import Result
from .geometry import BLOCK_SIZE

FORMATS = ("svg", "pdf", "dxf")
PIN = 0.012  # pin radius in a drawing, fraction of the mechanism's size
HOLE = 0.02  # default pivot hole diameter in a DXF part, fraction of the mechanism's size
DXF_UNITS = {"in": 1, "ft": 2, "mm": 4, "cm": 5, "m": 6, "km": 7}  # $INSUNITS codes (0: unitless)


class ExportError(VloopError):
    """A drawing or part file cannot be made as asked (the message names the option and the value)."""


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


def export(mech: Mechanism, folder: str | Path, at: Any, fmt: str) -> Path:
    """Write ``folder/<name>.svg|pdf`` (the drawing at ``at`` [s]) or ``folder/<name>.dxf`` (parts and assembly);
    returns the path. ``folder`` should be an OutputSet's stage (the CLI's), so the file appears whole or not."""
    from ..files.options import folder_path, instance
    from ..files.output import ensure_folder

    instance(mech, "mech", Mechanism, "a Mechanism (vloop.load)")
    if fmt not in FORMATS:
        raise ExportError(f"{mech.name}: --format {show(fmt)}: one of {', '.join(FORMATS)}", entry="format")
    folder = ensure_folder(folder_path(folder))
    res = configuration(mech, at)
    path = Path(folder) / f"{_file_name(mech.name)}.{fmt}"
    if fmt == "dxf":
        write_dxf(mech, res, path)
    else:
        write_drawing(mech, res, path)
    return path


def _file_name(name: str) -> str:
    from ..files.output import safe_folder_name

    return safe_folder_name(name)


# ---------------------------------------------------------------- the drawing


def write_drawing(mech: Mechanism, res: Result, path: str | Path) -> Path:
    """The drawing of :func:`figure` as SVG or PDF (by the suffix), the same bytes for the same mechanism."""
    import matplotlib

    path = Path(path)
    fig = figure(mech, res)
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "vloop", "pdf.compression": 6}):
        meta = dict.fromkeys(("Date", "Creator", "Format", "Type") if path.suffix == ".svg" else ("CreationDate",))
        fig.savefig(path, format=path.suffix[1:], metadata=meta, bbox_inches="tight")  # no date: the same bytes
    return path


def figure(mech: Mechanism, res: Result, k: int = 0) -> Any:
    """A matplotlib Figure of the mechanism at sample ``k`` of ``res``, to scale (lengths in the file's units)."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.0, 5.0))
    ax = fig.add_subplot()
    pos = {n: (float(res[f"{n}.x"][k]), float(res[f"{n}.y"][k])) for n in mech.tracked_points}
    size = mech.scale
    _draw_ground(ax, mech, pos, size)
    _draw_links(ax, mech, pos)
    _draw_sliders(ax, mech, res, k, pos, size)
    _draw_pins(ax, mech, pos, size)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.margins(0.08)
    ax.axis("off")
    ax.set_title(f"{mech.title or mech.name} — t = {float(res.t[k]):g} s ({mech.units})", fontsize=10)
    return fig


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
    """Binary links as bars, links with more members (joints and tracer points) as plates, with their names."""
    from matplotlib.patches import Polygon

    for name, lk in mech.links.items():
        if lk.ground:
            continue
        members = [*lk.joints, *(p for p, pt in mech.points.items() if pt.link == name)]
        xy = np.array([pos[m] for m in members])
        if len(members) == 2:
            ax.plot(xy[:, 0], xy[:, 1], color="#0072B2", lw=3, solid_capstyle="round", zorder=2)
        elif len(members) > 2:
            c = xy.mean(axis=0)
            order = np.argsort(np.arctan2(xy[:, 1] - c[1], xy[:, 0] - c[0]))
            ax.add_patch(Polygon(xy[order], closed=True, fc="#56B4E9", ec="#0072B2", alpha=0.5, lw=2, zorder=2))
        c = xy.mean(axis=0)
        label = {"xytext": (0, 6), "textcoords": "offset points", "ha": "center", "fontsize": 8, "zorder": 5}
        ax.annotate(name, c, style="italic", color="#0072B2", **label)


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
        label = {"xytext": (0, -14), "textcoords": "offset points", "ha": "center", "fontsize": 8, "zorder": 5}
        ax.annotate(name, (x, y), style="italic", color="#D55E00", **label)


def _draw_pins(ax: Any, mech: Mechanism, pos: dict, size: float) -> None:
    """Pins as open circles, tracer points as dots, every one named."""
    from matplotlib.patches import Circle

    r = PIN * size
    for j in mech.tracked_points:
        x, y = pos[j]
        if j in mech.points:
            ax.add_patch(Circle((x, y), 0.5 * r, fc="k", zorder=4))
        else:
            ax.add_patch(Circle((x, y), r, fc="white", ec="k", lw=1.2, zorder=4))
        ax.annotate(j, (x, y), xytext=(5, 5), textcoords="offset points", fontsize=9, zorder=5)


# ---------------------------------------------------------------- parts for fabrication (DXF)


def write_dxf(mech: Mechanism, res: Result, path: str | Path, hole: float | None = None, k: int = 0) -> Path:
    """Each link as a part (centre lines and pivot holes of diameter ``hole``, default 2 % of the mechanism's size,
    in its own frame: its first joint at the part's origin, its second on +x), the ground's pivots as a frame
    template, laid out to the right of the assembly's centre lines at sample ``k`` of ``res`` (layer ASSEMBLY)."""
    try:
        import ezdxf
    except ImportError:
        raise ExportError("DXF export needs ezdxf: pip install 'vloop[export]'", entry="format") from None
    hole = HOLE * mech.scale if hole is None else hole
    if isinstance(hole, bool) or not isinstance(hole, (int, float)) or not 0 < hole < mech.scale:
        raise ExportError(f"{mech.name}: hole {show(hole)}: a diameter greater than 0 and below the mechanism's size")
    doc = ezdxf.new("R2010", setup=True)
    doc.header["$INSUNITS"] = DXF_UNITS.get(mech.units.strip().lower(), 0)
    doc.header["$MEASUREMENT"] = 0 if mech.units.strip().lower() in ("in", "ft") else 1
    msp = doc.modelspace()
    pos = {n: (float(res[f"{n}.x"][k]), float(res[f"{n}.y"][k])) for n in mech.tracked_points}
    _assembly(doc, msp, mech, pos)
    xs = [x for x, _ in pos.values()]
    ys = [y for _, y in pos.values()]
    x0, top, gap = max(xs) + 0.5 * mech.scale, max(ys), 3 * hole + 0.1 * mech.scale
    for name, local in _parts(mech):
        layer = f"PART-{name}"
        doc.layers.add(layer)
        lo = np.min(np.array(list(local.values())), axis=0)
        hi = np.max(np.array(list(local.values())), axis=0)
        shift = np.array([x0, top]) - np.array([lo[0], hi[1]])
        at = {j: tuple(np.array(xy) + shift) for j, xy in local.items()}
        joints = list(at)
        for a, b in _edges(joints):
            msp.add_line(at[a], at[b], dxfattribs={"layer": layer, "linetype": "CENTER"})
        for j in joints:
            msp.add_circle(at[j], hole / 2, dxfattribs={"layer": layer})
        msp.add_text(name, height=hole, dxfattribs={"layer": layer}).set_placement(at[joints[0]])
        top -= hi[1] - lo[1] + gap
    doc.saveas(path)
    return Path(path)


def _assembly(doc: Any, msp: Any, mech: Mechanism, pos: dict) -> None:
    """The links' centre lines and pins at the drawn instant, world coordinates."""
    doc.layers.add("ASSEMBLY")
    for lk in mech.links.values():
        joints = [j for j in lk.joints if not lk.ground or len(mech.bodies_at(j)) > 1]
        for a, b in _edges(joints):
            msp.add_line(pos[a], pos[b], dxfattribs={"layer": "ASSEMBLY"})
    for j in mech.joints:
        msp.add_point(pos[j], dxfattribs={"layer": "ASSEMBLY"})


def _parts(mech: Mechanism) -> list[tuple[str, dict[str, tuple[float, float]]]]:
    """Every link's pivots in its own frame (the ground's in the world frame), links with two or more joints."""
    bodies = mech.bodies()
    out = []
    for name, lk in mech.links.items():
        joints = [j for j in lk.joints if not lk.ground or len(mech.bodies_at(j)) > 1]
        if len(joints) >= 2:
            out.append((name, {j: bodies[name].local[j] for j in joints}))
    return out


def _edges(joints: list[str]) -> list[tuple[str, str]]:
    """Centre lines between a part's pivots: a bar's one, a plate's outline through its joints in order."""
    if len(joints) == 2:
        return [(joints[0], joints[1])]
    return [(joints[i], joints[(i + 1) % len(joints)]) for i in range(len(joints))] if len(joints) > 2 else []
