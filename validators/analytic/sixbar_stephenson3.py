"""Closed-form kinematics of the Stephenson III six-bar: a dyad on a coupler point, as two dyads.

Structure (checked by :func:`applies`; names are free): ground pivots O2, O4, O6;
crank O2A (a, driven θ2, ω2, α2); a ternary coupler carrying A, B and P (|AB| = b,
ρ_P the coupler-frame vector A→P); rocker O4B (c); link PE (l5); output rocker
O6E (l6). Every pin joins exactly two bodies. Angles: φ3 = arg(B − A),
φ4 = arg(B − O4), φ5 = arg(E − P), φ6 = arg(E − O6) (member-vector directions;
a body's own θ is φ − β, β the vector's angle in its frame, see validators.analytic.common).

Loops (complex numbers):

    O2 + a·e^{jθ2} + b·e^{jφ3} = O4 + c·e^{jφ4}                 (four-bar)
    O2 + a·e^{jθ2} + e^{jθ3}·ρ_P + l5·e^{jφ5} = O6 + l6·e^{jφ6}  (through the coupler point)

θ3 = φ3 − β3 the coupler's angle (β3 the direction of A→B in the coupler frame).

Step 1 — A from the crank: A = O2 + a·e^{jθ2}, Ȧ = j·ω2·(A − O2),
Ä = (j·α2 − ω2²)·(A − O2).

Step 2 — RRR dyad A–B–O4 (law of cosines in triangle A–B–O4): δ = O4 − A,
f = |δ|, p = (b² − c² + f²)/(2f), q = √(b² − p²); φ3 = arg δ + σ1·atan2(q, p),
B = A + b·e^{jφ3}, φ4 = arg(B − O4). Rates (differentiate the four-bar loop and
project on e^{jφ4}, e^{jφ3}; D1 = −Ȧ since O4 is fixed):
    ω3 = −Re(D1·e^{−jφ4})/(b·sin(φ3 − φ4)),   ω4 = Re(D1·e^{−jφ3})/(c·sin(φ4 − φ3)),
    α3, α4: the same with R1 = −Ä + b·ω3²·e^{jφ3} − c·ω4²·e^{jφ4} in place of D1.

Step 3 — the coupler point by rigid-body transport from A:
P = A + e^{jθ3}·ρ_P,  Ṗ = Ȧ + j·ω3·(P − A),  P̈ = Ä + (j·α3 − ω3²)·(P − A).

Step 4 — RRR dyad P–E–O6: the same triangle with (P, l5, O6, l6, σ2), D2 = −Ṗ,
R2 = −P̈ + l5·ω5²·e^{jφ5} − l6·ω6²·e^{jφ6}:
    ω5 = −Re(D2·e^{−jφ6})/(l5·sin(φ5 − φ6)),  ω6 = Re(D2·e^{−jφ5})/(l6·sin(φ6 − φ5)),
    α5, α6 likewise from R2.

σ1 = sign((O4 − A) × (B − A)), σ2 = sign((O6 − P) × (E − P)) at t = 0. A dyad
cannot be closed where its base |δ| leaves (|l1 − l2|, l1 + l2). The general dyad
is :func:`validators.analytic.dyads.rrr`.
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
from .dyads import carry, fixed_kin, local_vector, rrr, rrr_sigma

NAME = "sixbar_stephenson3"

__all__ = ["applies", "roles", "solve"]


@dataclass(frozen=True)
class Roles:
    """Which bodies and joints play which part in the Stephenson III six-bar."""

    ground: str
    crank: str
    coupler: str  # ternary: A, B, P
    rocker: str
    link5: str
    output: str
    O2: str
    A: str
    B: str
    O4: str
    P: str
    E: str
    O6: str


def roles(mech: Mechanism) -> Roles | None:
    """Identify a four-bar whose ternary coupler drives a dyad to a third ground pivot, or None."""
    drv = crank_driver(mech)
    if drv is None or mech.sliders or len(mech.links) != 6:
        return None
    g, crank, o2 = mech.ground, drv.target, drv.pivot
    pm = pins(mech)
    if len(pm) != 7 or any(len(bs) != 2 for bs in pm.values()):
        return None
    gp = pins_of(mech, g)
    if len(gp) != 3 or o2 not in gp or set(pm[o2]) != {g, crank}:
        return None
    cp = pins_of(mech, crank) - {o2}
    if len(cp) != 1:
        return None
    a = cp.pop()
    coupler = other_body(pm[a], crank)
    if coupler is None or coupler == g:
        return None
    kp = pins_of(mech, coupler) - {a}
    if len(kp) != 2:
        return None
    # of the coupler's two other pins, B leads to a rocker pivoted on the ground, P to the dyad
    found = []
    for b in kp:
        rocker = other_body(pm[b], coupler)
        rp = pins_of(mech, rocker) if rocker not in (None, g) else set()
        if len(rp) == 2 and len(rp & gp) == 1:
            found.append((b, rocker, (rp & gp).pop()))
    if len(found) != 1:
        return None
    b, rocker, o4 = found[0]
    p = (kp - {b}).pop()
    link5 = other_body(pm[p], coupler)
    if link5 is None or link5 in (g, rocker):
        return None
    lp = pins_of(mech, link5) - {p}
    if len(lp) != 1:
        return None
    e = lp.pop()
    output = other_body(pm[e], link5)
    if output is None or output == g:
        return None
    op = pins_of(mech, output) - {e}
    if len(op) != 1 or (o6 := op.pop()) not in gp - {o2, o4}:
        return None
    return Roles(g, crank, coupler, rocker, link5, output, o2, a, b, o4, p, e, o6)


def applies(mech: Mechanism) -> bool:
    """True for a crank-driven Stephenson III six-bar (a dyad hung on the four-bar's ternary coupler)."""
    return roles(mech) is not None


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics over ``times`` (default: the file's [time]).

    Raises LimitPositionError (a ValueError) at the first sample a dyad cannot
    be closed, with the samples before it in ``.partial``.
    """
    r = roles(mech)
    if r is None:
        raise ValueError(f"{mech.name}: not a crank-driven Stephenson III six-bar")
    drv = mech.drivers[0]
    bodies = mech.bodies()
    a, beta2 = member_vector(bodies[r.crank], r.O2, r.A)
    b, _ = member_vector(bodies[r.coupler], r.A, r.B)
    c, _ = member_vector(bodies[r.rocker], r.O4, r.B)
    l5, _ = member_vector(bodies[r.link5], r.P, r.E)
    l6, _ = member_vector(bodies[r.output], r.O6, r.E)
    z = {j: complex(*mech.joints[j]) for j in (r.A, r.B, r.O4, r.P, r.E, r.O6)}
    sigma1 = rrr_sigma(z[r.A], z[r.O4], z[r.B], f"{mech.name}: pin {r.B} on the line {r.A}{r.O4}")
    sigma2 = rrr_sigma(z[r.P], z[r.O6], z[r.E], f"{mech.name}: pin {r.E} on the line {r.P}{r.O6}")

    t, inserted, anchor = evaluation_times(mech, times)
    n = len(t)
    th2, om2, al2 = driver_input(drv, t)
    asm = Assembly(mech, t, inserted, anchor)
    zA = carry(fixed_kin(asm.fixed(r.O2), len(t)), (th2, om2, al2), a * np.exp(1j * beta2))
    ok1, phi3, phi4, zB = rrr(zA, fixed_kin(z[r.O4], n), b, c, sigma1)
    asm.set_from_vector(r.coupler, r.A, r.B, *phi3)
    asm.set_from_vector(r.rocker, r.O4, r.B, *phi4)
    zP = carry(zA, asm.angles[r.coupler], local_vector(mech, r.coupler, r.A, r.P))
    ok2, phi5, phi6, zE = rrr(zP, fixed_kin(z[r.O6], n), l5, l6, sigma2)
    fails = (
        (ok1, f"coupler {r.coupler} and rocker {r.rocker} cannot close"),
        (ok2, f"link {r.link5} and rocker {r.output} cannot close"),
    )
    check_dyads(fails, mech=mech, t=t, inserted=inserted, theta_in=th2, resolve=lambda tt: solve(mech, tt))
    asm.set_angle(r.crank, th2, om2, al2)
    asm.set_from_vector(r.link5, r.P, r.E, *phi5)
    asm.set_from_vector(r.output, r.O6, r.E, *phi6)
    for j, zz in ((r.A, zA), (r.B, zB), (r.P, zP), (r.E, zE)):
        asm.set_point(j, *zz)
    return asm.result(NAME, {"branch": [int(sigma1), int(sigma2)], "lengths": [a, b, c, l5, l6]})
