"""Change points of closed-form dyads: where a block's two assembly branches meet between samples.

A sampled minimum of the dyad's discriminant h (the two solutions lie 2·√h apart) is refined by
zooming probes; where the branches come within CHANGE_GAP of the mechanism size it is a change
point, continued on the branch whose rates stay continuous (or the other one, as the file asks).
Rates at rows next to one, where the Jacobian is singular, come from a well-conditioned stencil.

Every minimum of a run (or, in the batch, of every variant) is zoomed on at once (:func:`locate_minima`), and
the probes of every change point's continuation and stencils are solved together: where the blocks before are
closed forms each probe row is solved on its own (:func:`dyads_at`), so the work is a few batches however many
dips the sampling shows; past a Newton block, probes continue bracket by bracket from the sample before.
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..errors import MechanismError
from ..method.loops import LoopSystem
from .accuracy import EPS, error_bound
from .context import ChangePoint, Failure, Inputs, Run, Solved, change_point_choices, impose_drivers, input_units
from .data import Probe, State
from .dyads import closed_form, dyad_health, dyad_rates, jacobian_columns
from .plans import Plan, block_plans, store_rates

CHANGE_GAP = 1e-6  # two assembly branches closer than this fraction of the mechanism size meet: a change point


ZOOM_POINTS = 17  # probes per zoom step when locating where two branches meet


ZOOM_STEPS = 12  # each step narrows the bracket 16-fold


ETA_INPUT = 1e-5  # the rates across a change point are compared this far from it (input units: rad, or size)
DIP = 0.9  # a sampled minimum of h below this fraction of its larger neighbour is zoomed on


def candidate_minima(h: np.ndarray, tail: bool = True, t: np.ndarray | None = None) -> np.ndarray:
    """(brackets, 3) ints (variant, row lo, row hi) around sampled minima of h (variants × samples) that dip:
    where a zero could hide between samples; per variant in the order of their rows.

    Near a double zero √h is V-shaped, so a sample next to it is well below its larger neighbour
    (h below 1/4 of it for an even V) whatever the sampling's phase; a broad, shallow minimum keeps
    the three samples alike and is left alone. A dip is only a candidate: the zoom decides.
    At an end of the run a zero between the two outer samples has only one neighbour to dip below: near the
    middle of that interval the two samples are alike (:func:`_edge_dips`). ``tail``: also look between the
    last two samples (the end of the run, not of a chunk: the next chunk sees that minimum with both its
    neighbours). ``t``: the sample times (s; uniform steps if not given).
    """
    n = h.shape[1]
    found = []
    if n > 2:
        flat = np.ascontiguousarray(h).reshape(-1)  # the variants' rows one after the other
        m = np.flatnonzero((flat[1:-1] <= flat[:-2]) & (flat[1:-1] <= flat[2:])) + 1  # sampled minima ...
        if len(h) > 1:
            m = m[(m % n != 0) & (m % n != n - 1)]  # ... inside a variant's rows
        m = m[flat[m] < DIP * np.maximum(flat[m - 1], flat[m + 1])]  # those that dip are candidates
        if len(m):
            found.append(np.column_stack([m // n, m % n - 1, m % n + 1]))
        steps = np.diff(t[:3]) if t is not None else np.ones(2)
        start = (h[:, 0] < DIP * h[:, 1]) | _edge_dips(h[:, :3], steps[0] / steps[1])
        v = np.nonzero(start & (h[:, 1] <= h[:, 2]))[0]  # rising from the first sample
        if len(v):
            found.append(np.column_stack([v, np.zeros_like(v), np.ones_like(v)]))
    if tail and n > 1:  # still falling at the end: a zero may lie before the last sample
        end = h[:, -1] < DIP * h[:, -2]
        if n > 2:
            steps = np.diff(t[-3:]) if t is not None else np.ones(2)
            end |= _edge_dips(h[:, :-4:-1], steps[1] / steps[0])
        v = np.nonzero(end)[0]
        if len(v):
            found.append(np.column_stack([v, np.full_like(v, n - 2), np.full_like(v, n - 1)]))
    if len(found) < 2:  # (each part is in order already)
        return found[0] if found else np.zeros((0, 3), int)
    out = np.concatenate(found)
    return out[np.lexsort((out[:, 2], out[:, 1], out[:, 0]))]


def _edge_dips(h: np.ndarray, ratio: float) -> np.ndarray:
    """Whether √h may reach zero between the outer samples of h (…, 3: the outer sample, its neighbour, the
    next), h rising inwards; ``ratio``: the outer interval over the next one.

    Near a change point √h is V-shaped, as steep either side of its vertex: a zero between the outer two
    samples makes √h0 + √h1 the slope times the outer interval, where a plain rise makes it √h1 − √h0. The
    slope is taken twice the one between the inner samples, as in :func:`first_look` (√h bends: steepest at
    its vertex)."""
    with np.errstate(invalid="ignore"):
        r = np.sqrt(h)
        return (h[..., 0] <= h[..., 1]) & (r[..., 0] + r[..., 1] <= 2.0 * ratio * (r[..., 2] - r[..., 1]))


LIMIT, CLEAR, ZOOM = 0, 1, 2  # what a first look at a bracket finds (:func:`first_look`)


def look_times(a: np.ndarray, b: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """(brackets, 3·ZOOM_POINTS): ZOOM_POINTS times from a to b, then each less η, then each plus η (times h is
    probed at: its values, and g(t) = h(t + η) − h(t − η), which crosses zero linearly at h's minimum)."""
    ts = np.linspace(a, b, ZOOM_POINTS, axis=-1)
    return np.concatenate([ts, ts - eta[..., None], ts + eta[..., None]], axis=-1)


def first_look(h: np.ndarray, scale: float) -> np.ndarray:
    """What the discriminants h at :func:`look_times` (brackets, 3·ZOOM_POINTS) say of each bracket: LIMIT
    where h < 0 (the loop cannot close between the samples), CLEAR where no change point can hide (h least at
    an end of the bracket, or √h kept above CHANGE_GAP of the size between the probes by its Lipschitz bound),
    ZOOM where one may."""
    p = ZOOM_POINTS
    mid, g = h[:, :p], h[:, 2 * p :] - h[:, p : 2 * p]
    at_end = ~((g[:, 0] < 0) & (0 <= g[:, -1]))  # (e.g. a limit approached but not passed: h falls to the end)
    with np.errstate(invalid="ignore"):
        root = np.sqrt(mid)  # √h is Lipschitz: no lower between grid points than this bound allows (the
        # slope is taken twice the largest seen, since √h bends: steepest at its vertex, between grid points)
        apart = root.min(axis=1) - np.max(np.abs(np.diff(root, axis=1)), axis=1) > 0.5 * CHANGE_GAP * scale
    return np.where(np.any(mid < 0, axis=1), LIMIT, np.where(at_end | apart, CLEAR, ZOOM))


def eta_of_rates(rates: np.ndarray, units: np.ndarray, width: np.ndarray, move: float = ETA_INPUT) -> np.ndarray:
    """Time offsets over which inputs moving at ``rates`` (…, drivers) move ``move`` (radians, or mechanism sizes
    for sliders: ``units``), at most a quarter of ``width``."""
    rate = np.max(np.abs(rates) / units, axis=-1, initial=0.0)
    with np.errstate(divide="ignore"):
        return np.minimum(np.where(rate > 0, move / np.where(rate > 0, rate, 1.0), np.inf), 0.25 * width)


def probe(run: Run, state: State, t_grid: np.ndarray, base: int, times: np.ndarray, upto: int, **mode: bool) -> tuple:
    """Solve blocks 0..upto at ``times`` (ascending, after sample ``base``), continuing from sample ``base``.

    Returns (the Solved record, the probe's state); row 0 of the probe is sample ``base``.
    """
    system = run.system
    grid = np.concatenate([[t_grid[base]], times])
    trial = State(len(grid), system.n_angles, len(system.slider_names))
    for name in ("e", "theta", "s"):
        getattr(trial, name)[0] = getattr(state, name)[base]
    try:
        impose_drivers(system, trial, *run.inputs(grid))
    except MechanismError:  # a probe past the end of a tabulated input: nothing to learn there
        return Solved(0, None, [], [], [], np.zeros(0, bool)), trial
    sub = dataclasses.replace(run, detect=False, **mode)  # shares the events found so far
    return sub.blocks(sub, trial, grid, len(grid), upto=upto), trial


def find_change_points(
    run: Run, state: State, t_grid: np.ndarray, i: int, h: np.ndarray
) -> tuple[list[ChangePoint], Failure | None]:
    """Locate where block ``i``'s two assembly branches meet between samples, and pick the continuation.

    Every sampled minimum of the discriminant h that dips is refined at once (:func:`locate_minima`); where the
    branches come within CHANGE_GAP of the mechanism size of each other it is a change point. The continuation
    is the one whose rates stay continuous across it (or the other one where the file asks so in
    ``[solver] change_points``). h < 0 between samples means the motion passes a limit there: returned as the
    failure, with the change points found before it.
    """
    loop = run.system.loops[block_plans(run.system)[i].block.loops[0]]
    choices = change_point_choices(run.system, loop.index + 1)
    found_minima = candidate_minima(h[None, :], run.tail, t_grid[: len(h)])
    if not len(found_minima):
        return [], None
    lo, hi = found_minima[:, 1:].T
    known = sorted(ev.time for ev in run.events.get(i, ()))
    fresh = ~_passed(known, t_grid[lo], t_grid[hi])  # (found already: by the chunk before, whose last rows this
    lo, hi = lo[fresh], hi[fresh]  # chunk starts from)
    if not len(lo):
        return [], None
    a, b = t_grid[lo], t_grid[hi]
    eta = times_to_move(run, 0.5 * (a + b), b - a)
    t_star, h_min = locate_minima(_Discriminants(run, state, t_grid, i, lo), a, b, eta, run.scale)
    with np.errstate(invalid="ignore"):
        meets = 2.0 * np.sqrt(h_min) <= CHANGE_GAP * run.scale
    continuations = _Continuations(run, state, t_grid, i, lo[meets], t_star[meets])
    found: list[ChangePoint] = []
    for k in np.nonzero(meets | (h_min < 0))[0].tolist():  # (the others: no change point, no limit)
        if found and _passed(known, t_grid[lo[k : k + 1]], t_grid[hi[k : k + 1]])[0]:
            continue  # (brackets around neighbouring minima can overlap: the change point is found already)
        if h_min[k] < 0:  # the loop cannot close at t*: the rows up to it are kept, the limit sought before it
            why = "the loop cannot close between samples: the input passes a limit position"
            row = int(np.searchsorted(t_grid, t_star[k]))  # the first row at or past t*
            return found, Failure(row, loop.index, why, (float(t_star[k]), run.inputs(t_star[k : k + 1])[0][0]))
        if not meets[k]:
            continue
        smooth_flip = continuations.smooth_flip(int(np.count_nonzero(meets[:k])))
        choice = choices[min(len(found), len(choices) - 1)]
        flip = smooth_flip if choice == "smooth" else not smooth_flip
        ev = ChangePoint(i, float(t_star[k]), flip, choice == "smooth")
        run.events.setdefault(i, []).append(ev)
        bisect.insort(known, ev.time)
        found.append(ev)
    return found, None


def _passed(known: list[float], a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Whether a change point is known (at a time of the sorted ``known``) in each bracket [a, b]."""
    if not known:
        return np.zeros(len(a), bool)
    times = np.array(known)
    j = np.searchsorted(times, a)
    return (j < len(times)) & (times[np.minimum(j, len(times) - 1)] <= b)


def locate_minima(
    probe_h: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    a: np.ndarray,
    b: np.ndarray,
    eta: np.ndarray,
    scale: float,
) -> tuple[np.ndarray, np.ndarray]:
    """(t*, h(t*)) of every bracket [a, b] (one per entry): where a discriminant h is least, every bracket zoomed
    at once. ``probe_h(which, times)`` gives h at ``times`` (len(which), p) for the brackets ``which`` (indices)
    and whether every block it depends on closes at all of them; η: the offset of g below, per bracket.

    Zooms on the sign change of g(t) = h(t + η) − h(t − η), which crosses zero linearly at the minimum (h
    itself is flat there), so t* is found to ~1e-12 of the bracket, not to √ε. A bracket where no change point
    can hide (the first look) or where an earlier block cannot close gets h(t*) = ∞; one where h < 0 (a limit)
    its least sampled h.
    """
    n = len(a)
    t_star, h_min = np.asarray(a, float).copy(), np.full(n, np.inf)
    lo, hi, width = t_star.copy(), np.asarray(b, float).copy(), np.asarray(b, float) - a
    final = np.zeros(n, bool)  # zoomed to the end: h at the middle of the last bracket
    act = np.arange(n)
    for step in range(ZOOM_STEPS):
        times = look_times(lo[act], hi[act], eta[act])
        h, solvable = _first_look_h(probe_h, act, times, scale) if step == 0 else probe_h(act, times)
        look = first_look(h, scale)
        ts, mid = times[:, :ZOOM_POINTS], h[:, :ZOOM_POINTS]
        limit = solvable & (look == LIMIT)
        j = np.argmin(np.where(limit[:, None], mid, np.inf), axis=1)[limit]
        t_star[act[limit]], h_min[act[limit]] = ts[limit, j], mid[limit, j]
        out = ~solvable | (look == CLEAR) if step == 0 else ~solvable
        t_star[act[out]] = lo[act[out]]
        go = np.nonzero(~out & ~limit)[0]
        up = h[go, 2 * ZOOM_POINTS :] >= h[go, ZOOM_POINTS : 2 * ZOOM_POINTS]  # g ≥ 0
        j = np.where(up.any(axis=1), np.argmax(up, axis=1), ZOOM_POINTS - 1)
        act = act[go]
        lo[act], hi[act] = ts[go, np.maximum(j - 1, 0)], ts[go, j]
        narrow = hi[act] - lo[act] <= 1e-9 * width[act]
        final[act[narrow]] = True
        act = act[~narrow]
        if not len(act):
            break
    final[act] = True
    which = np.nonzero(final)[0]
    if len(which):
        t_star[which] = 0.5 * (lo[which] + hi[which])
        h, solvable = probe_h(which, t_star[which][:, None])
        h_min[which] = np.where(solvable, h[:, 0], np.inf)
    return t_star, h_min


FIRST = np.r_[0 : ZOOM_POINTS + 1, 2 * ZOOM_POINTS - 1, 2 * ZOOM_POINTS, 3 * ZOOM_POINTS - 1]  # what a first look reads
REST = np.setdiff1d(np.arange(3 * ZOOM_POINTS), FIRST)  # ... and what the zoom reads besides: g inside the bracket


def _first_look_h(
    probe_h: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    which: np.ndarray,
    times: np.ndarray,
    scale: float,
) -> tuple[np.ndarray, np.ndarray]:
    """h at :func:`look_times` and whether every block closes there, as ``probe_h`` gives them, probed in two
    steps: what :func:`first_look` reads (h between the samples and g at the bracket's ends) for every bracket,
    the rest only for brackets it does not find CLEAR (most are: a broad minimum that dips between coarse
    samples). Entries not probed are NaN."""
    h = np.full(times.shape, np.nan)
    h[:, FIRST], solvable = probe_h(which, times[:, FIRST])
    rest = np.nonzero(solvable & (first_look(h, scale) != CLEAR))[0]
    if len(rest):
        h[np.ix_(rest, REST)], more = probe_h(which[rest], times[np.ix_(rest, REST)])
        solvable[rest] &= more
    return h, solvable


class _Discriminants:
    """Block ``i``'s discriminant at probe times of brackets that start at samples ``base``: for
    :func:`locate_minima`. Where the blocks before it are closed forms, every row is solved on its own, all at
    once (each on its branch at its time); past a Newton block, bracket by bracket, continued from its base."""

    def __init__(self, run: Run, state: State, t_grid: np.ndarray, i: int, base: np.ndarray) -> None:
        self.run, self.state, self.t_grid, self.i, self.base = run, state, t_grid, i, base

    def __call__(self, which: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        run, i = self.run, self.i
        if closed_forms_upto(run.system, i):
            try:  # (block i's own h < 0 is a limit between the samples, not a probe that failed)
                solved = dyads_at(run, times.reshape(-1), i, own=False)
            except MechanismError:  # a probe past the end of a tabulated input: bracket by bracket below
                solved = None
            if solved is not None:
                _, h, ok = solved
                return h.reshape(times.shape), ok.reshape(times.shape).all(axis=1)
        h = np.full(times.shape, np.inf)
        solvable = np.zeros(len(which), bool)
        for r, (w, ts) in enumerate(zip(which.tolist(), times, strict=True)):
            got = _discriminant(run, self.state, self.t_grid, int(self.base[w]), i, ts)
            if got is not None:
                h[r], solvable[r] = got, True
        return h, solvable


def closed_forms_upto(system: LoopSystem, i: int) -> bool:
    """Whether blocks 0..i are all closed-form dyads (rows are then solved each on its own)."""
    return all(plan.block.kind != "newton" for plan in block_plans(system)[: i + 1])


def dyads_at(
    run: Run,
    times: np.ndarray,
    upto: int,
    sigma: np.ndarray | None = None,
    rates: bool = False,
    health: bool = False,
    own: bool = True,
    inputs: Callable[[np.ndarray], tuple] | None = None,
) -> tuple:
    """Closed-form blocks 0..upto at ``times`` (any order: each row solved on its own, on each block's branch at
    its time; block ``upto`` on ``sigma`` if given), in chunks of ROWS rows. Returns the probe's state, block
    upto's discriminant h and whether every block closes, per row (block upto itself only if ``own``: else its
    h < 0 tells), and with ``health`` block upto's condition number; with ``rates``, velocities and
    accelerations. ``inputs``: the drivers' values as a function of time (default: the run's, a late start's
    lead-in path included). Raises MechanismError where a time is outside a tabulated input."""
    system = run.system
    n, na = len(times), system.n_angles
    trial = Probe(n, na, len(system.slider_names))
    order = np.argsort(times, kind="stable")  # (ascending: a lead-in path is told by the first time)
    inputs_at = run.inputs if inputs is None else inputs
    values = np.empty((3, n, len(system.drivers)))
    values[:, order] = inputs_at(times[order])
    impose_drivers(system, trial, *values)
    h, ok, cond = np.empty(n), np.ones(n, bool), np.empty(n)
    plans = block_plans(system)
    for start in range(0, n, ROWS):
        k = slice(start, min(start + ROWS, n))
        for b in range(upto + 1):
            plan = plans[b]
            s = sigma[k] if sigma is not None and b == upto else run.sigma(b, times[k])
            closes, h[k] = closed_form(plan, trial, k, s)
            if own or b < upto:
                ok[k] &= closes
            cols = jacobian_columns(plan, trial, k) if rates or (health and b == upto) else None
            if health and b == upto:
                cond[k] = dyad_health(plan, trial, k, run.scale, cols)[0]
            if rates:
                for what in ("v", "a"):
                    store_rates(plan, trial, k, dyad_rates(plan, trial, k, what, cols), what, na)
    return (trial, h, ok, cond) if health else (trial, h, ok)


ROWS = 16_000  # probe rows solved together (complex temporaries below numpy's in-place threshold, as a run's)


class _Continuations:
    """Which continuation keeps block ``i``'s rates continuous across each change point t* (after samples
    ``lo``): its rates at t* − η and t* + η on either branch, all at once where the blocks before it are closed
    forms (by probes from sample lo otherwise, as each is met)."""

    def __init__(self, run: Run, state: State, t_grid: np.ndarray, i: int, lo: np.ndarray, t_star: np.ndarray) -> None:
        self.run, self.state, self.t_grid, self.i, self.lo, self.t_star = run, state, t_grid, i, lo, t_star
        self.eta = times_to_move(run, t_star, t_grid[lo + 1] - t_grid[lo])
        self.rates: np.ndarray | None = None
        if len(lo) and closed_forms_upto(run.system, i):
            # per change point: t* − η and t* + η, each on σ = +1 and −1
            times = (t_star[:, None] + self.eta[:, None] * np.array([-1.0, -1.0, 1.0, 1.0])).reshape(-1)
            sigma = np.tile(np.array([1.0, -1.0, 1.0, -1.0]), len(lo))
            try:
                trial, _, ok = dyads_at(run, times, i, sigma, rates=True)
            except MechanismError:
                return
            r = _block_rates(run, trial, i, slice(0, len(times)))
            r[~ok] = np.nan
            self.rates = r.reshape(len(lo), 2, 2, -1)  # (change point, before/after, σ = +1/−1, unknown)

    def smooth_flip(self, k: int) -> bool:
        """Whether flipping σ at change point k keeps the rates continuous (else keeping it does), given the
        change points recorded before it."""
        run, i, t_star = self.run, self.i, float(self.t_star[k])
        if self.rates is None:
            return _smooth_continuation(run, self.state, self.t_grid, i, int(self.lo[k]), t_star)
        eta = float(self.eta[k])
        before, after = run.sigma(i, np.array([t_star - eta, t_star + eta]))
        side = {1.0: 0, -1.0: 1}
        r0 = self.rates[k, 0, side[before]]
        jumps = [float(np.max(np.abs(self.rates[k, 1, side[s]] - r0))) for s in (-after, after)]
        jumps = [math.inf if math.isnan(j) else j for j in jumps]
        return jumps[0] <= jumps[1]


def _discriminant(
    run: Run, state: State, t_grid: np.ndarray, base: int, i: int, times: np.ndarray
) -> np.ndarray | None:
    """Block ``i``'s discriminant h at ``times`` by a probe continued from sample ``base`` (None if a block
    fails there)."""
    order = np.argsort(times, kind="stable")
    solved, _ = probe(run, state, t_grid, base, times[order], i, check=False, rates=False)
    if solved.n_ok < len(times) + 1 or len(solved.discs) <= i:
        return None
    h = np.empty(len(times))
    h[order] = solved.discs[i][1:]
    return h


def time_to_move(run: Run, t_star: float, width: float, move: float = ETA_INPUT) -> float:
    """A time offset over which the inputs move ``move`` (radians, or mechanism sizes for sliders)."""
    return float(times_to_move(run, np.array([t_star]), np.array([width]), move)[0])


def times_to_move(run: Run, t: np.ndarray, width: np.ndarray, move: float = ETA_INPUT) -> np.ndarray:
    """:func:`time_to_move` at each of the times ``t`` (at most a quarter of each ``width``)."""
    order = np.argsort(t, kind="stable")  # (ascending: a lead-in path is told by the first time)
    XD = np.empty((len(t), len(run.system.mechanism.drivers)))
    XD[order] = run.inputs(t[order])[1]
    return eta_of_rates(XD, input_units(run.system.mechanism, run.scale), width, move)


def _block_rates(run: Run, trial: State, i: int, rows: slice) -> np.ndarray:
    """Block ``i``'s unknown rates (angles: rad/s; sliders: sizes/s) on ``rows`` of a probe."""
    plan = block_plans(run.system)[i]
    na = run.system.n_angles
    return np.stack(
        [trial.omega[rows, v] if v < na else trial.s_dot[rows, v - na] / run.scale for v in plan.block.unknowns], 1
    )


