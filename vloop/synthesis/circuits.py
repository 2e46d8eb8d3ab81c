"""Circuits and branches of a synthesized linkage, and the defect its precision positions make.

The driven crank O2A (at θ) closes the linkage through one dyad: the four-bar's A–B–O4, the slider-crank's rod
A–B on the slider's line. For a given θ the dyad closes in two assemblies (the two signs σ of the closed form's
square root: the side of the line A → O4 that B lies on; the sign of the rod's projection on the slider's axis)
or in none; it closes where cos(θ − φ) ∈ [lo, hi] (|AO4| within [|b − c|, b + c]; A's offset from the slider's
line within ±b). So the input's reachable angles are the full circle, one arc, or two arcs, and

* a **branch** is one arc with one sign σ: along it the linkage moves without a toggle;
* a **circuit** is what the linkage reaches without being taken apart. An arc short of the full circle ends
  in toggles where its two branches meet (σ changes as the input reverses): the arc with both signs is one
  circuit. A full circle has no toggle: each sign is a circuit of its own (a crank's two assemblies).

The defects (Erdman & Sandor; Norton, ch. 5), from the configurations the method meant at each position:
*circuit* — positions on different circuits; *branch* — on one circuit but on different branches (a toggle
between them); *order* — on one branch, but the input moving one way (either way) does not meet them in the
order asked: on an arc the input cannot pass the gap, so an arc's positions are ordered by their angle along
it, never modulo a turn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .linkages import Topology, side

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class Arcs:
    """The input angles θ [rad] at which the dyad closes: cos(θ − ``phase``) ∈ [``lo``, ``hi``]."""

    phase: float
    lo: float
    hi: float

    @property
    def full(self) -> bool:
        """The input turns fully (no toggle)."""
        return self.lo <= -1.0 and self.hi >= 1.0

    @property
    def count(self) -> int:
        """How many arcs (a full circle counts as one)."""
        if self.lo > 1.0 or self.hi < -1.0 or self.lo > self.hi:
            return 0
        return 2 if self.lo > -1.0 and self.hi < 1.0 else 1

    def psi(self, theta: np.ndarray) -> np.ndarray:
        """θ − phase, wrapped so that every arc is one interval: (−π, π], or [0, 2π) for the arc about π."""
        psi = np.angle(np.exp(1j * (np.asarray(theta, float) - self.phase)))
        if self.count == 1 and not self.full and self.lo <= -1.0:  # one arc about π
            psi = np.mod(psi, TWO_PI)
        return psi

    def index(self, theta: np.ndarray) -> np.ndarray:
        """Which arc each θ is on (0 or 1; the arc at negative ψ is 1 when there are two)."""
        if self.count == 2:
            return np.where(self.psi(theta) < 0, 1, 0)
        return np.zeros(np.shape(theta), int)

    def limits(self, k: int) -> tuple[float, float]:
        """Arc k's ends as input angles [rad] (ascending along ψ)."""
        a_hi = math.acos(min(max(self.hi, -1.0), 1.0))
        a_lo = math.acos(min(max(self.lo, -1.0), 1.0))
        if self.count == 2:
            ends = (a_hi, a_lo) if k == 0 else (-a_lo, -a_hi)
        elif self.lo <= -1.0:
            ends = (a_hi, TWO_PI - a_hi)
        else:
            ends = (-a_lo, a_lo)
        return ends[0] + self.phase, ends[1] + self.phase


def arcs(top: Topology, z: dict[str, complex]) -> Arcs:
    """The input's reachable angles of a four-bar or slider-crank with joint positions ``z`` (any instant)."""
    a = abs(z["A"] - z["O2"])
    if top.sliders:
        ((_, axis),) = top.sliders.values()
        u = complex(*axis) / abs(complex(*axis))
        b = abs(z["B"] - z["A"])
        off = ((z["O2"] - z["B"]) / u).imag  # the crank pivot's offset from the slider's line
        return Arcs(float(np.angle(u)) + math.pi / 2, (-b - off) / a, (b - off) / a)
    b, c, d = abs(z["B"] - z["A"]), abs(z["B"] - z["O4"]), abs(z["O4"] - z["O2"])
    lo = (a * a + d * d - (b + c) ** 2) / (2 * a * d)
    hi = (a * a + d * d - (b - c) ** 2) / (2 * a * d)
    return Arcs(float(np.angle(z["O4"] - z["O2"])), lo, hi)


