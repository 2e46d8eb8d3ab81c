"""Position, velocity and acceleration over time, block by block.

State over the sample grid (rows = samples):

* ``E[:, a] = e^{jθ_a}`` (unit complex) and ``TH[:, a]`` (unwrapped θ) per rotating
  link, ``W``/``AL`` its ω/α; ``S``/``SD``/``SDD`` per slider. A last padding
  column (E = 1, others 0) stands for "fixed" so terms index it with -1.
* Term vectors ``z = (r + s)·cδ·E`` with cδ = e^{jδ}; velocities and
  accelerations follow by differentiation:
  ż = ṡ·e + jω·z,   z̈ = s̈·e + 2jṡω·e + (jα − ω²)·z,   e = cδ·E.

Blocks are solved in the order of the block-triangular decomposition. One-loop
dyads have closed forms evaluated for all samples at once (branch σ from the
t = 0 assembly); other blocks use Newton–Raphson per sample with the analytic
Jacobian, warm-started by the Taylor predictor x + ẋ·h + ẍ·h²/2 from the
previous sample. Velocities and accelerations are the exact linear systems
J·u̇ = −(known part of Σ ż), J·ü = −(known part of Σ z̈), solved for all samples
at once (Cramer's rule for 2×2 blocks, batched ``numpy.linalg.solve`` otherwise).
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
from ..method.assembly import redundancy_text
from ..method.loops import LoopSystem
from ..result import Result
from . import newton
from .changepoints import (
    STENCIL_INPUT,
    _eta,
    _find_change_points,
    _near_change_point,
    _probe,
    _rates_across,
    find_singular_points,
)
from .kernels import (
    DEFAULT_RTOL,
    ILL_FRACTION,
    TWO_PI,
    _block_health,
    _closed_form,
    _columns,
    _error_bound,
    _fail,
    _Failure,
    _impose_drivers,
    _initial_state,
    _Inputs,
    _Plan,
    _plans,
    _rates,
    _rates_by,
    _Run,
    _Solved,
    _State,
    _store,
    _Sum,
    _system_sums,
    _velocity_bound,
    row_max,
)

DEFAULT_TOL = 1e-12  # Newton stops when the step is below tol·(1 + |x|)


DEFAULT_MAX_ITER = 30


def _run_blocks(run: _Run, st: _State, tg: np.ndarray, n: int, upto: int | None = None) -> _Solved:
    """Solve blocks 0..upto (default: all) in order on rows 0..n-1 (row 0 must be assembled)."""
    sys = run.sys
    na = sys.n_angles
    out = _Solved(n, None, [], [], [], np.zeros(n, bool))
    for i, p in enumerate(_plans(sys)):
        if upto is not None and i > upto:
            break
        fac = None
        if p.block.kind == "newton":
            failure, fac = newton.solve_block(run, st, tg, i, p, out.n_ok)
            if failure is not None:
                _fail(out, failure)
            out.discs.append(None)
            sig = run.sigma(i, tg[: out.n_ok])
        else:
            sig = _positions(run, st, tg, i, p, out)
        if out.n_ok == 0:
            break
        k = slice(0, out.n_ok)
        cols = None
        if fac is None:
            cols = _columns(p, st, k)  # shared by health and rates
            cond, sgn = _block_health(p, st, k, run.scale, cols)
        else:
            cond, sgn = fac.cond[k], fac.sign[k]
            if p.C.shape[0] * 2 > len(p.block.unknowns):  # redundant: one branch, singular points passed
                find_singular_points(run, st, tg, i, cond)
        near = _near_change_point(run, i, tg[k], cond)
        if run.check:
            signed = sgn * sig[: out.n_ok]
            bad = np.nonzero(((_velocity_bound(cond) > run.rtol) | (signed != signed[0])) & ~near)[0]
            if len(bad):
                _fail(out, _Failure(int(bad[0]), p.block.loops[0], _toggle_reason(cond[bad[0]], run.rtol)))
                k = slice(0, out.n_ok)
                cond, sgn, near = cond[k], sgn[k], near[k]
                cols = None if cols is None else cols.head(out.n_ok)
        out.conds.append(cond)
        out.signs.append(sgn)
        if out.n_ok == 0 or not run.rates:
            continue
        if fac is None:
            _store(p, st, k, _rates(p, st, k, "v", cols), "v", na)
            _store(p, st, k, _rates(p, st, k, "a", cols), "a", na)
        else:
            _store(p, st, k, _rates_by(p, st, k, fac.inv[k], "v"), "v", na)
            _store(p, st, k, _rates_by(p, st, k, fac.inv[k], "a"), "a", na)
        if near.any():
            _rates_across(run, st, tg, i, p, np.nonzero(near)[0], out, cond)
    out.at_change = out.at_change[: out.n_ok]
    return out


def _toggle_reason(cond: float, rtol: float) -> str:
    return (
        f"the mechanism reaches a toggle (singular Jacobian: condition number {cond:.3g}, so the velocities "
        f"could be wrong by cond²·ε = {min(float(_velocity_bound(cond)), 1.0):.2g} of their size, "
        f"more than rtol = {rtol:g})"
    )


def _positions(run: _Run, st: _State, tg: np.ndarray, i: int, p: _Plan, out: _Solved) -> np.ndarray:
    """Solve block ``i``'s positions on rows 0..out.n_ok-1 (finding change points on the main run)."""
    na = run.sys.n_angles
    k = slice(0, out.n_ok)
    sig = run.sigma(i, tg[k])
    ok, h = _closed_form(p, st, k, na, sig)
    if run.detect and p.block.kind != "PP":
        n_lim = int(np.argmin(ok)) if not ok.all() else out.n_ok
        try:
            found = _find_change_points(run, st, tg, i, h[:n_lim])
        except _Failure as f:
            found = []
            _fail(out, f)
        if found:
            sig = run.sigma(i, tg[k])
            ok, h = _closed_form(p, st, k, na, sig)
    if not ok[: out.n_ok].all():
        bad = int(np.argmin(ok))
        _fail(out, _Failure(bad, p.block.loops[0], "the loop cannot close: the input is past a limit position"))
    out.discs.append(h)
    return sig


