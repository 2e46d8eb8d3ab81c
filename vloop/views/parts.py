"""Links as parts a laser cutter can cut (DXF), in the file's length units.

Each link with two or more pivots is a part in its own frame (its first joint at the part's origin, its second
on +x; the ground's pivots in the world frame, a frame plate), laid out side by side to the right of the
assembly's centre lines at the drawn instant (layer ``ASSEMBLY``):

* layer ``PART-<link>`` (the cut): the outline — the convex hull of the part's holes, tracer points and slot
  ends, offset by half the link ``width`` (a bar: a stadium with round ends about its pivots; a plate: its
  polygon with rounded corners), one closed LWPOLYLINE of lines and arcs (bulges) —, a hole of diameter ``pin``
  at every pivot (CIRCLE), and where the link guides a slider, a slot of width ``pin`` along the sliding line
  over the slider's travel in the run (a closed LWPOLYLINE);
* layer ``ENGRAVE``: the link's name, placed along its longest edge (or at a plate's centre) clear of every
  hole, and at every tracer point a mark (a circle of diameter ``pin``/2 and a cross);
* ``kerf``: the beam's width. Cut paths are offset by half of it — outlines outward, holes and slots inward —
  so the parts come out at their stated sizes; the minimum web between a hole and the outline is
  (width − pin)/2 of material, whatever the kerf.

Defaults: pin diameter 2 % of the mechanism's size, link width three pin diameters (a web of one pin diameter).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import VloopError
from ..files.schema import show
from ..model import Mechanism
from ..result import Result

HOLE = 0.02  # default pivot hole (pin) diameter, fraction of the mechanism's size
WIDTH = 3.0  # default link width, in pin diameters
DXF_UNITS = {"in": 1, "ft": 2, "mm": 4, "cm": 5, "m": 6, "km": 7}  # $INSUNITS codes (0: unitless)
CHAR = 0.8  # a label's width per character as a fraction of its height (wider than DXF fonts' ~0.6-0.7)


class ExportError(VloopError):
    """A drawing or part file cannot be made as asked (the message names the option and the value)."""


def _positive(name: str, value: Any, below: float, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not 0 < value < below:
        raise ExportError(f"{name} {show(value)}: {what}", entry=name.lstrip("-"))
    return float(value)


def sizes(mech: Mechanism, pin: Any = None, width: Any = None, kerf: Any = 0.0) -> tuple[float, float, float]:
    """(pin diameter, link width, kerf) in the file's units, checked: 0 < pin < size, pin < width < size,
    0 <= kerf < pin."""
    size = mech.scale
    pin = HOLE * size if pin is None else pin
    pin = _positive("--pin", pin, size, "a diameter greater than 0 and below the mechanism's size")
    width = WIDTH * pin if width is None else width
    width = _positive("--width", width, size, "a link width greater than 0 and below the mechanism's size")
    if width <= pin:
        raise ExportError(
            f"--width {show(width)}: wider than the pin diameter {pin:g} (a web to hold the pin)", entry="width"
        )
    if isinstance(kerf, bool) or not isinstance(kerf, (int, float)) or not 0 <= kerf < pin:
        raise ExportError(f"--kerf {show(kerf)}: a beam width from 0 to below the pin diameter {pin:g}", entry="kerf")
    return pin, width, float(kerf)


# ---------------------------------------------------------------- geometry of a part (its own frame)


def hull(points: np.ndarray) -> np.ndarray:
    """Convex hull, counter-clockwise (monotone chain); two points (or collinear ones) give their two extremes."""
    pts = np.unique(np.asarray(points, float), axis=0)
    if len(pts) <= 2:
        return pts
    pts = pts[np.lexsort((pts[:, 1], pts[:, 0]))]

    def half(seq: np.ndarray) -> list[np.ndarray]:
        out: list[np.ndarray] = []
        for p in seq:
            while len(out) >= 2 and _cross(out[-1] - out[-2], p - out[-2]) <= 1e-12 * np.ptp(pts):
                out.pop()
            out.append(p)
        return out

    lower, upper = half(pts), half(pts[::-1])
    return np.array(lower[:-1] + upper[:-1])


def _cross(a: np.ndarray, b: np.ndarray) -> float:
    return float(a[0] * b[1] - a[1] * b[0])


def outline(points: np.ndarray, r: float) -> list[tuple[float, float, float]]:
    """The convex hull of ``points`` offset by ``r``: (x, y, bulge) vertices of a closed LWPOLYLINE, an arc
    about each hull vertex (bulge = tan(angle/4), counter-clockwise) then a straight side to the next one."""
    h = hull(points)
    if len(h) == 1:
        c = h[0]
        return [(c[0] + r, c[1], 1.0), (c[0] - r, c[1], 1.0)]
    n = len(h)
    edges = np.roll(h, -1, axis=0) - h
    normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1) / np.linalg.norm(edges, axis=1)[:, None]  # outward
    out = []
    for i in range(n):
        a, b = normals[i - 1], normals[i]
        turn = math.atan2(a[0] * b[1] - a[1] * b[0], a @ b) % (2 * math.pi)  # the arc's angle, CCW
        start, end = h[i] + r * a, h[i] + r * b
        out.append((float(start[0]), float(start[1]), math.tan(turn / 4)))
        out.append((float(end[0]), float(end[1]), 0.0))
    return out


def slot(a: np.ndarray, b: np.ndarray, width: float) -> list[tuple[float, float, float]]:
    """A slot of ``width`` whose centre line runs from ``a`` to ``b`` (round ends)."""
    return outline(np.array([a, b]) if np.linalg.norm(np.asarray(b) - a) > 0 else np.array([a]), width / 2)


def _members(
    mech: Mechanism, name: str, travel: dict[str, tuple[float, float]]
) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], list[tuple[np.ndarray, np.ndarray]]]:
    """(pivots, tracer points, slots' centre lines) of a link in its own frame."""
    body = mech.bodies()[name]
    lk = mech.links[name]
    pivots = {j: np.asarray(body.local[j], float) for j in lk.joints if not lk.ground or len(mech.bodies_at(j)) > 1}
    points = {p: np.asarray(body.local[p], float) for p, pt in mech.points.items() if pt.link == name}
    c, s = math.cos(body.theta0), math.sin(body.theta0)
    to_local = np.array([[c, s], [-s, c]])
    slots = []
    for sl in mech.sliders.values():
        if sl.guide != name or lk.ground:
            continue
        q0 = to_local @ (np.asarray(mech.joints[sl.joint], float) - np.asarray(body.origin))
        u = to_local @ np.asarray(sl.axis, float)
        s0 = float((np.asarray(mech.joints[sl.joint]) - np.asarray(body.origin)) @ np.asarray(sl.axis))
        lo, hi = travel.get(sl.name, (s0, s0))
        slots.append((q0 + (lo - s0) * u, q0 + (hi - s0) * u))
    return pivots, points, slots


def label_place(
    name: str, holes: list[np.ndarray], pin: float, width: float, plate: bool
) -> tuple[np.ndarray, float, float] | None:
    """(centre, angle [rad], height) of a link's name on the part, clear of every hole (and slot) by pin/4 and
    inside the outline: at a plate's centre, or along an edge between two holes (its middle first, then nearer
    its ends, on it or beside it), longest edges first; the largest height up to width/2 that fits; None if none
    fits."""
    if len(holes) < 2:
        return None
    pts = np.array(holes)
    h = hull(pts)
    sides = [(h[i], h[(i + 1) % len(h)]) for i in range(len(h) if len(h) > 2 else 1)]
    sides.sort(key=lambda ab: -float(np.linalg.norm(ab[1] - ab[0])))
    places = [(pts.mean(axis=0), sides[0][1] - sides[0][0])] if plate else []
    for a, b in sides:
        n = np.array([-(b - a)[1], (b - a)[0]]) / max(float(np.linalg.norm(b - a)), 1e-300)
        places += [
            (a + f * (b - a) + d * width * n, b - a) for d in (0.0, 0.28, -0.28) for f in (0.5, 0.3, 0.7, 0.2, 0.8)
        ]
    height = 0.5 * width
    while height > 0.05 * width:
        for centre, d in places:
            angle = math.atan2(d[1], d[0])
            if math.cos(angle) < -1e-9 or (abs(math.cos(angle)) <= 1e-9 and math.sin(angle) < 0):
                angle += math.pi  # read left to right
            fits = clearance(centre, angle, height, len(name), pts) >= 0.75 * pin
            if fits and _inside(_corners(centre, angle, height, len(name)), h, 0.45 * width):
                return centre, angle % (2 * math.pi), height
        height *= 0.85
    return None


def _corners(centre: np.ndarray, angle: float, height: float, chars: int) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    half = np.array([0.5 * CHAR * height * max(chars, 1), 0.5 * height])
    box = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]]) * half
    return centre + box @ np.array([[c, s], [-s, c]])


