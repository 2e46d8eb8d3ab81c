"""Closed-form kinematics of a change-point four-bar, continued through its change points.

A four-bar whose lengths satisfy s + l = p + q (shortest + longest = the other two: the
parallelogram, the kite, any "change-point" linkage) passes through configurations where all
four pins are collinear. There the two assembly branches (open and crossed) meet, and the
closed form of :mod:`validators.analytic.fourbar` — which keeps the branch sign σ fixed — jumps
from one branch to the other: its angles are continuous but its velocities are not. The
physical motion (and vloop, once it follows the branch that keeps the velocities continuous)
goes straight on. This module gives that motion.

Notation as in :mod:`validators.analytic.fourbar`: crank O2A (a, input φ2 = θ2 + β2), coupler AB
(b), rocker O4B (c), ground d at angle θ1; δ = O4 − A, f = |δ|, p = (b² − c² + f²)/(2f),
q = √(b² − p²), θ3 = arg δ + σ·atan2(q, p), B = A + b·e^{jθ3}, θ4 = arg(B − O4). Velocities and
accelerations are the four-bar's (projections of the differentiated loop on e^{jθ4}, e^{jθ3}).

Where the branches meet. f² = a² + d² − 2·a·d·cos(φ2 − θ1) ranges over [|d − a|, d + a]; the
chain folds (q = 0) where f = |b − c| or f = b + c. For a change-point linkage one of these
equals an end of f's range: d + a = b + c (the crank pointing away from O4, φ2 = θ1 + π) or
|d − a| = |b − c| (the crank pointing at O4, φ2 = θ1). There f has an extremum, so
q² = b² − p(f)² touches zero quadratically: q ≈ k·|φ2 − φc| with k ≠ 0. The two smooth curves
through the collinear configuration are therefore θ3 = arg δ + atan2(±k·(φ2 − φc), p): the
signed height changes sign with φ2 − φc, i.e. each smooth curve *flips σ* as the input crosses
φc. So the branch sign of the continuous motion is

    σ(t) = σ0 · (−1)^{n(t)},   n(t) = Σ_c ⌊(φ2(t) − φc)/2π⌋ − ⌊(φ2(0) − φc)/2π⌋,

the number of times (net, which has the right parity) the input crossed a change-point angle
φc + 2πk since t = 0; σ0 is the side of the diagonal A–O4 that B is on at t = 0. Sampled
exactly at φc the branch is undefined (0/0 in the rates): such a grid is refused.

Degenerate kites (a = d and b = c: A reaches O4, f = 0, B anywhere on a circle) are not
covered (:func:`applies` is False; :mod:`validators.analytic.fourbar` applies as usual).
"""

from __future__ import annotations

import math

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from . import fourbar
from .common import (
    TWO_PI,
    Assembly,
    check_assembly,
    driver_input,
    evaluation_times,
)

NAME = "fourbar_change_point"
REL_TOL = 1e-9  # s + l = p + q to this fraction of the longest link counts as a change point
TOUCH = 1e-12  # q² above −TOUCH·b² is a fold, not a failure to assemble

__all__ = ["applies", "change_angles", "solve"]


def change_angles(mech: Mechanism) -> tuple[float, ...]:
    """Crank angles θ2 [rad, in [0, 2π)] at which the branches meet; () if not a change-point four-bar."""
    r = fourbar.roles(mech)
    if r is None:
        return ()
    m = fourbar.dims(mech, r)
    scale = max(m.a, m.b, m.c, m.d)
    ls = sorted([m.a, m.b, m.c, m.d])
    if abs(ls[0] + ls[3] - ls[1] - ls[2]) > REL_TOL * scale:
        return ()
    if abs(m.d - m.a) <= REL_TOL * scale and abs(m.b - m.c) <= REL_TOL * scale:
        return ()  # the degenerate kite: A lands on O4
    out = []
    if abs(m.d + m.a - m.b - m.c) <= REL_TOL * scale:
        out.append((m.theta1 + math.pi - m.beta2) % TWO_PI)
    if abs(abs(m.d - m.a) - abs(m.b - m.c)) <= REL_TOL * scale:
        out.append((m.theta1 - m.beta2) % TWO_PI)
    return tuple(out)


def applies(mech: Mechanism) -> bool:
    """True for a crank-driven four-bar with s + l = p + q (not the degenerate kite)."""
    return bool(change_angles(mech))


def branch_signs(theta_in: np.ndarray, anchor: int, sigma0: float, angles: tuple[float, ...]) -> np.ndarray:
    """σ at every sample: σ0 flipped once per crossing of a change-point angle since the anchor sample."""
    n = np.zeros(len(theta_in), int)
    for c in angles:
        turns = np.floor((theta_in - c) / TWO_PI).astype(int)
        n += turns - turns[anchor]
    return np.where(n % 2 == 0, sigma0, -sigma0)


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Kinematics through the change points on the velocity-continuous branch (module docstring)."""
    angles = change_angles(mech)
    if not angles:
        raise ValueError(f"{mech.name}: not a (non-degenerate) change-point four-bar")
    r = fourbar.roles(mech)
    m = fourbar.dims(mech, r)
    sigma0 = fourbar.branch_at_start(mech, r)
    t, inserted, anchor = evaluation_times(mech, times)
    th_in, w2, al2 = driver_input(mech.drivers[0], t)
    near = np.min([np.abs(np.remainder(th_in - c + math.pi, TWO_PI) - math.pi) for c in angles], axis=0)
    sigma = branch_signs(th_in, anchor, sigma0, angles)

    delta, _, p, q2 = fourbar.diagonal(mech, r, m, th_in)
    ok = (q2 > -TOUCH * m.b * m.b) & (near > 1e-9)
    check_assembly(
        ok,
        mech=mech,
        t=t,
        inserted=inserted,
        theta_in=th_in,
        what=lambda k: "input at a change point (branch undefined)" if near[k] <= 1e-9 else "the chain cannot close",
        limit=None,
        resolve=lambda tt: solve(mech, tt),
    )
    th3 = np.angle(delta) + sigma * np.arctan2(np.sqrt(np.maximum(q2, 0.0)), p)
    asm = fourbar.coupler_and_rocker(Assembly(mech, t, inserted, anchor), r, m, (th_in, w2, al2), th3)
    flips = int(np.count_nonzero(np.diff(sigma)))
    meta = {"branch": int(sigma0), "change_angles": list(angles), "branch_flips": flips}
    return asm.result(NAME, meta)