def sign(top: Topology, z: dict[str, complex]) -> int:
    """The assembly σ (+1 / −1) the positions ``z`` show (see the module docstring)."""
    if top.sliders:
        ((_, axis),) = top.sliders.values()
        return 1 if ((z["B"] - z["A"]) * complex(*axis).conjugate()).real >= 0 else -1
    return int(side(z, ("A", "B", "O4")))


@dataclass(frozen=True)
class Verdict:
    """The defect the positions make (``kind``: "circuit", "branch", "order" or "" for none), why (``note``), the
    input's direction ``omega`` (±1 rad/s) that meets them in order (or the one chosen), and the instants [s]."""

    kind: str
    note: str
    omega: float
    times: np.ndarray


def classify(top: Topology, configs: list[dict[str, complex]], omega: float | None = None) -> Verdict:
    """The defect of a linkage meant to be at ``configs`` (joint positions at each precision position, in the
    order asked); ``omega`` the input's direction when it is asked (function generation), else either way."""
    rng = arcs(top, configs[0])
    theta = np.array([np.angle(z["A"] - z["O2"]) for z in configs])
    sigma = np.array([sign(top, z) for z in configs])
    arc = rng.index(theta)
    circuit = sigma if rng.full else arc
    times, w = _instants(rng, theta, omega)
    if len(set(circuit.tolist())) > 1:
        k = int(np.nonzero(circuit != circuit[0])[0][0])
        where = "the two assemblies of an input that turns fully" if rng.full else "the input's two arcs"
        note = f"circuit defect: positions 1 and {k + 1} are on different circuits ({where})"
        return Verdict("circuit", note, w, times)
    if len(set(sigma.tolist())) > 1:
        k = int(np.nonzero(sigma != sigma[0])[0][0])
        lo, hi = (math.degrees(v) for v in rng.limits(int(arc[0])))
        return Verdict(
            "branch",
            f"branch defect: position {k + 1} is on the other branch of the same circuit, past a toggle (the input "
            f"rocks between {lo:.2f}° and {hi:.2f}°)",
            w, times,
        )  # fmt: skip
    if not np.all(np.diff(times) > 0):
        return Verdict("order", _order_note(rng, theta, omega), w, times)
    return Verdict("", "", w, times)


def _instants(rng: Arcs, theta: np.ndarray, omega: float | None) -> tuple[np.ndarray, float]:
    """The input's turn [rad] (= instants at 1 rad/s) from position 1 to each position, and the direction: a full
    circle turns modulo a turn, an arc only along itself. The direction that meets them in order, else the one
    asked, else the one that leaves none behind, else +1."""
    psi = rng.psi(theta)
    choices = (omega,) if omega is not None else (1.0, -1.0)
    for w in choices:
        t = _turns(rng, psi, w)
        if np.all(np.diff(t) > 0):
            return t, float(w)
    for w in choices:
        t = _turns(rng, psi, w)
        if np.all(t >= 0):
            return t, float(w)
    w = float(choices[0])
    return _turns(rng, psi, w), w


def _turns(rng: Arcs, psi: np.ndarray, w: float) -> np.ndarray:
    t = w * (psi - psi[0])
    if rng.full:
        t = np.mod(t, TWO_PI)
        t[0] = 0.0
    return t


def _order_note(rng: Arcs, theta: np.ndarray, omega: float | None) -> str:
    """Which order the input meets the positions in, turning each way allowed."""
    psi = rng.psi(theta)
    ways = (omega,) if omega is not None else (1.0, -1.0)
    seen = []
    for w in ways:
        order = np.argsort(_turns(rng, psi, w), kind="stable") + 1
        turning = "counter-clockwise" if w > 0 else "clockwise"
        seen.append(f"{turning}: {', '.join(str(k) for k in order)}")
    along = "" if rng.full else " (the input rocks on an arc: it cannot pass the gap between its limits)"
    return f"order defect: the input meets the positions in another order than asked ({'; '.join(seen)}){along}"


def swept(rng: Arcs, start: float, stop: float) -> tuple[float, float] | None:
    """Whether the input can turn from ``start`` to ``stop`` [rad] (the way the sign of stop − start says) without
    leaving its arc: None if so, else the arc's ends [rad] it runs into."""
    if rng.full:
        return None
    psi = rng.psi(np.array([start]))[0]
    k = int(rng.index(np.array([start]))[0])
    lo, hi = rng.limits(k)
    end = psi + (stop - start)
    lo_psi, hi_psi = lo - rng.phase, hi - rng.phase
    return None if lo_psi - 1e-12 <= end <= hi_psi + 1e-12 else (lo, hi)