def _smooth_continuation(run: Run, state: State, t_grid: np.ndarray, i: int, lo: int, t_star: float) -> bool:
    """Whether flipping σ at ``t_star`` keeps block ``i``'s rates continuous (else keeping it does)."""
    eta = time_to_move(run, t_star, float(t_grid[lo + 1] - t_grid[lo]))
    ts = np.array([t_star - eta, t_star + eta])
    jumps = []
    for flip in (True, False):
        run.events.setdefault(i, []).append(ChangePoint(i, t_star, flip, True))
        try:
            solved, trial = probe(run, state, t_grid, lo, ts, i, check=False)
        finally:
            run.events[i].pop()
        if solved.n_ok < 3:
            jumps.append(math.inf)
            continue
        r = _block_rates(run, trial, i, slice(1, 3))
        jumps.append(float(np.max(np.abs(r[1] - r[0]))))
    return jumps[0] <= jumps[1]


STENCIL = np.r_[-8:0, 1:9].astype(float)  # rates across a change point: interpolated (degree 15) from these


STENCIL_INPUT = 0.05  # ... multiples of at most the time in which the inputs move this far (rad, or sizes)
STENCIL_COND = 100.0  # ... and of the time from the change point at which the condition number falls to this


def near_change_point(run: Run, i: int, t: np.ndarray, cond: np.ndarray) -> np.ndarray:
    """Rows next to a change point whose rates the direct solve cannot deliver to ``rtol``: their accelerations'
    bound ρ·cond³·ε above it (ρ: the round-off the block's known part carries, :func:`roundoff_factor`).
    :func:`rates_across` keeps the better of theirs and the interpolated ones; rows merely ill-conditioned (within
    rtol, above its flag level) keep their direct rates, flagged in health.
    """
    near = np.zeros(len(t), bool)
    events = run.events.get(i, ())
    if not events or not run.check:
        return near
    refused = roundoff_factor(run, i) * error_bound(cond) > run.rtol
    for ev in events:
        reach = 4.0 * time_to_move(run, ev.time, math.inf, STENCIL_INPUT)
        near |= refused & (np.abs(t - ev.time) < reach)
    return near


