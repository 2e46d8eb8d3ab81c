"""Reading and writing mechanism files: TOML → Mechanism (one small reader per section) and back.

The keys each reader accepts come from :mod:`vloop.files.schema`. Every problem is a
:class:`~vloop.errors.MechanismError` naming the file, the entry and what is wrong, never a
traceback: non-finite or huge numbers, deep nesting, unsafe names, files that are not regular
files, profiles outside the mechanism's folder (unless allowed), oversized inputs.
"""

from __future__ import annotations

import dataclasses
import math
import os
import stat
import tomllib
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import MechanismError
from ..model import (
    LENGTH_UNITS,
    Driver,
    Dynamics,
    Link,
    Load,
    LoadProfile,
    MassProperties,
    Mechanism,
    Point,
    Profile,
    Slider,
    Spring,
    joint_mean,
    mobility_message,
    to_world,
)
from .dimensions import (
    axes_from_angles,
    check_lengths,
    check_proportions,
    check_ternaries,
    dimension_mode,
    dimension_size,
    place_joints,
    points_from_local,
    reach,
)
from .schema import (
    FAR,
    SIZES,
    TOP_LEVEL,
    Problems,
    beyond_sizes,
    check_keys,
    direction,
    name_problem,
    number,
    pair,
    real,
    show,
)

MAX_SAMPLES = 10**12  # a ceiling for absurd counts; the limit that applies is the memory budget (_time_limit)
TIME_BYTES = 16  # per sample of a time grid: the array and the check of its steps (see vloop.files.budget)


def _time_limit(n: float) -> str | None:
    """Why a time grid of n samples is refused (it alone would exceed the memory budget), or None."""
    from .budget import budget, fmt_size

    limit, source = budget()
    if n <= MAX_SAMPLES and n * TIME_BYTES <= limit:
        return None
    return (
        f"{n:,.0f} samples: the time grid alone needs {fmt_size(n * TIME_BYTES)}, more than the memory budget of "
        f"{fmt_size(limit)} ({source}); use a larger step or a shorter run, or raise VLOOP_MEMORY_BUDGET"
    )


MAX_FILE_BYTES = 64 * 2**20  # a mechanism file larger than this is refused before reading
MAX_PROFILE_BYTES = 2**30  # a profile CSV larger than this is refused before reading
MAX_PROFILE_ROWS = 10_000_000
MAX_ANGLE = 1e6  # rad: a larger angle's floating-point spacing (≥ 1.2e-10 rad) nears the solver's rtol
COINCIDENT_TOL = 1e-9  # relative to the mechanism's size: two joints on one link closer than this
BRANCH_CHOICES = ("open", "crossed", "flip", "keep")
CHANGE_POINT_CHOICES = ("smooth", "other")


@dataclass(frozen=True)
class _Context:
    source: str
    base: Path
    allow_external_profiles: bool


# ---------------------------------------------------------------- entry points


def load(path: str | Path, *, allow_external_profiles: bool = False) -> Mechanism:
    """Read and validate a mechanism file. Raises :class:`MechanismError` on any problem.

    Profiles (CSV) must lie inside the file's folder unless ``allow_external_profiles``.
    """
    path = Path(path)
    text = _read_text_file(path, MAX_FILE_BYTES, what="file", entry=str(path))
    return loads(text, source=str(path), base_dir=path.parent, allow_external_profiles=allow_external_profiles)


def loads(
    text: str, *, source: str = "<string>", base_dir: str | Path | None = None, allow_external_profiles: bool = False
) -> Mechanism:
    """Parse and validate a mechanism from TOML text (see :func:`load`). A leading byte-order mark is ignored."""
    data = parse_toml(text, source)
    return from_dict(data, source=source, base_dir=base_dir, allow_external_profiles=allow_external_profiles)


def parse_toml(text: str, source: str) -> Any:
    """The TOML structure of ``text`` (a leading byte-order mark ignored); MechanismError naming ``source`` for
    a syntax error or nesting too deep to parse. Every vloop file (mechanism, study, synthesis) is read so."""
    try:
        return tomllib.loads(text.removeprefix("\ufeff"))
    except tomllib.TOMLDecodeError as exc:
        raise MechanismError(f"{source}: TOML syntax error: {exc}", entry="toml") from None
    except RecursionError:
        raise MechanismError(
            f"{source}: TOML nested too deeply (arrays or tables inside each other)", entry="toml"
        ) from None


def from_dict(
    data: dict, *, source: str = "<dict>", base_dir: str | Path | None = None, allow_external_profiles: bool = False
) -> Mechanism:
    """Build and validate a Mechanism from the parsed TOML structure: one reader per section, in order."""
    ctx = _Context(source, Path(base_dir) if base_dir is not None else Path.cwd(), allow_external_profiles)
    probs = Problems(source)
    if not isinstance(data, dict):
        raise MechanismError(f"{source}: expected a TOML table at top level", entry="file")
    check_keys(data, "file", "file", probs, extra=TOP_LEVEL)
    name, title, units = read_meta(data, source, probs)
    joints = read_joints(data.get("joints"), probs)
    missing: dict[str, str] = {}  # joints named without coordinates → the entry naming them first
    links = read_links(data.get("links"), joints, probs, missing)
    sliders = read_sliders(data.get("sliders", {}), joints, links, probs, missing)
    points = read_points(data.get("points", {}), joints, links, sliders, probs, set(missing))
    probs.raise_if_any()
    read = Mechanism(name, joints, links, sliders, points, (), np.zeros(1), title, units, source)
    proto = _geometry(data, read, missing, probs)
    check_extent(proto, probs)
    probs.raise_if_any()
    if proto.from_dimensions:
        proto = dataclasses.replace(proto, reach=reach(proto))
    check_topology(proto, probs)
    probs.raise_if_any()
    proto = dataclasses.replace(proto, points=points_from_local(proto, proto.points))  # through its body frames
    drivers = read_drivers(data.get("drivers"), proto, ctx, probs)
    probs.raise_if_any()
    times = read_time(data.get("time"), drivers, probs)
    options = read_solver(data.get("solver", {}), probs)
    dynamics = read_dynamics(data, proto, ctx, probs)
    if "dynamics" in data:
        dynamics["dynamics"] = read_simulation(data["dynamics"], proto, drivers, ctx, probs)
    probs.raise_if_any()
    times.flags.writeable = False
    mech = dataclasses.replace(proto, drivers=tuple(drivers), times=times, options=options, **dynamics)
    if mech.gruebler()[2] > len(drivers):  # fewer drivers than Gruebler's count: never enough to fix the motion
        raise MechanismError(mobility_message(mech), entry="drivers")
    return mech  # Gruebler's count below the drivers may be a redundant linkage: the compiler decides by rank


def _geometry(data: dict, m: Mechanism, missing: dict[str, str], probs: Problems) -> Mechanism:
    """The mechanism's t = 0 geometry: written from dimensions or not (:mod:`vloop.files.dimensions`), joints
    without coordinates placed provisionally, slider axes from their angles (points given by their local coordinates
    are placed once the topology is checked)."""
    dims, lacks = dimension_mode(m.links, m.sliders, m.points, data, probs)
    ground = m.ground if any(lk.ground for lk in m.links.values()) else None
    for j, entry in missing.items():
        if not dims or (ground is not None and j in m.links[ground].joints):
            known = ", ".join(list(m.joints)[:20]) or "none"
            why = "a ground joint needs its coordinates"
            if not dims:
                why = f"only a file written from dimensions may leave a joint without coordinates; here {lacks}"
            probs.add(entry, f"unknown joint {show(j)} (known: {known}; {why})")
    check_ternaries(m.links, m.joints, probs)
    probs.raise_if_any()
    joints = place_joints(m.joints, m.links, m.sliders, missing, probs) if missing else m.joints
    probs.raise_if_any()
    sliders = axes_from_angles(m.sliders, m.links, joints)
    return dataclasses.replace(m, joints=joints, sliders=sliders, from_dimensions=dims, unplaced=tuple(missing))


