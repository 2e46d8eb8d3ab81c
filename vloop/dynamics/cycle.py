"""Machine-dynamics quantities of a simulated crank over its cycles (Norton, *Design of Machinery*, ch. 11).

A cycle is one whole turn of the input, from the integrator's events (the times q − q₀ = 2πk, located on
its dense output). Over the last cycle:

* mean speed ω̄ = 2π / (cycle time) [rad/s];
* ω_max, ω_min and the textbook's average ω_avg = (ω_max + ω_min)/2; the coefficient of speed
  fluctuation C_s = (ω_max − ω_min)/ω_avg;
* the energy fluctuation ΔE = max − min over the cycle of the kinetic energy ½·J(q)·q̇² [J] (by the energy
  balance, the largest swing of the work of the torques over the cycle: the textbook's area under the
  torque–angle curve);
* steady: whether the last two cycle times agree to STEADY (relative);
* start-up time: the end of the first cycle from which every cycle's mean speed is within 1 % of ω̄.

A flywheel for a stated C_s: the textbook's I_s = ΔE/(C_s·ω̄²) first (ΔE of the constant-speed cycle:
:func:`textbook_energy`), then the inertia on the input that brings the simulated C_s to the stated value
(secant iterations on 1/C_s, nearly linear in the inertia).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import MechanismError
from ..model import Mechanism
from .equations import Model
from .integrate import Simulation, simulate

STEADY = 1e-6  # the last two cycle times agree to this (relative): steady state
STARTUP = 0.01  # start-up: every later cycle's mean speed within 1 % of the steady one
SAMPLES = 4096  # dense-output samples per cycle for the extremes (each refined by a parabola)


@dataclass(frozen=True)
class Cycle:
    """The last whole turn of a simulated crank: times [s], speeds [rad/s], ΔE [J] (see the module notes)."""

    start: float
    stop: float
    mean_speed: float
    omega_max: float
    omega_min: float
    omega_avg: float
    cs: float
    energy_fluctuation: float
    steady: bool
    startup: float
    cycles: int

    def lines(self) -> list[str]:
        """The quantities as a short report, one per line."""
        return [
            f"  last cycle: t = {self.start:.10g} .. {self.stop:.10g} s ({self.cycles} whole turns simulated"
            f"{'' if self.steady else '; NOT steady: cycle times still change by more than 1e-6'})",
            f"  mean speed {self.mean_speed:.10g} rad/s; omega max {self.omega_max:.10g}, min {self.omega_min:.10g}, "
            f"avg (max+min)/2 {self.omega_avg:.10g} rad/s",
            f"  coefficient of speed fluctuation Cs = {self.cs:.6g}; energy fluctuation dE = "
            f"{self.energy_fluctuation:.6g} J",
            f"  start-up time (the end of the first turn from which every turn's mean speed is within 1 %): "
            f"{self.startup:.6g} s",
        ]


def cycle(sim: Simulation) -> Cycle:
    """The machine-dynamics quantities of the last whole turn of ``sim`` (MechanismError without two turns)."""
    turns = np.asarray(sim.turns, float)
    if sim.model.tables.period is None or len(turns) < 2:
        raise MechanismError(
            f"{sim.mechanism.name}: cycle quantities need an input that turns fully at least twice in the run "
            f"({len(turns)} whole turn(s) simulated)",
            entry="dynamics",
        )
    a, b = float(turns[-2]), float(turns[-1])
    t = np.linspace(a, b, SAMPLES + 1)
    y = sim.ode.sol(t)
    qd = y[1] / sim.model.qscale
    J = np.array([sim.model.tables.at(q)[0][0] for q in y[0]])
    kinetic = 0.5 * J * y[1] ** 2
    w_max, w_min = _extreme(qd, 1), _extreme(qd, -1)
    avg = 0.5 * (w_max + w_min)
    means = 2 * math.pi / np.diff(np.concatenate([[0.0], turns]))
    steady_speed = means[-1]
    off = np.flatnonzero(np.abs(means - steady_speed) > STARTUP * abs(steady_speed))
    startup = float(turns[off[-1] + 1 if len(off) else 0])  # the end of the first turn of the good tail
    steady = len(turns) >= 3 and abs((b - a) / (turns[-2] - turns[-3]) - 1.0) <= STEADY
    return Cycle(
        a, b, float(steady_speed), w_max, w_min, avg, (w_max - w_min) / avg,
        _extreme(kinetic, 1) - _extreme(kinetic, -1), bool(steady), startup, len(turns),
    )  # fmt: skip


def _extreme(y: np.ndarray, sign: int) -> float:
    """The largest (sign 1) or smallest (−1) value of samples, refined by the parabola through its neighbours."""
    k = int(np.argmax(sign * y))
    if 0 < k < len(y) - 1:
        a, b, c = y[k - 1], y[k], y[k + 1]
        den = a - 2 * b + c
        if den != 0.0:
            return float(b - 0.125 * (c - a) ** 2 / den)
    return float(y[k])


@dataclass(frozen=True)
class Flywheel:
    """A flywheel on the input for a stated C_s: the textbook's estimate and the simulated answer [kg·m²]."""

    target: float
    textbook: float
    inertia: float
    cs: float
    iterations: int
    base: Cycle
    energy: float  # the textbook's ΔE at the mean speed [J]

    def lines(self) -> list[str]:
        return [
            f"  flywheel for Cs = {self.target:g}: textbook I = dE/(Cs*omega^2) = {self.textbook:.6g} kg m^2 "
            f"(dE = {self.energy:.6g} J at the constant speed omega = {self.base.mean_speed:.6g} rad/s)",
            f"  simulated: I = {self.inertia:.6g} kg m^2 gives Cs = {self.cs:.6g} ({self.iterations} simulations)",
        ]


