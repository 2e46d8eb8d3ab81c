"""Exudyn's constraint forces: driver torques and every reaction, from the same file.

    kin, forces = solve_with_forces(mech, mode="kinematic")   # engine "exudyn-kinematic"
    kin, forces = solve_with_forces(mech, mode="dynamic")     # engine "exudyn-dynamic"

The Exudyn model of :mod:`validators.exudyn_model` is built with the file's masses (each body's
node at its centre of mass, its mass and inertia), and Exudyn items for the rest: gravity as a
``LoadMassProportional`` on every body, point forces as ``LoadForceVector`` at a body marker,
torques as ``LoadTorqueVector`` (tabulated loads through their user functions). Nothing of vloop's
force code is used. Exudyn's equations of motion are

    M·q̈ + C_qᵀ·λ = f(q, q̇, t)          (ODE2 coordinates: x, y, φ of every body's node)

so every constraint object's force on the bodies is −C_q[rows]ᵀ·λ[rows]: a revolute joint's x, y
components on a body are the pin force on it, a prismatic joint's are the guide's force on the
block (its component along n the normal force) and its φ component the moment about the block's
centre of mass (moved to the slider joint), a driver's the crank torque or the slider force.

``kinematic``: at every sample the positions, velocities and accelerations of Exudyn's own
constraint equations (:mod:`validators.exudyn`), then Exudyn's mass matrix M and right-hand side
f at that state and λ from the square system C_qᵀ·λ = f − M·q̈. ``dynamic``: Exudyn's
``SolveDynamic`` (generalized-α, prescribed drivers) and its Lagrange multipliers λ — its own
joint reaction forces (the revolute joints' ``Force`` output is λ in global coordinates) — read
at the sample times after each step, with the same C_q (Exudyn's exact velocity-level Jacobian).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from vloop.errors import MotionError
from vloop.forces import ForceResult
from vloop.mechanism import Mechanism
from vloop.result import Result

from . import exudyn as vexu
from . import exudyn_model as em
from .forces_common import factor, force_result, load_series, mass_table

ENGINES = vexu.ENGINES


def build(mech: Mechanism) -> em.ExudynModel:
    """The Exudyn model with the file's masses, gravity and loads (file length units throughout)."""
    from exudyn.itemInterface import (
        LoadForceVector,
        LoadMassProportional,
        LoadTorqueVector,
        MarkerBodyMass,
        MarkerBodyPosition,
        MarkerBodyRigid,
    )

    f = factor(mech)
    masses = {b: (m, com, inertia / f**2) for b, (m, com, inertia) in mass_table(mech).items()}
    model = em.build(mech, masses=masses)
    mbs = model.mbs
    if mech.gravity is not None:
        g = [mech.gravity[0] / f, mech.gravity[1] / f, 0.0]
        for name in masses:
            marker = mbs.AddMarker(MarkerBodyMass(bodyNumber=model.moving[name].obj))
            mbs.AddLoad(LoadMassProportional(markerNumber=marker, loadVector=g))
    for ld in mech.loads:
        obj = model.moving[ld.body].obj
        if ld.kind == "force":
            local = model.local_rel_com(ld.body, model.bodies[ld.body].local[ld.point])
            marker = mbs.AddMarker(MarkerBodyPosition(bodyNumber=obj, localPosition=[*local, 0.0]))
            kw = {"loadVectorUserFunction": _force_function(ld, f)} if ld.profile is not None else {}
            value = [0.0, 0.0] if ld.value is None else [v / f for v in ld.value]  # type: ignore[union-attr]
            mbs.AddLoad(LoadForceVector(markerNumber=marker, loadVector=[*value, 0.0], **kw))
        else:
            marker = mbs.AddMarker(MarkerBodyRigid(bodyNumber=obj, localPosition=[0.0, 0.0, 0.0]))
            kw = {"loadVectorUserFunction": _torque_function(ld, f)} if ld.profile is not None else {}
            value = 0.0 if ld.value is None else ld.value / f**2  # type: ignore[operator]
            mbs.AddLoad(LoadTorqueVector(markerNumber=marker, loadVector=[0.0, 0.0, value], **kw))
    mbs.Assemble()
    return model


