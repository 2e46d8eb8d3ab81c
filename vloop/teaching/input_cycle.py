"""One cycle of the input: dead centres, toggles, time ratio, stroke, transmission-angle extremes.

The mechanism is re-solved (public ``vloop.compile``/``vloop.solve``) with its one driver moving at
unit rate from its t = 0 value, on the file's assembly branch: over one turn for a crank that turns
fully, else over its feasible range (``vloop.sweep.feasible_range``: the input's limit positions,
found by the solver's bisection), walking both ways from t = 0. The time of a unit-rate walk is the
input's travel, so every search works on input values.

* **Dead centres of an output** (a link's ω or a slider's v is zero: its extreme positions, where
  the input cannot move it and it cannot drive the input): sign changes of the output's rate on a
  ``samples``-per-cycle grid, each bracket narrowed by re-solving 32 equally spaced inputs inside
  it until it is shorter than ``TOL`` of the input's range (bisection in 32nds), then the zero of
  the rate's straight line across the last bracket. A rate that touches zero without changing
  sign (a double root) between two grid samples is not found.
* **Toggles of the input** (a dyad's transmission angle 0° or 180°: the input cannot go further):
  the ends of a limited input's feasible range, with the dyad that folds there.
* **Time ratio** (quick-return ratio) of an output with two dead centres per crank turn: the crank
  angles of its two strokes, Δ and 2π − Δ, give slow/quick = max/min >= 1 at constant crank speed.
* **Stroke** of a slider (and swing of a rocker): max − min of its s (θ) over the cycle, from its
  dead centres (and the ends of a limited range). None for a link that turns fully.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..drivers import evaluate
from ..errors import MechanismError, MotionError
from ..model import Mechanism
from ..result import Result
from . import _motion
from .ratios import default_outputs, output_rate_column
from .transmission import Dyad, dyads, raw_angle

TOL = 1e-12  # dead centres located to this fraction of the input's range
SECTIONS = 32  # a bracket is cut in this many parts per re-solve
ZOOMS = 5  # extremes of the transmission angle: zooming re-solves around the best sample


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
    (>= 1) and the sense (+1/−1) of the output's motion during the slow stroke."""

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
    try:
        res = solve(system)
        end = float(grid[-1])
    except MotionError as exc:  # a limit before the end: keep what assembled, end where the solver bisected it
        if not partial or exc.partial is None or len(exc.partial) < 2:
            raise
        res = exc.partial
        end = abs(exc.limit_value[0] - x0) if exc.limit_value is not None else float(res.t[-1])
    return _Walk(system, x0, sense, res.t.copy(), res, max(end, float(res.t[-1])))


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


def _refine_zero(mech: Mechanism, walk: _Walk, output: str, a: float, b: float, tol: float) -> tuple[float, float]:
    """Travel where the output's rate vanishes in [a, b] (rate changes sign there), and the output's value."""
    while True:
        pts = np.linspace(a, b, SECTIONS + 1)
        res = walk.solve(pts)
        r = _rate(mech, res, output)
        v = _value(mech, res, output)
        change = np.flatnonzero(np.sign(r[:-1]) != np.sign(r[1:]))
        if not change.size or r[change[0]] == 0:  # an exact zero, or round-off hid the sign change
            k = int(np.argmin(np.abs(r)))
            return float(pts[k]), float(v[k])
        k = int(change[0])
        a, b = float(pts[k]), float(pts[k + 1])
        if b - a <= tol:
            f = r[k] / (r[k] - r[k + 1])  # the rate's straight line across the bracket
            return a + f * (b - a), float(v[k] + f * (v[k + 1] - v[k]))


def _rests(mech: Mechanism, walk: _Walk, output: str, tol: float, skip_last: bool) -> list[Rest]:
    r = _rate(mech, walk.result, output)
    g = walk.grid
    out: list[Rest] = []
    last = len(r) - (2 if skip_last else 1)
    for k in range(len(r) - 1):
        if r[k] == 0:
            out.append(Rest(output, float(walk.input(g[k])), float(_value(mech, walk.result, output)[k])))
        elif r[k + 1] != 0 and (r[k] > 0) != (r[k + 1] > 0):
            travel, value = _refine_zero(mech, walk, output, g[k], g[k + 1], tol)
            out.append(Rest(output, float(walk.input(travel)), value))
    if not skip_last and r[last] == 0:
        out.append(Rest(output, float(walk.input(g[last])), float(_value(mech, walk.result, output)[last])))
    return out


