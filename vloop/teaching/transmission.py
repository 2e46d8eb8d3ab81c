"""Dyads and their transmission angles (pressure angles for sliders).

The dyads come from the compiled structure: each closed-form block of the LoopSystem is one loop
with two unknowns, i.e. two bodies joined to each other and, at their far ends, to bodies already
solved. Definitions (angles in [0, π] rad, then folded as textbooks quote them):

* **RRR** (two links, e.g. coupler AB and rocker O4B of a four-bar, pinned at B): the raw
  transmission angle is the interior angle at the middle pin, between B→A and B→O4 — for a
  four-bar cos μ = (b² + c² − a² − d² + 2ad·cos θ2)/(2bc). It is the same whichever side drives.
* **RRP** (a rod AB and a block pinned at B sliding along a guide of axis u, e.g. the connecting
  rod and piston of a slider-crank): raw μ is the angle between the rod B→A and the axis normal
  n = j·u (u as the file gives it, turning with its guide). μ = 90° with the rod along the
  sliding direction; the pressure angle, between the force along the rod and the block's motion,
  is 90° − μ.
* **RPR** (a block pinned at A, known from the driver side, sliding in a slot of a guide that
  turns about its pivot O, e.g. the slotted lever of an inverted slider-crank or a Whitworth):
  the block pushes the guide normal to the slot through A, and the guide's point under A moves
  perpendicular to O→A; raw μ is the angle between n = j·u and A→O. A slot through the pivot
  gives μ = 90° throughout.

Folded μ = min(μ, π − μ) in [0, π/2] (the textbook transmission angle: 0 at a toggle, 90°
ideal); pressure angle = π/2 − folded μ. Blocks solved by Newton (several loops together) and
two-slider (PP) blocks have no dyad here; :func:`dyads` says so in its notes.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model import Mechanism
from ..result import Result
from . import _motion

ORIGIN = "@O"  # the LoopSystem's world-origin node on the ground


@dataclass(frozen=True)
class Dyad:
    """A two-body dyad of the structure.

    ``kind``: "RRR" | "RRP" | "RPR"; ``loop``: loop index (0-based); ``joint``: where the angle is
    measured (RRR: the middle pin; RRP, RPR: the block's pin); ``label``: ``joint``, made unique;
    RRR: ``bodies`` = the two links, ``ends`` = their far joints; RRP: ``bodies`` = (rod, block),
    ``ends`` = (rod's far joint, ""); RPR: ``bodies`` = (block, guide), ``ends`` = ("", guide pivot).
    """

    label: str
    kind: str
    loop: int
    joint: str
    bodies: tuple[str, str]
    ends: tuple[str, str]

    def describe(self) -> str:
        a, b = self.bodies
        if self.kind == "RRR":
            return f"{a}–{b} at {self.joint} ({self.ends[0]}–{self.joint}–{self.ends[1]})"
        if self.kind == "RRP":
            return f"rod {a} on block {b} at {self.joint}"
        return f"block {a} at {self.joint} in the slot of {b} (pivot {self.ends[1]})"


def _runs(nodes: tuple[tuple[str, str], ...]) -> list[list[tuple[str, str]]]:
    """The loop's nodes cut into runs on one body (cyclic), without pass-through visits of a pin star."""
    n = len(nodes)
    start = next((i for i in range(n) if nodes[i][0] != nodes[i - 1][0]), 0)
    seq = list(nodes[start:] + nodes[:start])
    runs: list[list[tuple[str, str]]] = []
    for node in seq:
        if runs and runs[-1][-1][0] == node[0]:
            runs[-1].append(node)
        else:
            runs.append([node])
    k = 0
    while k < len(runs) and len(runs) > 2:  # a body touched at one pin only, between two others there
        r, prev, nxt = runs[k], runs[k - 1], runs[(k + 1) % len(runs)]
        if len(r) == 1 and prev[-1][1] == r[0][1] == nxt[0][1]:
            runs.pop(k)
        else:
            k += 1
    return runs


def _far_end(run: list[tuple[str, str]], near: str) -> str:
    """The joint at the other end of a body's run from ``near``."""
    return run[-1][1] if run[0][1] == near else run[0][1]


def dyads(system: Any) -> tuple[list[Dyad], list[str]]:
    """The dyads of a compiled LoopSystem, in solving order, and notes on blocks that are not dyads."""
    mech: Mechanism = system.mechanism
    na = len(system.angle_links)
    found: list[Dyad] = []
    notes: list[str] = []
    used: set[str] = set()
    for block in system.blocks:
        lp = system.loops[block.loops[0]]
        if block.kind not in ("RRR", "RRP", "RPR"):
            what = "solved together by Newton" if block.kind == "newton" else "two sliders"
            loops = ", ".join(str(i + 1) for i in block.loops)
            notes.append(f"loop{'s' if len(block.loops) > 1 else ''} {loops}: no dyad ({what})")
            continue
        bodies = [system.angle_links[v] if v < na else system.slider_names[v - na] for v in block.unknowns]
        dyad = _dyad(mech, block.kind, lp.index, _runs(lp.nodes), bodies)
        if dyad is None:
            notes.append(f"loop {lp.index + 1} ({lp.label}): {block.kind} block not recognised as a dyad")
            continue
        label = dyad.joint if dyad.joint not in used else f"{dyad.joint}-{dyad.bodies[1]}"
        used.add(label)
        found.append(dataclasses.replace(dyad, label=label))
    return found, notes


def _dyad(mech: Mechanism, kind: str, loop: int, runs: list, bodies: list[str]) -> Dyad | None:
    by_body = {r[0][0]: (i, r) for i, r in enumerate(runs)}
    if any(b not in by_body for b in bodies):
        return None
    n = len(runs)

    def pinned(i: int, j: int) -> str | None:  # the joint where runs i and j touch by a pin, if they do
        ri, rj = runs[i], runs[j]
        if (i + 1) % n == j and ri[-1][1] == rj[0][1]:
            return ri[-1][1]
        if (j + 1) % n == i and rj[-1][1] == ri[0][1]:
            return rj[-1][1]
        return None

    if kind == "RRR":
        (i, ra), (j, rb) = by_body[bodies[0]], by_body[bodies[1]]
        mid = pinned(i, j)
        if mid is None:
            return None
        ends = (_far_end(ra, mid), _far_end(rb, mid))
        if mid in ends or ORIGIN in ends:
            return None
        return Dyad(mid, kind, loop, mid, (bodies[0], bodies[1]), ends)
    rod_or_guide = next(b for b in bodies if b in mech.links)
    block = next(b for b in bodies if b in mech.sliders)
    (i, rl), (j, _) = by_body[rod_or_guide], by_body[block]
    pin = mech.sliders[block].joint
    if kind == "RRP":
        if pinned(i, j) != pin or _far_end(rl, pin) in (pin, ORIGIN):
            return None
        return Dyad(pin, kind, loop, pin, (rod_or_guide, block), (_far_end(rl, pin), ""))
    # RPR: the loop leaves the guide by the slider edge at its reference node; the pivot is the other end
    before, after = runs[(i - 1) % n], runs[(i + 1) % n]
    if after[0][0] == block:
        pivot = rl[0][1] if before[-1][1] == rl[0][1] else None
    else:
        pivot = rl[-1][1] if after[0][1] == rl[-1][1] else None
    if pivot is None or pivot == ORIGIN:
        return None
    return Dyad(pin, kind, loop, pin, (block, rod_or_guide), ("", pivot))


def _angle_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Unsigned angle between complex vectors, in [0, π] (atan2 form: accurate near 0 and π)."""
    return np.abs(np.angle(v * np.conj(u)))


def raw_angle(mech: Mechanism, result: Result, dyad: Dyad) -> np.ndarray:
    """Raw transmission angle of a dyad over the run [rad, in [0, π]] (module docstring)."""
    at = _motion.point(result, dyad.joint)
    if dyad.kind == "RRR":
        a, b = (_motion.point(result, e) for e in dyad.ends)
        return _angle_between(a - at, b - at)
    block = dyad.bodies[1] if dyad.kind == "RRP" else dyad.bodies[0]
    normal = 1j * np.exp(1j * result[f"{block}.theta"])
    if dyad.kind == "RRP":
        return _angle_between(_motion.point(result, dyad.ends[0]) - at, normal)
    return _angle_between(normal, _motion.point(result, dyad.ends[1]) - at)


def _turning(u: np.ndarray, du: np.ndarray) -> np.ndarray:
    """The rate of turn of complex vectors u whose rate is du [rad/s]: Im(u̇/u)."""
    return (du * np.conj(u)).imag / np.abs(u) ** 2


def raw_rate(mech: Mechanism, result: Result, dyad: Dyad) -> np.ndarray:
    """d(raw μ)/dt [rad/s] over the run, from the positions and velocities of the vectors that make μ (the
    angle from u to v is arg(v/u), its rate Im(v̇/v) − Im(u̇/u); raw μ = |arg(v/u)| turns with its sign)."""
    at, v_at = _motion.point(result, dyad.joint), _motion.point_velocity(result, dyad.joint)
    if dyad.kind == "RRR":
        a, b = dyad.ends
        u, du = _motion.point(result, a) - at, _motion.point_velocity(result, a) - v_at
        v, dv = _motion.point(result, b) - at, _motion.point_velocity(result, b) - v_at
        turn = _turning(v, dv) - _turning(u, du)
    else:
        block = dyad.bodies[1] if dyad.kind == "RRP" else dyad.bodies[0]
        normal, w = 1j * np.exp(1j * result[f"{block}.theta"]), result[f"{block}.omega"]
        end = dyad.ends[0] if dyad.kind == "RRP" else dyad.ends[1]
        r, dr = _motion.point(result, end) - at, _motion.point_velocity(result, end) - v_at
        u, turn = (r, w - _turning(r, dr)) if dyad.kind == "RRP" else (normal, _turning(r, dr) - w)
        v = normal if dyad.kind == "RRP" else r
    return np.sign(np.angle(v * np.conj(u))) * turn


@dataclass(frozen=True)
class TransmissionAngle:
    """One dyad's transmission angle over a run [rad]: ``raw`` in [0, π], ``folded`` in [0, π/2],
    ``pressure`` = π/2 − folded (the angle between the transmitted force and the output's motion)."""

    dyad: Dyad
    raw: np.ndarray
    t: np.ndarray = field(repr=False)
    inputs: np.ndarray = field(repr=False)  # (n_samples, n_drivers) driver values

    @property
    def folded(self) -> np.ndarray:
        return np.minimum(self.raw, np.pi - self.raw)

    @property
    def pressure(self) -> np.ndarray:
        return np.pi / 2 - self.folded

    def extremes(self) -> dict[str, dict[str, Any]]:
        """Min and max of the folded angle over the run [rad] with the sample, time [s] and inputs there."""
        out = {}
        for key, k in (("min", int(np.argmin(self.folded))), ("max", int(np.argmax(self.folded)))):
            out[key] = {
                "value": float(self.folded[k]),
                "raw": float(self.raw[k]),
                "sample": k,
                "t": float(self.t[k]),
                "inputs": self.inputs[k].tolist(),
            }
        return out


def transmission_angles(mech: Mechanism, result: Result, system: Any = None) -> list[TransmissionAngle]:
    """Transmission angle of every dyad over the run [rad] (raw, folded, pressure; module docstring)."""
    if system is None:
        from .. import compile

        system = compile(mech)
    found, _ = dyads(system)
    if not len(result.t):
        return []
    x = _motion.inputs(mech, result)
    return [TransmissionAngle(d, raw_angle(mech, result, d), result.t, x) for d in found]