def _force_function(load: Any, f: float) -> Any:
    def uf(mbs: Any, t: float, value: Any) -> list[float]:
        fx, fy = load_series(load, np.array([t]))[0]
        return [fx / f, fy / f, 0.0]

    return uf


def _torque_function(load: Any, f: float) -> Any:
    def uf(mbs: Any, t: float, value: Any) -> list[float]:
        return [0.0, 0.0, float(load_series(load, np.array([t]))[0]) / f**2]

    return uf


# ---------------------------------------------------------------- constraint objects → reactions


def constraint_objects(model: em.ExudynModel) -> list[tuple[str, Any, int]]:
    """(kind, what, object) of every constraint, in the order exudyn_model.build adds them:
    ("pin", (joint, first body, other body), obj), ("slider", name, obj), ("driver", Driver, obj)."""
    mech, mbs = model.mechanism, model.mbs
    pins = [
        (j, mech.bodies_at(j)[0], b) for j in mech.joints if len(mech.bodies_at(j)) >= 2 for b in mech.bodies_at(j)[1:]
    ]
    sliders = list(mech.sliders)
    found: dict[str, list[int]] = {"ObjectJointRevolute2D": [], "ObjectJointPrismatic2D": []}
    for i in range(mbs.systemData.NumberOfObjects()):
        kind = mbs.GetObject(i)["objectType"]
        key = f"Object{kind}" if not kind.startswith("Object") else kind
        if key in found:
            found[key].append(i)
    if len(found["ObjectJointRevolute2D"]) != len(pins) or len(found["ObjectJointPrismatic2D"]) != len(sliders):
        raise RuntimeError(f"{mech.name}: exudyn model has an unexpected set of joints")
    out = [("pin", p, o) for p, o in zip(pins, found["ObjectJointRevolute2D"], strict=True)]
    out += [("slider", s, o) for s, o in zip(sliders, found["ObjectJointPrismatic2D"], strict=True)]
    out += [("driver", d, o) for d, o in zip(mech.drivers, model.driver_objects, strict=True)]
    return out


def _body_point(model: em.ExudynModel, q: np.ndarray, body: str, local: Any) -> np.ndarray:
    """World position of a body-frame point at coordinates q (displacements from the reference)."""
    if body not in model.moving:
        return np.asarray(local, float)
    bm = model.moving[body]
    x, y, th = q[bm.ode2] + bm.ref
    return np.array([x, y]) + em.rot(th) @ model.local_rel_com(body, local)


def reactions(model: em.ExudynModel, q: np.ndarray, jac: np.ndarray, lam: np.ndarray, f: float) -> dict[str, Any]:
    """One sample's reactions [SI] from Exudyn's multipliers λ (convention M·q̈ + C_qᵀ·λ = f)."""
    mech, sd = model.mechanism, model.mbs.systemData
    net = {(j, b): np.zeros(2) for j in mech.joints for b in mech.bodies_at(j) if len(mech.bodies_at(j)) >= 2}
    sliders, drivers = {}, {}
    for kind, what, obj in constraint_objects(model):
        rows = list(sd.GetObjectLTGAE(obj))
        gen = -jac[rows].T @ lam[rows]  # generalized force of this constraint on every coordinate

        def on(body: str, gen: np.ndarray = gen) -> np.ndarray:
            return gen[model.moving[body].ode2] if body in model.moving else np.zeros(3)

        if kind == "pin":
            j, first, other = what
            force = on(other)[:2] if other in model.moving else -on(first)[:2]
            net[(j, other)] += force
            net[(j, first)] -= force
        elif kind == "slider":
            g = on(what)
            u = _axis(model, q, what)
            p = _body_point(model, q, what, (0.0, 0.0))  # the block frame's origin is the slider joint
            c = _body_point(model, q, what, model.moving[what].com)
            moment_p = g[2] - ((p - c)[0] * g[1] - (p - c)[1] * g[0])
            sliders[what] = (float(g[:2] @ np.array([-u[1], u[0]])) * f, moment_p * f * f)
        elif what.kind == "crank":
            drivers[f"{what.target}.torque"] = on(what.target)[2] * f * f
        else:
            drivers[f"{what.target}.force"] = float(on(what.target)[:2] @ _axis(model, q, what.target)) * f
    frames = model.bodies
    positions = {}
    for j in mech.tracked_points:
        b = mech.body_of_point(j)
        positions[j] = _body_point(model, q, b, frames[b].local[j]) * f
    return {
        "drivers": drivers,
        "pins": {k: v * f for k, v in net.items()},
        "sliders": sliders,
        "positions": positions,
        "axes": {s: _axis(model, q, s) for s in mech.sliders},
    }


