"""The mechanism's functions of its input q, tabulated once from vloop's loop solve.

With one degree of freedom every position is a function of the input q (the driver's θ [rad], or its s in
metres), so the equations of motion need only a few scalar functions of q: the generalized inertia
J(q) = Σ m·|∂r_G/∂q|² + I·(∂θ/∂q)², the potential of gravity V(q) = −Σ m·g·r_G, and the angles, lengths and
point coordinates that springs and loads act through. vloop's run over q at unit rate (q̇ = 1, q̈ = 0) gives
each of them with its first two derivatives exactly at every node: positions, velocity coefficients ∂/∂q
(the ω, v columns) and their derivatives ∂²/∂q² (the α, a columns); J′ = 2·Σ (m·∂r_G/∂q·∂²r_G/∂q² +
I·∂θ/∂q·∂²θ/∂q²). Between nodes each function is the quintic Hermite polynomial through those values (the
drivers' profile interpolant), so the integrator reads the solve's own numbers, smoothly (C²); J″ at the
nodes comes from a cubic spline through J′ (its error enters at O(h⁵)).

The table is checked against the loop solve itself at every interval's midpoint, values and slopes, each
relative to the channel's range over the nodes: the largest error is kept (``Tables.error``), and for an
input with limits the range the integrator may use
(``Tables.lo``, ``Tables.hi``) ends before the first interval that fails the check (near a limit the
coefficients grow as 1/√distance and no polynomial follows them).
"""

from __future__ import annotations

import bisect
import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..drivers import _quintic_hermite
from ..errors import MechanismError, MotionError
from ..forces import body_com
from ..model import Mechanism, Point, length_factor, to_world
from ..sweep import feasible_range

TURN_NODES = 2048  # intervals per turn of a crank (the midpoint check: ~1e-12 relative on the catalog)
RANGE_NODES = 2048  # intervals over a limited input's range (cosine-spaced: denser near the limits)
MAX_NODES = 32768  # a crank's turn is tabulated again with 4× the nodes while its check fails, up to this
CHECK = 1e-9  # an interval whose midpoint is off the loop solve by more than this (relative) is not used
G_PREFIX = "_G_"  # the centres of mass, as tracer points of the augmented mechanism


@dataclass(frozen=True)
class Channels:
    """Which scalar functions of q are tabulated, by name → row of the coefficient table."""

    names: tuple[str, ...]

    def index(self, name: str) -> int:
        return self.names.index(name)


@dataclass
class Tables:
    """Quintic pieces of every channel over q (SI), with their per-turn increments (a crank's angles)."""

    channels: Channels
    nodes: np.ndarray  # (n + 1,) q at the nodes [rad or m], increasing
    coef: np.ndarray  # (n, channels, 6): highest power first, in u = q − nodes[i]
    dcoef: np.ndarray  # (n, channels, 5): the derivative's
    period: float | None  # 2π for a crank that turns fully, else None
    increment: np.ndarray  # (channels,): value(q + period) − value(q)
    lo: float  # the range the tables may be used in
    hi: float
    error: float  # the largest relative midpoint error in the range used
    qscale: float  # metres per input unit (1 for a crank)
    limits: tuple[float, float] | None  # a limited input's limit positions [input units]

    def at(self, q: float) -> tuple[list[float], list[float]]:
        """Every channel's value and derivative d/dq at q (a crank's q anywhere; else within [lo, hi]).
        Plain floats: the integrator calls this a few times per step, where numpy's overhead would dominate."""
        rows = self.__dict__.get("_rows")
        if rows is None:
            rows = self._prepare()
        knots, values, slopes, inc = rows
        turns = 0
        if self.period is not None:
            turns = math.floor((q - knots[0]) / self.period)
            q -= turns * self.period
        i = min(max(bisect.bisect_right(knots, q) - 1, 0), len(values) - 1)
        u = q - knots[i]
        v = [((((a * u + b) * u + c) * u + d) * u + e) * u + f for a, b, c, d, e, f in values[i]]
        if turns:
            v = [x + turns * k for x, k in zip(v, inc, strict=True)]
        return v, [(((a * u + b) * u + c) * u + d) * u + e for a, b, c, d, e in slopes[i]]

    def _prepare(self) -> tuple[list[float], list, list, list[float]]:
        """The coefficients as nested lists of floats (read once)."""
        rows = (self.nodes.tolist(), self.coef.tolist(), self.dcoef.tolist(), self.increment.tolist())
        self.__dict__["_rows"] = rows
        return rows


