"""The design-study file: its schema (every key, type, default, unit), its reader, and its documentation tables.

    mechanism = "../mechanisms/fourbar_textbook_example.toml"
    samples = 10000                      # Monte-Carlo draws (parameters with a tolerance)
    seed = 1
    [[parameters]]
    name = "links.l3.length"
    tolerance = { dist = "uniform", half_width = 0.05 }
    [[outputs]]
    quantity = "l4.theta"
    stat = "range"

The keys come from :data:`SECTIONS` (the tables in docs/studies.md are generated from it: :func:`markdown`, and a
test keeps the two equal). Every problem is one :class:`~vloop.errors.MechanismError` naming the study
file, the entry (``parameters[2]``, ``outputs[0]``) and what is wrong; numbers must be finite (nan, inf,
10**400, strings, booleans and nested arrays are refused), counts are bounded integers.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import MechanismError
from ..files.schema import Key, Problems, Section, check_keys, integer, real, show
from ..files.schema import markdown as schema_markdown
from ..model import Mechanism

MAX_VALUES = 1_000_000  # grid values of one parameter
MAX_SAMPLES = 10_000_000  # Monte-Carlo draws
MAX_DESIGNS = 50_000_000  # variants (grid × draws) of one study
MAX_STUDY_BYTES = 16 * 2**20
DISTRIBUTIONS = ("uniform", "normal")
SENSITIVITY = ("nominal", "each", "none")
STATS = ("range", "min", "max", "peak", "mean", "rms", "start", "end", "series")
_OUTPUT_NAME = re.compile(r"[^\W_.][\w.-]*|_[\w.-]*")
RESERVED = (
    "variant",
    "grid",
    "draw",
    "assembled",
    "completed",
    "stopped_at",
    "stopped_sample",
    "reason",
    "solver",
    "max_cond",
)  # the table's own columns

SECTIONS: tuple[Section, ...] = (
    Section(
        "study",
        "top level",
        "the mechanism studied and how variants are drawn",
        (
            Key("mechanism", "path", "required", "", "the mechanism file (relative to the study file)", "m.toml"),
            Key("samples", "integer ≥ 1", "none", "", "Monte-Carlo draws (needs a parameter with a tolerance)", 100),
            Key("seed", "integer ≥ 0", "0", "", "seed of the draws (every value is drawn up front)", 7),
            Key(
                "sensitivity",
                '"nominal" | "each" | "none"',
                '"nominal"',
                "",
                "where d(output)/d(parameter) is taken: the nominal design(s), every variant, nowhere",
                "each",
            ),
            Key("chunk", "integer ≥ 1", "automatic", "", "variants per task (never changes a number)", 500),
        ),
    ),
    Section(
        "parameters",
        "[[parameters]]",
        "a number of the mechanism file that varies: a grid of values, a tolerance, or both",
        (
            Key(
                "name",
                "SECTION.ENTRY.FIELD",
                "required",
                "",
                "joints.J.x|y, points.P.x|y, links.L.length (binary), sliders.S.angle|offset, "
                "drivers.T.theta0|omega|alpha|s0|v|a",
                "links.l3.length",
            ),
            Key("values", "list of numbers", "none", "the field's", "grid values", [1.0, 2.0]),
            Key("start", "number", "none", "the field's", "first grid value (with stop and num)", 1.0),
            Key("stop", "number", "none", "the field's", "last grid value", 2.0),
            Key("num", "integer ≥ 1", "none", "", "grid values from start to stop, evenly spaced", 3),
            Key("tolerance", "table", "none", "", "random deviation around the nominal (or each grid) value", None),
        ),
    ),
    Section(
        "tolerance",
        "tolerance = { ... }",
        "how a parameter deviates in the Monte-Carlo draws",
        (
            Key("dist", '"uniform" | "normal"', "required", "", "distribution of the deviation", "normal"),
            Key("half_width", "number > 0", "none", "the field's", "uniform: deviation in ±half_width", 0.05),
            Key("sigma", "number > 0", "none", "the field's", "normal: standard deviation", 0.02),
        ),
    ),
    Section(
        "outputs",
        "[[outputs]]",
        "a quantity every variant reports",
        (
            Key(
                "quantity",
                "string",
                "required",
                "",
                "a result column (l4.theta, B.ay, s1.v), POINT.speed, POINT.acceleration, POINT.path, "
                "transmission_angle[.JOINT], grashof[.LOOP]",
                "l4.theta",
            ),
            Key(
                "stat",
                "string",
                "range (θ, s, x, y), peak (rates), min (transmission angle)",
                "",
                "range, min, max, peak (max |x|), mean, rms, start, end, series (the whole motion)",
                "peak",
            ),
            Key("name", "letters, digits, _ - .", "QUANTITY.STAT", "", "the output's column name", "swing"),
        ),
    ),
    Section(
        "time",
        "[time]",
        "the samples of every variant (default: the mechanism's [time])",
        (
            Key("start", "number", "0", "s", "first sample", 0.0),
            Key("stop", "number", "required", "s", "last sample (within half a step)", 1.0),
            Key("step", "number > 0", "required", "s", "sample spacing", 0.1),
            Key("times", "list of numbers", "none", "s", "explicit, strictly increasing samples instead", None),
        ),
    ),
)

SECTION = {s.name: s for s in SECTIONS}


def markdown() -> str:
    """The study file format as Markdown tables, one per section (docs/studies.md holds a copy a test keeps equal)."""
    return schema_markdown(SECTIONS)


# ---------------------------------------------------------------- the specification


@dataclass(frozen=True)
class Tolerance:
    """A random deviation: ``dist`` "uniform" (in ±width) or "normal" (standard deviation width)."""

    dist: str
    width: float

    @property
    def sigma(self) -> float:
        """The deviation's standard deviation [the parameter's unit]."""
        return self.width / math.sqrt(3.0) if self.dist == "uniform" else self.width


@dataclass(frozen=True)
class ParameterSpec:
    """A varied number: its name, its grid values (None: the nominal only) and its tolerance (None: exact)."""

    name: str
    values: tuple[float, ...] | None = None
    tolerance: Tolerance | None = None


@dataclass(frozen=True)
class OutputSpec:
    """An output: its column ``name``, the ``quantity`` and the ``stat`` taken over the motion."""

    name: str
    quantity: str
    stat: str


@dataclass(frozen=True)
class StudySpec:
    """A whole study: the mechanism, its parameters and outputs, the draws, the samples, the sensitivity."""

    mechanism: Mechanism
    parameters: tuple[ParameterSpec, ...]
    outputs: tuple[OutputSpec, ...]
    samples: int | None = None
    seed: int = 0
    sensitivity: str = "nominal"
    chunk: int | None = None
    times: np.ndarray | None = None
    source: str = "<study>"


# ---------------------------------------------------------------- reading


def load(path: str | Path) -> StudySpec:
    """Read and check a study file (and the mechanism it names). Raises MechanismError naming the entry."""
    from .. import load as load_mechanism  # (assembled at t = 0 if written from dimensions)
    from ..files.fileformat import _read_text_file, parse_toml

    path = Path(path)
    data = parse_toml(_read_text_file(path, MAX_STUDY_BYTES, what="study file", entry=str(path)), str(path))
    probs = Problems(str(path))
    mech_name = data.get("mechanism") if isinstance(data, dict) else None
    if not isinstance(mech_name, str) or not mech_name.strip() or "\x00" in mech_name:
        raise MechanismError(
            f"{path}: [study] 'mechanism' must name the mechanism file, got {show(mech_name)}", entry="mechanism"
        )
    mech = load_mechanism(path.parent / mech_name)
    spec = from_dict(data, mech, source=str(path), probs=probs)
    return spec


def from_dict(data: Any, mech: Mechanism, *, source: str = "<study>", probs: Problems | None = None) -> StudySpec:
    """A StudySpec from the parsed TOML structure (``mechanism`` already read: ``mech``)."""
    probs = probs or Problems(source)
    if not isinstance(data, dict):
        raise MechanismError(f"{source}: expected a TOML table at top level", entry="study")
    _check_keys(data, "study", "study", probs, extra={"parameters", "outputs", "time"})
    samples = _integer(data, "samples", "study", 1, MAX_SAMPLES, probs)
    seed = _integer(data, "seed", "study", 0, 2**63 - 1, probs)
    chunk = _integer(data, "chunk", "study", 1, MAX_DESIGNS, probs)
    sensitivity = data.get("sensitivity", "nominal")
    if sensitivity not in SENSITIVITY:
        probs.add("study", f"'sensitivity' must be one of {', '.join(SENSITIVITY)}, got {show(sensitivity)}")
    params = read_parameters(data.get("parameters"), mech, probs)
    outputs = read_outputs(data.get("outputs"), mech, probs)
    times = None
    if "time" in data:
        from ..files.fileformat import read_time

        times = read_time(data["time"], list(mech.drivers), probs)
    probs.raise_if_any()
    spec = StudySpec(mech, params, outputs, samples, seed or 0, sensitivity, chunk, times, source)
    check(spec)
    return spec


def check(spec: StudySpec) -> None:
    """Whole-study rules: samples go with tolerances, the study is not empty, its size is bounded."""
    where = spec.source
    tolerant = [p.name for p in spec.parameters if p.tolerance is not None]
    if tolerant and spec.samples is None:
        raise MechanismError(
            f"{where}: [study] 'samples' is needed: {', '.join(tolerant)} "
            "has a tolerance (how many Monte-Carlo draws?)",
            entry="samples",
        )
    if spec.samples is not None and not tolerant:
        raise MechanismError(
            f"{where}: [study] 'samples' draws Monte-Carlo variants, but no parameter has a tolerance", entry="samples"
        )
    taken = set(RESERVED) | {p.name for p in spec.parameters}
    for i, o in enumerate(spec.outputs):
        cols = {o.name, f"{o.name}.x", f"{o.name}.y"} if o.stat == "path" else {o.name}
        cols |= {f"{o.name}.is_grashof"} if o.stat == "class" else set()
        clash = sorted(cols & taken)
        if clash:
            raise MechanismError(
                f"{where}: [outputs[{i}]] the name {clash[0]!r} is a column of the table already: "
                "give the output another 'name'",
                entry=f"outputs[{i}]",
            )
        taken |= cols
    n = math.prod(len(p.values) for p in spec.parameters if p.values is not None) * (spec.samples or 1)
    if n > MAX_DESIGNS:
        raise MechanismError(f"{where}: the study has {n:,} variants, more than {MAX_DESIGNS:,}", entry="study")


def read_parameters(raw: Any, mech: Mechanism, probs: Problems) -> tuple[ParameterSpec, ...]:
    """[[parameters]]: each a name with values, start/stop/num, a tolerance, or a grid and a tolerance."""
    from ..core.variants import resolve

    if not isinstance(raw, list) or not raw:
        probs.add(
            "parameters", "missing or empty: give at least one [[parameters]] entry (name and values or tolerance)"
        )
        return ()
    out: list[ParameterSpec] = []
    for i, d in enumerate(raw):
        entry = f"parameters[{i}]"
        if not isinstance(d, dict):
            probs.add(entry, f"must be a table, got {show(d)}")
            continue
        _check_keys(d, "parameters", entry, probs)
        try:
            ref = resolve(mech, d.get("name"), entry)
        except MechanismError as exc:
            probs.add(entry, str(exc).split("] ", 1)[-1])
            continue
        if any(p.name == ref.name for p in out):
            probs.add(entry, f"{ref.name} is given twice")
            continue
        values = _grid(d, entry, probs)
        tol = _tolerance(d["tolerance"], entry, probs) if "tolerance" in d else None
        if values is None and tol is None and not _has_any(d, ("values", "start", "stop", "num", "tolerance")):
            probs.add(entry, "give values, start/stop/num, or a tolerance")
            continue
        if values is not None and ref.positive and any(v <= 0 for v in values):
            bad = next(v for v in values if v <= 0)
            probs.add(entry, f"{ref.name} must be positive (a length), got {bad:g}")
            continue
        out.append(ParameterSpec(ref.name, values, tol))
    return tuple(out)


def _has_any(d: dict, keys: tuple[str, ...]) -> bool:
    return any(k in d for k in keys)


def _grid(d: dict, entry: str, probs: Problems) -> tuple[float, ...] | None:
    """Grid values from ``values`` or ``start``/``stop``/``num`` (never both)."""
    ranged = [k for k in ("start", "stop", "num") if k in d]
    if "values" in d and ranged:
        probs.add(entry, f"give either 'values' or start/stop/num, not both (has values and {', '.join(ranged)})")
        return None
    if "values" in d:
        vals = d["values"]
        if not isinstance(vals, list) or not vals or len(vals) > MAX_VALUES:
            probs.add(entry, f"'values' must be a non-empty list of at most {MAX_VALUES:,} numbers, got {show(vals)}")
            return None
        nums = [real(v, "values", entry, probs) for v in vals]
        return None if None in nums else tuple(nums)  # type: ignore[arg-type]
    if not ranged:
        return None
    if len(ranged) != 3:
        probs.add(
            entry,
            f"start, stop and num go together (missing {', '.join(k for k in ('start', 'stop', 'num') if k not in d)})",
        )
        return None
    start, stop = real(d["start"], "start", entry, probs), real(d["stop"], "stop", entry, probs)
    num = _integer(d, "num", entry, 1, MAX_VALUES, probs)
    if start is None or stop is None or num is None:
        return None
    with np.errstate(over="ignore", invalid="ignore"):
        vals = np.linspace(start, stop, num)
    if not np.all(np.isfinite(vals)):
        probs.add(entry, f"start {start:g} to stop {stop:g} is too wide a range for floating-point numbers")
        return None
    return tuple(float(v) + 0.0 for v in vals)


def _tolerance(raw: Any, entry: str, probs: Problems) -> Tolerance | None:
    if not isinstance(raw, dict):
        probs.add(entry, f"'tolerance' must be a table {{ dist = \"uniform\", half_width = ... }}, got {show(raw)}")
        return None
    _check_keys(raw, "tolerance", f"{entry}.tolerance", probs)
    dist = raw.get("dist")
    if dist not in DISTRIBUTIONS:
        probs.add(entry, f"tolerance 'dist' must be one of {', '.join(DISTRIBUTIONS)}, got {show(dist)}")
        return None
    key = "half_width" if dist == "uniform" else "sigma"
    other = "sigma" if dist == "uniform" else "half_width"
    if other in raw:
        probs.add(entry, f"a {dist} tolerance takes '{key}', not '{other}'")
        return None
    if key not in raw:
        probs.add(entry, f"a {dist} tolerance needs '{key}'")
        return None
    width = real(raw[key], key, entry, probs)
    if width is None:
        return None
    if not width > 0:
        probs.add(entry, f"tolerance '{key}' must be positive, got {width:g}")
        return None
    return Tolerance(dist, width)


def read_outputs(raw: Any, mech: Mechanism, probs: Problems) -> tuple[OutputSpec, ...]:
    """[[outputs]]: quantity, stat (default by quantity), name (default QUANTITY.STAT); or strings
    ``"QUANTITY[.STAT]"`` (``outputs = ["l4.theta.range", "transmission_angle"]``)."""
    if not isinstance(raw, list) or not raw:
        probs.add("outputs", "missing or empty: give at least one [[outputs]] entry (quantity and stat)")
        return ()
    out: list[OutputSpec] = []
    for i, d in enumerate(raw):
        entry = f"outputs[{i}]"
        if isinstance(d, str):  # "QUANTITY" or "QUANTITY.STAT"
            q, _, st = d.rpartition(".")
            d = {"quantity": q, "stat": st} if q and st in STATS else {"quantity": d}
        if not isinstance(d, dict):
            probs.add(entry, f"must be a table {{ quantity = ..., stat = ... }}, got {show(d)}")
            continue
        _check_keys(d, "outputs", entry, probs)
        spec = output_spec(d, mech, entry, probs)
        if spec is None:
            continue
        if any(o.name == spec.name for o in out):
            probs.add(entry, f"output name {spec.name!r} is used twice: give one of them a 'name'")
            continue
        out.append(spec)
    return tuple(out)


def output_spec(d: dict, mech: Mechanism, entry: str, probs: Problems) -> OutputSpec | None:
    """One output's quantity and stat checked against the mechanism (see :mod:`vloop.studies.study` for the meaning)."""
    q = d.get("quantity")
    if not isinstance(q, str) or not q:
        probs.add(entry, f"'quantity' must be a string such as l4.theta or transmission_angle, got {show(q)}")
        return None
    kind = quantity_kind(mech, q)
    if kind is None:
        probs.add(entry, f"unknown quantity {show(q)}: {_quantity_help(mech)}")
        return None
    allowed = {"path": ("path",), "class": ("class",)}.get(kind, STATS)
    stat = d.get("stat", default_stat(q, kind))
    if stat not in allowed:
        probs.add(entry, f"'stat' of {q} must be one of {', '.join(allowed)}, got {show(stat)}")
        return None
    name = d.get("name", q if kind in ("path", "class") else f"{q}.{stat}")
    if not isinstance(name, str) or len(name) > 100 or not _OUTPUT_NAME.fullmatch(name):
        probs.add(entry, f"'name' may use only letters, digits, '_', '-' and '.', got {show(name)}")
        return None
    return OutputSpec(name, q, stat)


