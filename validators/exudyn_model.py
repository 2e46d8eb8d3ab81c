"""Build an Exudyn multibody system from a vloop :class:`~vloop.mechanism.Mechanism`.

This module only *describes* the mechanism to Exudyn; the numerics (kinematic
Newton on Exudyn's constraint residuals, or Exudyn's own time integration) live
in :mod:`validators.exudyn`. Nothing here uses vloop's loop equations.

Model (one Exudyn item per physical part, no per-mechanism code):

* every moving link and every slider block is a 2D rigid body
  (``NodeRigidBody2D`` + ``ObjectRigidBody2D``). The node sits at the body's
  centre of mass and its rotation coordinate is the body's θ (reference angle =
  ``Body.theta0``), so the node angle *is* the output θ, unwrapped;
* a pin joining k + 1 bodies becomes k ``ObjectJointRevolute2D`` (each between
  the first naming body and one of the others), with position markers;
* a slider is an ``ObjectJointPrismatic2D`` between a rigid marker on its guide
  (on the sliding line, axis in the guide frame) and a rigid marker at the
  block's joint (normal = block y axis; the block frame's x axis is the slider
  axis), so the block slides along the guide and does not turn relative to it;
* a crank driver is a ``CoordinateConstraint`` between a ground coordinate and
  the link node's rotation coordinate with ``offsetUserFunction`` =
  θ(t) − θ_ref and ``offsetUserFunction_t`` = ω(t) (the coordinate is the
  rotation *without* its reference angle);
* a driven slider is a ``CoordinateConstraint`` between a ground coordinate and
  a ``MarkerBodiesRelativeTranslationCoordinate`` that measures
  s = (P_joint − O_guide)·u(t) (guide origin and axis fixed to the guide body);
  its offset user functions give s(t), ṡ(t).

Mass and inertia (they do not change prescribed kinematics; they condition the
dynamic run): a link is a frame of uniform slender rods along the outline
(convex hull) of its joints, tracer points and guided sliding-line points, with
mass per unit length 1 [mass/length unit] and a rod width of 2 % of the
mechanism size (so a rod has I = m (L² + w²)/12 about its centre); a block is a
square of side 10 % of the mechanism size with mass = side · 1, I = m b²/6,
centred on its joint.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vloop.drivers import evaluate
from vloop.mechanism import Body, Driver, Mechanism

ROD_WIDTH = 0.02  # rod width relative to the mechanism size (inertia regularisation)
BLOCK_SIZE = 0.10  # block side relative to the mechanism size
LINEAR_DENSITY = 1.0  # mass per unit length of link rods and blocks


# ---------------------------------------------------------------- driver input functions


class DriverInput:
    """x(t), ẋ(t), ẍ(t) of one driver, evaluated with :func:`vloop.drivers.evaluate` and cached by time.

    Exudyn calls the offset user functions many times per step at the same
    times; :meth:`prefetch` evaluates a whole grid at once (vectorised).
    """

    def __init__(self, driver: Driver) -> None:
        self.driver = driver
        self.shift = 0.0  # Exudyn's clock is t − shift (a time integration that starts before t = 0)
        self.offset0 = 0.0  # subtracted from x(t) in the constraint's offset (a crank's reference angle)
        self._cache: dict[float, tuple[float, float, float]] = {}

    def prefetch(self, t: np.ndarray) -> None:
        t = np.asarray(t, float)
        if t.size == 0:
            return
        x, v, a = evaluate(self.driver, t)
        self._cache.update(zip(t.tolist(), zip(x.tolist(), v.tolist(), a.tolist(), strict=True), strict=True))

    def __call__(self, t: float) -> tuple[float, float, float]:
        t = float(t) + self.shift
        hit = self._cache.get(t)
        if hit is None:
            if self.driver.profile is None:  # closed form: no need to cache
                d = self.driver
                return d.x0 + d.v0 * t + 0.5 * d.a0 * t * t, d.v0 + d.a0 * t, d.a0
            x, v, a = evaluate(self.driver, np.array([t]))
            hit = (float(x[0]), float(v[0]), float(a[0]))
            if len(self._cache) > 1_000_000:
                self._cache.clear()
            self._cache[t] = hit
        return hit


# ---------------------------------------------------------------- mass properties


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull vertices (CCW, monotone chain); collinear input gives its two extremes."""
    pts = np.unique(np.round(points, 15), axis=0)
    if len(pts) <= 2:
        return pts
    order = np.lexsort((pts[:, 1], pts[:, 0]))
    pts = pts[order]

    def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

    lower: list[np.ndarray] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    upper: list[np.ndarray] = []
    for p in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    hull = np.array(lower[:-1] + upper[:-1])
    return hull


