"""Pinocchio's constrained forward dynamics of a mechanism's [dynamics], independent of vloop.

    res, correction = simulate(mech, times, step)          # engine "pinocchio-simulate"

The model is :mod:`validators.pinocchio`'s kinematic tree (loops cut at pins, each cut closed by a
``PointAnchorConstraintModel``) with the file's masses and gravity as :mod:`validators.pinocchio_forces` adds
them; the driver is not imposed: the tree moves under its loads. At every state (q, v) of the tree:

    [ M   Jcᵀ ] [ a ]   [ τ − h(q, v)                      ]
    [ Jc  0   ] [ −λ] = [ −γ(q, v) − 2β·Jc·v − β²·c(q)     ]

M by ``crba``, h (Coriolis, centrifugal and gravity) by ``nonLinearEffects``, Jc the cut anchors' Jacobian and
γ = J̇c·v their acceleration error (Pinocchio's constraint models, through validators.pinocchio's rows), c(q)
their position error, β = BAUMGARTE a stabilization gain, the same at every step (so that every step size
integrates the same equations and Richardson's estimate holds; a gain tied to h would make the error first
order, measured). τ: the input's torque and motor line on the driven body (its frame Jacobian), a flywheel
appended to its inertia, the file's [[loads]] and the springs and dampers (point and frame Jacobians).
The state is integrated by the classical fourth-order Runge–Kutta method at a fixed step h; its error is
estimated by Richardson from the same run at 2h: correction = (x(h) − x(2h))/15.

Outputs: every body's θ and ω (its frame's angle, unwrapped along the run) at the rows.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from vloop.mechanism import Mechanism
from vloop.model import Dynamics
from vloop.result import Result

from . import pinocchio as vpin
from . import pinocchio_forces as vpf
from .forces_common import factor, load_series

ENGINE = "pinocchio-simulate"
BAUMGARTE = 10.0  # 1/s: pulls the cut anchors' drift (RK4's local errors) back over ~0.1 s


def simulate(mech: Mechanism, times: np.ndarray, step: float) -> tuple[Result, dict[str, np.ndarray]]:
    """(the run at ``step``, Richardson's correction per column) at ``times`` [s] (from 0; their spacing a
    multiple of 2·step): the exact motion is ≈ run + correction, its error O(h⁵)."""
    fine = _run(mech, times, step)
    coarse = _run(mech, times, 2 * step)
    return fine, {c: (fine[c] - coarse[c]) / 15.0 for c in fine.columns}


class _Dynamics:
    """The right-hand side (q, v) → (v, a) of the constrained tree."""

    def __init__(self, mech: Mechanism) -> None:
        import pinocchio as pin

        self.mech, self.f = mech, factor(mech)
        self.dyn = mech.dynamics or Dynamics()
        self.pm = vpin.build_model(mech)
        vpf._add_dynamics(self.pm, mech)
        target = mech.drivers[0].target
        if self.dyn.flywheel:
            self.pm.model.appendBodyToJoint(
                self.pm.body_joint[target],
                pin.Inertia(0.0, np.zeros(3), np.diag([0.0, 0.0, self.dyn.flywheel / self.f**2])),
                pin.SE3.Identity(),
            )
        self.work = vpin._Work(self.pm)
        self.ncut = 2 * len(self.pm.cuts)
        self.beta = BAUMGARTE
        self.target = target

    def frame(self, name: str, lwa: Any) -> tuple[float, np.ndarray]:
        """A body's angle [rad] and its frame Jacobian (6, nv) at the current placement."""
        import pinocchio as pin

        fid = self.pm.body_frame[name]
        rot = self.work.data.oMf[fid].rotation
        return math.atan2(rot[1, 0], rot[0, 0]), pin.getFrameJacobian(self.pm.model, self.work.data, fid, lwa)

    def rhs(self, t: float, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        import pinocchio as pin

        m, d = self.pm.model, self.work.data
        error, jac = self.work.residual(q, np.zeros(len(self.mech.drivers)), True)
        c, jc = error[: self.ncut], jac[: self.ncut]
        gamma = self.work.drift(q, v)[: self.ncut]
        pin.computeJointJacobians(m, d, q)
        pin.updateFramePlacements(m, d)
        tau = self._forces(t, v) - pin.nonLinearEffects(m, d, q, v)
        M = pin.crba(m, d, q)
        M = np.triu(M) + np.triu(M, 1).T
        n = self.pm.nv
        kkt = np.block([[M, jc.T], [jc, np.zeros((self.ncut, self.ncut))]])
        rhs = np.concatenate([tau, -gamma - 2 * self.beta * (jc @ v) - self.beta**2 * c])
        return np.linalg.solve(kkt, rhs)[:n]

    def _forces(self, t: float, v: np.ndarray) -> np.ndarray:
        """Generalized forces of the input's torque, the [[loads]] and the springs [file units]."""
        import pinocchio as pin

        lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        f, dyn = self.f, self.dyn
        _, jin = self.frame(self.target, lwa)
        w = float(jin[5] @ v)
        torque = dyn.torque + (dyn.motor[0] * (1.0 - w / dyn.motor[1]) if dyn.motor else 0.0)
        tau = jin[5] * torque / f**2
        for ld in self.mech.loads:
            value = load_series(ld, np.array([t]))[0]
            if ld.kind == "torque":
                tau += self.frame(ld.body, lwa)[1][5] * float(value) / f**2
            else:
                tau += self._point(ld.body, ld.point)[1].T @ (np.asarray(value, float) / f)
        for s in dyn.springs:
            tau += self._spring(s, v, lwa)
        return tau

    def _point(self, body: str, name: str) -> tuple[np.ndarray, np.ndarray]:
        """A point's world position [file units] and its (2, nv) Jacobian."""
        p = self.work.data.oMf[self.pm.point_frame[name]].translation[:2].copy()
        return p, vpf._point_jacobian(self.pm, self.work.data, body, p)

    def _spring(self, s: Any, v: np.ndarray, lwa: Any) -> np.ndarray:
        f = self.f
        if s.kind == "rotational":
            (ta, ja), (tb, jb) = (
                self.frame(b, lwa) if b != self.mech.ground else (0.0, np.zeros((6, self.pm.nv))) for b in s.ends
            )
            drawn = self.drawn_angle(s)
            rest = drawn if s.rest is None else s.rest
            phi = drawn + vpin._wrap(ta - tb - drawn)  # within half a turn of the drawing
            jrel = ja[5] - jb[5]
            return -(s.k * (phi - rest) + s.c * float(jrel @ v)) * jrel / f**2
        (p, jp), (q, jq) = (self._point(self.mech.body_of_point(n), n) for n in s.ends)
        dvec = (p - q) * f
        length = float(np.hypot(*dvec))
        jrel = (jp - jq) * f
        rate = float(dvec @ (jrel @ v)) / length
        rest = math.dist(*(self.mech.points[n].at if n in self.mech.points else self.mech.joints[n] for n in s.ends))
        rest = rest * f if s.rest is None else s.rest * f
        force = -(s.k * (length - rest) + s.c * rate) * dvec / length  # on P, N
        return (jp - jq).T @ (force / f)

    def drawn_angle(self, s: Any) -> float:
        bodies = self.mech.bodies()
        a, b = (bodies[n].theta0 if n != self.mech.ground else 0.0 for n in s.ends)
        return a - b


def _run(mech: Mechanism, times: np.ndarray, h: float) -> Result:
    """RK4 on the tree's (q, v) from the assembly at t = 0 with the input at its [dynamics] rate."""
    import pinocchio as pin

    dyn = mech.dynamics or Dynamics()
    d = mech.drivers[0]
    rate = d.v0 if dyn.rate is None else dyn.rate
    driven = dataclasses.replace(mech, drivers=(dataclasses.replace(d, v0=rate, a0=0.0, profile=None),))
    start = vpin.solve(driven, np.array([0.0]))
    q, v = np.array(start.meta["q"][0], float), np.array(start.meta["v"][0], float)
    model = _Dynamics(mech)
    rows = round((times[1] - times[0]) / h) if len(times) > 1 else 1
    names = [b for b in mech.moving_links if b in model.pm.body_frame]
    out: dict[str, list[float]] = {f"{b}.{k}": [] for b in names for k in ("theta", "omega")}
    t = 0.0
    lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    for k in range(len(times)):
        if k:
            for _ in range(rows):
                q, v = _rk4(model, t, q, v, h)
                t += h
        pin.computeJointJacobians(model.pm.model, model.work.data, q)
        pin.updateFramePlacements(model.pm.model, model.work.data)
        for b in names:
            angle, jac = model.frame(b, lwa)
            out[f"{b}.theta"].append(angle)
            out[f"{b}.omega"].append(float(jac[5] @ v))
    cols = {c: np.asarray(x) for c, x in out.items()}
    for b in names:  # unwrap against the t = 0 frame angle of the file (θ as vloop states it)
        th = np.unwrap(cols[f"{b}.theta"])
        cols[f"{b}.theta"] = th + 2 * math.pi * round((mech.bodies()[b].theta0 - th[0]) / (2 * math.pi))
    return Result(mech.name, ENGINE, np.asarray(times, float), cols)


def _rk4(model: _Dynamics, t: float, q: np.ndarray, v: np.ndarray, h: float) -> tuple[np.ndarray, np.ndarray]:
    """One classical Runge–Kutta step of (q̇, v̇) = (v, a(q, v)) (the tree's joints are all 1-dof: q̇ = v)."""
    a1 = model.rhs(t, q, v)
    a2 = model.rhs(t + h / 2, q + h / 2 * v, v + h / 2 * a1)
    v2 = v + h / 2 * a1
    a3 = model.rhs(t + h / 2, q + h / 2 * v2, v + h / 2 * a2)
    v3 = v + h / 2 * a2
    a4 = model.rhs(t + h, q + h * v3, v + h * a3)
    v4 = v + h * a3
    return q + h / 6 * (v + 2 * v2 + 2 * v3 + v4), v + h / 6 * (a1 + 2 * a2 + 2 * a3 + a4)