LIMIT_RTOL = 1e-12  # the limit is located to this fraction of the drivers' range over the run


def _locate_failure(run: _Run, st: _State, tg: np.ndarray, k: int, X: np.ndarray) -> tuple[float, np.ndarray]:
    """Bisect between the last solved sample k−1 and the failing sample k for the last assemblable
    time (a limit position or toggle). Returns (time, driver values there)."""
    span = np.ptp(X, axis=0) if X.size else np.zeros(0)
    span = np.where(span > 0, span, 1.0)
    base = _State(1, run.sys.n_angles, len(run.sys.slider_names))
    for name in ("E", "TH", "S"):
        getattr(base, name)[0] = getattr(st, name)[k - 1]
    lo, hi = float(tg[k - 1]), float(tg[k])
    x_lo, x_hi = X[k - 1], X[k]
    for _ in range(200):
        if X.size and np.all(np.abs(x_hi - x_lo) <= LIMIT_RTOL * span):
            break
        if hi - lo <= 4 * np.spacing(max(abs(hi), 1.0)):
            break
        mid = 0.5 * (lo + hi)
        solved, trial = _probe(
            run, base, np.array([lo]), 0, np.array([mid]), len(_plans(run.sys)) - 1, check=False, rates=False
        )
        xm = run.inputs(np.array([mid]))[0][0]
        if solved.n_ok == 2:
            lo, x_lo = mid, xm
            for name in ("E", "TH", "S"):
                getattr(base, name)[0] = getattr(trial, name)[1]
        else:
            hi, x_hi = mid, xm
    return lo, x_lo


def assemble_blocks(sys: LoopSystem, blocks: tuple, q0: np.ndarray) -> np.ndarray:
    """The t = 0 configuration the closed-form blocks give with their (possibly flipped) branches."""
    trial_sys = dataclasses.replace(sys, blocks=blocks, q0=q0, cache={})
    na, ns = sys.n_angles, len(sys.slider_names)
    st = _State(1, na, ns)
    st.TH[0] = q0[:na]
    st.E[0, :na] = np.exp(1j * q0[:na])
    st.S[0, :ns] = q0[na:]
    mech = sys.mechanism
    run = _Run(trial_sys, _Inputs(mech), mech.scale, DEFAULT_TOL, DEFAULT_MAX_ITER, DEFAULT_RTOL, detect=False)
    run.blocks = _run_blocks
    _impose_drivers(sys, st, *run.inputs(np.zeros(1)))
    solved = _run_blocks(run, st, np.zeros(1), 1)
    if solved.n_ok < 1:
        raise MechanismError(
            f"{mech.source}: [solver] branches: the mechanism cannot be assembled on the requested branch at t = 0 "
            f"({solved.failure.why if solved.failure else 'no solution'})",
            entry="solver",
        )
    th = st.TH[0].copy()
    free = np.array([v not in sys.drivers for v in range(na)], bool)
    th[free] %= TWO_PI  # the file's convention at t = 0: θ in [0, 2π)
    return np.concatenate([th, st.S[0, :ns]])


