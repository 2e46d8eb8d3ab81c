"""Independent Pinocchio engine: the mechanism as a kinematic tree with its loops cut.

Engine name ``"pinocchio"``. It reads only the mechanism description
(:meth:`vloop.mechanism.Mechanism.bodies`: body frames and local joint/point
coordinates) and the driver inputs (:func:`vloop.drivers.evaluate_all`); it never
uses vloop's loop equations or solver, so agreement with vloop is evidence.

Model (built automatically for any mechanism, see :func:`plan_tree`):

* every body (moving link, slider block, and the ground unless it is the root)
  hangs on one Pinocchio joint: ``JointModelRZ`` about a pin, ``JointModelPX``
  along a slider axis (the block slides along its guide without turning; an
  inverse slider simply has a moving guide);
* the spanning tree keeps every slider pair (slider pairs alone never close a
  loop: a block has one guide and a guide is never a block) and as many pins as
  it can; each remaining pin is cut and closed with
  ``pin.PointAnchorConstraintModel`` (a pin of order k joins k + 1 bodies, so it
  needs k point equalities: tree pins at that joint plus cut anchors make a
  spanning tree of those bodies);
* the tree root is a parameter: the ground (fixed base) by default, or any other
  body on a planar base chain (PX, PY, RZ) with the ground pinned to the world by
  three frame equations.

Solve, per sample (sequential, warm-started from the previous sample by a Taylor
predictor; intervals where a driver moves more than MAX_CRANK_STEP / MAX_SLIDER_STEP are
split, and an interval that fails is bisected, so the branch is the one of the t = 0
assembly; a sign change of det J — a limit or toggle position — stops the run):

* positions: Newton on [cut residuals (x, y rows; the z rows are identically 0),
  ground anchor, driver equations] with Pinocchio's residuals and Jacobians,
  Armijo backtracking, stopped on the size of the Newton step;
* velocities: ``J·v = [0; ẋ_d]``;
* accelerations: ``J·a = [0; ẍ_d] − J̇·v`` where ``J̇·v`` is Pinocchio's constraint
  acceleration error (and frame classical accelerations) at zero joint acceleration.

Units: the file's lengths, radians, seconds.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vloop.drivers import evaluate_all
from vloop.errors import MechanismError, MotionError
from vloop.mechanism import Body, Mechanism
from vloop.result import Result

from .tolerances import condition_numbers

ENGINE = "pinocchio"
TWO_PI = 2.0 * math.pi


def _wrap(a: float | np.ndarray) -> Any:
    """Angle difference mapped to [−π, π)."""
    return (a + math.pi) % TWO_PI - math.pi


# ---------------------------------------------------------------- tree plan (pure Python)


@dataclass(frozen=True)
class Edge:
    """A pair between two bodies: a pin at ``joint`` or a slider (block ``b`` on guide ``a``)."""

    kind: str  # "pin" | "slider"
    a: str
    b: str
    joint: str


@dataclass(frozen=True)
class TreePlan:
    """Spanning tree of the bodies and the cut pins that close its loops.

    ``order``: bodies from the root outward (root first); ``parent[b] = (p, edge)``
    for every other body; ``cuts``: (joint, body1, body2) point equalities.
    ``floating``: the root is not the ground (planar base chain + ground anchor).
    """

    root: str
    order: tuple[str, ...]
    parent: dict[str, tuple[str, Edge]]
    cuts: tuple[tuple[str, str, str], ...]
    floating: bool


class _UnionFind:
    def __init__(self, items: Iterable[str]) -> None:
        self.p = {i: i for i in items}

    def find(self, x: str) -> str:
        while self.p[x] != x:
            self.p[x] = self.p[self.p[x]]
            x = self.p[x]
        return x

    def union(self, x: str, y: str) -> bool:
        rx, ry = self.find(x), self.find(y)
        if rx == ry:
            return False
        self.p[ry] = rx
        return True


def plan_tree(mech: Mechanism, root: str | None = None, cut_preference: Sequence[str] = ()) -> TreePlan:
    """Choose the spanning tree and the cut pins.

    Kruskal over body pairs: slider pairs first (always in the tree), then pin pairs
    in file order, except pins at joints named in ``cut_preference``, which come last
    so they are the ones cut when they lie on a loop. ``root`` (default: the ground)
    is the body attached to the world.
    """
    bodies = mech.body_names
    root = mech.ground if root is None else root
    if root not in bodies:
        raise ValueError(f"root '{root}' is not a body of {mech.name} (bodies: {', '.join(bodies)})")
    unknown = [j for j in cut_preference if j not in mech.joints]
    if unknown:
        raise ValueError(f"cut_preference names unknown joints: {', '.join(unknown)}")
    pins = {j: mech.bodies_at(j) for j in mech.joints if len(mech.bodies_at(j)) >= 2}
    edges = [Edge("slider", s.guide, s.name, s.joint) for s in mech.sliders.values()]
    pin_edges = [
        Edge("pin", bs[i], bs[k], j) for j, bs in pins.items() for i in range(len(bs)) for k in range(i + 1, len(bs))
    ]
    late = set(cut_preference)
    edges += [e for e in pin_edges if e.joint not in late]
    edges += sorted((e for e in pin_edges if e.joint in late), key=lambda e: list(cut_preference).index(e.joint))
    uf = _UnionFind(bodies)
    tree = [e for e in edges if uf.union(e.a, e.b)]
    if len(tree) != len(bodies) - 1:  # the loader checks connectivity; this is a guard
        raise MechanismError(f"{mech.name}: bodies are not connected into one mechanism")

    # orient from the root
    adj: dict[str, list[tuple[str, Edge]]] = {b: [] for b in bodies}
    for e in tree:
        adj[e.a].append((e.b, e))
        adj[e.b].append((e.a, e))
    order, parent = [root], {}
    for b in order:  # BFS; `order` grows while iterating
        for c, e in adj[b]:
            if c != root and c not in parent:
                parent[c] = (b, e)
                order.append(c)

    # cuts: per pin, join the components its tree pairs leave among its bodies
    cuts = []
    for j, bs in pins.items():
        local = _UnionFind(bs)
        for e in tree:
            if e.kind == "pin" and e.joint == j:
                local.union(e.a, e.b)
        reps = list(dict.fromkeys(local.find(b) for b in bs))
        cuts += [(j, reps[0], r) for r in reps[1:]]
    return TreePlan(root, tuple(order), parent, tuple(cuts), root != mech.ground)


# ---------------------------------------------------------------- Pinocchio model


def _se3(theta: float, x: float, y: float) -> Any:
    import pinocchio as pin

    c, s = math.cos(theta), math.sin(theta)
    return pin.SE3(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([x, y, 0.0]))


def _pose(body: Body) -> Any:
    """World pose of a body frame at t = 0 (from the file's coordinates)."""
    return _se3(body.theta0, *body.origin)


@dataclass
class _Row:
    """One scalar/vector group of the square system beyond the cut anchors.

    ``kind``: "angle" (frame angle − target), "position" (frame origin x, y − 0),
    "slider" (s of a slider − target). ``driver``: index into the driver arrays, or
    None for a fixed target of 0 (ground anchor).
    """

    kind: str
    frame: int
    driver: int | None = None
    guide_frame: int = -1
    u_local: np.ndarray = field(default_factory=lambda: np.zeros(2))

    @property
    def size(self) -> int:
        return 2 if self.kind == "position" else 1


@dataclass
class PinocchioModel:
    """The compiled Pinocchio model of one mechanism (model + constraint descriptions).

    ``q_scale``: per coordinate, the length scale for prismatic/base translations and
    1 for angles, so Newton steps and tolerances are dimensionless.
    """

    mech: Mechanism
    plan: TreePlan
    model: Any
    body_joint: dict[str, int]
    body_frame: dict[str, int]
    point_frame: dict[str, int]  # tracked point/joint -> frame on the body that carries it
    cuts: list[Any]  # PointAnchorConstraintModel
    rows: list[_Row]
    slider_rows: dict[str, _Row]  # s of every slider (outputs)
    q_scale: np.ndarray
    bodies: dict[str, Body]

    @property
    def nv(self) -> int:
        return int(self.model.nv)

    @property
    def n_rows(self) -> int:
        return 2 * len(self.cuts) + sum(r.size for r in self.rows)


def build_model(mech: Mechanism, root: str | None = None, cut_preference: Sequence[str] = ()) -> PinocchioModel:
    """Build the Pinocchio tree, frames, cut anchors and driver/anchor rows for ``mech``.

    At q = 0 every body sits at its t = 0 pose from the coordinates (cut joints may
    be slightly open if the coordinates are approximate; the assembly closes them).
    """
    import pinocchio as pin

    plan = plan_tree(mech, root, cut_preference)
    bodies = mech.bodies()
    model = pin.Model()
    model.name = mech.name
    joint: dict[str, int] = {}
    in_joint: dict[str, Any] = {}  # body frame expressed in its joint's frame
    q_scale: list[float] = []
    L = mech.scale

    if plan.floating:  # planar base chain: x, y, then rotation of the root about the world z
        jx = model.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "base_x")
        jy = model.addJoint(jx, pin.JointModelPY(), pin.SE3.Identity(), "base_y")
        joint[plan.root] = model.addJoint(jy, pin.JointModelRZ(), pin.SE3.Identity(), f"{plan.root}@base")
        in_joint[plan.root] = _pose(bodies[plan.root])
        q_scale += [L, L, 1.0]
    else:
        joint[plan.root] = 0
        in_joint[plan.root] = pin.SE3.Identity()

    def at(body: str, name: str) -> Any:
        """Placement, in the body's joint frame, of a point of the body (axes = body axes)."""
        return in_joint[body] * _se3(0.0, *bodies[body].local[name])

    for c in plan.order[1:]:
        p, e = plan.parent[c]
        P, C = bodies[p], bodies[c]
        if e.kind == "pin":
            # joint frame at the pin, turned to the child's t = 0 orientation
            placement = at(p, e.joint) * _se3(C.theta0 - P.theta0, 0.0, 0.0)
            jm, offset, scale = pin.JointModelRZ(), _se3(0.0, *(-np.asarray(C.local[e.joint]))), 1.0
        elif c == e.b:  # block below its guide: slide along the axis fixed to the guide
            x_in_guide = _pose(P).actInv(np.array([*mech.joints[e.joint], 0.0]))
            placement = in_joint[p] * _se3(C.theta0 - P.theta0, x_in_guide[0], x_in_guide[1])
            jm, offset, scale = pin.JointModelPX(), _se3(0.0, *(-np.asarray(C.local[e.joint]))), L
        else:  # guide below its block: the guide slides the other way along the block's axis
            placement = at(p, e.joint)
            offset = at(p, e.joint).inverse() * in_joint[p] * _pose(P).inverse() * _pose(C)
            jm, scale = pin.JointModelPX(), L
        joint[c] = model.addJoint(joint[p], jm, placement, f"{c}@{e.joint}")
        in_joint[c] = offset
        q_scale.append(scale)

    body_frame = {}
    for b in mech.body_names:
        body_frame[b] = model.addFrame(pin.Frame(b, joint[b], in_joint[b], pin.FrameType.OP_FRAME))
    point_frame = {}
    for name in mech.tracked_points:
        b = mech.body_of_point(name)
        point_frame[name] = model.addFrame(pin.Frame(f"{b}/{name}", joint[b], at(b, name), pin.FrameType.OP_FRAME))
    # slider joints as seen from the block (= the point the slider's s measures)
    block_frame = {
        s.name: model.addFrame(
            pin.Frame(f"{s.name}/{s.joint}", joint[s.name], at(s.name, s.joint), pin.FrameType.OP_FRAME)
        )
        for s in mech.sliders.values()
    }

    # constraint models only once the model is complete
    cuts = [
        pin.PointAnchorConstraintModel(model, joint[b1], at(b1, j), joint[b2], at(b2, j)) for j, b1, b2 in plan.cuts
    ]

    rows: list[_Row] = []
    if plan.floating:
        rows += [_Row("position", body_frame[mech.ground]), _Row("angle", body_frame[mech.ground])]
    for i, d in enumerate(mech.drivers):
        if d.kind == "crank":
            rows.append(_Row("angle", body_frame[d.target], i))
        else:
            rows.append(_slider_row(mech, bodies, body_frame, block_frame, d.target, i))
    slider_rows = {s: _slider_row(mech, bodies, body_frame, block_frame, s, None) for s in mech.sliders}
    pm = PinocchioModel(
        mech, plan, model, joint, body_frame, point_frame, cuts, rows, slider_rows, np.asarray(q_scale), bodies
    )
    if pm.n_rows != pm.nv:  # the loader's mobility check makes this square; guard anyway
        raise MechanismError(f"{mech.name}: Pinocchio system is {pm.n_rows} equations for {pm.nv} coordinates")
    return pm