def roundoff_factor(run: Run, i: int) -> float:
    """How much more round-off block ``i``'s positions carry than ε of the mechanism's size: the magnitudes its
    known part is summed from (a ground chord counts the pivots' distances from the origin) over the size, at
    least 1. Its rates' error bounds next to a change point grow with it (cond²·ε, cond³·ε times this)."""
    plan = block_plans(run.system)[i]
    sizes = plan.sizes[plan.known]
    return max(1.0, float(np.max(np.sum(sizes, axis=0), initial=0.0)) / run.scale)


def rates_across(
    run: Run, state: State, t_grid: np.ndarray, i: int, plan: Plan, rows: np.ndarray, out: Solved, cond: np.ndarray
) -> None:
    """Rates of block ``i`` at rows next to a change point, where its Jacobian is (nearly) singular.

    Interpolated (degree 15) from the smooth branch at t* ± k·η, k = 1..8, η where the condition number falls
    to STENCIL_COND (the stencil's own points then carry ~STENCIL_COND²·ε in their velocities, STENCIL_COND³·ε
    in their accelerations), and again at 2η: their difference bounds the narrower one's truncation error
    (conservatively: it falls like η¹⁶ once the stencil resolves the branch). Each row keeps, for its velocities
    and its accelerations apart, whichever is better: the interpolated ones (that estimate) or its direct ones
    (their bounds cond²·ε and cond³·ε). The stencils of every change point are probed at once, on the file's
    motion (also before a late start's first time) and on the branches either side of their change point.
    """
    events = run.events[i]
    t_star = np.array([ev.time for ev in events])
    widest = times_to_move(run, t_star, np.full(len(t_star), math.inf), STENCIL_INPUT)  # (η is at most this)
    t_rows = t_grid[rows]
    reach = np.abs(t_rows[None, :] - t_star[:, None]) < 8.0 * widest[:, None]
    k = np.nonzero(reach.any(axis=1))[0]
    if not len(k):
        return
    sides = [_sides(run, i, events[j]) for j in k.tolist()]
    t_star, widest = t_star[k], widest[k]
    eta = _stencil_eta(run, state, t_grid, i, t_star, widest, sides)
    near = np.abs(t_rows[None, :] - t_star[:, None]) < 8.0 * eta[:, None]
    k = np.nonzero(near.any(axis=1))[0]
    stencils = [t_star[j] + f * eta[j] * STENCIL for j in k for f in (1.0, 2.0)]  # narrow, then wide
    sigma = [np.where(STENCIL < 0, *sides[j]) for j in k for _ in (1.0, 2.0)]
    probed = _probe_groups(run, state, t_grid, i, stencils, rates=True, sigma=sigma)
    for n, j in enumerate(k.tolist()):
        narrow, wide = probed[2 * n], probed[2 * n + 1]
        if narrow is None or wide is None:
            continue  # a stencil leaves the feasible range: keep the direct rates (flagged)
        mine = rows[near[j]]
        u = (t_grid[mine] - t_star[j]) / eta[j]
        _keep_better(run, plan, (mine, cond[mine], u), roundoff_factor(run, i), (narrow, wide), state, out)