LEAD_STEP = math.pi / 180  # lead-in path step: 1° of crank (or 1/180 of the size of a slider input)


MAX_LEAD = 100_000


TURN_SAMPLES = 720  # samples of the one-turn probe that measures winding numbers


def _lead_in(sys: LoopSystem, run: _Run, t_first: float) -> tuple[np.ndarray, _Inputs, np.ndarray]:
    """Lead-in grid, inputs and whole-turn offsets of the angles for a run whose first time is not 0.

    The configuration at t_first is reached from the t = 0 assembly along a straight path in
    input space to the inputs at t_first less their whole crank turns K_j; the unwrapped angles
    then get 2π·K_j·w_j(v) for the winding number w_j(v) of angle v over one turn of crank j.
    """
    mech = sys.mechanism
    offsets = np.zeros(sys.n_angles)
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
    inputs = _Inputs(mech, t_first, t_first - length, length, x0, R)
    for j in np.nonzero(K)[0]:
        offsets += abs(K[j]) * _turn_winding(sys, run, j, math.copysign(TWO_PI, K[j]), x0)
    return lead, inputs, offsets


def _turn_winding(sys: LoopSystem, run: _Run, j: int, turn: float, x0: np.ndarray) -> np.ndarray:
    """How much every angle grows [rad] while crank ``j`` turns once by ``turn`` from the t = 0 assembly."""
    mech = sys.mechanism
    R = np.zeros(len(x0))
    R[j] = turn
    grid = np.linspace(0.0, 1.0, TURN_SAMPLES + 1)
    inputs = _Inputs(mech, math.inf, 0.0, 1.0, x0, R)
    st = _initial_state(sys, len(grid))
    _impose_drivers(sys, st, *inputs(grid))
    turn_run = dataclasses.replace(run, inputs=inputs, events={})
    solved = _run_blocks(turn_run, st, grid, len(grid))
    name = mech.drivers[j].symbol
    if solved.failure is not None:
        raise MotionError(
            f"{mech.name}: cannot reach the first requested time: {name} cannot turn fully from its t = 0 value "
            f"({solved.failure.why})",
            entry="time",
        )
    if (
        np.max(np.abs(st.E[-1] - st.E[0]), initial=0) > 1e-9
        or np.max(np.abs(st.S[-1] - st.S[0]), initial=0) > 1e-9 * mech.scale
    ):
        raise MotionError(
            f"{mech.name}: cannot start at the first requested time without solving every turn before it: "
            f"one turn of {name} does not bring the mechanism back to its t = 0 branch; start nearer t = 0",
            entry="time",
        )
    return TWO_PI * np.round((st.TH[-1] - st.TH[0]) / TWO_PI)


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
    budget.check(run.sys, len(times), False, 2 * chunk, run.memory_budget)
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
    budget.check(run.sys, len(times), True, CHUNK_ROWS, run.memory_budget)
    with np.errstate(all="ignore"):
        yield from solve_chunks(run, times, chunk or CHUNK)


def _prepare(
    system: LoopSystem, times: np.ndarray | None, tol: Any, max_iter: Any, rtol: Any, memory_budget: Any
) -> tuple[_Run, np.ndarray]:
    """The run context and checked times of a solve."""
    mech = system.mechanism
    budget.keep_heap()
    tol = float(mech.options.get("tol", DEFAULT_TOL if tol is None else tol))
    max_iter = int(mech.options.get("max_iter", DEFAULT_MAX_ITER if max_iter is None else max_iter))
    rtol = float(rtol if rtol is not None else mech.options.get("rtol", DEFAULT_RTOL))
    times = np.asarray(mech.times if times is None else times, float)
    if times.ndim != 1 or len(times) == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise MotionError("times must be a non-empty, finite, strictly increasing 1-D array", entry="time")
    run = _Run(system, _Inputs(mech), mech.scale, tol, max_iter, rtol)
    run.blocks = _run_blocks
    run.memory_budget = memory_budget
    return run, times