def _slider_row(
    mech: Mechanism,
    bodies: dict[str, Body],
    body_frame: dict[str, int],
    block_frame: dict[str, int],
    name: str,
    driver: int | None,
) -> _Row:
    sl = mech.sliders[name]
    g = bodies[sl.guide]
    c, s = math.cos(g.theta0), math.sin(g.theta0)
    u_local = np.array([c * sl.axis[0] + s * sl.axis[1], -s * sl.axis[0] + c * sl.axis[1]])
    return _Row("slider", block_frame[name], driver, body_frame[sl.guide], u_local)


# ---------------------------------------------------------------- numerics on one configuration


class _Work:
    """Pinocchio Data and constraint Data for one solve, plus the row evaluations."""

    def __init__(self, pm: PinocchioModel) -> None:
        import pinocchio as pin

        self.pm, self.model, self.nv, self.n_rows = pm, pm.model, pm.nv, pm.n_rows
        self.data = pm.model.createData()
        self.cdata = [c.createData() for c in pm.cuts]
        self.cut_pairs = list(zip(pm.cuts, self.cdata, strict=True))
        self.lwa = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        # residual weights make the merit dimensionless: lengths / mechanism size, angles as they are
        self.weights = np.full(pm.n_rows, 1.0 / pm.mech.scale)
        starts = 2 * len(pm.cuts) + np.cumsum([0, *(row.size for row in pm.rows)], dtype=int)[:-1]
        self.starts = [int(r) for r in starts]  # each row's first line in F and J
        for r, row in zip(starts, pm.rows, strict=True):
            if row.kind == "angle":
                self.weights[r] = 1.0
        # driver rows (all scalar) and the driver each one imposes
        self.drv_index = np.array([r for r, row in zip(starts, pm.rows, strict=True) if row.driver is not None], int)
        self.drv_which = np.array([row.driver for row in pm.rows if row.driver is not None], int)

    # --- frame helpers (after updateFramePlacements / forwardKinematics with v, a)
    def _angle(self, fid: int) -> float:
        R = self.data.oMf[fid].rotation
        return math.atan2(R[1, 0], R[0, 0])

    def slider_s(self, row: _Row, jac: bool = False) -> tuple[float, np.ndarray | None]:
        """s of a slider and, if asked, ds/dq (Pinocchio frame Jacobians)."""
        import pinocchio as pin

        d, m = self.data, self.pm.model
        Mg = d.oMf[row.guide_frame]
        u = Mg.rotation[:2, :2] @ row.u_local
        r = d.oMf[row.frame].translation[:2] - Mg.translation[:2]
        s = float(r @ u)
        if not jac:
            return s, None
        Jp = pin.getFrameJacobian(m, d, row.frame, self.lwa)
        Jg = pin.getFrameJacobian(m, d, row.guide_frame, self.lwa)
        u_perp = np.array([-u[1], u[0]])
        # ds/dt = (v_P − v_O)·u + (r·u⊥)·ω_guide
        return s, u @ (Jp[:2] - Jg[:2]) + (r @ u_perp) * Jg[5]

    def residual(self, q: np.ndarray, x: np.ndarray, jac: bool) -> tuple[np.ndarray, np.ndarray | None]:
        """Residual F(q) (driver inputs x) and, if ``jac``, its Jacobian dF/dq.

        The frames are placed by the same forward pass with or without ``jac`` (computeJointJacobians places the
        joints as forwardKinematics does), so F does not depend on ``jac``.
        """
        import pinocchio as pin

        m, d, lwa = self.model, self.data, self.lwa
        if jac:
            pin.computeJointJacobians(m, d, q)  # also places the joints
        else:
            pin.forwardKinematics(m, d, q)
        pin.updateFramePlacements(m, d)
        F = np.empty(self.n_rows)
        J = np.empty((self.n_rows, self.nv)) if jac else None
        r = 0
        for cm, cd in self.cut_pairs:
            cm.calc(m, d, cd)
            F[r : r + 2] = cd.constraint_position_error[:2]  # z row is identically zero in the plane
            if J is not None:
                J[r : r + 2] = cm.jacobian(m, d, cd)[:2]
            r += 2
        for r, row in zip(self.starts, self.pm.rows, strict=True):
            target = 0.0 if row.driver is None else x[row.driver]
            if row.kind == "slider":
                s, Js = self.slider_s(row, jac)
                F[r] = s - target
                if J is not None:
                    J[r] = Js
            elif row.kind == "angle":
                F[r] = _wrap(self._angle(row.frame) - target)
                if J is not None:
                    J[r] = pin.getFrameJacobian(m, d, row.frame, lwa)[5]
            else:
                F[r : r + 2] = d.oMf[row.frame].translation[:2]
                if J is not None:
                    J[r : r + 2] = pin.getFrameJacobian(m, d, row.frame, lwa)[:2]
        return F, J

    def drift(self, q: np.ndarray, v: np.ndarray) -> np.ndarray:
        """J̇·v: every row's second time derivative at zero joint acceleration (Pinocchio)."""
        import pinocchio as pin

        m, d, lwa = self.model, self.data, self.lwa
        pin.forwardKinematics(m, d, q, v, np.zeros(self.nv))
        pin.updateFramePlacements(m, d)
        out = np.empty(self.n_rows)
        r = 0
        for cm, cd in self.cut_pairs:
            cm.calc(m, d, cd)
            out[r : r + 2] = cd.constraint_acceleration_error[:2]
            r += 2
        for r, row in zip(self.starts, self.pm.rows, strict=True):
            if row.kind == "slider":
                out[r] = self.slider_sva(row)[2]
            elif row.kind == "angle":
                out[r] = pin.getFrameClassicalAcceleration(m, d, row.frame, lwa).angular[2]
            else:
                out[r : r + 2] = pin.getFrameClassicalAcceleration(m, d, row.frame, lwa).linear[:2]
        return out

    def slider_sva(self, row: _Row) -> tuple[float, float, float]:
        """s, v, a of a slider from frame kinematics (after forwardKinematics(q, v, a)).

        s = (P − O)·u with u = R_guide·u_local; differentiating with u̇ = ω u⊥:
        v = (v_P − v_O)·u + ω (P − O)·u⊥,
        a = (a_P − a_O)·u + 2ω (v_P − v_O)·u⊥ + (P − O)·(α u⊥ − ω² u).
        """
        import pinocchio as pin

        m, d, lwa = self.pm.model, self.data, self.lwa
        Mg = d.oMf[row.guide_frame]
        u = Mg.rotation[:2, :2] @ row.u_local
        up = np.array([-u[1], u[0]])
        r = d.oMf[row.frame].translation[:2] - Mg.translation[:2]
        vP = pin.getFrameVelocity(m, d, row.frame, lwa)
        vG = pin.getFrameVelocity(m, d, row.guide_frame, lwa)
        aP = pin.getFrameClassicalAcceleration(m, d, row.frame, lwa)
        aG = pin.getFrameClassicalAcceleration(m, d, row.guide_frame, lwa)
        w, al = vG.angular[2], aG.angular[2]
        dv = vP.linear[:2] - vG.linear[:2]
        da = aP.linear[:2] - aG.linear[:2]
        return float(r @ u), float(dv @ u + w * (r @ up)), float(da @ u + 2 * w * (dv @ up) + r @ (al * up - w * w * u))


