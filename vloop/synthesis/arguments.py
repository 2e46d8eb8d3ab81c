"""Every argument of the synthesis functions, checked in one place before any work (as SciPy's ``_ivp/common.py``
does for ``solve_ivp``): the Python functions call these checks, the synthesis file's reader takes its ranges
from :data:`LIMITS`, and ``vloop synth`` reads the file. A bad value is one :class:`~vloop.errors.SynthesisError`
naming the argument (as the caller wrote it: ``samples``, ``[function] samples`` in a file) and what it accepts.

Numbers are finite and bounded: lengths within ±:data:`MAX_LENGTH` (a linkage's lengths are squared twice by the
solver, :data:`vloop.files.schema.SIZES`), angles within ±:data:`MAX_ANGLE` rad (a cosine of 1e300 rad has no
digits left); counts are integers (a bool or 2.0 is not a count).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np

from ..errors import SynthesisError
from ..files.options import show
from ..files.schema import MAX_LENGTH, MIN_LENGTH, name_problem

MAX_ANGLE = 1e4  # rad (≈ 1,600 turns): beyond it an angle's cosine has lost its digits
MAX_SEED = 2**63 - 1

# (lo, hi) of every bounded count and number: the functions' checks, the file's reader and its key tables
LIMITS: dict[str, tuple[float, float]] = {
    "function.points": (3, 1000),
    "function.samples": (2, 100_000),
    "function.ground": (MIN_LENGTH, MAX_LENGTH),
    "motion.grid": (2, 40),
    "path.tolerance": (1e-12, 1.0),
    "path.region": (0.1, 100.0),
    "path.population": (5, 200),
    "path.generations": (1, 100_000),
    "path.samples": (16, 10_000),
    "path.restarts": (1, 100),
    "count": (1, 100),
    "files": (0, 100),
    "seed": (0, MAX_SEED),
    "links": (1e-6, 1e6),
}


def _fail(where: str, what: str, value: Any) -> SynthesisError:
    return SynthesisError(f"{where}: must be {what}, got {show(value, 40)}", entry=where)


def count(value: Any, where: str, key: str | None = None) -> int:
    """An integer within LIMITS[key] (key defaults to ``where``)."""
    lo, hi = LIMITS[key or where]
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not lo <= value <= hi:
        raise _fail(where, f"an integer from {int(lo):,} to {int(hi):,}", value)
    return int(value)


def number(value: Any, where: str, lo: float, hi: float, *, open_low: bool = False) -> float:
    """A finite number in [lo, hi] ((lo, hi] with ``open_low``)."""
    what = f"a number {'above' if open_low else 'from'} {lo:g} {'and at most' if open_low else 'to'} {hi:g}"
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise _fail(where, what, value)
    try:
        x = float(value)
    except OverflowError:
        raise _fail(where, what, value) from None
    if not (lo < x if open_low else lo <= x) or not x <= hi:
        raise _fail(where, what, value)
    return x


def limited(value: Any, where: str, key: str, *, open_low: bool = False) -> float:
    """A number within LIMITS[key]."""
    lo, hi = LIMITS[key]
    return number(value, where, lo, hi, open_low=open_low)


def pair(value: Any, where: str, bound: float) -> tuple[float, float]:
    """Two different finite numbers [start, stop] within ±bound."""
    what = f"two different numbers [start, stop] within ±{bound:g}"
    arr = table(value, where, what)
    if arr.shape != (2,) or not np.all(np.abs(arr) <= bound) or not _apart(arr[0], arr[1]):
        raise _fail(where, what, value)
    return float(arr[0]), float(arr[1])


def _apart(a: float, b: float) -> bool:
    """Two numbers far enough apart for a range (more than 1e-12 of their size)."""
    return abs(b - a) > 1e-12 * max(abs(a), abs(b))


def table(value: Any, where: str, what: str) -> np.ndarray:
    """A numeric array of finite numbers (strings, bools, None and ragged lists refused)."""
    if isinstance(value, (str, bytes, bool)) or value is None:
        raise _fail(where, what, value)
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise _fail(where, what, value) from None
    flat = np.asarray(value, dtype=object).ravel() if arr.size else np.zeros(0, object)
    if any(isinstance(v, (bool, np.bool_, str)) for v in flat) or not np.all(np.isfinite(arr)):
        raise _fail(where, what, value)
    return arr


def rows(value: Any, where: str, lo: int, hi: int, columns: tuple[tuple[str, float], ...]) -> np.ndarray:
    """A table of lo..hi rows of finite numbers, one column per (label, bound): each within ±bound."""
    labels = ", ".join(c for c, _ in columns)
    limits = ", ".join(f"{c} within ±{b:g}" for c, b in columns)
    what = f"a list of {lo} to {hi} [{labels}] rows ({limits})"
    arr = table(value, where, what)
    if arr.ndim != 2 or arr.shape[1] != len(columns) or not lo <= len(arr) <= hi:
        raise _fail(where, what, value)
    if not np.all(np.abs(arr) <= np.array([b for _, b in columns])[None, :]):
        raise _fail(where, what, value)
    return arr


def point(value: Any, where: str, bound: float = MAX_LENGTH) -> complex:
    """A point [x, y] of finite numbers within ±bound."""
    what = f"a point [x, y] within ±{bound:g}"
    arr = table(value, where, what)
    if arr.shape != (2,) or not np.all(np.abs(arr) <= bound):
        raise _fail(where, what, value)
    return complex(arr[0], arr[1])


def angles(value: Any, where: str, lo: int = 1, hi: int = 10_000) -> np.ndarray:
    """A list of lo..hi angles [rad] within ±MAX_ANGLE."""
    what = f"a list of {lo} to {hi} angles [rad] within ±{MAX_ANGLE:g}"
    arr = table(value, where, what)
    if arr.ndim != 1 or not lo <= len(arr) <= hi or not np.all(np.abs(arr) <= MAX_ANGLE):
        raise _fail(where, what, value)
    return arr


def choice(value: Any, where: str, choices: tuple[str, ...]) -> str:
    if not isinstance(value, str) or value not in choices:
        raise _fail(where, f"one of {', '.join(choices)}", value)
    return value


def name(value: Any, where: str = "name") -> str:
    """A name-like string (it becomes file names NAME_k.toml inside the output folder: never a path)."""
    problem = name_problem(value)
    if problem:
        raise SynthesisError(f"{where}: {problem}", entry=where)
    return value


def text(value: Any, where: str) -> str:
    """A short string without control characters (units, titles)."""
    if not isinstance(value, str) or len(value) > 200 or any(ord(ch) < 32 or ord(ch) == 127 for ch in value):
        raise _fail(where, "a string of at most 200 printable characters", value)
    return value


def function_of_x(value: Any, where: str = "f") -> Callable[[np.ndarray], np.ndarray]:
    """f as text (parsed, never run) or a Python callable."""
    from .expression import parse

    if isinstance(value, str):
        return parse(value)
    if not callable(value):
        raise _fail(where, "an expression in x (text) or a function of an array", value)
    return value


def requirements(value: Any, where: str = "requirements") -> Any:
    from .defects import Requirements

    if value is None:
        return None
    if not isinstance(value, Requirements):
        raise _fail(where, "a vloop.synthesis.Requirements", value)
    number(value.min_transmission, f"{where}.min_transmission", 0.0, math.pi / 2)
    if value.min_transmission >= math.pi / 2:
        raise _fail(f"{where}.min_transmission", "a number from 0 to below π/2", value.min_transmission)
    if value.pivots is not None:
        pivots(value.pivots, f"{where}.pivots")
    if value.links is not None:
        links(value.links, f"{where}.links")
    return value


def pivots(value: Any, where: str = "pivots") -> tuple[float, float, float, float]:
    """A region [xmin, ymin, xmax, ymax] (min < max) within ±MAX_LENGTH."""
    what = f"[xmin, ymin, xmax, ymax] with min < max, within ±{MAX_LENGTH:g}"
    box = table(value, where, what)
    if box.shape != (4,) or not np.all(np.abs(box) <= MAX_LENGTH) or not (box[0] < box[2] and box[1] < box[3]):
        raise _fail(where, what, value)
    return tuple(float(v) for v in box)  # type: ignore[return-value]


def links(value: Any, where: str = "links") -> tuple[float, float]:
    """A range of link lengths [min, max], 0 < min < max ≤ MAX_LENGTH."""
    what = f"[min, max] link lengths with 0 < min < max ≤ {MAX_LENGTH:g}"
    rng = table(value, where, what)
    if rng.shape != (2,) or not (0 < rng[0] < rng[1] <= MAX_LENGTH):
        raise _fail(where, what, value)
    return float(rng[0]), float(rng[1])


def common(name_: Any, units: Any, requirements_: Any) -> None:
    """The arguments every synthesis function takes."""
    name(name_)
    text(units, "units")
    requirements(requirements_)