def rod_frame_mass(points: np.ndarray, size: float) -> tuple[float, np.ndarray, float]:
    """Mass, centre of mass (body frame) and inertia about it of a frame of rods along the outline.

    ``points``: (n, 2) body-frame coordinates; ``size``: mechanism length scale.
    """
    width = ROD_WIDTH * size
    hull = _hull(np.asarray(points, float))
    if len(hull) == 1:  # a single point: a short rod along the body x axis
        c = hull[0]
        half = np.array([0.05 * size, 0.0])
        hull = np.array([c - half, c + half])
    edges = [(hull[0], hull[1])] if len(hull) == 2 else [(hull[i], hull[(i + 1) % len(hull)]) for i in range(len(hull))]
    m_tot, first, second = 0.0, np.zeros(2), 0.0
    for a, b in edges:
        length = float(np.hypot(*(b - a)))
        m = LINEAR_DENSITY * max(length, 1e-12 * size)
        mid = 0.5 * (a + b)
        m_tot += m
        first += m * mid
        second += m * (length**2 + width**2) / 12.0 + m * float(mid @ mid)
    com = first / m_tot
    inertia = second - m_tot * float(com @ com)
    return m_tot, com, inertia


# ---------------------------------------------------------------- the model


@dataclass
class BodyModel:
    """One moving body in Exudyn: its node, object and where its frame sits."""

    name: str
    node: int
    obj: int
    com: np.ndarray  # centre of mass in the body frame [length]
    ref: np.ndarray  # node reference coordinates (x, y, φ) in world [length, length, rad]
    ode2: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # global ODE2 indices (x, y, φ)


@dataclass
class ExudynModel:
    """The Exudyn system of one mechanism and the maps back to vloop names."""

    mechanism: Mechanism
    SC: Any
    mbs: Any
    bodies: dict[str, Body]
    moving: dict[str, BodyModel]
    ground_object: int
    driver_inputs: list[DriverInput]
    driver_objects: list[int]
    driver_rows: list[int] = field(default_factory=list)  # AE index of each driver constraint
    n_ode2: int = 0
    n_ae: int = 0
    # a driven slider on a moving guide: Exudyn's position Jacobian of its relative-translation marker
    # leaves out the guide's rotation, so ∂ċ/∂q̇ must be taken from the velocity-level residual itself
    simplified_jacobian: bool = False

    def local_rel_com(self, body: str, xy: tuple[float, float] | np.ndarray) -> np.ndarray:
        """Body-frame point relative to the body's centre of mass (ground: world coordinates)."""
        if body not in self.moving:
            return np.asarray(xy, float)
        return np.asarray(xy, float) - self.moving[body].com

    def reference_vector(self) -> np.ndarray:
        """Reference (t = 0 file) coordinates of all ODE2 coordinates, in ODE2 order."""
        ref = np.zeros(self.n_ode2)
        for bm in self.moving.values():
            ref[bm.ode2] = bm.ref
        return ref


def rot(th: float) -> np.ndarray:
    """2D rotation matrix R(θ) [θ in rad]."""
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s], [s, c]])


def _to_body(body: Body, world_xy: tuple[float, float]) -> np.ndarray:
    """World point at t = 0 in the body frame."""
    d = np.asarray(world_xy, float) - np.asarray(body.origin, float)
    return rot(body.theta0).T @ d