def _read_text_file(path: Path, limit: int, *, what: str, entry: str) -> str:
    """A regular file's UTF-8 text (a byte-order mark dropped), refused if larger than ``limit`` bytes."""
    if "\x00" in str(path):
        raise MechanismError(f"{show(str(path))}: a path cannot contain a NUL character", entry=entry)
    try:
        st = os.stat(path)
    except OSError as exc:
        raise MechanismError(
            f"{path}: cannot read {what} ({(exc.strerror or str(exc)).lower()})", entry=entry
        ) from None
    if not stat.S_ISREG(st.st_mode):
        raise MechanismError(f"{path}: not a regular file (a folder, pipe or device)", entry=entry)
    if st.st_size > limit:
        raise MechanismError(f"{path}: {st.st_size:,} bytes, more than the {limit:,} vloop reads", entry=entry)
    try:
        with open(path, "rb") as fh:  # a buffer of the file's size, not of the limit (64 MB for every small file)
            raw = fh.read(st.st_size + 1)
            if len(raw) > st.st_size:  # it grew since: read on, up to the limit
                raw += fh.read(limit + 1 - len(raw))
    except OSError as exc:
        raise MechanismError(
            f"{path}: cannot read {what} ({(exc.strerror or str(exc)).lower()})", entry=entry
        ) from None
    if len(raw) > limit:
        raise MechanismError(f"{path}: more than the {limit:,} bytes vloop reads", entry=entry)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise MechanismError(f"{path}: not a UTF-8 text file", entry=entry) from None


# ---------------------------------------------------------------- sections


def read_meta(data: dict, source: str, probs: Problems) -> tuple[str, str, str]:
    """name (default: the file's name), title, units."""
    default = Path(source).stem if source not in ("<string>", "<dict>") else "mechanism"
    name = data.get("name", default)
    if not isinstance(name, str) or not name.strip() or "\x00" in name or len(name) > 200:
        probs.add("name", f"must be a non-empty string without NUL, at most 200 characters, got {show(name)}")
        name = "mechanism"
    title, units = data.get("title", ""), data.get("units", "m")
    for key, val in (("title", title), ("units", units)):
        if not isinstance(val, str) or "\x00" in val:
            probs.add(key, f"must be a string, got {show(val)}")
    return name, title if isinstance(title, str) else "", units if isinstance(units, str) else "m"


def _names(table: Any, section: str, probs: Problems) -> dict:
    """A section's table with only its well-named entries (problems recorded for the others)."""
    out = {}
    for key, val in table.items():
        why = name_problem(key)
        if why:
            probs.add(section, why)
        else:
            out[key] = val
    return out


def read_joints(raw: Any, probs: Problems) -> dict[str, tuple[float, float]]:
    """[joints] NAME = [x, y]."""
    if not isinstance(raw, dict) or not raw:
        probs.add("joints", "missing or empty: give every pin/slider point as NAME = [x, y]")
        return {}
    joints = {}
    for jn, val in _names(raw, "joints", probs).items():
        xy = pair(val, "coordinate", f"joints.{jn}", probs)
        if xy is not None:
            joints[jn] = xy
    return joints


def read_links(raw: Any, joints: dict, probs: Problems, missing: dict[str, str]) -> dict[str, Link]:
    """[links] NAME = { joints, ground, length, sides, angle } (masses are read with the dynamics). Joints named
    without coordinates go to ``missing`` (joint → entry): only a file written from dimensions may have them."""
    if not isinstance(raw, dict) or not raw:
        probs.add("links", "missing or empty: give each link as NAME = { joints = [...] }")
        return {}
    links: dict[str, Link] = {}
    for ln, val in _names(raw, "links", probs).items():
        link = _read_link(ln, {"joints": val} if isinstance(val, list) else val, joints, probs, missing)
        if link is not None:
            links[ln] = link
    grounds = [n for n, lk in links.items() if lk.ground]
    if links and not grounds:
        probs.add("links", "no ground link: mark the frame with ground = true")
    elif len(grounds) > 1:
        probs.add("links", f"more than one ground link ({', '.join(grounds)}): list every fixed joint on one ground")
    return links


def _read_link(ln: str, val: Any, joints: dict, probs: Problems, missing: dict[str, str]) -> Link | None:
    entry = f"links.{ln}"
    if not isinstance(val, dict):
        probs.add(entry, f"expected a table {{ joints = [...] }}, got {show(val)}")
        return None
    check_keys(val, "links", entry, probs)
    jl = val.get("joints", [])
    if not isinstance(jl, list) or not all(isinstance(j, str) for j in jl):
        probs.add(entry, "'joints' must be a list of joint names")
        return None
    if not jl:
        probs.add(entry, "has no joints")
        return None
    if len(set(jl)) != len(jl):
        probs.add(entry, f"names joint {', '.join(sorted({j for j in jl if jl.count(j) > 1}))} twice")
        return None
    for j in jl:
        if j not in joints:
            _missing_joint(j, entry, joints, probs, missing)
    ground = val.get("ground", False)
    if not isinstance(ground, bool):
        probs.add(entry, "'ground' must be true or false")
        ground = False
    length = number(val, "length", entry, probs)
    if length is not None and len(jl) != 2:
        probs.add(entry, "'length' is only for binary links (two joints)")
        length = None
    elif length is not None and length <= 0:
        probs.add(entry, f"'length' must be positive, got {length:g}")
        length = None
    sides, turn = _read_sides(val, jl, entry, probs)
    if ground and (length is not None or sides is not None):
        probs.add(entry, "the ground's dimensions are its joints' coordinates: it takes no length or sides")
    return Link(ln, tuple(jl), ground, length, sides, turn)


def angle(table: dict, key: str, entry: str, probs: Problems, default: float | None = None) -> float | None:
    """``table[key]`` as an angle [rad] within ±MAX_ANGLE, ``default`` if absent (or after recording a problem)."""
    x = number(table, key, entry, probs, default)
    if x is not None and abs(x) > MAX_ANGLE:
        probs.add(entry, f"'{key}' = {x:.6g} rad cannot be resolved: beyond ±{MAX_ANGLE:g} rad an angle's "
                  f"floating-point spacing is {math.ulp(x):.2g} rad (give the angle modulo 2π)")  # fmt: skip
        return default
    return x


def _missing_joint(j: str, entry: str, joints: dict, probs: Problems, missing: dict[str, str]) -> None:
    """A joint named without coordinates: kept in ``missing`` if its name is valid (a file written from dimensions
    may leave it out; :func:`_geometry` decides)."""
    if name_problem(j):
        probs.add(entry, f"unknown joint {show(j)} (known: {', '.join(list(joints)[:20]) or 'none'})")
    else:
        missing.setdefault(j, entry)


