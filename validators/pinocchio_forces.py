"""Pinocchio's inverse dynamics with the loop-closure forces: driver torques and every reaction.

    kin, forces = solve_with_forces(mech)        # engine "pinocchio"

Independent of vloop's force code: the kinematic tree of :mod:`validators.pinocchio` (loops cut
at pins, closed by point-anchor constraints) gets the file's masses — each body's inertia appended
to its joint — gravity and loads, and its own joint trajectories q(t), v(t), a(t). At every sample:

1. the constraint rows, all in the world frame: for a cut pin (joint j, bodies b1, b2) the
   velocity of j on b2 minus on b1 (Pinocchio joint Jacobians, v_P = v_O + ω × (P − O)), for a
   crank driver the driven body's angular velocity, for a driven slider ds/dq;
   with the drivers these are nv equations: J is square (nv × nv);
2. the tree's inverse dynamics with the loads as external forces, τ = RNEA(q, v, a, f_loads)
   = M(q)·a + h(q, v) − J_loadsᵀ f_loads (gravity in the model), and since no joint of the tree is
   actuated, τ = Jᵀ·λ: the multipliers λ = J⁻ᵀ τ are the cut pins' forces (on b2 from b1, world
   frame), the crank torques (ground on link) and the slider drivers' forces (guide on block);
3. RNEA once more with the loads and every λ applied as external forces: now no joint transmits
   a torque along its axis (checked) and Pinocchio's joint forces ``data.f[i]`` (parent on the
   subtree of i, in the joint frame) are the reactions at the tree's own joints: pin forces, and at a
   prismatic joint the guide's normal force and moment on the block.

Per pin the net force on every body (tree joints and cuts together) is reported in vloop's
convention (:mod:`validators.forces_common`). Lengths are the file's: inertias, gravity and loads
are converted into file units and the results back into N and N·m.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from vloop.errors import MotionError
from vloop.forces import ForceResult
from vloop.mechanism import Mechanism
from vloop.result import Result

from . import pinocchio as vpin
from .forces_common import factor, force_result, load_series, mass_table

ENGINE = "pinocchio"
TORQUE_CHECK = 1e-9  # |τ| left on a joint after applying λ, relative to the largest generalized force


def solve_with_forces(
    mechanism: Mechanism, times: np.ndarray | Sequence[float] | None = None, **options: Any
) -> tuple[Result, ForceResult]:
    """Kinematics (validators.pinocchio) and forces [N, N·m] of ``mechanism`` over ``times`` [s].

    Raises MotionError (``.partial`` = (kinematics, forces) of the samples solved) like the
    kinematic engine.
    """
    if options.get("root") not in (None, mechanism.ground):
        raise ValueError("pinocchio forces need the tree rooted at the ground")
    try:
        kin = vpin.solve(mechanism, times, **options)
    except MotionError as exc:
        part = exc.partial
        raise MotionError(str(exc), time=exc.time, sample=exc.sample, partial=(part, forces(mechanism, part))) from None
    return kin, forces(mechanism, kin, options.get("cut_preference", ()))


def forces(mech: Mechanism, kin: Result, cut_preference: Sequence[str] = ()) -> ForceResult:
    """Forces at every sample of a Result of :func:`validators.pinocchio.solve` (its meta q, v, a)."""
    pm = vpin.build_model(mech, None, cut_preference)
    _add_dynamics(pm, mech)
    work = vpin._Work(pm)  # Pinocchio Data (after the inertias) and the slider-row helper
    f = factor(mech)
    t = kin.t
    loads = [(ld, load_series(ld, t)) for ld in mech.loads]
    n = len(t)
    rows: dict[str, list[Any]] = {"drivers": [], "pins": [], "sliders": [], "positions": [], "axes": []}
    for k in range(n):
        out = _sample(
            pm, work, kin.meta["q"][k], kin.meta["v"][k], kin.meta["a"][k], [(ld, v[k]) for ld, v in loads], f
        )
        for key in rows:
            rows[key].append(out[key])
    drivers = {c: np.array([r[c] for r in rows["drivers"]]) for c in (rows["drivers"][0] if n else {})}
    pins = {key: np.array([r[key] for r in rows["pins"]]).reshape(n, 2) for key in _pin_keys(mech)}
    sliders = {
        s: (np.array([r[s][0] for r in rows["sliders"]]), np.array([r[s][1] for r in rows["sliders"]]))
        for s in mech.sliders
    }
    positions = {j: np.array([r[j] for r in rows["positions"]]).reshape(n, 2) for j in mech.joints}
    axes = {s: np.array([r[s] for r in rows["axes"]]).reshape(n, 2) for s in mech.sliders}
    if not n:
        drivers = {_driver_column(d): np.zeros(0) for d in mech.drivers}
    return force_result(mech, ENGINE, t, drivers, pins, sliders, positions, axes)


def _pin_keys(mech: Mechanism) -> list[tuple[str, str]]:
    return [(j, b) for j in mech.joints for b in mech.bodies_at(j) if len(mech.bodies_at(j)) >= 2]


def _driver_column(d: Any) -> str:
    return f"{d.target}.torque" if d.kind == "crank" else f"{d.target}.force"


def _add_dynamics(pm: vpin.PinocchioModel, mech: Mechanism) -> None:
    """Append every body's inertia to its joint (file length units: kg, kg·unit²) and set gravity."""
    import pinocchio as pin

    f = factor(mech)
    for name, (mass, com, inertia) in mass_table(mech).items():
        placement = pm.model.frames[pm.body_frame[name]].placement  # body frame in its joint frame
        rot = np.diag([0.0, 0.0, inertia / f**2])
        pm.model.appendBodyToJoint(pm.body_joint[name], pin.Inertia(mass, np.array([*com, 0.0]), rot), placement)
    g = mech.gravity or (0.0, 0.0)
    pm.model.gravity = pin.Motion(np.array([g[0] / f, g[1] / f, 0.0, 0.0, 0.0, 0.0]))


