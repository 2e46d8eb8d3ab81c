"""What the two six-bars share: a four-bar (crank, coupler, rocker) and a second RRR dyad hung on one of its links.

Not a closed form of its own: :mod:`.sixbar_watt2` hangs the second dyad on the rocker (Watt II),
:mod:`.sixbar_stephenson3` on the coupler (Stephenson III); each finds its roles and calls :func:`solve`.

Roles (names are free): ground pivots O2, O4, O6; crank O2A (a, driven θ2, ω2, α2); coupler AB (b);
rocker O4B (c); the second dyad's link PE (l5) from the point P of the *carrier* (the rocker or the
coupler) to the output rocker O6E (l6). Every pin joins exactly two bodies.

Steps (derivations in :mod:`.dyads`):
  1. A from the crank (:func:`.dyads.crank_pin`);
  2. RRR dyad A–B–O4 (coupler, rocker), σ1 = side of A→O4 that B lies on at t = 0;
  3. P by rigid-body transport on the carrier from its known member (O4 on the rocker, A on the coupler):
     P = K + e^{jθ}·ρ_KP, Ṗ = K̇ + j·ω·(P − K), P̈ = K̈ + (j·α − ω²)·(P − K);
  4. RRR dyad P–E–O6 (link5, output), σ2 = side of P→O6 that E lies on at t = 0.
A dyad cannot be closed where its base |δ| leaves (|l1 − l2|, l1 + l2).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from .common import (
    Assembly,
    CrankStart,
    check_dyads,
    crank_start,
    driver_input,
    evaluation_times,
    member_vector,
    next_link,
    sole_pin,
)
from .dyads import carry, close_rrr, crank_pin, fixed_kin, local_vector

__all__ = ["SixBar", "four_bar_start", "second_dyad", "solve"]


@dataclass(frozen=True)
class SixBar:
    """Which bodies and joints play which part; ``carrier`` carries P and is known at its member ``base``."""

    ground: str
    crank: str
    coupler: str
    rocker: str
    link5: str
    output: str
    O2: str
    A: str
    B: str
    O4: str
    P: str
    E: str
    O6: str
    carrier: str
    base: str


def four_bar_start(mech: Mechanism) -> tuple[CrankStart, str, str] | None:
    """(start, A, coupler) of a crank-driven six-bar on three ground pivots with seven two-body pins, or None."""
    st = crank_start(mech, links=6, sliders=0, pin_count=7, ground_pivots=3)
    if st is None:
        return None
    a = sole_pin(mech, st.crank, st.pivot)
    coupler = None if a is None else next_link(st, a, st.crank)
    return None if coupler is None else (st, a, coupler)


def second_dyad(
    mech: Mechanism, st: CrankStart, carrier: str, p: str, rocker: str, o4: str
) -> tuple[str, str, str, str] | None:
    """(link5, E, output, O6): the dyad hung on ``carrier`` at ``p`` to a third ground pivot, or None."""
    link5 = next_link(st, p, carrier)
    if link5 is None or link5 == rocker:
        return None
    e = sole_pin(mech, link5, p)
    output = None if e is None else next_link(st, e, link5)
    o6 = None if output is None else sole_pin(mech, output, e)
    if o6 is None or o6 not in st.ground_pins - {st.pivot, o4}:
        return None
    return link5, e, output, o6


def solve(mech: Mechanism, times: np.ndarray | None, r: SixBar | None, names: tuple[str, str, str]) -> Result:
    """The steps of the module docstring over ``times``; ``names``: the closed form's, the family's, link5's kind.

    Raises ValueError if ``r`` is None (not this family), and LimitPositionError (a ValueError) at the first
    sample a dyad cannot be closed, with the samples before it in ``.partial``.
    """
    name, family, link5_kind = names
    if r is None:
        raise ValueError(f"{mech.name}: not a crank-driven {family}")
    bodies = mech.bodies()
    lengths = [
        member_vector(bodies[b], j1, j2)[0]
        for b, j1, j2 in (
            (r.crank, r.O2, r.A),
            (r.coupler, r.A, r.B),
            (r.rocker, r.O4, r.B),
            (r.link5, r.P, r.E),
            (r.output, r.O6, r.E),
        )
    ]
    t, inserted, anchor = evaluation_times(mech, times)
    n = len(t)
    th2 = driver_input(mech.drivers[0], t)
    asm = Assembly(mech, t, inserted, anchor)
    asm.set_angle(r.crank, *th2)
    asm.set_point(r.A, *crank_pin(asm, r.crank, r.O2, r.A, th2))
    asm.set_point(r.O4, *fixed_kin(asm.fixed(r.O4), n))
    ok1, _, sigma1 = close_rrr(asm, (r.coupler, r.rocker), (r.A, r.O4, r.B), asm.points[r.A], asm.points[r.O4])
    asm.set_point(r.P, *carry(asm.points[r.base], asm.angles[r.carrier], local_vector(mech, r.carrier, r.base, r.P)))
    z6 = fixed_kin(asm.fixed(r.O6), n)
    ok2, _, sigma2 = close_rrr(asm, (r.link5, r.output), (r.P, r.O6, r.E), asm.points[r.P], z6)
    fails = (
        (ok1, f"coupler {r.coupler} and rocker {r.rocker} cannot close"),
        (ok2, f"{link5_kind} {r.link5} and rocker {r.output} cannot close"),
    )
    check_dyads(
        fails,
        mech=mech,
        t=t,
        inserted=inserted,
        theta_in=th2[0],
        resolve=lambda tt: solve(mech, tt, r, names),
    )
    return asm.result(name, {"branch": [int(sigma1), int(sigma2)], "lengths": lengths})