def centre_points(mech: Mechanism) -> dict[str, Point]:
    """A tracer point at every massive body's centre of mass (the file's mass properties, forces' frames)."""
    bodies = mech.bodies()
    return {
        f"{G_PREFIX}{b}": Point(f"{G_PREFIX}{b}", b, to_world(bodies[b], body_com(mech, b)))
        for b in mech.masses
        if mech.masses[b].mass > 0 or mech.masses[b].inertia > 0
    }


def augmented(mech: Mechanism) -> Mechanism:
    """The mechanism with its centres of mass as tracer points (what the tables and the outputs solve)."""
    return dataclasses.replace(mech, points={**mech.points, **centre_points(mech)})


def build(mech: Mechanism, channels: list[tuple[str, Any]], flywheel: float) -> Tables:
    """Tabulate J, V and ``channels`` (name, how) of a one-input mechanism over its input's range.

    ``how``: ("angle", a, b) for θ_a − θ_b (b the ground: θ_a), ("length", P, Q) for |PQ| [m], ("x"|"y", P)
    for a point's coordinate [m]. ``flywheel``: inertia added on the input [kg·m², kg on a slider]. A crank's
    turn whose midpoint check exceeds CHECK is tabulated again with four times the nodes (up to MAX_NODES) while
    that improves it.
    """
    lo, hi, full = feasible_range(mech)
    n = TURN_NODES if full else RANGE_NODES
    best = _tabulate(mech, channels, flywheel, (lo, hi, full), n)
    while full and best.error > CHECK and 4 * n <= MAX_NODES:
        n *= 4
        finer = _tabulate(mech, channels, flywheel, (lo, hi, full), n)
        if finer.error >= best.error:  # round-off (J″ from the slopes over shorter intervals) wins from here
            break
        best = finer
    return best


