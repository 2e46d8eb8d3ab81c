"""Closed-form kinematics of the Whitworth quick-return (and the crank-shaper): two dyads.

Structure (checked by :func:`applies`; names are free): ground pivots O2, O4;
crank O2A (a, driven θ2, ω2, α2); a block pinned at A sliding in a slot of the
lever, which turns about O4; the lever carries the pin C of a rod CD (length ℓ)
whose end D is pinned to a ram sliding on a ground-fixed line. The slot may pass
at an offset e from O4 and C may sit anywhere on the lever; the ram's line is
any ground line (through D at t = 0, unit axis w). With d = |O2O4| < a the lever
turns fully (Whitworth); with d > a it oscillates (crank-and-slotted-lever
shaper); the formulas are the same.

Loops (complex numbers):

    O2 + a·e^{jθ2} = O4 + (s_A + j·e)·e^{jφ}            (crank, block, lever)
    O4 + e^{jθ4}·ρ_C + ℓ·e^{jθ5} = D = L0 + λ·w          (lever arm, rod, ram)

with φ the slot direction, θ4 = φ − γ the lever's angle (γ the slot's angle in
the lever frame), ρ_C the lever-frame vector O4→C, θ5 the rod's direction C→D.

Dyad 1, RPR (inverted slider; derivation in :mod:`validators.analytic.dyads`):
δ = A − O4 = ρ·e^{jψ} from the crank;  s_A = σ1·√(ρ² − e²),  φ = ψ − atan2(e, s_A);
ω4 = Im(e^{−jφ}·Ȧ)/s_A,  ṡ_A = Re(e^{−jφ}·Ȧ) + ω4·e,
α4 = (Im(e^{−jφ}·Ä) − 2·ω4·ṡ_A + ω4²·e)/s_A.  σ1 = sign(s_A) at t = 0.

C by rigid-body transport on the lever: C = O4 + e^{jθ4}·ρ_C,
Ċ = j·ω4·(C − O4), C̈ = (j·α4 − ω4²)·(C − O4).

Dyad 2, RRP (rod and ram; :func:`validators.analytic.dyads.rrp`):
with n = j·w and η = (C − L0)·n the distance of C from the ram's line,
sin(θ5 − arg w) = −η/ℓ, cos(θ5 − arg w) = σ2·√(1 − η²/ℓ²) (σ2 = sign((D − C)·w)
at t = 0); λ = w·C + ℓ·cos(θ5 − arg w); rates by differentiating those two
projections (derivation there).

Time ratio (:func:`time_ratio`), for the catalog's layout: slot and C on a line
through O4, ram line through O4 perpendicular to O2O4, d < a. The ram stops where
rod and arm are collinear along its line, i.e. where the lever lies along the ram
line, i.e. where A crosses that line: a·sin(φ2) = −d with φ2 measured from the
ram line's direction (O2 on the +normal side), φ2 = −asin(d/a) and π + asin(d/a).
The strokes take crank angles π + 2·asin(d/a) and π − 2·asin(d/a); at constant
crank speed the time ratio is (π + 2·asin(d/a))/(π − 2·asin(d/a)). (For the
oscillating crank-shaper the roles of a and d swap: asin(a/d).)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from .common import (
    branch_sign,
    check_dyads,
    crank_start,
    cross,
    driver_input,
    evaluation_times,
    member_vector,
    other_body,
    pins_of,
    sole_pin,
)
from .dyads import GuidedAssembly, carry, crank_pin, fixed_kin, local_vector, rpr, rrp

NAME = "whitworth"

__all__ = ["applies", "roles", "solve", "time_ratio"]


@dataclass(frozen=True)
class Roles:
    """Which bodies and joints play which part in the quick-return mechanism."""

    ground: str
    crank: str
    block: str
    lever: str
    rod: str
    ram: str
    O2: str
    A: str
    O4: str
    C: str
    D: str


def roles(mech: Mechanism) -> Roles | None:
    """Identify crank–block–lever (RPR) followed by rod–ram (RRP), or None."""
    st = crank_start(mech, links=4, sliders=2, pin_count=5, ground_pivots=2)
    if st is None:
        return None
    g, crank, o2, pm = st.ground, st.crank, st.pivot, st.pins
    on_lever = [n for n, s in mech.sliders.items() if s.guide != g]
    on_ground = [n for n, s in mech.sliders.items() if s.guide == g]
    if len(on_lever) != 1 or len(on_ground) != 1:
        return None
    block, ram = on_lever[0], on_ground[0]
    lever = mech.sliders[block].guide
    a, d = mech.sliders[block].joint, mech.sliders[ram].joint
    o4 = (st.ground_pins - {o2}).pop()
    if lever in (g, crank) or other_body(pm[o4], g) != lever:
        return None
    if pins_of(mech, crank) != {o2, a} or set(pm[a]) != {crank, block}:
        return None
    c = sole_pin(mech, lever, o4)
    rod = None if c is None else other_body(pm[c], lever)
    if rod is None or rod not in mech.links or pins_of(mech, rod) != {c, d} or set(pm[d]) != {rod, ram}:
        return None
    return Roles(g, crank, block, lever, rod, ram, o2, a, o4, c, d)


def applies(mech: Mechanism) -> bool:
    """True for a crank-driven slotted-lever quick-return: crank, block in a pivoted lever, rod, ram on ground."""
    return roles(mech) is not None


def time_ratio(a: float, d: float) -> float:
    """Cutting / return time of the Whitworth layout (module docstring) at constant crank speed, d < a."""
    if not 0.0 < d < a:
        raise ValueError(f"the Whitworth lever turns fully only for 0 < d < a (a = {a}, d = {d})")
    g = 2.0 * math.asin(d / a)
    return (math.pi + g) / (math.pi - g)


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics over ``times`` (default: the file's [time]).

    Raises LimitPositionError (a ValueError) at the first sample a dyad cannot
    be closed, with the samples before it in ``.partial``.
    """
    r = roles(mech)
    if r is None:
        raise ValueError(f"{mech.name}: not a crank / slotted lever / rod / ram quick-return mechanism")
    drv = mech.drivers[0]
    bodies = mech.bodies()
    a, _ = member_vector(bodies[r.crank], r.O2, r.A)
    ell, _ = member_vector(bodies[r.rod], r.C, r.D)
    u0 = complex(*mech.sliders[r.block].axis)
    w = complex(*mech.sliders[r.ram].axis)
    zA0, zO4 = complex(*mech.joints[r.A]), complex(*mech.joints[r.O4])
    zC0, zD0 = complex(*mech.joints[r.C]), complex(*mech.joints[r.D])
    e = float(cross(u0, zA0 - zO4))
    sigma1 = branch_sign(float((np.conj(u0) * (zA0 - zO4)).real), f"{mech.name}: block {r.block} over pivot {r.O4}")
    sigma2 = branch_sign(float((np.conj(w) * (zD0 - zC0)).real), f"{mech.name}: rod {r.rod} across the ram's line")

    t, inserted, anchor = evaluation_times(mech, times)
    th2, om2, al2 = driver_input(drv, t)
    asm = GuidedAssembly(mech, t, inserted, anchor)
    zA = crank_pin(asm, r.crank, r.O2, r.A, (th2, om2, al2))
    ok1, phi, _ = rpr(zA, fixed_kin(zO4, len(t)), e, sigma1)
    asm.set_from_axis(r.lever, r.block, phi)
    zC = carry(fixed_kin(zO4, len(t)), asm.angles[r.lever], local_vector(mech, r.lever, r.O4, r.C))
    ok2, th5, _ = rrp(zC, ell, zD0, w, sigma2)
    fails = (
        (ok1, f"the slot of {r.lever} cannot reach the crank pin {r.A}"),
        (ok2, f"rod {r.rod} (length {ell:g}) cannot reach the line of ram {r.ram}"),
    )
    check_dyads(fails, mech=mech, t=t, inserted=inserted, theta_in=th2, resolve=lambda tt: solve(mech, tt))
    asm.set_angle(r.crank, th2, om2, al2)
    asm.set_point(r.A, *zA)
    asm.set_point(r.C, *zC)
    asm.set_from_vector(r.rod, r.C, r.D, *th5)
    d = abs(zO4 - asm.fixed(r.O2))
    return asm.result(NAME, {"branch": [int(sigma1), int(sigma2)], "a": a, "d": d, "rod": ell, "offset": e})