Inputs = Callable[[float], tuple[np.ndarray, np.ndarray, np.ndarray]]  # t -> driver x, ẋ, ẍ
RESIDUAL_TOL = 1e-9  # scaled residual (lengths / mechanism size, rad) a converged position must meet
# Largest driver change per continuation step: 0.25 rad of a crank, 5 % of the mechanism size
# of a slider. The Taylor predictor is then within ~0.25³/6 ≈ 3e-3 of the solution, well
# inside Newton's basin, so a coarse sampling cannot carry the solve onto another branch.
MAX_CRANK_STEP = 0.25
MAX_SLIDER_STEP = 0.05
# A step across det J = 0 is accepted as a change point (branches crossing) when Newton corrected the
# Taylor prediction by less than this fraction of the predicted move: on the smooth branch the predictor
# errs by O(h³) against a move of O(h); a jump to the other branch needs a correction of O(move).
CROSS_JUMP = 0.01
# Every step, not only one across det J = 0: Newton's correction of the prediction, and the velocities' departure
# from the predicted ones (v + h·a) times h, must stay below JUMP_RATIO of the predicted move (+ JUMP_FLOOR for a
# mechanism at rest). On the branch followed both are O(h³) against a move of O(h); a landing on the other branch
# that meets this one at a change point keeps det J's sign (the branches cross) and differs by about the move, in
# the velocities even where the two branches' positions are close. The step is then bisected.
JUMP_RATIO = 0.1
JUMP_FLOOR = 1e-9
# How often a failing interval between samples is halved before the run stops there: 2^-12 of it. A motion can
# start next to a limit it is leaving, where the Taylor predictor holds only over steps much shorter than the time
# since the limit: seed 2026's c01868, an eight-bar whose slider dyad was at its limit 17 µs before t = 0 (the
# slider at 542 m/s, κ = 438), needs steps of ~1e-5 s, 2^-12 of its 0.0388 s sample spacing (2^-8 stopped it).
MAX_BISECT = 12
NEWTON_TOL = 1e-10  # Newton's stopping rule on the scaled step (lengths / mechanism size, rad)
MAX_ITER = 50  # Newton iterations per attempt
MAX_COND = 1e12  # a position whose Jacobian's condition number is above this counts as singular


