"""Closed-form kinematics of Jansen's linkage (any number of legs on one crank pin), as dyads.

Jansen's leg looks like a tangle of loops but is built from RRR dyads that can be
solved one after the other, each by the law of cosines, so it has a closed form.

Structure (checked by :func:`applies`; names are free; Jansen's letters in
brackets): a crank O→M [m], driven; for every leg, a ground pivot Q and six
bodies: link MU [j], link MW [k], link QW [c], a ternary "upper triangle" with
Q, U, X [b = QU, d = QX, e = UX], link XY [f] and a ternary "foot triangle"
with W, Y (and the foot F, or any other points) [g = WY, i = WF, h = YF].
Every leg hangs on the same crank pin M; every other pin joins two bodies,
except W (three: k, c and the foot triangle).

Loops of one leg (complex numbers; φ_PQ is the direction of P→Q):

    M + j·e^{jφ_MU} = Q + b·e^{jφ_QU}
    M + k·e^{jφ_MW} = Q + c·e^{jφ_QW}
    Q + e^{jθ_T}·ρ_X + f·e^{jφ_XY} = W + g·e^{jφ_WY}

with θ_T the upper triangle's angle (θ_T = φ_QU − β, β the direction of Q→U in
its frame) and ρ_X its frame vector Q→X.

Each dyad "P1–X–P2, lengths l1, l2" (P1, P2 known with their rates) is solved as
in :mod:`validators.analytic.dyads` (law of cosines; rates by differentiating the
loop and projecting on e^{jφ2}, e^{jφ1}):
    δ = P2 − P1, f = |δ|, p = (l1² − l2² + f²)/(2f), φ1 = arg δ + σ·atan2(√(l1² − p²), p),
    X = P1 + l1·e^{jφ1}, φ2 = arg(X − P2),
    ω1 = −Re(D·e^{−jφ2})/(l1·sin(φ1 − φ2)),  ω2 = Re(D·e^{−jφ1})/(l2·sin(φ2 − φ1)),  D = Ṗ2 − Ṗ1,
    α1, α2 the same with R = P̈2 − P̈1 + l1·ω1²·e^{jφ1} − l2·ω2²·e^{jφ2} for D.

Order for each leg:
  1. M = O + m·e^{jθ} (Ṁ = j·ω·(M − O), M̈ = (j·α − ω²)·(M − O));
  2. dyad M–U–Q (j, b): U, the angles of link j and of the upper triangle;
  3. dyad M–W–Q (k, c): W, the angles of links k and c;
  4. X = Q + e^{jθ_T}·ρ_X (rigid transport; Q fixed);
  5. dyad X–Y–W (f, g): Y, the angles of link f and of the foot triangle;
  6. the foot F (and any point) by rigid transport on the foot triangle.
Each branch σ is the side of P1→P2 on which the middle pin lies at t = 0.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from .common import (
    Assembly,
    check_dyads,
    crank_driver,
    driver_input,
    evaluation_times,
    member_vector,
    other_body,
    pins,
    pins_of,
)
from .dyads import carry, close_rrr, fixed_kin, local_vector

NAME = "jansen"

__all__ = ["applies", "legs", "solve"]


@dataclass(frozen=True)
class Leg:
    """Bodies and joints of one Jansen leg (Jansen's letters for the links)."""

    j: str
    k: str
    c: str
    upper: str  # Q, U, X
    f: str
    foot: str  # W, Y, ...
    Q: str
    U: str
    W: str
    X: str
    Y: str


def _leg(mech: Mechanism, q: str, m: str, pm: dict[str, tuple[str, ...]]) -> Leg | None:
    """The leg hung on ground pivot ``q`` and crank pin ``m``, or None."""
    g = mech.ground
    at_q = [b for b in pm[q] if b != g]
    if len(at_q) != 2:
        return None
    upper = next((b for b in at_q if len(pins_of(mech, b)) == 3), None)
    c = next((b for b in at_q if len(pins_of(mech, b)) == 2), None)
    if upper is None or c is None:
        return None
    w = (pins_of(mech, c) - {q}).pop()
    rest = pins_of(mech, upper) - {q}
    # U: the upper triangle's pin whose other body is a binary link to the crank pin
    to_crank = [p for p in rest if (b := other_body(pm[p], upper)) is not None and pins_of(mech, b) == {m, p}]
    if len(to_crank) != 1:
        return None
    u = to_crank[0]
    x = (rest - {u}).pop()
    j = other_body(pm[u], upper)
    f = other_body(pm[x], upper)
    if j is None or f is None or pins_of(mech, j) != {m, u} or len(pins_of(mech, f)) != 2:
        return None
    y = (pins_of(mech, f) - {x}).pop()
    foot = other_body(pm[y], f)
    if foot is None or pins_of(mech, foot) != {w, y}:
        return None
    at_w = set(pm[w])
    if len(at_w) != 3 or not {c, foot} < at_w:
        return None
    k = (at_w - {c, foot}).pop()
    if pins_of(mech, k) != {m, w}:
        return None
    return Leg(j, k, c, upper, f, foot, q, u, w, x, y)


def legs(mech: Mechanism) -> tuple[str, str, str, tuple[Leg, ...]] | None:
    """(crank, O, M, legs) if ``mech`` is a crank-driven set of Jansen legs on one crank pin, else None."""
    drv = crank_driver(mech)
    if drv is None or mech.sliders:
        return None
    g, crank, o = mech.ground, drv.target, drv.pivot
    pm = pins(mech)
    cp = pins_of(mech, crank) - {o}
    if set(pm.get(o, ())) != {g, crank} or len(cp) != 1:
        return None
    m = cp.pop()
    pivots = sorted(pins_of(mech, g) - {o})
    if not pivots:
        return None
    out = []
    for q in pivots:
        leg = _leg(mech, q, m, pm)
        if leg is None:
            return None
        out.append(leg)
    used = {g, crank} | {b for lg in out for b in (lg.j, lg.k, lg.c, lg.upper, lg.f, lg.foot)}
    if len(used) != 2 + 6 * len(out) or used != set(mech.links):
        return None
    if set(pm[m]) != {crank} | {lg.j for lg in out} | {lg.k for lg in out}:
        return None
    return crank, o, m, tuple(out)


def applies(mech: Mechanism) -> bool:
    """True for one or more Jansen legs hung on the pin of one driven crank."""
    return legs(mech) is not None


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics over ``times`` (default: the file's [time]).

    Raises LimitPositionError (a ValueError) at the first sample a dyad cannot
    be closed, with the samples before it in ``.partial``.
    """
    found = legs(mech)
    if found is None:
        raise ValueError(f"{mech.name}: not a set of Jansen legs on one driven crank")
    crank, o, m, leg_list = found
    drv = mech.drivers[0]
    bodies = mech.bodies()
    rm, beta = member_vector(bodies[crank], o, m)
    t, inserted, anchor = evaluation_times(mech, times)
    n = len(t)
    th, om, al = driver_input(drv, t)
    asm = Assembly(mech, t, inserted, anchor)
    r = rm * np.exp(1j * (th + beta))
    zM = (asm.fixed(o) + r, 1j * om * r, (1j * al - om * om) * r)
    asm.set_angle(crank, th, om, al)
    asm.set_point(m, *zM)
    z0 = {name: complex(*xy) for name, xy in mech.joints.items()}
    fails = []
    for lg in leg_list:
        zQ = fixed_kin(z0[lg.Q], n)
        ok1, _, _ = close_rrr(asm, (lg.j, lg.upper), (m, lg.Q, lg.U), zM, zQ)
        ok2, zW, _ = close_rrr(asm, (lg.k, lg.c), (m, lg.Q, lg.W), zM, zQ)
        zX = carry(zQ, asm.angles[lg.upper], local_vector(mech, lg.upper, lg.Q, lg.X))
        asm.set_point(lg.X, *zX)
        ok3, _, _ = close_rrr(asm, (lg.f, lg.foot), (lg.X, lg.W, lg.Y), zX, zW)
        fails += [
            (ok1, f"links {lg.j} and {lg.upper} cannot close"),
            (ok2, f"links {lg.k} and {lg.c} cannot close"),
            (ok3, f"links {lg.f} and {lg.foot} cannot close"),
        ]
    check_dyads(fails, mech=mech, t=t, inserted=inserted, theta_in=th, resolve=lambda tt: solve(mech, tt))
    return asm.result(NAME, {"legs": len(leg_list)})
