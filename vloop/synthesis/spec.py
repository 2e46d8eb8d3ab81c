"""The synthesis file: its schema (every key, type, default, unit), its reader, and its key tables.

    name = "lever"
    units = "mm"
    method = "path"                  # function | motion | path
    min_transmission_angle = 0.5236  # rad (30°)
    [path]
    points = [[0, 100], [100, 200], [200, 150], [300, 0], [150, -50]]

The keys come from :data:`SECTIONS` (docs/synthesis.md's key tables are generated from it: :func:`markdown`; a
test keeps the two equal). Every problem is one :class:`~vloop.errors.VloopError` naming the file, the entry and
what is wrong, found before any work starts: numbers must be finite (nan, inf, 10**400, strings, booleans and
nested arrays refused), counts are bounded integers, point lists have the right shape.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..errors import MechanismError, SynthesisError
from ..files.schema import Key, Problems, Section, check_keys, integer, name_problem, real, show
from ..files.schema import markdown as schema_markdown
from . import arguments as args
from .arguments import LIMITS
from .candidates import shortfall
from .defects import Requirements

MAX_SPEC_BYTES = 4 * 2**20
METHODS = ("function", "motion", "path")
MAX_POINTS = 100

SECTIONS: tuple[Section, ...] = (
    Section(
        "synthesis",
        "top level",
        "what is synthesized and what a solution must also do",
        (
            Key("name", "name-like string", "the file's name", "", "the candidates' names NAME_1, NAME_2, …", "lever"),
            Key("title", "string", '""', "", "a title for the candidates' files", "A lever"),
            Key("units", "string", '"m"', "", "length unit of every coordinate", "mm"),
            Key(
                "method",
                '"function", "motion" or "path"',
                "required",
                "",
                "function, motion or path generation",
                "path",
            ),
            Key("seed", "integer ≥ 0", "0", "", "seed of the search (the same seed, the same candidates)", 7),
            Key("candidates", "integer 1..100", "5", "", "candidates kept, ranked", 3),
            Key("files", "integer 0..100", "3", "", "mechanism files written for the best solutions", 2),
            Key(
                "min_transmission_angle",
                "0 ≤ number < π/2",
                "0 (none)",
                "rad",
                "a solution's smallest transmission angle over its motion",
                0.5236,
            ),
            Key("full_rotation", "bool", "true for path, else false", "", "the input must turn fully", True),
            Key(
                "pivots",
                "[xmin, ymin, xmax, ymax]",
                "none",
                "length",
                "a solution's ground pivots lie in this region (the search keeps them there)",
                [-500.0, -500.0, 500.0, 500.0],
            ),
            Key(
                "links",
                "[min, max]",
                "none",
                "length",
                "every moving link's length (a plate's sides) lies in this range (the search keeps them there)",
                [10.0, 800.0],
            ),
        ),
    ),
    Section(
        "function",
        "[function]",
        "function generation: the output follows y = f(x) as the input follows x",
        (
            Key(
                "expression",
                "string in x",
                "required (or pairs)",
                "",
                "f(x): numbers, x, pi, e, + - * / **, sin…",
                "log10(x)",
            ),
            Key("x", "[x0, xf]", "required (or pairs)", "", "the range of x", [1.0, 2.0]),
            Key("y", "[y0, yf]", "[f(x0), f(xf)]", "", "the y values the output range stands for", [0.0, 0.30103]),
            Key("input", "[start, stop]", "required", "rad", "the input crank's angle over the range of x", [0.5, 2.0]),
            Key(
                "output",
                "[start, stop]",
                "required (or pairs)",
                "rad or length",
                "the rocker's angle (four-bar) or the slider's position (slider-crank) over y",
                [4.0, 5.5],
            ),
            Key("points", "integer 3..1000", "3", "", "precision points (three exact, more by least squares)", 3),
            Key("spacing", '"chebyshev" or "even"', '"chebyshev"', "", "where the precision points lie", "even"),
            Key("precision", "list of x", "none", "", "the precision points' x instead of a spacing", [1.1, 1.5, 1.9]),
            Key("pairs", "list of [input, output]", "none", "rad, rad or length", "precision pairs instead of f", None),
            Key("linkage", '"fourbar" or "slider-crank"', '"fourbar"', "", "the generator", "slider-crank"),
            Key("ground", "number 1e-50..1e50", "1", "length", "the four-bar's ground pivot distance O2O4", 100.0),
            Key("samples", "integer 2..100000", "201", "", "x values the structural error is measured at", 401),
        ),
    ),
    Section(
        "motion",
        "[motion]",
        "motion generation: the coupler carries a body through poses",
        (
            Key(
                "poses",
                "list of [x, y, θ]",
                "required",
                "length, length, rad",
                "2 to 5 poses of point P and the body",
                None,
            ),
            Key(
                "region",
                "[xmin, ymin, xmax, ymax]",
                "the poses' box grown by their size",
                "length",
                "where pivots are searched",
                None,
            ),
            Key("grid", "integer 2..40", "10", "", "pivots searched on a grid × grid lattice", 8),
        ),
    ),
    Section(
        "dyads",
        "[[motion.dyads]]",
        "the free choices of each of the two dyads (2 poses: a pivot and rotations; 3 poses: one of the three)",
        (
            Key("fixed", "[x, y]", "none", "length", "the ground pivot", [0.0, 0.0]),
            Key("moving", "[x, y]", "none", "length", "the moving pivot at the first pose", [1.0, 1.0]),
            Key(
                "rotations",
                "list of numbers",
                "none",
                "rad",
                "the link's turn from pose 1 to each later pose",
                [0.5, 1.1],
            ),
        ),
    ),
    Section(
        "path",
        "[path]",
        "path generation: the tracer passes through points as the input turns once",
        (
            Key("points", "list of [x, y]", "required", "length", "3 to 100 target points, in order", None),
            Key("timing", "list of numbers", "none", "rad", "input angles at which the points are reached", None),
            Key(
                "linkage",
                '"auto", "fourbar" or "sixbar"',
                '"auto"',
                "",
                "a six-bar only if no four-bar will do",
                "fourbar",
            ),
            Key(
                "tolerance",
                "1e-12 < number ≤ 1",
                "0.01",
                "",
                "error that counts as reached, fraction of the points' size",
                0.005,
            ),
            Key("population", "integer 5..200", "10", "", "differential evolution: members per gene", 15),
            Key("generations", "integer 1..100000", "400", "", "differential evolution: at most this many", 200),
            Key("samples", "integer 16..10000", "120", "", "input angles per turn the search scores", 360),
            Key("restarts", "integer 1..100", "1", "", "independent searches (more distinct candidates)", 2),
            Key("region", "0.1 ≤ number ≤ 100", "1.5", "", "joints searched within this many sizes of the points", 2.0),
        ),
    ),
)

SECTION = {s.name: s for s in SECTIONS}


def markdown() -> str:
    """The synthesis file format as Markdown tables, one per section (docs/synthesis.md holds a copy a test keeps
    equal)."""
    return schema_markdown(SECTIONS)


@dataclass(frozen=True)
class SynthSpec:
    """A synthesis file, read: the method and its options (keyword arguments of :func:`vloop.synthesis.function`,
    ``motion`` or ``path``), the requirements, how many candidates and files."""

    method: str
    name: str
    options: dict[str, Any] = field(default_factory=dict)
    units: str = "m"
    title: str = ""
    seed: int = 0
    candidates: int = 5
    files: int = 3
    requirements: Requirements = field(default_factory=Requirements)
    source: str = "<synthesis>"


def load(path: str | Path) -> SynthSpec:
    """Read and check a synthesis file. Raises a VloopError naming the file and the entry."""
    from ..files.fileformat import _read_text_file, parse_toml

    if not isinstance(path, (str, Path)) or not str(path).strip():
        raise SynthesisError(f"path: must be a synthesis file's path, got {show(path)}", entry="path")
    path = Path(path)
    data = parse_toml(_read_text_file(path, MAX_SPEC_BYTES, what="synthesis file", entry=str(path)), str(path))
    return from_dict(data, source=str(path), default_name=path.stem)


def from_dict(data: Any, *, source: str = "<synthesis>", default_name: str = "synthesis") -> SynthSpec:
    """A SynthSpec from the parsed TOML structure."""
    if not isinstance(data, dict):
        raise MechanismError(f"{source}: expected a TOML table at top level", entry="synthesis")
    probs = Problems(source)
    _check_keys(data, "synthesis", "synthesis", probs, extra=set(METHODS))
    method = data.get("method")
    if method not in METHODS:
        raise MechanismError(
            f"{source}: [synthesis] 'method' must be one of {', '.join(METHODS)}, got {show(method)}", entry="method"
        )
    name = data.get("name", default_name)
    if name_problem(name):
        probs.add("synthesis", name_problem(name))  # type: ignore[arg-type]
    for k in ("title", "units"):
        if k in data and not isinstance(data[k], str):
            probs.add("synthesis", f"'{k}' must be a string, got {show(data[k])}")
    others = [m for m in METHODS if m != method and m in data]
    if others:
        probs.add("synthesis", f"method is {method!r}, but the file has a [{others[0]}] section")
    common = {
        "seed": integer(data, "seed", "synthesis", *_limits("seed"), probs, 0),
        "candidates": integer(data, "candidates", "synthesis", *_limits("count"), probs, 5),
        "files": integer(data, "files", "synthesis", 0, 100, probs, 3),
    }
    req = _requirements(data, method, probs)
    section = data.get(method)
    if not isinstance(section, dict):
        probs.add(method, f"missing: give a [{method}] section")
        probs.raise_if_any()
    options = _READERS[method](section, probs)
    probs.raise_if_any()
    units = data.get("units", "m")
    return SynthSpec(method, name, options, units, data.get("title", ""), requirements=req, source=source, **common)


def _requirements(data: dict, method: str, probs: Problems) -> Requirements:
    mu = 0.0
    if "min_transmission_angle" in data:
        mu = real(data["min_transmission_angle"], "min_transmission_angle", "synthesis", probs) or 0.0
        if not 0 <= mu < math.pi / 2:
            probs.add("synthesis", f"'min_transmission_angle' must be in [0, π/2) rad, got {mu:g}")
    full = data.get("full_rotation", method == "path")
    if not isinstance(full, bool):
        probs.add("synthesis", f"'full_rotation' must be true or false, got {show(full)}")
        full = False
    bounds: dict[str, Any] = {}
    for key, check in (("pivots", args.pivots), ("links", args.links)):
        if key in data:
            try:
                bounds[key] = check(data[key], key)
            except SynthesisError as exc:
                probs.add("synthesis", f"'{key}' {str(exc).split(': ', 1)[-1]}")
    return Requirements(full, mu, **bounds)


def _read_function(d: dict, probs: Problems) -> dict[str, Any]:
    from .expression import parse

    e = "function"
    _check_keys(d, "function", e, probs)
    opts: dict[str, Any] = {}
    if "pairs" in d:
        opts["pairs"] = _rows(d["pairs"], 2, "pairs", e, probs, lo=3)
    if "expression" in d:
        try:
            parse(d["expression"])
            opts["f"] = d["expression"]
        except SynthesisError as exc:
            probs.add(e, "'expression': " + str(exc).split(": ", 1)[-1])
    elif "pairs" not in d:
        probs.add(e, "give 'expression' (with x, input, output) or 'pairs'")
    for key, arg in (("x", "x_range"), ("y", "y_range"), ("input", "input_range"), ("output", "output_range")):
        if key in d:
            opts[arg] = _pair(d[key], key, e, probs)
    if "f" in opts:
        missing = [k for k in ("x", "input", "output") if k not in d]
        if missing:
            probs.add(e, f"the expression needs {', '.join(missing)}")
    for key in ("points", "samples"):
        if key in d:
            opts[key] = integer(d, key, e, *_limits(f"function.{key}"), probs, None)
    for key, choices in (("spacing", ("chebyshev", "even")), ("linkage", ("fourbar", "slider-crank"))):
        if key in d:
            opts[key] = _choice(d[key], key, choices, e, probs)
    if "precision" in d:
        opts["precision"] = _numbers(d["precision"], "precision", e, probs)
    if "ground" in d:
        g = real(d["ground"], "ground", e, probs)
        lo, hi = LIMITS["function.ground"]
        if g is not None and not lo <= g <= hi:
            probs.add(e, f"'ground' must be a length from {lo:g} to {hi:g}, got {g:g}")
        opts["ground"] = g
    return opts


def _read_motion(d: dict, probs: Problems) -> dict[str, Any]:
    e = "motion"
    _check_keys(d, "motion", e, probs, extra={"dyads"})
    opts: dict[str, Any] = {"poses": _rows(d.get("poses"), 3, "poses", e, probs, lo=2, hi=5)}
    if "region" in d:
        opts["region"] = _numbers(d["region"], "region", e, probs, n=4)
    if "grid" in d:
        opts["grid"] = integer(d, "grid", e, *_limits("motion.grid"), probs, None)
    if "dyads" in d:
        raw = d["dyads"]
        if not isinstance(raw, list) or len(raw) != 2:
            probs.add(e, f"'dyads' must be two [[motion.dyads]] tables, got {show(raw)}")
        else:
            opts["dyads"] = [_dyad(x, i, probs) for i, x in enumerate(raw)]
    return opts


def _dyad(d: Any, i: int, probs: Problems) -> dict[str, Any]:
    e = f"motion.dyads[{i}]"
    if not isinstance(d, dict):
        probs.add(e, f"must be a table, got {show(d)}")
        return {}
    _check_keys(d, "dyads", e, probs)
    out: dict[str, Any] = {}
    for k in ("fixed", "moving"):
        if k in d:
            out[k] = _pair(d[k], k, e, probs)
    if "rotations" in d:
        out["rotations"] = _numbers(d["rotations"], "rotations", e, probs)
    if not out:
        probs.add(e, "give fixed, moving or rotations")
    return out


def _read_path(d: dict, probs: Problems) -> dict[str, Any]:
    e = "path"
    _check_keys(d, "path", e, probs)
    opts: dict[str, Any] = {"points": _rows(d.get("points"), 2, "points", e, probs, lo=3, hi=MAX_POINTS)}
    if "timing" in d:
        opts["timing"] = _numbers(d["timing"], "timing", e, probs)
    if "linkage" in d:
        opts["linkage"] = _choice(d["linkage"], "linkage", ("auto", "fourbar", "sixbar"), e, probs)
    for key in ("population", "generations", "samples", "restarts"):
        if key in d:
            opts[key] = integer(d, key, e, *_limits(f"path.{key}"), probs, None)
    for key in ("tolerance", "region"):
        lo, hi = LIMITS[f"path.{key}"]
        if key in d:
            v = real(d[key], key, e, probs)
            if v is not None and not (lo < v <= hi if key == "tolerance" else lo <= v <= hi):
                probs.add(e, f"'{key}' must be in {'(' if key == 'tolerance' else '['}{lo:g}, {hi:g}], got {v:g}")
            opts[key] = v
    return opts


_READERS = {"function": _read_function, "motion": _read_motion, "path": _read_path}
# the functions' argument names as the file's keys (a message from a function names the file's key)
FILE_KEYS = {
    "f": "expression", "x_range": "x", "y_range": "y", "input_range": "input", "output_range": "output",
    "count": "candidates",
}  # fmt: skip


def _limits(key: str) -> tuple[int, int]:
    lo, hi = LIMITS[key]
    return int(lo), int(hi)


# ---------------------------------------------------------------- values


def _check_keys(table: dict, section: str, entry: str, probs: Problems, extra: set[str] | None = None) -> None:
    check_keys(table, SECTION[section], entry, probs, extra)


def _choice(v: Any, key: str, choices: tuple[str, ...], entry: str, probs: Problems) -> Any:
    if v not in choices:
        probs.add(entry, f"'{key}' must be one of {', '.join(choices)}, got {show(v)}")
    return v


def _numbers(v: Any, key: str, entry: str, probs: Problems, n: int | None = None) -> list[float] | None:
    if not isinstance(v, list) or not v or len(v) > 10_000 or (n is not None and len(v) != n):
        probs.add(entry, f"'{key}' must be a list of {n or 'some'} numbers, got {show(v)}")
        return None
    out = [real(x, key, entry, probs) for x in v]
    return None if None in out else out  # type: ignore[return-value]


def _pair(v: Any, key: str, entry: str, probs: Problems) -> list[float] | None:
    return _numbers(v, key, entry, probs, n=2)


def _rows(v: Any, width: int, key: str, entry: str, probs: Problems, lo: int, hi: int = 10_000) -> list | None:
    shape = "[x, y]" if width == 2 else "[x, y, θ]"
    if not isinstance(v, list) or not lo <= len(v) <= hi:
        probs.add(entry, f"'{key}' must be a list of {lo} to {hi} {shape} rows, got {show(v)}")
        return None
    rows = []
    for i, row in enumerate(v):
        if not isinstance(row, list) or len(row) != width:
            probs.add(entry, f"'{key}'[{i}] must be {shape}, got {show(row)}")
            return None
        vals = [real(x, f"{key}[{i}]", entry, probs) for x in row]
        if None in vals:
            return None
        rows.append(vals)
    return rows


def run(spec: SynthSpec, progress: Any = None) -> Any:
    """Synthesize what a spec asks (:func:`vloop.synthesis.function`, ``motion`` or ``path``); a problem the
    functions find is named as the file's entry."""
    if not isinstance(spec, SynthSpec):
        raise SynthesisError(f"spec: must be a SynthSpec (vloop.synthesis.load), got {show(spec)}", entry="spec")
    if progress is not None and not callable(progress):
        raise SynthesisError(f"progress: must be a function of one message, got {show(progress)}", entry="progress")
    try:
        out = _run(spec, progress)
    except SynthesisError as exc:
        text = str(exc)
        key, _, rest = text.partition(": ")
        if not text.startswith("[") and rest and key.isidentifier():
            sep = " " if rest.startswith("must") else ": "
            text = f"[{spec.method}] '{FILE_KEYS.get(key, key)}'{sep}{rest}"
        raise SynthesisError(f"{spec.source}: {text}", entry=exc.entry) from None
    if spec.title:
        for c in out:
            c.mechanism = dataclasses.replace(c.mechanism, title=f"{spec.title} ({c.name})")
    if len(out) < spec.candidates:
        dyads, poses = bool(spec.options.get("dyads")), len(spec.options.get("poses") or ())
        out.note = shortfall(spec.method, spec.candidates, len(out), dyads=dyads, poses=poses)
    return out


def _run(spec: SynthSpec, progress: Any) -> Any:
    from . import function, motion, path

    common = {"name": spec.name, "units": spec.units, "requirements": spec.requirements}
    opts = dict(spec.options)
    if spec.method == "function":
        return function(**opts, **common)
    if spec.method == "motion":
        return motion(**opts, count=spec.candidates, **common)
    return path(**opts, count=spec.candidates, seed=spec.seed, progress=progress, **common)
