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
from typing import Any

import numpy as np

from .linkages import Topology, side

TWO_PI = 2.0 * math.pi


@dataclass(frozen=True)
class Arcs:
    """The input angles θ [rad] at which the dyad closes: cos(θ − ``phase``) ∈ [``lo``, ``hi``]; numbers, or arrays
    over a population (then θ has one more axis: the positions)."""

    phase: Any
    lo: Any
    hi: Any

    @property
    def full(self) -> Any:
        """The input turns fully (no toggle)."""
        return np.logical_and(np.asarray(self.lo) <= -1.0, np.asarray(self.hi) >= 1.0)

    @property
    def count(self) -> Any:
        """How many arcs (a full circle counts as one)."""
        lo, hi = np.asarray(self.lo), np.asarray(self.hi)
        empty = (lo > 1.0) | (hi < -1.0) | (lo > hi)
        return np.where(empty, 0, np.where((lo > -1.0) & (hi < 1.0), 2, 1))

    def psi(self, theta: np.ndarray) -> np.ndarray:
        """θ − phase, wrapped so that every arc is one interval: (−π, π], or [0, 2π) for the arc about π."""
        phase = (
            np.expand_dims(np.asarray(self.phase, float), -1) if np.ndim(theta) > np.ndim(self.phase) else self.phase
        )
        psi = np.angle(np.exp(1j * (np.asarray(theta, float) - phase)))
        about_pi = (self.count == 1) & ~self.full & (np.asarray(self.lo) <= -1.0)  # one arc about π
        if np.ndim(theta) > np.ndim(about_pi):
            about_pi = np.expand_dims(about_pi, -1)
        return np.where(about_pi, np.mod(psi, TWO_PI), psi)

    def index(self, theta: np.ndarray) -> np.ndarray:
        """Which arc each θ is on (0 or 1; the arc at negative ψ is 1 when there are two)."""
        two = self.count == 2
        if np.ndim(theta) > np.ndim(two):
            two = np.expand_dims(two, -1)
        return np.where(two & (self.psi(theta) < 0), 1, 0)

    def limits(self, k: int) -> tuple[float, float]:
        """Arc k's ends as input angles [rad] (ascending along ψ) of a single linkage."""
        a_hi = math.acos(min(max(float(self.hi), -1.0), 1.0))
        a_lo = math.acos(min(max(float(self.lo), -1.0), 1.0))
        if int(self.count) == 2:
            ends = (a_hi, a_lo) if k == 0 else (-a_lo, -a_hi)
        elif float(self.lo) <= -1.0:
            ends = (a_hi, TWO_PI - a_hi)
        else:
            ends = (-a_lo, a_lo)
        return ends[0] + float(self.phase), ends[1] + float(self.phase)


def arcs(top: Topology, z: dict[str, Any]) -> Arcs:
    """The input's reachable angles of a four-bar or slider-crank with joint positions ``z`` (any instant;
    complex numbers, or arrays over a population)."""
    a = np.abs(z["A"] - z["O2"])
    with np.errstate(divide="ignore", invalid="ignore"):
        if top.sliders:
            ((_, axis),) = top.sliders.values()
            u = complex(*axis) / abs(complex(*axis))
            b = np.abs(z["B"] - z["A"])
            off = ((z["O2"] - z["B"]) / u).imag  # the crank pivot's offset from the slider's line
            return Arcs(float(np.angle(u)) + math.pi / 2 + 0 * off, (-b - off) / a, (b - off) / a)
        b, c, d = np.abs(z["B"] - z["A"]), np.abs(z["B"] - z["O4"]), np.abs(z["O4"] - z["O2"])
        lo = (a * a + d * d - (b + c) ** 2) / (2 * a * d)
        hi = (a * a + d * d - (b - c) ** 2) / (2 * a * d)
    return Arcs(np.angle(z["O4"] - z["O2"]), lo, hi)


def sign(top: Topology, z: dict[str, Any]) -> Any:
    """The assembly σ (+1 / −1) the positions ``z`` show (see the module docstring)."""
    if top.sliders:
        ((_, axis),) = top.sliders.values()
        return np.where(((z["B"] - z["A"]) * complex(*axis).conjugate()).real >= 0, 1, -1)
    return side(z, ("A", "B", "O4")).astype(int)


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
    sigma = np.array([int(sign(top, z)) for z in configs])
    arc = rng.index(theta)
    circuit = sigma if bool(rng.full) else arc
    times, w = _instants(rng, theta, omega)
    if len(set(circuit.tolist())) > 1:
        k = int(np.nonzero(circuit != circuit[0])[0][0])
        where = "the two assemblies of an input that turns fully" if bool(rng.full) else "the input's two arcs"
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


def _turns(rng: Arcs, psi: np.ndarray, w: Any) -> np.ndarray:
    """The input's turn from position 1 to each (last axis), turning the way w (±1): modulo a turn on a full
    circle, along the arc otherwise."""
    t = np.expand_dims(w, -1) * (psi - psi[..., :1]) if np.ndim(psi) > 1 else w * (psi - psi[0])
    full = np.expand_dims(rng.full, -1) if np.ndim(psi) > np.ndim(rng.full) else rng.full
    t = np.where(full, np.mod(t, TWO_PI), t)
    t[..., 0] = 0.0
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
    along = "" if bool(rng.full) else " (the input rocks on an arc: it cannot pass the gap between its limits)"
    return f"order defect: the input meets the positions in another order than asked ({'; '.join(seen)}){along}"


def swept(rng: Arcs, start: float, stop: float) -> tuple[float, float] | None:
    """Whether the input can turn from ``start`` to ``stop`` [rad] (the way the sign of stop − start says) without
    leaving its arc: None if so, else the arc's ends [rad] it runs into."""
    if bool(rng.full):
        return None
    psi = rng.psi(np.array([start]))[0]
    k = int(rng.index(np.array([start]))[0])
    lo, hi = rng.limits(k)
    end = psi + (stop - start)
    lo_psi, hi_psi = lo - float(rng.phase), hi - float(rng.phase)
    return None if lo_psi - 1e-12 <= end <= hi_psi + 1e-12 else (lo, hi)


def screen(top: Topology, configs: dict[str, np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A population's rows (joint positions (V, N) at each position, complex): the direction (±1) that meets the
    positions in order on one branch, the input's turn to each (V, N) [rad], and whether a row does (no circuit,
    branch or order defect) — :func:`classify`'s rule, every row at once."""
    rng = arcs(top, {k: v[:, 0] for k, v in configs.items()})
    theta = np.angle(configs["A"] - configs["O2"])
    sigma = sign(top, configs)
    psi = rng.psi(theta)
    one_branch = np.all(sigma == sigma[:, :1], axis=1) & np.all(rng.index(theta) == rng.index(theta)[:, :1], axis=1)
    omega, times, ok = np.ones(len(theta)), np.zeros(theta.shape), np.zeros(len(theta), bool)
    for w in (-1.0, 1.0):
        t = _turns(rng, psi, np.full(len(theta), w))
        good = one_branch & np.all(np.diff(t, axis=1) > 1e-9, axis=1) & (rng.count > 0)
        omega, times, ok = np.where(good, w, omega), np.where(good[:, None], t, times), ok | good
    return omega, times, ok
