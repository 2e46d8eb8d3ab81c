"""The studio's document: a mechanism file's TOML structure being drawn and edited (plain dicts and lists).

Joints carry their coordinates at t = 0 and every moving binary link its ``length`` (a plate its ``sides``), so a
drawing is always a file *written from dimensions* whose coordinates are the assembly the user sees: a drag moves
coordinates and restates the lengths they give; a typed length restates one length and lets vloop's own t = 0
assembly (:mod:`vloop.authoring`) place the joints, the branch nearest the drawing. Every function here returns a
new document and never solves: the session asks the core. Lengths in the document's units, angles in rad.
"""

from __future__ import annotations

import copy
import math
import re
from typing import Any

NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,31}$")
DEFAULT_TIME = {"start": 0.0, "stop": 1.0, "step": 1.0 / 360}  # one turn at 2π rad/s, at 1° per sample


class EditError(ValueError):
    """An edit that cannot apply to this drawing (the message says what and where)."""


def empty(units: str = "mm", name: str = "drawing") -> dict[str, Any]:
    """A new drawing: a ground with no joint yet, one turn of a crank over 1 s once a driver is set."""
    ground = {"joints": [], "ground": True}
    return {"name": name, "title": "", "units": units, "joints": {}, "links": {"ground": ground}, "drivers": [],
            "time": dict(DEFAULT_TIME)}  # fmt: skip


# the sections edits change in place; the rest is shared between versions ([time] is only ever replaced whole)
EDITED = ("joints", "links", "sliders", "drivers")


def edited(doc: dict) -> dict:
    """A new version of ``doc`` whose editable sections are copies (the others, never edited, are shared: an
    opened file's long time list or profiles are not copied at every drag)."""
    out = dict(doc)
    for key in EDITED:
        if key in out:
            out[key] = copy.deepcopy(out[key])
    return out


def number(value: Any, what: str, *, positive: bool = False) -> float:
    """A finite float (EditError naming ``what`` otherwise)."""
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise EditError(f"{what} must be a number, got {str(value)[:40]!r}")
    x = float(value)
    if not math.isfinite(x) or abs(x) > 1e12 or (positive and not x > 0):
        raise EditError(f"{what} must be a finite{' positive' if positive else ''} number, got {x!r}")
    return x


def name_of(value: Any, what: str) -> str:
    if not isinstance(value, str) or not NAME.match(value):
        raise EditError(f"{what}: a name of letters, digits and _ starting with a letter, got {str(value)[:40]!r}")
    return value


def ground_name(doc: dict) -> str:
    return next(n for n, lk in doc["links"].items() if lk.get("ground"))


def fresh(existing: Any, prefix: str, start: int = 1) -> str:
    k = start
    while f"{prefix}{k}" in existing:
        k += 1
    return f"{prefix}{k}"


def add_joint(doc: dict, x: Any, y: Any, *, ground: bool = False, name: Any = None) -> tuple[dict, str]:
    """A joint at (x, y); ``ground``: a ground pivot (joined to the ground link)."""
    out = edited(doc)
    taken = set(out["joints"]) | set(out["links"]) | set(out.get("sliders", {}))
    name = name_of(name, "joint name") if name is not None else fresh(taken, "O" if ground else "J")
    if name in taken:
        raise EditError(f"joint {name}: the name is taken")
    out["joints"][name] = [number(x, f"{name}.x"), number(y, f"{name}.y")]
    if ground:
        out["links"][ground_name(out)]["joints"].append(name)
    return out, name


def add_link(doc: dict, joints: Any, *, name: Any = None) -> tuple[dict, str]:
    """A binary link (two joints) or a plate (three): its length or sides stated from the coordinates."""
    if not isinstance(joints, list) or len(joints) not in (2, 3) or len(set(map(str, joints))) != len(joints):
        raise EditError("a link joins 2 (binary) or 3 (plate) different joints")
    out = edited(doc)
    for j in joints:
        if j not in out["joints"]:
            raise EditError(f"a link's joint {str(j)[:40]!r}: no such joint")
    ground = out["links"][ground_name(out)]["joints"]
    if all(j in ground for j in joints):
        raise EditError("every joint of this link is a ground pivot: it would be part of the ground")
    taken = set(out["joints"]) | set(out["links"]) | set(out.get("sliders", {}))
    name = name_of(name, "link name") if name is not None else fresh(taken, "l", 2)
    if name in taken:
        raise EditError(f"link {name}: the name is taken")
    out["links"][name] = {"joints": list(joints)}
    restate(out, name)
    return out, name


