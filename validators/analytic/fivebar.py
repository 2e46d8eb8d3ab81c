"""Closed-form kinematics of the five-bar with two driven cranks (mobility 2): one dyad.

Structure (checked by :func:`applies`; names are free): ground pivots O2, O5;
two crank drivers, O2A (a, θ2, ω2, α2) and O5D (e, θ5, ω5, α5); link AC (l3) and
link DC (l4) pinned together at the output pin C. Every pin joins exactly two
bodies. φ3 = arg(C − A), φ4 = arg(C − D) (member-vector directions; a body's own
θ is φ − β, β the vector's angle in its frame, see validators.analytic.common).

Loop (complex numbers):

    O2 + a·e^{jθ2} + l3·e^{jφ3} = O5 + e·e^{jθ5} + l4·e^{jφ4}.

Both cranks are inputs, so A and D are known with their rates:
A = O2 + a·e^{jθ2}, Ȧ = j·ω2·(A − O2), Ä = (j·α2 − ω2²)·(A − O2); D likewise.

Positions — RRR dyad A–C–D (law of cosines in triangle A–C–D): δ = D − A,
f = |δ|, p = (l3² − l4² + f²)/(2f), q = √(l3² − p²),
φ3 = arg δ + σ·atan2(q, p), C = A + l3·e^{jφ3}, φ4 = arg(C − D);
σ = sign((D − A) × (C − A)) at t = 0. No assembly where f ≥ l3 + l4 or
f ≤ |l3 − l4|.

Velocities (differentiate the loop: j·l3·ω3·e^{jφ3} − j·l4·ω4·e^{jφ4} = Ḋ − Ȧ;
project on e^{jφ4} and e^{jφ3}):
    ω3 = −Re((Ḋ − Ȧ)·e^{−jφ4})/(l3·sin(φ3 − φ4)),
    ω4 = Re((Ḋ − Ȧ)·e^{−jφ3})/(l4·sin(φ4 − φ3)).
Accelerations: the same with R = D̈ − Ä + l3·ω3²·e^{jφ3} − l4·ω4²·e^{jφ4}.
Unlike a four-bar, both pins of the dyad move: the result is a function of the two
inputs and their rates, whatever each crank does (one may reverse).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from .common import (
    Assembly,
    check_assembly,
    driver_input,
    evaluation_times,
    member_vector,
    other_body,
    pins,
    pins_of,
)
from .dyads import close_rrr, crank_pin

NAME = "fivebar"

__all__ = ["applies", "roles", "solve"]


@dataclass(frozen=True)
class Roles:
    """Which bodies and joints play which part in the two-crank five-bar."""

    ground: str
    crank2: str
    link3: str
    link4: str
    crank5: str
    O2: str
    A: str
    C: str
    D: str
    O5: str


def roles(mech: Mechanism) -> Roles | None:
    """Identify ground–crank–link–link–crank driven by its two cranks, or None."""
    if len(mech.drivers) != 2 or any(d.kind != "crank" for d in mech.drivers):
        return None
    if mech.sliders or len(mech.links) != 5:
        return None
    g = mech.ground
    (c2, o2), (c5, o5) = ((d.target, d.pivot) for d in mech.drivers)
    pm = pins(mech)
    if len(pm) != 5 or any(len(bs) != 2 for bs in pm.values()):
        return None
    if pins_of(mech, g) != {o2, o5} or set(pm[o2]) != {g, c2} or set(pm[o5]) != {g, c5}:
        return None
    p2, p5 = pins_of(mech, c2) - {o2}, pins_of(mech, c5) - {o5}
    if len(p2) != 1 or len(p5) != 1:
        return None
    a, d = p2.pop(), p5.pop()
    l3, l4 = other_body(pm[a], c2), other_body(pm[d], c5)
    if l3 is None or l4 is None or len({g, c2, c5, l3, l4}) != 5:
        return None
    common = (pins_of(mech, l3) - {a}) & (pins_of(mech, l4) - {d})
    if len(common) != 1 or pins_of(mech, l3) != {a, *common} or pins_of(mech, l4) != {d, *common}:
        return None
    return Roles(g, c2, l3, l4, c5, o2, a, common.pop(), d, o5)


def applies(mech: Mechanism) -> bool:
    """True for a five-bar driven by both of its ground-pivoted cranks."""
    return roles(mech) is not None


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics over ``times`` (default: the file's [time]).

    Raises LimitPositionError (a ValueError) at the first sample the two links
    cannot reach each other, with the samples before it in ``.partial``
    (``input_value`` is the first crank's θ there).
    """
    r = roles(mech)
    if r is None:
        raise ValueError(f"{mech.name}: not a five-bar driven by its two cranks")
    t, inserted, anchor = evaluation_times(mech, times)
    drv = {d.target: d for d in mech.drivers}
    th2, th5 = driver_input(drv[r.crank2], t), driver_input(drv[r.crank5], t)
    asm = Assembly(mech, t, inserted, anchor)
    asm.set_angle(r.crank2, *th2)
    asm.set_angle(r.crank5, *th5)
    zA, zD = crank_pin(asm, r.crank2, r.O2, r.A, th2), crank_pin(asm, r.crank5, r.O5, r.D, th5)
    asm.set_point(r.A, *zA)
    asm.set_point(r.D, *zD)
    ok, _, sigma = close_rrr(asm, (r.link3, r.link4), (r.A, r.D, r.C), zA, zD)
    f = np.abs(zD[0] - zA[0])
    check_assembly(
        ok,
        mech=mech,
        t=t,
        inserted=inserted,
        theta_in=th2[0],
        what=lambda k: f"links {r.link3} and {r.link4} cannot reach each other (|{r.A}{r.D}| = {f[k]:.10g})",
        limit=None,
        resolve=lambda tt: solve(mech, tt),
    )
    bodies = mech.bodies()
    lengths = [member_vector(bodies[b], j1, j2)[0] for b, j1, j2 in ((r.crank2, r.O2, r.A), (r.link3, r.A, r.C))]
    lengths += [member_vector(bodies[b], j1, j2)[0] for b, j1, j2 in ((r.link4, r.D, r.C), (r.crank5, r.O5, r.D))]
    return asm.result(NAME, {"branch": int(sigma), "lengths": lengths})
