"""The mechanism description: plain, immutable data read from a TOML file.

Conventions (see README "Mechanism file"):

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
import tomllib
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from .errors import MechanismError

MAX_SAMPLES = 10_000_000  # beyond this a time grid is refused (memory, not maths)
COINCIDENT_TOL = 1e-9  # relative to the mechanism's size: two joints on one link closer than this


@dataclass(frozen=True)
class Link:
    """A rigid link. ``length`` is an optional stated length (binary links only)."""

    name: str
    joints: tuple[str, ...]
    ground: bool = False
    length: float | None = None


@dataclass(frozen=True)
class Slider:
    """A block carrying pin ``joint`` that slides along ``axis`` (unit, world, t = 0) of ``guide``."""

    name: str
    joint: str
    guide: str
    axis: tuple[float, float]


@dataclass(frozen=True)
class Point:
    """A tracer point fixed to ``link`` (a link or a slider block), at ``at`` when t = 0."""

    name: str
    link: str
    at: tuple[float, float]


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

    @property
    def symbol(self) -> str:
        return f"θ_{self.target}" if self.kind == "crank" else f"s_{self.target}"


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
    coordinates at t = 0 [the file's length units]."""

    mass: float
    inertia: float
    com: tuple[float, float]


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
    # kinetostatics (README "Masses and loads"): bodies without an entry are massless
    masses: dict[str, MassProperties] = field(default_factory=dict)
    gravity: tuple[float, float] | None = None  # m/s², world frame
    loads: tuple[Load, ...] = ()

    # ----- derived views (pure functions of the description) -----
    @property
    def ground(self) -> str:
        return next(n for n, lk in self.links.items() if lk.ground)

    @property
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
        out = [n for n, lk in self.links.items() if joint in lk.joints]
        out += [s.name for s in self.sliders.values() if s.joint == joint]
        return tuple(out)

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
        """Body frames and local joint coordinates (stated binary-link lengths applied)."""
        return _bodies(self)

    @cached_property
    def scale(self) -> float:
        """A length scale: the diagonal of the bounding box of all joints/points at t = 0."""
        pts = np.array([*self.joints.values(), *(p.at for p in self.points.values())], float)
        if len(pts) < 2:
            return 1.0
        span = np.ptp(pts, axis=0)
        return float(max(math.hypot(*span), 1e-300))


# ---------------------------------------------------------------- bodies


def _angle(v: tuple[float, float]) -> float:
    return math.atan2(v[1], v[0]) % (2 * math.pi)


def _bodies(m: Mechanism) -> dict[str, Body]:
    out: dict[str, Body] = {}
    guided: dict[str, list[Slider]] = {}
    for s in m.sliders.values():
        guided.setdefault(s.guide, []).append(s)

    def pos(name: str) -> tuple[float, float]:
        return m.points[name].at if name in m.points else m.joints[name]

    def on_body(body: str, joints: tuple[str, ...]) -> tuple[str, ...]:
        return joints + tuple(p.name for p in m.points.values() if p.link == body)

    for name, lk in m.links.items():
        members = on_body(name, lk.joints)
        if lk.ground:
            out[name] = Body(name, "ground", lk.joints, (0.0, 0.0), 0.0, {j: pos(j) for j in members})
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
            dx, dy = pos(j)[0] - o[0], pos(j)[1] - o[1]
            local[j] = (c * dx + s * dy, -s * dx + c * dy)
        if len(lk.joints) >= 2:  # the x axis points at the second joint by definition
            local[lk.joints[1]] = (lk.length if lk.length is not None else math.dist(o, pos(lk.joints[1])), 0.0)
        out[name] = Body(name, "link", lk.joints, o, th, local)
    for name, sl in m.sliders.items():
        o = pos(sl.joint)
        th = _angle(sl.axis)
        c, s = math.cos(th), math.sin(th)
        local = {}
        for j in on_body(name, (sl.joint,)):
            dx, dy = pos(j)[0] - o[0], pos(j)[1] - o[1]
            local[j] = (c * dx + s * dy, -s * dx + c * dy)
        out[name] = Body(name, "block", (sl.joint,), o, th, local, guide=sl.guide)
    return out


# ---------------------------------------------------------------- loading

_TOP_KEYS = {"name", "title", "units", "joints", "links", "sliders", "points", "drivers", "time", "solver"}
_TOP_KEYS |= {"gravity", "loads"}  # kinetostatics
_MASS_KEYS = {"mass", "inertia", "com"}