def _keep_better(
    run: Run,
    plan: Plan,
    at: tuple[np.ndarray, np.ndarray, np.ndarray],
    rho: float,
    stencils: tuple[_Probed, _Probed],
    state: State,
    out: Solved,
) -> None:
    """Store at rows ``at`` = (rows, their condition numbers, their stencil coordinates u) the interpolated
    velocities, and accelerations, where they are better than the direct ones: the stencil's error estimate (the
    narrow and wide stencils' difference, and its own points' round-off) against ρ·cond²·ε (ρ·cond³·ε) of the
    rates' scale, ρ the round-off factor of the block's known part (:func:`roundoff_factor`)."""
    rows, cond, u = at
    narrow, wide = stencils
    narrow_at, wide_at = _interpolated(narrow, u), _interpolated(wide, 0.5 * u)
    for what, power in (("v", 2), ("a", 3)):
        scale = _rate_scale(run, plan, narrow_at["scale_" + what], narrow_at["scale_v"], what)
        err_stencil = np.abs(narrow_at[what] - wide_at[what]) + rho * STENCIL_COND**power * EPS * scale
        err_direct = (rho * cond**power * EPS)[:, None] * scale
        use = np.all(err_stencil < err_direct, axis=1)
        if use.any():
            store_rates(plan, state, rows[use], narrow_at[what][use], what, run.system.n_angles)
            out.at_change[rows[use]] = True


