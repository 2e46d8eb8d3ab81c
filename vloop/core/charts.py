"""A chart of a run's motion over its one input: every variable as a function of the input, on the run's branches.

A linkage with one input x (a crank's θ, a slider's s) that passes no change point has one configuration per
input value on its assembly branches: q = q(x), and for a crank q(x + 2π) = q(x) + w·2π (w: whole turns of each
link per turn of the crank). A run that travels over its input's range many times — many turns, or a rocking
input rocking many times, sampled finely or coarsely — therefore needs the motion's continuation only once: over
one turn of the crank (or the input's range), at rows CHART_STEP apart, checked as the run's own rows are
(limits, toggles, change points: a chart that meets one is not drawn, and the run meets it row after row).

Every sample is then placed on that curve without continuation from its neighbours: a Newton block starts from
the chart's quintic Hermite interpolant in x at the sample's input (:func:`vloop.core.newton.solve_block`), a
closed-form dyad's angles get their whole turns from it (:meth:`Chart.turns`), and no row needs to be inserted
between coarse samples for the turns to be counted or a change point to be seen: the chart has seen the whole
range at its own spacing. Work then grows with the samples, not with the turns between them.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ..errors import MechanismError
from .context import Inputs, Run, impose_drivers, initial_state
from .data import TWO_PI

CHART_STEP = math.radians(3.75)  # a chart's rows are this far apart in its input (rad; sliders: 2π per size)
CHART_TRAVEL = 2.0  # a chart is drawn for a run whose input travels more than this many times the chart's span
CLOSED_TURN = 1e-9  # a crank's one-turn chart closes: every variable back to within this (rad; sizes for sliders)


class ChartMiss(Exception):
    """A row predicted from the chart fails a check of the run (convergence, closure, branch, jump): the chunk is
    solved again without the chart, as if none had been drawn."""


@dataclass
class Chart:
    """Every variable (θ of each rotating link, then s of each slider: columns of ``q``) as a function of the run's
    one input at ascending input values ``x``: positions q, dq/dx and d²q/dx² (each (variables, nodes)). A crank's
    chart covers one turn (``turn`` = 2π) from ``x[0]``: past it, the variables add ``wind`` per turn; another
    input's chart covers [x[0], x[-1]] only."""

    x: np.ndarray
    q: np.ndarray
    dq: np.ndarray
    ddq: np.ndarray
    turn: float
    wind: np.ndarray
    unit: np.ndarray  # per variable: what a move is measured in (angles: rad; sliders: 2π per mechanism size)

    def covers(self, x: np.ndarray) -> bool:
        """Whether every input value of ``x`` lies on the chart."""
        return bool(self.turn) or bool(len(x) == 0 or (self.x[0] <= np.min(x) and np.max(x) <= self.x[-1]))

    def predict(self, x: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Variables ``cols`` at inputs ``x`` by the quintic Hermite interpolant in x: (len(cols), len(x)); and the
        move of those variables across the chart's interval each input falls in (largest component, in ``unit``):
        what a Newton correction from the prediction is measured against."""
        turns = np.floor((x - self.x[0]) / self.turn) if self.turn else np.zeros(len(x))
        xs = x - turns * self.turn
        j = np.clip(np.searchsorted(self.x, xs, side="right") - 1, 0, len(self.x) - 2)
        pred = hermite(self.x, self.q[cols], self.dq[cols], self.ddq[cols], xs, j, ordered=False)
        if self.turn:
            pred += self.wind[cols][:, None] * turns
        return pred, interval_moves(self.q[cols], self.unit[cols])[j]

    def steep(self, step: float) -> np.ndarray:
        """The angle columns that could turn by π/2 or more while the input moves ``step`` (their largest rate
        dθ/dx at the chart's rows, taken twice for what lies between them): only those need their turns counted
        from the chart (:meth:`turns`); the others' rows lie too close for the count from row to row (which takes
        the change between two rows to be less than π) to err."""
        angles = np.nonzero(self.unit == 1.0)[0]
        rate = 2.0 * np.max(np.abs(self.dq[angles]), axis=1, initial=0.0)
        return angles[~(rate * step < 0.5 * math.pi)]

    def turns(self, theta: np.ndarray, x: np.ndarray, col: int) -> np.ndarray:
        """Whole turns [rad] to add to angle ``col``'s values ``theta`` at inputs ``x`` so that each lies within π
        of the chart's angle there: the turns counted along the continuous motion, however far apart the rows.
        (The chart's angle between its rows by straight lines: off by at most (3.75°)²/8 times its second
        derivative, far less than π.)"""
        turns = np.floor((x - self.x[0]) / self.turn) if self.turn else np.zeros(len(x))
        pred = np.interp(x - turns * self.turn, self.x, self.q[col]) + self.wind[col] * turns
        return TWO_PI * np.round((pred - theta) / TWO_PI)


def interval_moves(xc: np.ndarray, unit: np.ndarray) -> np.ndarray:
    """The move across each interval between nodes whose positions are xc (variables, nodes): its largest
    component measured in ``unit`` (per variable: angles 1 (rad), sliders 2π per mechanism size), plus a floor at
    round-off of the positions."""
    unit = unit[:, None]
    with np.errstate(invalid="ignore"):
        move = np.max(np.abs(np.diff(xc, axis=1)) * unit, axis=0)
        move += 1e-9 * (1.0 + np.max(np.abs(xc[:, :-1]) * unit, axis=0))
    return move


def hermite(
    tc: np.ndarray, xc: np.ndarray, v: np.ndarray, acc: np.ndarray, t: np.ndarray, j: np.ndarray, ordered: bool
) -> np.ndarray:
    """The quintic Hermite interpolant through positions xc, rates v and accelerations acc at nodes tc (each
    (n, nodes), batch-last) at the abscissae t, each in interval j (tc[j] ≤ t ≤ tc[j + 1]): (n, len(t)), error
    ~ interval⁶. The coefficients in u (0..1 across an interval) are taken once per interval; each abscissa
    gathers them and runs Horner (``ordered``: t sorted by interval, the coefficients repeated, not gathered)."""
    H = tc[1:] - tc[:-1]
    xa, xb = xc[:, :-1], xc[:, 1:]
    va, vb = v[:, :-1] * H, v[:, 1:] * H  # rates and accelerations in units of the interval
    aa, ab = acc[:, :-1] * (H * H), acc[:, 1:] * (H * H)
    d = xb - xa
    C = np.stack(
        [
            xa,
            va,
            0.5 * aa,
            10 * d - 6 * va - 4 * vb - 1.5 * aa + 0.5 * ab,
            -15 * d + 8 * va + 7 * vb + 1.5 * aa - ab,
            6 * d - 3 * va - 3 * vb - 0.5 * aa + 0.5 * ab,
        ]
    )
    # each interval's coefficients repeated over its abscissae (contiguous: ~5× faster arithmetic after)
    C = np.repeat(C, np.bincount(j, minlength=len(H)), axis=2) if ordered else np.take(C, j, axis=2)
    u = (t - tc[j]) / H[j]
    pred = C[5] * u
    for power in range(4, 0, -1):
        pred += C[power]
        pred *= u
    pred += C[0]
    return pred


@dataclass(frozen=True)
class Travel:
    """How a run's one input moves over the run: its least and largest value, and how far it travels in all."""

    lo: float
    hi: float
    travel: float
    samples: int


def input_travel(run: Run, times: np.ndarray) -> Travel | None:
    """The :class:`Travel` of the run's one input over ``times`` and at t = 0 (None with several inputs, or an
    input that cannot be evaluated there). A driver's polynomial has at most one turning point; a profile is taken
    at its own rows between the run's ends (its interpolant may overshoot them slightly: a chunk whose inputs the
    chart does not cover is solved without it)."""
    mech = run.system.mechanism
    if len(mech.drivers) != 1:
        return None
    d = mech.drivers[0]
    t0, t1 = float(times[0]), float(times[-1])
    if d.profile is None:
        ts = [0.0, t0, t1] + ([-d.v0 / d.a0] if d.a0 and t0 < -d.v0 / d.a0 < t1 else [])
        x = [d.x0 + d.v0 * t + 0.5 * d.a0 * t * t for t in ts]
        path = abs(x[1] - x[3]) + abs(x[3] - x[2]) if len(x) > 3 else abs(x[2] - x[1])
        return Travel(min(x), max(x), path, len(times))
    rows = d.profile.t
    ts = np.concatenate([[t0], rows[(rows > t0) & (rows < t1)], [t1]])
    try:
        x = Inputs(mech)(np.concatenate([[0.0], ts]))[0][:, 0]
    except MechanismError:
        return None
    return Travel(float(np.min(x)), float(np.max(x)), float(np.sum(np.abs(np.diff(x[1:])))), len(times))


def worth_drawing(run: Run, trip: Travel | None, min_step: float) -> bool:
    """Whether a chart saves work: the input travels over its range more than CHART_TRAVEL times, and (where
    ``min_step`` > 0) moves on average at least ``min_step`` per sample (rad; sliders: 2π per size)."""
    if trip is None:
        return False
    crank = run.system.mechanism.drivers[0].kind == "crank"
    unit = 1.0 if crank else TWO_PI / run.scale
    span = (TWO_PI if crank and trip.hi - trip.lo >= TWO_PI else trip.hi - trip.lo) * unit
    travel = trip.travel * unit
    return span > 0 and travel > CHART_TRAVEL * span and travel >= min_step * max(trip.samples - 1, 1)


def draw(run: Run, trip: Travel) -> Chart | None:
    """The run's chart from its t = 0 assembly (:class:`Chart`): one turn of a crank whose input spans a turn,
    else up from the input's value at t = 0 to ``trip.hi`` and down to ``trip.lo``; None where it cannot be drawn
    on the t = 0 branches (a limit, a toggle or a change point on the way, a turn that does not close). Kept with
    the LoopSystem (as its plans are): another run of it over the same range, with the same tolerances, takes the
    same chart."""
    crank = run.system.mechanism.drivers[0].kind == "crank"
    turn = TWO_PI if crank and trip.hi - trip.lo >= TWO_PI else 0.0
    key = (turn or (trip.lo, trip.hi), run.tol, run.max_iter, run.rtol)
    kept = run.system.cache.setdefault("charts", {})
    if key not in kept:
        if len(kept) >= 8:
            kept.clear()
        kept[key] = _draw(run, trip, turn)
    return kept[key]


def _draw(run: Run, trip: Travel, turn: float) -> Chart | None:
    """:func:`draw`, drawn."""
    system = run.system
    na = system.n_angles
    x0 = float(Inputs(system.mechanism)(np.zeros(1))[0][0, 0])
    legs = [_leg(run, x0, turn)] if turn else [_leg(run, x0, d) for d in (trip.lo - x0, trip.hi - x0) if d]
    if not legs or any(leg is None for leg in legs):
        return None
    unit = np.concatenate([np.ones(na), np.full(len(system.slider_names), TWO_PI / run.scale)])
    wind = np.zeros(len(unit))
    if turn:
        (leg,) = legs
        gain = leg[1][:, -1] - leg[1][:, 0]
        wind[:na] = TWO_PI * np.round(gain[:na] / TWO_PI)
        if not np.all(np.abs(gain - wind) * np.where(unit == 1.0, 1.0, 1.0 / run.scale) <= CLOSED_TURN):
            return None  # one turn does not bring the mechanism back (a double turn, or another circuit)
    else:
        legs = [tuple(a[..., ::-1] for a in leg) if leg[0][-1] < leg[0][0] else leg for leg in legs]
        legs.sort(key=lambda leg: float(leg[0][0]))
        if len(legs) == 2:  # the value at t = 0 ends one leg and starts the other
            legs[1] = tuple(a[..., 1:] for a in legs[1])
    x, q, dq, ddq = (np.concatenate([leg[k] for leg in legs], axis=-1) for k in range(4))
    return Chart(x, q, dq, ddq, turn, wind, unit)


def _leg(run: Run, x0: float, travel: float) -> tuple[np.ndarray, ...] | None:
    """Every block continued from the t = 0 assembly along the input from x0 to x0 + travel, rows CHART_STEP apart,
    checked as a run's rows are: (x, q, dq/dx, d²q/dx²), or None if a row cannot be solved or a change point is
    passed."""
    system = run.system
    na = system.n_angles
    unit = 1.0 if system.mechanism.drivers[0].kind == "crank" else TWO_PI / run.scale
    m = max(8, math.ceil(abs(travel) * unit / CHART_STEP)) + 1
    u = np.linspace(0.0, 1.0, m)
    inputs = Inputs(system.mechanism, math.inf, 0.0, 1.0, np.array([x0]), np.array([travel]))
    sub = dataclasses.replace(run, inputs=inputs, events={}, tail=True, sink=None, chart=None, t_start=0.0)
    trial = initial_state(system, m)
    impose_drivers(system, trial, *inputs(u))
    solved = sub.blocks(sub, trial, u, m)
    if solved.n_ok < m or any(sub.events.values()):
        return None
    q = np.concatenate([trial.theta.T, trial.s[:, :-1].T])
    dq = np.concatenate([trial.omega[:, :na].T, trial.s_dot[:, :-1].T]) / travel
    ddq = np.concatenate([trial.alpha[:, :na].T, trial.s_ddot[:, :-1].T]) / (travel * travel)
    return x0 + travel * u, q, dq, ddq
