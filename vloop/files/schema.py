"""The mechanism file's schema, in one place: every section, key, type, default and unit.

The readers (:mod:`vloop.files.fileformat`) accept exactly these keys, and the file-format page's key
tables (docs/file-format.md) are generated from them (:func:`markdown`; a test keeps the two equal), so the
documentation cannot drift from what is accepted. The value checks every reader shares live
here too: finite numbers (10**400, nan, inf, strings and booleans refused), coordinate pairs,
directions normalised without overflow, and names safe in CSV headers, file names and HTML.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

from ..errors import MechanismError
from .options import show

NAME_MAX = 64
SIZES = (1e-60, 1e60)  # mechanism sizes (in its units) whose lengths can be squared twice in double precision
# Every length synthesis takes (targets, ground lengths, regions) lies within ±MAX_LENGTH of the units, so that a
# linkage up to a few hundred times its targets stays inside SIZES; MIN_LENGTH is the smallest positive one.
MAX_LENGTH = 1e50
MIN_LENGTH = 1e-50
FAR = 1e5  # a coordinate or length this many times the mechanism's size from it is a typing error, not a design
_NAME = re.compile(r"[^\W_][\w-]*|_[\w-]*")  # letters, digits, '_' and '-' (Unicode letters and digits too)


@dataclass(frozen=True)
class Key:
    """One key of a section: its type, default, unit and meaning (``example``: a valid value, for tests)."""

    name: str
    type: str
    default: str
    unit: str
    doc: str
    example: Any = None


@dataclass(frozen=True)
class Section:
    """A section of the file (``form`` shows how it is written) and the keys of each entry."""

    name: str
    form: str
    doc: str
    keys: tuple[Key, ...]

    @property
    def allowed(self) -> set[str]:
        return {k.name for k in self.keys}


MASS_KEYS = (
    Key("mass", "number ≥ 0", "0 (massless)", "kg", "mass of the body, at its centre of mass `com`", 1.5),
    Key("inertia", "number ≥ 0", "0", "kg·m²", "moment of inertia about the centre of mass", 0.02),
    Key(
        "com",
        "[x, y]",
        "mean of the body's joints as assembled",
        "length",
        "centre of mass at t = 0, world frame (default: the mean of the joints in the body as assembled, a stated "
        "`length` applied, not of the typed coordinates)",
        [1.0, 1.0],
    ),
    Key("com_local", "[u, v]", "none", "length", "centre of mass in the body's frame instead of com", [0.5, 0.0]),
)

SECTIONS: tuple[Section, ...] = (
    Section(
        "file",
        "top level",
        "what the mechanism is called and its units",
        (
            Key(
                "name",
                "name-like string",
                "the file's name",
                "",
                "the mechanism's name (messages, output folder)",
                "m1",
            ),
            Key("title", "string", '""', "", "a title for reports and plots", "A four-bar"),
            Key("units", "string", '"m"', "", "length unit (m, cm, mm, km, in, ft for forces)", "m"),
            Key("gravity", "[gx, gy]", "none", "m/s²", "gravitational acceleration, world frame", [0.0, -9.81]),
        ),
    ),
    Section(
        "joints",
        "[joints] NAME = [x, y]",
        "every pin or slider point at t = 0 (written from dimensions: the ground's, and rough hints)",
        (
            Key(
                "NAME",
                "[x, y]",
                "required (from dimensions: ground joints)",
                "length",
                "position at t = 0 (from dimensions: a hint for moving joints)",
                [0.0, 0.0],
            ),
        ),
    ),
    Section(
        "links",
        "[links] NAME = { ... }",
        "rigid links; exactly one is the ground",
        (
            Key(
                "joints",
                "list of joint names",
                "required",
                "",
                "the link's joints; θ runs from the first to the second",
                None,
            ),
            Key("ground", "bool", "false", "", "this link is the frame", None),
            Key("length", "number > 0", "from the coordinates", "length", "stated length (binary links only)", None),
            Key(
                "sides",
                "[a, b, c] or [a, c] > 0",
                "from the coordinates",
                "length",
                "ternary J0-J1-J2: |J0J1|, |J1J2|, |J2J0|; or |J0J1|, |J0J2| with angle",
                [4.0, 3.5],
            ),
            Key("angle", "number", "none", "rad", "with two sides: angle at J0 from J0→J1 to J0→J2, CCW", -2.0),
            *MASS_KEYS,
        ),
    ),
    Section(
        "sliders",
        "[sliders] NAME = { ... }",
        "a block carrying pin `joint`, sliding along `axis` of `guide`",
        (
            Key("joint", "joint name", "required", "", "the pin the block carries", None),
            Key("guide", "link name", '"ground"', "", "the guide (a moving link: an inverse slider)", None),
            Key("axis", "[ux, uy]", "required (or angle)", "", "sliding direction at t = 0 (normalised)", None),
            Key("angle", "number", "from axis", "rad", "sliding direction in the guide's frame, CCW from its θ", 0.1),
            Key(
                "offset",
                "number",
                "through the joint",
                "length",
                "sliding line's distance from the guide's origin, + to the left of the axis",
                0.2,
            ),
            *MASS_KEYS,
        ),
    ),
    Section(
        "points",
        "[points] NAME = { ... }",
        "tracer points fixed to a link or slider block",
        (
            Key("link", "link or slider name", "required", "", "the body carrying the point", None),
            Key("at", "[x, y]", "required (or local)", "length", "position at t = 0", None),
            Key("local", "[u, v]", "none", "length", "position in the body's frame instead of at", [1.0, 0.5]),
        ),
    ),
    Section(
        "crank",
        "[[drivers]] with link = ...",
        "a driven link: θ(t) = theta0 + omega·t + alpha·t²/2",
        (
            Key("link", "link name", "required", "", "the driven link", None),
            Key("pivot", "joint name", "the link's first joint", "", "must be the link's first joint", None),
            Key(
                "theta0",
                "number",
                "the coordinates' angle",
                "rad",
                "θ at t = 0 (state it when coordinates are hints)",
                0.5,
            ),
            Key("omega", "number", "0", "rad/s", "angular velocity at t = 0", 2.0),
            Key("alpha", "number", "0", "rad/s²", "angular acceleration", 0.1),
            Key("profile", "CSV path or table", "none", "", "columns t, theta[, omega, alpha] instead", None),
        ),
    ),
    Section(
        "actuator",
        "[[drivers]] with slider = ...",
        "a driven slider: s(t) = s0 + v·t + a·t²/2",
        (
            Key("slider", "slider name", "required", "", "the driven slider", None),
            Key(
                "s0",
                "number",
                "from the coordinates",
                "length",
                "s at t = 0 (state it when coordinates are hints)",
                None,
            ),
            Key("v", "number", "0", "length/s", "velocity", None),
            Key("a", "number", "0", "length/s²", "acceleration", None),
            Key("profile", "CSV path or table", "none", "", "columns t, s[, v, a] instead", None),
        ),
    ),
    Section(
        "time",
        "[time]",
        "the samples: start + k·step up to and including stop (the decimals as written: 7 × 0.05 is 0.35), "
        "or an explicit list",
        (
            Key("start", "number", "0", "s", "first sample", 0.0),
            Key("stop", "number", "required", "s", "last sample (within half a step)", 1.0),
            Key("step", "number > 0", "required", "s", "sample spacing", 0.1),
            Key("times", "list of numbers", "none", "s", "explicit, strictly increasing samples instead", None),
        ),
    ),
    Section(
        "solver",
        "[solver]",
        "how the motion is solved",
        (
            Key(
                "method",
                '"auto" | "newton"',
                '"auto"',
                "",
                "closed-form dyads where possible, or Newton only",
                "newton",
            ),
            Key("tol", "0 < number < 1", "1e-12", "", "Newton step tolerance, relative", 1e-11),
            Key("rtol", "0 < number < 1", "1e-9", "", "accuracy asked of every output (refuses samples beyond)", 1e-8),
            Key("max_iter", "integer ≥ 1", "30", "", "Newton iterations per sample", 40),
            Key("assembly_tolerance", "0 < number < 1", "1e-3", "", "t = 0 closure accepted, fraction of size", 2e-3),
            Key(
                "branches",
                "{ N = choice }",
                "none",
                "",
                'per loop N: "open", "crossed", "flip", "keep" at t = 0 (from dimensions: the assembly)',
                {"1": "keep"},
            ),
            Key(
                "change_points",
                "{ N = choice }",
                '"smooth"',
                "",
                'per loop N: "smooth" or "other" (or a list)',
                {"1": "smooth"},
            ),
            Key(
                "memory_budget",
                'bytes or "2G"',
                "half the free memory",
                "bytes",
                "refuse a run estimated to need more (docs: Big runs)",
                "4G",
            ),
        ),
    ),
    Section(
        "loads",
        "[[loads]]",
        "external loads (kinetostatics)",
        (
            Key("point", "joint or point name", "none", "", "where a force acts", None),
            Key("link", "link or slider name", "the point's body", "", "the body a force or torque acts on", None),
            Key("force", "[fx, fy]", "none", "N", "constant force, world frame", None),
            Key("torque", "number", "none", "N·m", "constant torque, CCW positive", None),
            Key("profile", "CSV path or table", "none", "", "columns t, fx, fy (force) or t, torque instead", None),
        ),
    ),
)

SECTIONS += (
    Section(
        "dynamics",
        "[dynamics]",
        "forward dynamics (`vloop simulate`): the input's state at t = 0, its loads, the integrator",
        (
            Key("position", "number", "the driver's value at t = 0", "rad or length", "the input at t = 0", 0.5),
            Key("rate", "number", "the driver's rate at t = 0", "rad/s or length/s", "the input's rate at t = 0", 0.0),
            Key(
                "torque",
                "number, CSV path or table",
                "0",
                "N·m (N on a slider)",
                "on the input: constant, or columns t, torque",
                1.5,
            ),
            Key(
                "motor",
                "{ stall, no_load_speed }",
                "none",
                "N·m, rad/s",
                "motor line T = stall·(1 − ω/no_load_speed) on the input (N and length/s on a slider)",
                {"stall": 2.0, "no_load_speed": 30.0},
            ),
            Key("flywheel", "number ≥ 0", "0", "kg·m² (kg on a slider)", "extra inertia on the input", 0.01),
            Key(
                "method",
                '"DOP853" | "RK45" | "Radau" | "BDF" | "LSODA"',
                '"DOP853"',
                "",
                "scipy's solve_ivp method (an implicit one for stiff springs)",
                "Radau",
            ),
            Key("rtol", "0 < number < 1", "1e-10", "", "the integrator's relative tolerance", 1e-9),
            Key("atol", "number > 0", "1e-10", "rad, rad/s (m, m/s)", "the integrator's absolute tolerance", 1e-9),
            Key("stop", "number > 0", "[time] stop", "s", "the last simulated row (rows from t = 0)", 5.0),
            Key("step", "number > 0", "[time] step", "s", "the rows' spacing", 0.01),
            Key("springs", "[[dynamics.springs]]", "none", "", "springs and dampers (next table)", None),
        ),
    ),
    Section(
        "springs",
        "[[dynamics.springs]]",
        "a spring and/or damper: rotational at a pin (`joint`) or linear `between` two points",
        (
            Key("joint", "joint name", "none", "", "a rotational spring at this pin", None),
            Key(
                "links",
                "[a, b]",
                "the first two bodies at the pin",
                "",
                "acting on φ = θ_a − θ_b (b may be the ground)",
                None,
            ),
            Key("between", "[P, Q]", "none", "", "a linear spring between two joints or points", None),
            Key("k", "number ≥ 0", "0", "N·m/rad or N/m", "stiffness", 100.0),
            Key("c", "number ≥ 0", "0", "N·m·s/rad or N·s/m", "damping", 0.5),
            Key("rest", "number", "as at t = 0", "rad or length", "φ or the length at rest", 0.0),
        ),
    ),
)

SECTION = {s.name: s for s in SECTIONS}
TOP_LEVEL = SECTION["file"].allowed | {"joints", "links", "sliders", "points", "drivers", "time", "solver", "loads"}
TOP_LEVEL |= {"dynamics"}


def markdown(sections: tuple[Section, ...] | None = None) -> str:
    """A file format as Markdown tables, one per section (default: the mechanism file's; the copy in
    docs/file-format.md must equal this). A ``|`` inside a cell is escaped, so each row keeps five cells."""
    out = []
    for s in SECTIONS if sections is None else sections:
        out.append(f"**{s.form}** — {s.doc}\n")
        out.append("| key | type | default | unit | meaning |")
        out.append("|---|---|---|---|---|")
        for k in s.keys:
            cells = (f"`{k.name}`", k.type, k.default, k.unit or "—", k.doc)
            out.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
        out.append("")
    return "\n".join(out).rstrip() + "\n"


# ---------------------------------------------------------------- problems and values


class Problems:
    """Collects every problem found in one validation stage, raised as one message."""

    def __init__(self, where: str) -> None:
        self.where = where
        self.items: list[tuple[str, str]] = []

    def add(self, entry: str, msg: str) -> None:
        self.items.append((entry, msg))

    def raise_if_any(self) -> None:
        if self.items:
            entry = self.items[0][0]
            text = "; ".join(f"[{e}] {m}" for e, m in self.items[:8])
            more = f" (and {len(self.items) - 8} more)" if len(self.items) > 8 else ""
            raise MechanismError(f"{self.where}: {text}{more}", entry=entry)


def check_keys(table: dict, section: str | Section, entry: str, probs: Problems, extra: set[str] | None = None) -> None:
    """Every key of ``table`` must be one of the section's (plus ``extra``); ``section`` names one of the
    mechanism file's or is a Section of another file's schema."""
    allowed = (SECTION[section] if isinstance(section, str) else section).allowed | (extra or set())
    for k in table:
        if k not in allowed:
            probs.add(entry, f"unknown key {show(k)} (allowed: {', '.join(sorted(allowed))})")


def integer(table: dict, key: str, entry: str, lo: int, hi: int, probs: Problems, default: Any = None) -> Any:
    """``table[key]`` as an integer in [lo, hi] (a float with an integer value is refused: counts are
    integers), ``default`` if absent (or after recording a problem)."""
    if key not in table:
        return default
    v = table[key]
    if isinstance(v, bool) or not isinstance(v, int) or not lo <= v <= hi:
        probs.add(entry, f"'{key}' must be an integer from {lo:,} to {hi:,}, got {show(v)}")
        return default
    return v


def real(value: Any, what: str, entry: str, probs: Problems) -> float | None:
    """A finite real number, or None after recording why not (bools, strings, 10**400, nan, inf)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        probs.add(entry, f"'{what}' must be a number, got {show(value)}")
        return None
    try:
        x = float(value)
    except OverflowError:
        probs.add(entry, f"'{what}' is too large for a floating-point number ({len(str(abs(value)))} digits)")
        return None
    if not math.isfinite(x):
        probs.add(entry, f"'{what}' is not finite ({show(value)}): non-finite values are refused")
        return None
    return x + 0.0  # -0.0 → 0.0


