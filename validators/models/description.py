"""The mechanism as plain data, for the scripts ``vloop export --format exudyn|pinocchio`` writes.

A script carries the mechanism as a literal (:func:`describe`: the body frames and local coordinates of
:meth:`vloop.mechanism.Mechanism.bodies`, the joints, sliders, tracer points, drivers and times) and the
classes below, which give the model-building code of the validators (copied into the script verbatim) the
attributes it reads from a :class:`vloop.mechanism.Mechanism` — so the script builds the model the validators
build, without vloop. This module's classes are copied into every script too: it imports numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Body:
    """A rigid body: its frame at t = 0 (``origin``, ``theta0`` [rad]) and its joints' coordinates in it."""

    name: str
    kind: str  # "ground" | "link" | "block"
    joints: tuple[str, ...]
    origin: tuple[float, float]
    theta0: float
    local: dict[str, tuple[float, float]]
    guide: str | None = None


@dataclass(frozen=True)
class Slider:
    """A block carrying pin ``joint``, sliding along ``axis`` (unit, world, t = 0) of body ``guide``."""

    name: str
    joint: str
    guide: str
    axis: tuple[float, float]


@dataclass(frozen=True)
class Profile:
    """A tabulated input: times [s], values (θ [rad] or s), optional rates and accelerations."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray | None = None
    a: np.ndarray | None = None


@dataclass(frozen=True)
class Driver:
    """One input: a link's absolute θ (``crank``) or a slider's s; x(t) = x0 + v0·t + a0·t²/2 or a profile."""

    kind: str
    target: str
    x0: float
    v0: float = 0.0
    a0: float = 0.0
    pivot: str | None = None
    profile: Profile | None = None
    entry: str = "drivers"

    @property
    def symbol(self) -> str:
        return f"θ_{self.target}" if self.kind == "crank" else f"s_{self.target}"

    def value_text(self, x: float, units: str, digits: int = 10) -> str:
        return f"{self.symbol} = {x:.{digits}g}" + (" rad" if self.kind == "crank" else f" {units}")


@dataclass(frozen=True)
class LoadProfile:
    """A tabulated load: times [s] and rows of ``columns`` (fx, fy [N] or torque [N·m]), linear between rows."""

    t: np.ndarray
    values: np.ndarray
    columns: tuple[str, ...]


@dataclass(frozen=True)
class Load:
    """A force (fx, fy) [N, world] at ``point`` of ``body``, or a torque τ [N·m, CCW] on it; or a table of them."""

    kind: str
    body: str
    value: Any
    point: str | None = None
    profile: LoadProfile | None = None


@dataclass
class Mechanism:
    """What the model-building code reads of a mechanism (the names of :class:`vloop.mechanism.Mechanism`)."""

    name: str
    units: str
    scale: float
    ground: str
    joints: dict[str, tuple[float, float]]
    body_frames: dict[str, Body]
    sliders: dict[str, Slider]
    points: dict[str, str]  # tracer point -> the body that carries it
    drivers: tuple[Driver, ...]
    times: np.ndarray
    by_joint: dict[str, tuple[str, ...]] = field(default_factory=dict)
    masses_table: dict[str, tuple[float, np.ndarray, float]] = field(default_factory=dict)  # kg, body frame, kg·m²
    gravity: tuple[float, float] | None = None  # m/s²
    loads: tuple[Load, ...] = ()
    length_factor: float = 1.0  # metres per length unit

    @property
    def body_names(self) -> tuple[str, ...]:
        return tuple(self.body_frames)

    @property
    def moving_links(self) -> tuple[str, ...]:
        return self.body_names[1:]

    @property
    def tracked_points(self) -> tuple[str, ...]:
        return (*self.joints, *self.points)

    def bodies(self) -> dict[str, Body]:
        return self.body_frames

    def bodies_at(self, joint: str) -> tuple[str, ...]:
        return self.by_joint.get(joint, ())

    def body_of_point(self, name: str) -> str:
        return self.points[name] if name in self.points else self.bodies_at(name)[0]


def from_data(d: dict[str, Any]) -> Mechanism:
    """The :class:`Mechanism` of a script's data literal."""

    def profile(p: dict[str, Any] | None) -> Profile | None:
        if p is None:
            return None
        arr = {k: (None if p.get(k) is None else np.asarray(p[k], float)) for k in ("t", "x", "v", "a")}
        return Profile(arr["t"], arr["x"], arr["v"], arr["a"])

    bodies = {
        n: Body(
            n,
            b["kind"],
            tuple(b["joints"]),
            tuple(b["origin"]),
            b["theta0"],
            {j: tuple(xy) for j, xy in b["local"].items()},
            b.get("guide"),
        )
        for n, b in d["bodies"].items()
    }
    return Mechanism(
        d["name"],
        d["units"],
        d["scale"],
        d["ground"],
        {j: tuple(xy) for j, xy in d["joints"].items()},
        bodies,
        {n: Slider(n, s["joint"], s["guide"], tuple(s["axis"])) for n, s in d["sliders"].items()},
        dict(d["points"]),
        tuple(Driver(**{**v, "profile": profile(v.get("profile"))}) for v in d["drivers"]),
        np.asarray(d["times"], float),
        {j: tuple(bs) for j, bs in d["bodies_at"].items()},
        {b: (m, np.asarray(c, float), i) for b, (m, c, i) in d.get("masses", {}).items()},
        None if d.get("gravity") is None else tuple(d["gravity"]),
        tuple(
            Load(
                ld["kind"],
                ld["body"],
                None if ld["value"] is None else (tuple(ld["value"]) if ld["kind"] == "force" else ld["value"]),
                ld["point"],
                None
                if ld["profile"] is None
                else LoadProfile(
                    np.asarray(ld["profile"]["t"], float),
                    np.asarray(ld["profile"]["values"], float),
                    tuple(ld["profile"]["columns"]),
                ),
            )
            for ld in d.get("loads", [])
        ),
        d.get("length_factor", 1.0),
    )