def textbook_energy(model: Model, speed: float, samples: int = 4096) -> tuple[float, float]:
    """(ΔE [J], the mean torque [N·m]) of the textbook's constant-speed cycle: the torque the input needs to
    turn at ``speed`` [rad/s] (Lagrange with q̈ = 0: ½·J′·ω² + V′ + the springs' and dampers' −Q − the loads'
    −Q, loads at their t = 0 values), less its mean over the turn, integrated over the angle; ΔE is the swing
    of that integral (Norton, eq. 11.xx: the area between the torque curve and its mean)."""
    tab = model.tables
    if tab.period is None:
        raise MechanismError("the textbook's energy fluctuation needs an input that turns fully", entry="dynamics")
    q = tab.nodes[0] + np.linspace(0.0, tab.period, samples + 1)
    need = np.empty_like(q)
    for i, x in enumerate(q):
        v, d = tab.at(float(x))
        springs = sum(k * (v[j] - r) * d[j] + c * d[j] * d[j] * speed for j, k, c, r in model._springs)
        need[i] = 0.5 * d[0] * speed * speed + d[1] + springs - sum(w * d[j] for j, w in model.load_weights(0.0))
    mean = float(np.trapezoid(need, q) / tab.period)
    work = np.concatenate([[0.0], np.cumsum(0.5 * (need[1:] + need[:-1] - 2 * mean) * np.diff(q))])
    return float(work.max() - work.min()), mean


def flywheel_for(mech: Mechanism, cs: float, times: np.ndarray | None = None, **options: Any) -> Flywheel:
    """The flywheel inertia [kg·m²] added on the input that brings the simulated C_s to ``cs`` (to 1e-4): from
    the textbook's estimate ΔE/(C_s·ω̄²) (ΔE at constant speed: :func:`textbook_energy`), each trial started at
    the mean speed ω̄ of the run without it (its transient is then short)."""
    if not 0 < cs < 2:
        raise MechanismError(f"--flywheel-for: Cs must be between 0 and 2, got {cs:g}", entry="flywheel")
    base_fly = (mech.dynamics.flywheel if mech.dynamics else 0.0) + options.pop("flywheel", 0.0)
    first = simulate(mech, times, flywheel=base_fly, **options)
    base = cycle(first)
    energy, _ = textbook_energy(first.model, base.mean_speed)
    textbook = energy / (cs * base.mean_speed**2)
    options["rate"] = base.mean_speed

    def cs_with(extra: float) -> float:
        return cycle(simulate(mech, times, flywheel=base_fly + extra, **options)).cs

    x0, g0 = 0.0, 1.0 / base.cs - 1.0 / cs
    x1 = textbook
    got = cs_with(x1)
    n = 2
    while abs(got / cs - 1.0) > 1e-4 and n < 10:
        g1 = 1.0 / got - 1.0 / cs
        x0, g0, x1 = x1, g1, x1 - g1 * (x1 - x0) / (g1 - g0)  # the right side is read before assigning
        got = cs_with(x1)
        n += 1
    return Flywheel(cs, textbook, x1, got, n, base, energy)
