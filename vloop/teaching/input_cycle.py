"""One cycle of the input: dead centres, toggles, time ratio, stroke, transmission-angle extremes.

The mechanism is re-solved (public ``vloop.compile``/``vloop.solve``) with its one driver moving at
unit rate from its t = 0 value, on the file's assembly branch: over one turn for a crank that turns
fully, else over its feasible range (``vloop.sweep.feasible_range``: the input's limit positions,
found by the solver's bisection to 1e-12 of the range), walking both ways from t = 0. The time of a
unit-rate walk is the input's travel, so every search works on input values. Every extreme is taken
where it is located, never at a grid sample:

* **Dead centres of an output** (a link's ω or a slider's v is zero: its extreme positions, where
  the input cannot move it and it cannot drive the input): sign changes of the output's rate on a
  ``samples``-per-cycle grid, each bracket narrowed by re-solving 32 equally spaced inputs inside
  it until it is shorter than ``TOL`` of the input's range (bisection in 32nds), then the zero of
  the rate's straight line across the last bracket. Where the rate vanishes to a higher order (an
  upstream link or slider rests at the same input) the upstream rest, a simple zero, places it
  (:func:`_settle`). A rate that touches zero without changing sign (a double root) between two
  grid samples is not found.
* **Toggles of the input** (a dyad's transmission angle 0° or 180°: the input cannot go further):
  the ends of a limited input's feasible range, with the dyad that folds there. The configuration
  at a toggle is the mean of the folding loop's two assembly branches at the located limit
  (:func:`_end`): exact to the limit's location, where each branch alone is off by its square root.
* **Transmission-angle extremes** of each dyad: where the raw angle's rate vanishes, where it
  crosses 90° (the folded angle's peak), and at the ends of the walks (the toggles).
* **Time ratio** (quick-return ratio) of an output with two dead centres per crank turn: the crank
  angles of its two strokes, Δ and 2π − Δ, give slow/quick = max/min >= 1 at constant crank speed;
  the slow stroke's sense is that of the output as the crank turns the way the file drives it
  (clockwise for ω < 0).
* **Stroke** of a slider (and swing of a rocker): max − min of its s (θ) over the cycle, from its
  dead centres and the ends of the walks (the toggles of a limited range). None for a link that
  turns fully.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..drivers import evaluate
from ..errors import MechanismError, MotionError
from ..model import Mechanism
from ..result import Result
from . import _motion
from .ratios import default_outputs, output_rate_column
from .transmission import Dyad, dyads, raw_angle, raw_rate

TOL = 1e-12  # dead centres located to this fraction of the input's range
SECTIONS = 32  # a bracket is cut in this many parts per re-solve
ROUND_OFF = 1e-12  # a transmission angle [rad] (or its rate per unit of input) this close to 90° (0) stays there


@dataclass(frozen=True)
class Rest:
    """An output at rest (a dead centre): input value [rad or length], output θ [rad] or s [length]."""

    output: str
    input: float
    value: float


@dataclass(frozen=True)
class OutputCycle:
    """An output over the cycle: its dead centres, its travel (stroke of a slider [length], swing of a
    link [rad]; None if it turns fully), and for a full-turn crank with two dead centres the time ratio
    (>= 1) and the sense (+1/−1) of the output's motion during the slow stroke, the crank turning the way
    the file drives it (:func:`turn_sense`)."""

    name: str
    rests: tuple[Rest, ...]
    travel: float | None
    time_ratio: float | None = None
    slow_sense: int = 0


@dataclass(frozen=True)
class DyadCycle:
    """A dyad's folded transmission angle over the cycle: min and max [rad] and the inputs there."""

    dyad: Dyad
    min: float
    min_input: float
    max: float
    max_input: float


@dataclass(frozen=True)
class Toggle:
    """An end of a limited input's range: the input value and the dyad that folds there (μ ≈ 0)."""

    input: float
    dyad: str
    folded: float | None


@dataclass(frozen=True)
class Cycle:
    """The input's cycle (module docstring). ``lower``/``upper``: the input's range [rad or length]."""

    driver: str
    full_turn: bool
    lower: float
    upper: float
    outputs: dict[str, OutputCycle]
    dyads: list[DyadCycle]
    toggles: list[Toggle]
    notes: list[str]


