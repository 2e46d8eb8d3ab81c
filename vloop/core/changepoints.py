"""Change points of closed-form dyads: where a block's two assembly branches meet between samples.

A sampled minimum of the dyad's discriminant h (the two solutions lie 2·√h apart) is refined by
zooming probes; where the branches come within CHANGE_GAP of the mechanism size it is a change
point, continued on the branch whose rates stay continuous (or the other one, as the file asks).
Rates at rows next to one, where the Jacobian is singular, come from a well-conditioned stencil.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..errors import MechanismError
from .kernels import (
    EPS,
    _change_point_choices,
    _ChangePoint,
    _error_bound,
    _Failure,
    _impose_drivers,
    _Plan,
    _plans,
    _Run,
    _Solved,
    _State,
    _store,
)

CHANGE_GAP = 1e-6  # two assembly branches closer than this fraction of the mechanism size meet: a change point


ZOOM_POINTS = 17  # probes per zoom step when locating where two branches meet


ZOOM_STEPS = 12  # each step narrows the bracket 16-fold


ETA_INPUT = 1e-5  # the rates across a change point are compared this far from it (input units: rad, or size)
DIP = 0.9  # a sampled minimum of h below this fraction of its larger neighbour is zoomed on


def _candidate_minima(t: np.ndarray, h: np.ndarray, tail: bool = True) -> list[tuple[int, int]]:
    """Brackets (row lo, row hi) around sampled minima of h that dip: where a zero could hide between samples.

    Near a double zero √h is V-shaped, so a sample next to it is well below its larger neighbour
    (h below 1/4 of it for an even V) whatever the sampling's phase; a broad, shallow minimum keeps
    the three samples alike and is left alone. A dip is only a candidate: the zoom decides.
    ``tail``: also look between the last two samples (the end of the run, not of a chunk: the next
    chunk sees that minimum with both its neighbours).
    """
    n = len(h)
    if n < 2:
        return []
    m = np.nonzero((h[1:-1] <= h[:-2]) & (h[1:-1] <= h[2:]))[0] + 1
    dips = m[h[m] < DIP * np.maximum(h[m - 1], h[m + 1])]
    out = [(int(c) - 1, int(c) + 1) for c in dips]
    if n > 2 and h[0] < DIP * h[1] and h[1] <= h[2]:  # rising from the first sample: a zero may lie just after it
        out.insert(0, (0, 1))
    if tail and h[-1] < DIP * h[-2]:  # still falling at the end: a zero may lie before the last sample
        out.append((n - 2, n - 1))
    return out


def _probe(run: _Run, st: _State, tg: np.ndarray, base: int, times: np.ndarray, upto: int, **mode: bool) -> tuple:
    """Solve blocks 0..upto at ``times`` (ascending, after sample ``base``), continuing from sample ``base``.

    Returns (the _Solved record, the probe's state); row 0 of the probe is sample ``base``.
    """
    sys = run.sys
    grid = np.concatenate([[tg[base]], times])
    trial = _State(len(grid), sys.n_angles, len(sys.slider_names))
    for name in ("E", "TH", "S"):
        getattr(trial, name)[0] = getattr(st, name)[base]
    try:
        _impose_drivers(sys, trial, *run.inputs(grid))
    except MechanismError:  # a probe past the end of a tabulated input: nothing to learn there
        return _Solved(0, None, [], [], [], np.zeros(0, bool)), trial
    sub = dataclasses.replace(run, detect=False, **mode)  # shares the events found so far
    return sub.blocks(sub, trial, grid, len(grid), upto=upto), trial


def _find_change_points(run: _Run, st: _State, tg: np.ndarray, i: int, h: np.ndarray) -> list[_ChangePoint]:
    """Locate where block ``i``'s two assembly branches meet between samples, and pick the continuation.

    A sampled minimum of the discriminant h is refined by zooming probes; where the branches come
    within CHANGE_GAP of the mechanism size of each other it is a change point. The continuation
    is the one whose rates stay continuous across it (or the other one where the file asks so in
    ``[solver] change_points``). h < 0 between samples means the motion passes a limit there.
    """
    found = []
    loop = run.sys.loops[_plans(run.sys)[i].block.loops[0]]
    choices = _change_point_choices(run.sys, loop.index + 1)
    for lo, hi in _candidate_minima(tg[: len(h)], h, run.tail):
        if any(tg[lo] <= ev.time <= tg[hi] for ev in run.events.get(i, ())):
            continue  # found already (by the chunk before, whose last rows this chunk starts from)
        t_star, h_min = _zoom(run, st, tg, i, lo, hi)
        if h_min < 0:
            raise _Failure(hi, loop.index, "the loop cannot close between samples: the input passes a limit position")
        if 2.0 * math.sqrt(h_min) > CHANGE_GAP * run.scale:
            continue
        smooth_flip = _smooth_continuation(run, st, tg, i, lo, t_star)
        choice = choices[min(len(found), len(choices) - 1)]
        flip = smooth_flip if choice == "smooth" else not smooth_flip
        ev = _ChangePoint(i, t_star, flip, choice == "smooth")
        run.events.setdefault(i, []).append(ev)
        found.append(ev)
    return found


def _zoom(run: _Run, st: _State, tg: np.ndarray, i: int, lo: int, hi: int) -> tuple[float, float]:
    """(t*, h(t*)): where block ``i``'s discriminant h is least between samples lo and hi.

    Zooms on the sign change of g(t) = h(t + η) − h(t − η), which crosses zero linearly at the
    minimum (h itself is flat there), so t* is found to ~1e-12 of the bracket, not to √ε.
    """
    a, b = float(tg[lo]), float(tg[hi])
    eta = _eta(run, 0.5 * (a + b), b - a)
    first = True
    for _ in range(ZOOM_STEPS):
        ts = np.linspace(a, b, ZOOM_POINTS)
        h = _discriminant(run, st, tg, lo, i, np.concatenate([ts, ts - eta, ts + eta]))
        if h is None:  # an earlier block cannot be solved in the bracket: leave it to the main run
            return a, math.inf
        mid, g = h[: len(ts)], h[2 * len(ts) :] - h[len(ts) : 2 * len(ts)]
        if np.any(mid < 0):
            j = int(np.argmin(mid))
            return float(ts[j]), float(mid[j])
        if first and not (g[0] < 0 <= g[-1]):  # h least at an end of the bracket: no minimum inside it
            return a, math.inf  # (e.g. a limit approached but not passed: h falls to the last sample)
        root = np.sqrt(mid)  # √h is Lipschitz: no lower between grid points than this bound allows (the
        # slope is taken twice the largest seen, since √h bends: steepest at its vertex, between grid points)
        if first and root.min() - np.max(np.abs(np.diff(root))) > 0.5 * CHANGE_GAP * run.scale:
            j = int(np.argmin(mid))
            return float(ts[j]), float(mid[j])  # the branches stay apart: no change point here
        first = False
        j = int(np.argmax(g >= 0)) if np.any(g >= 0) else len(ts) - 1
        a, b = float(ts[max(j - 1, 0)]), float(ts[j])
        if b - a <= 1e-9 * (tg[hi] - tg[lo]):
            break
    t_star = 0.5 * (a + b)
    h = _discriminant(run, st, tg, lo, i, np.array([t_star]))
    return t_star, (math.inf if h is None else float(h[0]))


def _discriminant(run: _Run, st: _State, tg: np.ndarray, base: int, i: int, times: np.ndarray) -> np.ndarray | None:
    """Block ``i``'s discriminant h at ``times`` (None if an earlier block fails there)."""
    order = np.argsort(times, kind="stable")
    solved, _ = _probe(run, st, tg, base, times[order], i, check=False, rates=False)
    if solved.n_ok < len(times) + 1 or len(solved.discs) <= i:
        return None
    h = np.empty(len(times))
    h[order] = solved.discs[i][1:]
    return h


def _eta(run: _Run, t_star: float, width: float, move: float = ETA_INPUT) -> float:
    """A time offset over which the inputs move ``move`` (radians, or mechanism sizes for sliders)."""
    _, XD, _ = run.inputs(np.array([t_star]))
    units = np.array([1.0 if d.kind == "crank" else run.scale for d in run.sys.mechanism.drivers])
    rate = float(np.max(np.abs(XD[0]) / units, initial=0.0))
    return min(move / rate if rate > 0 else math.inf, 0.25 * width)


def _block_rates(run: _Run, trial: _State, i: int, rows: slice) -> np.ndarray:
    """Block ``i``'s unknown rates (angles: rad/s; sliders: sizes/s) on ``rows`` of a probe."""
    p = _plans(run.sys)[i]
    na = run.sys.n_angles
    return np.stack([trial.W[rows, v] if v < na else trial.SD[rows, v - na] / run.scale for v in p.block.unknowns], 1)


def _smooth_continuation(run: _Run, st: _State, tg: np.ndarray, i: int, lo: int, t_star: float) -> bool:
    """Whether flipping σ at ``t_star`` keeps block ``i``'s rates continuous (else keeping it does)."""
    eta = _eta(run, t_star, float(tg[lo + 1] - tg[lo]))
    ts = np.array([t_star - eta, t_star + eta])
    jumps = []
    for flip in (True, False):
        run.events.setdefault(i, []).append(_ChangePoint(i, t_star, flip, True))
        try:
            solved, trial = _probe(run, st, tg, lo, ts, i, check=False)
        finally:
            run.events[i].pop()
        if solved.n_ok < 3:
            jumps.append(math.inf)
            continue
        r = _block_rates(run, trial, i, slice(1, 3))
        jumps.append(float(np.max(np.abs(r[1] - r[0]))))
    return jumps[0] <= jumps[1]


STENCIL = np.array([-4, -3, -2, -1, 1, 2, 3, 4], float)  # rates across a change point: interpolated from these


STENCIL_INPUT = 0.05  # ... multiples of at most the time in which the inputs move this far (rad, or sizes)
STENCIL_COND = 100.0  # ... and of the time from the change point at which the condition number falls to this


def _near_change_point(run: _Run, i: int, t: np.ndarray, cond: np.ndarray) -> np.ndarray:
    """Rows next to a change point whose rates the direct solve cannot deliver to ``rtol`` (cond³·ε above it).

    Rows merely ill-conditioned (within rtol, above its flag level) keep their direct rates, flagged in health.
    """
    near = np.zeros(len(t), bool)
    events = run.events.get(i, ())
    if not events or not run.check:
        return near
    refused = _error_bound(cond) > run.rtol
    for ev in events:
        reach = 4.0 * _eta(run, ev.time, math.inf, STENCIL_INPUT)
        near |= refused & (np.abs(t - ev.time) < reach)
    return near


def _rates_across(
    run: _Run, st: _State, tg: np.ndarray, i: int, p: _Plan, rows: np.ndarray, out: _Solved, cond: np.ndarray
) -> None:
    """Rates of block ``i`` at rows next to a change point, where its Jacobian is (nearly) singular.

    Interpolated (degree 7) from the smooth branch at t* ± k·η, k = 1..4, η where the condition number
    falls to STENCIL_COND (the stencil's own points then carry ~STENCIL_COND³·ε), and again at 2η: their
    difference bounds the narrower one's truncation error (conservatively: where the branch bends fast the
    error does not yet fall like η⁸). Each row keeps whichever is better: the interpolated rates (that
    estimate) or its direct ones (their bound cond³·ε).
    """
    for ev in run.events[i]:
        eta = _stencil_eta(run, st, tg, i, ev.time)
        near = np.abs(tg[rows] - ev.time) < 8.0 * eta
        mine = rows[near]
        if not len(mine):
            continue
        narrow = _stencil_rates(run, st, tg, i, p, ev.time, eta, tg[mine])
        wide = _stencil_rates(run, st, tg, i, p, ev.time, 2.0 * eta, tg[mine])
        if narrow is None or wide is None:
            continue  # a stencil leaves the feasible range: keep the direct rates (flagged)
        use = np.zeros(len(mine), bool)
        for what in ("v", "a"):
            scale = _rate_scale(run, p, narrow["scale_" + what], narrow["scale_v"], what)
            err_stencil = np.abs(narrow[what] - wide[what]) + STENCIL_COND**3 * EPS * scale
            err_direct = (cond[mine] ** 3 * EPS)[:, None] * scale
            use |= np.all(err_stencil < err_direct, axis=1)
        if use.any():
            for what in ("v", "a"):
                _store(p, st, mine[use], narrow[what][use], what, run.sys.n_angles)
            out.at_change[mine[use]] = True


def _stencil_rates(
    run: _Run, st: _State, tg: np.ndarray, i: int, p: _Plan, t_star: float, eta: float, at: np.ndarray
) -> dict[str, np.ndarray] | None:
    """Block ``i``'s rates interpolated at times ``at`` from the stencil t* ± k·η, and their magnitudes."""
    na = run.sys.n_angles
    base = max(int(np.searchsorted(tg, t_star - 4.0 * eta)) - 1, 0)
    solved, trial = _probe(run, st, tg, base, t_star + eta * STENCIL, i, check=False)
    if solved.n_ok < len(STENCIL) + 1:
        return None
    u = (at - t_star) / eta
    out = {}
    for what, ang, sl in (("v", trial.W, trial.SD), ("a", trial.AL, trial.SDD)):
        vals = np.stack([ang[1:, v] if v < na else sl[1:, v - na] for v in p.block.unknowns], 1)
        fit = np.polynomial.polynomial.polyfit(STENCIL, vals, len(STENCIL) - 1)
        out[what] = np.polynomial.polynomial.polyval(u, fit).T
        out["scale_" + what] = np.max(np.abs(vals), axis=0)
    return out


def _rate_scale(run: _Run, p: _Plan, scale: np.ndarray, scale_v: np.ndarray, what: str) -> np.ndarray:
    """Per unknown, the magnitude its rate's error is relative to: the largest of its kind (angles together,
    sliders together), and for accelerations at least ω_max times the rates of that kind — an acceleration is
    a difference of such terms even where it is itself small (a parallelogram's coupler: α ≡ 0)."""
    angle = np.array([v < run.sys.n_angles for v in p.block.unknowns])
    omega = float(np.max(scale_v[angle], initial=0.0))
    base = scale if what == "v" else np.maximum(scale, omega * scale_v)
    out = np.empty(len(angle))
    for kind in (True, False):
        if np.any(angle == kind):
            out[angle == kind] = np.max(base[angle == kind])
    return out


def _stencil_eta(run: _Run, st: _State, tg: np.ndarray, i: int, t_star: float) -> float | None:
    """The stencil's step [s]: where block ``i``'s condition number falls to STENCIL_COND (it grows like
    1/|t − t*| next to a change point), at most the time the inputs take to move STENCIL_INPUT."""
    widest = _eta(run, t_star, math.inf, STENCIL_INPUT)
    d = 0.02 * widest
    base = max(int(np.searchsorted(tg, t_star - d)) - 1, 0)
    solved, _ = _probe(run, st, tg, base, np.array([t_star - d, t_star + d]), i, check=False, rates=False)
    if solved.n_ok < 3 or len(solved.conds) <= i:
        return widest
    k = float(np.min(solved.conds[i][1:])) * d  # cond·|t − t*|, about constant near the change point
    return float(np.clip(k / STENCIL_COND, 0.02 * widest, widest))


def find_singular_points(run: _Run, st: _State, tg: np.ndarray, i: int, cond: np.ndarray) -> None:
    """A redundant (least-squares) Newton block has a single branch: where its Jacobian loses rank between
    well-conditioned samples (a double parallelogram folding), the continuation went on smoothly, and the
    rates next to that point are interpolated across it as at a change point (event kind "singular")."""
    rows = np.nonzero(_error_bound(cond) > run.rtol)[0]
    if not len(rows) or not run.detect:
        return
    for seg in np.split(rows, np.nonzero(np.diff(rows) > 1)[0] + 1):
        lo, hi = int(seg[0]) - 1, int(seg[-1]) + 1
        if lo < 0 or hi >= len(cond):
            continue  # not passed (yet): the motion stops there, or the next chunk decides
        if any(tg[lo] <= ev.time <= tg[hi] for ev in run.events.get(i, ())):
            continue
        t_star = _cond_peak(run, st, tg, i, lo, hi)
        if t_star is not None:
            run.events.setdefault(i, []).append(_ChangePoint(i, t_star, False, True, "singular"))


def _cond_peak(run: _Run, st: _State, tg: np.ndarray, i: int, lo: int, hi: int) -> float | None:
    """Where block ``i``'s condition number peaks between samples lo and hi (zooming probes)."""
    a, b = float(tg[lo]), float(tg[hi])
    for step in range(ZOOM_STEPS):
        ts = np.linspace(a, b, ZOOM_POINTS)
        solved, _ = _probe(run, st, tg, lo, ts, i, check=False, rates=False)
        if solved.n_ok < len(ts) + 1 or len(solved.conds) <= i:  # Newton gave up right at the singular point
            return None if step == 0 else 0.5 * (a + b)
        j = int(np.argmax(solved.conds[i][1:]))
        a, b = float(ts[max(j - 1, 0)]), float(ts[min(j + 1, len(ts) - 1)])
        if b - a <= 1e-9 * (tg[hi] - tg[lo]):
            break
    return 0.5 * (a + b)
