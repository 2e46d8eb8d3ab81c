"""Forward dynamics of a two-input mechanism (two cranks): the loop solve at every right-hand side call.

With two inputs q = (q₁, q₂) the functions of q would need tables in two dimensions; instead every call of
the right-hand side asks vloop's run for the configuration at q (a run from the drawing's inputs to q, so the
assembly is the one the file's branches continue to), at three instants there: input rates e₁ and e₂ (the
velocity coefficients ∂r/∂qᵢ, ∂φ/∂qᵢ) and q̇ with q̈ = 0 (the accelerations' quadratic part a₀, α₀). Then

    J_ij = Σ m·∂r_G/∂qᵢ·∂r_G/∂qⱼ + I·∂φ/∂qᵢ·∂φ/∂qⱼ,    h_i = Σ m·∂r_G/∂qᵢ·a₀ + I·∂φ/∂qᵢ·α₀,
    Q_i = Σ m·g·∂r_G/∂qᵢ,                               J·q̈ = Q − h          (d'Alembert on each input)

(h holds the Christoffel terms). Slower than the tables of one input (a loop solve per call) but exact to the
solve's round-off. Loads in this version: gravity and the masses (no input torque, spring or [[loads]]).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from ..errors import MechanismError, MotionError
from ..model import Dynamics, Mechanism, Profile, length_factor
from .tables import G_PREFIX, augmented

GAP = 1e-3  # [s] between the three instants at q in a call's run (the path between them stays within ~GAP rad)


@dataclasses.dataclass
class TwoInputs:
    """The equations of motion of a two-crank mechanism with masses under gravity (vloop's solve at each call)."""

    mechanism: Mechanism
    dynamics: Dynamics
    qscale: float = 1.0
    calls: int = 0

    def __post_init__(self) -> None:
        self.rest = np.zeros(0)  # (no springs: the energy table's)
        self.aug = augmented(self.mechanism)
        self.x0 = np.array([float(d.x0) for d in self.mechanism.drivers])
        self.bodies = [b for b in self.mechanism.masses if G_PREFIX + b in self.aug.points]

    def terms(self, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, dict]:
        """(J (2, 2), h (2,), Q (2,), the run's columns at the instants) at the inputs q [rad], rates q̇ [rad/s]."""
        from .. import solve

        self.calls += 1
        t = np.array([0.0, 1.0, 1.0 + GAP, 1.0 + 2 * GAP])
        drivers = []
        for i, d in enumerate(self.aug.drivers):
            x = np.array([self.x0[i], q[i], q[i], q[i]])
            v = np.array([0.0, float(i == 0), float(i == 1), qd[i]])
            drivers.append(dataclasses.replace(d, profile=Profile(t, x, v, np.zeros(4), source="simulate")))
        run = dataclasses.replace(self.aug, drivers=tuple(drivers), times=t, dynamics=None)
        res = solve(run, t)
        f = length_factor(self.mechanism.units)
        g = np.asarray(self.mechanism.gravity or (0.0, 0.0), float)
        J, h, Q = np.zeros((2, 2)), np.zeros(2), np.zeros(2)
        for b in self.bodies:
            mp, p = self.mechanism.masses[b], G_PREFIX + b
            v = np.array([[res[f"{p}.vx"][1 + i], res[f"{p}.vy"][1 + i]] for i in range(2)]) * f  # ∂r_G/∂qᵢ
            w = np.array([res[f"{b}.omega"][1], res[f"{b}.omega"][2]])  # ∂φ/∂qᵢ
            a0 = np.array([res[f"{p}.ax"][3], res[f"{p}.ay"][3]]) * f
            J += mp.mass * v @ v.T + mp.inertia * np.outer(w, w)
            h += mp.mass * v @ a0 + mp.inertia * w * res[f"{b}.alpha"][3]
            Q += mp.mass * v @ g
        return J, h, Q, res

    def rhs(self, t: float, y: np.ndarray) -> np.ndarray:
        """d/dt of (q₁, q₂, q̇₁, q̇₂)."""
        J, h, Q, _ = self.terms(y[:2], y[2:])
        if not np.linalg.det(J) > 1e-12 * max(float(np.trace(J)), 1e-300) ** 2:  # (J is symmetric, ≥ 0)
            raise MechanismError(
                f"{self.mechanism.name}: [dynamics] the mechanism has no inertia in some direction of its two inputs "
                f"at {self.x0.tolist() if t == 0 else y[:2].tolist()} rad: give its links masses and inertias",
                entry="dynamics",
            )
        return np.concatenate([y[2:], np.linalg.solve(J, Q - h)])


def check(mech: Mechanism, dyn: Dynamics) -> None:
    """Two cranks, and loads this version integrates (gravity and masses): else one clear line."""
    what = []
    if any(d.kind != "crank" for d in mech.drivers):
        what.append("a slider input")
    if dyn.position is not None or dyn.rate is not None:
        what.append("a [dynamics] position or rate (the drivers' values at t = 0 are the initial state)")
    if dyn.torque or dyn.torque_profile is not None or dyn.motor is not None or dyn.flywheel or dyn.springs:
        what.append("an input torque, motor, flywheel or spring")
    if mech.loads:
        what.append("[[loads]]")
    if what:
        raise MechanismError(
            f"{mech.name}: forward dynamics of two inputs takes gravity and the masses only (not {', '.join(what)})",
            entry="dynamics",
        )


def integrate(mech: Mechanism, dyn: Dynamics, times: np.ndarray) -> tuple[TwoInputs, Any]:
    """solve_ivp of (q, q̇) from the drivers' values at t = 0, the rows as t_eval."""
    from scipy.integrate import solve_ivp

    check(mech, dyn)
    model = TwoInputs(mech, dyn)
    y0 = [*(float(d.x0) for d in mech.drivers), *(float(d.v0) for d in mech.drivers)]
    try:
        ode = solve_ivp(model.rhs, (0.0, float(times[-1])), y0, method=dyn.method, t_eval=times, rtol=dyn.rtol,
                        atol=dyn.atol, dense_output=True)  # fmt: skip
    except MotionError as exc:
        raise MotionError(f"{mech.name}: the simulated motion: {exc.message}", entry="dynamics") from None
    if ode.status < 0:
        raise MotionError(f"{mech.name}: the integrator failed: {ode.message}", entry="dynamics")
    return model, ode
