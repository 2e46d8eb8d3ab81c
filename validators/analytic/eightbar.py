"""The paper's algebraic solution of its eight-bar (Fig. 1, Table 1, Eqs. 2–6).

Structure (checked by :func:`applies`; names are free, the paper's in brackets):
crank [l2] O2A (a, driven θ2, ω2, α2); coupler [l3] AB (b); block [l4] at B on a
horizontal ground line y = y_B (the line of B at t = 0); two rods [l5] BC (d)
and [l7] BD (m) whose far ends carry blocks [l6], [l8] on vertical ground lines
x = h_C, x = h_D. Lengths come from the body frames (``Body.local``, so a stated
``length`` wins over the rounded coordinates); lines from the joints' t = 0
coordinates. In the paper O2 = 0, y_B = 0, h_C = h_D = h = 8.

Notation: θ2 is the direction of O2→A, θ3 of A→B, θ5 of B→C, θ7 of B→D (the
links' θ when their joints are listed in that order, as in ``eightbar.toml``);
c = x_B (the paper's c), k = y_C − y_B, and −g = y_D − y_B (g > 0 in Fig. 1).
Slider outputs follow the file's convention s = axis·P: l4.s = c for axis
(1, 0), l6.s = y_C = k for axis (0, 1), l8.s = −y_D = g for axis (0, −1).

Loop 1, O2AB (Eq. 3 first line, with the pivot at O2 = x0 + j·y0):
    x0 + j·y0 + a·e^{jθ2} + b·e^{jθ3} = c + j·y_B
  Im:  sin θ3 = (y_B − y0 − a·sin θ2)/b,  cos θ3 = σ1·√(1 − sin²θ3),
       σ1 = sign(x_B − x_A) at t = 0 (+1 in Fig. 1: θ3 = −0.6435 ≡ 5.6397),
  Re:  c = x0 + a·cos θ2 + b·cos θ3.
  d/dt (Eq. 4):   ω3 = −a·ω2·cos θ2 / (b·cos θ3),
                  ċ = −a·ω2·sin θ2 − b·ω3·sin θ3.
  d²/dt² (Eq. 5): α3 = (a·ω2²·sin θ2 + b·ω3²·sin θ3 − a·α2·cos θ2) / (b·cos θ3),
                  c̈ = −a·α2·sin θ2 − a·ω2²·cos θ2 − b·α3·sin θ3 − b·ω3²·cos θ3.

Loops 2 and 3, BCE and BDE (Eq. 3 lines 2–3; E = h + j·y_B on both lines):
    c + j·y_B + d·e^{jθ5} = h_C + j·(y_B + k)
  Re:  cos θ5 = (h_C − c)/d,
  Im:  k = d·sin θ5,  sin θ5 = σ2·√(1 − cos²θ5),  σ2 = sign(y_C − y_B) at t = 0.
  d/dt:    ω5 = ċ / (d·sin θ5),           k̇ = d·ω5·cos θ5,
  d²/dt²:  α5 = (c̈ − d·ω5²·cos θ5) / (d·sin θ5),
           k̈ = d·α5·cos θ5 − d·ω5²·sin θ5.
  Loop 3 is the same with m, h_D, θ7, σ3 = sign(y_D − y_B) (−1 in Fig. 1,
  θ7 = −0.8627 ≡ 5.4205) and y_D − y_B = m·sin θ7 = −g.

Joints: A = O2 + a·e^{jθ2} (Ȧ = jω2(A − O2), Ä = (jα2 − ω2²)(A − O2));
B = c + j·y_B; C = h_C + j·(y_B + k); D likewise; their rates from ċ, k̇, ....
Assembly fails where |sin θ3| ≥ 1 or |cos θ5|, |cos θ7| ≥ 1 (a rod cannot reach
its line); for Table 1's dimensions it never does. Units: the file's (m, s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from .common import (
    AXIS_TOL,
    Assembly,
    branch_sign,
    check_dyads,
    crank_start,
    driver_input,
    evaluation_times,
    member_vector,
    other_body,
    sole_pin,
)

NAME = "eightbar"


@dataclass(frozen=True)
class Roles:
    """Which bodies and joints play which part in the paper's eight-bar."""

    crank: str
    coupler: str
    block_b: str
    rods: tuple[str, str]
    blocks: tuple[str, str]  # on the vertical lines, at the rods' far ends
    O2: str
    A: str
    B: str
    ends: tuple[str, str]  # C, D


