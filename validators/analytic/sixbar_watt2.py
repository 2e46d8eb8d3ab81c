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
(|l1 − l2|, l1 + l2). The general dyad is :func:`validators.analytic.dyads.rrr`; the steps are
:func:`validators.analytic.sixbar.solve`'s (C is its P, D its E).
"""

from __future__ import annotations

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from . import sixbar
from .common import next_link, pins_of
from .sixbar import SixBar

NAME = "sixbar_watt2"

__all__ = ["applies", "roles", "solve"]


def roles(mech: Mechanism) -> SixBar | None:
    """Identify crank–coupler–ternary rocker–coupler–output rocker on three ground pivots, or None."""
    start = sixbar.four_bar_start(mech)
    if start is None:
        return None
    st, a, coupler = start
    kp = pins_of(mech, coupler) - {a}
    if len(kp) != 1:
        return None
    b = kp.pop()
    rocker = next_link(st, b, coupler)
    rp = set() if rocker is None else pins_of(mech, rocker)
    o4s = rp & st.ground_pins
    if len(rp) != 3 or len(o4s) != 1:
        return None
    o4 = o4s.pop()
    c = (rp - {o4, b}).pop()
    found = sixbar.second_dyad(mech, st, rocker, c, rocker, o4)
    if found is None:
        return None
    coupler2, d, output, o6 = found
    return SixBar(st.ground, st.crank, coupler, rocker, coupler2, output, st.pivot, a, b, o4, c, d, o6, rocker, o4)


def applies(mech: Mechanism) -> bool:
    """True for a crank-driven Watt II six-bar (second four-bar driven by a ternary ground-pivoted rocker)."""
    return roles(mech) is not None


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics over ``times`` (default: the file's [time]): :func:`validators.analytic.sixbar.solve`."""
    return sixbar.solve(mech, times, roles(mech), (NAME, "Watt II six-bar", "coupler"))