def _sides(run: Run, i: int, ev: ChangePoint) -> tuple[float, float]:
    """Block ``i``'s branch σ just before and just after the change point ``ev`` (the stencil's two halves)."""
    before = float(run.sigma(i, np.array([ev.time]))[0])  # (the flips strictly before t*)
    return before, (-before if ev.flip else before)


@dataclass
class _Probed:
    """Block ``i``'s condition number (rows,) and the rates of its unknowns (rows, unknowns: ω [rad/s], ṡ
    [length/s]; α, s̈) at a group of probe times."""

    cond: np.ndarray
    v: np.ndarray
    a: np.ndarray


def _probe_groups(
    run: Run,
    state: State,
    t_grid: np.ndarray,
    i: int,
    groups: list[np.ndarray],
    rates: bool,
    sigma: list[np.ndarray] | None = None,
) -> list[_Probed | None]:
    """Blocks 0..i solved at each group of times (ascending), on the run's branches (block i on ``sigma``, per
    group, where given): block i's condition number and (with ``rates``) its rates there, or None for a group
    where a block cannot be solved. Every row at once, on the file's motion, where blocks 0..i are closed forms;
    else a probe per group, continued from the sample before its first time."""
    plan = block_plans(run.system)[i]
    if closed_forms_upto(run.system, i) and groups:
        own = np.concatenate(sigma) if sigma is not None else None
        try:
            trial, _, ok, cond = dyads_at(
                run, np.concatenate(groups), i, own, rates=rates, health=True, inputs=Inputs(run.system.mechanism)
            )
        except MechanismError:  # a probe past the end of a tabulated input: group by group below
            trial = None
        if trial is not None:
            v, a = _unknown_rates(run, trial, plan, slice(None))
            ends = np.cumsum([0] + [len(g) for g in groups])
            return [
                _Probed(cond[p:q], v[p:q], a[p:q]) if ok[p:q].all() else None
                for p, q in zip(ends[:-1].tolist(), ends[1:].tolist(), strict=True)
            ]
    out: list[_Probed | None] = []
    for g in groups:
        base = max(int(np.searchsorted(t_grid, g[0])) - 1, 0)
        solved, trial = probe(run, state, t_grid, base, g, i, check=False, rates=rates)
        if solved.n_ok < len(g) + 1 or len(solved.conds) <= i:
            out.append(None)
            continue
        v, a = _unknown_rates(run, trial, plan, slice(1, None))
        out.append(_Probed(solved.conds[i][1:], v, a))
    return out