class _Problems:
    """Collects every problem found in one validation stage, raised as one message."""

    def __init__(self, where: str) -> None:
        self.where = where
        self.items: list[tuple[str, str]] = []

    def add(self, entry: str, msg: str) -> None:
        self.items.append((entry, msg))

    def raise_if_any(self) -> None:
        if self.items:
            entry = self.items[0][0]
            text = "; ".join(f"[{e}] {m}" for e, m in self.items)
            raise MechanismError(f"{self.where}: {text}", entry=entry)


def _finite_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


def _xy(value: Any, entry: str, probs: _Problems) -> tuple[float, float] | None:
    if (
        not isinstance(value, list)
        or len(value) != 2
        or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
    ):
        probs.add(entry, f"expected a pair of numbers [x, y], got {value!r}")
        return None
    if not all(math.isfinite(v) for v in value):
        probs.add(entry, f"non-finite coordinate {value!r}")
        return None
    return float(value[0]), float(value[1])


def _number(table: dict, key: str, entry: str, probs: _Problems, default: float | None = None) -> float | None:
    if key not in table:
        return default
    v = table[key]
    if not isinstance(v, (int, float)) or isinstance(v, bool):
        probs.add(entry, f"'{key}' must be a number, got {v!r}")
        return default
    if not math.isfinite(v):
        probs.add(entry, f"'{key}' is not finite ({v!r})")
        return default
    return float(v)


def _check_keys(table: dict, allowed: set[str], entry: str, probs: _Problems) -> None:
    for k in table:
        if k not in allowed:
            probs.add(entry, f"unknown key '{k}' (allowed: {', '.join(sorted(allowed))})")


def load(path: str | Path) -> Mechanism:
    """Read and validate a mechanism file. Raises :class:`MechanismError` on any problem."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise MechanismError(f"{path}: cannot read file ({exc.strerror or exc})", entry=str(path)) from None
    except UnicodeDecodeError:
        raise MechanismError(f"{path}: not a UTF-8 text file", entry=str(path)) from None
    return loads(text, source=str(path), base_dir=path.parent)


def loads(text: str, *, source: str = "<string>", base_dir: str | Path | None = None) -> Mechanism:
    """Parse and validate a mechanism from TOML text (see :func:`load`)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise MechanismError(f"{source}: TOML syntax error: {exc}", entry="toml") from None
    return from_dict(data, source=source, base_dir=base_dir)