class _NoConvergence(Exception):
    """A sample could not be assembled (the message says why)."""


@dataclass
class _State:
    t: float
    q: np.ndarray
    v: np.ndarray
    a: np.ndarray
    det_sign: float
    residual: float = 0.0
    jac: np.ndarray | None = None  # the constraint Jacobian at q (the health's condition number, at the end)
    iterations: int = 0


def _cond2(J: np.ndarray) -> float:
    """numpy.linalg.cond(J), the 2-norm condition number by SVD, without its per-call overhead (numpy's own
    function where the ratio is not finite: a singular or non-finite J, so that its value is numpy's too)."""
    s = np.linalg.svd(J, compute_uv=False)
    c = float(s[0]) / float(s[-1]) if s[-1] != 0 else math.inf
    return c if math.isfinite(c) else float(np.linalg.cond(J))


CERTAIN_COND = 1e-3  # of max_cond: below it the bound ‖J‖_F^n/|det J| certifies a position regular without an SVD


def _well_conditioned(J: np.ndarray, det: float, max_cond: float) -> bool:
    """Whether cond₂(J) ≤ max_cond for certain, from J's Frobenius norm and its determinant ``det`` (LU) alone.

    Π σ_i = |det| gives σ_min ≥ |det| / σ_max^(n−1), so cond₂ = σ_max/σ_min ≤ ‖J‖_F^n / |det|; this bound at most
    CERTAIN_COND·max_cond certifies the position (False: undecided, the SVD decides). LU's det is det(J + E) with
    ‖E‖ ≲ n·ρ·ε·‖J‖ (ρ: its growth factor); for a J with cond₂ > max_cond to pass, E must move σ_min by
    σ_max/(CERTAIN_COND·max_cond) = 1e-9·σ_max at the default 1e12, which needs n·ρ ≳ 4e6: beyond partial
    pivoting's worst-case growth 2^(n−1) up to n = 18 (the corpus's systems have n ≤ 7), and its growth is near 1
    in practice. Where it passes, numpy.linalg.cond passes too (tests/test_pinocchio.py checks both).
    """
    fro = math.sqrt(float((J * J).sum()))
    if not (math.isfinite(fro) and math.isfinite(det) and math.isfinite(max_cond)) or det == 0:
        return False
    try:
        return fro ** len(J) <= CERTAIN_COND * max_cond * abs(det)
    except OverflowError:
        return False