def _point_jacobian(pm: vpin.PinocchioModel, data: Any, body: str, p: np.ndarray) -> np.ndarray:
    """(2, nv): world velocity of the point of ``body`` at world position ``p`` per joint rate."""
    import pinocchio as pin

    jid = pm.body_joint[body]
    if jid == 0:
        return np.zeros((2, pm.nv))
    jac = pin.getJointJacobian(pm.model, data, jid, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
    r = p - data.oMi[jid].translation[:2]
    return jac[:2] + np.outer([-r[1], r[0]], jac[5])


def _world_force(data: Any, jid: int, force: np.ndarray, point: np.ndarray, torque: float = 0.0) -> Any:
    """A planar force at a world point (plus a couple) as a Pinocchio Force in joint ``jid``'s frame."""
    import pinocchio as pin

    moment = point[0] * force[1] - point[1] * force[0] + torque
    return data.oMi[jid].actInv(pin.Force(np.array([force[0], force[1], 0.0]), np.array([0.0, 0.0, moment])))


def _sample(
    pm: vpin.PinocchioModel, work: Any, q: np.ndarray, v: np.ndarray, a: np.ndarray, loads: list, f: float
) -> dict[str, Any]:
    """Multipliers and tree joint forces at one sample; results in SI."""
    import pinocchio as pin

    m, d, mech = pm.model, work.data, pm.mech
    pin.forwardKinematics(m, d, q, v, a)
    pin.computeJointJacobians(m, d, q)
    pin.updateFramePlacements(m, d)
    pos = {j: d.oMf[pm.point_frame[j]].translation[:2].copy() for j in mech.tracked_points}
    jac, applied = _constraint_rows(pm, work, pos)
    fext = [pin.Force.Zero() for _ in range(m.njoints)]
    for ld, value in loads:  # SI → file units: N → kg·unit/s², N·m → kg·unit²/s²
        jid = pm.body_joint[ld.body]
        if ld.kind == "torque":
            fext[jid] += _world_force(d, jid, np.zeros(2), np.zeros(2), value / f**2)
        else:
            fext[jid] += _world_force(d, jid, np.asarray(value) / f, pos[ld.point])
    tau = pin.rnea(m, d, q, v, a, fext).copy()
    lam = np.linalg.solve(jac.T, tau)
    for apply in applied:  # every multiplier as the external force it stands for
        apply(lam, fext)
    rest = pin.rnea(m, d, q, v, a, fext)
    if np.max(np.abs(rest), initial=0.0) > TORQUE_CHECK * max(np.max(np.abs(tau), initial=0.0), 1e-300):
        raise RuntimeError(f"{mech.name}: pinocchio: joint torques remain after applying the multipliers: {rest}")
    return _readout(pm, d, lam, pos, f)


def _constraint_rows(pm: vpin.PinocchioModel, work: Any, pos: dict[str, np.ndarray]) -> tuple[np.ndarray, list]:
    """The square constraint Jacobian (cuts, then driver rows) and, per row group, how its multiplier
    acts as external forces (functions adding them to an fext list)."""
    d, mech = work.data, pm.mech
    rows: list[np.ndarray] = []
    applied = []

    def add_force(body: str, force: np.ndarray, point: np.ndarray, fext: list, torque: float = 0.0) -> None:
        jid = pm.body_joint[body]
        if jid:
            fext[jid] += _world_force(d, jid, force, point, torque)

    for j, b1, b2 in pm.plan.cuts:
        i = len(rows)
        rows += list(_point_jacobian(pm, d, b2, pos[j]) - _point_jacobian(pm, d, b1, pos[j]))
        applied.append(
            lambda lam, fext, i=i, j=j, b1=b1, b2=b2: (
                add_force(b2, lam[i : i + 2], pos[j], fext),
                add_force(b1, -lam[i : i + 2], pos[j], fext),
            )
        )
    for row, drv in zip(pm.rows, mech.drivers, strict=True):
        i = len(rows)
        if drv.kind == "crank":
            rows.append(_angle_row(pm, d, drv.target))
            applied.append(lambda lam, fext, i=i, b=drv.target: add_force(b, np.zeros(2), np.zeros(2), fext, lam[i]))
        else:
            rows.append(work.slider_s(row, jac=True)[1])
            sl = mech.sliders[drv.target]
            u = _axis(pm, d, sl.name)
            applied.append(
                lambda lam, fext, i=i, sl=sl, u=u: (
                    add_force(sl.name, lam[i] * u, pos[sl.joint], fext),
                    add_force(sl.guide, -lam[i] * u, pos[sl.joint], fext),
                )
            )
    return np.array(rows).reshape(len(rows), pm.nv), applied


def _angle_row(pm: vpin.PinocchioModel, data: Any, body: str) -> np.ndarray:
    import pinocchio as pin

    return pin.getFrameJacobian(pm.model, data, pm.body_frame[body], pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)[5]


def _axis(pm: vpin.PinocchioModel, data: Any, slider: str) -> np.ndarray:
    """The slider's axis u in the world: the block frame's x axis."""
    return data.oMf[pm.body_frame[slider]].rotation[:2, 0].copy()


def _readout(pm: vpin.PinocchioModel, data: Any, lam: np.ndarray, pos: dict[str, np.ndarray], f: float) -> dict:
    """Net pin force on every body at every pin, slider normal force and moment, driver values [SI]."""
    mech = pm.mech
    net = {key: np.zeros(2) for key in _pin_keys(mech)}
    sliders = {}
    for child in pm.plan.order[1:]:
        parent, edge = pm.plan.parent[child]
        fw = data.oMi[pm.body_joint[child]].act(data.f[pm.body_joint[child]])  # parent on child, about O
        force, moment_o = fw.linear[:2].copy(), float(fw.angular[2])
        if edge.kind == "pin":
            net[(edge.joint, child)] += force
            net[(edge.joint, parent)] -= force
            continue
        p = pos[edge.joint]
        if child != edge.b:  # the guide hangs below its block: the guide's force on the block is the opposite
            force, moment_o = -force, -moment_o
        u = _axis(pm, data, edge.b)
        sliders[edge.b] = (
            float(force @ np.array([-u[1], u[0]])) * f,
            (moment_o - (p[0] * force[1] - p[1] * force[0])) * f * f,
        )
    i = 0
    for j, b1, b2 in pm.plan.cuts:
        net[(j, b2)] += lam[i : i + 2]
        net[(j, b1)] -= lam[i : i + 2]
        i += 2
    drivers = {}
    for drv in mech.drivers:
        drivers[_driver_column(drv)] = lam[i] * (f * f if drv.kind == "crank" else f)
        i += 1
    return {
        "drivers": drivers,
        "pins": {key: value * f for key, value in net.items()},
        "sliders": sliders,
        "positions": {j: p * f for j, p in pos.items()},
        "axes": {s: _axis(pm, data, s) for s in mech.sliders},
    }


def solve(mechanism: Mechanism, times: np.ndarray | None = None, **options: Any) -> Result:
    """Kinematics and forces in one Result (engine "pinocchio"): every P/V/A column plus the force columns."""
    kin, frc = solve_with_forces(mechanism, times, **options)
    return Result(kin.mechanism, ENGINE, kin.t, {**kin.columns, **frc.columns}, kin.health, {})


__all__ = ["ENGINE", "forces", "solve", "solve_with_forces"]