def from_dict(data: dict, *, source: str = "<dict>", base_dir: str | Path | None = None) -> Mechanism:
    """Build and validate a Mechanism from the parsed TOML structure."""
    base = Path(base_dir) if base_dir is not None else Path.cwd()
    probs = _Problems(source)
    if not isinstance(data, dict):
        raise MechanismError(f"{source}: expected a TOML table at top level")
    _check_keys(data, _TOP_KEYS, "file", probs)

    name = data.get("name", Path(source).stem if source not in ("<string>", "<dict>") else "mechanism")
    if not isinstance(name, str) or not name:
        probs.add("name", "must be a non-empty string")
        name = "mechanism"
    title = data.get("title", "")
    units = data.get("units", "m")
    for key, val in (("title", title), ("units", units)):
        if not isinstance(val, str):
            probs.add(key, "must be a string")

    # --- joints
    joints: dict[str, tuple[float, float]] = {}
    raw_joints = data.get("joints")
    if not isinstance(raw_joints, dict) or not raw_joints:
        probs.add("joints", "missing or empty: give every pin/slider point as NAME = [x, y]")
        raw_joints = {}
    for jn, val in raw_joints.items():
        xy = _xy(val, f"joints.{jn}", probs)
        if xy is not None:
            joints[jn] = xy

    # --- links
    links: dict[str, Link] = {}
    raw_links = data.get("links")
    if not isinstance(raw_links, dict) or not raw_links:
        probs.add("links", "missing or empty: give each link as NAME = { joints = [...] }")
        raw_links = {}
    for ln, val in raw_links.items():
        entry = f"links.{ln}"
        if isinstance(val, list):  # shorthand NAME = ["A", "B"]
            val = {"joints": val}
        if not isinstance(val, dict):
            probs.add(entry, f"expected a table {{ joints = [...] }}, got {val!r}")
            continue
        _check_keys(val, {"joints", "ground", "length", *_MASS_KEYS}, entry, probs)
        jl = val.get("joints", [])
        if not isinstance(jl, list) or not all(isinstance(j, str) for j in jl):
            probs.add(entry, "'joints' must be a list of joint names")
            continue
        if not jl:
            probs.add(entry, "has no joints")
            continue
        if len(set(jl)) != len(jl):
            dup = sorted({j for j in jl if jl.count(j) > 1})
            probs.add(entry, f"names joint {', '.join(dup)} twice")
            continue
        for j in jl:
            if j not in raw_joints:
                probs.add(entry, f"unknown joint '{j}' (known: {', '.join(raw_joints) or 'none'})")
        ground = val.get("ground", False)
        if not isinstance(ground, bool):
            probs.add(entry, "'ground' must be true or false")
            ground = False
        length = _number(val, "length", entry, probs)
        if length is not None:
            if len(jl) != 2:
                probs.add(entry, "'length' is only for binary links (two joints)")
                length = None
            elif length <= 0:
                probs.add(entry, f"'length' must be positive, got {length}")
                length = None
        links[ln] = Link(ln, tuple(jl), ground, length)
    grounds = [n for n, lk in links.items() if lk.ground]
    if links and not grounds:
        probs.add("links", "no ground link: mark the frame with ground = true")
    elif len(grounds) > 1:
        probs.add("links", f"more than one ground link ({', '.join(grounds)}): list every fixed joint on one ground")
    ground_name = grounds[0] if grounds else None

    # --- sliders
    sliders: dict[str, Slider] = {}
    raw_sliders = data.get("sliders", {})
    if not isinstance(raw_sliders, dict):
        probs.add("sliders", "must be a table of NAME = { joint, guide, axis }")
        raw_sliders = {}
    for sn, val in raw_sliders.items():
        entry = f"sliders.{sn}"
        if not isinstance(val, dict):
            probs.add(entry, f"expected a table {{ joint, guide, axis }}, got {val!r}")
            continue
        _check_keys(val, {"joint", "guide", "axis", *_MASS_KEYS}, entry, probs)
        if sn in links:
            probs.add(entry, f"duplicate name: '{sn}' is also a link (a slider's name is its block's name)")
            continue
        j = val.get("joint")
        if not isinstance(j, str) or j not in raw_joints:
            probs.add(entry, f"unknown joint {j!r}" if isinstance(j, str) else "missing 'joint'")
            continue
        guide = val.get("guide", "ground")
        if guide == "ground" and ground_name is not None:
            guide = ground_name
        if not isinstance(guide, str) or guide not in links:
            probs.add(entry, f"unknown guide link {guide!r} (a guide is a link or 'ground')")
            continue
        if j in links[guide].joints:
            probs.add(
                entry, f"the guide '{guide}' names the slider's joint '{j}': a block cannot be pinned to its own guide"
            )
            continue
        ax = _xy(val.get("axis"), f"{entry}.axis", probs)
        if ax is None:
            continue
        norm = math.hypot(*ax)
        if norm < 1e-12:
            probs.add(entry, "axis has zero length")
            continue
        sliders[sn] = Slider(sn, j, guide, (ax[0] / norm, ax[1] / norm))

    # --- points
    points: dict[str, Point] = {}
    raw_points = data.get("points", {})
    if not isinstance(raw_points, dict):
        probs.add("points", "must be a table of NAME = { link, at }")
        raw_points = {}
    for pn, val in raw_points.items():
        entry = f"points.{pn}"
        if not isinstance(val, dict):
            probs.add(entry, f"expected a table {{ link, at }}, got {val!r}")
            continue
        _check_keys(val, {"link", "at"}, entry, probs)
        if pn in raw_joints:
            probs.add(entry, f"duplicate name: '{pn}' is also a joint")
            continue
        lk = val.get("link")
        if not isinstance(lk, str) or (lk not in links and lk not in raw_sliders):
            probs.add(entry, f"unknown link {lk!r}")
            continue
        at = _xy(val.get("at"), f"{entry}.at", probs)
        if at is not None:
            points[pn] = Point(pn, lk, at)

    probs.raise_if_any()

    # --- topology checks
    proto = Mechanism(name, joints, links, sliders, points, (), np.zeros(1), title, units, source)
    _check_topology(proto, probs)
    probs.raise_if_any()

    # --- drivers, time
    drivers = _load_drivers(data.get("drivers"), proto, base, probs)
    probs.raise_if_any()
    times = _load_time(data.get("time"), drivers, probs)
    options = _load_solver(data.get("solver", {}), probs)
    dynamics = _load_dynamics(data, proto, base, probs)
    probs.raise_if_any()
    times.flags.writeable = False

    mech = Mechanism(
        name, joints, links, sliders, points, tuple(drivers), times, title, units, source, options, **dynamics
    )
    if mech.gruebler()[2] > len(drivers):  # fewer drivers than Gruebler's count: never enough to fix the motion
        raise MechanismError(mobility_message(mech), entry="drivers")
    return mech  # Gruebler's count below the drivers may be a redundant linkage: the compiler decides by rank


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