def build(mech: Mechanism, masses: dict[str, tuple[float, np.ndarray, float]] | None = None) -> ExudynModel:
    """Create and assemble the Exudyn system of ``mech`` (positions = file coordinates, all at rest).

    ``masses``: body → (mass, centre of mass in the body frame, inertia about it), in the file's
    units; when given it replaces the rod-frame masses below, and a body it omits is massless.
    """
    import exudyn as exu
    from exudyn.itemInterface import (
        CoordinateConstraint,
        MarkerBodiesRelativeTranslationCoordinate,
        MarkerBodyPosition,
        MarkerBodyRigid,
        MarkerNodeCoordinate,
        NodePointGround,
        NodeRigidBody2D,
        ObjectGround,
        ObjectJointPrismatic2D,
        ObjectJointRevolute2D,
        ObjectRigidBody2D,
    )

    bodies = mech.bodies()
    size = mech.scale
    SC = exu.SystemContainer()
    mbs = SC.AddSystem()
    ground_obj = int(mbs.AddObject(ObjectGround(referencePosition=[0.0, 0.0, 0.0])))

    # sliding-line points carried by each guide (body frame), for the mass outline
    line_points: dict[str, list[np.ndarray]] = {}
    for sl in mech.sliders.values():
        line_points.setdefault(sl.guide, []).append(_to_body(bodies[sl.guide], mech.joints[sl.joint]))

    moving: dict[str, BodyModel] = {}
    for name in mech.moving_links:
        b = bodies[name]
        if masses is not None:
            mass, com, inertia = masses.get(name, (0.0, np.zeros(2), 0.0))
            com = np.asarray(com, float)
        elif b.kind == "block":
            mass = LINEAR_DENSITY * BLOCK_SIZE * size
            com = np.zeros(2)
            inertia = mass * (BLOCK_SIZE * size) ** 2 / 6.0
        else:
            pts = np.array([*b.local.values(), *line_points.get(name, [])], float)
            mass, com, inertia = rod_frame_mass(pts, size)
        pos = np.asarray(b.origin, float) + rot(b.theta0) @ com
        ref = np.array([pos[0], pos[1], b.theta0])
        node = int(mbs.AddNode(NodeRigidBody2D(referenceCoordinates=ref.tolist())))
        obj = int(mbs.AddObject(ObjectRigidBody2D(nodeNumber=node, mass=mass, inertia=inertia)))
        moving[name] = BodyModel(name, node, obj, com, ref)

    model = ExudynModel(mech, SC, mbs, bodies, moving, ground_obj, [], [])

    def obj_of(body: str) -> int:
        return moving[body].obj if body in moving else ground_obj

    def p3(v: np.ndarray) -> list[float]:
        return [float(v[0]), float(v[1]), 0.0]

    # pins: a joint named by k + 1 bodies gives k revolute joints
    for j in mech.joints:
        names = mech.bodies_at(j)
        if len(names) < 2:
            continue
        markers = [
            int(
                mbs.AddMarker(
                    MarkerBodyPosition(
                        bodyNumber=obj_of(n), localPosition=p3(model.local_rel_com(n, bodies[n].local[j]))
                    )
                )
            )
            for n in names
        ]
        for m in markers[1:]:
            mbs.AddObject(ObjectJointRevolute2D(markerNumbers=[markers[0], m]))

    # sliders: prismatic joint guide -> block
    for sl in mech.sliders.values():
        g = bodies[sl.guide]
        on_line = _to_body(g, mech.joints[sl.joint])
        axis = rot(g.theta0).T @ np.asarray(sl.axis, float)
        m_guide = int(
            mbs.AddMarker(
                MarkerBodyRigid(bodyNumber=obj_of(sl.guide), localPosition=p3(model.local_rel_com(sl.guide, on_line)))
            )
        )
        at_joint = p3(model.local_rel_com(sl.name, (0.0, 0.0)))  # the block frame's origin is its joint
        m_block = int(mbs.AddMarker(MarkerBodyRigid(bodyNumber=moving[sl.name].obj, localPosition=at_joint)))
        mbs.AddObject(
            ObjectJointPrismatic2D(
                markerNumbers=[m_guide, m_block],
                axisMarker0=p3(axis),
                normalMarker1=[0.0, 1.0, 0.0],
                constrainRotation=True,
            )
        )

    # drivers
    ground_node = int(mbs.AddNode(NodePointGround(referenceCoordinates=[0.0, 0.0, 0.0])))
    m_ground_coord = int(mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=ground_node, coordinate=0)))
    for drv in mech.drivers:
        inp = DriverInput(drv)
        if drv.kind == "crank":
            bm = moving[drv.target]
            marker = int(mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=bm.node, coordinate=2)))
            offset0 = float(bm.ref[2])  # the coordinate is the rotation without its reference angle
        else:
            sl = mech.sliders[drv.target]
            g = bodies[sl.guide]
            axis = rot(g.theta0).T @ np.asarray(sl.axis, float)  # axis in the guide frame
            origin = np.zeros(2)  # O_guide: the world origin (ground) or the guide's first joint = its frame origin
            marker = int(
                mbs.AddMarker(
                    MarkerBodiesRelativeTranslationCoordinate(
                        bodyNumbers=[obj_of(sl.guide), moving[sl.name].obj],
                        localPosition0=p3(model.local_rel_com(sl.guide, origin)),
                        localPosition1=p3(model.local_rel_com(sl.name, (0.0, 0.0))),
                        axis0=p3(axis),
                        offset=0.0,
                    )
                )
            )
            offset0 = 0.0  # the marker measures the geometric s itself
            model.simplified_jacobian |= sl.guide in moving
        inp.offset0 = offset0
        uf, uf_t = _offset_functions(inp)
        obj = int(
            mbs.AddObject(
                CoordinateConstraint(
                    markerNumbers=[m_ground_coord, marker],
                    offsetUserFunction=uf,
                    offsetUserFunction_t=uf_t,
                )
            )
        )
        model.driver_inputs.append(inp)
        model.driver_objects.append(obj)

    mbs.Assemble()
    sd = mbs.systemData
    model.n_ode2 = int(sd.ODE2Size())
    model.n_ae = int(sd.AEsize())
    for bm in moving.values():
        bm.ode2 = np.asarray(sd.GetNodeLTGODE2(bm.node), int)
    model.driver_rows = [int(sd.GetObjectLTGAE(o)[0]) for o in model.driver_objects]
    return model