def number(table: dict, key: str, entry: str, probs: Problems, default: float | None = None) -> float | None:
    """``table[key]`` as a finite number, ``default`` if absent (or after recording a problem)."""
    if key not in table:
        return default
    x = real(table[key], key, entry, probs)
    return default if x is None else x


def pair(value: Any, what: str, entry: str, probs: Problems) -> tuple[float, float] | None:
    """A pair of finite numbers [x, y]."""
    if not isinstance(value, list) or len(value) != 2:
        probs.add(entry, f"expected a pair of numbers [x, y] for '{what}', got {show(value)}")
        return None
    xy = [real(v, what, entry, probs) for v in value]
    return None if None in xy else (xy[0], xy[1])  # type: ignore[return-value]


def direction(value: Any, what: str, entry: str, probs: Problems) -> tuple[float, float] | None:
    """A unit direction from a pair: scaled by its largest component first, so huge or tiny ones neither
    overflow nor underflow; a zero (or subnormal-only) pair is refused."""
    xy = pair(value, what, entry, probs)
    if xy is None:
        return None
    big = max(abs(xy[0]), abs(xy[1]))
    if big == 0.0:
        probs.add(entry, f"{what} has zero length")
        return None
    x, y = xy[0] / big, xy[1] / big
    n = math.hypot(x, y)
    return x / n, y / n


def beyond_sizes(units: str) -> str:
    """Why a length beyond ±SIZES[1] is refused (follows the value in a message)."""
    return (
        f"is beyond ±{SIZES[1]:g} {units}: only sizes from {SIZES[0]:g} to {SIZES[1]:g} of the units can be solved "
        "in double precision (lengths are squared twice); state the coordinates in larger units"
    )


def name_problem(name: Any) -> str | None:
    """Why a name is refused (None if it is fine): letters, digits, '_' and '-' only, at most 64 characters,
    so every name is safe as a CSV header, a file name, an HTML id and in a message."""
    if not isinstance(name, str) or not name:
        return f"a name must be a non-empty string, got {show(name)}"
    if len(name) > NAME_MAX:
        return f"name {show(name, 30)} is longer than {NAME_MAX} characters"
    if not _NAME.fullmatch(name):
        return (
            f"name {show(name)} may use only letters, digits, '_' and '-' (it becomes a column name "
            f"such as {_clip(name)}.x in results.csv)"
        )
    return None


def _clip(name: str) -> str:
    safe = "".join(c if c.isprintable() else "?" for c in name)
    return safe[:20]