def _check_topology(m: Mechanism, probs: _Problems) -> None:
    scale = m.scale
    named = {j for lk in m.links.values() for j in lk.joints} | {s.joint for s in m.sliders.values()}
    for j in m.joints:
        if j not in named:
            probs.add(f"joints.{j}", "is named by no link or slider")
    for lk in m.links.values():
        pts = [m.joints[j] for j in lk.joints]
        for i in range(len(pts)):
            for k in range(i + 1, len(pts)):
                if math.dist(pts[i], pts[k]) <= COINCIDENT_TOL * scale:
                    probs.add(
                        f"links.{lk.name}",
                        f"joints {lk.joints[i]} and {lk.joints[k]} coincide (zero-length link)",
                    )
        if not lk.ground and len(lk.joints) == 1 and not any(s.guide == lk.name for s in m.sliders.values()):
            probs.add(
                f"links.{lk.name}",
                "has a single joint: a moving link needs two (add its tip as a joint) unless it guides a slider",
            )
    if probs.items:
        return
    # connectivity: bodies joined by pins (shared joints) and slider pairs
    parent = {b: b for b in m.body_names}

    def find(b: str) -> str:
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        return b

    for j in m.joints:
        bs = m.bodies_at(j)
        for b in bs[1:]:
            parent[find(b)] = find(bs[0])
    for s in m.sliders.values():
        parent[find(s.name)] = find(s.guide)
    g = find(m.ground)
    loose = [b for b in m.body_names if find(b) != g]
    if loose:
        probs.add("links", f"disconnected mechanism: {', '.join(loose)} not connected to the ground '{m.ground}'")


def _read_profile(
    spec: Any, cols: tuple[str, str, str, str], entry: str, base: Path, probs: _Problems
) -> Profile | None:
    """A profile from an inline table of arrays or a CSV file with a header row."""
    tcol, xcol, vcol, acol = cols
    if isinstance(spec, str):
        path = base / spec
        try:
            arr = np.genfromtxt(path, delimiter=",", names=True, dtype=float, encoding="utf-8")
        except (OSError, ValueError) as exc:
            probs.add(entry, f"cannot read profile '{spec}': {exc}")
            return None
        if arr.dtype.names is None or arr.ndim != 1 or arr.size < 2:
            probs.add(entry, f"profile '{spec}' needs a header row and at least two data rows")
            return None
        table = {n.strip().lower(): np.atleast_1d(arr[n]) for n in arr.dtype.names}
        source = str(spec)
    elif isinstance(spec, dict):
        table = {}
        for k, v in spec.items():
            if not isinstance(v, list) or not all(_finite_number(x) for x in v):
                probs.add(entry, f"profile column '{k}' must be a list of finite numbers")
                return None
            table[k.lower()] = np.asarray(v, float)
        source = "inline"
    else:
        probs.add(entry, "'profile' must be a CSV file name or a table of columns")
        return None
    if tcol not in table or xcol not in table:
        probs.add(entry, f"profile needs columns '{tcol}' and '{xcol}' (has {', '.join(table)})")
        return None
    t = table[tcol]
    n = len(t)
    for k in (tcol, xcol, vcol, acol):
        if k in table and (len(table[k]) != n or not np.all(np.isfinite(table[k]))):
            probs.add(entry, f"profile column '{k}' has missing or non-finite values")
            return None
    if n < 2:
        probs.add(entry, "profile needs at least two rows")
        return None
    if np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        probs.add(entry, f"profile time is not strictly increasing (row {k + 1}: t = {t[k]:g} after {t[k - 1]:g})")
        return None
    return Profile(t, table[xcol], table.get(vcol), table.get(acol), source)


def _motion(
    d: dict,
    keys: tuple[str, str, str],
    cols: tuple[str, str, str, str],
    x_coords: float,
    entry: str,
    base: Path,
    probs: _Problems,
) -> tuple[float, float, float, Profile | None]:
    """A driver's x0 (default: from the coordinates), rate and acceleration, or its profile."""
    x0 = _number(d, keys[0], entry, probs, x_coords)
    v0 = _number(d, keys[1], entry, probs, 0.0)
    a0 = _number(d, keys[2], entry, probs, 0.0)
    prof = None
    if "profile" in d:
        for k in keys:
            if k in d:
                probs.add(entry, f"'{k}' and 'profile' both given: the profile sets the motion")
        prof = _read_profile(d["profile"], cols, entry, base, probs)
        x0 = float(prof.x[0]) if prof is not None else x0
    return x0, v0, a0, prof