def _read_sides(val: dict, jl: list, entry: str, probs: Problems) -> tuple[tuple[float, ...] | None, float | None]:
    """A ternary link's ``sides`` (three, or two with ``angle``), checked: positive, a triangle."""
    raw, turn = val.get("sides"), angle(val, "angle", entry, probs)
    if "angle" in val and turn is None:
        return None, None
    if raw is None:
        if turn is not None:
            probs.add(entry, "'angle' goes with two sides: sides = [|J0J1|, |J0J2|]")
        return None, None
    if len(jl) != 3 or "length" in val:
        probs.add(entry, "'sides' is for ternary links (three joints), instead of 'length'")
        return None, None
    if not isinstance(raw, list) or len(raw) not in (2, 3):
        probs.add(entry, f"'sides' must be [a, b, c] or [a, c] with 'angle', got {show(raw)}")
        return None, None
    sides = [real(x, "sides", entry, probs) for x in raw]
    if None in sides:
        return None, None
    if min(sides) <= 0:  # type: ignore[type-var]
        probs.add(entry, f"'sides' must be positive, got {show(raw)}")
        return None, None
    if (len(sides) == 2) != (turn is not None):
        probs.add(entry, "two sides need the 'angle' between them; three sides take no angle")
        return None, None
    a, b, c = sides if len(sides) == 3 else (sides[0], 1.0, 1.0)  # type: ignore[misc]
    if len(sides) == 3 and not (a < b + c and b < a + c and c < a + b):
        why = "each must be shorter than the other two together; a straight ternary link: two sides, angle = 0 or pi"
        probs.add(entry, f"sides {a:g}, {b:g}, {c:g} of {'-'.join(jl)} cannot form a triangle ({why})")
        return None, None
    return tuple(sides), turn  # type: ignore[arg-type]


def read_sliders(
    raw: Any, joints: dict, links: dict[str, Link], probs: Problems, missing: dict[str, str]
) -> dict[str, Slider]:
    """[sliders] NAME = { joint, guide, axis | angle, offset }."""
    if not isinstance(raw, dict):
        probs.add("sliders", "must be a table of NAME = { joint, guide, axis }")
        return {}
    ground = next((n for n, lk in links.items() if lk.ground), None)
    sliders: dict[str, Slider] = {}
    for sn, val in _names(raw, "sliders", probs).items():
        slider = _read_slider(sn, val, joints, links, ground, probs, missing)
        if slider is not None:
            sliders[sn] = slider
    return sliders


def _read_slider(
    sn: str, val: Any, joints: dict, links: dict[str, Link], ground: str | None, probs: Problems, missing: dict
) -> Slider | None:
    entry = f"sliders.{sn}"
    if not isinstance(val, dict):
        probs.add(entry, f"expected a table {{ joint, guide, axis }}, got {show(val)}")
        return None
    check_keys(val, "sliders", entry, probs)
    if sn in links:
        probs.add(entry, f"duplicate name: '{sn}' is also a link (a slider's name is its block's name)")
        return None
    j = val.get("joint")
    if not isinstance(j, str):
        probs.add(entry, "missing 'joint'")
        return None
    if j not in joints:
        _missing_joint(j, entry, joints, probs, missing)
    guide = val.get("guide", "ground")
    if guide == "ground" and ground is not None:
        guide = ground
    if not isinstance(guide, str) or guide not in links:
        probs.add(entry, f"unknown guide link {show(guide)} (a guide is a link or 'ground')")
        return None
    if j in links[guide].joints:
        probs.add(
            entry, f"the guide '{guide}' names the slider's joint '{j}': a block cannot be pinned to its own guide"
        )
        return None
    offset = number(val, "offset", entry, probs)
    if ("axis" in val) == ("angle" in val):
        probs.add(entry, "give 'axis' (its direction at t = 0) or 'angle' (in the guide's frame), one of them")
        return None
    if "angle" in val:
        turn = angle(val, "angle", entry, probs)
        if turn is not None and len(links[guide].joints) == 1 and not links[guide].ground:
            probs.add(entry, f"the one-joint guide '{guide}' turns with the slider's axis: give 'axis', not 'angle'")
            return None
        return None if turn is None else Slider(sn, j, guide, (1.0, 0.0), turn, offset)
    axis = direction(val["axis"], "axis", entry, probs)
    return None if axis is None else Slider(sn, j, guide, axis, None, offset)


def read_points(
    raw: Any, joints: dict, links: dict, sliders: dict, probs: Problems, unplaced: set[str] | None = None
) -> dict[str, Point]:
    """[points] NAME = { link, at | local } (a point given by ``local`` is placed on its body by :func:`_geometry`)."""
    if not isinstance(raw, dict):
        probs.add("points", "must be a table of NAME = { link, at }")
        return {}
    points: dict[str, Point] = {}
    for pn, val in _names(raw, "points", probs).items():
        entry = f"points.{pn}"
        if not isinstance(val, dict):
            probs.add(entry, f"expected a table {{ link, at }}, got {show(val)}")
            continue
        check_keys(val, "points", entry, probs)
        if pn in joints or pn in (unplaced or ()):
            probs.add(entry, f"duplicate name: '{pn}' is also a joint")
            continue
        lk = val.get("link")
        if not isinstance(lk, str) or (lk not in links and lk not in sliders):
            probs.add(entry, f"unknown link {show(lk)}")
            continue
        if ("at" in val) == ("local" in val):
            probs.add(entry, "give 'at' (its position at t = 0) or 'local' (in its body's frame), one of them")
            continue
        key = "at" if "at" in val else "local"
        xy = pair(val[key], key, entry, probs)
        if xy is not None:
            on = links[lk].joints[0] if lk in links else sliders[lk].joint
            near = joints.get(on, (0.0, 0.0))  # until placed on its body: its body's first joint (the size stays right)
            points[pn] = Point(pn, lk, xy) if key == "at" else Point(pn, lk, near, xy)
    return points


def joint_span(m: Mechanism) -> tuple[float, tuple[float, float]]:
    """(diagonal of the joints' bounding box [file units], its centre): the linkage's own size, which tracer
    points, centres of mass and stated lengths are measured against. Written from dimensions: its size by
    :func:`~vloop.files.dimensions.dimension_size` and its ground pivots' centre (the hints may be anywhere)."""
    if m.from_dimensions:
        pivots = [m.joints[j] for j in m.links[m.ground].joints if j in m.joints]
        xs, ys = [x for x, _ in pivots], [y for _, y in pivots]
        return dimension_size(m)[0], ((max(xs) + min(xs)) / 2, (max(ys) + min(ys)) / 2)
    xs, ys = [x for x, _ in m.joints.values()], [y for _, y in m.joints.values()]
    span = math.hypot(max(xs) - min(xs), max(ys) - min(ys)) if xs else 0.0
    return span, ((max(xs) + min(xs)) / 2, (max(ys) + min(ys)) / 2) if xs else (0.0, 0.0)