def quantity_kind(mech: Mechanism, q: str) -> str | None:
    """What a quantity is: "column" (a Result column), "magnitude" (POINT.speed|acceleration), "transmission",
    "path", "class" (grashof), or None if the mechanism has no such quantity."""
    links = set(mech.moving_links)
    points = set(mech.tracked_points)
    sliders = set(mech.sliders)
    if q == "transmission_angle" or q.startswith("transmission_angle."):
        return "transmission"
    if q == "grashof" or (q.startswith("grashof.") and q[8:].isdigit() and len(q) < 16):
        return "class"
    if "." not in q:
        return None
    ent, fld = q.rsplit(".", 1)
    if ent in links and fld in ("theta", "omega", "alpha"):
        return "column"
    if ent in sliders and fld in ("s", "v", "a"):
        return "column"
    if ent in points:
        if fld in ("x", "y", "vx", "vy", "ax", "ay"):
            return "column"
        if fld in ("speed", "acceleration"):
            return "magnitude"
        if fld == "path":
            return "path"
    return None


def default_stat(q: str, kind: str | None) -> str:
    """The stat a quantity takes when none is given."""
    if kind == "path":
        return "path"
    if kind == "class":
        return "class"
    if kind == "transmission":
        return "min"
    fld = q.rsplit(".", 1)[-1]
    return "range" if fld in ("theta", "s", "x", "y") else "peak"