def _load_drivers(raw: Any, m: Mechanism, base: Path, probs: _Problems) -> list[Driver]:
    if raw is None:
        probs.add("drivers", "missing: give at least one [[drivers]] entry (a crank or a driven slider)")
        return []
    if isinstance(raw, dict):
        raw = [raw]
    if not isinstance(raw, list):
        probs.add("drivers", "must be an array of tables [[drivers]]")
        return []
    bodies = m.bodies() if not probs.items else {}
    out: list[Driver] = []
    seen: set[str] = set()
    for i, d in enumerate(raw):
        entry = f"drivers[{i}]"
        if not isinstance(d, dict):
            probs.add(entry, "must be a table")
            continue
        if "link" in d:
            _check_keys(d, {"link", "pivot", "omega", "alpha", "theta0", "profile"}, entry, probs)
            ln = d["link"]
            entry = f"drivers[{i}] (link {ln})"
            if ln in m.sliders:
                probs.add(
                    entry,
                    f"'{ln}' is a slider block, which cannot turn relative to its guide; drive it with slider = '{ln}'",
                )
                continue
            if ln not in m.links:
                probs.add(entry, f"unknown link '{ln}'")
                continue
            if m.links[ln].ground:
                probs.add(entry, f"'{ln}' is the ground, which cannot be driven")
                continue
            lk = m.links[ln]
            pivot = d.get("pivot", lk.joints[0])
            if pivot not in lk.joints:
                probs.add(entry, f"pivot '{pivot}' is not a joint of link '{ln}'")
                continue
            if pivot != lk.joints[0]:
                probs.add(
                    entry, f"pivot '{pivot}' must be the first joint listed for link '{ln}' (its θ is measured from it)"
                )
                continue
            x0, v0, a0, prof = _motion(
                d, ("theta0", "omega", "alpha"), ("t", "theta", "omega", "alpha"), bodies[ln].theta0, entry, base, probs
            )
            key = f"link:{ln}"
            drv = Driver("crank", ln, x0, v0, a0, pivot, prof, entry)
        elif "slider" in d:
            _check_keys(d, {"slider", "s0", "v", "a", "profile"}, entry, probs)
            sn = d["slider"]
            entry = f"drivers[{i}] (slider {sn})"
            if sn not in m.sliders:
                probs.add(entry, f"unknown slider '{sn}'")
                continue
            sl = m.sliders[sn]
            gb = bodies[sl.guide]
            p = m.joints[sl.joint]
            s_coords = (p[0] - gb.origin[0]) * sl.axis[0] + (p[1] - gb.origin[1]) * sl.axis[1]
            x0, v0, a0, prof = _motion(d, ("s0", "v", "a"), ("t", "s", "v", "a"), s_coords, entry, base, probs)
            key = f"slider:{sn}"
            drv = Driver("slider", sn, x0, v0, a0, None, prof, entry)
        else:
            probs.add(entry, "needs 'link' (a crank) or 'slider' (a linear actuator)")
            continue
        if key in seen:
            probs.add(entry, f"{drv.target} is driven twice")
            continue
        seen.add(key)
        out.append(drv)
    return out


def _load_time(raw: Any, drivers: list[Driver], probs: _Problems) -> np.ndarray:
    if raw is None:
        profs = [d.profile for d in drivers if d.profile is not None]
        if profs:
            return np.array(profs[0].t, float)
        probs.add("time", "missing: give [time] start, stop, step (or times = [...])")
        return np.zeros(1)
    if not isinstance(raw, dict):
        probs.add("time", "must be a table")
        return np.zeros(1)
    _check_keys(raw, {"start", "stop", "step", "times"}, "time", probs)
    if "times" in raw:
        ts = raw["times"]
        if not isinstance(ts, list) or not ts or not all(_finite_number(x) for x in ts):
            probs.add("time", "'times' must be a non-empty list of finite numbers")
            return np.zeros(1)
        t = np.asarray(ts, float)
        if np.any(np.diff(t) <= 0):
            probs.add("time", "'times' must be strictly increasing")
        if len(t) > MAX_SAMPLES:
            probs.add("time", f"{len(t)} samples is more than the limit of {MAX_SAMPLES}")
        return t
    start = _number(raw, "start", "time", probs, 0.0)
    stop = _number(raw, "stop", "time", probs)
    step = _number(raw, "step", "time", probs)
    if stop is None or step is None:
        if not probs.items:
            probs.add("time", "needs 'stop' and 'step' (or 'times')")
        return np.zeros(1)
    if step <= 0:
        probs.add("time", f"step must be positive, got {step:g}")
        return np.zeros(1)
    if stop < start:
        probs.add("time", f"stop ({stop:g}) is before start ({start:g})")
        return np.zeros(1)
    n = math.floor((stop - start) / step + 1e-9) + 1  # up to and including stop, never past it
    if n > MAX_SAMPLES:
        probs.add(
            "time",
            f"step {step:g} over [{start:g}, {stop:g}] gives {n:,} samples, more than the limit of {MAX_SAMPLES:,}",
        )
        return np.zeros(1)
    return start + step * np.arange(n)