def far_problem(m: Mechanism, what: str, value: float | tuple[float, float]) -> str:
    """Why a tracer point, centre of mass (a pair, world) or length (a number) is refused ("" if it is fine): it lies
    more than FAR times the joints' span from them. Every relative tolerance (coincident joints, closure, the
    force balance's rank) is taken of the mechanism's size, and the force balance loses digits as
    ε·(distance/size)² (measured: a centre of mass 1.2e5 sizes away balances the power to 2e-11 of peak, 1.2e7
    sizes away to 2e-8, 1.2e15 sizes away not at all) — such a number is a typing error, not a design."""
    span, (cx, cy) = joint_span(m)
    if span <= 0:
        return ""
    dist = abs(value) if isinstance(value, float) else max(abs(value[0] - cx), abs(value[1] - cy))
    if dist <= FAR * span:
        return ""
    length = isinstance(value, float)
    shown = f"{value:.6g}" if length else f"[{value[0]:.6g}, {value[1]:.6g}]"
    return (
        f"'{what}' = {shown} {'is' if length else 'lies'} {dist / span:.2g} times the linkage's size "
        f"{'' if length else 'away from it '}({span:.6g} {m.units}, the span of its joints): at most {FAR:g} times "
        "(a typing error?)"
    )


def check_extent(m: Mechanism, probs: Problems) -> None:
    """Tracer points and stated lengths within FAR times the joints' span (:func:`far_problem`); written from
    dimensions, every length in proportion to the dimensions and ground pivots (:func:`check_proportions`)."""
    if m.from_dimensions:
        check_proportions(m, probs)
        if probs.items:
            return
    for p in m.points.values():
        problem = far_problem(m, "at", p.at)
        if problem:
            probs.add(f"points.{p.name}", problem)
    for lk in m.links.values():
        problem = far_problem(m, "length", lk.length) if lk.length is not None and not m.from_dimensions else ""
        if problem:
            probs.add(f"links.{lk.name}", problem)


def check_topology(m: Mechanism, probs: Problems) -> None:
    """Joints named by nobody, coincident joints on a link, single-joint moving links, disconnected parts."""
    scale = dimension_size(m)[0] if m.from_dimensions else m.scale  # the hints never set a size
    named = {j for lk in m.links.values() for j in lk.joints} | {s.joint for s in m.sliders.values()}
    for j in m.joints:
        if j not in named:
            probs.add(f"joints.{j}", "is named by no link or slider")
    guides = {s.guide for s in m.sliders.values()}
    if m.from_dimensions:
        check_lengths(m, COINCIDENT_TOL, probs)
    for lk in m.links.values():
        if m.from_dimensions and not lk.ground:  # its shape is its dimensions (checked above), not its coordinates
            pts = []
        else:
            pts = [m.joints[j] for j in lk.joints]
        for i in range(len(pts)):
            for k in range(i + 1, len(pts)):
                if math.dist(pts[i], pts[k]) <= COINCIDENT_TOL * scale:
                    probs.add(
                        f"links.{lk.name}", f"joints {lk.joints[i]} and {lk.joints[k]} coincide (zero-length link)"
                    )
        if not lk.ground and len(lk.joints) == 1 and lk.name not in guides:
            probs.add(
                f"links.{lk.name}",
                "has a single joint: a moving link needs two (add its tip as a joint) unless it guides a slider",
            )
    if not probs.items:
        _check_connected(m, probs)


def _check_connected(m: Mechanism, probs: Problems) -> None:
    parent = {b: b for b in m.body_names}

    def find(b: str) -> str:
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        return b

    at: dict[str, list[str]] = {}
    for n, lk in m.links.items():
        for j in lk.joints:
            at.setdefault(j, []).append(n)
    for s in m.sliders.values():
        at.setdefault(s.joint, []).append(s.name)
        parent[find(s.name)] = find(s.guide)
    for bs in at.values():
        for b in bs[1:]:
            parent[find(b)] = find(bs[0])
    g = find(m.ground)
    loose = [b for b in m.body_names if find(b) != g]
    if loose:
        probs.add("links", f"disconnected mechanism: {', '.join(loose[:10])} not connected to the ground '{m.ground}'")


# ---------------------------------------------------------------- drivers and profiles


def read_drivers(raw: Any, m: Mechanism, ctx: _Context, probs: Problems) -> list[Driver]:
    """[[drivers]]: cranks (link = ...) and linear actuators (slider = ...)."""
    if raw is None:
        probs.add("drivers", "missing: give at least one [[drivers]] entry (a crank or a driven slider)")
        return []
    if isinstance(raw, dict):
        raw = [raw]
    if not isinstance(raw, list):
        probs.add("drivers", "must be an array of tables [[drivers]]")
        return []
    bodies = m.bodies()
    out: list[Driver] = []
    seen: set[str] = set()
    for i, d in enumerate(raw):
        if not isinstance(d, dict):
            probs.add(f"drivers[{i}]", "must be a table")
            continue
        if "link" in d:
            drv = _read_crank(i, d, m, bodies, ctx, probs)
        elif "slider" in d:
            drv = _read_actuator(i, d, m, bodies, ctx, probs)
        else:
            probs.add(f"drivers[{i}]", "needs 'link' (a crank) or 'slider' (a linear actuator)")
            continue
        if drv is None:
            continue
        if (drv.kind, drv.target) in seen:
            probs.add(drv.entry, f"{drv.target} is driven twice")
            continue
        seen.add((drv.kind, drv.target))
        out.append(drv)
    return out


def _read_crank(i: int, d: dict, m: Mechanism, bodies: dict, ctx: _Context, probs: Problems) -> Driver | None:
    check_keys(d, "crank", f"drivers[{i}]", probs)
    ln = d["link"]
    entry = f"drivers[{i}] (link {show(ln, 30)})"
    if isinstance(ln, str) and ln in m.sliders:
        probs.add(
            entry, f"'{ln}' is a slider block, which cannot turn relative to its guide; drive it with slider = '{ln}'"
        )
        return None
    if not isinstance(ln, str) or ln not in m.links:
        probs.add(entry, f"unknown link {show(ln)}")
        return None
    lk = m.links[ln]
    if lk.ground:
        probs.add(entry, f"'{ln}' is the ground, which cannot be driven")
        return None
    pivot = d.get("pivot", lk.joints[0])
    if pivot not in lk.joints:
        probs.add(entry, f"pivot {show(pivot)} is not a joint of link '{ln}'")
        return None
    if pivot != lk.joints[0]:
        probs.add(entry, f"pivot '{pivot}' must be the first joint listed for link '{ln}' (its θ is measured from it)")
        return None
    keys, cols = ("theta0", "omega", "alpha"), ("t", "theta", "omega", "alpha")
    x0, v0, a0, prof = _motion(d, keys, cols, bodies[ln].theta0, entry, ctx, probs)
    return Driver(
        "crank", ln, x0, v0, a0, pivot, prof, entry, _from_coordinates(d, keys[0], lk.joints[:2], m, entry, probs)
    )


def _read_actuator(i: int, d: dict, m: Mechanism, bodies: dict, ctx: _Context, probs: Problems) -> Driver | None:
    check_keys(d, "actuator", f"drivers[{i}]", probs)
    sn = d["slider"]
    entry = f"drivers[{i}] (slider {show(sn, 30)})"
    if not isinstance(sn, str) or sn not in m.sliders:
        probs.add(entry, f"unknown slider {show(sn)}")
        return None
    sl = m.sliders[sn]
    gb = bodies[sl.guide]
    p = m.joints[sl.joint]
    s_coords = (p[0] - gb.origin[0]) * sl.axis[0] + (p[1] - gb.origin[1]) * sl.axis[1]
    x0, v0, a0, prof = _motion(d, ("s0", "v", "a"), ("t", "s", "v", "a"), s_coords, entry, ctx, probs)
    if abs(x0) > SIZES[1]:  # the slider's place at t = 0 is a length (its rates overflow on their own, as a crank's)
        probs.add(entry, f"'s0' = {x0:.6g} {beyond_sizes(m.units)}")
    on = (sl.joint, *([] if gb.kind == "ground" else m.links[sl.guide].joints[:2]))
    return Driver("slider", sn, x0, v0, a0, None, prof, entry, _from_coordinates(d, "s0", on, m, entry, probs))