@dataclass(frozen=True)
class _Grid:
    """The internal sample grid: the lead-in from t = 0, the requested times, and rows inserted
    between requested samples so the inputs move at most MAX_INPUT_STEP per row (turns of the
    other links are then counted right, change points found, Newton continued from near)."""

    t: np.ndarray
    out: np.ndarray  # internal row of each requested sample (increasing)
    inputs: tuple | None = None  # the inputs (X, XD, XDD) at t, where _grid has evaluated them already
    skip: int = 0  # leading requested samples already given by the chunk before (its last one)
    offset: int = 0  # index in the whole run of the requested sample at out[0]
    total: int = 0  # requested samples in the whole run

    @property
    def first(self) -> int:
        return int(self.out[0])

    def requested_before(self, row: int) -> int:
        """How many requested samples come before internal row ``row``."""
        return int(np.searchsorted(self.out, row))


MAX_INPUT_STEP = math.radians(10)  # per internal row: of a crank (or 1/36 of the size for a slider input)


MAX_INSERTED = 10_000_000


def _within_one_step(mech: Any, h: np.ndarray, XD: np.ndarray, units: np.ndarray) -> bool:
    """Whether no input can move more than MAX_INPUT_STEP between two samples, by one bound: with drivers
    x = x0 + v0·t + a0·t²/2 (no profile) ẋ is linear, so |Δx| and the rates' trapezoid over a step are at most
    h·max|ẋ| at its ends ≤ max h · max|ẋ| (profiles can peak between samples: they take the row-by-row test)."""
    if any(d.profile is not None for d in mech.drivers):
        return False
    with np.errstate(invalid="ignore", over="ignore"):
        bound = float(np.max(h)) * float(np.max(np.max(np.abs(XD), axis=0) / units))
    return bound <= MAX_INPUT_STEP  # (False where not finite: the row-by-row test then sorts it out)


def _as_requested(lead: np.ndarray, times: np.ndarray, inputs: tuple) -> _Grid:
    """The lead-in followed by the requested times, no rows inserted (the inputs at them kept without a lead-in)."""
    if not len(lead):
        return _Grid(times, np.arange(len(times)), inputs=inputs)
    return _Grid(np.concatenate([lead, times]), len(lead) + np.arange(len(times)))


def _grid(run: _Run, lead: np.ndarray, times: np.ndarray) -> _Grid:
    """Lead-in + requested times, with rows inserted where an input moves more than MAX_INPUT_STEP."""
    mech = run.sys.mechanism
    n = len(times)
    steps = np.ones(max(n - 1, 0), np.int64)
    if mech.drivers and n > 1:
        X, XD, XDD = run.inputs(times)
        units = np.array([1.0 if d.kind == "crank" else mech.scale / (2 * math.pi) for d in mech.drivers])
        h = np.diff(times)[:, None]
        if _within_one_step(mech, h, XD, units):
            return _as_requested(lead, times, (X, XD, XDD))
        travel = np.maximum(np.abs(np.diff(X, axis=0)), 0.5 * h * (np.abs(XD[1:]) + np.abs(XD[:-1]))) / units
        need = np.ceil(row_max(travel) / MAX_INPUT_STEP)
        need = np.where(np.isfinite(need) & (need <= MAX_INSERTED), need, 1.0)  # absurd inputs: refused later
        if need.sum() - len(need) > MAX_INSERTED:
            raise MotionError(
                f"{mech.name}: the inputs travel {float(travel.sum(axis=0).max()):.4g} rad (or sizes) over the run; "
                f"counting the other links' turns needs at most {math.degrees(MAX_INPUT_STEP):g}° per internal "
                f"sample, which would take {int(need.sum()):,} samples (more than {MAX_INSERTED:,}): shorten the run",
                entry="time",
            )
        steps = np.maximum(need, 1).astype(np.int64)
        if int(steps.sum()) == n - 1:  # no row to insert
            return _as_requested(lead, times, (X, XD, XDD))
    starts = np.concatenate([[0], np.cumsum(steps)])  # internal index of each requested sample
    k = np.arange(starts[-1])
    seg = np.repeat(np.arange(len(steps)), steps)
    frac = (k - starts[seg]) / steps[seg]
    inner = np.append(times[seg] + frac * (times[seg + 1] - times[seg]), times[-1]) if n > 1 else times.copy()
    inner[starts] = times  # the requested times exactly
    return _Grid(np.concatenate([lead, inner]), len(lead) + starts)