OFFSET_FUNCTIONS = ("offsetUserFunction", "offsetUserFunction_t")


@contextmanager
def formula_offsets(model: ExudynModel) -> Iterator[None]:
    """For the block: every driver whose input is a formula (x₀ + v₀t + a₀t²/2, no profile) gets offset functions
    that Exudyn evaluates itself (its symbolic user functions, the same expression as
    :meth:`DriverInput.__call__`) on the clock shifted by each input's current ``shift``; after it, none.

    Exudyn calls an offset function about eight times a step; from Python that is a quarter of a small
    linkage's step (measured: a four-bar's 7,812 steps in 0.19 s with the callbacks, 0.14 s without). A
    profile's input stays a Python function. The functions and the system refer to each other, so neither
    would ever be freed (measured: 130 kB a run, 1.2 GB in a worker over 10,000 mechanisms): they are
    taken off the objects when the block ends."""
    from exudyn.advancedUtilities import CreateSymbolicUserFunction

    kept, given = [], []
    try:
        for inp, obj in zip(model.driver_inputs, model.driver_objects, strict=True):
            d = inp.driver
            if d.profile is not None:
                continue
            offsets = _formula(float(d.x0), float(d.v0), float(d.a0), float(inp.shift), float(inp.offset0))
            given.append(obj)
            for name, fn in zip(OFFSET_FUNCTIONS, offsets, strict=True):
                uf = CreateSymbolicUserFunction(model.mbs, fn, name, itemIndex=_object_index(obj))
                model.mbs.SetObjectParameter(obj, name, uf)
                kept.append(uf)
        yield
    finally:
        for obj in given:
            for name in OFFSET_FUNCTIONS:
                model.mbs.SetObjectParameter(obj, name, 0)


def _formula(x0: float, v0: float, a0: float, shift: float, off: float) -> tuple[Callable[..., Any], ...]:
    """x(t + shift) − off and ẋ(t + shift) of x = x₀ + v₀t + a₀t²/2, as offset user functions (Exudyn traces
    them once with its symbolic numbers, then evaluates the expression itself)."""

    def offset(mbs: Any, t: Any, itemNumber: Any, lOffset: Any) -> Any:
        tt = t + shift
        return x0 + v0 * tt + 0.5 * a0 * tt * tt - off

    def offset_t(mbs: Any, t: Any, itemNumber: Any, lOffset: Any) -> Any:
        return v0 + a0 * (t + shift)

    return offset, offset_t


def _object_index(obj: int) -> Any:
    import exudyn as exu

    return exu.ObjectIndex(obj)


def _offset_functions(inp: DriverInput) -> tuple[Callable[..., float], Callable[..., float]]:
    def uf(mbs: Any, t: float, item: int, off: float) -> float:
        return inp(t)[0] - inp.offset0

    def uf_t(mbs: Any, t: float, item: int, off: float) -> float:
        return inp(t)[1]

    return uf, uf_t