def _from_coordinates(d: dict, key: str, joints: tuple[str, ...], m: Mechanism, entry: str, probs: Problems) -> bool:
    """Whether a driver's t = 0 value is taken from the coordinates of ``joints`` (it states none); refused where
    one of them has none."""
    if key in d or "profile" in d:
        return False
    without = [j for j in joints if j in m.unplaced]
    if without:
        probs.add(entry, f"give {key} (the input's value at t = 0): {', '.join(without)} has no coordinates to take it")
    return True


def _motion(
    d: dict,
    keys: tuple[str, str, str],
    cols: tuple[str, ...],
    x_coords: float,
    entry: str,
    ctx: _Context,
    probs: Problems,
) -> tuple[float, float, float, Profile | None]:
    """A driver's x0 (default: from the coordinates), rate and acceleration, or its profile."""
    x0 = (
        angle(d, keys[0], entry, probs, x_coords) if keys[0] == "theta0" else number(d, keys[0], entry, probs, x_coords)
    )
    v0 = number(d, keys[1], entry, probs, 0.0)
    a0 = number(d, keys[2], entry, probs, 0.0)
    prof = None
    if "profile" in d:
        for k in keys:
            if k in d:
                probs.add(entry, f"'{k}' and 'profile' both given: the profile sets the motion")
        table = read_table(d["profile"], entry, ctx, probs)
        source = str(d["profile"]) if isinstance(d["profile"], str) else "inline"
        prof = _profile(table, cols, entry, probs, source) if table is not None else None
        x0 = float(prof.x[0]) if prof is not None else x0
    return x0, v0, a0, prof


def read_table(spec: Any, entry: str, ctx: _Context, probs: Problems) -> dict[str, np.ndarray] | None:
    """A profile's columns (lower-case names → arrays) from an inline table of lists or a CSV file."""
    if isinstance(spec, dict):
        table = {}
        for k, v in spec.items():
            if not isinstance(v, list) or len(v) > MAX_PROFILE_ROWS:
                probs.add(entry, f"profile column {show(k)} must be a list of at most {MAX_PROFILE_ROWS:,} numbers")
                return None
            vals = [real(x, "profile", entry, Problems("")) for x in v]
            if None in vals:
                probs.add(entry, f"profile column {show(k, 20)} must be a list of finite numbers")
                return None
            table[str(k).strip().lower()] = np.asarray(vals, float)
        return table
    if isinstance(spec, str):
        return _read_csv(spec, entry, ctx, probs)
    probs.add(entry, "'profile' must be a CSV file name or a table of columns")
    return None


def _read_csv(spec: str, entry: str, ctx: _Context, probs: Problems) -> dict[str, np.ndarray] | None:
    """A CSV profile with a header row: a regular file inside the mechanism's folder (unless allowed),
    of bounded size; its content is never echoed in a message."""
    path = _profile_path(spec, entry, ctx, probs)
    if path is None:
        return None
    try:
        text = _read_text_file(path, MAX_PROFILE_BYTES, what="profile", entry=entry)
    except MechanismError as exc:
        probs.add(entry, f"profile {show(spec)}: {str(exc).split(': ', 1)[-1]}")
        return None
    lines = text.splitlines()
    header = [h.strip().lower() for h in lines[0].split(",")] if lines else []
    if len(lines) < 3 or len(set(header)) != len(header) or not all(header):
        probs.add(entry, f"profile {show(spec)} needs a header row of distinct column names and at least two data rows")
        return None
    if len(lines) - 1 > MAX_PROFILE_ROWS:
        probs.add(entry, f"profile {show(spec)} has more than {MAX_PROFILE_ROWS:,} rows")
        return None
    try:
        data = np.loadtxt(lines[1:], delimiter=",", ndmin=2, dtype=float)
    except ValueError:
        probs.add(entry, f"profile {show(spec)}: every data row must be {len(header)} numbers separated by commas")
        return None
    if data.shape[1] != len(header):
        probs.add(entry, f"profile {show(spec)}: its rows have {data.shape[1]} values, its header {len(header)} names")
        return None
    return {h: data[:, i] for i, h in enumerate(header)}


def _profile_path(spec: str, entry: str, ctx: _Context, probs: Problems) -> Path | None:
    """The profile's path: ``spec`` relative to the mechanism file's folder, or absolute. Without
    ``allow_external_profiles`` it must lie inside that folder once both are resolved the same way (symbolic
    links and ``..`` followed): an absolute path into the folder is read, a link out of it is refused."""
    if "\x00" in spec or not spec.strip():
        probs.add(entry, f"profile path {show(spec)} is not a file name")
        return None
    path = ctx.base / spec  # an absolute spec replaces the base
    if not ctx.allow_external_profiles:
        try:
            outside = not Path(os.path.realpath(path)).is_relative_to(os.path.realpath(ctx.base))
        except (OSError, ValueError):  # a path the system cannot resolve (too long, a link loop)
            outside = True
        if outside:
            probs.add(
                entry,
                f"profile {show(spec)} is outside the mechanism file's folder {show(str(ctx.base))}: vloop reads only "
                "files inside it (allow others with --allow-external-profiles, or load(..., "
                "allow_external_profiles=True))",
            )
            return None
    return path


def _column_ok(table: dict[str, np.ndarray], k: str, n: int, entry: str, probs: Problems, source: str) -> bool:
    """A profile column as long as its time column and finite; else a problem naming the file, column and row."""
    col = table[k]
    where = f"profile {show(source)} column '{k}'" if source != "inline" else f"profile column '{k}'"
    if len(col) != n:
        probs.add(entry, f"{where} has {len(col)} values for {n} times")
        return False
    bad = np.flatnonzero(~np.isfinite(col))
    if len(bad):
        probs.add(entry, f"{where} has a missing or non-finite value at data row {int(bad[0]) + 1}")
        return False
    return True


def _profile(
    table: dict[str, np.ndarray], cols: tuple[str, ...], entry: str, probs: Problems, source: str = "inline"
) -> Profile | None:
    """Columns t, x[, v, a] of a driver's profile, checked: finite, same length, strictly increasing time."""
    tcol, xcol, vcol, acol = cols
    if tcol not in table or xcol not in table:
        probs.add(entry, f"profile needs columns '{tcol}' and '{xcol}' (has {', '.join(list(table)[:8])})")
        return None
    t = table[tcol]
    n = len(t)
    for k in (tcol, xcol, vcol, acol):
        if k in table and not _column_ok(table, k, n, entry, probs, source):
            return None
    if n < 2:
        probs.add(entry, "profile needs at least two rows")
        return None
    if np.any(np.diff(t) <= 0):
        k = int(np.argmax(np.diff(t) <= 0)) + 1
        probs.add(entry, f"profile time is not strictly increasing (row {k + 1}: t = {t[k]:g} after {t[k - 1]:g})")
        return None
    return Profile(t, table[xcol], table.get(vcol), table.get(acol), source)


# ---------------------------------------------------------------- time and solver


