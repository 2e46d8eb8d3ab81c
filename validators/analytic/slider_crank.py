"""Closed-form kinematics of the offset slider-crank (either assembly branch).

Topology (checked by :func:`applies`, names are free): ground pivot O2, crank
O2A (length a, driven: θ2, ω2, α2), connecting rod AB (length b), block at B
sliding on a ground-fixed line through B's t = 0 position with unit axis
u = e^{jφ} (any direction; "horizontal" is φ = 0 or π); n = j·u is the line's
normal. The offset e = (B0 − O2)·n is the line's signed distance from the
crank pivot, η(t) = (A − B0)·n the crank pin's signed distance from the line.

Loop equation (complex numbers, world frame; L0 = B0 a point of the line,
s the block's displacement, s = u·B as in the file's convention):

    O2 + a·e^{jθ2} + b·e^{jθ3} = B = L0 + (s − u·L0)·u.

Positions. Project on n (the component across the line): with ψ = θ3 − φ,

    (A − L0)·n + b·sin ψ = 0     ⇒   sin ψ = −η / b,
    cos ψ = σ·√(1 − sin²ψ),         σ = sign((B0 − A0)·u) from the t = 0 coordinates,

so θ3 = φ + atan2(sin ψ, cos ψ); projecting on u, s = u·A + b·cos ψ. The block
cannot be assembled where η² ≥ b² (the rod can no longer reach the line).
For u = (1, 0), L0 = (c0, e), O2 = 0 this is the textbook a·sin θ2 + b·sin θ3 = e,
s = a·cos θ2 + b·cos θ3.

Velocities (differentiate once; ż_A = j·ω2·a·e^{jθ2}, η̇ = ż_A·n):

    b·cos ψ·ω3 = −η̇               ⇒  ω3 = −η̇ / (b·cos ψ),
    ṡ = u·ż_A − b·sin ψ·ω3.

Accelerations (differentiate again; z̈_A = (jα2 − ω2²)·a·e^{jθ2}, η̈ = z̈_A·n):

    b·cos ψ·α3 − b·sin ψ·ω3² = −η̈  ⇒  α3 = (b·sin ψ·ω3² − η̈) / (b·cos ψ),
    s̈ = u·z̈_A − b·cos ψ·ω3² − b·sin ψ·α3.

Joints: A from the crank, B = A + b·e^{jθ3} (and its derivatives), other
points by rigid-body transport. Units: the file's lengths, s, rad/s, rad/s².
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from .common import (
    ROUNDOFF,
    Assembly,
    branch_sign,
    check_assembly,
    crank_start,
    driver_input,
    evaluation_times,
    gap_text,
    member_vector,
    other_body,
    passes_between,
    pins_of,
    sole_pin,
)
from .dyads import rrp

NAME = "slider_crank"


@dataclass(frozen=True)
class Roles:
    """Which bodies and joints play which part in the slider-crank."""

    ground: str
    crank: str
    rod: str
    block: str
    O2: str
    A: str
    B: str


def roles(mech: Mechanism) -> Roles | None:
    """Identify the slider-crank structure, or None if the mechanism is not one."""
    st = crank_start(mech, links=3, sliders=1, pin_count=3, ground_pivots=1)
    if st is None:
        return None
    block, sl = next(iter(mech.sliders.items()))
    a = sole_pin(mech, st.crank, st.pivot)
    rod = None if a is None else other_body(st.pins[a], st.crank)
    if sl.guide != st.ground or rod is None or rod not in mech.links or pins_of(mech, rod) != {a, sl.joint}:
        return None
    if set(st.pins[sl.joint]) != {rod, block}:
        return None
    return Roles(st.ground, st.crank, rod, block, st.pivot, a, sl.joint)


def applies(mech: Mechanism) -> bool:
    """True for a crank-driven slider-crank: ground–crank–rod–block on a ground-fixed line."""
    return roles(mech) is not None


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form positions, velocities and accelerations of an offset slider-crank.

    Raises LimitPositionError (a ValueError) at the first sample the rod cannot
    reach the sliding line, with the samples before it in ``.partial``.
    """
    r = roles(mech)
    if r is None:
        raise ValueError(f"{mech.name}: not a crank-driven slider-crank (ground, crank, rod, block on a ground line)")
    drv = mech.drivers[0]
    bodies = mech.bodies()
    a, beta2 = member_vector(bodies[r.crank], r.O2, r.A)
    b, _ = member_vector(bodies[r.rod], r.A, r.B)
    sl = mech.sliders[r.block]
    u = complex(*sl.axis)
    L0 = complex(*mech.joints[r.B])
    zA0, zB0 = complex(*mech.joints[r.A]), complex(*mech.joints[r.B])
    sigma = branch_sign((np.conj(u) * (zB0 - zA0)).real, f"{mech.name}: rod {r.rod} perpendicular to the line")

    t, inserted, anchor = evaluation_times(mech, times)
    th2, om2, al2 = driver_input(drv, t)
    asm = Assembly(mech, t, inserted, anchor)
    zO2 = asm.fixed(r.O2)
    rA = a * np.exp(1j * (th2 + beta2))  # O2→A
    zA = (zO2 + rA, 1j * om2 * rA, (1j * al2 - om2 * om2) * rA)
    ok, (th3, om3, al3), _ = rrp(zA, b, L0, u, sigma)
    # the crank pin's distance from the line, a·cos(θ2 + β2 − arg n) + const, is extreme at θ2 = arg n − β2 (+ π)
    extremes = [np.angle(1j * u) - beta2 + k * np.pi for k in (0, 1)]

    slack = ROUNDOFF * (a + b + abs(L0 - zO2))  # a line the rod just touches there (a change point) is reached

    def reach(th: np.ndarray) -> np.ndarray:
        return np.abs((np.conj(1j * u) * (zO2 + a * np.exp(1j * (th + beta2)) - L0)).real) < b + slack

    between = passes_between(th2, extremes, reach)
    check_assembly(
        ok & between,
        mech=mech,
        t=t,
        inserted=inserted,
        theta_in=th2,
        what=lambda k: f"rod {r.rod} (b = {b:g}) cannot reach the line of slider {r.block}{gap_text(between, k)}",
        limit=None,
        resolve=lambda tt: solve(mech, tt),
    )
    rB = b * np.exp(1j * th3)
    asm.set_angle(r.crank, th2, om2, al2)
    asm.set_from_vector(r.rod, r.A, r.B, th3, om3, al3)
    asm.set_point(r.A, *zA)
    asm.set_point(r.B, zA[0] + rB, zA[1] + 1j * om3 * rB, zA[2] + (1j * al3 - om3 * om3) * rB)
    offset = float((np.conj(1j * u) * (L0 - zO2)).real)
    return asm.result(NAME, {"branch": int(sigma), "a": a, "b": b, "offset": offset})
