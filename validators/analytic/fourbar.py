"""Closed-form kinematics of the pin-jointed four-bar, with its limit positions.

Structure (checked by :func:`applies`; names are free): ground pivots O2, O4
(ground vector d·e^{jθ1} = O4 − O2); crank O2A (a, driven); coupler AB (b,
may carry tracer points); rocker O4B (c). φ2 is the direction O2→A (the
crank's θ when its joints are listed [O2, A]), θ3 the direction A→B, θ4 the
direction O4→B. Angles rad, CCW from +x; lengths in the file's units.

Loop equation:  a·e^{jφ2} + b·e^{jθ3} − c·e^{jθ4} − d·e^{jθ1} = 0.

Positions (triangle A–B–O4). With δ = O4 − A, f = |δ| (law of cosines:
f² = a² + d² − 2·a·d·cos(φ2 − θ1)), B lies on the circles |B − A| = b and
|B − O4| = c. Measured from A along δ/f, B's foot is p = (b² − c² + f²)/(2f)
and its distance from the diagonal q = √(b² − p²), so

    θ3 = arg δ + σ·atan2(q, p),   B = A + b·e^{jθ3},   θ4 = arg(B − O4),

σ = sign((O4 − A) × (B − A)) at t = 0 (the assembly branch of the file's
coordinates: which side of the diagonal A–O4 the pin B is on). The chain
cannot be assembled where b² − p² ≤ 0, i.e. f ≥ b + c (coupler and rocker
stretched collinear) or f ≤ |b − c| (folded collinear): the toggle positions.

Velocities (d/dt of the loop, divided by j):
    a·ω2·e^{jφ2} + b·ω3·e^{jθ3} = c·ω4·e^{jθ4}
  × e^{−jθ4}, Im:  ω3 = a·ω2·sin(θ4 − φ2) / (b·sin(θ3 − θ4)),
  × e^{−jθ3}, Im:  ω4 = a·ω2·sin(θ3 − φ2) / (c·sin(θ3 − θ4)).

Accelerations (d²/dt²):
    j·b·α3·e^{jθ3} − j·c·α4·e^{jθ4} = −R,
    R = (j·α2 − ω2²)·a·e^{jφ2} − b·ω3²·e^{jθ3} + c·ω4²·e^{jθ4},
  × e^{−jθ4}, Re:  α3 = Re(R·e^{−jθ4}) / (b·sin(θ3 − θ4)),
  × e^{−jθ3}, Re:  α4 = Re(R·e^{−jθ3}) / (c·sin(θ3 − θ4)).

Limit positions of the input (:func:`limit_angles`): the crank stops where the
coupler and the rocker become collinear, f = b + c or f = |b − c|; the law of
cosines gives cos(φ2 − θ1) = (a² + d² − f²)/(2·a·d), two input angles
θ1 ± arccos(·) for each toggle that is reachable (|·| ≤ 1).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from .common import (
    ROUNDOFF,
    TWO_PI,
    Assembly,
    LimitPositionError,
    branch_sign,
    check_assembly,
    crank_start,
    cross,
    driver_input,
    evaluation_times,
    gap_text,
    member_vector,
    other_body,
    passes_between,
    pins_of,
    sole_pin,
)

NAME = "fourbar"

__all__ = ["LimitPositionError", "applies", "grashof", "limit_angles", "solve"]


@dataclass(frozen=True)
class Roles:
    """Which bodies and joints play which part in the four-bar."""

    ground: str
    crank: str
    coupler: str
    rocker: str
    O2: str
    A: str
    B: str
    O4: str


@dataclass(frozen=True)
class Dims:
    """Lengths a (crank), b (coupler), c (rocker), d (ground); θ1 = arg(O4 − O2); β2 (crank frame offset)."""

    a: float
    b: float
    c: float
    d: float
    theta1: float
    beta2: float


def roles(mech: Mechanism) -> Roles | None:
    """Identify a crank-driven four-bar (four bodies, four order-one pins), or None."""
    st = crank_start(mech, links=4, sliders=0, pin_count=4, ground_pivots=2)
    if st is None:
        return None
    g, crank, o2, pm = st.ground, st.crank, st.pivot, st.pins
    o4 = (st.ground_pins - {o2}).pop()
    rocker = other_body(pm[o4], g)
    a = sole_pin(mech, crank, o2)
    if rocker is None or a is None:
        return None
    coupler = other_body(pm[a], crank)
    b = sole_pin(mech, rocker, o4)
    if coupler is None or coupler in (g, rocker) or b is None:
        return None
    if set(pm[b]) != {coupler, rocker} or pins_of(mech, coupler) != {a, b}:
        return None
    return Roles(g, crank, coupler, rocker, o2, a, b, o4)


def applies(mech: Mechanism) -> bool:
    """True for a crank-driven four-bar: ground, crank, coupler, rocker joined by four pins."""
    return roles(mech) is not None


def dims(mech: Mechanism, r: Roles | None = None) -> Dims:
    """Link lengths from the body frames (stated lengths win) and the ground angle."""
    r = r or roles(mech)
    if r is None:
        raise ValueError(f"{mech.name}: not a crank-driven four-bar")
    bodies = mech.bodies()
    a, beta2 = member_vector(bodies[r.crank], r.O2, r.A)
    b, _ = member_vector(bodies[r.coupler], r.A, r.B)
    c, _ = member_vector(bodies[r.rocker], r.O4, r.B)
    (x2, y2), (x4, y4) = mech.joints[r.O2], mech.joints[r.O4]
    return Dims(a, b, c, math.hypot(x4 - x2, y4 - y2), math.atan2(y4 - y2, x4 - x2), beta2)


def grashof(mech: Mechanism) -> str:
    """Grashof class: 'crank-rocker', 'drag-link', 'double-rocker', 'change-point' or 'non-Grashof (triple rocker)'.

    s + l vs p + q (shortest, longest, the other two); the class names what the
    *driven* link does when the chain is Grashof.
    """
    m = dims(mech)
    ls = sorted([m.a, m.b, m.c, m.d])
    lhs, rhs = ls[0] + ls[3], ls[1] + ls[2]
    if math.isclose(lhs, rhs, rel_tol=1e-12):
        return "change-point"
    if lhs > rhs:
        return "non-Grashof (triple rocker)"
    shortest = min((m.a, "crank"), (m.b, "coupler"), (m.c, "rocker"), (m.d, "ground"))[1]
    return {"crank": "crank-rocker", "ground": "drag-link"}.get(shortest, "double-rocker")


def toggles(mech: Mechanism) -> list[tuple[float, str]]:
    """Input angles θ (the crank link's θ, in [0, 2π)) of every reachable toggle, with its kind.

    kind is 'extended' (f = b + c) or 'folded' (f = |b − c|). Sorted by angle.
    """
    m = dims(mech)
    out = []
    for f, kind in ((m.b + m.c, "extended"), (abs(m.b - m.c), "folded")):
        x = (m.a * m.a + m.d * m.d - f * f) / (2.0 * m.a * m.d)
        if abs(x) > 1.0:
            continue
        g = math.acos(x)
        for phi in {m.theta1 + g, m.theta1 - g}:
            out.append(((phi - m.beta2) % TWO_PI, kind))
    return sorted(out)


def limit_angles(mech: Mechanism) -> tuple[float, ...]:
    """The input angles [rad, in [0, 2π)] at which the crank reaches a limit position.

    Law of cosines on triangle O2–A–O4 at a toggle (coupler and rocker collinear,
    |A − O4| = b + c or |b − c|). Empty for a crank that turns fully.
    """
    return tuple(th for th, _ in toggles(mech))


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics of the four-bar, branch from the t = 0 coordinates.

    Raises LimitPositionError (a ValueError) at the first sample where the input
    is at or beyond a limit position (no assembly, or a toggle with infinite
    rates), naming the sample, its time and the input angle; the samples before
    it are in ``.partial``.
    """
    r = roles(mech)
    if r is None:
        raise ValueError(f"{mech.name}: not a crank-driven four-bar (ground, crank, coupler, rocker, four pins)")
    m = dims(mech, r)
    drv = mech.drivers[0]
    zO2, zO4 = complex(*mech.joints[r.O2]), complex(*mech.joints[r.O4])
    sigma = branch_at_start(mech, r)

    t, inserted, anchor = evaluation_times(mech, times)
    th_in, w2, al2 = driver_input(drv, t)
    delta, f, p, q2 = diagonal(mech, r, m, th_in)
    # |A − O4| is extreme where A lies on the line O2O4: θ2 + β2 = arg(O4 − O2) (+ π)
    extremes = [np.angle(zO4 - zO2) - m.beta2 + k * np.pi for k in (0, 1)]

    slack = ROUNDOFF * (m.a + m.b + m.c + m.d)  # a reach just touched there (a change point) is reached

    def reach(th: np.ndarray) -> np.ndarray:
        ff = np.abs(zO4 - zO2 - m.a * np.exp(1j * (th + m.beta2)))
        return (ff < m.b + m.c + slack) & (ff > abs(m.b - m.c) - slack)

    between = passes_between(th_in, extremes, reach)
    ok = (q2 > 0.0) & between
    tog = toggles(mech)

    def what(k: int) -> str:
        kind = "stretched (f ≥ b + c)" if f[k] >= m.b + m.c else "folded (f ≤ |b − c|)"
        lims = ", ".join(f"{th:.10g}" for th, _ in tog) or "none"
        return (
            f"coupler {r.coupler} and rocker {r.rocker} cannot close, {kind}: |{r.A}{r.O4}| = {f[k]:.10g} "
            f"(b = {m.b:g}, c = {m.c:g}); limit angles of {r.crank}: {lims} rad{gap_text(between, k)}"
        )

    limit = None  # the toggle angle nearest the first failing input, in that input's turn
    if tog and not np.all(ok):
        th_k = float(th_in[np.flatnonzero(~ok)[0]])
        limit = min((th_k + math.remainder(th - th_k, TWO_PI) for th, _ in tog), key=lambda x: abs(x - th_k))
    check_assembly(
        ok,
        mech=mech,
        t=t,
        inserted=inserted,
        theta_in=th_in,
        what=what,
        limit=limit,
        resolve=lambda tt: solve(mech, tt),
    )

    th3 = np.angle(delta) + sigma * np.arctan2(np.sqrt(q2), p)
    asm = coupler_and_rocker(Assembly(mech, t, inserted, anchor), r, m, (th_in, w2, al2), th3)
    meta = {"branch": int(sigma), "a": m.a, "b": m.b, "c": m.c, "d": m.d, "grashof": grashof(mech)}
    return asm.result(NAME, meta)


def branch_at_start(mech: Mechanism, r: Roles) -> float:
    """σ at t = 0: +1 if B lies left of the diagonal A→O4 in the file's coordinates, −1 if right."""
    zO4, zA0, zB0 = (complex(*mech.joints[j]) for j in (r.O4, r.A, r.B))
    return branch_sign(float(cross(zO4 - zA0, zB0 - zA0)), f"{mech.name}: pin {r.B} on the diagonal {r.A}{r.O4}")


def diagonal(mech: Mechanism, r: Roles, m: Dims, th_in: np.ndarray) -> tuple[np.ndarray, ...]:
    """(δ, f, p, q²) at crank angles θ [rad]: δ = O4 − A, f = |δ|, B's foot p along δ and height² q² = b² − p²."""
    zO2, zO4 = complex(*mech.joints[r.O2]), complex(*mech.joints[r.O4])
    phi2 = th_in + m.beta2
    rA = m.a * np.exp(1j * phi2)
    zA = zO2 + rA
    delta = zO4 - zA
    f = np.abs(delta)
    p = (m.b * m.b - m.c * m.c + f * f) / (2.0 * f)
    q2 = (m.b - p) * (m.b + p)
    return delta, f, p, q2


def coupler_and_rocker(asm: Assembly, r: Roles, m: Dims, crank: tuple[np.ndarray, ...], th3: np.ndarray) -> Assembly:
    """Fill ``asm`` from the coupler's angle θ3 (rad) and the crank's input ``crank`` = (θ, ω, α):
    the rocker's θ4 = arg(B − O4), and the rates by the four-bar's rigid-link conditions
    (ω3 = a·ω2·sin(θ4 − φ2)/(b·sin(θ3 − θ4)), ω4 likewise; α3, α4 by the same projections)."""
    th_in, w2, al2 = crank
    phi2 = th_in + m.beta2
    rA = m.a * np.exp(1j * phi2)
    zA = complex(*asm.mech.joints[r.O2]) + rA
    zO4 = complex(*asm.mech.joints[r.O4])
    rB = m.b * np.exp(1j * th3)
    zB = zA + rB
    th4 = np.angle(zB - zO4)
    s34 = np.sin(th3 - th4)
    w3 = m.a * w2 * np.sin(th4 - phi2) / (m.b * s34)
    w4 = m.a * w2 * np.sin(th3 - phi2) / (m.c * s34)
    R = (1j * al2 - w2 * w2) * rA - m.b * w3 * w3 * np.exp(1j * th3) + m.c * w4 * w4 * np.exp(1j * th4)
    al3 = (R * np.exp(-1j * th4)).real / (m.b * s34)
    al4 = (R * np.exp(-1j * th3)).real / (m.c * s34)
    asm.set_angle(r.crank, th_in, w2, al2)
    asm.set_from_vector(r.coupler, r.A, r.B, th3, w3, al3)
    asm.set_from_vector(r.rocker, r.O4, r.B, th4, w4, al4)
    zAd, zAdd = 1j * w2 * rA, (1j * al2 - w2 * w2) * rA
    asm.set_point(r.A, zA, zAd, zAdd)
    asm.set_point(r.B, zB, zAd + 1j * w3 * rB, zAdd + (1j * al3 - w3 * w3) * rB)
    return asm