class _Solver:
    """Newton projection, velocity/acceleration solves and continuation for one model."""

    def __init__(self, pm: PinocchioModel, tol: float, max_iter: int, max_bisect: int, max_cond: float) -> None:
        self.pm, self.w = pm, _Work(pm)
        self.tol, self.max_iter, self.max_bisect, self.max_cond = tol, max_iter, max_bisect, max_cond
        self.crossings = 0  # change points passed (det J changed sign on the predicted path)
        self.lengths = np.zeros(pm.nv, bool)  # the coordinates that are lengths: prismatic joints (others turn)
        for j in list(pm.model.joints)[1:]:
            if j.shortname().startswith("JointModelP"):
                self.lengths[j.idx_v : j.idx_v + j.nv] = True
        crank = np.array([d.kind == "crank" for d in pm.mech.drivers])
        self.max_dx = np.where(crank, MAX_CRANK_STEP, MAX_SLIDER_STEP * pm.mech.scale)

    def n_steps(self, x0: np.ndarray, x1: np.ndarray) -> int:
        """Continuation steps needed to move the drivers from x0 to x1."""
        return max(1, math.ceil(float((np.abs(x1 - x0) / self.max_dx).max())))

    def project(self, q: np.ndarray, x: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """Newton onto {F(q; x) = 0} from ``q``; returns (q, F and J at q, iterations).

        Stops when the scaled Newton step max|Δq_i / scale_i| ≤ tol (the error after
        such a step is ~tol² by quadratic convergence); Armijo backtracking on
        ½|W·F|² guards against overshoot. Raises _NoConvergence otherwise. The line
        search evaluates J with F, so an accepted point's F and J start the next iteration.
        """
        w, sc, residual = self.w.weights, self.pm.q_scale, self.w.residual
        q = q.copy()
        F, J = residual(q, x, True)
        for it in range(1, self.max_iter + 1):
            try:
                dq = np.linalg.solve(J, -F)
            except np.linalg.LinAlgError:
                raise _NoConvergence("singular constraint Jacobian") from None
            step = float((np.abs(dq) / sc).max())
            if not math.isfinite(step) and not np.all(np.isfinite(dq)):
                raise _NoConvergence("singular constraint Jacobian")
            if step <= self.tol:
                q += dq
                F, J = residual(q, x, True)
                res = float(np.abs(w * F).max())
                if res > RESIDUAL_TOL:  # a small step is not enough: the equations must hold
                    raise _NoConvergence(f"Newton stalled at scaled residual {res:.3g}")
                return q, F, J, it
            phi0 = 0.5 * float(((w * F) ** 2).sum())
            lam = 1.0
            while True:
                F, J = residual(q + lam * dq, x, True)
                if 0.5 * float(((w * F) ** 2).sum()) <= (1.0 - 1e-4 * lam) * phi0:
                    break
                lam *= 0.5
                if lam < 1e-3:
                    raise _NoConvergence(f"line search failed (scaled residual {math.sqrt(2 * phi0):.3g})")
            q += lam * dq
        raise _NoConvergence(f"no convergence in {self.max_iter} Newton iterations (last step {step:.3g})")

    def state(
        self, t: float, q: np.ndarray, F: np.ndarray, J: np.ndarray, xd: np.ndarray, xdd: np.ndarray, it: int
    ) -> _State:
        """Velocities and accelerations at a converged q (two linear solves)."""
        det = float(np.linalg.det(J))
        if not _well_conditioned(J, det, self.max_cond):
            cond = _cond2(J)
            if not math.isfinite(cond) or cond > self.max_cond:
                raise _NoConvergence(f"singular position (Jacobian condition number {cond:.3g})")
        rhs = np.zeros(self.w.n_rows)
        rhs[self.w.drv_index] = xd[self.w.drv_which]
        v = np.linalg.solve(J, rhs)
        rhs[:] = -self.w.drift(q, v)
        rhs[self.w.drv_index] += xdd[self.w.drv_which]
        a = np.linalg.solve(J, rhs)
        return _State(t, q, v, a, float(np.sign(det)), float(np.abs(self.w.weights * F).max()), J, it)

    def step(
        self,
        prev: _State,
        t: float,
        x: np.ndarray,
        xd: np.ndarray,
        xdd: np.ndarray,
        guess: np.ndarray,
        on_path: bool = True,
        move: float | None = None,
    ) -> _State:
        """One continuation step; ``on_path``: held to the predicted path (JUMP_RATIO), which the last bisection
        level is not (a step that short is taken as Newton lands it, as before the path was checked); ``move``:
        the predictor's scaled move max|guess − prev.q|/scale, if the caller has it."""
        q, F, J, it = self.project(guess, x)
        st = self.state(t, q, F, J, xd, xdd, it)
        sc, dt = self.pm.q_scale, t - prev.t
        if move is None:
            move = float((np.abs(guess - prev.q) / sc).max())
        correction = float((np.abs(q - guess) / sc).max())
        turned = float((np.abs(st.v - prev.v - dt * prev.a) / sc).max()) * abs(dt)
        if on_path and max(correction, turned) > JUMP_RATIO * move + JUMP_FLOOR:
            raise _NoConvergence("Newton left the predicted path (the other branch of a change point, or a toggle)")
        if st.det_sign != prev.det_sign and not self.smooth(prev, q, guess):
            # crossed det J = 0 off the predicted path: a limit/toggle or a jump to the other branch
            raise _NoConvergence("assembly branch changed (the constraint Jacobian's determinant changed sign)")
        return st

    def smooth(self, prev: _State, q: np.ndarray, guess: np.ndarray) -> bool:
        """Whether a step whose determinant changed sign stayed on the Taylor-predicted path: a change point
        (two assembly branches crossing) passed on the branch whose velocities stay continuous. The
        correction Newton made must be a small part (CROSS_JUMP) of the move; a jump to the other branch, or
        a projection pulled back from past a limit, corrects by about the move itself."""
        sc = self.pm.q_scale
        move = float(np.max(np.abs(guess - prev.q) / sc))
        correction = float(np.max(np.abs(q - guess) / sc))
        if correction > CROSS_JUMP * move:
            return False
        self.crossings += 1
        return True

    def march(self, prev: _State, t: float, inputs: Inputs, n_min: int = 1) -> _State:
        """From ``prev`` to time ``t`` in at least ``n_min`` equal steps, more if the drivers move far."""
        n = max(n_min, self.n_steps(inputs(prev.t)[0], inputs(t)[0]))
        for i in range(1, n + 1):
            prev = self.advance(prev, t if i == n else prev.t + (t - prev.t) / (n - i + 1), inputs)
        return prev

    def advance(self, prev: _State, t: float, inputs: Inputs, depth: int = 0) -> _State:
        """From ``prev`` to time ``t``: Taylor predictor, then bisect the interval on failure.

        The interval is bisected first where the predictor moves any coordinate by more than
        MAX_CRANK_STEP (rad, or that fraction of its length scale), not only the drivers: next to a
        change point a follower can turn many times faster than the input (a kite's coupler swings
        through half a turn while the crank turns a little), and a predictor that far off can land
        Newton on the other branch, which meets this one there.
        """
        dt = t - prev.t
        x, xd, xdd = inputs(t)
        guess = prev.q + dt * prev.v + 0.5 * dt * dt * prev.a
        move = float((np.abs(guess - prev.q) / self.pm.q_scale).max())
        try:
            if move > MAX_CRANK_STEP and depth < self.max_bisect:
                raise _NoConvergence("predicted move too long")
            return self.step(prev, t, x, xd, xdd, guess, on_path=depth < self.max_bisect, move=move)
        except _NoConvergence:
            if depth >= self.max_bisect:
                raise
        mid = self.advance(prev, prev.t + 0.5 * dt, inputs, depth + 1)
        return self.advance(mid, t, inputs, depth + 1)


# ---------------------------------------------------------------- the engine


def _inputs_fn(mech: Mechanism, times: np.ndarray | None = None) -> Inputs:
    """Driver inputs x, ẋ, ẍ at one time (the shared description of the inputs).

    ``times`` (the samples) are evaluated in one call up front: evaluate_all works element by element, so a
    sample's inputs are the numbers a call at that time alone gives. Times between samples (continuation
    steps, bisections) are evaluated when asked for.
    """
    table: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
    if times is not None and len(times):
        try:
            x, xd, xdd = evaluate_all(mech, np.asarray(times, float))
            table = {float(tk): (x[k], xd[k], xdd[k]) for k, tk in enumerate(times)}
        except MechanismError:  # a time outside a profile: the sample says so when the run reaches it
            pass

    @functools.lru_cache(maxsize=16)  # each time is asked for by march and by advance
    def f(t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        hit = table.get(t)
        if hit is not None:
            return hit
        x, xd, xdd = evaluate_all(mech, np.array([t]))
        return x[0], xd[0], xdd[0]

    return f


def _assembly_time(mech: Mechanism) -> float:
    """The instant the coordinates describe: t = 0, moved inside the profiles' common range."""
    lo = max((d.profile.t[0] for d in mech.drivers if d.profile is not None), default=0.0)
    hi = min((d.profile.t[-1] for d in mech.drivers if d.profile is not None), default=0.0)
    return float(min(max(0.0, lo), hi)) if lo <= hi else 0.0


def _assemble(solver: _Solver, t_a: float, inputs: Inputs) -> _State:
    """Close the cut joints at t_a, starting from the file's coordinates (q = 0).

    The drivers are first held at the values the coordinates show (link θ0, slider s),
    then moved by continuation to their input at t_a (they differ when a driver states
    its own ``theta0``/``s0``), so the branch is the one the coordinates describe.
    """
    pm, mech = solver.pm, solver.pm.mech
    x, xd, xdd = inputs(t_a)
    crank = np.array([d.kind == "crank" for d in mech.drivers])
    solver.w.residual(np.zeros(pm.nv), x, False)  # place the frames at q = 0
    x_c = np.array(
        [
            pm.bodies[d.target].theta0 if d.kind == "crank" else solver.w.slider_s(pm.slider_rows[d.target])[0]
            for d in mech.drivers
        ]
    )
    x_c = np.where(crank, x + _wrap(x_c - x), x_c)  # the same turn as the input
    n = solver.n_steps(x_c, x) if np.any(x != x_c) else 0
    try:
        q, F, J, it = solver.project(np.zeros(pm.nv), x_c)
        for k in range(1, n + 1):
            q, F, J, it = solver.project(q, x_c + (x - x_c) * k / n)
        return solver.state(t_a, q, F, J, xd, xdd, it)
    except _NoConvergence as exc:
        raise MechanismError(f"{mech.name}: pinocchio cannot assemble the mechanism at t = {t_a:g} s: {exc}") from None


def solve(
    mechanism: Mechanism,
    times: np.ndarray | Sequence[float] | None = None,
    *,
    root: str | None = None,
    cut_preference: Sequence[str] = (),
    tol: float = NEWTON_TOL,
    max_iter: int = MAX_ITER,
    max_bisect: int = MAX_BISECT,
    max_cond: float = MAX_COND,
) -> Result:
    """Positions, velocities, accelerations of ``mechanism`` over ``times`` [s] (default: the
    file's [time]) with Pinocchio; the Result has every column of the output contract.

    Options: ``root`` — body attached to the world (default: the ground; any other
    body puts the tree on a planar base and pins the ground with 3 equations);
    ``cut_preference`` — joint names whose pins should be cut rather than kept in
    the tree; ``tol`` — Newton stopping rule on the scaled step (lengths / mechanism
    size, angles in rad); ``max_iter`` — Newton iterations per attempt;
    ``max_bisect`` — how many times a failing interval is halved before giving up;
    ``max_cond`` — condition number above which a position counts as singular.

    Raises MotionError (``.partial`` = the samples solved before) when a sample cannot
    be assembled, and MechanismError when the t = 0 coordinates cannot be.
    """
    mech = mechanism
    t = np.asarray(mech.times if times is None else times, float)
    pm = build_model(mech, root, cut_preference)
    solver = _Solver(pm, tol, max_iter, max_bisect, max_cond)
    inputs = _inputs_fn(mech, t)
    t_a = _assembly_time(mech)
    state = _assemble(solver, t_a, inputs)

    states: list[_State] = []
    for k, tk in enumerate(t):
        try:
            # from the assembly to the first sample: also no longer steps than the sampling step,
            # since an input may go out and back between t_a and times[0]
            n_min = math.ceil(abs(tk - t_a) / float(np.median(np.diff(t)))) if k == 0 and len(t) > 1 else 1
            state = solver.march(state, float(tk), inputs, max(n_min, 1))
        except _NoConvergence as exc:
            x = inputs(float(tk))[0]
            drv = ", ".join(f"{d.symbol} = {x[i]:.6g}" for i, d in enumerate(mech.drivers))
            raise MotionError(
                f"{mech.name}: pinocchio cannot assemble sample {k} at t = {tk:g} s ({drv}): {exc}",
                time=float(tk),
                sample=k,
                driver_value=x,
                partial=_collect(solver, t[:k], states),
            ) from None
        states.append(state)
    return _collect(solver, t, states)


def _frame_outputs(solver: _Solver, states: list[_State]) -> np.ndarray:
    """Per solved sample (rows): every link's θ (in (−π, π]), ω, α, every point's x, y, vx, vy, ax, ay and every
    slider's s, v, a, in that order (the mechanism's), read from Pinocchio's frames at the sample's q, v, a."""
    import pinocchio as pin

    pm, w = solver.pm, solver.w
    m, d, lwa, mech = pm.model, w.data, w.lwa, pm.mech
    link_frames = [pm.body_frame[b] for b in mech.moving_links]
    point_frames = [pm.point_frame[p] for p in mech.tracked_points]
    slider_rows = [pm.slider_rows[s] for s in mech.sliders]
    velocity, acceleration, oMf = pin.getFrameVelocity, pin.getFrameClassicalAcceleration, d.oMf
    rows = []
    for st in states:
        pin.forwardKinematics(m, d, st.q, st.v, st.a)
        pin.updateFramePlacements(m, d)
        row: list[float] = []
        for f in link_frames:
            row += (w._angle(f), velocity(m, d, f, lwa).angular[2], acceleration(m, d, f, lwa).angular[2])
        for f in point_frames:
            row += oMf[f].translation[:2].tolist()
            row += velocity(m, d, f, lwa).linear[:2].tolist()
            row += acceleration(m, d, f, lwa).linear[:2].tolist()
        for r in slider_rows:
            row += w.slider_sva(r)
        rows.append(row)
    width = 3 * len(link_frames) + 6 * len(point_frames) + 3 * len(slider_rows)
    return np.array(rows, float).reshape(len(states), width)


def _collect(solver: _Solver, t: np.ndarray, states: list[_State]) -> Result:
    """Every output at each solved sample (from Pinocchio's frames), the health and the joint coordinates."""
    pm, mech = solver.pm, solver.pm.mech
    n = len(states)
    cols = iter(_frame_outputs(solver, states).T)
    links = {b: [next(cols) for _ in range(3)] for b in mech.moving_links}
    points = {p: tuple(next(cols) for _ in range(6)) for p in mech.tracked_points}
    sliders = {s: tuple(next(cols) for _ in range(3)) for s in mech.sliders}
    for b, arr in links.items():
        arr[0] = _continuous_angle(arr[0], arr[1], t, pm.bodies[b].theta0)
    jacobians = np.array([s.jac for s in states], float).reshape(n, pm.nv, pm.nv)
    health = {
        "residual": np.array([s.residual for s in states]),
        "cond": condition_numbers(jacobians, solver.lengths, mech.scale),  # the health's: free of the file's units
        "iterations": np.array([s.iterations for s in states], float),
    }
    meta = {"root": pm.plan.root, "cuts": [f"{j}:{a}-{b}" for j, a, b in pm.plan.cuts], "nv": pm.nv}
    # the tree's joint coordinates, rates and accelerations per sample (validators.pinocchio_forces uses them)
    meta.update({k: np.array([getattr(s, k) for s in states]).reshape(n, pm.nv) for k in ("q", "v", "a")})
    return Result.from_arrays(
        mech.name,
        ENGINE,
        t,
        links={b: tuple(a) for b, a in links.items()},
        points=points,
        sliders=sliders,
        health=health,
        meta=meta,
    )


def _continuous_angle(raw: np.ndarray, omega: np.ndarray, t: np.ndarray, theta0: float) -> np.ndarray:
    """Unwrap frame angles in (−π, π] into a continuous θ, starting on the turn of ``theta0``.

    Each increment is taken as the trapezoidal ω-prediction plus the wrapped remainder,
    so steps of more than half a turn between samples are still followed.
    """
    if len(raw) == 0:
        return raw
    pred = 0.5 * (omega[1:] + omega[:-1]) * np.diff(t)
    inc = pred + _wrap(np.diff(raw) - pred)
    return theta0 + _wrap(raw[0] - theta0) + np.concatenate(([0.0], np.cumsum(inc)))