def _unknown_rates(run: Run, trial: State, plan: Plan, rows: slice) -> tuple[np.ndarray, np.ndarray]:
    """The rates and accelerations of a block's unknowns on ``rows`` of a probe, (rows, unknowns) each."""
    na = run.system.n_angles
    return tuple(
        np.stack([ang[rows, v] if v < na else sl[rows, v - na] for v in plan.block.unknowns], 1)
        for ang, sl in ((trial.omega, trial.s_dot), (trial.alpha, trial.s_ddot))
    )


def _interpolated(probed: _Probed, u: np.ndarray) -> dict[str, np.ndarray]:
    """The rates at stencil coordinates ``u`` (multiples of its step from t*) by the polynomial through the
    stencil's (its Lagrange basis at u: no Vandermonde system), and their magnitudes."""
    x = STENCIL
    diff = np.asarray(u, float)[:, None, None] - x[None, None, :]  # (rows, node k, node j): u − x_j
    span = x[:, None] - x[None, :]
    off = ~np.eye(len(x), dtype=bool)
    basis = np.prod(np.where(off, diff / np.where(off, span, 1.0), 1.0), axis=2)  # Π_{j≠k} (u − x_j)/(x_k − x_j)
    out = {}
    for what, vals in (("v", probed.v), ("a", probed.a)):
        out[what] = basis @ vals
        out["scale_" + what] = np.max(np.abs(vals), axis=0)
    return out