def _tabulate(
    mech: Mechanism, channels: list[tuple[str, Any]], flywheel: float, span: tuple[float, float, bool], n: int
) -> Tables:
    """The tables on ``n`` intervals: a crank's turn from x0, or a limited input's range [lo, hi]."""
    aug = augmented(mech)
    d = mech.drivers[0]
    qscale = 1.0 if d.kind == "crank" else length_factor(mech.units)
    x0 = float(d.x0)
    lo, hi, full = span
    if full:
        nodes = x0 + np.linspace(0.0, 2 * math.pi, n + 1)
    else:
        s = (np.arange(n + 1) + 0.5) / (n + 1)
        nodes = lo + (hi - lo) * 0.5 * (1 - np.cos(math.pi * s))
    names = ("J", "V", *(name for name, _ in channels))
    vals, d1, d2 = _sample(aug, channels, nodes, qscale, flywheel, not full)
    if full:  # the ends are the same position: the same coefficients, only the angles' whole turns differ
        d1[:, -1], d2[:, -1] = d1[:, 0], d2[:, 0]
    else:  # the nodes the runs reached on either side of x0
        keep = _solved_span(np.isfinite(vals[0]) & np.isfinite(d2[0]), nodes, x0)
        nodes, vals, d1, d2 = nodes[keep], vals[:, keep], d1[:, keep], d2[:, keep]
    d2[0] = _spline_slope(nodes * qscale, d1[0], full)
    bad = ~np.isfinite(vals).all(axis=1) | ~np.isfinite(d1).all(axis=1) | ~np.isfinite(d2).all(axis=1)
    if np.any(bad):  # e.g. a linear spring between two points that coincide somewhere
        raise MechanismError(f"{mech.name}: the dynamics' {names[int(np.argmax(bad))]} is not finite over the "
                             "input's range (a spring between coinciding points?)", entry="dynamics")  # fmt: skip
    _check_inertia(mech, vals[0], nodes)
    coef = np.stack([_quintic_hermite(nodes * qscale, v, a, b) for v, a, b in zip(vals, d1, d2, strict=True)])
    coef = coef.transpose(2, 0, 1)  # (intervals, channels, 6)

    def sample(q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return _sample(aug, channels, q / qscale, qscale, flywheel, not full)[:2]

    err = check(sample, nodes * qscale, (vals, d1, coef))
    lo_i, hi_i = _trusted(err, nodes, x0, full)
    return Tables(
        Channels(names), nodes[lo_i : hi_i + 1] * qscale, coef[lo_i:hi_i], _derivative(coef[lo_i:hi_i]),
        2 * math.pi if full else None, vals[:, -1] - vals[:, 0] if full else np.zeros(len(names)),
        nodes[lo_i] * qscale, nodes[hi_i] * qscale, float(err[lo_i:hi_i].max()), qscale,
        None if full else (lo, hi),
    )  # fmt: skip


def check(sample: Any, nodes: np.ndarray, tables: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """Per interval, the pieces' largest error at its midpoint against ``sample`` there (values and slopes of
    every channel, from the loop solve) relative to each channel's range; ``nodes`` in the pieces' variable."""
    vals, d1, coef = tables
    mids = 0.5 * (nodes[1:] + nodes[:-1])
    mvals, mslopes = sample(mids)
    powers = (0.5 * np.diff(nodes))[:, None] ** np.arange(5, -1, -1)[None, :]
    span = float(nodes[-1] - nodes[0])
    return np.maximum(
        _midpoint_error(np.einsum("ick,ik->ci", coef, powers), mvals, np.ptp(vals, axis=1)),
        _midpoint_error(
            np.einsum("ick,ik->ci", _derivative(coef), powers[:, 1:]),
            mslopes,
            np.maximum(np.ptp(d1, axis=1), (np.ptp(vals, axis=1) + 1e-6 * np.abs(vals).max(axis=1)) / span),
        ),
    )  # fmt: skip  (a slope that does not vary, e.g. of a coordinate that stays put, is judged at its round-off)


def _midpoint_error(approx: np.ndarray, exact: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Per interval, the largest error of the pieces at the midpoints relative to each channel's ``scale`` (its
    variation over the nodes; a channel that does not vary has none to lose); inf where the run has no midpoint."""
    rel = np.abs(approx - exact) / np.where(scale > 0, scale, np.inf)[:, None]
    return np.where(np.isfinite(exact).all(axis=0), rel.max(axis=0), np.inf)


def _check_inertia(mech: Mechanism, J: np.ndarray, nodes: np.ndarray) -> None:
    """J must stay positive: a mechanism without masses (or whose only masses stop moving at some input) has
    no equation of motion there."""
    k = int(np.argmin(J))
    if not J[k] > 1e-12 * max(float(J.max()), 1e-300):
        what = "has no inertia: give its links masses and inertias, or a flywheel" if J.max() <= 0 else (
            f"has no inertia at the input {nodes[k]:.6g} (its masses do not move there): add a flywheel"
        )  # fmt: skip
        raise MechanismError(f"{mech.name}: [dynamics] the mechanism {what}", entry="dynamics")


def _solved_span(ok: np.ndarray, nodes: np.ndarray, x0: float) -> slice:
    """The contiguous nodes around x0 that the runs solved (at least four)."""
    k = int(np.clip(np.searchsorted(nodes, x0), 0, len(nodes) - 1))
    lo, hi = k, k
    while lo > 0 and ok[lo - 1]:
        lo -= 1
    while hi < len(ok) - 1 and ok[hi + 1]:
        hi += 1
    if hi - lo < 3 or not ok[k]:
        raise MechanismError("the input at t = 0 is too close to a limit position for the dynamics", entry="dynamics")
    return slice(lo, hi + 1)


def _trusted(err: np.ndarray, nodes: np.ndarray, x0: float, full: bool) -> tuple[int, int]:
    """The node range the tables may be used in: every interval (a crank), else the intervals around x0 up
    to the first one off by more than CHECK on either side."""
    n = len(err)
    if full:
        return 0, n
    k = int(np.clip(np.searchsorted(nodes, x0) - 1, 0, n - 1))
    bad = err > CHECK
    if bad[k]:
        raise MechanismError(
            f"the input at t = 0 is too close to a limit position for the dynamics (tables off by {err[k]:.1e})",
            entry="dynamics",
        )
    below = np.flatnonzero(bad[:k])
    above = np.flatnonzero(bad[k:])
    return (int(below[-1]) + 1 if len(below) else 0), (k + int(above[0]) if len(above) else n)


def _derivative(coef: np.ndarray) -> np.ndarray:
    """The derivative's coefficients (highest power first) of quintic pieces."""
    return coef[..., :5] * np.arange(5, 0, -1)


def _spline_slope(q: np.ndarray, y: np.ndarray, periodic: bool) -> np.ndarray:
    """dy/dq at the nodes from the cubic spline through y (periodic for a crank's turn)."""
    from scipy.interpolate import CubicSpline

    if periodic:
        y = y.copy()
        y[-1] = y[0]
    return CubicSpline(q, y, bc_type="periodic" if periodic else "not-a-knot")(q, 1)


def _padded(res: Any, n: int) -> Any:
    """A partial Result's columns padded with NaN to ``n`` rows."""
    from ..result import Result

    cols = {k: np.concatenate([v, np.full(n - len(v), np.nan)]) for k, v in res.columns.items()}
    return Result(res.mechanism, res.engine, np.zeros(n), cols)


def _solve_at(aug: Mechanism, q: np.ndarray, partial: bool) -> Any:
    """vloop's run at unit input rate through the inputs ``q`` [input units]: forwards and backwards from the
    coordinates' input x0, so that each side is one continuous run (its columns are ∂/∂q and ∂²/∂q²).
    ``partial``: a run that stops (near a limit) gives NaN beyond its last row instead of an error."""
    from .. import solve

    d = aug.drivers[0]
    x0 = float(d.x0)
    parts = []
    for sign, sel in ((-1.0, q < x0), (1.0, q >= x0)):
        if not np.any(sel):
            continue
        drv = dataclasses.replace(d, v0=sign, a0=0.0, profile=None)
        run = dataclasses.replace(aug, drivers=(drv,), times=np.zeros(1), dynamics=None)
        t = np.sort(sign * (q[sel] - x0))
        try:
            res = solve(run, t)
        except MotionError as exc:
            if not partial or exc.partial is None:
                raise MotionError(f"the dynamics' tables: {exc.message}", entry="dynamics") from None
            res = _padded(exc.partial, len(t))  # near a limit: the rows solved, the rest unknown (NaN)
        order = np.argsort(sign * t + x0)
        parts.append((sign, res, order))
    return parts


def _sample(
    aug: Mechanism, channels: list[tuple[str, Any]], q: np.ndarray, qscale: float, flywheel: float, partial: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(channels, len(q)) values, first and second derivatives in q [SI] of J, V and the channels."""
    f = length_factor(aug.units)
    cols: list[list[np.ndarray]] = [[], [], []]
    for sign, res, order in _solve_at(aug, q, partial):

        def col(name: str, k: int, sign: float = sign, res: Any = res, order: Any = order) -> np.ndarray:
            return np.asarray(res[name], float)[order] * sign**k

        for i, rows in enumerate(_functions(aug, channels, col, f / qscale, 1.0 / qscale, flywheel)):
            cols[i].append(rows)
    return tuple(np.concatenate(c, axis=1) for c in cols)  # type: ignore[return-value]


def _functions(
    aug: Mechanism, channels: list[tuple[str, Any]], col: Any, lf: float, af: float, flywheel: float
) -> list[np.ndarray]:
    """Values, d/dq and d²/dq² of J, V and every channel from one run's columns (lf, af: SI per input unit)."""
    f = length_factor(aug.units)
    g = aug.gravity or (0.0, 0.0)
    J = np.zeros_like(col(f"{aug.moving_links[0]}.theta", 0))
    J1, V, V1, V2 = (np.zeros_like(J) for _ in range(4))
    for b, mp in aug.masses.items():
        name = G_PREFIX + b
        if name not in aug.points:
            continue
        x, y = col(f"{name}.x", 0) * f, col(f"{name}.y", 0) * f
        vx, vy = col(f"{name}.vx", 1) * lf, col(f"{name}.vy", 1) * lf
        ax, ay = col(f"{name}.ax", 2) * lf * af, col(f"{name}.ay", 2) * lf * af
        w, a = col(f"{b}.omega", 1) * af, col(f"{b}.alpha", 2) * af * af
        J += mp.mass * (vx * vx + vy * vy) + mp.inertia * w * w
        J1 += 2 * (mp.mass * (vx * ax + vy * ay) + mp.inertia * w * a)
        V -= mp.mass * (g[0] * x + g[1] * y)
        V1 -= mp.mass * (g[0] * vx + g[1] * vy)
        V2 -= mp.mass * (g[0] * ax + g[1] * ay)
    J += flywheel  # on the input: ∂x/∂q = 1
    out = [[J, V], [J1, V1], [np.zeros_like(J), V2]]
    for _, how in channels:
        v, v1, v2 = _channel(aug, how, col, f, lf, af)
        out[0].append(v)
        out[1].append(v1)
        out[2].append(v2)
    return [np.array(rows) for rows in out]


def _channel(aug: Mechanism, how: Any, col: Any, f: float, lf: float, af: float) -> tuple[Any, Any, Any]:
    """One channel's value and its first two derivatives in q (SI)."""
    kind = how[0]
    if kind == "angle":
        a, b = how[1], how[2]
        th = [col(f"{n}.theta", 0) if n != aug.ground else 0.0 for n in (a, b)]
        om = [col(f"{n}.omega", 1) * af if n != aug.ground else 0.0 for n in (a, b)]
        al = [col(f"{n}.alpha", 2) * af * af if n != aug.ground else 0.0 for n in (a, b)]
        return th[0] - th[1], om[0] - om[1], al[0] - al[1]
    if kind in ("x", "y"):
        p = how[1]
        return col(f"{p}.{kind}", 0) * f, col(f"{p}.v{kind}", 1) * lf, col(f"{p}.a{kind}", 2) * lf * af
    p, q = how[1], how[2]
    dx, dy = (col(f"{p}.{k}", 0) * f - col(f"{q}.{k}", 0) * f for k in ("x", "y"))
    vx, vy = (col(f"{p}.v{k}", 1) * lf - col(f"{q}.v{k}", 1) * lf for k in ("x", "y"))
    ax, ay = (col(f"{p}.a{k}", 2) * lf * af - col(f"{q}.a{k}", 2) * lf * af for k in ("x", "y"))
    L = np.hypot(dx, dy)
    L1 = (dx * vx + dy * vy) / L
    L2 = (vx * vx + vy * vy + dx * ax + dy * ay - L1 * L1) / L
    return L, L1, L2
