"""Closed-form kinetostatics of the slider-crank and the four-bar, derived by hand (engine "analytic").

The kinematics come from the closed forms (:mod:`validators.analytic.slider_crank`,
:mod:`validators.analytic.fourbar`); nothing of vloop's solver or force code is used.

Notation (all vectors in the world plane, SI units). F_ij is the force body i exerts on body j
(Norton's convention), a × b = a_x b_y − a_y b_x. For every moving body i with mass m_i, centre of
mass G_i, inertia I_i, angular acceleration α_i, loads L (force at point P) and load torques T:

    E_i    = m_i·a_Gi − m_i·g − Σ L                      the force its joints must supply,
    K_i(Q) = I_i·α_i + (G_i − Q) × m_i·(a_Gi − g)
             − Σ (P − Q) × L − Σ T                       the moment about Q its joints must supply,

(Newton: Σ F = m·a_G; Euler about any point Q of the body: Σ M_Q = I·α + (G − Q) × m·a_G.)
a_G = a_O + α·k × r − ω²·r, with r = R(θ)·c from the body frame's origin O to G.

**Slider-crank** (crank 2: O2 → A, rod 3: A → B, block 4 at B on a ground line with axis u,
n = k × u; the guide exerts N·n at B and a moment M on the block):

    block:  F34 + N·n = E4                      ⇒  F34·u = E4·u =: p                    (1)
    rod, moments about A (F23 passes through A):
            (B − A) × (−F34) = K3(A),  F34 = p·u + q·n, (B − A) × n = (B − A)·u
            ⇒  q = (−K3(A) − p·(B − A) × u) / ((B − A)·u)                              (2)
    block:  N = E4·n − q;   moments about B:  M = K4(B)                                (3)
    rod:    F23 − F34 = E3  ⇒  F23 = E3 + F34                                          (4)
    crank:  F12 − F23 = E2  ⇒  F12 = E2 + F23;  τ + (A − O2) × (−F23) = K2(O2)
            ⇒  τ = K2(O2) + (A − O2) × F23                                              (5)

(2) fails only where the rod stands perpendicular to the line, (B − A)·u = 0 (a dead point).

**Four-bar** (crank 2: O2 → A, coupler 3: A → B, rocker 4: O4 → B):

    rocker, moments about O4:   (B − O4) × F34 = K4(O4)
    coupler, moments about A:   (B − A) × F34 = −K3(A)
        two linear equations in F34 = (X, Y): −(B − O4)_y X + (B − O4)_x Y = K4(O4),
        −(B − A)_y X + (B − A)_x Y = −K3(A); Cramer's rule with the determinant
        (B − A) × (B − O4), zero only at a toggle (coupler and rocker aligned);
    F14 = E4 − F34,  F23 = E3 + F34,  F12 = E2 + F23,  τ = K2(O2) + (A − O2) × F23.

Reported in vloop's columns (:mod:`validators.forces_common`): ``O2:ground>crank`` = F12,
``A:crank>rod`` = F23, ``B:rod>block`` = F34, ``O4:ground>rocker`` = F14, ``block.normal`` = N,
``block.moment`` = M, ``crank.torque`` = τ.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from vloop.forces import ForceResult
from vloop.mechanism import Mechanism
from vloop.result import Result

from ..forces_common import factor, force_result, load_series, mass_table
from . import fourbar, slider_crank

ENGINE = "analytic"


def available(mech: Mechanism) -> bool:
    """True for a crank-driven slider-crank or four-bar (the structures solved here)."""
    return slider_crank.applies(mech) or fourbar.applies(mech)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """a × b for (n, 2) arrays (or one of them (2,))."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


class _Bodies:
    """Per body, over the samples [SI]: E_i and K_i(Q) of the module notes, from a kinematic Result."""

    def __init__(self, mech: Mechanism, kin: Result) -> None:
        self.mech, self.kin, self.f = mech, kin, factor(mech)
        self.masses = mass_table(mech)
        self.frames = mech.bodies()
        self.g = np.asarray(mech.gravity or (0.0, 0.0), float)
        self.loads = [(ld, load_series(ld, kin.t)) for ld in mech.loads]

    def point(self, name: str) -> np.ndarray:
        return np.column_stack([self.kin[f"{name}.x"], self.kin[f"{name}.y"]]) * self.f

    def _com(self, body: str) -> tuple[np.ndarray, np.ndarray, float, float]:
        """(G, a_G, m, I·α) of a body."""
        mass, com, inertia = self.masses.get(body, (0.0, np.zeros(2), 0.0))
        k = self.kin
        th, om, al = k[f"{body}.theta"], k[f"{body}.omega"], k[f"{body}.alpha"]
        o = self.frames[body].joints[0]
        c, s = np.cos(th), np.sin(th)
        r = np.column_stack([c * com[0] - s * com[1], s * com[0] + c * com[1]]) * self.f
        a_o = np.column_stack([k[f"{o}.ax"], k[f"{o}.ay"]]) * self.f
        a_g = a_o + al[:, None] * np.column_stack([-r[:, 1], r[:, 0]]) - (om * om)[:, None] * r
        return self.point(o) + r, a_g, mass, inertia * al

    def E(self, body: str) -> np.ndarray:
        _, a_g, mass, _ = self._com(body)
        out = mass * (a_g - self.g)
        for ld, v in self.loads:
            if ld.body == body and ld.kind == "force":
                out = out - v
        return out

    def K(self, body: str, q: np.ndarray) -> np.ndarray:
        g_pos, a_g, mass, i_alpha = self._com(body)
        out = i_alpha + _cross(g_pos - q, mass * (a_g - self.g))
        for ld, v in self.loads:
            if ld.body != body:
                continue
            out = out - (v if ld.kind == "torque" else _cross(self.point(ld.point) - q, v))
        return out