def _rate_scale(run: Run, plan: Plan, scale: np.ndarray, scale_v: np.ndarray, what: str) -> np.ndarray:
    """Per unknown, the magnitude its rate's error is relative to: the largest of its kind (angles together,
    sliders together), and for accelerations at least ω_max times the rates of that kind — an acceleration is
    a difference of such terms even where it is itself small (a parallelogram's coupler: α ≡ 0)."""
    angle = np.array([v < run.system.n_angles for v in plan.block.unknowns])
    omega = float(np.max(scale_v[angle], initial=0.0))
    base = scale if what == "v" else np.maximum(scale, omega * scale_v)
    out = np.empty(len(angle))
    for kind in (True, False):
        if np.any(angle == kind):
            out[angle == kind] = np.max(base[angle == kind])
    return out


def _stencil_eta(
    run: Run,
    state: State,
    t_grid: np.ndarray,
    i: int,
    t_star: np.ndarray,
    widest: np.ndarray,
    sides: list[tuple[float, float]],
) -> np.ndarray:
    """The stencil's step [s] at each change point t*: where block ``i``'s condition number falls to STENCIL_COND
    (it grows like 1/|t − t*| next to a change point), at most ``widest`` (the time the inputs take to move
    STENCIL_INPUT). ``sides``: block i's branch σ before and after each t*."""
    d = 0.02 * widest
    groups = [np.array([t - e, t + e]) for t, e in zip(t_star, d, strict=True)]
    sigma = [np.array(side) for side in sides]
    looks = _probe_groups(run, state, t_grid, i, groups, False, sigma=sigma)
    eta = widest.copy()
    for j, look in enumerate(looks):
        if look is not None:
            k = float(np.min(look.cond)) * d[j]  # cond·|t − t*|, about constant near the change point
            eta[j] = float(np.clip(k / STENCIL_COND, 0.02 * widest[j], widest[j]))
    return eta