_SOLVER_KEYS = {"method", "tol", "rtol", "max_iter", "assembly_tolerance", "branches", "change_points"}
BRANCH_CHOICES = ("open", "crossed", "flip", "keep")
CHANGE_POINT_CHOICES = ("smooth", "other")


def _load_solver(raw: Any, probs: _Problems) -> dict[str, Any]:
    if not isinstance(raw, dict):
        probs.add("solver", "must be a table")
        return {}
    _check_keys(raw, _SOLVER_KEYS, "solver", probs)
    out: dict[str, Any] = {}
    if "method" in raw:
        if raw["method"] not in ("auto", "newton"):
            probs.add("solver", "method must be 'auto' or 'newton'")
        else:
            out["method"] = raw["method"]
    for k in ("tol", "rtol", "assembly_tolerance"):
        v = _number(raw, k, "solver", probs)
        if v is not None:
            if not 0 < v < 1:
                probs.add("solver", f"{k} must be between 0 and 1 (a fraction), got {v:g}")
            out[k] = v
    if "change_points" in raw:
        cp = raw["change_points"]

        def ok(v: Any) -> bool:
            if isinstance(v, list):
                return bool(v) and all(x in CHANGE_POINT_CHOICES for x in v)
            return v in CHANGE_POINT_CHOICES

        if not isinstance(cp, dict) or not all(isinstance(k, str) and k.isdigit() and ok(v) for k, v in cp.items()):
            probs.add(
                "solver",
                'change_points must map loop numbers to "smooth" or "other" (or a list of them for successive '
                'change points), e.g. { 1 = "other" }',
            )
        else:
            out["change_points"] = {int(k): v for k, v in cp.items()}
    if "branches" in raw:
        br = raw["branches"]
        if not isinstance(br, dict) or not all(
            isinstance(k, str) and k.isdigit() and int(k) >= 1 and v in BRANCH_CHOICES for k, v in br.items()
        ):
            probs.add(
                "solver",
                "branches must map loop numbers to one of " + ", ".join(BRANCH_CHOICES) + ', e.g. { 1 = "crossed" }',
            )
        else:
            out["branches"] = {int(k): v for k, v in br.items()}
    if "max_iter" in raw:
        if not isinstance(raw["max_iter"], int) or raw["max_iter"] < 1:
            probs.add("solver", "max_iter must be a positive integer")
        else:
            out["max_iter"] = raw["max_iter"]
    return out


# ---------------------------------------------------------------- masses, gravity, loads (kinetostatics)

# Length units the force analysis knows (factor to metres): masses are in kg, forces in N, so the
# file's lengths must be converted; a file with masses or loads in other units is refused.
LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "km": 1000.0, "in": 0.0254, "ft": 0.3048}


def length_factor(units: str) -> float:
    """Metres per length unit of the file (KeyError for a unit vloop does not know)."""
    return LENGTH_UNITS[units.strip().lower()]