def read_time(raw: Any, drivers: list[Driver], probs: Problems) -> np.ndarray:
    """[time] start, stop, step — or times = [...]; with no [time], a profile's own times."""
    if raw is None:
        profs = [d.profile for d in drivers if d.profile is not None]
        if profs:
            return np.array(profs[0].t, float)
        probs.add("time", "missing: give [time] start, stop, step (or times = [...])")
        return np.zeros(1)
    if not isinstance(raw, dict):
        probs.add("time", "must be a table")
        return np.zeros(1)
    check_keys(raw, "time", "time", probs)
    if "times" in raw:
        return _explicit_times(raw["times"], probs)
    start = number(raw, "start", "time", probs, 0.0)
    stop = number(raw, "stop", "time", probs)
    step = number(raw, "step", "time", probs)
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
    count = (stop - start) / step  # may overflow to inf for a subnormal step
    if not math.isfinite(count) or _time_limit(count + 1):
        why = _time_limit(count + 1) if math.isfinite(count) else "too many samples to count"
        probs.add("time", f"step {step:g} over [{start:g}, {stop:g}] gives {why}")
        return np.zeros(1)
    n = math.floor(count + 1e-9) + 1  # up to and including stop, never past it
    t = time_grid(start, step, n)
    if n > 1 and np.any(np.diff(t) <= 0):
        probs.add("time", f"step {step:g} is too small to separate samples near t = {start:g}")
    return t