def add_slider(doc: dict, joint: Any, angle: Any = 0.0, *, name: Any = None) -> tuple[dict, str]:
    """A slider block at ``joint`` on a ground guide through it, its axis at ``angle`` [rad] from +x."""
    out = edited(doc)
    if joint not in out["joints"]:
        raise EditError(f"slider: no joint {str(joint)[:40]!r}")
    if joint in out["links"][ground_name(out)]["joints"]:
        raise EditError(f"slider: {joint} is a ground pivot; a slider carries a moving joint")
    if any(sl["joint"] == joint for sl in out.get("sliders", {}).values()):
        raise EditError(f"slider: {joint} already slides")
    taken = set(out["joints"]) | set(out["links"]) | set(out.get("sliders", {}))
    name = name_of(name, "slider name") if name is not None else fresh(taken, "l", 2)
    if name in taken:
        raise EditError(f"slider {name}: the name is taken")
    a = number(angle, "slider angle")
    axis = [math.cos(a), math.sin(a)]
    out.setdefault("sliders", {})[name] = {"joint": joint, "guide": ground_name(out), "axis": axis}
    restate_slider(out, name)
    return out, name


def restate_slider(doc: dict, name: str) -> None:
    """A ground slider's ``offset`` (its line's signed distance from the origin, left of the axis positive) from its
    joint's coordinates, in place."""
    sl = doc["sliders"][name]
    if sl["guide"] != ground_name(doc) or "axis" not in sl:
        return
    (ux, uy), (x, y) = sl["axis"], doc["joints"][sl["joint"]]
    n = math.hypot(ux, uy)
    sl["offset"] = (ux * y - uy * x) / n


def restate(doc: dict, link: str) -> None:
    """A moving link's length (binary) or sides and angle (plate) from the coordinates, in place."""
    lk = doc["links"][link]
    if lk.get("ground"):
        return
    p = [doc["joints"][j] for j in lk["joints"]]
    if len(p) == 2:
        lk["length"] = math.dist(p[0], p[1])
    elif len(p) == 3:
        a, b, c = (complex(*q) for q in p)
        lk.pop("length", None)
        lk["sides"] = [abs(b - a), abs(c - a)]
        lk["angle"] = math.atan2(((c - a) / (b - a)).imag, ((c - a) / (b - a)).real) if b != a and c != a else 0.0


def move_joint(doc: dict, joint: str, x: float, y: float) -> dict:
    """The joint moved to (x, y) at t = 0; the links through it restate their dimensions, the driver its θ₀."""
    out = edited(doc)
    if joint not in out["joints"]:
        raise EditError(f"joint {str(joint)[:40]!r}: no such joint")
    out["joints"][joint] = [number(x, f"{joint}.x"), number(y, f"{joint}.y")]
    for name, lk in out["links"].items():
        if joint in lk["joints"]:
            restate(out, name)
    for name, sl in out.get("sliders", {}).items():
        if sl["joint"] == joint:
            restate_slider(out, name)
    for d in out["drivers"]:
        d["theta0"] = driver_angle(out, d)
    return out


def driver_angle(doc: dict, driver: dict) -> float:
    """θ₀ of a crank from the coordinates: the direction from its pivot to its link's other first joint [rad]."""
    lk = doc["links"][driver["link"]]
    other = next(j for j in lk["joints"] if j != driver["pivot"])
    (x0, y0), (x1, y1) = doc["joints"][driver["pivot"]], doc["joints"][other]
    return math.atan2(y1 - y0, x1 - x0)


def set_length(doc: dict, link: Any, value: Any) -> dict:
    """A binary link's length (the joints are placed again by the t = 0 assembly)."""
    out = edited(doc)
    lk = out["links"].get(link)
    if lk is None or lk.get("ground") or len(lk["joints"]) != 2:
        raise EditError(f"link {str(link)[:40]!r}: no moving binary link of that name")
    lk["length"] = number(value, f"{link}.length", positive=True)
    return out


def set_sides(doc: dict, link: Any, sides: Any, angle: Any) -> dict:
    """A plate's two sides from its first joint, |J0J1| and |J0J2|, and the angle J1–J0–J2 [rad, CCW]: its joints are
    placed again by the t = 0 assembly."""
    out = edited(doc)
    lk = out["links"].get(link)
    if lk is None or lk.get("ground") or len(lk["joints"]) != 3:
        raise EditError(f"link {str(link)[:40]!r}: no plate (three joints) of that name")
    if not isinstance(sides, list) or len(sides) != 2:
        raise EditError(f"{link}.sides: two lengths, |J0J1| and |J0J2|")
    lk["sides"] = [number(v, f"{link}.sides", positive=True) for v in sides]
    lk["angle"] = number(angle, f"{link}.angle")
    lk.pop("length", None)
    return out