def _axis(model: em.ExudynModel, q: np.ndarray, block: str) -> np.ndarray:
    """A slider's axis u: the block node's angle is the axis direction."""
    bm = model.moving[block]
    th = q[bm.ode2[2]] + bm.ref[2]
    return np.array([math.cos(th), math.sin(th)])


def _collect(mech: Mechanism, engine: str, t: np.ndarray, samples: list[dict[str, Any]]) -> ForceResult:
    n = len(samples)

    def series(key: str, name: Any, width: int) -> np.ndarray:
        return np.array([s[key][name] for s in samples], float).reshape(n, width)

    drivers = {
        (f"{d.target}.torque" if d.kind == "crank" else f"{d.target}.force"): (
            np.array([s["drivers"][f"{d.target}.{'torque' if d.kind == 'crank' else 'force'}"] for s in samples])
        )
        for d in mech.drivers
    }
    pins = {k: series("pins", k, 2) for k in (samples[0]["pins"] if n else ())}
    if not n:
        pins = {(j, b): np.zeros((0, 2)) for j in mech.joints for b in mech.bodies_at(j)}
    sliders = {
        s: (np.array([x["sliders"][s][0] for x in samples]), np.array([x["sliders"][s][1] for x in samples]))
        for s in mech.sliders
    }
    positions = {j: series("positions", j, 2) for j in mech.tracked_points}
    axes = {s: series("axes", s, 2) for s in mech.sliders}
    return force_result(mech, engine, t[:n], drivers, pins, sliders, positions, axes)


# ---------------------------------------------------------------- kinematic mode


def _kinematic_sample(kin: Any, st: Any, f: float) -> dict[str, Any]:
    """λ from Exudyn's mass matrix and right-hand side at a solved state (q, q̇, q̈, t)."""
    eq = kin.eq
    jac, _ = eq.velocity_jacobian(st.q, st.t)
    eq._set(st.q, st.qd, st.t)
    eq.solver.ComputeMassMatrix(eq.mbs)
    mass = np.array(eq.solver.GetSystemMassMatrix())
    eq.solver.ComputeODE2RHS(eq.mbs)
    rhs = np.array(eq.solver.GetSystemResidual()[: eq.n])
    lam = np.linalg.solve(jac.T, rhs - mass @ st.qdd)  # M q̈ + C_qᵀ λ = f
    return reactions(kin.model, st.q, jac, lam, f)


def _solve_kinematic(mech: Mechanism, times: np.ndarray, tol: float = 1e-12) -> tuple[Result, ForceResult]:
    engine = ENGINES["kinematic"]
    model = build(mech)
    kin = vexu._Kinematics(model, tol=tol)
    for inp in model.driver_inputs:
        inp.prefetch(times)
    state = vexu._assemble(kin, mech, vexu._assembly_time(mech), engine, times)
    f = factor(mech)
    n = kin.n
    Q, QD, QDD = (np.zeros((len(times), n)) for _ in range(3))
    samples: list[dict[str, Any]] = []
    for k, t in enumerate(times):
        nxt = state if abs(t - state.t) <= 1e-14 * max(1.0, abs(t)) else kin.advance(state, float(t), 14)
        if nxt is None:
            part = vexu._result(mech, engine, model, times[:k], Q[:k], QD[:k], QDD[:k])
            raise MotionError(
                f"{mech.name}: {engine}: cannot assemble sample {k} at t = {t:.6g} s",
                time=float(t),
                sample=k,
                partial=(part, _collect(mech, engine, times, samples)),
            )
        state = nxt
        Q[k], QD[k], QDD[k] = state.q, state.qd, state.qdd
        samples.append(_kinematic_sample(kin, state, f))
    return vexu._result(mech, engine, model, times, Q, QD, QDD), _collect(mech, engine, times, samples)