def _real(value: Any, what: str, entry: str, probs: _Problems) -> float | None:
    """A finite real number, or None after recording why not (bools, strings, 10**400, nan, inf)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        probs.add(entry, f"'{what}' must be a number, got {value!r}")
        return None
    try:
        x = float(value)
    except OverflowError:
        probs.add(entry, f"'{what}' is too large ({str(value)[:20]}...)")
        return None
    if not math.isfinite(x):
        probs.add(entry, f"'{what}' is not finite ({value!r})")
        return None
    return x + 0.0  # -0.0 → 0.0


def _real_pair(value: Any, what: str, entry: str, probs: _Problems) -> tuple[float, float] | None:
    if not isinstance(value, list) or len(value) != 2:
        probs.add(entry, f"'{what}' must be a pair of numbers [x, y], got {value!r}")
        return None
    xy = [_real(v, what, entry, probs) for v in value]
    return None if None in xy else (xy[0], xy[1])  # type: ignore[return-value]


def _load_dynamics(data: dict, m: Mechanism, base: Path, probs: _Problems) -> dict[str, Any]:
    """Mechanism fields ``masses``, ``gravity``, ``loads`` (all optional) from the file."""
    masses = _load_masses(data, m, probs)
    gravity = None
    if "gravity" in data:
        gravity = _real_pair(data["gravity"], "gravity", "gravity", probs)
    loads = _load_loads(data.get("loads"), m, base, probs)
    if (masses or loads or gravity) and m.units.strip().lower() not in LENGTH_UNITS:
        probs.add(
            "units",
            f"forces need a length unit vloop knows ({', '.join(LENGTH_UNITS)}), got {m.units!r}",
        )
    return {"masses": masses, "gravity": gravity, "loads": tuple(loads)}


def _load_masses(data: dict, m: Mechanism, probs: _Problems) -> dict[str, MassProperties]:
    """``mass`` [kg], ``inertia`` [kg·m² about the centre of mass], ``com = [x, y]`` on links and blocks."""
    out: dict[str, MassProperties] = {}
    tables = [("links", n, v) for n, v in (data.get("links") or {}).items()]
    tables += [("sliders", n, v) for n, v in (data.get("sliders") or {}).items()]
    for section, name, val in tables:
        if not isinstance(val, dict) or not _MASS_KEYS & set(val):
            continue
        entry = f"{section}.{name}"
        if section == "links" and m.links[name].ground:
            probs.add(entry, "the ground does not move: it takes no mass, inertia or com")
            continue
        mass = _real(val.get("mass", 0.0), "mass", entry, probs)
        inertia = _real(val.get("inertia", 0.0), "inertia", entry, probs)
        joints = m.links[name].joints if section == "links" else (m.sliders[name].joint,)
        mean = (
            sum(m.joints[j][0] for j in joints) / len(joints),
            sum(m.joints[j][1] for j in joints) / len(joints),
        )
        com = _real_pair(val["com"], "com", entry, probs) if "com" in val else mean
        for what, x in (("mass", mass), ("inertia", inertia)):
            if x is not None and x < 0:
                probs.add(entry, f"'{what}' must not be negative, got {x:g}")
        if mass is not None and inertia is not None and com is not None and mass >= 0 and inertia >= 0:
            out[name] = MassProperties(mass, inertia, com)
    return out


def _load_loads(raw: Any, m: Mechanism, base: Path, probs: _Problems) -> list[Load]:
    if raw is None:
        return []
    if not isinstance(raw, list):
        probs.add("loads", "must be an array of tables [[loads]]")
        return []
    out = []
    for i, d in enumerate(raw):
        entry = f"loads[{i}]"
        if not isinstance(d, dict):
            probs.add(entry, "must be a table")
            continue
        _check_keys(d, {"point", "link", "force", "torque", "profile"}, entry, probs)
        load = _load_one(d, m, entry, base, probs)
        if load is not None:
            out.append(load)
    return out


def _load_body(d: dict, m: Mechanism, entry: str, probs: _Problems) -> tuple[str | None, str | None]:
    """(point, body) of a load: the body defaults to the point's link, or the slider block at a joint."""
    point, body = d.get("point"), d.get("link")
    moving = set(m.body_names[1:])
    if point is not None and (not isinstance(point, str) or (point not in m.joints and point not in m.points)):
        probs.add(entry, f"unknown point {point!r} (a joint or a tracer point)")
        return None, None
    if body is not None and (not isinstance(body, str) or body not in m.body_names):
        probs.add(entry, f"unknown link {body!r}")
        return None, None
    if body is not None and body not in moving:
        probs.add(entry, f"'{body}' is the ground: a load on it moves nothing")
        return None, None
    if point is None:
        return None, body
    carriers = (m.points[point].link,) if point in m.points else m.bodies_at(point)
    if body is None:
        blocks = [s.name for s in m.sliders.values() if s.joint == point]
        body = blocks[0] if blocks else next((b for b in carriers if b in moving), None)
        if body is None:
            probs.add(entry, f"'{point}' is on the ground only: a load there moves nothing")
    elif body not in carriers:
        probs.add(entry, f"'{point}' is not on '{body}' (it is on {', '.join(carriers)})")
        body = None
    return point, body


def _load_one(d: dict, m: Mechanism, entry: str, base: Path, probs: _Problems) -> Load | None:
    point, body = _load_body(d, m, entry, probs)
    given = [k for k in ("force", "torque", "profile") if k in d]
    if "profile" in d and len(given) > 1:
        probs.add(entry, f"'{given[0]}' and 'profile' both given: the profile sets the load")
        return None
    if len(given) != 1:
        probs.add(entry, "give one of force = [fx, fy] (with point), torque = T (with link) or a profile")
        return None
    kind = "force" if point is not None else "torque"
    if ("force" in d and point is None) or ("torque" in d and point is not None):
        probs.add(entry, "a force needs a point (and optionally a link); a torque needs a link and no point")
        return None
    if kind == "torque" and body is None and "link" not in d:
        probs.add(entry, "a torque load needs the link it acts on")
    if body is None:
        return None
    if "profile" in d:
        spec = d["profile"]
        if isinstance(spec, dict) and not all(
            isinstance(v, list) and all(_real(x, "profile", entry, _Problems("")) is not None for x in v)
            for v in spec.values()
        ):
            probs.add(entry, "profile columns must be lists of finite numbers")
            return None
        cols = ("t", "fx", "fy", "") if kind == "force" else ("t", "torque", "", "")
        prof = _read_profile(d["profile"], cols, entry, base, probs)
        if prof is None:
            return None
        if kind == "force" and prof.v is None:
            probs.add(entry, "a force profile needs columns 't', 'fx' and 'fy'")
            return None
        columns = ("fx", "fy") if kind == "force" else ("torque",)
        values = np.column_stack([prof.x, prof.v] if kind == "force" else [prof.x])
        return Load(kind, body, None, point, LoadProfile(prof.t, values, columns, prof.source), entry)
    if kind == "force":
        value: Any = _real_pair(d["force"], "force", entry, probs)
    else:
        value = _real(d["torque"], "torque", entry, probs)
    return None if value is None else Load(kind, body, value, point, None, entry)


