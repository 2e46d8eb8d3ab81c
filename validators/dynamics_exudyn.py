"""Exudyn's time integration of a mechanism's forward dynamics (the file's [dynamics]), independent of vloop.

    res, estimate = simulate(mech, times)          # engine "exudyn-simulate"

The model is :func:`validators.exudyn_forces.build`'s (each body's node at its centre of mass with the file's
mass and inertia, gravity, the [[loads]]), assembled at t = 0 with the driver at its [dynamics] rate by
Exudyn's own constraint equations (:mod:`validators.exudyn`), and then the driver's constraint is switched
off: the input moves under its loads. Exudyn items for the [dynamics] loads:

* the input's torque and motor line T(t, ω) = T(t) + T0·(1 − ω/ω0): a ``LoadTorqueVector`` on the input body
  whose user function reads the body's angular velocity;
* a flywheel: added to the input body's inertia;
* a rotational spring/damper: a ``CoordinateSpringDamper`` between the two bodies' rotation coordinates
  (a ground coordinate for the ground), offset so that it acts on θ_a − θ_b − rest;
* a linear spring/damper: an ``ObjectConnectorSpringDamper`` between the two points.

Integration: Exudyn's index-3 generalized-α (ρ∞ = 0.6, fixed step h, second order), the initial
accelerations from Exudyn's own equations. The error estimate is Richardson's: the same run at h and h/2,
x(h/2) + (x(h/2) − x(h))/3 is the exact motion to O(h³) (second order).
Lengths in the file's units as :mod:`validators.exudyn_forces` uses them: forces scaled by 1/f, torques and
inertias by 1/f² (f: metres per file unit).
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from vloop.mechanism import Mechanism
from vloop.model import Dynamics
from vloop.result import Result

from . import exudyn as vexu
from . import exudyn_forces as vforces
from .forces_common import factor

ENGINE = "exudyn-simulate"
SPECTRAL_RADIUS = 0.6


def applies(mech: Mechanism) -> str:
    """Why this engine cannot simulate ``mech`` ("" if it can): a crank input started from the coordinates."""
    dyn = mech.dynamics
    if dyn is None or len(mech.drivers) != 1:
        return "needs a [dynamics] section and one input"
    if mech.drivers[0].kind != "crank":
        return "the input must be a crank"
    if dyn.position is not None or dyn.torque_profile is not None:
        return "starts from the file's coordinates with a constant or motor torque only"
    return ""


def simulate(mech: Mechanism, times: np.ndarray, step: float) -> tuple[Result, dict[str, np.ndarray]]:
    """(the run at h/2, Richardson's correction per column) of ``mech``'s forward dynamics at ``times`` [s]
    (from 0) with Exudyn steps ``step`` and ``step``/2 [s] (divisors of the rows' spacing): the exact motion is
    ≈ run + correction, with correction = (x(h/2) − x(h))/3 (second order), its error O(h³)."""
    coarse = _run(mech, times, step)
    fine = _run(mech, times, step / 2)
    return fine, {c: (fine[c] - coarse[c]) / 3.0 for c in fine.columns}


def _run(mech: Mechanism, times: np.ndarray, step: float) -> Result:
    """One generalized-α run at step h, sampled at ``times`` (their spacing a multiple of h)."""
    dyn = mech.dynamics or Dynamics()
    d = mech.drivers[0]
    rate = d.v0 if dyn.rate is None else dyn.rate
    driven = dataclasses.replace(mech, drivers=(dataclasses.replace(d, v0=rate, a0=0.0, profile=None),))
    model = vforces.build(driven)
    kin = vexu._Kinematics(model)
    start = vexu._assemble(kin, driven, 0.0, ENGINE, times)
    mbs = model.mbs
    mbs.SetObjectParameter(model.driver_objects[0], "activeConnector", False)
    _add_loads(model, dyn, factor(mech))
    sensors = vexu._start_from(model, start)
    ss = vexu._dynamic_settings(SPECTRAL_RADIUS, 1e-12 * mech.scale)
    ss.timeIntegration.generalizedAlpha.computeInitialAccelerations = True
    ss.timeIntegration.startTime = 0.0
    ss.timeIntegration.endTime = float(times[-1])
    ss.timeIntegration.numberOfSteps = round(times[-1] / step)
    ss.solution.sensors.writePeriod = float(times[1] - times[0]) if len(times) > 1 else step
    records = vexu._Records(model, sensors, 0.0)
    with vexu._Quiet():
        mbs.SolveDynamic(ss, updateInitialValues=True, showHints=False, showCausingItems=False)
    records.collect()
    return vexu._dynamic_result(driven, ENGINE, model, times, records, complete=True)


def _add_loads(model: Any, dyn: Dynamics, f: float) -> None:
    """The input's torque and motor line, a flywheel, springs and dampers, as Exudyn items (see the notes)."""
    import exudyn as exu
    from exudyn.itemInterface import LoadTorqueVector, MarkerBodyRigid

    mech, mbs = model.mechanism, model.mbs
    bm = model.moving[mech.drivers[0].target]
    if dyn.flywheel:
        inertia = mbs.GetObjectParameter(bm.obj, "physicsInertia")
        mbs.SetObjectParameter(bm.obj, "physicsInertia", inertia + dyn.flywheel / f**2)
    motor = dyn.motor

    def torque(mbs_: Any, t: float, load: Any) -> list[float]:
        value = dyn.torque
        if motor is not None:
            w = mbs_.GetNodeOutput(bm.node, exu.OutputVariableType.Coordinates_t)[2]
            value += motor[0] * (1.0 - w / motor[1])
        return [0.0, 0.0, value / f**2]

    marker = mbs.AddMarker(MarkerBodyRigid(bodyNumber=bm.obj, localPosition=[0.0, 0.0, 0.0]))
    mbs.AddLoad(LoadTorqueVector(markerNumber=marker, loadVector=[0.0, 0.0, 0.0], loadVectorUserFunction=torque))
    for s in dyn.springs:
        _spring(model, s, f)
    mbs.Assemble()


def _spring(model: Any, s: Any, f: float) -> None:
    """One spring/damper of [dynamics] as an Exudyn connector, its rest state from the file's coordinates."""
    from exudyn.itemInterface import (
        CoordinateSpringDamper,
        MarkerBodyPosition,
        MarkerNodeCoordinate,
        NodePointGround,
        ObjectConnectorSpringDamper,
    )

    mech, mbs = model.mechanism, model.mbs
    if s.kind == "rotational":
        markers, ref = [], []
        for body in (s.ends[1], s.ends[0]):  # Exudyn's force: k·(q₁ − q₀ − offset), marker 1 on body a
            if body in model.moving:
                node, ref_angle = model.moving[body].node, float(model.moving[body].ref[2])
            else:
                node, ref_angle = mbs.AddNode(NodePointGround(referenceCoordinates=[0.0, 0.0, 0.0])), 0.0
            markers.append(mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=node, coordinate=2 if body in model.moving
                                                              else 0)))  # fmt: skip
            ref.append(ref_angle)
        drawn = ref[1] - ref[0]  # θ_a − θ_b as drawn
        rest = drawn if s.rest is None else s.rest
        mbs.AddObject(CoordinateSpringDamper(markerNumbers=markers, stiffness=s.k / f**2, damping=s.c / f**2,
                                             offset=rest - drawn))  # fmt: skip
        return
    markers = []
    for p in s.ends:
        body = mech.points[p].link if p in mech.points else mech.bodies_at(p)[0]
        obj = model.moving[body].obj if body in model.moving else model.ground_object
        local = model.local_rel_com(body, model.bodies[body].local[p])
        markers.append(mbs.AddMarker(MarkerBodyPosition(bodyNumber=obj, localPosition=[*local, 0.0])))
    drawn = math.dist(*(mech.points[p].at if p in mech.points else mech.joints[p] for p in s.ends))
    mbs.AddObject(ObjectConnectorSpringDamper(markerNumbers=markers, stiffness=s.k, damping=s.c,
                                              referenceLength=drawn if s.rest is None else s.rest))  # fmt: skip