# ---------------------------------------------------------------- dynamic mode


def _solve_dynamic(
    mech: Mechanism, times: np.ndarray, accuracy: float = vexu.DEFAULT_ACCURACY
) -> tuple[Result, ForceResult]:
    """SolveDynamic on the force model; λ, q, q̇, q̈ recorded after each step that ends on a sample."""
    import exudyn as exu

    engine = ENGINES["dynamic"]
    t_asm = vexu._assembly_time(mech)
    base = vexu._commensurate(times, t_asm)
    if base is None or times[0] < t_asm:
        raise ValueError(f"{mech.name}: {engine} forces need samples on a regular grid from t = {t_asm:g} s")
    model = build(mech)
    kin = vexu._Kinematics(model)
    start = vexu._assemble(kin, mech, t_asm, engine, times)
    try:
        kin_res, _ = _solve_kinematic(mech, times)  # for the step size (rates) only
    except MotionError as exc:  # a run to a limit position: the rates up to it
        kin_res = exc.partial[0]
    rate = max(
        [1.0]
        + [float(np.max(np.abs(kin_res[f"{b}.omega"]), initial=0.0)) for b in mech.moving_links]
        + [float(np.max(np.sqrt(np.abs(kin_res[f"{b}.alpha"])), initial=0.0)) for b in mech.moving_links]
    )
    h = vexu.dynamic_step(mech, times, accuracy, rate=rate)
    m = max(1, math.ceil(base / h - 1e-9))
    later = times[times > t_asm + 0.5 * base]
    if later.size:
        m = max(m, math.ceil(vexu.MIN_STEPS_TO_SAMPLE / round((later[0] - t_asm) / base)))
    n_steps = round((times[-1] - t_asm) / base) * m
    mbs, sd = model.mbs, model.mbs.systemData
    for bm in model.moving.values():
        mbs.SetNodeParameter(bm.node, "initialCoordinates", start.q[bm.ode2].tolist())
        mbs.SetNodeParameter(bm.node, "initialVelocities", start.qd[bm.ode2].tolist())
    record: dict[float, tuple[np.ndarray, ...]] = {}
    wanted = {round((tk - t_asm) / base) for tk in times}

    pins = [obj for kind, _, obj in constraint_objects(model) if kind == "pin"]

    def post_step(mbs_: Any, t: float) -> bool:
        k = round((t - t_asm) / base)
        if k in wanted and abs(t - (t_asm + k * base)) <= 1e-9 * base:
            state = (sd.GetODE2Coordinates(), sd.GetODE2Coordinates_t(), sd.GetODE2Coordinates_tt())
            lam = np.array(sd.GetAECoordinates())
            # the revolute joints' own reaction output is their multiplier in global coordinates
            out = np.concatenate([np.asarray(mbs.GetObjectOutput(o, exu.OutputVariableType.Force))[:2] for o in pins])
            mine = np.concatenate([lam[list(sd.GetObjectLTGAE(o))] for o in pins]) if pins else out
            if not np.allclose(out, mine, rtol=1e-12, atol=1e-12 * max(np.max(np.abs(lam), initial=0.0), 1e-300)):
                raise RuntimeError(f"{mech.name}: Exudyn's joint Force output differs from its multipliers")
            record[k] = (*(np.array(a) for a in state), lam)
        return True

    mbs.SetPostStepUserFunction(post_step)
    mbs.Assemble()
    sd.SetODE2Coordinates_tt(start.qdd.tolist(), configuration=exu.ConfigurationType.Initial)
    for inp in model.driver_inputs:
        inp.prefetch(np.linspace(t_asm, times[-1], n_steps + 1))
    ss = _dynamic_settings(mech, t_asm, float(times[-1]), n_steps)
    try:
        with vexu._Quiet():
            mbs.SolveDynamic(ss, updateInitialValues=True, showHints=False, showCausingItems=False)
    except Exception as exc:  # Exudyn's SolverError: keep the samples reached before it
        done = 0
        while done < len(times) and (round((times[done] - t_asm) / base) in record or times[done] == t_asm):
            done += 1
        part = _dynamic_results(mech, engine, model, kin, times[:done], t_asm, base, start, record)
        reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise MotionError(
            f"{mech.name}: {engine}: Exudyn's time integration failed before sample {done}: {reason}",
            sample=done,
            partial=part,
        ) from None
    return _dynamic_results(mech, engine, model, kin, times, t_asm, base, start, record)