@dataclass
class _Walk:
    """The input moving at unit rate from x0 in one sense; time = travel of the input."""

    system: Any
    x0: float
    sense: float
    grid: np.ndarray  # travels of the coarse samples
    result: Result
    end: float  # travel to the end of the walk: the last grid sample, or the limit the solver located
    folds: int | None = None  # the loop that cannot close past the limit (None: no limit)
    cache: dict = dataclasses.field(default_factory=dict, repr=False)

    def solve(self, travel: np.ndarray, **options: Any) -> Result:
        """The walk re-solved at these increasing travels (walking in over the coarse grid below them)."""
        from .. import solve

        lead = self.grid[self.grid < travel[0]]
        res = solve(self.system, times=np.concatenate([lead, travel]), **options)
        return _rows(res, len(lead))

    def input(self, travel: np.ndarray | float) -> Any:
        return self.x0 + self.sense * np.asarray(travel)


def _rows(res: Result, start: int) -> Result:
    return Result(
        res.mechanism, res.engine, res.t[start:], {k: v[start:] for k, v in res.columns.items()}, {}, dict(res.meta)
    )


def _walk(mech: Mechanism, x0: float, sense: float, span: float, steps: int, partial: bool = True) -> _Walk | None:
    from .. import compile, solve

    if span <= 0:
        return None
    driver = dataclasses.replace(mech.drivers[0], x0=x0, v0=sense, a0=0.0, profile=None)
    grid = np.linspace(0.0, span, max(steps, 16) + 1)
    walked = dataclasses.replace(mech, drivers=(driver,), times=grid)
    system = compile(walked)
    folds = None
    try:
        res = solve(system)
        end = float(grid[-1])
    except MotionError as exc:  # a limit before the end: keep what assembled, end where the solver bisected it
        if not partial or exc.partial is None or len(exc.partial) < 2:
            raise
        res = exc.partial
        end = abs(exc.limit_value[0] - x0) if exc.limit_value is not None else float(res.t[-1])
        if exc.limit_value is not None and str(exc.entry).startswith("loop "):
            folds = int(str(exc.entry).split()[1]) - 1
    return _Walk(system, x0, sense, res.t.copy(), res, max(end, float(res.t[-1])), folds)


def _walks(mech: Mechanism, samples: int) -> tuple[list[_Walk], float, float, bool]:
    """Unit-rate walks over the input's cycle: one turn of a crank that turns fully, else both ways
    from the t = 0 value to the limits of the feasible range. Returns (walks, lower, upper, full_turn)."""
    from ..sweep import feasible_range

    d = mech.drivers[0]
    x0 = float(evaluate(d, np.zeros(1))[0][0])
    if d.kind == "crank":
        try:
            turn = _walk(mech, x0, 1.0, 2 * math.pi, samples, partial=False)
        except MotionError:
            pass
        else:
            return [turn], x0, x0 + 2 * math.pi, True  # type: ignore[list-item]
    lo, hi, _ = feasible_range(mech)
    walks = []
    for sense, travel in ((1.0, hi - x0), (-1.0, x0 - lo)):
        w = _walk(mech, x0, sense, travel, math.ceil(samples * travel / (hi - lo)))
        if w is not None:
            walks.append(w)
    return walks, lo, hi, False


def _rate(mech: Mechanism, res: Result, output: str) -> np.ndarray:
    return res[output_rate_column(mech, output)]


def _value(mech: Mechanism, res: Result, output: str) -> np.ndarray:
    return res[f"{output}.s"] if output in mech.sliders else res[f"{output}.theta"]


def _zero(walk: _Walk, f: Callable[[Result], np.ndarray], a: float, b: float, tol: float) -> float:
    """Travel in [a, b] where ``f`` (a quantity of a Result) changes sign: the bracket re-solved at 32 equal parts
    until it is shorter than ``tol``, then the zero of f's straight line across it."""
    while True:
        pts = np.linspace(a, b, SECTIONS + 1)
        r = f(walk.solve(pts))
        change = np.flatnonzero(np.sign(r[:-1]) != np.sign(r[1:]))
        if not change.size or r[change[0]] == 0:  # an exact zero, or round-off hid the sign change
            return float(pts[int(np.argmin(np.abs(r)))])
        k = int(change[0])
        a, b = float(pts[k]), float(pts[k + 1])
        if b - a <= tol:
            return a + r[k] / (r[k] - r[k + 1]) * (b - a)


