"""Closed-form kinematics of the Watt II six-bar: two four-bars in series, solved as two dyads.

Structure (checked by :func:`applies`; names are free): ground pivots O2, O4, O6;
crank O2A (a, driven θ2, ω2, α2); coupler AB (b); a ternary rocker turning about
O4 that carries B and C (|O4B| = c); coupler CD (l5); output rocker O6D (l6).
Every pin joins exactly two bodies. Angles: φ3 = arg(B − A), φ4 = arg(B − O4),
φ5 = arg(D − C), φ6 = arg(D − O6) (member-vector directions; a body's own θ is
φ − β, β the vector's angle in its frame, see validators.analytic.common).

Loops (complex numbers):

    O2 + a·e^{jθ2} + b·e^{jφ3} = O4 + c·e^{jφ4}                (first four-bar)
    O4 + e^{jθ4}·ρ_C + l5·e^{jφ5} = O6 + l6·e^{jφ6}            (second four-bar)

ρ_C the rocker-frame vector O4→C, θ4 = φ4 − β4 the rocker's angle.

Step 1 — A from the crank: A = O2 + a·e^{jθ2}, Ȧ = j·ω2·(A − O2),
Ä = (j·α2 − ω2²)·(A − O2).

Step 2 — RRR dyad A–B–O4 (law of cosines in triangle A–B–O4): δ = O4 − A,
f = |δ|, p = (b² − c² + f²)/(2f), q = √(b² − p²); φ3 = arg δ + σ1·atan2(q, p),
B = A + b·e^{jφ3}, φ4 = arg(B − O4). Rates (differentiate the first loop and
project on e^{jφ4}, e^{jφ3}; D1 = −Ȧ since O4 is fixed):
    ω3 = −Re(D1·e^{−jφ4})/(b·sin(φ3 − φ4)),   ω4 = Re(D1·e^{−jφ3})/(c·sin(φ4 − φ3)),
    α3, α4: the same with R1 = −Ä + b·ω3²·e^{jφ3} − c·ω4²·e^{jφ4} in place of D1.

Step 3 — C on the rocker: C = O4 + e^{jθ4}·ρ_C, Ċ = j·ω4·(C − O4),
C̈ = (j·α4 − ω4²)·(C − O4).

Step 4 — RRR dyad C–D–O6: the same triangle with (C, l5, O6, l6, σ2):
    ω5 = −Re(D2·e^{−jφ6})/(l5·sin(φ5 − φ6)),  ω6 = Re(D2·e^{−jφ5})/(l6·sin(φ6 − φ5)),
D2 = −Ċ, and R2 = −C̈ + l5·ω5²·e^{jφ5} − l6·ω6²·e^{jφ6} for α5, α6.

σ1 = sign((O4 − A) × (B − A)), σ2 = sign((O6 − C) × (D − C)) at t = 0 (each
dyad's assembly branch). A dyad cannot be closed where its base |δ| leaves
(|l1 − l2|, l1 + l2). The general dyad is :func:`validators.analytic.dyads.rrr`.
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

NAME = "sixbar_watt2"

__all__ = ["applies", "roles", "solve"]


@dataclass(frozen=True)
class Roles:
    """Which bodies and joints play which part in the Watt II six-bar."""

    ground: str
    crank: str
    coupler: str
    rocker: str  # ternary: O4, B, C
    coupler2: str
    output: str
    O2: str
    A: str
    B: str
    O4: str
    C: str
    D: str
    O6: str


def roles(mech: Mechanism) -> Roles | None:
    """Identify crank–coupler–ternary rocker–coupler–output rocker on three ground pivots, or None."""
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
    if len(kp) != 1:
        return None
    b = kp.pop()
    rocker = other_body(pm[b], coupler)
    if rocker is None or rocker == g:
        return None
    rp = pins_of(mech, rocker)
    o4s = rp & gp
    if len(rp) != 3 or len(o4s) != 1:
        return None
    o4 = o4s.pop()
    c = (rp - {o4, b}).pop()
    coupler2 = other_body(pm[c], rocker)
    if coupler2 is None or coupler2 == g:
        return None
    k2 = pins_of(mech, coupler2) - {c}
    if len(k2) != 1:
        return None
    d = k2.pop()
    output = other_body(pm[d], coupler2)
    if output is None or output == g:
        return None
    op = pins_of(mech, output) - {d}
    if len(op) != 1 or (o6 := op.pop()) not in gp - {o2, o4}:
        return None
    return Roles(g, crank, coupler, rocker, coupler2, output, o2, a, b, o4, c, d, o6)


def applies(mech: Mechanism) -> bool:
    """True for a crank-driven Watt II six-bar (second four-bar driven by a ternary ground-pivoted rocker)."""
    return roles(mech) is not None


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics over ``times`` (default: the file's [time]).

    Raises LimitPositionError (a ValueError) at the first sample a dyad cannot
    be closed, with the samples before it in ``.partial``.
    """
    r = roles(mech)
    if r is None:
        raise ValueError(f"{mech.name}: not a crank-driven Watt II six-bar")
    drv = mech.drivers[0]
    bodies = mech.bodies()
    a, beta2 = member_vector(bodies[r.crank], r.O2, r.A)
    b, _ = member_vector(bodies[r.coupler], r.A, r.B)
    c, _ = member_vector(bodies[r.rocker], r.O4, r.B)
    l5, _ = member_vector(bodies[r.coupler2], r.C, r.D)
    l6, _ = member_vector(bodies[r.output], r.O6, r.D)
    z = {j: complex(*mech.joints[j]) for j in (r.A, r.B, r.O4, r.C, r.D, r.O6)}
    sigma1 = rrr_sigma(z[r.A], z[r.O4], z[r.B], f"{mech.name}: pin {r.B} on the line {r.A}{r.O4}")
    sigma2 = rrr_sigma(z[r.C], z[r.O6], z[r.D], f"{mech.name}: pin {r.D} on the line {r.C}{r.O6}")

    t, inserted, anchor = evaluation_times(mech, times)
    n = len(t)
    th2, om2, al2 = driver_input(drv, t)
    asm = Assembly(mech, t, inserted, anchor)
    zA = carry(fixed_kin(asm.fixed(r.O2), len(t)), (th2, om2, al2), a * np.exp(1j * beta2))
    zO4 = fixed_kin(z[r.O4], n)
    ok1, phi3, phi4, zB = rrr(zA, zO4, b, c, sigma1)
    asm.set_from_vector(r.coupler, r.A, r.B, *phi3)
    asm.set_from_vector(r.rocker, r.O4, r.B, *phi4)
    zC = carry(zO4, asm.angles[r.rocker], local_vector(mech, r.rocker, r.O4, r.C))
    ok2, phi5, phi6, zD = rrr(zC, fixed_kin(z[r.O6], n), l5, l6, sigma2)
    fails = (
        (ok1, f"coupler {r.coupler} and rocker {r.rocker} cannot close"),
        (ok2, f"coupler {r.coupler2} and rocker {r.output} cannot close"),
    )
    check_dyads(fails, mech=mech, t=t, inserted=inserted, theta_in=th2, resolve=lambda tt: solve(mech, tt))
    asm.set_angle(r.crank, th2, om2, al2)
    asm.set_from_vector(r.coupler2, r.C, r.D, *phi5)
    asm.set_from_vector(r.output, r.O6, r.D, *phi6)
    for j, zz in ((r.A, zA), (r.B, zB), (r.C, zC), (r.D, zD)):
        asm.set_point(j, *zz)
    return asm.result(NAME, {"branch": [int(sigma1), int(sigma2)], "lengths": [a, b, c, l5, l6]})