def find_singular_points(run: Run, state: State, t_grid: np.ndarray, i: int, cond: np.ndarray) -> None:
    """A redundant (least-squares) Newton block has a single branch: where its Jacobian loses rank between
    well-conditioned samples (a double parallelogram folding), the continuation went on smoothly, and the
    rates next to that point are interpolated across it as at a change point (event kind "singular")."""
    rows = np.nonzero(error_bound(cond) > run.rtol)[0]
    if not len(rows) or not run.detect:
        return
    for seg in np.split(rows, np.nonzero(np.diff(rows) > 1)[0] + 1):
        lo, hi = int(seg[0]) - 1, int(seg[-1]) + 1
        if lo < 0 or hi >= len(cond):
            continue  # not passed (yet): the motion stops there, or the next chunk decides
        if any(t_grid[lo] <= ev.time <= t_grid[hi] for ev in run.events.get(i, ())):
            continue
        t_star = _cond_peak(run, state, t_grid, i, lo, hi)
        if t_star is not None:
            run.events.setdefault(i, []).append(ChangePoint(i, t_star, False, True, "singular"))


def _cond_peak(run: Run, state: State, t_grid: np.ndarray, i: int, lo: int, hi: int) -> float | None:
    """Where block ``i``'s condition number peaks between samples lo and hi (zooming probes)."""
    a, b = float(t_grid[lo]), float(t_grid[hi])
    for step in range(ZOOM_STEPS):
        ts = np.linspace(a, b, ZOOM_POINTS)
        solved, _ = probe(run, state, t_grid, lo, ts, i, check=False, rates=False)
        if solved.n_ok < len(ts) + 1 or len(solved.conds) <= i:  # Newton gave up right at the singular point
            return None if step == 0 else 0.5 * (a + b)
        j = int(np.argmax(solved.conds[i][1:]))
        a, b = float(ts[max(j - 1, 0)]), float(ts[min(j + 1, len(ts) - 1)])
        if b - a <= 1e-9 * (t_grid[hi] - t_grid[lo]):
            break
    return 0.5 * (a + b)