def _inside(points: np.ndarray, h: np.ndarray, r: float) -> bool:
    """Whether every point lies within ``r`` of the convex polygon (or segment) ``h``."""
    for p in points:
        if len(h) > 2 and all(_cross(h[(i + 1) % len(h)] - h[i], p - h[i]) >= 0 for i in range(len(h))):
            continue
        ends = [(h[i], h[(i + 1) % len(h)]) for i in range(len(h) if len(h) > 2 else 1)]
        if min(_to_segment(p, a, b) for a, b in ends) > r:
            return False
    return True


def _to_segment(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    d = b - a
    t = min(max(float((p - a) @ d) / max(float(d @ d), 1e-300), 0.0), 1.0)
    return float(np.linalg.norm(p - (a + t * d)))


def clearance(centre: np.ndarray, angle: float, height: float, chars: int, holes: np.ndarray) -> float:
    """The least distance from the hole centres to a label's box (CHAR·height per character, centred)."""
    c, s = math.cos(angle), math.sin(angle)
    rel = (np.asarray(holes) - centre) @ np.array([[c, -s], [s, c]])
    half = np.array([0.5 * CHAR * height * max(chars, 1), 0.5 * height])
    d = np.maximum(np.abs(rel) - half, 0.0)
    return float(np.min(np.hypot(d[:, 0], d[:, 1])))


# ---------------------------------------------------------------- the file


def run_travel(mech: Mechanism) -> dict[str, tuple[float, float]]:
    """Every slider's s range over the file's run (the part of it that solves, where the motion stops)."""
    from ..compiler import compile_system
    from ..core.solver import solve
    from ..errors import MotionError

    try:
        res = solve(compile_system(mech), np.asarray(mech.times, float))
    except MotionError as exc:
        res = exc.partial
    if res is None or not len(res):
        return {}
    return {s: (float(np.min(res[f"{s}.s"])), float(np.max(res[f"{s}.s"]))) for s in mech.sliders}


def write_dxf(
    mech: Mechanism,
    res: Result,
    path: str | Path,
    hole: Any = None,
    k: int = 0,
    width: Any = None,
    kerf: Any = 0.0,
    travel: dict[str, tuple[float, float]] | None = None,
) -> Path:
    """The parts (cut and engrave layers) and the assembly at sample ``k`` of ``res`` as DXF at ``path``.
    ``hole``: the pin diameter; ``width``: the link width; ``kerf``: the beam width (module docstring)."""
    try:
        import ezdxf
    except ImportError:
        raise ExportError("DXF export needs ezdxf: pip install 'vloop[export]'", entry="format") from None
    pin, width, kerf = sizes(mech, hole, width, kerf)
    travel = run_travel(mech) if travel is None else travel
    doc = ezdxf.new("R2010", setup=True)
    units = mech.units.strip().lower()
    doc.header["$INSUNITS"] = DXF_UNITS.get(units, 0)
    doc.header["$MEASUREMENT"] = 0 if units in ("in", "ft") else 1
    doc.layers.add("ENGRAVE", color=5)
    msp = doc.modelspace()
    pos = {n: (float(res[f"{n}.x"][k]), float(res[f"{n}.y"][k])) for n in mech.tracked_points}
    _assembly(doc, msp, mech, pos)
    x0 = max(x for x, _ in pos.values()) + 0.5 * mech.scale + width
    top = max(y for _, y in pos.values())
    for name in mech.links:
        pivots, points, slots = _members(mech, name, travel)
        if len(pivots) < 2:
            continue
        top -= _part(msp, doc, name, pivots, points, slots, (pin, width, kerf), np.array([x0, top])) + width
    doc.saveas(path)
    return Path(path)


def _part(
    msp: Any,
    doc: Any,
    name: str,
    pivots: dict,
    points: dict,
    slots: list,
    dims: tuple[float, float, float],
    corner: np.ndarray,
) -> float:
    """One part with its top-left corner at ``corner``; returns its height."""
    pin, width, kerf = dims
    members = np.array([*pivots.values(), *points.values(), *(p for s in slots for p in s)])
    lo, hi = members.min(axis=0) - width / 2, members.max(axis=0) + width / 2
    shift = corner - np.array([lo[0], hi[1]])
    layer = f"PART-{name}"
    doc.layers.add(layer, color=1)
    cut = {"layer": layer}
    msp.add_lwpolyline(_moved(outline(members, width / 2 + kerf / 2), shift), format="xyb", close=True, dxfattribs=cut)
    for a, b in slots:
        msp.add_lwpolyline(_moved(slot(a, b, pin - kerf), shift), format="xyb", close=True, dxfattribs=cut)
    for xy in pivots.values():
        msp.add_circle(tuple(xy + shift), pin / 2 - kerf / 2, dxfattribs=cut)
    engrave = {"layer": "ENGRAVE"}
    for xy in points.values():
        c = xy + shift
        msp.add_circle(tuple(c), pin / 4, dxfattribs=engrave)
        for d in (np.array([pin / 2, 0.0]), np.array([0.0, pin / 2])):
            msp.add_line(tuple(c - d), tuple(c + d), dxfattribs=engrave)
    holes = [*pivots.values(), *(p for a, b in slots for p in _along(a, b, pin / 4))]
    place = label_place(name, holes, pin, width, plate=len(pivots) + len(slots) > 2)
    if place is not None:
        centre, angle, height = place
        text = msp.add_text(name, height=height, rotation=math.degrees(angle), dxfattribs=engrave)
        text.set_placement(tuple(centre + shift), align=_MIDDLE_CENTER())
    return float(hi[1] - lo[1])


def _MIDDLE_CENTER() -> Any:
    from ezdxf.enums import TextEntityAlignment

    return TextEntityAlignment.MIDDLE_CENTER


def _along(a: np.ndarray, b: np.ndarray, step: float) -> list[np.ndarray]:
    """Points from ``a`` to ``b`` at most ``step`` apart (a slot's centre line, for keeping labels off it)."""
    n = max(1, math.ceil(float(np.linalg.norm(b - a)) / step))
    return [a + (b - a) * i / n for i in range(n + 1)]


def _moved(vertices: list[tuple[float, float, float]], shift: np.ndarray) -> list[tuple[float, float, float]]:
    return [(x + shift[0], y + shift[1], b) for x, y, b in vertices]


def _assembly(doc: Any, msp: Any, mech: Mechanism, pos: dict) -> None:
    """The links' centre lines and pins at the drawn instant, world coordinates."""
    doc.layers.add("ASSEMBLY", color=8)
    for lk in mech.links.values():
        joints = [j for j in lk.joints if not lk.ground or len(mech.bodies_at(j)) > 1]
        pairs = (
            [(joints[0], joints[1])]
            if len(joints) == 2
            else ([(joints[i], joints[(i + 1) % len(joints)]) for i in range(len(joints))] if len(joints) > 2 else [])
        )
        for a, b in pairs:
            msp.add_line(pos[a], pos[b], dxfattribs={"layer": "ASSEMBLY"})
    for j in mech.joints:
        msp.add_point(pos[j], dxfattribs={"layer": "ASSEMBLY"})