CHUNK = 16_384  # requested samples solved together: the state stays in cache, memory stays bounded


CHUNK_ROWS = 2 * CHUNK  # internal rows allowed in one chunk (inserted rows included) before it is split


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


def _solve(run: _Run, times: np.ndarray, chunk: int | None = None) -> Result:
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
    n = sum(len(p.t) for p in parts)
    return Result(
        first.mechanism,
        first.engine,
        np.concatenate([p.t for p in parts]),
        {k: sink.take(k, n) if sink else np.concatenate([p.columns[k] for p in parts]) for k in first.columns},
        {k: np.concatenate([p.health[k] for p in parts]) for k in first.health},
        dict(last.meta),
    )


def solve_chunks(run: _Run, times: np.ndarray, chunk: int = CHUNK) -> Iterator[Result]:
    """Solve ``times`` in chunks of about ``chunk`` requested samples, yielding each chunk's Result.

    State carried across a chunk border: two internal rows (positions, unwrapped angles, so turn counts
    continue; change-point detection sees the border row with both neighbours), the change points found
    so far and each Newton block's branch sign (in ``run``). A chunk's last rows that a change point just
    past its end could still reach (ill-conditioned rows within its stencil: see _cut) are not given out
    but solved again by the next chunk, as in a run solved in one piece; a failure there is decided by a
    longer chunk. A failure raises MotionError whose ``partial``
    holds this chunk's rows before it (``sample`` counts from the start of the run)."""
    sys = run.sys
    lead, run.inputs, turns = _lead_in(sys, run, float(times[0]))
    run.t_start = float(times[0])
    carry: tuple[np.ndarray, _State] | None = None
    i0, n_total, size, at_least = 0, len(times), chunk, 1
    while i0 < n_total:
        i1 = min(i0 + size, n_total)
        grid = _chunk_grid(run, lead, carry, times, i0, i1, n_total, at_least, 2 * chunk)
        run.tail = grid.offset + len(grid.out) == n_total
        st = _initial_state(sys, len(grid.t))
        if carry is not None:
            for name in ("E", "TH", "S"):
                getattr(st, name)[:2] = getattr(carry[1], name)
        events = {i: list(evs) for i, evs in run.events.items()}
        try:
            res = _solve_grid(run, grid, st, turns if carry is None else None)
            failure = None
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
        carry = (grid.t[row - 1 : row + 1], _rows(st, slice(row - 1, row + 1)))
        i0, size, at_least = grid.offset + cut + 1, chunk, 1