def _zeros(
    mech: Mechanism,
    walk: _Walk,
    f: Callable[[Result], np.ndarray],
    tol: float,
    skip_last: bool,
    upstream: list[str],
    floor: float = 0.0,
) -> list[float]:
    """Travels where ``f`` vanishes along a walk: its exact zeros on the grid and its located sign changes (each
    settled on an ``upstream`` link's or slider's rest where the zero is multiple: :func:`_settle`). Sign changes
    between two samples both within ``floor`` of zero are round-off of a quantity that stays at zero (a
    transmission angle of 90° throughout): no zero."""
    r, g = f(walk.result), walk.grid
    out = []
    for k in range(len(r) - 1):
        if r[k] == 0 and floor == 0:
            out.append(float(g[k]))
        elif max(abs(r[k]), abs(r[k + 1])) <= floor:
            continue
        elif r[k + 1] != 0 and (r[k] > 0) != (r[k + 1] > 0):
            out.append(_settle(mech, walk, f, _zero(walk, f, g[k], g[k + 1], tol), upstream, tol))
    if not skip_last and len(r) and r[-1] == 0 and floor == 0:
        out.append(float(g[len(r) - 1]))
    return out


def _upstream(system: Any, bodies: list[str]) -> list[str]:
    """The links and sliders that the blocks solving ``bodies`` take from earlier blocks, transitively (the
    drivers and the bodies' own blocks left out)."""
    na = system.n_angles
    names = list(system.angle_links) + list(system.slider_names)
    todo = [system.angle_links.index(b) if b in system.angle_links else na + names[na:].index(b) for b in bodies]
    block_of = {v: b for b in system.blocks for v in b.unknowns}
    seen: set[int] = set()
    own = {v for v in todo}
    while todo:
        b = block_of.get(todo.pop())
        for v in () if b is None else {w for li in b.loops for w in system.loops[li].variables}:
            if v not in b.unknowns and v not in system.drivers and v not in seen:
                seen.add(v)
                todo.append(v)
    return [names[v] for v in sorted(seen - own)]


def _settle(
    mech: Mechanism, walk: _Walk, f: Callable[[Result], np.ndarray], z: float, upstream: list[str], tol: float
) -> float:
    """A zero of ``f`` (an output's rate, a transmission angle's rate) that is multiple lies where a link or slider
    upstream rests. ``f`` is then a product of the quantity's own coefficient and the upstream rates, and where a
    factor of each vanishes at once (the eight-bar's rods stand upright as l4 rests) it falls like the square or
    cube of the distance: its sign is round-off within ~√ε of the zero. The upstream rate's simple zero is
    located to round-off: take the nearest. A simple zero (|f| doubles with the distance), one near an end of the
    walk or one with no upstream rest around it is kept as found."""
    h = (walk.grid[1] - walk.grid[0]) / SECTIONS
    pts = z + h * np.array([-2.0, -1.0, 1.0, 2.0])
    if not upstream or pts[0] < walk.grid[0] or pts[-1] > walk.grid[len(walk.result.t) - 1]:
        return z
    res = walk.solve(pts)
    r = np.abs(f(res))
    if not np.all(r > 0) or min(r[0] / r[1], r[3] / r[2]) < 3.0:  # simple: 2; double 4, triple 8
        return z
    found = []
    for u in upstream:
        ru = _rate(mech, res, u)
        if (ru[0] > 0) != (ru[-1] > 0) and ru[0] != 0 and ru[-1] != 0:
            found.append(_zero(walk, lambda res, u=u: _rate(mech, res, u), pts[0], pts[-1], tol))
    return min(found, key=lambda x: abs(x - z)) if found else z


def _rests(mech: Mechanism, walk: _Walk, output: str, tol: float, skip_last: bool) -> list[Rest]:
    """The output's dead centres along a walk (zeros of its rate), with its value there."""
    rate = lambda res: _rate(mech, res, output)  # noqa: E731
    travels = _zeros(mech, walk, rate, tol, skip_last, _upstream(walk.system, [output]))
    if not travels:
        return []
    at = _positions(walk, travels)
    return [Rest(output, float(walk.input(x)), float(_value(mech, at, output)[i])) for i, x in enumerate(travels)]


def _positions(walk: _Walk, travels: list[float]) -> Result:
    """The walk's configurations at these travels, in the order given (positions; rates where resolvable)."""
    order = np.unique(travels)
    res = walk.solve(order, rtol=math.inf)
    return _rows_at(res, np.searchsorted(order, travels))


def _rows_at(res: Result, rows: Any) -> Result:
    return Result(
        res.mechanism, res.engine, res.t[rows], {k: v[rows] for k, v in res.columns.items()}, {}, dict(res.meta)
    )


