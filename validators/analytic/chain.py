"""Closed-form kinematics of any mechanism built from dyads on its cranks, found from its structure.

Textbook mechanisms are "Assur groups of class II": starting from the ground and the driven
cranks, every other link belongs to a dyad hung on points already known, and each dyad has a
closed form. This module finds such an order for any mechanism (names free, structure only)
and solves it with the dyads of :mod:`validators.analytic.dyads`. It is the closed form of the corpus's "random
ternary attachments" (a four-bar or slider-crank with dyads hung on new pins of its links) and
of the tilted eight-bars; the catalog's hand-written closed forms apply first where they exist.

Known points carry (z, ż, z̈) (complex), known links (θ, ω, α). Steps, tried in this order until
every body is known (:func:`plan`; if none applies and bodies remain, there is no closed form):

* **crank** — a driven link pivoted on a known fixed point: θ, ω, α from the driver
  (:func:`vloop.drivers.evaluate`); its points by rigid transport z = z_P + e^{jθ}·(ρ − ρ_P).
* **RRR** — two unknown links L1, L2 pinned together at an unknown X, L1 to a known point P1 and
  L2 to a known P2 (their only known points): law of cosines in triangle P1–X–P2
  (:func:`validators.analytic.dyads.rrr`, derivation there), σ = side of P1→P2 on which X lies
  at t = 0; each link's θ is the direction of P→X less that vector's angle in its frame.
* **RRP** — an unknown link from a known P1 to an unknown X that is the pin of a block on a
  ground-fixed line (through X at t = 0, along the slider axis u): projection on the line's
  normal (:func:`validators.analytic.dyads.rrp`), σ = sign((X − P1)·u) at t = 0.
* **RPR** — an unknown guide link turning about a known point O, carrying the slot of a block
  whose pin P is known: the slot at offset e = u × (P − O) from O (u the axis at t = 0),
  s = σ·√(|P − O|² − e²) (:func:`validators.analytic.dyads.rpr`), σ = sign(s) at t = 0.

Blocks turn with their guides; slider s, ṡ, s̈ and every other point come from
:class:`validators.analytic.dyads.GuidedAssembly`. Mechanisms with a driven slider (linear
actuator) or loops that must be solved together (a Stephenson III driven at its output) have no
such order: :func:`applies` is False.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import Result

from .common import (
    branch_sign,
    check_dyads,
    driver_input,
    evaluation_times,
    member_vector,
    pins,
)
from .dyads import GuidedAssembly, carry, close_rrr, fixed_kin, local_vector, rpr, rrp

NAME = "dyad_chain"

__all__ = ["Step", "applies", "plan", "solve"]


@dataclass(frozen=True)
class Step:
    """One step of the solution: ``kind`` in crank, rrr, rrp, rpr; the bodies and joints it uses."""

    kind: str
    bodies: tuple[str, ...]
    joints: tuple[str, ...]  # crank: (pivot,); rrr: (P1, P2, X); rrp: (P1, X); rpr: (P, O)
    driver: int = -1
    slider: str = ""


class _State:
    """Which bodies and points are known while a plan is built."""

    def __init__(self, mech: Mechanism) -> None:
        self.mech = mech
        self.bodies = mech.bodies()
        self.members = {n: set(b.local) for n, b in self.bodies.items()}
        self.known_bodies = {mech.ground}
        self.known = set(self.members[mech.ground])
        self.pins = pins(mech)

    def learn(self, body: str) -> None:
        self.known_bodies.add(body)
        self.known |= self.members[body]

    def known_members(self, body: str) -> set[str]:
        return self.members[body] & self.known

    def unknown_links(self) -> list[str]:
        return [n for n in self.mech.links if n not in self.known_bodies]


def _crank_steps(st: _State) -> list[Step] | None:
    steps = []
    for i, d in enumerate(st.mech.drivers):
        if d.kind != "crank" or d.pivot not in st.members[st.mech.ground]:
            return None
        steps.append(Step("crank", (d.target,), (d.pivot,), driver=i))
        st.learn(d.target)
    return steps


def _find_rrr(st: _State) -> Step | None:
    for l1 in st.unknown_links():
        k1 = st.known_members(l1)
        if len(k1) != 1:
            continue
        for x in sorted(st.members[l1] - st.known):
            for l2 in st.pins.get(x, ()):
                if l2 == l1 or l2 not in st.mech.links or l2 in st.known_bodies:
                    continue
                k2 = st.known_members(l2)
                if len(k2) == 1 and k2 != k1:
                    return Step("rrr", (l1, l2), (next(iter(k1)), next(iter(k2)), x))
    return None


def _find_rrp(st: _State) -> Step | None:
    ground = st.mech.ground
    for l1 in st.unknown_links():
        k1 = st.known_members(l1)
        if len(k1) != 1:
            continue
        for name, sl in st.mech.sliders.items():
            if sl.guide == ground and name not in st.known_bodies and sl.joint in st.members[l1] - st.known:
                return Step("rrp", (l1, name), (next(iter(k1)), sl.joint), slider=name)
    return None


def _find_rpr(st: _State) -> Step | None:
    for name, sl in st.mech.sliders.items():
        guide = sl.guide
        if name in st.known_bodies or guide in st.known_bodies or sl.joint not in st.known:
            continue
        k = st.known_members(guide)
        if len(k) == 1:
            return Step("rpr", (guide, name), (sl.joint, next(iter(k))), slider=name)
    return None


def plan(mech: Mechanism) -> list[Step] | None:
    """The order of steps that solves ``mech`` in closed form, or None if there is none."""
    st = _State(mech)
    steps = _crank_steps(st)
    if steps is None or not mech.drivers:
        return None
    while True:
        for name, sl in mech.sliders.items():  # a block on a known guide, at a known pin, is known
            if name not in st.known_bodies and sl.guide in st.known_bodies and sl.joint in st.known:
                st.learn(name)
        if all(b in st.known_bodies for b in st.bodies):
            return steps
        step = _find_rrr(st) or _find_rrp(st) or _find_rpr(st)
        if step is None:
            return None
        steps.append(step)
        for b in step.bodies:
            st.learn(b)


def applies(mech: Mechanism) -> bool:
    """True when the mechanism is a chain of RRR, RRP and RPR dyads on ground-pivoted cranks."""
    return plan(mech) is not None


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics over ``times`` (default: the file's [time]), dyad by dyad.

    Raises LimitPositionError (a ValueError) at the first sample where a dyad cannot close.
    """
    steps = plan(mech)
    if steps is None:
        raise ValueError(f"{mech.name}: not a chain of dyads on ground-pivoted cranks")
    t, inserted, anchor = evaluation_times(mech, times)
    n = len(t)
    asm = GuidedAssembly(mech, t, inserted, anchor)
    z0 = {j: complex(*xy) for j, xy in mech.joints.items()}
    for j in asm.bodies[mech.ground].local:
        asm.set_point(j, *fixed_kin(asm.fixed(j), n))
    fails: list[tuple[np.ndarray, str]] = []
    inputs = []
    for step in steps:
        if step.kind == "crank":
            th = driver_input(mech.drivers[step.driver], t)
            inputs.append(th[0])
            asm.set_angle(step.bodies[0], *th)
        elif step.kind == "rrr":
            fails.append(_rrr(asm, step))
        elif step.kind == "rrp":
            fails.append(_rrp(asm, step, z0))
        else:
            fails.append(_rpr(asm, step, z0))
        for b in step.bodies:
            _carry_members(asm, b)
    check_dyads(
        fails,
        mech=mech,
        t=t,
        inserted=inserted,
        theta_in=inputs[0],
        resolve=lambda tt: solve(mech, tt),
    )
    return asm.result(NAME, {"steps": [f"{s.kind}({', '.join(s.joints)})" for s in steps]})