def _chunk_grid(
    run: _Run,
    lead: np.ndarray,
    carry: tuple | None,
    times: np.ndarray,
    i0: int,
    i1: int,
    n_total: int,
    at_least: int,
    max_rows: int = CHUNK_ROWS,
) -> _Grid:
    """The internal grid of requested samples i0..i1-1 (after the carried rows), halved until it fits ``max_rows``
    or holds ``at_least`` requested samples."""
    while True:
        if carry is None:
            grid = _grid(run, lead, times[i0:i1])
        else:
            grid = _grid(run, carry[0][:1], np.concatenate([carry[0][1:], times[i0:i1]]))
        if len(grid.t) <= max_rows or i1 - i0 <= at_least:
            break
        i1 = max(i0 + (i1 - i0) // 2, i0 + at_least)
    return dataclasses.replace(grid, skip=0 if carry is None else 1, offset=i0 - (carry is not None), total=n_total)


def _border_reach(run: _Run, grid: _Grid) -> float:
    """The earliest time a change point found after this chunk's end could still reach back to (its stencil,
    4·η with η the time the inputs take to move STENCIL_INPUT)."""
    t_end = float(grid.t[-1])
    if not run.sys.mechanism.drivers:
        return t_end
    return t_end - 4.0 * _eta(run, t_end, math.inf, STENCIL_INPUT)


def _cut(run: _Run, grid: _Grid, res: Result, reach: float) -> int:
    """The last requested sample of a chunk (index into grid.out) that nothing after the chunk can change:
    before the first sample that is ill-conditioned (next to a singular row: a change point found by
    the next chunk would take its rates across) and within the reach of the chunk's end."""
    weak = _error_bound(res.health["cond"]) > ILL_FRACTION * run.rtol
    unsafe = np.nonzero(weak & (res.t > reach))[0]
    return grid.skip + len(res) - 1 if not len(unsafe) else grid.skip + int(unsafe[0]) - 1


def _rows(st: _State, k: slice) -> _State:
    """A copy of rows ``k`` of a state's positions (rates are recomputed where carried)."""
    out = _State.__new__(_State)
    for name in ("E", "TH", "S"):
        setattr(out, name, getattr(st, name)[k].copy())
    return out


def _solve_grid(run: _Run, grid: _Grid, st: _State, turns: np.ndarray | None) -> Result:
    """Solve one chunk's grid (row 0 assembled; rows 0–1 carried from the chunk before, if any)."""
    sys = run.sys
    tg, n, first = grid.t, len(grid.t), grid.first
    X, XD, XDD = grid.inputs if grid.inputs is not None else run.inputs(tg)
    _impose_drivers(sys, st, X, XD, XDD)
    early = _check_inputs(sys, X, XD, XDD, first, run.rtol)
    solved = _run_blocks(run, st, tg, early.sample if early else n)
    failure = solved.failure if early is None or (solved.failure and solved.failure.sample < early.sample) else early
    n_ok = min(solved.n_ok, failure.sample if failure else n)
    free = [v for v in range(sys.n_angles) if v not in sys.drivers and turns[v]] if turns is not None else []
    if free:  # whole turns skipped by the lead-in: θ = φ + 2π·n with n counted in whole turns, as from t = 0
        phi = np.angle(st.E[first:, free])
        st.TH[first:, free] = phi + TWO_PI * np.round((st.TH[first:, free] + turns[free] - phi) / TWO_PI)
    limit = None
    if failure is not None and failure.sample > first and failure.loop is not None and failure is not early:
        limit = _locate_failure(run, st, tg, failure.sample, X)
    result, sources = _result(run, st, grid, n_ok, solved)
    bad = None if all(np.isfinite(np.sum(a)) for a in sources) else _first_non_finite(result)
    if bad is not None:
        row, column = bad
        failure = _Failure(
            int(grid.out[row + grid.skip]), None, f"{column} is not finite (an overflow: the inputs are too large)"
        )
        result, limit = result.head(row), None
    if failure is not None:
        raise _motion_error(sys, failure, grid, X, result, limit)
    return result


def _check_inputs(
    sys: LoopSystem, X: np.ndarray, XD: np.ndarray, XDD: np.ndarray, off: int, rtol: float
) -> _Failure | None:
    """The first sample whose driver inputs are not finite, or whose crank angle is too large to
    resolve to ``rtol`` (its floating-point spacing exceeds rtol radians)."""
    mech = sys.mechanism
    bad = ~np.isfinite(X) | ~np.isfinite(XD) | ~np.isfinite(XDD)
    # spacing(x) = 2^(e − 52) on [2^e, 2^(e+1)): it exceeds rtol from 2^(⌊log2 rtol⌋ + 53) on
    too_large = 2.0 ** (math.floor(math.log2(rtol)) + 53) if 0 < rtol < math.inf else math.inf
    for j, d in enumerate(mech.drivers):
        if d.kind == "crank":
            bad[off:, j] |= np.abs(X[off:, j]) >= too_large
    rows = np.nonzero(row_max(bad) if bad.shape[1] else np.zeros(len(bad), bool))[0]
    if not len(rows):
        return None
    r = int(rows[0])
    j = int(np.argmax(bad[r]))
    d = mech.drivers[j]
    vals = (X[r, j], XD[r, j], XDD[r, j])
    if np.all(np.isfinite(vals)):
        why = f"the input {d.symbol} = {X[r, j]:.6g} rad is too large to resolve to rtol = {rtol:g} rad"
    else:
        which = ("value", "rate", "acceleration")[int(np.argmin(np.isfinite(vals)))]
        why = f"the input's {which} is not finite (an overflow: the driver's numbers are too large)"
    return _Failure(r, None, why)


def _first_non_finite(result: Result) -> tuple[int, str] | None:
    """(row, column) of the first non-finite output value, if any (searched column by column only where a sum
    over the arrays the columns come from is not finite: a NaN or ±∞ anywhere makes it so)."""
    first = None
    for name, col in result.columns.items():
        bad = ~np.isfinite(col)
        if bad.any():
            r = int(np.argmax(bad))
            if first is None or r < first[0]:
                first = (r, name)
    return first


def _result(run: _Run, st: _State, grid: _Grid, n_ok: int, solved: _Solved) -> tuple[Result, list[np.ndarray]]:
    """The Result of a chunk's solved rows, and the arrays its columns are taken from (to check finiteness)."""
    sys = run.sys
    mech = sys.mechanism
    rows = grid.out[grid.skip :][grid.out[grid.skip :] < n_ok]  # the requested samples solved
    points, loops = _system_sums(sys)
    k = _as_slice(rows)
    P, V, A = (points.by_column(st, k, what) for what in ("p", "v", "a"))  # (points, rows) each
    cols: dict[str, np.ndarray] = {}

    def column(state: np.ndarray, j: int) -> np.ndarray:  # a state column's rows, as an array of its own
        return state[k, j].copy() if isinstance(k, slice) and run.sink is None else state[k, j]

    for name, a, offset in sys.link_outputs:
        if a >= 0:
            cols[f"{name}.theta"] = st.TH[k, a] + offset
            cols[f"{name}.omega"] = column(st.W, a)
            cols[f"{name}.alpha"] = column(st.AL, a)
        else:
            cols[f"{name}.theta"] = np.full(len(rows), offset % TWO_PI)
            cols[f"{name}.omega"] = np.zeros(len(rows))
            cols[f"{name}.alpha"] = np.zeros(len(rows))
    for i, name in enumerate(sys.point_names):
        cols[f"{name}.x"], cols[f"{name}.y"] = P[i].real, P[i].imag
        cols[f"{name}.vx"], cols[f"{name}.vy"] = V[i].real, V[i].imag
        cols[f"{name}.ax"], cols[f"{name}.ay"] = A[i].real, A[i].imag
    for i, name in enumerate(sys.slider_names):
        cols[f"{name}.s"], cols[f"{name}.v"], cols[f"{name}.a"] = (column(q, i) for q in (st.S, st.SD, st.SDD))
    if run.sink is not None:  # (the sink copies each column once: a state column is given as a view)
        cols = {name: run.sink.put(name, grid.offset + grid.skip, v) for name, v in cols.items()}
    sources = [P, V, A, *(getattr(st, name)[k] for name in ("TH", "W", "AL", "S", "SD", "SDD"))]
    t = grid.t[rows]
    seen = grid.t[grid.out[: grid.skip + len(rows)]]  # requested times solved in this chunk and the one before
    span = np.array([run.t_start, seen[-1]]) if len(seen) else np.zeros(0)
    return Result(
        mech.name,
        "vloop",
        t,
        cols,
        _health(run, st, grid.t[grid.out[: grid.skip + len(rows)]], rows, solved, loops),
        {
            "blocks": [b.kind for b in sys.blocks],
            "assembly": sys.assembly,
            **_events_meta(run, span),
            **_redundancy(sys),
        },
    ), sources


def _as_slice(rows: np.ndarray) -> slice | np.ndarray:
    """Consecutive rows as a slice (state arrays are then read as views, not copied)."""
    if len(rows) and int(rows[-1]) - int(rows[0]) + 1 == len(rows):
        return slice(int(rows[0]), int(rows[-1]) + 1)
    return rows


def _health(run: _Run, st: _State, t: np.ndarray, rows: np.ndarray, solved: _Solved, loops: _Sum) -> dict:
    """Per requested sample (``rows``): closure residual, worst block condition number, branch signature,
    flags. ``t``: the times of the rows, after the last sample of the chunk before if there is one."""
    sys = run.sys
    k = _as_slice(rows)
    residual = np.zeros(len(rows))
    if len(sys.loops):
        F = loops.by_column(st, k, "p").view(float) * (1.0 / run.scale)  # in sizes: the squares cannot overflow
        np.sqrt(np.max(F[:, 0::2] * F[:, 0::2] + F[:, 1::2] * F[:, 1::2], axis=0), out=residual)
    cond = np.ones(len(rows))
    if solved.conds:
        cond = solved.conds[0][k].copy()
        for c in solved.conds[1:]:
            np.maximum(cond, c[k], out=cond)
    branch = np.zeros(len(rows), np.int64)
    for bit, sgn in enumerate(solved.signs):
        branch |= (sgn[k] > 0).astype(np.int64) << bit
    at_change = solved.at_change[k] if len(solved.at_change) else np.zeros(len(rows), bool)
    change = at_change.astype(np.int8)
    skip = len(t) - len(rows)  # t starts with the chunk before's last sample, if any
    for evs in run.events.values():
        for ev in evs:
            j = int(np.searchsorted(t, ev.time))
            if 0 < j < len(t) and j >= skip:
                change[j - skip] = 1
    ill = _error_bound(cond) > ILL_FRACTION * run.rtol
    ill &= ~at_change
    return {
        "residual": residual,
        "cond": cond,
        "branch": branch,
        "ill_conditioned": ill.astype(np.int8),
        "change_point": change,
    }


def _redundancy(sys: LoopSystem) -> dict[str, str]:
    """For a redundant linkage, the line that says so (its reactions are indeterminate)."""
    info = sys.assembly.get("redundancy")
    return {"redundancy": redundancy_text(info, sys)} if info else {}


def _events_meta(run: _Run, t: np.ndarray) -> dict[str, Any]:
    """The change points passed within the requested times (loop, time, inputs, which continuation)."""
    sys = run.sys
    out = []
    for i, evs in sorted(run.events.items()):
        loop = sys.loops[_plans(sys)[i].block.loops[0]]
        for ev in evs:
            if not len(t) or not t[0] <= ev.time <= t[-1]:
                continue
            x = run.inputs(np.array([ev.time]))[0][0]
            out.append(
                {
                    "loop": loop.index + 1,
                    "label": loop.label,
                    "time": ev.time,
                    "inputs": {d.symbol: float(v) for d, v in zip(sys.mechanism.drivers, x, strict=True)},
                    "continued": "smooth" if ev.smooth else "other",
                    "kind": ev.kind,
                }
            )
    return {"change_points": sorted(out, key=lambda e: e["time"]), "rtol": run.rtol}


def _motion_error(
    sys: LoopSystem,
    f: _Failure,
    grid: _Grid,
    X: np.ndarray,
    partial: Result,
    limit: tuple[float, np.ndarray] | None = None,
) -> MotionError:
    """The MotionError for failure ``f`` at internal row f.sample; ``sample`` is the first requested one lost."""
    mech = sys.mechanism
    t = float(grid.t[f.sample])
    n_req = grid.total or len(grid.out)
    j = grid.requested_before(f.sample)
    jg = j + grid.offset  # in the whole run
    drv = ", ".join(
        f"{d.symbol} = {X[f.sample, i]:.6g} {'rad' if d.kind == 'crank' else mech.units}"
        for i, d in enumerate(mech.drivers)
    )
    if f.sample < grid.first:
        where = "before the first requested time (on the way from the t = 0 assembly)"
    elif j < len(grid.out) and grid.out[j] == f.sample:
        where = f"at t = {t:.6g} s (sample {jg} of {n_req})"
    else:
        where = f"at t = {t:.6g} s (between samples {jg - 1} and {jg} of {n_req})"
    kept = f"{jg} earlier sample{'s' if jg != 1 else ''} kept" if jg else "no sample kept"
    lim = ""
    if limit is not None:
        vals = ", ".join(
            f"{d.symbol} = {limit[1][i]:.10g} {'rad' if d.kind == 'crank' else mech.units}"
            for i, d in enumerate(mech.drivers)
        )
        lim = f" (last assembled at t = {limit[0]:.10g} s, {vals})"
    at = f": loop {f.loop + 1} ({sys.loops[f.loop].label})" if f.loop is not None else ""
    err = MotionError(
        f"{mech.name}: cannot assemble {where}, {drv}{at}: {f.why}{lim}; {kept}",
        entry=f"loop {f.loop + 1}" if f.loop is not None else "drivers",
        time=t if f.sample >= grid.first else None,
        sample=jg if f.sample >= grid.first else None,
        driver_value=X[f.sample].tolist() if len(X) else None,
        partial=partial,
    )
    err.limit_time = limit[0] if limit is not None else None
    err.limit_value = limit[1].tolist() if limit is not None else None
    return err