def _end(walk: _Walk) -> Result:
    """The walk's configuration at its end (one row): its last grid sample, or at the limit the solver located.
    There the loop that folds has its two assembly branches within O(√Δx) of the toggle (Δx: the limit's
    location, ~1e-12 of the range) and their mean within O(Δx): the mean of the two, where the other branch
    can be solved, else the last assemblable position (within O(√Δx))."""
    if "end" in walk.cache:
        return walk.cache["end"]
    last = _rows(walk.result, len(walk.result.t) - 1)
    out = last
    if walk.end > walk.grid[-1]:
        try:
            out = walk.solve(np.array([walk.end]), rtol=math.inf)
            other = _other_branch(walk)
            if other is not None:
                out = _mean_configuration(out, other.solve(np.array([walk.end]), rtol=math.inf))
        except (MotionError, MechanismError):
            pass
    walk.cache["end"] = out
    return out


BRANCH_OTHER = {"flip": "keep", "keep": "flip", "open": "crossed", "crossed": "open"}


def _other_branch(walk: _Walk) -> _Walk | None:
    """The same walk with the folding loop on its other assembly branch (None if that loop has no two)."""
    from .. import compile

    if walk.folds is None or not any(
        b.loops == (walk.folds,) and b.kind in ("RRR", "RRP", "RPR") for b in walk.system.blocks
    ):
        return None
    mech = walk.system.mechanism
    asked = dict(mech.options.get("branches") or {})
    asked[walk.folds + 1] = BRANCH_OTHER.get(asked.get(walk.folds + 1, "keep"), "flip")
    flipped = dataclasses.replace(mech, options={**mech.options, "branches": asked})
    return dataclasses.replace(walk, system=compile(flipped), cache={})


def _mean_configuration(a: Result, b: Result) -> Result:
    """Positions half-way between two configurations (angles by their shorter arc; rates: a's)."""
    cols = dict(a.columns)
    for k, v in a.columns.items():
        field_ = k.rsplit(".", 1)[-1]
        if field_ == "theta":
            cols[k] = v + np.angle(np.exp(1j * (b[k] - v))) / 2
        elif field_ in ("x", "y", "s"):
            cols[k] = (v + b[k]) / 2
    return Result(a.mechanism, a.engine, a.t, cols, {}, dict(a.meta))


def dead_centres(mech: Mechanism, outputs: list[str] | None = None, *, samples: int = 720) -> list[Rest]:
    """Inputs [rad or length] where each output's rate is zero over the input's cycle (module docstring).

    ``outputs``: links or sliders (default: every slider and every undriven link pivoted on the ground).
    """
    return [r for oc in cycle(mech, outputs, samples=samples).outputs.values() for r in oc.rests]


def turn_sense(mech: Mechanism) -> int:
    """The sense the single driver moves in over the file's run: +1 (θ or s increasing; a crank CCW) or −1,
    from its net travel, else its rate at the first sample, else its acceleration there; +1 if it never moves."""
    x, v, a = evaluate(mech.drivers[0], np.asarray(mech.times, float)[[0, -1]])
    for change in (x[1] - x[0], v[0], a[0]):
        if change != 0 and math.isfinite(change):
            return 1 if change > 0 else -1
    return 1


def _output_cycle(mech: Mechanism, walks: list[_Walk], output: str, full: bool, span: float) -> OutputCycle:
    tol = TOL * span
    rests = sorted(
        (r for w in walks for r in _rests(mech, w, output, tol, skip_last=full)), key=lambda r: r.input
    )  # fmt: skip
    ends = [float(_value(mech, res, output)[0]) for w in walks for res in (_rows(w.result, 0), _end(w))]
    values = [r.value for r in rests] + ends
    turns = output in mech.links and full and abs(values[-1] - values[-2]) > math.pi
    travel = None if turns else max(values) - min(values)
    ratio, sense = None, 0
    if full and len(rests) == 2:
        ccw = rests[1].input - rests[0].input  # counter-clockwise crank travel from rest 0 to rest 1
        there = ccw if turn_sense(mech) > 0 else 2 * math.pi - ccw  # the crank's travel as it turns: 0 → 1
        back = 2 * math.pi - there  # and 1 → 0
        ratio = max(there, back) / min(there, back)
        rise = rests[1].value - rests[0].value  # the output's change from rest 0 to rest 1
        sense = int(np.sign(rise if there >= back else -rise))
    return OutputCycle(output, tuple(rests), travel, ratio, sense)


def _folded(mech: Mechanism, res: Result, dyad: Dyad) -> np.ndarray:
    raw = raw_angle(mech, res, dyad)
    return np.minimum(raw, np.pi - raw)