def roles(mech: Mechanism) -> Roles | None:
    """Identify the eight-bar structure of the paper's Fig. 1, or None."""
    st = crank_start(mech, links=5, sliders=3, pin_count=5, ground_pivots=1, binary=False)
    if st is None or any(sl.guide != st.ground for sl in mech.sliders.values()):
        return None
    crank, o2, pm = st.crank, st.pivot, st.pins
    a = sole_pin(mech, crank, o2)
    coupler = None if a is None else other_body(pm[a], crank)
    if coupler is None or coupler not in mech.links:
        return None
    b = sole_pin(mech, coupler, a)
    if b is None:
        return None
    at_b = [x for x in pm[b] if x != coupler]
    blocks_b = [x for x in at_b if x in mech.sliders]
    rods = [x for x in mech.links if x in at_b]  # file order
    if len(pm[b]) != 4 or len(blocks_b) != 1 or len(rods) != 2:
        return None
    _, uy = mech.sliders[blocks_b[0]].axis
    if abs(uy) > AXIS_TOL:
        return None
    ends, blocks = [], []
    for rod in rods:
        e = sole_pin(mech, rod, b)
        if e is None:
            return None
        blk = other_body(pm[e], rod)
        if blk not in mech.sliders or mech.sliders[blk].joint != e or abs(mech.sliders[blk].axis[0]) > AXIS_TOL:
            return None
        ends.append(e)
        blocks.append(blk)
    return Roles(crank, coupler, blocks_b[0], (rods[0], rods[1]), (blocks[0], blocks[1]), o2, a, b, (ends[0], ends[1]))


def applies(mech: Mechanism) -> bool:
    """True for the paper's eight-bar: crank–coupler–horizontal block at B, two rods to vertical blocks."""
    return roles(mech) is not None


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics of the eight-bar over ``times`` (default: the file's [time]).

    Raises LimitPositionError (a ValueError) at the first sample a loop cannot
    be closed, with the samples before it in ``.partial``.
    """
    r = roles(mech)
    if r is None:
        raise ValueError(f"{mech.name}: not the paper's eight-bar structure (Fig. 1)")
    drv = mech.drivers[0]
    bodies = mech.bodies()
    a, beta2 = member_vector(bodies[r.crank], r.O2, r.A)
    b, _ = member_vector(bodies[r.coupler], r.A, r.B)
    x0, y0 = mech.joints[r.O2]
    xA0 = mech.joints[r.A][0]
    xB0, yB = mech.joints[r.B]
    sigma1 = branch_sign(xB0 - xA0, f"{mech.name}: coupler {r.coupler} vertical")

    t, inserted, anchor = evaluation_times(mech, times)
    th_in, w2, al2 = driver_input(drv, t)
    th2 = th_in + beta2
    s2, c2 = np.sin(th2), np.cos(th2)

    # loop 1
    s3 = (yB - y0 - a * s2) / b
    ok = 1.0 - s3 * s3 > 0.0
    c3 = sigma1 * np.sqrt(np.where(ok, 1.0 - s3 * s3, 1.0))
    th3 = np.arctan2(s3, c3)
    c = x0 + a * c2 + b * c3
    w3 = -a * w2 * c2 / (b * c3)
    cd = -a * w2 * s2 - b * w3 * s3
    al3 = (a * w2 * w2 * s2 + b * w3 * w3 * s3 - a * al2 * c2) / (b * c3)
    cdd = -a * al2 * s2 - a * w2 * w2 * c2 - b * al3 * s3 - b * w3 * w3 * c3
    failures = [(ok, f"coupler {r.coupler} (b = {b:g}) cannot reach the line of block {r.block_b}")]

    # loops 2 and 3
    rod_sol = []
    for rod, end in zip(r.rods, r.ends, strict=True):
        d, _ = member_vector(bodies[rod], r.B, end)
        h, yE0 = mech.joints[end]
        sigma = branch_sign(yE0 - yB, f"{mech.name}: rod {rod} along the line of {r.block_b}")
        c5 = (h - c) / d
        ok5 = 1.0 - c5 * c5 > 0.0
        failures.append((ok5, f"rod {rod} (length {d:g}) cannot reach the line of its block"))
        s5 = sigma * np.sqrt(np.where(ok5, 1.0 - c5 * c5, 1.0))
        th5 = np.arctan2(s5, c5)
        w5 = cd / (d * s5)
        al5 = (cdd - d * w5 * w5 * c5) / (d * s5)
        k, kd = d * s5, d * w5 * c5
        kdd = d * al5 * c5 - d * w5 * w5 * s5
        rod_sol.append((rod, end, h, th5, w5, al5, k, kd, kdd))

    check_dyads(failures, mech=mech, t=t, inserted=inserted, theta_in=th_in, resolve=lambda tt: solve(mech, tt))
    asm = Assembly(mech, t, inserted, anchor)
    zO2 = complex(x0, y0)
    rA = a * np.exp(1j * th2)
    asm.set_angle(r.crank, th_in, w2, al2)
    asm.set_point(r.A, zO2 + rA, 1j * w2 * rA, (1j * al2 - w2 * w2) * rA)
    asm.set_from_vector(r.coupler, r.A, r.B, th3, w3, al3)
    asm.set_point(r.B, c + 1j * yB, cd + 0j, cdd + 0j)
    for rod, end, h, th5, w5, al5, k, kd, kdd in rod_sol:
        asm.set_from_vector(rod, r.B, end, th5, w5, al5)
        asm.set_point(end, h + 1j * (yB + k), 1j * kd, 1j * kdd)
    meta = {"a": a, "b": b, "h": [s[2] for s in rod_sol], "branch": [int(sigma1)]}
    return asm.result(NAME, meta)