def _dynamic_settings(mech: Mechanism, t0: float, t1: float, n_steps: int) -> Any:
    ss = vexu._settings()
    ti = ss.timeIntegration
    ti.generalizedAlpha.spectralRadius = vexu.SPECTRAL_RADIUS
    ti.generalizedAlpha.useIndex2Constraints = False
    ti.generalizedAlpha.useNewmark = False
    ti.generalizedAlpha.computeInitialAccelerations = False
    ti.newton.residualMode = 1
    ti.newton.relativeTolerance = 1e-10 * mech.scale
    ti.newton.absoluteTolerance = 1e-10 * mech.scale
    ti.newton.useModifiedNewton = False
    ti.adaptiveStep = False
    ti.automaticStepSize = False
    ti.startTime, ti.endTime, ti.numberOfSteps = t0, t1, n_steps
    return ss


def _dynamic_results(
    mech: Mechanism,
    engine: str,
    model: em.ExudynModel,
    kin: Any,
    times: np.ndarray,
    t_asm: float,
    base: float,
    start: Any,
    record: dict,
) -> tuple[Result, ForceResult]:
    f = factor(mech)
    n = kin.n
    Q, QD, QDD = (np.zeros((len(times), n)) for _ in range(3))
    samples = []
    for i, tk in enumerate(times):
        k = round((tk - t_asm) / base)
        if k == 0:  # the assembly itself: no step has ended there; λ from the kinematic state
            q, qd, qdd = start.q, start.qd, start.qdd
            samples.append(_kinematic_sample(kin, start, f))
        else:
            q, qd, qdd, lam = record[k]
            jac, _ = kin.eq.velocity_jacobian(q, float(tk))
            samples.append(reactions(model, q, jac, lam, f))
        Q[i], QD[i], QDD[i] = q, qd, qdd
    return vexu._result(mech, engine, model, times, Q, QD, QDD), _collect(mech, engine, times, samples)


def solve_with_forces(
    mechanism: Mechanism, times: np.ndarray | None = None, mode: str = "kinematic", **options: Any
) -> tuple[Result, ForceResult]:
    """Kinematics and forces [N, N·m] of ``mechanism`` over ``times`` [s] with Exudyn (``mode``:
    "kinematic" or "dynamic"). Raises MotionError (``.partial`` = (kinematics, forces)) on failure."""
    t = np.asarray(mechanism.times if times is None else times, float)
    if mode == "kinematic":
        return _solve_kinematic(mechanism, t, **options)
    if mode == "dynamic":
        return _solve_dynamic(mechanism, t, **options)
    raise ValueError(f"mode must be 'kinematic' or 'dynamic', got {mode!r}")


def solve(mechanism: Mechanism, times: np.ndarray | None = None, mode: str = "kinematic", **options: Any) -> Result:
    """Kinematics and forces in one Result (engine "exudyn-kinematic" / "exudyn-dynamic")."""
    kin, frc = solve_with_forces(mechanism, times, mode, **options)
    return Result(kin.mechanism, kin.engine, kin.t, {**kin.columns, **frc.columns}, kin.health, {})