def set_driver(doc: dict, link: Any, omega: Any, alpha: Any = 0.0, theta0: Any = None) -> dict:
    """The input: link ``link`` turned about its ground pivot, θ(t) = θ₀ + ω·t + α·t²/2 [rad, rad/s, rad/s²]."""
    out = edited(doc)
    lk = out["links"].get(link)
    if lk is None or lk.get("ground"):
        raise EditError(f"driver: no moving link {str(link)[:40]!r}")
    ground = out["links"][ground_name(out)]["joints"]
    pivots = [j for j in lk["joints"] if j in ground]
    if len(pivots) != 1:
        raise EditError(f"driver: link {link} must have exactly one ground pivot to turn about")
    d = {"link": link, "pivot": pivots[0], "omega": number(omega, "omega"), "alpha": number(alpha, "alpha")}
    d["theta0"] = number(theta0, "theta0") if theta0 is not None else driver_angle(out, d)
    if theta0 is not None:  # the crank's joint turned to θ₀ about its pivot, its length kept
        other = next(j for j in lk["joints"] if j != d["pivot"])
        (x0, y0) = out["joints"][d["pivot"]]
        r = lk.get("length") or math.dist(*(out["joints"][j] for j in lk["joints"]))
        out["joints"][other] = [x0 + r * math.cos(d["theta0"]), y0 + r * math.sin(d["theta0"])]
    out["drivers"] = [d]
    return out


def set_time(doc: dict, start: Any, stop: Any, step: Any) -> dict:
    out = edited(doc)
    t0, t1, dt = number(start, "time.start"), number(stop, "time.stop"), number(step, "time.step", positive=True)
    if not t1 > t0 or (t1 - t0) / dt > 1_000_000:
        raise EditError("time: stop must follow start, with at most 1,000,000 steps")
    out["time"] = {"start": t0, "stop": t1, "step": dt}
    return out


def set_meta(doc: dict, name: Any = None, title: Any = None, units: Any = None) -> dict:
    out = edited(doc)
    if name is not None:
        out["name"] = name_of(name, "name")
    if title is not None:
        if not isinstance(title, str) or len(title) > 200:
            raise EditError("title: text of at most 200 characters")
        out["title"] = title
    if units is not None:
        if units not in ("m", "cm", "mm", "km", "in", "ft"):
            raise EditError("units: one of m, cm, mm, km, in, ft")
        out["units"] = units
    return out


def delete(doc: dict, name: Any) -> dict:
    """A joint (with the links through it) or a link removed."""
    out = edited(doc)
    if name in out["joints"]:
        del out["joints"][name]
        gone = [n for n, lk in out["links"].items() if name in lk["joints"] and not lk.get("ground")]
        out["links"][ground_name(out)]["joints"] = [j for j in out["links"][ground_name(out)]["joints"] if j != name]
    elif name in out.get("sliders", {}):
        del out["sliders"][name]
        gone = []
    elif name in out["links"] and not out["links"][name].get("ground"):
        gone = [name]
    else:
        raise EditError(f"delete: no joint or moving link {str(name)[:40]!r}")
    for n in gone:
        del out["links"][n]
    for n in [n for n, sl in out.get("sliders", {}).items() if sl["joint"] not in out["joints"]]:
        del out["sliders"][n]
    out["drivers"] = [d for d in out["drivers"] if d["link"] in out["links"] and d["pivot"] in out["joints"]]
    return out


def file_dict(doc: dict, *, drawn: bool = False) -> dict:
    """The document as a mechanism file's structure (empty sections left out). ``drawn``: its coordinates are the
    assembly (a drag restated every length from them), so the file is read from the coordinates alone — the links'
    lengths, plates' sides and the driver's θ₀ are what the coordinates give — and vloop's t = 0 assembly is not run
    again for a drawing that is already closed."""
    out = {k: v for k, v in edited(doc).items() if v not in ("", [], {})}
    if drawn:
        for lk in out["links"].values():
            for key in ("length", "sides", "angle"):
                lk.pop(key, None)
        for sl in out.get("sliders", {}).values():
            if "axis" in sl:
                sl.pop("offset", None)
        for d in out.get("drivers", []):
            if "link" in d and "pivot" in d:
                d.pop("theta0", None)
    return out
