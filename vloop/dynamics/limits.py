"""The last stretch before each limit position of the input, tabulated on u = √|q − q_lim|.

At a limit position the dyad that closes the loop stretches out (its discriminant is zero): the positions are
regular functions of u = √|q − q_lim| (the two assemblies that meet there are u > 0 and u < 0), while their
derivatives in q grow as 1/u and J(q) as 1/u², which no polynomial in q follows. So the stretch of width
ZONE·(range) before each limit is tabulated on u, with q = q_lim − σ·u² (σ = +1 at the upper limit, −1 at the
lower; q_u = −2σu, q_uu = −2σ): every function f(q) becomes F(u) = f(q(u)), F′ = f′·q_u, F″ = f″·q_u² + f′·q_uu,
and the inertia J_u = J·q_u² (finite at the limit). The limits are the kinematic run's, located at the root of
the dyad's discriminant (:func:`vloop.sweep.feasible_range`), so u = 0 is the limit itself; the integrator
reaches it as an event. The nodes are uniform on (0, u_end], checked at every midpoint as the tables on q are;
the intervals nearest the limit, where the loop solve's rates lose digits (its Jacobian's condition grows as
1/u), are dropped up to the last one that fails the check, and the first piece kept reaches back to u = 0
(an extrapolation over a few intervals of a function regular there).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..drivers import _quintic_hermite
from ..errors import MechanismError
from ..model import Mechanism
from .tables import CHECK, Tables, _derivative, _sample, _spline_slope, augmented, check

ZONE = 0.05  # the fraction of the input's range, before each limit, tabulated on u
NODES = 256  # intervals on u over a zone
ENTER = 0.81  # the motion on q switches to u at ENTER·(the zone's width) from the limit (back to q at the zone's end)


def limit_tables(mech: Mechanism, channels: list[tuple[str, Any]], flywheel: float, tables: Tables) -> tuple:
    """(lower, upper): the tables on u at each limit of a limited input (both None for a crank that turns)."""
    if tables.limits is None:
        return None, None
    lo, hi = (x * tables.qscale for x in tables.limits)
    width = ZONE * (hi - lo)
    if not (tables.lo <= lo + width and hi - width <= tables.hi):
        raise MechanismError(
            f"{mech.name}: the dynamics' tables do not reach within {ZONE:g} of the range of the input's limits "
            f"(they cover {tables.lo / tables.qscale:.10g} to {tables.hi / tables.qscale:.10g})",
            entry="dynamics",
        )
    aug = augmented(mech)
    sides = ((lo, -1.0), (hi, 1.0))
    return tuple(_side(aug, channels, flywheel, tables, q_lim, sigma, width) for q_lim, sigma in sides)


def _side(
    aug: Mechanism, channels: list[tuple[str, Any]], flywheel: float, tables: Tables, q_lim: float, sigma: float,
    width: float,
) -> Tables:  # fmt: skip
    """The tables on u ∈ [0, √width] at the limit q_lim [SI] (σ: +1 upper, −1 lower)."""
    u_end = math.sqrt(width)
    nodes = u_end * np.arange(1, NODES + 1) / NODES

    def sample(u: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        return _in_u(aug, channels, flywheel, tables.qscale, (q_lim, sigma), u)

    vals, d1, d2 = sample(nodes)
    ok = np.isfinite(vals).all(axis=0) & np.isfinite(d1).all(axis=0) & np.isfinite(d2).all(axis=0)
    k = int(np.flatnonzero(~ok)[-1]) + 1 if not ok.all() else 0  # next to the limit the solve may refuse
    nodes, vals, d1, d2 = nodes[k:], vals[:, k:], d1[:, k:], d2[:, k:]
    if len(nodes) > 1:
        d2[0] = _spline_slope(nodes, d1[0], False)
    coef = np.stack([_quintic_hermite(nodes, v, a, b) for v, a, b in zip(vals, d1, d2, strict=True)])
    coef = coef.transpose(2, 0, 1)
    err = check(lambda u: sample(u)[:2], nodes, (vals, d1, coef)) if len(nodes) > 1 else np.full(1, np.inf)
    bad = np.flatnonzero(~(err <= CHECK))
    k = int(bad[-1]) + 1 if len(bad) else 0  # the intervals nearest the limit, where the solve's rates lose digits
    if k >= len(err) or nodes[k] > 0.25 * u_end:
        raise MechanismError(
            f"{aug.name}: the dynamics' tables at the input's limit {q_lim / tables.qscale:.10g} are off the loop "
            f"solve by more than {CHECK:g} from {nodes[min(k, len(nodes) - 1)] ** 2:.3g} before it",
            entry="dynamics",
        )
    nodes, coef = nodes[k:], coef[k:]
    worst = float(err[k:].max())
    n = len(tables.channels.names)
    return Tables(tables.channels, nodes, coef, _derivative(coef), None, np.zeros(n), 0.0, u_end, worst, 1.0, None)


def _in_u(
    aug: Mechanism, channels: list[tuple[str, Any]], flywheel: float, qscale: float, limit: tuple[float, float],
    u: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """J_u, V and the channels, with their derivatives in u (J_u's second left zero), at u."""
    q_lim, sigma = limit
    qu, quu = -2.0 * sigma * u, -2.0 * sigma
    order = np.argsort(q_lim - sigma * u * u)  # the samples come in increasing q
    got = _sample(aug, channels, (q_lim - sigma * u[order] ** 2) / qscale, qscale, flywheel, True)
    v, d1, d2 = (np.empty_like(x) for x in got)
    for x, y in zip((v, d1, d2), got, strict=True):
        x[:, order] = y
    f1, f2 = d1 * qu, d2 * qu * qu + d1 * quu
    J, J1 = v[0].copy(), d1[0]
    v[0] = J * qu * qu
    f1[0] = J1 * qu**3 + 2.0 * J * qu * quu
    f2[0] = 0.0
    return v, f1, f2


def to_u(q: float, qd: float, q_lim: float, sigma: float) -> tuple[float, float]:
    """(u, u̇) of the input's (q, q̇) [SI] near the limit q_lim (u > 0)."""
    u = math.sqrt(max(sigma * (q_lim - q), 0.0))
    return u, -sigma * qd / (2.0 * u)


def from_u(u: np.ndarray, ud: np.ndarray, udd: np.ndarray, q_lim: float, sigma: float) -> tuple:
    """(q, q̇, q̈) [SI] of (u, u̇, ü) at the limit q_lim."""
    return q_lim - sigma * u * u, -2.0 * sigma * u * ud, -2.0 * sigma * (ud * ud + u * udd)