def _extremes(mech: Mechanism, walk: _Walk, dyad: Dyad, tol: float) -> tuple[Result, list[float]]:
    """Where a dyad's folded transmission angle can be extreme along a walk, and the configurations there: the
    zeros of the raw angle's rate (smooth extremes), its crossings of 90° (the folded angle's peak), the
    walk's start and its end (at a limit: the toggle, μ = 0)."""
    upstream = _upstream(walk.system, list(dyad.bodies))
    unit = 1.0 if mech.drivers[0].kind == "crank" else 1.0 / mech.scale  # a rate of turn per unit of input
    travels = [float(walk.grid[0])]
    travels += _zeros(mech, walk, lambda r: raw_rate(mech, r, dyad), tol, False, upstream, ROUND_OFF * unit)
    travels += _zeros(mech, walk, lambda r: raw_angle(mech, r, dyad) - np.pi / 2, tol, False, upstream, ROUND_OFF)
    inside = _positions(walk, travels)
    end = _end(walk)
    both = Result(
        inside.mechanism, inside.engine, np.append(inside.t, end.t),
        {k: np.append(v, end[k]) for k, v in inside.columns.items()}, {}, {},
    )  # fmt: skip
    return both, [*travels, walk.end]


def _dyad_cycle(mech: Mechanism, walks: list[_Walk], dyad: Dyad, tol: float) -> DyadCycle:
    values, inputs = [], []
    for w in walks:
        res, travels = _extremes(mech, w, dyad, tol)
        values += _folded(mech, res, dyad).tolist()
        inputs += [float(w.input(x)) for x in travels]
    lo, hi = int(np.argmin(values)), int(np.argmax(values))
    return DyadCycle(dyad, values[lo], inputs[lo], values[hi], inputs[hi])


def cycle(mech: Mechanism, outputs: list[str] | None = None, *, samples: int = 720) -> Cycle:
    """Dead centres, strokes, time ratios, toggles, transmission-angle extremes [rad; inputs rad or length].

    One driver only. ``samples``: grid samples per cycle before refinement. Inputs in rad (crank) or
    the file's length (driven slider); module docstring for the definitions.
    """
    _motion.single_driver(mech, "a cycle analysis (dead centres, time ratio, stroke)")
    from .. import compile

    if isinstance(samples, bool) or not isinstance(samples, int) or not 16 <= samples <= 1_000_000:
        raise ValueError(f"samples must be an integer from 16 to 1000000, got {samples!r}")
    outputs = default_outputs(mech) if outputs is None else list(outputs)
    for o in outputs:
        output_rate_column(mech, o)
    walks, lo, hi, full = _walks(mech, samples)
    if not walks:
        raise MechanismError(f"{mech.name}: the input cannot move from its t = 0 value", entry="drivers")
    span = hi - lo
    outs = {o: _output_cycle(mech, walks, o, full, span) for o in outputs}
    found, notes = dyads(compile(mech))
    dcs = [_dyad_cycle(mech, walks, d, TOL * span) for d in found]
    toggles = [] if full else sorted((_toggle(mech, w, found) for w in walks), key=lambda tg: tg.input)
    for w in [] if full else walks:  # the range the walks reached (the solver's own limits where it stopped)
        lo, hi = (lo, float(w.input(w.end))) if w.sense > 0 else (float(w.input(w.end)), hi)
    return Cycle(mech.drivers[0].symbol, full, lo, hi, outs, dcs, toggles, notes)


def _toggle(mech: Mechanism, walk: _Walk, found: list[Dyad]) -> Toggle:
    """The end of a limited walk, with the dyad whose folded transmission angle is smallest there."""
    res = _end(walk)
    at_end = {d.label: float(_folded(mech, res, d)[0]) for d in found}
    label = min(at_end, key=at_end.__getitem__) if at_end else ""
    return Toggle(float(walk.input(walk.end)), label, at_end.get(label))


def time_ratio(mech: Mechanism, output: str, *, samples: int = 720) -> float:
    """Quick-return ratio (slow stroke / quick stroke >= 1) of an output over one crank turn at constant speed."""
    oc = cycle(mech, [output], samples=samples).outputs[output]
    if oc.time_ratio is None:
        raise MechanismError(
            f"{mech.name}: no time ratio for '{output}': it needs a crank that turns fully and an output with two "
            f"dead centres per turn (found {len(oc.rests)})",
            entry="drivers",
        )
    return oc.time_ratio


def stroke(mech: Mechanism, output: str, *, samples: int = 720) -> float:
    """Stroke of a slider [length] (swing of a link [rad]) over the input's cycle: max − min of its s (θ)."""
    oc = cycle(mech, [output], samples=samples).outputs[output]
    if oc.travel is None:
        raise MechanismError(f"{mech.name}: '{output}' turns fully: it has no stroke", entry="outputs")
    return oc.travel