# ---------------------------------------------------------------- saving


def to_dict(mech: Mechanism) -> dict[str, Any]:
    """The TOML structure of a Mechanism (:func:`from_dict` reads it back to an equal Mechanism).

    Tabulated profiles are written inline (``profile = { t = [...], theta = [...] }``);
    the time grid as an explicit ``times`` list.
    """
    out: dict[str, Any] = {"name": mech.name}
    if mech.title:
        out["title"] = mech.title
    out["units"] = mech.units
    out["joints"] = {j: list(xy) for j, xy in mech.joints.items()}
    links: dict[str, Any] = {}
    for n, lk in mech.links.items():
        entry: dict[str, Any] = {"joints": list(lk.joints)}
        if lk.ground:
            entry["ground"] = True
        if lk.length is not None:
            entry["length"] = lk.length
        links[n] = entry
    out["links"] = links
    if mech.sliders:
        out["sliders"] = {
            n: {"joint": s.joint, "guide": s.guide, "axis": list(s.axis)} for n, s in mech.sliders.items()
        }
    if mech.points:
        out["points"] = {n: {"link": p.link, "at": list(p.at)} for n, p in mech.points.items()}
    drivers = []
    for d in mech.drivers:
        names = ("theta0", "omega", "alpha") if d.kind == "crank" else ("s0", "v", "a")
        cols = ("t", "theta", "omega", "alpha") if d.kind == "crank" else ("t", "s", "v", "a")
        entry = {"link": d.target, "pivot": d.pivot} if d.kind == "crank" else {"slider": d.target}
        if d.profile is None:
            entry.update(zip(names, (d.x0, d.v0, d.a0), strict=True))
        else:
            p = d.profile
            prof = {cols[0]: p.t.tolist(), cols[1]: p.x.tolist()}
            if p.v is not None:
                prof[cols[2]] = p.v.tolist()
            if p.a is not None:
                prof[cols[3]] = p.a.tolist()
            entry["profile"] = prof
        drivers.append(entry)
    out["drivers"] = drivers
    out["time"] = {"times": mech.times.tolist()}
    if mech.options:
        out["solver"] = dict(mech.options)
        for key in ("branches", "change_points"):
            if key in out["solver"]:
                out["solver"][key] = {str(k): v for k, v in out["solver"][key].items()}
    _dynamics_to_dict(mech, out)
    return out


def _dynamics_to_dict(mech: Mechanism, out: dict[str, Any]) -> None:
    """Add masses (on their link/slider tables), gravity and loads to a to_dict structure."""
    for name, mp in mech.masses.items():
        table = out["links"][name] if name in mech.links else out["sliders"][name]
        table.update(mass=mp.mass, inertia=mp.inertia, com=list(mp.com))
    if mech.gravity is not None:
        out["gravity"] = list(mech.gravity)
    loads = []
    for ld in mech.loads:
        entry: dict[str, Any] = {"link": ld.body}
        if ld.point is not None:
            entry["point"] = ld.point
        if ld.profile is not None:
            p = ld.profile
            entry["profile"] = {"t": p.t.tolist(), **{c: p.values[:, i].tolist() for i, c in enumerate(p.columns)}}
        elif ld.kind == "force":
            entry["force"] = list(ld.value)  # type: ignore[arg-type]
        else:
            entry["torque"] = ld.value
        loads.append(entry)
    if loads:
        out["loads"] = loads


def dumps(mech: Mechanism) -> str:
    """The mechanism as TOML text (see :func:`to_dict`)."""
    import tomli_w

    return tomli_w.dumps(to_dict(mech))


def save(mech: Mechanism, path: str | Path) -> None:
    """Write the mechanism to a TOML file that :func:`load` reads back to an equal Mechanism."""
    Path(path).write_text(dumps(mech), encoding="utf-8")
