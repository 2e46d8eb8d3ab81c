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

from .errors import MechanismError
from .kernels import (
    ILL_FRACTION,
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


def _candidate_minima(t: np.ndarray, h: np.ndarray, tail: bool = True) -> list[tuple[int, int]]:
    """Brackets (row lo, row hi) around sampled minima of h deep enough to hide a zero between samples.

    Near a double zero h ≈ c·(t − t*)², so a parabola through three samples has its minimum
    near 0 whatever the phase of the sampling; a broad minimum keeps it near the samples.
    ``tail``: also look between the last two samples (the end of the run, not of a chunk: the
    next chunk sees that minimum with both its neighbours).
    """
    n = len(h)
    if n < 2:
        return []
    out = []
    m = np.nonzero((h[1:-1] <= h[:-2]) & (h[1:-1] <= h[2:]))[0] + 1
    for c in m:
        if _parabola_low(t, h, c, c - 1, c + 1) <= 0.25 * min(h[c - 1], h[c + 1]):
            out.append((c - 1, c + 1))
    if tail and h[-1] < h[-2]:  # still falling at the end: a zero may lie before the last sample
        if n < 3 or _parabola_low(t, h, n - 2, n - 2, n - 1) <= 0.25 * h[-1]:
            out.append((n - 2, n - 1))
    return out


def _parabola_low(t: np.ndarray, h: np.ndarray, c: int, lo: int, hi: int) -> float:
    """The least value over [t[lo], t[hi]] of the parabola through samples c − 1, c, c + 1 of h."""
    u0, u2 = t[c - 1] - t[c], t[c + 1] - t[c]
    g0, g2 = (h[c - 1] - h[c]) / u0, (h[c + 1] - h[c]) / u2
    a = (g0 - g2) / (u0 - u2)  # h ≈ h[c] + b·u + a·u² through the three samples
    b = g0 - a * u0
    if not a > 0:
        return float(min(h[lo], h[hi]))
    u = min(max(-b / (2 * a), t[lo] - t[c]), t[hi] - t[c])
    return float(h[c] + b * u + a * u * u)


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


STENCIL_INPUT = 0.05  # ... multiples of the time in which the inputs move this far (rad, or sizes)


def _near_change_point(run: _Run, i: int, t: np.ndarray, cond: np.ndarray) -> np.ndarray:
    """Rows too ill-conditioned for accurate rates that lie within a change point's stencil."""
    near = np.zeros(len(t), bool)
    events = run.events.get(i, ())
    if not events or not run.check:
        return near
    weak = _error_bound(cond) > run.rtol * ILL_FRACTION
    for ev in events:
        reach = 4.0 * _eta(run, ev.time, math.inf, STENCIL_INPUT)
        near |= weak & (np.abs(t - ev.time) < reach)
    return near


def _rates_across(run: _Run, st: _State, tg: np.ndarray, i: int, p: _Plan, rows: np.ndarray, out: _Solved) -> None:
    """Rates of block ``i`` at rows next to a change point, where its Jacobian is (nearly) singular:
    interpolated (degree 7) from the smooth branch at t* ± k·η, k = 1..4, where it is well conditioned."""
    na = run.sys.n_angles
    for ev in run.events[i]:
        eta = _eta(run, ev.time, math.inf, STENCIL_INPUT)
        mine = rows[np.abs(tg[rows] - ev.time) < 4.0 * eta]
        if not len(mine):
            continue
        base = max(int(np.searchsorted(tg, ev.time - 4.0 * eta)) - 1, 0)
        solved, trial = _probe(run, st, tg, base, ev.time + eta * STENCIL, i, check=False)
        if solved.n_ok < len(STENCIL) + 1:
            continue  # the stencil leaves the feasible range: keep the direct rates (flagged)
        u = (tg[mine] - ev.time) / eta
        for what, ang, sl in (("v", trial.W, trial.SD), ("a", trial.AL, trial.SDD)):
            vals = np.stack([ang[1:, v] if v < na else sl[1:, v - na] for v in p.block.unknowns], 1)
            fit = np.polynomial.polynomial.polyfit(STENCIL, vals, len(STENCIL) - 1)
            _store(p, st, mine, np.polynomial.polynomial.polyval(u, fit).T, what, na)
        out.at_change[mine] = True
