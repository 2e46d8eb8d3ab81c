"""What a mechanism is: plain, immutable data (read from a file by :mod:`vloop.files.fileformat`).

Conventions (see docs/file-format.md):

* Lengths in the file's units (SI by default), angles in radians, CCW positive from +x.
* Joint coordinates describe the assembly at t = 0.
* A *body* is a rigid part: the ground, every link, and one block per slider.
  A joint named by k bodies is a revolute pin of order k − 1.
* A link's θ is the direction from its first to its second listed joint; a
  one-joint link that guides a slider takes that slider's axis as its θ
  direction; a slider block's θ is its axis direction.
* A slider's s is the signed distance of its joint along the axis from the
  guide's origin (world origin for ground, the guide's first joint otherwise).

Everything here describes the input; nothing here solves the motion, so every
engine (vloop and the validators) reads the same :class:`Mechanism`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from .result import LENGTH_UNITS


@dataclass(frozen=True)
class Link:
    """A rigid link. ``length`` is an optional stated length (binary links only).

    A ternary link (joints J0, J1, J2) may be given by its ``sides``: (|J0J1|, |J1J2|, |J2J0|), the triangle
    turned as its coordinates draw it, or (|J0J1|, |J0J2|) with ``angle``, the angle at J0 from J0→J1 to J0→J2
    [rad, CCW positive].
    """

    name: str
    joints: tuple[str, ...]
    ground: bool = False
    length: float | None = None
    sides: tuple[float, ...] | None = None
    angle: float | None = None

    @property
    def dimensioned(self) -> bool:
        """Whether its shape comes from stated dimensions (a length or sides), not from coordinates."""
        return self.length is not None or self.sides is not None


@dataclass(frozen=True)
class Slider:
    """A block carrying pin ``joint`` that slides along ``axis`` (unit, world, t = 0) of ``guide``.

    Stated dimensions (optional): ``angle``, the axis direction in the guide's frame [rad] (``axis`` is then that
    direction at t = 0); ``offset``, the sliding line's signed distance from the guide's origin, positive to the
    left of the axis [length] (without it the line passes through the joint's coordinates).
    """

    name: str
    joint: str
    guide: str
    axis: tuple[float, float]
    angle: float | None = None
    offset: float | None = None


@dataclass(frozen=True)
class Point:
    """A tracer point fixed to ``link`` (a link or a slider block), at ``at`` when t = 0; ``local``: its stated
    coordinates in that body's frame (``at`` then follows from the body's position)."""

    name: str
    link: str
    at: tuple[float, float]
    local: tuple[float, float] | None = None


@dataclass(frozen=True)
class Profile:
    """A tabulated input: times ``t`` and values ``x`` (θ [rad] or s), optional rates."""

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray | None = None
    a: np.ndarray | None = None
    source: str = "inline"


@dataclass(frozen=True)
class Driver:
    """One input of the mechanism.

    ``kind == "crank"``: ``target`` is a link turned about ``pivot`` (its first
    joint); the input is the link's absolute θ.
    ``kind == "slider"``: ``target`` is a slider; the input is its s.
    Without a profile: x(t) = x0 + v0·t + a0·t²/2 (t from 0, the coordinates' instant).
    """

    kind: str
    target: str
    x0: float
    v0: float = 0.0
    a0: float = 0.0
    pivot: str | None = None
    profile: Profile | None = None
    entry: str = "drivers"
    from_coordinates: bool = field(default=False, compare=False)  # x0 taken from the coordinates (not stated)

    @property
    def symbol(self) -> str:
        return f"θ_{self.target}" if self.kind == "crank" else f"s_{self.target}"

    def value_text(self, x: float, units: str, digits: int = 10) -> str:
        """``symbol = value``: a crank's angle as :func:`angle_text` prints it, a slider's s in ``units``."""
        return f"{self.symbol} = {angle_text(x, digits) if self.kind == 'crank' else f'{x:.{digits}g} {units}'}"

    def range_text(self, lo: float, hi: float, units: str) -> str:
        """The input's range from ``lo`` to ``hi`` (lo <= hi): a crank's as two angles in [0°, 360°) and the
        counter-clockwise travel between them, a slider's as an interval in ``units``."""
        if self.kind != "crank":
            return f"{self.symbol} from {lo:.10g} to {hi:.10g} {units}"
        return (
            f"{self.symbol} from {angle_text(lo)} counter-clockwise to {angle_text(hi)}, a travel of "
            f"{math.degrees(hi - lo):.4f}°"
        )


def angle_text(x: float, digits: int = 10) -> str:
    """An angle as vloop prints it: rad (``digits`` significant) and degrees (4 decimals), wrapped into
    [0, 2π) = [0°, 360°) — an unwrapped θ of 384.1468° prints as 24.1468°; one within the printed precision
    of a full turn prints as 0."""
    w = float(x) % (2 * math.pi)
    if round(math.degrees(w), 4) >= 360.0:
        w = 0.0
    return f"{w:.{digits}g} rad ({math.degrees(w):.4f}°)"


@dataclass(frozen=True)
class Body:
    """A rigid body as every engine sees it.

    ``origin`` is the world position of the body frame origin at t = 0 and
    ``theta0`` the frame's angle at t = 0; ``local`` maps each joint/point on the
    body to its coordinates in the body frame. For a link the frame origin is its
    first joint and the x axis points to its second (θ convention above); for the
    ground the frame is the world frame; for a block, origin at its joint and x
    along the slider axis.
    """

    name: str
    kind: str  # "ground" | "link" | "block"
    joints: tuple[str, ...]
    origin: tuple[float, float]
    theta0: float
    local: dict[str, tuple[float, float]]
    guide: str | None = None  # blocks: the guide body


@dataclass(frozen=True)
class MassProperties:
    """Mass [kg], inertia [kg·m²] about the centre of mass, and the centre of mass (x, y) in world
    coordinates at t = 0 [the file's length units], carried into the body's frame by the frame the coordinates
    give. Unstated, it is the mean of the body's joints as the body is assembled (in its frame, a stated link
    length applied), not of the typed coordinates. ``local``: the centre of mass stated in the body's frame."""

    mass: float
    inertia: float
    com: tuple[float, float]
    local: tuple[float, float] | None = None


@dataclass(frozen=True, eq=False)
class LoadProfile:
    """A tabulated load: times ``t`` [s] and ``values`` (rows; columns ``fx, fy`` [N] or ``torque`` [N·m]),
    linearly interpolated between rows."""

    t: np.ndarray
    values: np.ndarray
    columns: tuple[str, ...]
    source: str = "inline"

    def __eq__(self, other: object) -> bool:
        return (
            isinstance(other, LoadProfile)
            and self.columns == other.columns
            and np.array_equal(self.t, other.t)
            and np.array_equal(self.values, other.values)
        )

    __hash__ = None  # type: ignore[assignment]


@dataclass(frozen=True)
class Load:
    """An external load on a moving body.

    ``kind == "force"``: ``value`` = (fx, fy) [N, world frame] applied at joint/point ``point`` of
    body ``body``; ``kind == "torque"``: ``value`` = τ [N·m, CCW positive] on ``body``. With a
    ``profile`` the value follows the table over time (``value`` is then None).
    """

    kind: str
    body: str
    value: tuple[float, float] | float | None
    point: str | None = None
    profile: LoadProfile | None = None
    entry: str = "loads"


@dataclass(frozen=True)
class Spring:
    """A spring and/or damper of the forward dynamics.

    ``kind == "rotational"``: at pin ``joint`` between bodies ``ends`` = (a, b) (b may be the ground), acting on
    the relative angle φ = θ_a − θ_b [rad]: torque −k·(φ − rest) − c·φ̇ on a, the opposite on b.
    ``kind == "linear"``: between joints/points ``ends`` = (P, Q), acting along their distance L [file length
    units]: tension k·(L − rest) + c·L̇ [N] pulling P and Q together. ``rest``: φ or L at rest (None: as at t = 0).
    Units: k in N·m/rad or N/m, c in N·m·s/rad or N·s/m (lengths in metres).
    """

    kind: str
    ends: tuple[str, str]
    k: float = 0.0
    c: float = 0.0
    rest: float | None = None
    joint: str | None = None
    entry: str = "dynamics.springs"


@dataclass(frozen=True)
class Dynamics:
    """The forward dynamics of a mechanism with one input, or two cranks under gravity (the file's ``[dynamics]``,
    docs/dynamics.md: what two inputs accept).

    The input x (the driver's θ [rad] or s [length]) starts at ``position`` with rate ``rate`` at t = 0 (None:
    the driver's values at t = 0). Loads on the input: a constant ``torque`` [N·m, or N on a slider] or a
    tabulated one (``torque_profile``, columns t, torque), a motor line T = stall·(1 − ẋ/no_load_speed)
    (``motor`` = (stall, no_load_speed)), and a ``flywheel`` [kg·m², or kg on a slider] on the input; the
    file's gravity, masses and [[loads]] act as in the force analysis. Integration: scipy's solve_ivp with
    ``method`` at ``rtol``/``atol`` (rad and rad/s, or m and m/s), rows every ``step`` up to ``stop`` [s].
    """

    position: float | None = None
    rate: float | None = None
    torque: float = 0.0
    torque_profile: LoadProfile | None = None
    motor: tuple[float, float] | None = None
    flywheel: float = 0.0
    springs: tuple[Spring, ...] = ()
    method: str = "DOP853"
    rtol: float = 1e-10
    atol: float = 1e-10
    stop: float | None = None  # the simulated rows: 0, step, … stop [s] (None: the file's [time])
    step: float | None = None


SYSTEMS_KEY = "_loop_systems"  # the LoopSystems vloop.solve compiled for a Mechanism, kept on the object


@dataclass(frozen=True)
class Mechanism:
    """A planar linkage as described by its file. Immutable; engines read it."""

    name: str
    joints: dict[str, tuple[float, float]]
    links: dict[str, Link]
    sliders: dict[str, Slider]
    points: dict[str, Point]
    drivers: tuple[Driver, ...]
    times: np.ndarray
    title: str = ""
    units: str = "m"
    source: str = ""
    options: dict[str, Any] = field(default_factory=dict)
    # kinetostatics (docs/forces.md): bodies without an entry are massless
    masses: dict[str, MassProperties] = field(default_factory=dict)
    gravity: tuple[float, float] | None = None  # m/s², world frame
    loads: tuple[Load, ...] = ()
    # written from dimensions (docs/dimensions.md): the coordinates of moving joints are hints,
    # and ``unplaced`` joints have none (placed provisionally until vloop.authoring assembles the mechanism)
    from_dimensions: bool = False
    unplaced: tuple[str, ...] = ()
    # until assembled, the hints may lie anywhere: ``scale`` is at most this reach (its dimensions' sum and its ground
    # pivots' span, vloop.files.dimensions.reach), so that no far hint loosens a tolerance of the assembly
    reach: float | None = None
    # forward dynamics (docs/dynamics.md): the [dynamics] section, None without one
    dynamics: Dynamics | None = None

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without the LoopSystems compiled for it (compiled again where it lands, if solved there)."""
        return {k: v for k, v in self.__dict__.items() if k != SYSTEMS_KEY}

    # ----- derived views (pure functions of the description) -----
    @cached_property
    def ground(self) -> str:
        return next(n for n, lk in self.links.items() if lk.ground)

    @cached_property
    def body_names(self) -> tuple[str, ...]:
        """Ground first, then links in file order, then slider blocks."""
        return (self.ground, *(n for n, lk in self.links.items() if not lk.ground), *self.sliders)

    @property
    def moving_links(self) -> tuple[str, ...]:
        """Every body with a θ in the output: moving links then slider blocks."""
        return self.body_names[1:]

    @property
    def tracked_points(self) -> tuple[str, ...]:
        """Every joint and tracer point (output order: joints, then points)."""
        return (*self.joints, *self.points)

    def bodies_at(self, joint: str) -> tuple[str, ...]:
        """Bodies that name ``joint`` (a slider block names its own joint)."""
        return self._bodies_by_joint.get(joint, ())

    @cached_property
    def _bodies_by_joint(self) -> dict[str, tuple[str, ...]]:
        """joint → the bodies naming it: links in file order, then slider blocks (built once)."""
        out: dict[str, list[str]] = {}
        for n, lk in self.links.items():
            for j in lk.joints:
                out.setdefault(j, []).append(n)
        for s in self.sliders.values():
            out.setdefault(s.joint, []).append(s.name)
        return {j: tuple(bs) for j, bs in out.items()}

    def body_of_point(self, name: str) -> str:
        """The body that carries a joint/point for position purposes (first naming body)."""
        if name in self.points:
            return self.points[name].link
        return self.bodies_at(name)[0]

    def pin_order(self, joint: str) -> int:
        return max(len(self.bodies_at(joint)) - 1, 0)

    def gruebler(self) -> tuple[int, int, int]:
        """(L, J, M): bodies incl. ground, full joints (pins of order k count k, sliders 1), mobility."""
        n_bodies = len(self.body_names)
        n_joints = sum(self.pin_order(j) for j in self.joints) + len(self.sliders)
        return n_bodies, n_joints, 3 * (n_bodies - 1) - 2 * n_joints

    def bodies(self) -> dict[str, Body]:
        """Body frames and local joint coordinates (stated lengths, sides and local coordinates applied)."""
        return _bodies(self)

    def _repr_html_(self) -> str:
        """A notebook's summary: what it is (mobility, drivers, run), then its bodies, sliders, points, drivers."""
        import html

        from .result import html_table

        L, J, M = self.gruebler()
        t = self.times
        run = f"{len(t):,} samples, t = {t[0]:g} … {t[-1]:g} s" if len(t) else "no sample"
        how = "written from dimensions" if self.from_dimensions else "coordinates at t = 0"
        head = (
            f"<p><b>{html.escape(self.title or self.name)}</b> ({html.escape(self.name)}; {html.escape(self.units)}, "
            f"{how}): L = {L} bodies, J = {J} joints, Gruebler M = {M}; {len(self.drivers)} driver(s); {run}</p>"
        )
        return head + html_table(self._html_rows(), ["name", "kind", "joints", "dimensions"], "bodies and inputs")

    def _html_rows(self) -> list[list[str]]:
        """One row per link, slider, tracer point and driver."""
        rows = []
        for n, lk in self.links.items():
            dims = f"length {lk.length:g}" if lk.length is not None else ""
            if lk.sides is not None:
                dims = f"sides {', '.join(f'{x:g}' for x in lk.sides)}" + (
                    f", angle {lk.angle:g} rad" if lk.angle else ""
                )
            coords = "pivots at their coordinates" if lk.ground else "from the coordinates"
            rows.append([n, "ground" if lk.ground else "link", " – ".join(lk.joints), dims or coords])
        for n, sl in self.sliders.items():
            dims = f"axis ({sl.axis[0]:.4g}, {sl.axis[1]:.4g})" + (f", offset {sl.offset:g}" if sl.offset else "")
            rows.append([n, f"slider on {sl.guide}", sl.joint, dims])
        rows += [[n, f"point on {p.link}", "", f"at ({p.at[0]:.4g}, {p.at[1]:.4g})"] for n, p in self.points.items()]
        for d in self.drivers:
            unit = "rad" if d.kind == "crank" else self.units
            motion = "profile" if d.profile is not None else f"{d.x0:.6g} {unit} + {d.v0:g}·t + {d.a0:g}·t²/2"
            rows.append([d.target, f"driver ({d.kind})", d.pivot or "", motion])
        return rows

    def body_joints(self, body: str) -> tuple[str, ...]:
        """A link's joints, or a slider's one joint."""
        return self.links[body].joints if body in self.links else (self.sliders[body].joint,)

    @cached_property
    def largest_dimension(self) -> float:
        """The largest stated dimension (link lengths and sides, slider offsets, local coordinates), 0 if none."""
        sizes = [x for lk in self.links.values() for x in (lk.length or 0.0, *(lk.sides or ()))]
        sizes += [abs(s.offset or 0.0) for s in self.sliders.values()]
        sizes += [math.hypot(*p.local) for p in self.points.values() if p.local is not None]
        return max(sizes, default=0.0)

    @cached_property
    def scale(self) -> float:
        """A length scale: the diagonal of the bounding box of all joints/points at t = 0 (at most ``reach``)."""
        pts = [*self.joints.values(), *(p.at for p in self.points.values())]
        if len(pts) < 2:
            return 1.0
        span = [_ptp([float(x) for x in axis]) for axis in zip(*pts, strict=True)]  # np.ptp's, in Python numbers
        return float(max(min(math.hypot(*span), self.reach or math.inf), 1e-300))


def _ptp(xs: list[float]) -> float:
    """max − min (nan if any x is nan, as numpy's)."""
    return max(xs) - min(xs) if all(x == x for x in xs) else math.nan


# ---------------------------------------------------------------- bodies


def _angle(v: tuple[float, float]) -> float:
    return math.atan2(v[1], v[0]) % (2 * math.pi)


def to_world(body: Body, local: tuple[float, float]) -> tuple[float, float]:
    """World coordinates at t = 0 of a point given in a body's frame."""
    c, s = math.cos(body.theta0), math.sin(body.theta0)
    return body.origin[0] + c * local[0] - s * local[1], body.origin[1] + s * local[0] + c * local[1]


def joint_mean(body: Body, joints: tuple[str, ...]) -> tuple[float, float]:
    """The mean of ``joints`` in the body's frame (as assembled: rigid, its stated length applied), in world
    coordinates through the frame at t = 0: the default centre of mass."""
    lx = sum(body.local[j][0] for j in joints) / len(joints)
    ly = sum(body.local[j][1] for j in joints) / len(joints)
    return to_world(body, (lx, ly))


def third_corner(lk: Link, p: list[tuple[float, float]]) -> tuple[float, float]:
    """J2 of a ternary link stated by its sides, in the link's frame (J0 at the origin, J1 on +x); with three sides
    on the side of J0→J1 where the coordinates ``p`` (of J0, J1, J2) draw it."""
    assert lk.sides is not None
    if len(lk.sides) == 2:
        c, phi = lk.sides[1], lk.angle or 0.0
        return c * math.cos(phi), c * math.sin(phi)
    a, b, c = lk.sides
    x = (a * a + c * c - b * b) / (2 * a)
    y = math.sqrt(max(c * c - x * x, 0.0))
    turn = (p[1][0] - p[0][0]) * (p[2][1] - p[0][1]) - (p[1][1] - p[0][1]) * (p[2][0] - p[0][0])
    return x, y if turn >= 0 else -y


def _bodies(m: Mechanism) -> dict[str, Body]:
    out: dict[str, Body] = {}
    guided: dict[str, list[Slider]] = {}
    for s in m.sliders.values():
        guided.setdefault(s.guide, []).append(s)

    carried: dict[str, tuple[str, ...]] = {}  # the points on each body
    for p in m.points.values():
        carried[p.link] = (*carried.get(p.link, ()), p.name)

    def pos(name: str) -> tuple[float, float]:
        return m.points[name].at if name in m.points else m.joints[name]

    def on_body(body: str, joints: tuple[str, ...]) -> tuple[str, ...]:
        return joints + carried.get(body, ())

    for name, lk in m.links.items():
        members = on_body(name, lk.joints)
        if lk.ground:
            local = _stated_points(m, carried.get(name, ()), {j: pos(j) for j in members})
            out[name] = Body(name, "ground", lk.joints, (0.0, 0.0), 0.0, local)
            continue
        o = pos(lk.joints[0])
        if len(lk.joints) >= 2:
            p1 = pos(lk.joints[1])
            th = _angle((p1[0] - o[0], p1[1] - o[1]))
        else:
            th = _angle(guided[name][0].axis)
        c, s = math.cos(th), math.sin(th)
        local = {}
        for j in members:
            x, y = pos(j)
            dx, dy = x - o[0], y - o[1]
            local[j] = (c * dx + s * dy, -s * dx + c * dy)
        if len(lk.joints) >= 2:  # the x axis points at the second joint by definition
            stated = lk.length if lk.length is not None else (lk.sides[0] if lk.sides else None)
            local[lk.joints[1]] = (stated if stated is not None else math.dist(o, pos(lk.joints[1])), 0.0)
        if lk.sides is not None:
            local[lk.joints[2]] = third_corner(lk, [pos(j) for j in lk.joints])
        out[name] = Body(name, "link", lk.joints, o, th, _stated_points(m, carried.get(name, ()), local))
    for name, sl in m.sliders.items():
        o = pos(sl.joint)
        th = _angle(sl.axis)
        c, s = math.cos(th), math.sin(th)
        local = {}
        for j in on_body(name, (sl.joint,)):
            x, y = pos(j)
            dx, dy = x - o[0], y - o[1]
            local[j] = (c * dx + s * dy, -s * dx + c * dy)
        out[name] = Body(name, "block", (sl.joint,), o, th, _stated_points(m, carried.get(name, ()), local), sl.guide)
    return out


def _stated_points(m: Mechanism, points: tuple[str, ...], local: dict) -> dict:
    """A body's local coordinates with its points' stated ``local`` coordinates applied."""
    for p in points:
        if m.points[p].local is not None:
            local[p] = m.points[p].local
    return local


# ---------------------------------------------------------------- units and mobility

# LENGTH_UNITS (from vloop.result): the length units vloop converts (factor to metres); the force analysis needs one
# (masses in kg, forces in N), so a file with masses or loads in other units is refused.


def length_factor(units: str) -> float:
    """Metres per length unit of the file (KeyError for a unit vloop does not know)."""
    return LENGTH_UNITS[units.strip().lower()]


def mobility_message(mech: Mechanism, rank_note: str = "") -> str:
    """The one-line explanation of a mobility mismatch: Gruebler's count against the drivers given."""
    L, J, M = mech.gruebler()
    n = len(mech.drivers)
    if M <= 0:
        meaning = (
            "it is a rigid structure"
            if M == 0
            else f"it is over-constrained by {-M} (a statically indeterminate structure)"
        )
        hint = "it cannot move: check the joints and sliders"
    else:
        meaning = f"it has {M} independent degree{'s' if M > 1 else ''} of freedom"
        hint = f"give exactly {M} driver{'s' if M > 1 else ''}" if n < M else "remove a driver"
    return (
        f"{mech.source}: [drivers] mobility mismatch: Gruebler M = 3(L-1) - 2J = 3({L}-1) - 2*{J} = {M}, "
        f"so {meaning}, but {n} driver{'s are' if n != 1 else ' is'} given{rank_note}; {hint}"
    )
