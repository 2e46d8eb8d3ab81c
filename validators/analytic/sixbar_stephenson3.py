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
is :func:`validators.analytic.dyads.rrr`; the steps are :func:`validators.analytic.sixbar.solve`'s.
"""

from __future__ import annotations

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from . import sixbar
from .common import next_link, pins_of
from .sixbar import SixBar

NAME = "sixbar_stephenson3"

__all__ = ["applies", "roles", "solve"]


def roles(mech: Mechanism) -> SixBar | None:
    """Identify a four-bar whose ternary coupler drives a dyad to a third ground pivot, or None."""
    start = sixbar.four_bar_start(mech)
    if start is None:
        return None
    st, a, coupler = start
    kp = pins_of(mech, coupler) - {a}
    if len(kp) != 2:
        return None
    # of the coupler's two other pins, B leads to a rocker pivoted on the ground, P to the dyad
    found = []
    for b in kp:
        rocker = next_link(st, b, coupler)
        rp = pins_of(mech, rocker) if rocker is not None else set()
        if len(rp) == 2 and len(rp & st.ground_pins) == 1:
            found.append((b, rocker, (rp & st.ground_pins).pop()))
    if len(found) != 1:
        return None
    b, rocker, o4 = found[0]
    p = (kp - {b}).pop()
    dyad = sixbar.second_dyad(mech, st, coupler, p, rocker, o4)
    if dyad is None:
        return None
    link5, e, output, o6 = dyad
    return SixBar(st.ground, st.crank, coupler, rocker, link5, output, st.pivot, a, b, o4, p, e, o6, coupler, a)


def applies(mech: Mechanism) -> bool:
    """True for a crank-driven Stephenson III six-bar (a dyad hung on the four-bar's ternary coupler)."""
    return roles(mech) is not None


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics over ``times`` (default: the file's [time]): :func:`validators.analytic.sixbar.solve`."""
    return sixbar.solve(mech, times, roles(mech), (NAME, "Stephenson III six-bar", "link"))
