"""Closed-form kinematics of the inverted slider-crank (the paper's "inverse slider").

Structure (checked by :func:`applies`; names are free): ground pivots O2 and O4;
crank O2A (length a, driven: θ2, ω2, α2); a block pinned to the crank at A that
slides along a line fixed to the rocker, which turns about O4. The line's
direction u = e^{jφ} is the slider axis; at t = 0 it passes at signed distance
e = u × (A − O4) from O4 (e = 0 when the slot runs through the pivot). The
rocker may carry any other points (its θ = φ − γ, γ the axis angle in its frame).

Loop (complex numbers; s is A's position along the line from the foot of O4):

    O2 + a·e^{jθ2} = A = O4 + (s + j·e)·e^{jφ}.

Positions. The crank gives A directly; with δ = A − O4 = ρ·e^{jψ}, the line
through A at distance e from O4 makes sin(ψ − φ) = e/ρ, so

    s = σ·√(ρ² − e²),   φ = ψ − atan2(e, s),

σ = sign(s) at t = 0 (which way along the axis the block sits from O4). No
assembly where ρ ≤ |e| (the crank pin comes closer to O4 than the slot's offset).

Velocities and accelerations (the RPR dyad of :mod:`validators.analytic.dyads`,
δ̇ = Ȧ = j·ω2·(A − O2), δ̈ = Ä = (j·α2 − ω2²)·(A − O2)):

    ω = Im(conj(u)·δ̇)/s,               ṡ = Re(conj(u)·δ̇) + ω·e,
    α = (Im(conj(u)·δ̈) − 2·ω·ṡ + ω²·e)/s,   s̈ = Re(conj(u)·δ̈) + α·e + ω²·s

(the 2·ω·ṡ term is the Coriolis acceleration of the block in the turning slot).
The block turns with the rocker; the slider's s, ṡ, s̈ in the output are the
projection on the turning axis from the rocker's first joint (GuidedAssembly).

Quick return (:func:`time_ratio`): for e = 0 and d = |O2O4| > a the rocker
oscillates; it stops where the slot is tangent to the crank circle, i.e. where
the crank is perpendicular to the slot: the triangle O2–A–O4 has its right
angle at A, so cos(∠AO2O4) = a/d and the crank is at ±acos(a/d) from the ground
line O2→O4. The two swings take crank angles 2·acos(a/d) = π − 2·asin(a/d) (crank
pin on O4's side) and 2π − 2·acos(a/d) = π + 2·asin(a/d): at constant crank speed
the time ratio is (π + 2·asin(a/d))/(π − 2·asin(a/d)).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from .common import (
    ROUNDOFF,
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
)
from .dyads import GuidedAssembly, crank_pin, fixed_kin, rpr

NAME = "inverted_slider_crank"

__all__ = ["applies", "roles", "solve", "time_ratio"]


@dataclass(frozen=True)
class Roles:
    """Which bodies and joints play which part in the inverted slider-crank."""

    ground: str
    crank: str
    rocker: str
    block: str
    O2: str
    A: str
    O4: str


def roles(mech: Mechanism) -> Roles | None:
    """Identify ground–crank–block–rocker with the block sliding on the rocker, or None."""
    st = crank_start(mech, links=3, sliders=1, pin_count=3, ground_pivots=2)
    if st is None:
        return None
    block, sl = next(iter(mech.sliders.items()))
    g, crank, o2, pm = st.ground, st.crank, st.pivot, st.pins
    rocker = sl.guide
    if rocker in (g, crank):
        return None
    o4 = (st.ground_pins - {o2}).pop()
    if other_body(pm[o4], g) != rocker or pins_of(mech, rocker) != {o4}:
        return None
    if pins_of(mech, crank) != {o2, sl.joint} or set(pm[sl.joint]) != {crank, block}:
        return None
    return Roles(g, crank, rocker, block, o2, sl.joint, o4)


def applies(mech: Mechanism) -> bool:
    """True for a crank-driven inverted slider-crank (block on the crank pin, sliding on a pivoted rocker)."""
    return roles(mech) is not None


def time_ratio(a: float, d: float) -> float:
    """Slow swing / fast swing of the rocker at constant crank speed (slot through O4, d > a)."""
    if not 0.0 < a < d:
        raise ValueError(f"the rocker oscillates only for 0 < a < d (a = {a}, d = {d})")
    g = 2.0 * math.asin(a / d)
    return (math.pi + g) / (math.pi - g)


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics over ``times`` (default: the file's [time]).

    Raises LimitPositionError (a ValueError) at the first sample the block
    cannot be placed on the slot, with the samples before it in ``.partial``.
    """
    r = roles(mech)
    if r is None:
        raise ValueError(f"{mech.name}: not a crank-driven inverted slider-crank")
    drv = mech.drivers[0]
    bodies = mech.bodies()
    a, beta2 = member_vector(bodies[r.crank], r.O2, r.A)
    u0 = complex(*mech.sliders[r.block].axis)
    zA0, zO4 = complex(*mech.joints[r.A]), complex(*mech.joints[r.O4])
    e = float(cross(u0, zA0 - zO4))
    sigma = branch_sign(float((np.conj(u0) * (zA0 - zO4)).real), f"{mech.name}: block {r.block} over pivot {r.O4}")

    t, inserted, anchor = evaluation_times(mech, times)
    th2, om2, al2 = driver_input(drv, t)
    asm = GuidedAssembly(mech, t, inserted, anchor)
    zA = crank_pin(asm, r.crank, r.O2, r.A, (th2, om2, al2))
    ok, phi, _ = rpr(zA, fixed_kin(zO4, len(t)), e, sigma)
    # the slot reaches the crank pin while |A − O4| ≥ |e|; |A − O4| is least where A lies on the line O2O4
    zO2 = complex(asm.fixed(r.O2))
    extremes = [np.angle(zO4 - zO2) - beta2 + k * np.pi for k in (0, 1)]

    slack = ROUNDOFF * (a + abs(zO4 - zO2) + abs(e))  # a slot just touched there (a change point) is reached

    def reach(th: np.ndarray) -> np.ndarray:
        return np.abs(zO2 + a * np.exp(1j * (th + beta2)) - zO4) > abs(e) - slack

    between = passes_between(th2, extremes, reach)
    check_assembly(
        ok & between,
        mech=mech,
        t=t,
        inserted=inserted,
        theta_in=th2,
        what=lambda k: (
            f"the slot of {r.rocker} (offset {e:g} from {r.O4}) cannot reach the crank pin {r.A}" + gap_text(between, k)
        ),
        limit=None,
        resolve=lambda tt: solve(mech, tt),
    )
    asm.set_angle(r.crank, th2, om2, al2)
    asm.set_point(r.A, *zA)
    asm.set_from_axis(r.rocker, r.block, phi)
    d = abs(zO4 - asm.fixed(r.O2))
    return asm.result(NAME, {"branch": int(sigma), "a": a, "d": d, "offset": e})