def _carry_members(asm: GuidedAssembly, body: str) -> None:
    """Every member of a body whose angle is known, by rigid transport from a known member."""
    if body not in asm.angles or body in asm.mech.sliders:
        return
    members = asm.bodies[body].local
    k = next(j for j in members if j in asm.points)
    for j in members:
        if j not in asm.points:
            asm.set_point(j, *carry(asm.points[k], asm.angles[body], local_vector(asm.mech, body, k, j)))


def _rrr(asm: GuidedAssembly, step: Step) -> tuple[np.ndarray, str]:
    l1, l2 = step.bodies
    p1, p2, x = step.joints
    ok, _, _ = close_rrr(asm, (l1, l2), (p1, p2, x), asm.points[p1], asm.points[p2])
    return ok, f"dyad {l1}, {l2} ({p1}–{x}–{p2}) cannot close"


def _rrp(asm: GuidedAssembly, step: Step, z0: dict[str, complex]) -> tuple[np.ndarray, str]:
    rod, block = step.bodies
    p1, x = step.joints
    length, _ = member_vector(asm.bodies[rod], p1, x)
    u = complex(*asm.mech.sliders[block].axis)
    sigma = branch_sign(float((np.conj(u) * (z0[x] - z0[p1])).real), f"{asm.mech.name}: rod {rod} across its line")
    ok, (th, om, al), _ = rrp(asm.points[p1], length, z0[x], u, sigma)
    asm.set_from_vector(rod, p1, x, th, om, al)
    r = length * np.exp(1j * th)
    z, zd, zdd = asm.points[p1]
    asm.set_point(x, z + r, zd + 1j * om * r, zdd + (1j * al - om * om) * r)
    return ok, f"rod {rod} cannot reach the line of {block}"


def _rpr(asm: GuidedAssembly, step: Step, z0: dict[str, complex]) -> tuple[np.ndarray, str]:
    guide, block = step.bodies
    p, o = step.joints
    u = complex(*asm.mech.sliders[block].axis)
    d0 = z0[p] - z0[o]
    e = float((np.conj(u) * d0).imag)
    sigma = branch_sign(float((np.conj(u) * d0).real), f"{asm.mech.name}: block {block} over the pivot {o}")
    ok, phi, _ = rpr(asm.points[p], asm.points[o], e, sigma)
    asm.set_from_axis(guide, block, phi)
    return ok, f"the slot of {guide} cannot reach the pin {p}"
