"""A run: position, velocity and acceleration of a compiled system over time (``solve``, ``solve_iter``).

The state (:mod:`vloop.core.data`) is filled over an internal grid (:mod:`vloop.core.grid`: the requested
times, rows inserted where an input moves far, and a lead-in path from the t = 0 assembly when the first
requested time is not 0) by the blocks in their solving order (:mod:`vloop.core.blocks`): closed-form dyads for
all samples at once, Newton blocks by continuation. Velocities and accelerations are the exact linear systems
J·u̇ = −(known part of Σ ż), J·ü = −(known part of Σ z̈), solved for all samples at once. A long run is solved in
chunks that carry two rows, the change points found and each Newton block's branch across their borders; a
run that stops says where and why (:mod:`vloop.core.results`), with a limit located by bisection. A run whose
one input travels over its range many times is solved on a chart of that range (:mod:`vloop.core.charts`):
no rows inserted, Newton rows predicted from it, turns counted from it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import MechanismError, MotionError
from ..files import budget
from ..method.loops import LoopSystem
from ..result import Result
from . import charts
from .accuracy import DEFAULT_MAX_ITER, DEFAULT_RTOL, DEFAULT_TOL, ILL_FRACTION, error_bound
from .blocks import run_blocks
from .changepoints import (
    STENCIL_INPUT,
    probe,
    time_to_move,
)
from .context import Failure, Inputs, Run, impose_drivers, initial_state, input_units
from .data import TWO_PI, State
from .grid import Grid, check_inputs, internal_grid
from .plans import block_plans
from .results import chunk_result, first_non_finite, motion_error

LIMIT_RTOL = 1e-12  # the limit is located to this fraction of the drivers' range over the run


def _locate_failure(run: Run, state: State, t_grid: np.ndarray, f: Failure, X: np.ndarray) -> tuple[float, np.ndarray]:
    """Bisect between the last solved sample k−1 and the failing sample k (or the time between them where the
    failure was found: ``f.at``) for the last assemblable time (a limit position or toggle), then, where a
    closed-form dyad cannot close there, take the root of its discriminant (:func:`_discriminant_root`).
    Returns (time, driver values there)."""
    k = f.sample
    span = np.ptp(X, axis=0) if X.size else np.zeros(0)
    span = np.where(span > 0, span, 1.0)
    base = State(1, run.system.n_angles, len(run.system.slider_names))
    for name in ("e", "theta", "s"):
        getattr(base, name)[0] = getattr(state, name)[k - 1]
    lo, hi = float(t_grid[k - 1]), float(t_grid[k])
    x_lo, x_hi = X[k - 1], X[k]
    if f.at is not None:
        hi, x_hi = f.at
    elif _probe_at(run, base, lo, hi)[0].n_ok == 2:  # row k closes (refused for its condition): the limit is there
        return hi, x_hi
    for _ in range(200):
        if X.size and np.all(np.abs(x_hi - x_lo) <= LIMIT_RTOL * span):
            break
        if hi - lo <= 4 * np.spacing(max(abs(hi), 1.0)):
            break
        mid = 0.5 * (lo + hi)
        solved, trial = _probe_at(run, base, lo, mid)
        xm = run.inputs(np.array([mid]))[0][0]
        if solved.n_ok == 2:
            lo, x_lo = mid, xm
            for name in ("e", "theta", "s"):
                getattr(base, name)[0] = getattr(trial, name)[1]
        else:
            hi, x_hi = mid, xm
    root = _discriminant_root(run, base, lo, hi)
    return (lo, x_lo) if root is None else (root, run.inputs(np.array([root]))[0][0])


def _probe_at(run: Run, base: State, lo: float, t: float) -> tuple:
    """Every block solved at time ``t``, continued from ``base`` (the configuration at ``lo``)."""
    upto = len(block_plans(run.system)) - 1
    return probe(run, base, np.array([lo]), 0, np.array([t]), upto, check=False, rates=False)


LIMIT_STEPS = 12  # secant steps on a discriminant (it crosses zero linearly at a limit: a few suffice)


def _discriminant_root(run: Run, base: State, lo: float, hi: float) -> float | None:
    """Where the closed-form dyad that cannot close at ``hi`` (but closes at ``lo``) has its discriminant h = 0,
    by the Illinois variant of regula falsi on h(t) inside [lo, hi]: h crosses zero linearly at a limit, so the
    input is located to round-off (bisection to a tolerance leaves the configuration √Δx off the toggle). The
    latest time found where every block closes (h within round-off of zero or above); None where the failing
    block has no discriminant (a Newton block)."""
    solved, _ = _probe_at(run, base, lo, hi)
    plans = block_plans(run.system)
    if solved.failure is None or solved.failure.loop is None:
        return None
    i = next((n for n, p in enumerate(plans) if solved.failure.loop in p.block.loops), None)
    if i is None or plans[i].block.kind == "newton" or len(solved.discs) <= i or solved.discs[i][1] >= 0:
        return None

    def h_at(t: float) -> float | None:  # h at t, None where the run does not close there
        got, _ = _probe_at(run, base, lo, t)
        h = float(got.discs[i][1]) if len(got.discs) > i and len(got.discs[i]) > 1 else math.nan
        return h if got.n_ok == 2 or h < 0 else None

    a, b, ha, hb = lo, hi, h_at(lo), float(solved.discs[i][1])
    if ha is None or ha < 0:
        return None
    side = 0
    for _ in range(LIMIT_STEPS):
        t = b - hb * (b - a) / (hb - ha) if hb < ha else 0.5 * (a + b)
        if not a < t < b:
            t = 0.5 * (a + b)
        h = h_at(t)
        if h is None:  # (another block fails there: halve)
            b = t
            continue
        if h >= 0:
            a, ha = t, h
            hb, side = (0.5 * hb if side == 1 else hb), 1  # (Illinois: an end kept twice in a row counts half)
            if h == 0:  # on the toggle, to the round-off of h
                break
        else:
            b, hb = t, h
            ha, side = (0.5 * ha if side == -1 else ha), -1
        if b - a <= 4 * np.spacing(max(abs(b), 1.0)):
            break
    return a


def assemble_blocks(system: LoopSystem, blocks: tuple, q0: np.ndarray) -> np.ndarray:
    """The t = 0 configuration the closed-form blocks give with their (possibly flipped) branches."""
    q, why = close_at_start(system, blocks, q0)
    if q is None:
        raise MechanismError(
            f"{system.mechanism.source}: [solver] branches: the mechanism cannot be assembled on the requested branch "
            f"at t = 0 ({why})",
            entry="solver",
        )
    return q


def close_at_start(
    system: LoopSystem, blocks: tuple, q0: np.ndarray, upto: int | None = None
) -> tuple[np.ndarray | None, str]:
    """The t = 0 configuration that blocks 0..``upto`` (default: all) give from ``q0``: each closed-form dyad on its
    branch σ, a Newton block as ``q0`` holds it (assembled already), the drivers at their t = 0 values. Returns
    (the variables, free angles in [0, 2π), "") or (None, why not)."""
    trial_system = dataclasses.replace(system, blocks=blocks, q0=q0, cache={})
    na, ns = system.n_angles, len(system.slider_names)
    state = State(1, na, ns)
    state.theta[0] = q0[:na]
    state.e[0, :na] = np.exp(1j * q0[:na])
    state.s[0, :ns] = q0[na:]
    mech = system.mechanism
    run = Run(trial_system, Inputs(mech), mech.scale, DEFAULT_TOL, DEFAULT_MAX_ITER, DEFAULT_RTOL, detect=False)
    run.blocks = run_blocks
    impose_drivers(system, state, *run.inputs(np.zeros(1)))
    solved = run_blocks(run, state, np.zeros(1), 1, upto)
    if solved.n_ok < 1:
        return None, solved.failure.why if solved.failure else "no solution"
    th = state.theta[0].copy()
    free = np.array([v not in system.drivers for v in range(na)], bool)
    th[free] %= TWO_PI  # the file's convention at t = 0: θ in [0, 2π)
    return np.concatenate([th, state.s[0, :ns]]), ""


LEAD_STEP = math.pi / 180  # lead-in path step: 1° of crank (or 1/180 of the size of a slider input)


MAX_LEAD = 100_000


TURN_SAMPLES = 720  # samples of the one-turn probe that measures winding numbers


def _lead_in(system: LoopSystem, run: Run, t_first: float) -> tuple[np.ndarray, Inputs, np.ndarray]:
    """Lead-in grid, inputs and whole-turn offsets of the angles for a run whose first time is not 0.

    The configuration at t_first is reached from the t = 0 assembly along a straight path in
    input space to the inputs at t_first less their whole crank turns K_j; the unwrapped angles
    then get 2π·K_j·w_j(v) for the winding number w_j(v) of angle v over one turn of crank j.
    """
    mech = system.mechanism
    offsets = np.zeros(system.n_angles)
    if t_first == 0.0 or not mech.drivers:
        return np.zeros(0), run.inputs, offsets
    x0 = run.inputs(np.zeros(1))[0][0]
    x1 = run.inputs(np.array([t_first]))[0][0]
    crank = np.array([d.kind == "crank" for d in mech.drivers])
    K = np.where(crank, np.trunc((x1 - x0) / TWO_PI), 0.0)
    R = x1 - x0 - TWO_PI * K
    units = np.where(crank, 1.0, mech.scale)
    n_lead = int(np.clip(np.ceil(np.max(np.abs(R) / units) / LEAD_STEP), 8, MAX_LEAD))
    length = max(1.0, 1e-3 * abs(t_first))
    lead = t_first - length + length * np.arange(n_lead) / n_lead
    inputs = Inputs(mech, t_first, t_first - length, length, x0, R)
    for j in np.nonzero(K)[0]:
        offsets += abs(K[j]) * _turn_winding(system, run, j, math.copysign(TWO_PI, K[j]), x0)
    return lead, inputs, offsets


def _turn_winding(system: LoopSystem, run: Run, j: int, turn: float, x0: np.ndarray) -> np.ndarray:
    """How much every angle grows [rad] while crank ``j`` turns once by ``turn`` from the t = 0 assembly."""
    mech = system.mechanism
    R = np.zeros(len(x0))
    R[j] = turn
    grid = np.linspace(0.0, 1.0, TURN_SAMPLES + 1)
    inputs = Inputs(mech, math.inf, 0.0, 1.0, x0, R)
    state = initial_state(system, len(grid))
    impose_drivers(system, state, *inputs(grid))
    turn_run = dataclasses.replace(run, inputs=inputs, events={})
    solved = run_blocks(turn_run, state, grid, len(grid))
    name = mech.drivers[j].symbol
    if solved.failure is not None:
        raise MotionError(
            f"{mech.name}: cannot reach the first requested time: {name} cannot turn fully from its t = 0 value "
            f"({solved.failure.why})",
            entry="time",
        )
    if (
        np.max(np.abs(state.e[-1] - state.e[0]), initial=0) > 1e-9
        or np.max(np.abs(state.s[-1] - state.s[0]), initial=0) > 1e-9 * mech.scale
    ):
        raise MotionError(
            f"{mech.name}: cannot start at the first requested time without solving every turn before it: "
            f"one turn of {name} does not bring the mechanism back to its t = 0 branch; start nearer t = 0",
            entry="time",
        )
    return TWO_PI * np.round((state.theta[-1] - state.theta[0]) / TWO_PI)


def solve(
    system: LoopSystem,
    times: np.ndarray | None = None,
    *,
    tol: float | None = None,
    max_iter: int | None = None,
    rtol: float | None = None,
    memory_budget: Any = None,
) -> Result:
    """P/V/A of a compiled system at ``times`` [s] (default: the file's). Raises MotionError with ``partial``.

    ``tol``: Newton step tolerance (relative); ``max_iter``; ``rtol``: accuracy asked of every output
    (samples whose velocities' error bound cond²·ε exceeds it are refused). The file's [solver] values win for tol
    and max_iter; an ``rtol`` given here wins over the file's. ``memory_budget`` (bytes or "2G"; see
    vloop.files.budget): a run whose results would not fit is refused before it starts (MemoryBudgetError).
    """
    run, times = _prepare(system, times, tol, max_iter, rtol, memory_budget)
    chunk = _in_memory_chunk(len(times))
    budget.check(run.system, len(times), False, chunk_rows(chunk), run.memory_budget)
    run.sink = _Sink(len(times)) if len(times) > chunk else None  # several chunks: written in place, not joined
    with np.errstate(all="ignore"):  # overflow and singular rows are found and reported below
        return _solve(run, times, chunk)


def solve_iter(
    system: LoopSystem,
    times: np.ndarray | None = None,
    *,
    chunk: int | None = None,
    tol: float | None = None,
    max_iter: int | None = None,
    rtol: float | None = None,
    memory_budget: Any = None,
) -> Iterator[Result]:
    """As :func:`solve`, but yield the run in chunks of about ``chunk`` samples: memory is bounded by a chunk
    whatever the run's length. A failure raises MotionError whose ``partial`` holds the failing chunk's rows."""
    run, times = _prepare(system, times, tol, max_iter, rtol, memory_budget)
    budget.check(run.system, len(times), True, CHUNK_ROWS, run.memory_budget)
    with np.errstate(all="ignore"):
        yield from solve_chunks(run, times, chunk or CHUNK)


def _prepare(
    system: LoopSystem, times: np.ndarray | None, tol: Any, max_iter: Any, rtol: Any, memory_budget: Any
) -> tuple[Run, np.ndarray]:
    """The run context and checked times of a solve."""
    mech = system.mechanism
    budget.keep_heap()
    tol = float(mech.options.get("tol", DEFAULT_TOL if tol is None else tol))
    max_iter = int(mech.options.get("max_iter", DEFAULT_MAX_ITER if max_iter is None else max_iter))
    rtol = float(rtol if rtol is not None else mech.options.get("rtol", DEFAULT_RTOL))
    times = np.asarray(mech.times if times is None else times, float)
    if times.ndim != 1 or len(times) == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise MotionError("times must be a non-empty, finite, strictly increasing 1-D array", entry="time")
    run = Run(system, Inputs(mech), mech.scale, tol, max_iter, rtol)
    run.blocks = run_blocks
    run.memory_budget = memory_budget
    return run, times


CHUNK = 16_384  # requested samples solved together: the state stays in cache, memory stays bounded


CHUNK_ROWS = 2 * CHUNK  # internal rows allowed in one chunk (inserted rows included) before it is split


def chunk_rows(chunk: int) -> int:
    """Internal rows a chunk of ``chunk`` requested samples may hold before it is split: twice as many, and at least
    CHUNK_ROWS (a short chunk sampled coarsely, several rows inserted per sample, stays one chunk)."""
    return max(2 * chunk, CHUNK_ROWS)


IN_MEMORY = 4  # solve() takes chunks up to this many times longer than streamed runs


def _in_memory_chunk(n: int) -> int:
    """Requested samples per chunk of solve() for ``n`` samples: up to IN_MEMORY·CHUNK (fewer chunks, less per-chunk
    work), split evenly. (The state is column-major: a chunk's time per sample does not grow with its length or the
    state's width — the Jansen pair, 13 angle columns, at 48,000 samples in one chunk: 0.94× its time per sample at
    4,800.)"""
    rows = IN_MEMORY * CHUNK
    return -(-n // -(-n // rows)) if n else rows  # ⌈n / ⌈n / rows⌉⌉: no short last chunk


@dataclass
class _Sink:
    """solve()'s output columns over the whole run (``n`` requested samples), each chunk's written in place at
    its rows: a run of several chunks is then not copied again to be joined."""

    n: int
    columns: dict[str, np.ndarray] = dataclasses.field(default_factory=dict)

    def put(self, name: str, row: int, values: np.ndarray) -> np.ndarray:
        """Copy ``values`` into column ``name`` from ``row`` on; the copy's view."""
        if name not in self.columns:
            self.columns[name] = np.empty(self.n)
        out = self.columns[name][row : row + len(values)]
        np.copyto(out, values)
        return out

    def take(self, name: str, n: int) -> np.ndarray:
        """Column ``name``'s first n rows (the whole array when the run finished: nothing else kept alive)."""
        col = self.columns[name]
        return col if n == len(col) else col[:n]


def _solve(run: Run, times: np.ndarray, chunk: int | None = None) -> Result:
    """The whole run as one Result: the chunks joined (on failure, the MotionError's partial joins them)."""
    parts: list[Result] = []
    try:
        for part in solve_chunks(run, times, chunk or CHUNK):
            parts.append(part)
    except MotionError as exc:
        if exc.partial is not None and parts:
            exc.partial = join([*parts, exc.partial])
        raise
    return join(parts, run.sink)


def join(parts: list[Result], sink: _Sink | None = None) -> Result:
    """Results of consecutive chunks as one (meta from the last: it has every change point); where they were
    written into ``sink`` in place, its columns' first rows."""
    if len(parts) == 1:
        return parts[0]
    first, last = parts[0], parts[-1]
    n = sum(len(plan.t) for plan in parts)
    return Result(
        first.mechanism,
        first.engine,
        np.concatenate([plan.t for plan in parts]),
        {k: sink.take(k, n) if sink else np.concatenate([plan.columns[k] for plan in parts]) for k in first.columns},
        {k: np.concatenate([plan.health[k] for plan in parts]) for k in first.health},
        dict(last.meta),
    )


def solve_chunks(run: Run, times: np.ndarray, chunk: int = CHUNK) -> Iterator[Result]:
    """Solve ``times`` in chunks of about ``chunk`` requested samples, yielding each chunk's Result.

    State carried across a chunk border: two internal rows (positions, unwrapped angles, so turn counts
    continue; change-point detection sees the border row with both neighbours), the change points found
    so far and each Newton block's branch sign (in ``run``). A chunk's last rows that a change point just
    past its end could still reach (ill-conditioned rows within its stencil: see _cut) are not given out
    but solved again by the next chunk, as in a run solved in one piece; a failure there is decided by a
    longer chunk. A failure raises MotionError whose ``partial``
    holds this chunk's rows before it (``sample`` counts from the start of the run)."""
    system = run.system
    lead, run.inputs, turns = _lead_in(system, run, float(times[0]))
    run.t_start = float(times[0])
    chart = _chart(run, times)
    carry: tuple[np.ndarray, State] | None = None
    i0, n_total, size, at_least = 0, len(times), chunk, 1
    while i0 < n_total:
        i1 = min(i0 + size, n_total)
        events = {i: list(evs) for i, evs in run.events.items()}
        charted = _on_chart(run, chart, lead, carry, times, i0, i1, n_total, at_least, chunk_rows(chunk))
        solved = None if charted is None else _solve_on_chart(run, chart, charted, carry, turns)
        failure = None
        if solved is not None:
            grid, (state, res) = charted, solved
        else:  # (no chart, or one the chunk misses: solved as if none had been drawn)
            run.events = {i: list(evs) for i, evs in events.items()}
            grid = _chunk_grid(run, lead, carry, times, i0, i1, n_total, at_least, chunk_rows(chunk))
            run.tail = grid.offset + len(grid.out) == n_total
            state = _start_state(system, grid, carry)
            try:
                res = _solve_grid(run, grid, state, turns if carry is None else None)
            except MotionError as exc:
                res, failure = exc.partial, exc
        reach = math.inf if run.tail else _border_reach(run, grid)
        cut = len(grid.out) - 1 if run.tail else _cut(run, grid, res, reach)
        if failure is not None and (run.tail or failure.time is None or failure.time <= reach):
            raise failure
        if not run.tail and (cut <= grid.skip or grid.out[cut] < 1):  # nothing safe from the chunk's end yet
            at_least = len(grid.out) - grid.skip + 1  # one more requested sample than this chunk had
            run.events, size = events, max(2 * size, at_least)
            continue
        t_cut = float(grid.t[grid.out[cut]])
        run.events = {i: [ev for ev in evs if ev.time <= t_cut] for i, evs in run.events.items()}
        keep = cut + 1 - grid.skip
        yield res if keep == len(res) else res.head(keep)
        if run.tail:
            return
        row = int(grid.out[cut])
        carry = (grid.t[row - 1 : row + 1], state.copy_positions(slice(row - 1, row + 1)))
        i0, size, at_least = grid.offset + cut + 1, chunk, 1


def _start_state(system: LoopSystem, grid: Grid, carry: tuple | None) -> State:
    """A chunk's state: row 0 the t = 0 assembly, or rows 0–1 carried from the chunk before."""
    state = initial_state(system, len(grid.t))
    if carry is not None:
        for name in State.POSITIONS:
            getattr(state, name)[:2] = getattr(carry[1], name)
    return state


CHART_MIN_STEP = math.radians(2.0)  # closed forms alone: a chart is drawn where samples are this far apart on average


def _chart(run: Run, times: np.ndarray) -> charts.Chart | None:
    """The run's chart over its one input (:mod:`vloop.core.charts`), where it saves work: Newton blocks whose
    input travels its range many times, closed forms only where, besides, the samples lie far apart (rows would be
    inserted between them, dips of the discriminants searched: finely sampled, closed forms cost less)."""
    newton = any(b.kind == "newton" for b in run.system.blocks)
    trip = charts.input_travel(run, times)
    if not charts.worth_drawing(run, trip, 0.0 if newton else CHART_MIN_STEP):
        return None
    return charts.draw(run, trip)


def _on_chart(
    run: Run,
    chart: charts.Chart | None,
    lead: np.ndarray,
    carry: tuple | None,
    times: np.ndarray,
    i0: int,
    i1: int,
    n_total: int,
    at_least: int,
    max_rows: int,
) -> Grid | None:
    """The chunk's grid without inserted rows, where no change point has been passed and the chart covers the
    chunk's inputs (a crank's one-turn chart covers every input; another is checked on the chunk's grid with its
    rows inserted: the input between samples too). Sets ``run.tail``."""
    if chart is None or any(run.events.values()):
        return None
    if not chart.turn:
        grid = _chunk_grid(run, lead, carry, times, i0, i1, n_total, at_least, max_rows)
        if not chart.covers(run.inputs(grid.t)[0][:, 0]):
            return None
        i1 = grid.offset + len(grid.out)
    grid = _chunk_grid(run, lead, carry, times, i0, i1, n_total, at_least, max_rows, insert=False)
    run.tail = grid.offset + len(grid.out) == n_total
    return grid


def _solve_on_chart(
    run: Run, chart: charts.Chart, grid: Grid, carry: tuple | None, turns: np.ndarray
) -> tuple[State, Result] | None:
    """The chunk solved on the chart (its state and Result), or None where a row misses it or the motion stops
    (the chunk is then solved without it, as if none had been drawn)."""
    state = _start_state(run.system, grid, carry)
    run.chart = chart
    try:
        return state, _solve_grid(run, grid, state, turns if carry is None else None)
    except (charts.ChartMiss, MotionError):
        return None
    finally:
        run.chart = None


def _chunk_grid(
    run: Run,
    lead: np.ndarray,
    carry: tuple | None,
    times: np.ndarray,
    i0: int,
    i1: int,
    n_total: int,
    at_least: int,
    max_rows: int = CHUNK_ROWS,
    insert: bool = True,
) -> Grid:
    """The internal grid of requested samples i0..i1-1 (after the carried rows), halved until it fits ``max_rows``
    or holds ``at_least`` requested samples."""
    while True:
        if carry is None:
            grid = internal_grid(run, lead, times[i0:i1], insert)
        else:
            grid = internal_grid(run, carry[0][:1], np.concatenate([carry[0][1:], times[i0:i1]]), insert)
        if len(grid.t) <= max_rows or i1 - i0 <= at_least:
            break
        i1 = max(i0 + (i1 - i0) // 2, i0 + at_least)
    return dataclasses.replace(grid, skip=0 if carry is None else 1, offset=i0 - (carry is not None), total=n_total)


def _border_reach(run: Run, grid: Grid) -> float:
    """The earliest time a change point found after this chunk's end could still reach back to (its stencil,
    4·η with η the time the inputs take to move STENCIL_INPUT)."""
    t_end = float(grid.t[-1])
    if not run.system.mechanism.drivers:
        return t_end
    return t_end - 4.0 * time_to_move(run, t_end, math.inf, STENCIL_INPUT)


def _cut(run: Run, grid: Grid, res: Result, reach: float) -> int:
    """The last requested sample of a chunk (index into grid.out) that nothing after the chunk can change:
    before the first sample that is ill-conditioned (next to a singular row: a change point found by
    the next chunk would take its rates across) and within the reach of the chunk's end."""
    weak = error_bound(res.health["cond"]) > ILL_FRACTION * run.rtol
    unsafe = np.nonzero(weak & (res.t > reach))[0]
    return grid.skip + len(res) - 1 if not len(unsafe) else grid.skip + int(unsafe[0]) - 1


def _count_turns(run: Run, state: State, grid: Grid, X: np.ndarray, XD: np.ndarray, every: bool) -> None:
    """The whole turns of the angles on a chunk's rows from the run's chart (they lie too far apart to count them
    from row to row): of each angle that could turn π/2 or more between two rows (:meth:`charts.Chart.steep`), or
    of ``every`` angle (a late start: the turns before the lead-in's are counted from t = 0)."""
    system, chart = run.system, run.chart
    first, n = grid.first, len(grid.t)
    if n - first < 1:
        return
    if every:
        cols = np.arange(system.n_angles)
    else:  # the input's move between two rows, at most: |Δx|, or its largest rate over the longest step
        x, t = X[first:, 0], grid.t[first:]
        if len(t) < 2:
            return
        step = max(float(np.max(np.abs(np.diff(x)))), float(np.max(np.abs(XD[first:, 0]))) * float(np.max(np.diff(t))))
        cols = chart.steep(step / float(input_units(system.mechanism, system.mechanism.scale / TWO_PI)[0]))
    driven = set(system.drivers)
    for col in (c for c in cols.tolist() if c not in driven):
        theta = state.theta[first:n, col]
        theta += chart.turns(theta, X[first:n, 0], col)


def _solve_grid(run: Run, grid: Grid, state: State, turns: np.ndarray | None) -> Result:
    """Solve one chunk's grid (row 0 assembled; rows 0–1 carried from the chunk before, if any)."""
    system = run.system
    t_grid, n, first = grid.t, len(grid.t), grid.first
    X, XD, XDD = grid.inputs if grid.inputs is not None else run.inputs(t_grid)
    impose_drivers(system, state, X, XD, XDD)
    early = check_inputs(system, X, XD, XDD, first, run.rtol)
    rated = None if len(grid.out) == n else grid.out  # rows inserted (or a lead-in): rates at the requested ones
    solved = run_blocks(run, state, t_grid, early.sample if early else n, rated=rated)
    if run.chart is not None:
        if early is not None or solved.failure is not None:
            raise charts.ChartMiss("the motion stops")
        _count_turns(run, state, grid, X, XD, every=turns is not None and bool(np.any(turns)))
        turns = None
    failure = solved.failure if early is None or (solved.failure and solved.failure.sample < early.sample) else early
    n_ok = min(solved.n_ok, failure.sample if failure else n)
    free = [v for v in range(system.n_angles) if v not in system.drivers and turns[v]] if turns is not None else []
    if free:  # whole turns skipped by the lead-in: θ = φ + 2π·n with n counted in whole turns, as from t = 0
        phi = np.angle(state.e[first:, free])
        state.theta[first:, free] = phi + TWO_PI * np.round((state.theta[first:, free] + turns[free] - phi) / TWO_PI)
    limit = None
    if failure is not None and failure.sample > first and failure.loop is not None and failure is not early:
        limit = _locate_failure(run, state, t_grid, failure, X)
    result, sources = chunk_result(run, state, grid, n_ok, solved)
    bad = None if all(np.isfinite(np.sum(a)) for a in sources) else first_non_finite(result)
    if bad is not None:
        row, column = bad
        failure = Failure(
            int(grid.out[row + grid.skip]), None, f"{column} is not finite (an overflow: the inputs are too large)"
        )
        result, limit = result.head(row), None
    if failure is not None:
        raise motion_error(system, failure, grid, X, result, limit)
    return result