def dead_centres(mech: Mechanism, outputs: list[str] | None = None, *, samples: int = 720) -> list[Rest]:
    """Inputs [rad or length] where each output's rate is zero over the input's cycle (module docstring).

    ``outputs``: links or sliders (default: every slider and every undriven link pivoted on the ground).
    """
    return [r for oc in cycle(mech, outputs, samples=samples).outputs.values() for r in oc.rests]


def _output_cycle(mech: Mechanism, walks: list[_Walk], output: str, full: bool, span: float) -> OutputCycle:
    tol = TOL * span
    rests = sorted(
        (r for w in walks for r in _rests(mech, w, output, tol, skip_last=full)), key=lambda r: r.input
    )  # fmt: skip
    values = [r.value for r in rests] + [float(_value(mech, w.result, output)[i]) for w in walks for i in (0, -1)]
    turns = output in mech.links and full and abs(values[-1] - values[-2]) > math.pi
    travel = None if turns else max(values) - min(values)
    ratio, sense = None, 0
    if full and len(rests) == 2:
        d1 = rests[1].input - rests[0].input  # the stroke from rest 0 to rest 1; the other takes 2π − d1
        d2 = 2 * math.pi - d1
        ratio = max(d1, d2) / min(d1, d2)
        rise = rests[1].value - rests[0].value
        sense = int(np.sign(rise if d1 >= d2 else -rise))
    return OutputCycle(output, tuple(rests), travel, ratio, sense)


def _folded(mech: Mechanism, res: Result, dyad: Dyad) -> np.ndarray:
    raw = raw_angle(mech, res, dyad)
    return np.minimum(raw, np.pi - raw)


def _zoom(mech: Mechanism, walk: _Walk, dyad: Dyad, pick: Any) -> tuple[float, float]:
    """(folded μ, travel) at the extreme ``pick`` (np.argmin/np.argmax) of a dyad's μ along a walk."""
    g = walk.grid
    mu = _folded(mech, walk.result, dyad)
    k = int(pick(mu))
    best, at = float(mu[k]), float(g[k])
    lo, hi = g[max(k - 1, 0)], g[min(k + 1, len(g) - 1)]
    for _ in range(ZOOMS):
        if hi <= lo:
            break
        pts = np.linspace(lo, hi, SECTIONS + 1)
        m = _folded(mech, walk.solve(pts), dyad)
        j = int(pick(m))
        if pick([best, m[j]]) == 1:
            best, at = float(m[j]), float(pts[j])
        lo, hi = pts[max(j - 1, 0)], pts[min(j + 1, SECTIONS)]
    return best, at


def _dyad_cycle(mech: Mechanism, walks: list[_Walk], dyad: Dyad) -> DyadCycle:
    lows = [(*_zoom(mech, w, dyad, np.argmin), w) for w in walks]
    highs = [(*_zoom(mech, w, dyad, np.argmax), w) for w in walks]
    mn = min(lows, key=lambda x: x[0])
    mx = max(highs, key=lambda x: x[0])
    return DyadCycle(dyad, mn[0], float(mn[2].input(mn[1])), mx[0], float(mx[2].input(mx[1])))


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
    dcs = [_dyad_cycle(mech, walks, d) for d in found]
    toggles = [] if full else sorted((_toggle(mech, w, found) for w in walks), key=lambda tg: tg.input)
    for w in [] if full else walks:  # the range the walks reached (the solver's own limits where it stopped)
        lo, hi = (lo, float(w.input(w.end))) if w.sense > 0 else (float(w.input(w.end)), hi)
    return Cycle(mech.drivers[0].symbol, full, lo, hi, outs, dcs, toggles, notes)


def _toggle(mech: Mechanism, walk: _Walk, found: list[Dyad]) -> Toggle:
    """The end of a limited walk, with the dyad whose folded transmission angle is smallest there."""
    res = _rows(walk.result, len(walk.result.t) - 1)
    if walk.end > walk.grid[-1]:
        try:
            # at the limit itself the rates are unresolvable (a toggle), the positions are not: accept it
            res = walk.solve(np.array([walk.end]), rtol=math.inf)
        except MotionError:
            pass
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