def time_grid(start: float, step: float, n: int) -> np.ndarray:
    """The samples start + k·step, k = 0 … n − 1 [s], each the double nearest the decimal value the file's
    numbers state (start and step read as their shortest decimal text: 7 × 0.05 gives 0.35, where the floating
    product is 0.35000000000000003). Exact by integer arithmetic where the numerators and the common
    denominator are exact doubles (one correctly rounded division); otherwise start + k·step in floating point."""
    from fractions import Fraction

    a, b = Fraction(repr(float(start))), Fraction(repr(float(step)))
    den = math.lcm(a.denominator, b.denominator)
    first, inc = a.numerator * (den // a.denominator), b.numerator * (den // b.denominator)
    if den < 2**1000 and float(den) == den and max(abs(first), abs(inc), abs(first + inc * (n - 1))) < 2**53:
        return (first + inc * np.arange(n, dtype=np.int64)).astype(float) / den
    return start + step * np.arange(n)


def _explicit_times(ts: Any, probs: Problems) -> np.ndarray:
    if not isinstance(ts, list) or not ts:
        probs.add("time", "'times' must be a non-empty list of numbers")
        return np.zeros(1)
    if _time_limit(len(ts)):
        probs.add("time", f"'times' has {_time_limit(len(ts))}")
        return np.zeros(1)
    vals = [real(x, "times", "time", probs) for x in ts]
    if None in vals:
        return np.zeros(1)
    t = np.asarray(vals, float)
    if np.any(np.diff(t) <= 0):
        probs.add("time", "'times' must be strictly increasing")
    return t


def read_solver(raw: Any, probs: Problems) -> dict[str, Any]:
    """[solver]: method, tol, rtol, max_iter, assembly_tolerance, branches, change_points, memory_budget."""
    if not isinstance(raw, dict):
        probs.add("solver", "must be a table")
        return {}
    check_keys(raw, "solver", "solver", probs)
    out: dict[str, Any] = {}
    if "method" in raw:
        if raw["method"] not in ("auto", "newton"):
            probs.add("solver", "method must be 'auto' or 'newton'")
        else:
            out["method"] = raw["method"]
    for k in ("tol", "rtol", "assembly_tolerance"):
        v = number(raw, k, "solver", probs)
        if v is not None:
            if not 0 < v < 1:
                probs.add("solver", f"{k} must be between 0 and 1 (a fraction), got {v:g}")
            out[k] = v
    if "memory_budget" in raw:  # bytes or a size such as "2G" (vloop.files.budget)
        from .budget import parse_size

        try:
            out["memory_budget"] = parse_size(raw["memory_budget"], "memory_budget")
        except ValueError as exc:
            probs.add("solver", str(exc))
    if "max_iter" in raw:
        mi = raw["max_iter"]
        if isinstance(mi, bool) or not isinstance(mi, int) or not 1 <= mi <= 10_000:
            probs.add("solver", "max_iter must be an integer from 1 to 10000")
        else:
            out["max_iter"] = mi
    for key, choices, example in (
        ("branches", BRANCH_CHOICES, "crossed"),
        ("change_points", CHANGE_POINT_CHOICES, "other"),
    ):
        if key in raw:
            table = _per_loop(raw[key], choices, key == "change_points")
            if table is None:
                probs.add(
                    "solver",
                    f"{key} must map loop numbers to one of {', '.join(choices)}"
                    f'{" (or a list of them)" if key == "change_points" else ""}, e.g. {{ 1 = "{example}" }}',
                )
            else:
                out[key] = table
    return out


def _per_loop(table: Any, choices: tuple[str, ...], lists: bool) -> dict[int, Any] | None:
    if not isinstance(table, dict):
        return None
    out = {}
    for k, v in table.items():
        ok = (
            v in choices if isinstance(v, str) else lists and isinstance(v, list) and v and all(x in choices for x in v)
        )
        if not (isinstance(k, str) and k.isdigit() and len(k) < 7 and int(k) >= 1 and ok):
            return None
        out[int(k)] = v
    return out


# ---------------------------------------------------------------- masses, gravity, loads (kinetostatics)


def read_dynamics(data: dict, m: Mechanism, ctx: _Context, probs: Problems) -> dict[str, Any]:
    """Mechanism fields ``masses``, ``gravity``, ``loads`` (all optional) from the file."""
    masses = read_masses(data, m, probs)
    gravity = pair(data["gravity"], "gravity", "gravity", probs) if "gravity" in data else None
    loads = read_loads(data.get("loads"), m, ctx, probs)
    if (masses or loads or gravity) and m.units.strip().lower() not in LENGTH_UNITS:
        probs.add("units", f"forces need a length unit vloop knows ({', '.join(LENGTH_UNITS)}), got {show(m.units)}")
    return {"masses": masses, "gravity": gravity, "loads": tuple(loads)}


def read_masses(data: dict, m: Mechanism, probs: Problems) -> dict[str, MassProperties]:
    """``mass`` [kg], ``inertia`` [kg·m² about the centre of mass], ``com = [x, y]`` on links and blocks.

    Without ``com`` the centre of mass is the mean of the body's joints as the body is assembled — in its own
    frame, where a stated ``length`` places the second joint (the typed coordinates may be rounded) — stored, as
    a stated ``com`` is, in world coordinates at t = 0 through the body's frame."""
    out: dict[str, MassProperties] = {}
    tables = [("links", n, v) for n, v in (data.get("links") or {}).items() if n in m.links]
    tables += [("sliders", n, v) for n, v in (data.get("sliders") or {}).items() if n in m.sliders]
    bodies = m.bodies() if tables else {}
    for section, name, val in tables:
        if not isinstance(val, dict) or not {"mass", "inertia", "com", "com_local"} & set(val):
            continue
        entry = f"{section}.{name}"
        if section == "links" and m.links[name].ground:
            probs.add(entry, "the ground does not move: it takes no mass, inertia or com")
            continue
        mass = real(val.get("mass", 0.0), "mass", entry, probs)
        inertia = real(val.get("inertia", 0.0), "inertia", entry, probs)
        joints = m.links[name].joints if section == "links" else (m.sliders[name].joint,)
        if "com" in val and "com_local" in val:
            probs.add(entry, "give 'com' (world, t = 0) or 'com_local' (in the body's frame), one of them")
            continue
        local = pair(val["com_local"], "com_local", entry, probs) if "com_local" in val else None
        com = pair(val["com"], "com", entry, probs) if "com" in val else joint_mean(bodies[name], joints)
        com = to_world(bodies[name], local) if local is not None else com
        far = far_problem(m, "com", com) if com is not None else ""
        if far:
            probs.add(entry, far)
            continue
        for what, x in (("mass", mass), ("inertia", inertia)):
            if x is not None and x < 0:
                probs.add(entry, f"'{what}' must not be negative, got {x:g}")
        if mass is not None and inertia is not None and com is not None and mass >= 0 and inertia >= 0:
            out[name] = MassProperties(mass, inertia, com, local)
    return out


def read_loads(raw: Any, m: Mechanism, ctx: _Context, probs: Problems) -> list[Load]:
    """[[loads]]: a force at a point, or a torque on a link, constant or tabulated."""
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
        check_keys(d, "loads", entry, probs)
        load = _read_load(d, m, entry, ctx, probs)
        if load is not None:
            out.append(load)
    return out


def _load_body(d: dict, m: Mechanism, entry: str, probs: Problems) -> tuple[str | None, str | None]:
    """(point, body) of a load: the body defaults to the point's link, or the slider block at a joint."""
    point, body = d.get("point"), d.get("link")
    moving = set(m.body_names[1:])
    if point is not None and (not isinstance(point, str) or (point not in m.joints and point not in m.points)):
        probs.add(entry, f"unknown point {show(point)} (a joint or a tracer point)")
        return None, None
    if body is not None and (not isinstance(body, str) or body not in m.body_names):
        probs.add(entry, f"unknown link {show(body)}")
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


def _read_load(d: dict, m: Mechanism, entry: str, ctx: _Context, probs: Problems) -> Load | None:
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
        return _load_profile(d["profile"], kind, body, point, entry, ctx, probs)
    value: Any = (
        pair(d["force"], "force", entry, probs) if kind == "force" else real(d["torque"], "torque", entry, probs)
    )
    return None if value is None else Load(kind, body, value, point, None, entry)


def _load_profile(
    spec: Any, kind: str, body: str, point: str | None, entry: str, ctx: _Context, probs: Problems
) -> Load | None:
    table = read_table(spec, entry, ctx, probs)
    if table is None:
        return None
    columns = ("fx", "fy") if kind == "force" else ("torque",)
    if "t" not in table or columns[0] not in table:
        probs.add(entry, f"profile needs columns 't' and '{columns[0]}' (has {', '.join(list(table)[:8])})")
        return None
    if any(c not in table for c in columns):
        probs.add(entry, "a force profile needs columns 't', 'fx' and 'fy'")
        return None
    source = spec if isinstance(spec, str) else "inline"
    prof = _profile({"t": table["t"], columns[0]: table[columns[0]]}, ("t", columns[0], "", ""), entry, probs, source)
    if prof is None or not all(_column_ok(table, c, len(prof.t), entry, probs, source) for c in columns):
        return None
    values = np.column_stack([table[c] for c in columns])
    return Load(kind, body, None, point, LoadProfile(prof.t, values, columns, source), entry)


# ---------------------------------------------------------------- forward dynamics

INTEGRATORS = ("DOP853", "RK45", "RK23", "Radau", "BDF", "LSODA")


def read_simulation(raw: Any, m: Mechanism, drivers: list[Driver], ctx: _Context, probs: Problems) -> Dynamics | None:
    """[dynamics]: the input's state at t = 0, its torque or motor line, a flywheel, springs, the integrator."""
    if not isinstance(raw, dict):
        probs.add("dynamics", "must be a table [dynamics]")
        return None
    check_keys(raw, "dynamics", "dynamics", probs)
    if len(drivers) not in (1, 2):
        probs.add("dynamics", f"forward dynamics needs one or two inputs (this mechanism has {len(drivers)} drivers)")
    if m.units.strip().lower() not in LENGTH_UNITS:
        probs.add("units", f"dynamics needs a length unit vloop knows ({', '.join(LENGTH_UNITS)}), got {show(m.units)}")
    out: dict[str, Any] = {}
    for key in ("position", "rate"):
        out[key] = number(raw, key, "dynamics", probs)
    out["flywheel"] = _non_negative(raw, "flywheel", "dynamics", probs)
    if isinstance(raw.get("torque"), (dict, str)):
        out["torque_profile"] = _load_profile(raw["torque"], "torque", "", None, "dynamics.torque", ctx, probs)
        out["torque_profile"] = out["torque_profile"].profile if out["torque_profile"] is not None else None
    else:
        out["torque"] = number(raw, "torque", "dynamics", probs, 0.0)
    out["motor"] = _motor(raw["motor"], probs) if "motor" in raw else None
    method = raw.get("method", "DOP853")
    if method not in INTEGRATORS:
        probs.add("dynamics", f"method must be one of {', '.join(INTEGRATORS)}, got {show(method)}")
    out["method"] = method
    for key in ("rtol", "atol"):
        v = number(raw, key, "dynamics", probs, 1e-10)
        if v is not None and not (0 < v < 1 if key == "rtol" else v > 0):
            probs.add("dynamics", f"{key} must be {'between 0 and 1' if key == 'rtol' else 'positive'}, got {v:g}")
        out[key] = v
    _simulated_rows(raw, out, probs)
    springs = raw.get("springs", [])
    if not isinstance(springs, list):
        probs.add("dynamics.springs", "must be an array of tables [[dynamics.springs]]")
        springs = []
    out["springs"] = tuple(s for i, d in enumerate(springs) if (s := _spring(d, m, f"dynamics.springs[{i}]", probs)))
    return Dynamics(**out)


def _simulated_rows(raw: dict, out: dict[str, Any], probs: Problems) -> None:
    """stop and step [s] of the simulated rows, both or neither, within the time limit."""
    stop, step = number(raw, "stop", "dynamics", probs), number(raw, "step", "dynamics", probs)
    if (stop is None) != (step is None):
        probs.add("dynamics", "give both 'stop' and 'step' (the simulated rows), or neither (the file's [time])")
    elif stop is not None and step is not None:
        if not (stop > 0 and step > 0):
            probs.add("dynamics", f"'stop' and 'step' must be positive, got {stop:g} and {step:g}")
        elif (limit := _time_limit(stop / step + 1)) is not None:
            probs.add("dynamics", limit)
        else:
            out.update(stop=stop, step=step)


def _non_negative(raw: dict, key: str, entry: str, probs: Problems) -> float:
    v = number(raw, key, entry, probs, 0.0)
    if v is not None and v < 0:
        probs.add(entry, f"'{key}' must not be negative, got {v:g}")
    return v or 0.0


def _motor(raw: Any, probs: Problems) -> tuple[float, float] | None:
    """motor = { stall, no_load_speed }: T = stall·(1 − ω/no_load_speed), no_load_speed ≠ 0."""
    entry = "dynamics.motor"
    if not isinstance(raw, dict) or set(raw) != {"stall", "no_load_speed"}:
        probs.add(entry, "must be a table { stall = T0, no_load_speed = ω0 } (N·m and rad/s)")
        return None
    stall, speed = number(raw, "stall", entry, probs), number(raw, "no_load_speed", entry, probs)
    if speed == 0.0:
        probs.add(entry, "'no_load_speed' must not be zero")
    return None if stall is None or not speed else (stall, speed)


def _spring(d: Any, m: Mechanism, entry: str, probs: Problems) -> Spring | None:
    """[[dynamics.springs]]: rotational (joint, links) or linear (between), with k, c and rest."""
    if not isinstance(d, dict):
        probs.add(entry, "must be a table")
        return None
    check_keys(d, "springs", entry, probs)
    k, c = _non_negative(d, "k", entry, probs), _non_negative(d, "c", entry, probs)
    rest = number(d, "rest", entry, probs)
    if ("joint" in d) == ("between" in d):
        probs.add(entry, "give joint = J (a rotational spring at a pin) or between = [P, Q] (a linear one)")
        return None
    if "between" in d:
        ends = d["between"]
        known = set(m.joints) | set(m.points)
        names = isinstance(ends, list) and len(ends) == 2 and all(isinstance(e, str) for e in ends)
        if not names or ends[0] == ends[1] or not set(ends) <= known:
            probs.add(entry, f"'between' must name two different joints or points, got {show(ends)}")
            return None
        return Spring("linear", (ends[0], ends[1]), k, c, rest, None, entry)
    joint = d["joint"]
    at = (*m.bodies_at(joint),) if isinstance(joint, str) else ()
    if len(at) < 2:
        probs.add(entry, f"'joint' must name a pin joining two bodies, got {show(joint)}")
        return None
    ends = d.get("links", list(at[:2]))
    names = isinstance(ends, list) and len(ends) == 2 and all(isinstance(e, str) for e in ends)
    if not names or ends[0] == ends[1] or not set(ends) <= set(at):
        probs.add(entry, f"'links' must name two different bodies at {joint} ({', '.join(at)}), got {show(ends)}")
        return None
    return Spring("rotational", (ends[0], ends[1]), k, c, rest, joint, entry)


def _simulation_to_dict(dyn: Dynamics) -> dict[str, Any]:
    """The [dynamics] table of a Dynamics (read back to an equal one by :func:`read_simulation`)."""
    out: dict[str, Any] = {k: getattr(dyn, k) for k in ("position", "rate") if getattr(dyn, k) is not None}
    p = dyn.torque_profile
    out["torque"] = {"t": p.t.tolist(), "torque": p.values[:, 0].tolist()} if p is not None else dyn.torque
    if dyn.motor is not None:
        out["motor"] = {"stall": dyn.motor[0], "no_load_speed": dyn.motor[1]}
    out.update(flywheel=dyn.flywheel, method=dyn.method, rtol=dyn.rtol, atol=dyn.atol)
    if dyn.stop is not None:
        out.update(stop=dyn.stop, step=dyn.step)
    springs = []
    for s in dyn.springs:
        entry: dict[str, Any] = (
            {"joint": s.joint, "links": list(s.ends)} if s.kind == "rotational" else {"between": list(s.ends)}
        )
        entry.update(k=s.k, c=s.c, **({"rest": s.rest} if s.rest is not None else {}))
        springs.append(entry)
    if springs:
        out["springs"] = springs
    return out


# ---------------------------------------------------------------- writing


def to_dict(mech: Mechanism) -> dict[str, Any]:
    """The TOML structure of a Mechanism (:func:`from_dict` reads it back to an equal Mechanism).

    Tabulated profiles are written inline (``profile = { t = [...], theta = [...] }``);
    the time grid as an explicit ``times`` list.
    """
    out: dict[str, Any] = {"name": mech.name}
    if mech.title:
        out["title"] = mech.title
    out["units"] = mech.units
    out["joints"] = {j: list(xy) for j, xy in mech.joints.items() if j not in mech.unplaced}
    out["links"] = {n: _link_dict(lk) for n, lk in mech.links.items()}
    if mech.sliders:
        out["sliders"] = {n: _slider_dict(s) for n, s in mech.sliders.items()}
    if mech.points:
        out["points"] = {
            n: {"link": p.link, **({"at": list(p.at)} if p.local is None else {"local": list(p.local)})}
            for n, p in mech.points.items()
        }
    out["drivers"] = [_driver_dict(d) for d in mech.drivers]
    out["time"] = {"times": mech.times.tolist()}
    if mech.options:
        out["solver"] = dict(mech.options)
        for key in ("branches", "change_points"):
            if key in out["solver"]:
                out["solver"][key] = {str(k): v for k, v in out["solver"][key].items()}
    _dynamics_to_dict(mech, out)
    if mech.dynamics is not None:
        out["dynamics"] = _simulation_to_dict(mech.dynamics)
    return out


def _link_dict(lk: Link) -> dict[str, Any]:
    entry: dict[str, Any] = {"joints": list(lk.joints)}
    if lk.ground:
        entry["ground"] = True
    if lk.length is not None:
        entry["length"] = lk.length
    if lk.sides is not None:
        entry["sides"] = list(lk.sides)
    if lk.angle is not None:
        entry["angle"] = lk.angle
    return entry


def _slider_dict(s: Slider) -> dict[str, Any]:
    entry: dict[str, Any] = {"joint": s.joint, "guide": s.guide}
    entry.update({"axis": list(s.axis)} if s.angle is None else {"angle": s.angle})
    if s.offset is not None:
        entry["offset"] = s.offset
    return entry


def _driver_dict(d: Driver) -> dict[str, Any]:
    names = ("theta0", "omega", "alpha") if d.kind == "crank" else ("s0", "v", "a")
    cols = ("t", "theta", "omega", "alpha") if d.kind == "crank" else ("t", "s", "v", "a")
    entry: dict[str, Any] = {"link": d.target, "pivot": d.pivot} if d.kind == "crank" else {"slider": d.target}
    if d.profile is None:
        entry.update(zip(names, (d.x0, d.v0, d.a0), strict=True))
        return entry
    p = d.profile
    prof = {cols[0]: p.t.tolist(), cols[1]: p.x.tolist()}
    if p.v is not None:
        prof[cols[2]] = p.v.tolist()
    if p.a is not None:
        prof[cols[3]] = p.a.tolist()
    entry["profile"] = prof
    return entry


def _dynamics_to_dict(mech: Mechanism, out: dict[str, Any]) -> None:
    """Add masses (on their link/slider tables), gravity and loads to a to_dict structure."""
    for name, mp in mech.masses.items():
        table = out["links"][name] if name in mech.links else out["sliders"][name]
        table.update(mass=mp.mass, inertia=mp.inertia)
        if mp.local is not None:
            table["com_local"] = list(mp.local)
        elif not mech.from_dimensions:  # written from dimensions, the centre of mass is the mean of the joints
            table["com"] = list(mp.com)
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
    """The mechanism as TOML text (see :func:`to_dict`), short arrays (coordinates, a link's joints) on one line."""
    import re

    import tomli_w

    short = re.compile(r"\[\n((?:[ ]+[^\[\]{}\n]+,\n){1,4})[ ]*\]")

    def one_line(m: re.Match) -> str:
        return "[" + ", ".join(x.strip().rstrip(",") for x in m.group(1).splitlines()) + "]"

    return short.sub(one_line, tomli_w.dumps(to_dict(mech)))


def save(mech: Mechanism, path: str | Path) -> None:
    """Write the mechanism atomically to a TOML file that :func:`load` reads back to an equal Mechanism."""
    from .output import write_text

    write_text(path, dumps(mech))