def output_unit(mech: Mechanism, o: OutputSpec) -> str:
    """The unit of an output's values (rad for angles; the file's length unit for lengths)."""
    q, u = o.quantity, mech.units
    if q.startswith("transmission_angle"):
        return "rad"
    fld = q.rsplit(".", 1)[-1]
    units = {"theta": "rad", "omega": "rad/s", "alpha": "rad/s²", "x": u, "y": u, "vx": f"{u}/s", "vy": f"{u}/s"}
    units.update({"ax": f"{u}/s²", "ay": f"{u}/s²", "s": u, "v": f"{u}/s", "a": f"{u}/s²", "speed": f"{u}/s"})
    units.update({"acceleration": f"{u}/s²", "path": u})
    return units.get(fld, "")


def display_unit(mech: Mechanism, o: OutputSpec) -> tuple[float, str]:
    """(factor, unit) an output is shown in — plots and the printed summary: radians become degrees (the tables
    keep the output's own unit, :func:`output_unit`)."""
    u = output_unit(mech, o)
    if u.startswith("rad"):
        return 180.0 / math.pi, "deg" + u[3:]
    return 1.0, u or "1"


def _quantity_help(mech: Mechanism) -> str:
    link = next(iter(mech.moving_links), "LINK")
    point = next(iter(mech.tracked_points), "POINT")
    return (
        f"a result column such as {link}.theta|omega|alpha, {point}.x|y|vx|vy|ax|ay, SLIDER.s|v|a; "
        f"{point}.speed, {point}.acceleration, {point}.path; transmission_angle[.JOINT]; grashof[.LOOP]"
    )


# ---------------------------------------------------------------- small checks


def _check_keys(table: dict, section: str, entry: str, probs: Problems, extra: set[str] | None = None) -> None:
    check_keys(table, SECTION[section], entry, probs, extra)


def _integer(table: dict, key: str, entry: str, lo: int, hi: int, probs: Problems) -> int | None:
    return integer(table, key, entry, lo, hi, probs)