def _slider_crank(b: _Bodies, r: Any) -> tuple[dict, dict, dict, dict]:
    sl = b.mech.sliders[r.block]
    u = np.asarray(sl.axis, float)
    n = np.array([-u[1], u[0]])
    A, B, O2 = b.point(r.A), b.point(r.B), b.point(r.O2)
    E4 = b.E(r.block)
    p = E4 @ u  # (1)
    BA = B - A
    q = (-b.K(r.rod, A) - p * _cross(BA, u)) / (BA @ u)  # (2)
    F34 = p[:, None] * u + q[:, None] * n
    N, M = E4 @ n - q, b.K(r.block, B)  # (3)
    F23 = b.E(r.rod) + F34  # (4)
    F12 = b.E(r.crank) + F23
    tau = b.K(r.crank, O2) + _cross(A - O2, F23)  # (5)
    pins = {(r.O2, r.crank): F12, (r.O2, r.ground): -F12, (r.A, r.rod): F23, (r.A, r.crank): -F23}
    pins |= {(r.B, r.block): F34, (r.B, r.rod): -F34}
    return {f"{r.crank}.torque": tau}, pins, {r.block: (N, M)}, {r.block: np.broadcast_to(u, A.shape)}


def _fourbar(b: _Bodies, r: Any) -> tuple[dict, dict, dict, dict]:
    A, B, O2, O4 = b.point(r.A), b.point(r.B), b.point(r.O2), b.point(r.O4)
    k4, k3 = b.K(r.rocker, O4), -b.K(r.coupler, A)
    BO, BA = B - O4, B - A
    det = -BO[:, 1] * BA[:, 0] + BO[:, 0] * BA[:, 1]
    X = (k4 * BA[:, 0] - BO[:, 0] * k3) / det
    Y = (-BO[:, 1] * k3 + BA[:, 1] * k4) / det
    F34 = np.column_stack([X, Y])
    F14 = b.E(r.rocker) - F34
    F23 = b.E(r.coupler) + F34
    F12 = b.E(r.crank) + F23
    tau = b.K(r.crank, O2) + _cross(A - O2, F23)
    pins = {(r.O2, r.crank): F12, (r.O2, r.ground): -F12, (r.A, r.coupler): F23, (r.A, r.crank): -F23}
    pins |= {(r.B, r.rocker): F34, (r.B, r.coupler): -F34, (r.O4, r.rocker): F14, (r.O4, r.ground): -F14}
    return {f"{r.crank}.torque": tau}, pins, {}, {}


def solve_forces(mech: Mechanism, times: np.ndarray | None = None, kinematics: Result | None = None) -> ForceResult:
    """Closed-form driver torque [N·m], pin forces, slider normal force and moment [N, N·m] and shaking
    force over ``times`` [s] (kinematics from the closed forms unless given)."""
    sc, fb = slider_crank.roles(mech), fourbar.roles(mech)
    if sc is None and fb is None:
        raise ValueError(f"{mech.name}: no closed-form force analysis (slider-crank and four-bar only)")
    if kinematics is None:
        mod = slider_crank if sc is not None else fourbar
        kinematics = mod.solve(mech, times)
    b = _Bodies(mech, kinematics)
    drivers, pins, sliders, axes = _slider_crank(b, sc) if sc is not None else _fourbar(b, fb)
    positions = {j: b.point(j) for j in mech.joints}
    return force_result(mech, ENGINE, kinematics.t, drivers, pins, sliders, positions, axes)


def solve(mech: Mechanism, times: np.ndarray | None = None) -> Result:
    """Closed-form kinematics and forces in one Result (engine "analytic")."""
    mod = slider_crank if slider_crank.applies(mech) else fourbar
    kin = mod.solve(mech, times)
    frc = solve_forces(mech, kinematics=kin)
    return Result(kin.mechanism, ENGINE, kin.t, {**kin.columns, **frc.columns}, kin.health, dict(kin.meta))


__all__ = ["ENGINE", "available", "solve", "solve_forces"]