def describe(mech: Any) -> dict[str, Any]:
    """A :class:`vloop.mechanism.Mechanism` as the plain data :func:`from_data` reads (lists, floats, strings)."""

    def arr(a: Any) -> list[float] | None:
        return None if a is None else [float(x) for x in np.asarray(a, float)]

    return {
        "name": mech.name,
        "units": mech.units,
        "scale": float(mech.scale),
        "ground": mech.ground,
        "joints": {j: [float(x), float(y)] for j, (x, y) in mech.joints.items()},
        "bodies": {
            n: {
                "kind": b.kind,
                "joints": list(b.joints),
                "origin": [float(c) for c in b.origin],
                "theta0": float(b.theta0),
                "local": {j: [float(c) for c in xy] for j, xy in b.local.items()},
                "guide": b.guide,
            }
            for n, b in mech.bodies().items()
        },
        "sliders": {
            n: {"joint": s.joint, "guide": s.guide, "axis": [float(c) for c in s.axis]} for n, s in mech.sliders.items()
        },
        "points": {n: p.link for n, p in mech.points.items()},
        "drivers": [
            {
                "kind": d.kind,
                "target": d.target,
                "x0": float(d.x0),
                "v0": float(d.v0),
                "a0": float(d.a0),
                "pivot": d.pivot,
                "profile": None if d.profile is None else {k: arr(getattr(d.profile, k)) for k in ("t", "x", "v", "a")},
            }
            for d in mech.drivers
        ],
        "times": arr(mech.times),
        "bodies_at": {j: list(mech.bodies_at(j)) for j in mech.joints},
        **_dynamics(mech),
    }


def _dynamics(mech: Any) -> dict[str, Any]:
    """Masses (body -> [kg, centre of mass in the body frame, kg·m²]), gravity [m/s²], loads, metres per unit."""
    if not (mech.masses or mech.gravity or mech.loads):
        return {}
    from vloop.model import LENGTH_UNITS

    from ..forces_common import mass_table

    def value(v: Any) -> Any:
        return None if v is None else ([float(x) for x in v] if isinstance(v, tuple) else float(v))

    return {
        "masses": {b: [float(m), [float(x) for x in c], float(i)] for b, (m, c, i) in mass_table(mech).items()},
        "gravity": None if mech.gravity is None else [float(x) for x in mech.gravity],
        "loads": [
            {
                "kind": ld.kind,
                "body": ld.body,
                "value": value(ld.value),
                "point": ld.point,
                "profile": None
                if ld.profile is None
                else {
                    "t": [float(x) for x in ld.profile.t],
                    "values": np.asarray(ld.profile.values, float).tolist(),
                    "columns": list(ld.profile.columns),
                },
            }
            for ld in mech.loads
        ],
        "length_factor": LENGTH_UNITS.get(mech.units.strip().lower(), 1.0),
    }
