"""Independent Exudyn engine: any vloop mechanism as an Exudyn multibody system.

    from validators import exudyn as vexu
    res = vexu.solve(mech)                      # mode="kinematic", engine "exudyn-kinematic"
    res = vexu.solve(mech, mode="dynamic")      # engine "exudyn-dynamic"

The model (2D rigid bodies, revolute/prismatic joints, driver constraints) is
built by :mod:`validators.exudyn_model` from the mechanism description only;
nothing of vloop's loop equations or solver is used. Two modes, both on
Exudyn's own numerics:

``kinematic``
    At every sample: Newton on Exudyn's position-level constraint residual
    C(q, t) with Exudyn's constraint Jacobian (``MainSolverStatic``
    ``ComputeAlgebraicEquations`` / ``ComputeJacobianAE``), drivers imposed by
    their constraints. Velocities from Exudyn's velocity-level residual
    ċ(q, q̇, t) = C_q q̇ + C_t, which is affine in q̇: C_q q̇ = −ċ(q, 0, t), with
    C_q Exudyn's constraint Jacobian, or, where Exudyn simplifies that (the
    relative-translation marker of a driven slider on a rotating guide), taken
    column by column as ċ(q, e_i, t) − ċ(q, 0, t) (exact up to round-off; the
    two agree to round-off everywhere else: tests/test_exudyn.py).
    Accelerations from C_q q̈ = −(∂ċ/∂q · q̇ + ∂ċ/∂t): the quadratic velocity
    term ∂ċ/∂q · q̇ is the derivative of Exudyn's velocity-level residual along
    the motion, d/dε ċ(q + ε q̇, q̇, t), taken with a 6th-order central
    difference (step ε = 0.01 / max|φ̇| so each body turns by at most 0.01 rad:
    truncation ~(0.01)^6/140 ≈ 1e-14, round-off ~1e-14 relative); ∂ċ/∂t is
    −ẍ(t) of each driver (the prescribed input acceleration, from
    :mod:`vloop.drivers`), zero for the other constraints. Samples are tracked
    by continuation from the t = 0 assembly with a Taylor predictor and step
    halving; an interval that cannot be bridged (no root, or only a jump to
    another branch) is a :class:`~vloop.errors.MotionError`. Measured agreement
    with vloop and the closed forms: ~1e-13 of each quantity's peak.

``dynamic``
    Exudyn's real multibody simulation: ``SolveDynamic`` with the index-3
    generalized-α integrator (spectral radius 0.6), fixed step h, prescribed
    driver motion, started from the kinematic t = 0 assembly with consistent
    velocities and accelerations; sampled at the requested times by node
    sensors stored in memory. The step is chosen from an accuracy target (see
    :func:`dynamic_step`): positions are exact to the Newton tolerance (the
    constraints fix them), velocities and accelerations carry the integrator's
    O(h²) error — measured ≤ 1.3e-6 and ≤ 9e-6 of the group's peak at the
    default target 1e-5 over the catalog (tests/test_exudyn.py). By default
    that error is removed by Richardson extrapolation instead of a small step:
    two runs at h and 2h (h = 4× that step), r = r_h + (r_h − r_2h)/3, and the
    first samples (the coarse runs' start-up) from one run at the accuracy's
    step — ≤ 2e-7 of the peak against the closed forms in less than half the
    steps (:func:`_extrapolated`); ``richardson=False`` gives the single run.

Neither mode writes files (``solution.file.write = False``, sensors with
``storeInternal`` and no file name) or starts the renderer.

Output (the Result contract): ``LINK.theta|omega|alpha`` for every moving link
and slider block (the node rotation = the body's θ, continuous, = Body.theta0
at the reference), ``POINT.x|y|vx|vy|ax|ay`` for every joint and tracer point,
``SLIDER.s|v|a`` with s = (P_joint − O_guide)·u(t).
"""

from __future__ import annotations

import contextlib
import itertools
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from vloop.drivers import evaluate_all
from vloop.errors import MotionError
from vloop.mechanism import Mechanism
from vloop.result import Result

from . import exudyn_model as em
from .tolerances import condition_numbers, integrator_roundoff

ENGINES = {"kinematic": "exudyn-kinematic", "dynamic": "exudyn-dynamic"}

# 6th-order central difference for a first derivative: offsets ±1, ±2, ±3
_FD_OFFSETS = (1, 2, 3)
_FD_WEIGHTS = (3 / 4, -3 / 20, 1 / 60)
FD_TURN = 0.01  # rad: largest body rotation within the difference stencil's unit step
# kinematic continuation: largest predicted move of any coordinate per step (rad, or fraction of the mechanism
# size); the Taylor predictor is then within ~0.25³/6 ≈ 3e-3 of the solution, well inside Newton's basin
MAX_MOVE = 0.25
JUMP_RATIO = 0.1  # largest Newton correction of a continuation step, as a fraction of the predicted move
JUMP_FLOOR = 1e-9  # ... plus this (rad, fraction of the size): a mechanism at rest moves by round-off only

# dynamic mode: step from an accuracy target (see dynamic_step)
DEFAULT_ACCURACY = 1e-5  # relative acceleration error aimed at by the default step
ACC_ERROR_COEFF = 5.0  # measured: relative acceleration error ≤ ACC_ERROR_COEFF · (Ω h)² (see dynamic_step)
MIN_ACCURACY = 1e-6  # below this, round-off of the index-3 accelerations (∝ 1/h²) wins over the O(h²) error
MAX_STEPS = 2_000_000  # a motion racing into a limit position must not ask for an endless run
SPECTRAL_RADIUS = 0.6
# generalized-α starts with a transient in the accelerations (≈ 1e-2 of their peak, damped by ≈ 0.64
# per step, measured): no sample may come before 40 steps (0.64^40 ≈ 2e-8 of it left)
MIN_STEPS_TO_SAMPLE = 40
# the default run is two runs at h and 2h, Richardson-extrapolated (_extrapolated), h this many times the step the
# accuracy asks of a single run (dynamic_step): measured against the catalog's closed forms, the extrapolation's
# error at this h is ≤ 2e-7 of the peak against the single run's ≤ 4e-6 at its own step (tests/test_exudyn.py)
RICHARDSON_FACTOR = 4
Segment = tuple[float, float, int, float]  # an integration run: start [s], end [s], steps, sensor period [s]


# ---------------------------------------------------------------- public API


def solve(
    mechanism: Mechanism,
    times: np.ndarray | None = None,
    mode: str = "kinematic",
    **options: Any,
) -> Result:
    """Positions, velocities and accelerations of ``mechanism`` over ``times`` [s], computed by Exudyn.

    ``times`` default to the mechanism's own samples; if ``times[0] != 0`` the
    motion is still followed from the t = 0 assembly. ``mode``: ``"kinematic"``
    (Newton on Exudyn's constraint equations at each sample) or ``"dynamic"``
    (Exudyn's generalized-α time integration).

    Options, kinematic: ``tol`` (Newton step tolerance, relative to the
    mechanism size / in rad; default 1e-12), ``max_iter`` (25), ``max_halvings``
    (14: how often an interval between samples may be halved before giving up).
    Options, dynamic: ``step`` (h [s]; default from ``accuracy``, see
    :func:`dynamic_step`), ``accuracy`` (target acceleration error relative to
    the peak, default 1e-5, not below 1e-6), ``spectral_radius`` (ρ∞, 0.6),
    ``newton_tol`` (Newton increment tolerance relative to the mechanism size,
    default 1e-10), ``max_steps`` (the samples a single run's first ``max_steps``
    steps reach, whole sample periods; ``meta["budget"]`` says how many of how
    many; default: all), ``richardson`` (default: True unless ``step`` is given;
    ``meta["richardson"]`` gives the runs' steps). Samples on a common grid from
    t = 0 are integrated in one run whose step divides the grid (or the
    extrapolated pair and its head); irregular samples in one run per interval.

    Raises :class:`vloop.errors.MotionError` (with ``.partial``) when a sample
    cannot be assembled (kinematic) or the integration fails (dynamic).
    """
    if mode not in ENGINES:
        raise ValueError(f"mode must be 'kinematic' or 'dynamic', got {mode!r}")
    t = np.asarray(mechanism.times if times is None else times, float)
    if t.ndim != 1 or t.size == 0:
        raise ValueError("times must be a non-empty 1-D array")
    if np.any(np.diff(t) <= 0):
        raise ValueError("times must be strictly increasing")
    evaluate_all(mechanism, t)  # a profile that does not cover the times fails here, cleanly
    if mode == "kinematic":
        return _solve_kinematic(mechanism, t, **options)
    return _solve_dynamic(mechanism, t, **options)


# ---------------------------------------------------------------- Exudyn access


def _settings() -> Any:
    """Simulation settings that write nothing and print nothing."""
    import exudyn as exu

    ss = exu.SimulationSettings()
    ss.solution.file.write = False
    ss.solution.restart.write = False
    ss.solution.sensors.active = True
    ss.solution.sensors.writeHeader = False
    ss.solution.sensors.writeFooter = False
    ss.solution.recordImagesInterval = -1
    ss.solution.solverInformationFileName = ""
    ss.staticSolver.verboseMode = 0
    ss.staticSolver.verboseModeFile = 0
    ss.timeIntegration.verboseMode = 0
    ss.timeIntegration.verboseModeFile = 0
    ss.show.computationTime = False
    ss.show.statistics = False
    ss.show.globalTimers = False
    return ss


class ConstraintEquations:
    """Exudyn's algebraic (constraint) equations of a model at given coordinates and time.

    ``q``, ``qd`` are the ODE2 coordinates (displacements from the node
    reference values) and their rates; all functions return copies.
    """

    def __init__(self, model: em.ExudynModel) -> None:
        import exudyn as exu

        self.model = model
        self.mbs = model.mbs
        self.sd = model.mbs.systemData
        self.n = model.n_ode2
        self.n_ae = model.n_ae
        self.solver = exu.MainSolverStatic()
        self.solver.InitializeSolver(self.mbs, _settings())
        self._zero = np.zeros(self.n)

    def _set(self, q: np.ndarray, qd: np.ndarray | None, t: float) -> None:
        self.sd.SetODE2Coordinates(q)
        self.sd.SetODE2Coordinates_t(self._zero if qd is None else qd)
        self.sd.SetTime(float(t))

    def residual(self, q: np.ndarray, t: float) -> np.ndarray:
        """C(q, t), position level."""
        self._set(q, None, t)
        self.solver.ComputeAlgebraicEquations(self.mbs, velocityLevel=False)
        return np.array(self.solver.GetSystemResidual()[self.n :])

    def jacobian(self, q: np.ndarray, t: float) -> np.ndarray:
        """Exudyn's constraint Jacobian ∂C/∂q (n_ae × n)."""
        self._set(q, None, t)
        self.solver.ComputeJacobianODE2RHS(self.mbs, 0.0, 0.0, 0.0)  # zeroes the system Jacobian
        self.solver.ComputeJacobianAE(self.mbs, 1.0, 0.0, 1.0, False)
        return np.array(self.solver.GetSystemJacobian()[self.n :, : self.n])

    def velocity_residual(self, q: np.ndarray, qd: np.ndarray, t: float) -> np.ndarray:
        """ċ(q, q̇, t), velocity level (= C_q q̇ + C_t)."""
        self._set(q, qd, t)
        self.solver.ComputeAlgebraicEquations(self.mbs, velocityLevel=True)
        return np.array(self.solver.GetSystemResidual()[self.n :])

    def velocity_jacobian(self, q: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(∂ċ/∂q̇, ċ(q, 0, t)): ∂ċ/∂q̇ = C_q, Exudyn's position Jacobian, where that is exact; else (a driven
        slider on a moving guide) by differences of the affine map q̇ ↦ ċ(q, q̇, t), column by column."""
        c0 = self.velocity_residual(q, self._zero, t)
        if not self.model.simplified_jacobian:
            return self.jacobian(q, t), c0
        jac = np.empty((self.n_ae, self.n))
        e = np.zeros(self.n)
        for i in range(self.n):
            e[i] = 1.0
            jac[:, i] = self.velocity_residual(q, e, t) - c0
            e[i] = 0.0
        return jac, c0


# ---------------------------------------------------------------- kinematic mode


@dataclass
class _State:
    t: float
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    jac: np.ndarray  # the velocity-level constraint Jacobian C_q at q (its condition number goes to health)
    iters: int


class _Kinematics:
    """Position/velocity/acceleration solution on Exudyn's constraint equations."""

    def __init__(self, model: em.ExudynModel, tol: float = 1e-12, max_iter: int = 25) -> None:
        self.model = model
        self.eq = ConstraintEquations(model)
        self.n = model.n_ode2
        size = model.mechanism.scale
        # weights: lengths relative to the mechanism size, rotations in rad
        self.w = np.ones(self.n)
        self.rot = np.zeros(self.n, bool)
        for bm in model.moving.values():
            self.w[bm.ode2[:2]] = 1.0 / size
            self.rot[bm.ode2[2]] = True
        self.size = size
        self.tol = tol
        self.max_iter = max_iter

    # --- positions
    def newton(
        self, q: np.ndarray, t: float, max_iter: int | None = None, damped: bool = False
    ) -> tuple[np.ndarray, bool, int]:
        """Newton on C(q, t) = 0 from ``q``; returns (q, converged, iterations)."""
        max_iter = self.max_iter if max_iter is None else max_iter
        q = np.array(q, float)
        r = self.eq.residual(q, t)
        extra = 0
        for it in range(1, max_iter + 1):
            jac = self.eq.jacobian(q, t)
            try:
                dq = (
                    np.linalg.solve(jac, -r)
                    if jac.shape[0] == jac.shape[1]
                    else np.linalg.lstsq(jac, -r, rcond=None)[0]
                )
            except np.linalg.LinAlgError:
                return q, False, it
            if not np.all(np.isfinite(dq)):
                return q, False, it
            step = 1.0
            if damped:  # backtracking on |C| (assembly from rough coordinates only)
                r_norm = float(np.linalg.norm(r))
                while step > 1e-4:
                    r_try = self.eq.residual(q + step * dq, t)
                    if np.linalg.norm(r_try) < (1 - 1e-4 * step) * r_norm or r_norm < 1e-14 * self.size:
                        break
                    step *= 0.5
            q = q + step * dq
            r = self.eq.residual(q, t)
            size = float(np.max(np.abs(self.w * dq))) * step
            if size < self.tol:
                extra += 1
                if extra >= 2 or size < 1e-15:  # one polishing iteration after the step is below tol
                    return q, bool(np.all(np.isfinite(q))), it
        return q, False, max_iter

    # --- velocities and accelerations
    def rates(self, q: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(q̇, q̈, C_q) at a solved position."""
        eq = self.eq
        jac, c0 = eq.velocity_jacobian(q, t)
        square = jac.shape[0] == jac.shape[1]

        def lin(b: np.ndarray) -> np.ndarray:
            return np.linalg.solve(jac, b) if square else np.linalg.lstsq(jac, b, rcond=None)[0]

        qd = lin(-c0)
        # quadratic velocity term: d/dε ċ(q + ε q̇, q̇, t) at ε = 0 (6th-order central difference)
        rate = float(np.max(np.abs(qd[self.rot]), initial=0.0))
        rate = max(rate, float(np.max(np.abs(qd[~self.rot] * self.w[~self.rot]), initial=0.0)))
        gamma = np.zeros(eq.n_ae)
        if rate > 0:
            eps = FD_TURN / rate
            for k, wk in zip(_FD_OFFSETS, _FD_WEIGHTS, strict=True):
                gamma += wk * (
                    eq.velocity_residual(q + k * eps * qd, qd, t) - eq.velocity_residual(q - k * eps * qd, qd, t)
                )
            gamma /= eps
        # explicit time derivative: ċ = (marker rate) − ẋ_driver(t)  ⇒  ∂ċ/∂t = −ẍ_driver(t)
        for inp, row in zip(self.model.driver_inputs, self.model.driver_rows, strict=True):
            gamma[row] -= inp(t)[2]
        qdd = lin(-gamma)
        return qd, qdd, jac

    def state(self, q: np.ndarray, t: float, iters: int) -> _State:
        qd, qdd, jac = self.rates(q, t)
        return _State(t, q, qd, qdd, jac, iters)

    def step(self, s: _State, t: float, jump_tol: float = 0.1) -> _State | None:
        """From state ``s`` to time ``t`` by Taylor predictor + Newton; None if not accepted.

        Not accepted either when the predictor moves any coordinate by more than MAX_MOVE (rad, or
        that fraction of the mechanism size), or when Newton corrects the predicted position, or the
        new velocities differ from the predicted ones (q̇ + h·q̈) times h, by more than JUMP_RATIO of the
        predicted move: on the branch being followed both err by O(h³) against a move of O(h), while
        a landing on another branch (next to a toggle or a change point, where branches come close or
        meet and a follower can turn many times faster than the input) differs by about the move
        itself, in the velocities even where the positions of the two branches are close. The step is
        then halved until the predictor is that good, so the motion continues from Exudyn's own
        previous state on its own branch.
        """
        dt = t - s.t
        pred = s.q + dt * s.qd + 0.5 * dt * dt * s.qdd
        move = float(np.max(np.abs(self.w * (pred - s.q))))
        if move > MAX_MOVE:
            return None
        q, ok, it = self.newton(pred, t)
        if not ok:
            return None
        correction = float(np.max(np.abs(self.w * (q - pred))))
        if correction > min(jump_tol, JUMP_RATIO * move + JUMP_FLOOR):  # a jump, not a continuation
            return None
        st = self.state(q, t, it)
        if not np.all(np.isfinite(st.qdd)):
            return None
        turned = float(np.max(np.abs(self.w * (st.qd - s.qd - dt * s.qdd)))) * abs(dt)
        if turned > JUMP_RATIO * move + JUMP_FLOOR:  # the velocities of another branch
            return None
        return st

    def advance(self, s: _State, t: float, max_halvings: int) -> _State | None:
        """Continue from ``s`` to ``t`` (either direction), halving the step where needed (None: cannot)."""
        span = t - s.t
        h = span
        min_h = abs(span) / 2**max_halvings
        cur = s
        while (t - cur.t) * span > 0:
            t_next = t if abs(t - cur.t) <= abs(h) * (1 + 1e-12) else cur.t + h
            nxt = self.step(cur, t_next)
            if nxt is None:
                if abs(h) <= min_h:
                    return None
                h *= 0.5
                continue
            cur = nxt
            if nxt.iters <= 4:  # an easy step: try a longer one next
                h = span if abs(2 * h) >= abs(span) else 2 * h
        return cur


def _assembly_time(mech: Mechanism) -> float:
    """The instant the coordinates describe: t = 0 (or a profile's first time if it starts later)."""
    starts = [float(d.profile.t[0]) for d in mech.drivers if d.profile is not None and d.profile.t[0] > 0]
    return max(starts) if starts else 0.0


def _driver_text(mech: Mechanism, t: float) -> str:
    """The drivers' input values at ``t``, e.g. "θ_l2 = 2.4312 rad (139.2974°)" (angles in [0°, 360°))."""
    x, _, _ = evaluate_all(mech, np.array([t]))
    return ", ".join(d.value_text(x[0, i], mech.units, 6) for i, d in enumerate(mech.drivers))


def _assemble(kin: _Kinematics, mech: Mechanism, t0: float, engine: str, times: np.ndarray) -> _State:
    """Assemble at ``t0`` from the file coordinates with the drivers at their t0 values."""
    for inp in kin.model.driver_inputs:
        inp.prefetch(np.array([t0]))
    q, ok, it = kin.newton(np.zeros(kin.n), t0, max_iter=100, damped=True)
    if ok:
        st = kin.state(q, t0, it)
        if np.all(np.isfinite(st.qdd)):
            return st
    empty = _result(
        mech, engine, kin.model, times[:0], np.zeros((0, kin.n)), np.zeros((0, kin.n)), np.zeros((0, kin.n))
    )
    raise MotionError(
        f"{mech.name}: {engine}: cannot assemble the mechanism at t = {t0:g} s ({_driver_text(mech, t0)}): "
        "Newton on Exudyn's constraint equations did not converge from the file coordinates",
        time=t0,
        sample=0,
        driver_value=evaluate_all(mech, np.array([t0]))[0][0],
        partial=empty,
    )


def _solve_kinematic(
    mech: Mechanism, times: np.ndarray, tol: float = 1e-12, max_iter: int = 25, max_halvings: int = 14
) -> Result:
    engine = ENGINES["kinematic"]
    model = em.build(mech)
    kin = _Kinematics(model, tol=tol, max_iter=max_iter)
    for inp in model.driver_inputs:
        inp.prefetch(times)
    state = _assemble(kin, mech, _assembly_time(mech), engine, times)
    if (tol, max_iter, max_halvings) != (1e-12, 25, 14):
        return _track(kin, mech, times, state, engine, max_halvings)
    try:
        res = _track(kin, mech, times, state, engine, max_halvings)
    except MotionError as exc:
        _LAST.keep(mech, times, exc.partial)
        raise
    _LAST.keep(mech, times, res)
    return res


class _LastPass:
    """Exudyn's last kinematic solution in this process (default options), up to a limit if the motion stops.

    The dynamic mode's kinematic pass (its step's rate Ω and its conditioning κ) over the same mechanism and times
    is the same computation — the same model, assembly and continuation, Exudyn's own numbers — so a validation task
    that runs exudyn-kinematic then exudyn-dynamic on one mechanism does it once (bit for bit the same Result).
    Holding the Mechanism itself keeps the identity test sound (its id cannot be reused while it is held)."""

    def __init__(self) -> None:
        self.mech: Mechanism | None = None
        self.times = np.zeros(0)
        self.result: Result | None = None

    def keep(self, mech: Mechanism, times: np.ndarray, result: Result) -> None:
        self.mech, self.times, self.result = mech, np.array(times, float), result

    def recall(self, mech: Mechanism, times: np.ndarray) -> Result | None:
        same = self.mech is mech and self.times.shape == np.shape(times) and np.array_equal(self.times, times)
        return self.result if same else None


_LAST = _LastPass()


def _track(
    kin: _Kinematics, mech: Mechanism, times: np.ndarray, state: _State, engine: str, max_halvings: int = 14
) -> Result:
    """Every sample by continuation from the assembled ``state`` (MotionError with the samples before a failure)."""
    model = kin.model
    n = kin.n
    Q, QD, QDD = (np.zeros((len(times), n)) for _ in range(3))
    jacs: list[np.ndarray] = []
    iters = np.zeros(len(times))

    def kappa() -> np.ndarray:  # the samples' condition numbers in one batch (health, round-off bounds)
        return condition_numbers(np.asarray(jacs), ~kin.rot, kin.size) if jacs else np.zeros(0)

    for k, t in enumerate(times):
        nxt = state if abs(t - state.t) <= 1e-14 * max(1.0, abs(t)) else kin.advance(state, float(t), max_halvings)
        if nxt is None:
            partial = _result(mech, engine, model, times[:k], Q[:k], QD[:k], QDD[:k], kappa(), iters[:k])
            raise MotionError(
                f"{mech.name}: {engine}: cannot assemble sample {k} at t = {t:.6g} s ({_driver_text(mech, float(t))}): "
                f"Newton on Exudyn's constraint equations finds no continuation from t = {state.t:.6g} s "
                "(limit position, toggle or branch change)",
                time=float(t),
                sample=k,
                driver_value=evaluate_all(mech, np.array([t]))[0][0],
                partial=partial,
            )
        state = nxt
        Q[k], QD[k], QDD[k], iters[k] = state.q, state.qd, state.qdd, state.iters
        jacs.append(state.jac)
    return _result(mech, engine, model, times, Q, QD, QDD, kappa(), iters)


# ---------------------------------------------------------------- dynamic mode


def _commensurate(times: np.ndarray, t_start: float) -> float | None:
    """The largest spacing Δ such that every sample time is t_start + k·Δ (None if the times are irregular)."""
    pts = np.concatenate([[t_start], times])
    gaps = np.diff(pts)
    gaps = gaps[gaps > 0]
    if gaps.size == 0:
        return None
    base = float(np.min(gaps))
    span = float(pts[-1] - pts[0])
    ratio = (pts - t_start) / base
    if np.max(np.abs(ratio - np.round(ratio))) * base > 1e-9 * max(span, 1.0):
        return None
    return base


def _kinematic_pass(
    mech: Mechanism, times: np.ndarray, kin: _Kinematics | None = None, start: _State | None = None
) -> Result:
    """Exudyn's kinematic solution over ``times`` (up to a limit, if the motion stops), on ``kin``'s model if given
    (the one this process computed last for the same mechanism and times, if any: :class:`_LastPass`)."""
    known = _LAST.recall(mech, times)
    if known is not None:
        return known
    try:
        if kin is None or start is None:
            return _solve_kinematic(mech, times)
        return _track(kin, mech, times, start, ENGINES["kinematic"])
    except MotionError as exc:
        return exc.partial


def _motion_rate(mech: Mechanism, times: np.ndarray, res: Result | None = None) -> float:
    """Characteristic angular rate Ω [rad/s] of the motion, for choosing the time step.

    Ω = max over moving bodies and samples of max(|ω|, sqrt|α|), from a kinematic
    pass (``res``, else one is run); the drivers' own rates (θ̇, or ṡ / size for a slider) also count.
    """
    size = mech.scale
    _, v, a = evaluate_all(mech, times)
    per_driver = [1.0 if d.kind == "crank" else 1.0 / size for d in mech.drivers]
    rate = max(float(np.max(np.abs(v[:, i]) * f, initial=0.0)) for i, f in enumerate(per_driver))
    rate = max(rate, *(float(np.max(np.sqrt(np.abs(a[:, i]) * f), initial=0.0)) for i, f in enumerate(per_driver)))
    if res is None:
        res = _kinematic_pass(mech, times)
    if res is not None and len(res):
        for name in mech.moving_links:
            lk = res.link(name)
            rate = max(rate, float(np.max(np.abs(lk.omega))), float(np.max(np.sqrt(np.abs(lk.alpha)))))
    return rate if rate > 0 else 1.0


def dynamic_step(
    mechanism: Mechanism, times: np.ndarray, accuracy: float = DEFAULT_ACCURACY, rate: float | None = None
) -> float:
    """Generalized-α step h [s] for a target relative acceleration error ``accuracy``.

    With index-3 generalized-α (ρ∞ = 0.6) and prescribed motion the constraints
    fix the positions (exact to the Newton tolerance); velocities and
    accelerations carry an O(h²) error. Measured on the catalog and the test
    mechanisms (tests/test_exudyn.py): acceleration error ≈ C·(Ω h)² of the
    group's peak with C = 0.3 … 4.5 (4.5: jansen_pair) and Ω = max over bodies
    and samples of max(|ω|, sqrt|α|) [rad/s] (from a kinematic pass); velocity
    error ≤ 0.31 × the acceleration error. Hence h = sqrt(accuracy / C) / Ω with
    C = ACC_ERROR_COEFF = 5. Targets below MIN_ACCURACY = 1e-6 are raised to it:
    accelerations come from positions differentiated twice over h, so round-off
    grows like ε·|q|/h² (measured on the eight-bar: 1.1e-6 at h = 1e-4 and 5.3e-6
    over a 10 s run, against 8e-7 at h = 2e-4). h is at most the smallest sample
    spacing and at least span / MAX_STEPS. ``rate`` overrides Ω.

    The run itself may take a smaller step: it must divide the sample grid and
    give MIN_STEPS_TO_SAMPLE = 40 steps before the first sample after t = 0,
    because the integrator starts with a transient (measured ≈ 1e-2 of the
    acceleration peak, damped by ≈ 0.64 per step: 1e-4 after 10 steps, 1e-6
    after 20, gone after 40).
    """
    t = np.asarray(times, float)
    if rate is None:
        rate = _motion_rate(mechanism, t)
    h = math.sqrt(max(accuracy, MIN_ACCURACY) / ACC_ERROR_COEFF) / max(rate, 1e-12)
    if len(t) > 1:
        h = min(h, float(np.min(np.diff(t))))
    span = float(t[-1] - min(t[0], _assembly_time(mechanism)))
    return max(h, span / MAX_STEPS)


# A run another engine disagrees with is integrated again at these targets (steps ≈ h/2, then ≈ h/3.2: the
# finest the round-off floor allows, MIN_ACCURACY) before anything is blamed on it (refine).
REFINE_ACCURACIES = (DEFAULT_ACCURACY / 4, MIN_ACCURACY)


def refine(
    mech: Mechanism, first: Result, stopped: bool, solve_at: Callable[[np.ndarray, float], Result] | None = None
) -> tuple[Result | None, str, str]:
    """Integrate the samples of ``first`` (all the file's if the run ``stopped``) again at finer steps, and estimate
    each run's error from the run before it: generalized-α is second order, so for steps h₁ > h₂ (ρ = h₁/h₂) the
    finer run's error is |r₁ − r₂|/(ρ² − 1) (Richardson). The runs are single ones: where ``first`` is an
    extrapolated pair (whose error is of another order next to a change point, not ρ²'s), its single twin at the
    same accuracy is made first and the estimates start from it. Exudyn's evidence only, never another engine's.

    Returns (run, "", note) for the first finer run that is complete and whose estimate is within its allowance
    (the stated tolerance of validators/tolerances.py plus its own round-off bound); (None, why, note) when none is:
    the estimate stays above the allowance, or every step tried fails at the same sample (Newton rejects it).
    ``solve_at(times, accuracy)``: the run at an accuracy target (default: :func:`solve` in dynamic mode)."""
    from vloop.compare import compare

    from .tolerances import DYNAMIC_STEPS, tolerance

    times = np.asarray(mech.times if stopped else first.t, float)
    budget = 4 * DYNAMIC_STEPS if stopped else None  # a stopped run: the same stretch of time, at most, at h/2
    run = solve_at or (lambda t, acc: solve(mech, t, mode="dynamic", accuracy=acc, max_steps=budget, richardson=False))
    stated = tolerance(ENGINES["dynamic"], "vloop")
    prev, why = first, ""
    if "richardson" in first.meta:  # an extrapolation's error is of another order: estimate from single runs only
        try:
            prev = run(times, float(first.meta.get("accuracy", DEFAULT_ACCURACY)))
        except MotionError as exc:
            k, reason = len(exc.partial), str(exc).split(": ", 2)[-1]
            why = f"its single run fails before sample {k}, where its extrapolated pair went on: {reason}"
            return None, why, "integrated again as a single run at the accuracy's step"
    steps, accuracies = [float(prev.meta.get("step", 0.0))], [float(prev.meta.get("accuracy", DEFAULT_ACCURACY))]
    for acc in REFINE_ACCURACIES:
        try:
            res, failed = run(times, acc), ""
        except MotionError as exc:
            res, failed = exc.partial, str(exc).split(": ", 2)[-1]
        steps.append(float(res.meta.get("step", steps[-1] * math.sqrt(acc / accuracies[-1]))))
        accuracies.append(acc)
        n = min(len(prev), len(res))
        alike = bool(failed) and stopped and len(res) == len(first)  # it stops where it stopped: a limit, not a step
        if alike:
            n = max(int(0.9 * (n - 1)), 0)  # next to a limit every rate grows without bound: as the harness compares
        rho2 = (steps[-2] / steps[-1]) ** 2 if steps[-1] > 0 and steps[-2] > 0 else 4.0
        k = rho2 - 1.0
        scaled = {g: k * v for g, v in stated.as_dict()["rtol"].items()}
        own = {g: k * np.asarray(a, float)[:n] for g, a in (res.meta.get("allowance") or {}).items()}
        est = compare(res.head(n), prev.head(n), scaled, floor=scaled, atol_t=own or None)
        worst = max(est.errors, key=lambda e: e.max_abs / max(e.tol, 1e-300), default=None)
        tried = ", ".join(f"{h:.3g}" for h in steps)
        if failed and not alike:
            why = f"its time integration fails at sample {len(res)} at every step tried (h = {tried} s): {failed}"
        elif worst is not None and not est.passed:
            why = (
                f"its own error estimate (Richardson, runs at h = {tried} s) is {worst.max_abs / worst.tol:.3g}× its "
                f"allowance at t = {worst.t_at_max:.6g} s ({worst.column})"
            )
        else:
            if first.meta.get("budget") and not res.meta.get("budget"):  # the same first samples, by design
                res.meta["budget"] = {**first.meta["budget"], "samples": len(res)}
            return res, "", f"integrated again at h = {steps[-1]:.3g} s (own error estimate within its allowance)"
        prev = res
    return None, why, f"integrated again at h = {', '.join(f'{h:.3g}' for h in steps[1:])} s"


class _Quiet:
    """Silence Exudyn's console output (solver banners, failure reports) for a block."""

    def __enter__(self) -> None:
        import exudyn as exu

        self._was = exu.config.printToConsole
        exu.config.printToConsole = False

    def __exit__(self, *exc: object) -> None:
        import exudyn as exu

        exu.config.printToConsole = self._was


def _plan(
    kin: _Kinematics,
    mech: Mechanism,
    times: np.ndarray,
    t_asm: float,
    step: float,
    start: _State,
    too_fine: Callable[[float], bool],
) -> tuple[list[Segment], float, _State]:
    """The integration runs (start, end, steps, sensor period), the step h [s] and the state to start from.

    Samples on a common grid from t_asm: one run whose step h = spacing / m (m from ``step``). The
    integrator's start-up transient must have died out (MIN_STEPS_TO_SAMPLE steps) by the first sample
    after the start (the one at t_asm is the assembly itself), so h is cut to give those steps. Where that
    cut would take h so small that the index-3 accelerations' round-off (∝ 1/h²) swamps them (``too_fine``:
    samples much closer than the accuracy's step, next to a toggle), the run keeps the accuracy's step and
    starts that many steps *before* t_asm instead, from Exudyn's own kinematic solution continued backwards
    (inputs given by formulas hold for t < 0 too; not a profile's); the sample at t_asm is then an integrated
    one too. Irregular samples: one run per interval.
    """
    base = _commensurate(times, t_asm)
    if base is None:  # irregular samples: one run per interval, each continued from the previous end state
        edges = np.concatenate([[t_asm], times[times > t_asm]])
        segments = []
        for a, b in itertools.pairwise(edges):
            k = max(MIN_STEPS_TO_SAMPLE, math.ceil((b - a) / step - 1e-9))  # each restart has its transient
            segments.append((float(a), float(b), k, float(b - a)))
        return segments, step, start
    m = max(1, math.ceil(base / step - 1e-9))
    later = times[times > t_asm + 0.5 * base]
    first = round((later[0] - t_asm) / base) if later.size else MIN_STEPS_TO_SAMPLE
    t0 = t_asm
    if first * m < MIN_STEPS_TO_SAMPLE:
        cut = math.ceil(MIN_STEPS_TO_SAMPLE / first)
        periods = math.ceil(MIN_STEPS_TO_SAMPLE / m)  # whole sample periods keep the sensors on the grid
        earlier = None
        if too_fine(base / cut) and all(d.profile is None for d in mech.drivers):
            earlier = kin.advance(start, t_asm - periods * base, max_halvings=14)
        if earlier is not None:
            t0, start = t_asm - periods * base, earlier
        else:
            m = cut
    n_steps = round((times[-1] - t0) / base) * m
    return [(t0, float(times[-1]), n_steps, base)], base / m, start


def _within(segments: list[Segment], max_steps: int) -> list[Segment]:
    """The runs cut to about ``max_steps`` steps: whole sample periods (at least one past t = 0), or whole runs."""
    if sum(k for _, _, k, _ in segments) <= max_steps:
        return segments
    if len(segments) == 1:  # one run on the sample grid, perhaps started a few periods before t = 0
        a, b, k, period = segments[0]
        per_period = k / round((b - a) / period)
        keep = max(int(max_steps // per_period), round(max(-a, 0.0) / period) + 1)
        return [(a, a + keep * period, round(keep * per_period), period)]
    kept, total = [], 0
    for seg in segments:
        if kept and total + seg[2] > max_steps:
            break
        kept.append(seg)
        total += seg[2]
    return kept


def _solve_dynamic(
    mech: Mechanism,
    times: np.ndarray,
    step: float | None = None,
    accuracy: float = DEFAULT_ACCURACY,
    spectral_radius: float = SPECTRAL_RADIUS,
    newton_tol: float = 1e-10,
    max_steps: int | None = None,
    richardson: bool | None = None,
) -> Result:
    engine = ENGINES["dynamic"]
    t_asm = _assembly_time(mech)
    if times[0] < t_asm:
        raise ValueError(
            f"{mech.name}: {engine} integrates forward from the assembly at t = {t_asm:g} s; "
            f"the first sample (t = {times[0]:g} s) is before it"
        )
    model = em.build(mech)
    kin = _Kinematics(model)
    start = _assemble(kin, mech, t_asm, engine, times)
    for inp in model.driver_inputs:
        inp.prefetch(times)
    passed = _kinematic_pass(mech, times, kin, start)  # the step's rate Ω and the conditioning κ
    requested = len(times)
    if richardson is None:
        richardson = step is None
    if step is None:
        step = dynamic_step(mech, times, accuracy, rate=_motion_rate(mech, times, passed))
    segments, h, head_start = _plan(kin, mech, times, t_asm, step, start, _too_fine(passed, mech, spectral_radius))
    planned = sum(k for _, _, k, _ in segments)
    if max_steps is not None:  # the samples a single run's first max_steps steps reach (the claim says so)
        segments = _within(segments, max_steps)
        times = times[times <= segments[-1][1] + 1e-9 * max(float(times[-1] - t_asm), 1.0)]
    settings = _dynamic_settings(spectral_radius, newton_tol * mech.scale)
    pair = _richardson_plan(segments, step, t_asm) if richardson else None
    res = None
    if pair is not None:
        with contextlib.suppress(MotionError):  # a coarse run failed (a limit, a hard stretch): the single run
            res = _extrapolated(mech, times, pair, head_start, start, settings, passed)  # says where and why
    if res is None:
        model, records = _run(mech, times, segments, head_start, settings, h)
        res = _dynamic_result(mech, engine, model, times, records, complete=True)
        res.meta.update(step=float(h), runs=len(segments))
        res.meta["allowance"] = _roundoff(res, passed, mech.scale, h, spectral_radius)
    res.meta.update(spectral_radius=spectral_radius, accuracy=accuracy)
    if len(res) < requested:
        res.meta["budget"] = {"max_steps": max_steps, "planned_steps": planned, "samples": len(res), "of": requested}
    return res


def _run(
    mech: Mechanism, times: np.ndarray, segments: list[Segment], start: _State, ss: Any, h: float
) -> tuple[em.ExudynModel, _Records]:
    """One time integration of a model of its own over ``segments`` from ``start``: the model and its records."""
    model = em.build(mech)
    grid = np.concatenate([np.linspace(a, b, k + 1) for a, b, k, _ in segments])
    clock = min(segments[0][0], 0.0)  # Exudyn's time starts at 0 or later: a pre-roll before t = 0 runs on t − clock
    for inp in model.driver_inputs:
        if inp.driver.profile is not None:  # a formula's input is evaluated by Exudyn (em.formula_offsets)
            inp.prefetch(grid)
        inp.shift = clock
    with em.formula_offsets(model):
        sensors = _start_from(model, start)
        records = _Records(model, sensors, clock)
        _integrate(mech, model, times, segments, records, ss, h)
    return model, records


@dataclass(frozen=True)
class _Pair:
    """The runs of a Richardson-extrapolated integration: a fine head, and two coarse runs at h and 2h."""

    head: Segment  # the single run's plan, cut where the coarse runs' start-up has died out
    coarse: tuple[Segment, Segment]  # at h and at 2h, from the assembly

    @property
    def t_head(self) -> float:
        """[s] Samples up to here come from the head, later ones from the extrapolation."""
        return self.head[1]

    @property
    def h_head(self) -> float:
        """[s] The head's step."""
        return (self.head[1] - self.head[0]) / self.head[2]

    @property
    def h(self) -> float:
        """[s] The finer coarse run's step."""
        a, b, k, _ = self.coarse[0]
        return (b - a) / k


def _richardson_plan(segments: list[Segment], step: float, t_asm: float) -> _Pair | None:
    """The runs of :func:`_extrapolated` in place of a single run ``segments`` (one run on a common sample grid),
    or None where they would not be cheaper (or the samples are irregular).

    The coarse runs take h = RICHARDSON_FACTOR × ``step`` (rounded so that 2h divides the sample period) and 2h,
    both from the assembly; their start-up transients (MIN_STEPS_TO_SAMPLE steps of the run at 2h) fall in the head,
    whose samples come from the single run's plan, cut there."""
    if len(segments) != 1:
        return None
    t0, t_end, n_single, base = segments[0]
    per_period = n_single / round((t_end - t0) / base)
    m_coarse = max(1, math.ceil(base / (2 * RICHARDSON_FACTOR * step) - 1e-9))  # steps of the run at 2h, a period
    periods = round((t_end - t_asm) / base)
    head = math.ceil(MIN_STEPS_TO_SAMPLE / m_coarse)
    head_steps = round((head + (t_asm - t0) / base) * per_period)
    if head >= periods or head_steps + 3 * m_coarse * periods >= n_single:  # h and 2h cost 1.5 runs at h
        return None
    return _Pair(
        head=(t0, t_asm + head * base, head_steps, base),
        coarse=((t_asm, t_end, 2 * m_coarse * periods, base), (t_asm, t_end, m_coarse * periods, base)),
    )


def _extrapolated(
    mech: Mechanism, times: np.ndarray, pair: _Pair, head_start: _State, start: _State, ss: Any, passed: Result
) -> Result:
    """Rates from two runs at h and 2h, Richardson-extrapolated: r = r_h + (r_h − r_2h)/3 (generalized-α's error is
    O(h²) with a smooth expansion in h; measured 13× to 190× closer to the closed forms, tests/test_exudyn.py);
    positions from the run at h (exact to the Newton tolerance in both). The samples before ``pair.t_head``
    (the coarse runs' start-up) from the fine head run. A MotionError if any run fails."""
    engine = ENGINES["dynamic"]
    head_times = times[times <= pair.t_head + 1e-9 * max(abs(pair.t_head), 1.0)]
    k = len(head_times)
    model, fine = _run(mech, times, [pair.coarse[0]], start, ss, pair.h)
    coarse = _run(mech, times, [pair.coarse[1]], start, ss, 2 * pair.h)[1]
    q, qd_h, qdd_h = _at_samples(mech, engine, times, fine, complete=True)
    _, qd_2h, qdd_2h = _at_samples(mech, engine, times, coarse, complete=True)
    qd, qdd = qd_h + (qd_h - qd_2h) / 3.0, qdd_h + (qdd_h - qdd_2h) / 3.0
    if k:  # samples in the coarse runs' start-up: the head run's
        rec = _run(mech, head_times, [pair.head], head_start, ss, pair.h_head)[1]
        q[:k], qd[:k], qdd[:k] = _at_samples(mech, engine, head_times, rec, complete=True)
    res = _result(mech, engine, model, times, q, qd, qdd)
    steps = (pair.head[2] if k else 0) + pair.coarse[0][2] + pair.coarse[1][2]
    res.meta.update(step=float(pair.h), runs=3 if k else 2)
    res.meta["richardson"] = {"steps": [float(pair.h), 2 * float(pair.h)], "head_step": float(pair.h_head),
                              "head_samples": k, "total_steps": steps}  # fmt: skip
    rho = ss.timeIntegration.generalizedAlpha.spectralRadius
    res.meta["allowance"] = _extrapolated_roundoff(res, passed, mech.scale, pair, k, rho)
    return res


def _integrate(
    mech: Mechanism,
    model: em.ExudynModel,
    times: np.ndarray,
    segments: list[Segment],
    records: _Records,
    ss: Any,
    h: float,
) -> None:
    """Exudyn's time integration over each run (start, end, steps, sensor period), its sensors gathered after each;
    a MotionError with the samples (of ``times``) recorded before a failure."""
    for a, b, k, period in segments:
        ss.timeIntegration.startTime = a - records.clock
        ss.timeIntegration.endTime = b - records.clock
        ss.timeIntegration.numberOfSteps = k
        ss.solution.sensors.writePeriod = period
        try:
            with _Quiet():
                model.mbs.SolveDynamic(ss, updateInitialValues=True, showHints=False, showCausingItems=False)
        except Exception as exc:  # Exudyn raises SolverError (or another ExudynError) when Newton fails
            records.collect()
            raise _integration_failed(mech, ENGINES["dynamic"], model, times, records, h, exc) from None
        records.collect()


def _start_from(model: em.ExudynModel, start: _State) -> list[list[int]]:
    """The initial state from the (pre-rolled) assembly, the sensors, the assembled system; the sensors' ids."""
    import exudyn as exu

    mbs = model.mbs
    for bm in model.moving.values():  # positions and velocities are node parameters ...
        mbs.SetNodeParameter(bm.node, "initialCoordinates", start.q[bm.ode2].tolist())
        mbs.SetNodeParameter(bm.node, "initialVelocities", start.qd[bm.ode2].tolist())
    sensors = _sensors(model)
    mbs.Assemble()
    # ... the accelerations come from the same constraint equations (Exudyn's own initial-acceleration solve
    # ignores the time dependence of the driver user functions, i.e. a driver's own acceleration)
    mbs.systemData.SetODE2Coordinates_tt(start.qdd.tolist(), configuration=exu.ConfigurationType.Initial)
    return sensors


def _sensors(model: em.ExudynModel) -> list[list[int]]:
    """Node sensors kept in memory: coordinates, their rates and accelerations of every moving body."""
    import exudyn as exu
    from exudyn.itemInterface import SensorNode

    def sensor(node: int, kind: Any) -> int:
        item = SensorNode(nodeNumber=node, storeInternal=True, writeToFile=False, fileName="", outputVariableType=kind)
        return int(model.mbs.AddSensor(item))

    kinds = (exu.OutputVariableType.Coordinates, exu.OutputVariableType.Coordinates_t)
    kinds += (exu.OutputVariableType.Coordinates_tt,)
    return [[sensor(bm.node, kind) for bm in model.moving.values()] for kind in kinds]


def _dynamic_settings(spectral_radius: float, newton_tol: float) -> Any:
    """Index-3 generalized-α with a fixed step, Newton on every iteration's Jacobian."""
    import exudyn as exu

    ss = _settings()
    ti = ss.timeIntegration
    ti.generalizedAlpha.spectralRadius = spectral_radius
    ti.generalizedAlpha.useIndex2Constraints = False
    ti.generalizedAlpha.useNewmark = False
    ti.generalizedAlpha.computeInitialAccelerations = False
    # Newton's error from its coordinate increments (residualMode 1), not from the residual: the
    # residual mixes forces and lengths whose size depends on the file's units (a mm mechanism's
    # residual cannot reach a fixed tolerance), the increment is a length [file units] or an angle
    ti.newton.residualMode = 1
    ti.newton.relativeTolerance = newton_tol
    ti.newton.absoluteTolerance = newton_tol
    ti.newton.useModifiedNewton = False
    ti.adaptiveStep = False
    ti.automaticStepSize = False
    # Exudyn's Eigen-based dense LU: the same solution to round-off as its own default dense solver, a
    # third less time a step (factorization is ~30 % of a step of a planar linkage's ~20 unknowns)
    ss.linearSolver.solverType = exu.LinearSolverType.EigenDense
    return ss


class _Records:
    """The sensors' rows gathered after each run: times (on vloop's clock) and q, q̇, q̈ of every body."""

    def __init__(self, model: em.ExudynModel, sensors: list[list[int]], clock: float) -> None:
        self.model, self.sensors, self.clock = model, sensors, clock
        self.t: list[np.ndarray] = []
        self.rows: list[list[np.ndarray]] = [[], [], []]

    def collect(self) -> None:
        mbs, bodies, n = self.model.mbs, list(self.model.moving.values()), self.model.n_ode2
        data = [[np.asarray(mbs.GetSensorStoredData(s)) for s in group] for group in self.sensors]
        if data[0][0].ndim != 2 or data[0][0].shape[0] == 0:
            return
        nr = min(arr.shape[0] for group in data for arr in group)
        self.t.append(data[0][0][:nr, 0] + self.clock)
        for kind, group in enumerate(data):
            block = np.zeros((nr, n))
            for bm, arr in zip(bodies, group, strict=True):
                block[:, bm.ode2] = arr[:nr, 1:4]
            self.rows[kind].append(block)


def _integration_failed(
    mech: Mechanism, engine: str, model: em.ExudynModel, times: np.ndarray, records: _Records, h: float, exc: Exception
) -> MotionError:
    """The MotionError of a time integration that stopped, with the samples recorded before it."""
    partial = _dynamic_result(mech, engine, model, times, records, complete=False)
    partial.meta["step"] = float(h)  # what was tried, for a second look's account
    k_fail = len(partial)
    t_fail = float(times[min(k_fail, len(times) - 1)])
    reason = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
    return MotionError(
        f"{mech.name}: {engine}: Exudyn's time integration (h = {h:.3g} s) failed before sample {k_fail} "
        f"at t = {t_fail:.6g} s ({_driver_text(mech, t_fail)}): {reason}",
        time=t_fail,
        sample=k_fail,
        driver_value=evaluate_all(mech, np.array([t_fail]))[0][0],
        partial=partial,
    )


def _too_fine(passed: Result, mech: Mechanism, spectral_radius: float) -> Callable[[float], bool]:
    """Whether a step h [s] makes the accelerations' round-off bound (tolerances.integrator_roundoff) more than
    a tenth of what the stated tolerance allows them, judged on the kinematic pass (its peaks and κ)."""
    from .tolerances import tolerance

    allowed = tolerance(ENGINES["dynamic"], "vloop").rtol

    def fine(h: float) -> bool:
        bound = _roundoff(passed, passed, mech.scale, h, spectral_radius)
        for group in ("acceleration", "angular acceleration"):
            cols = [
                c for c in passed.columns if c.endswith((".ax", ".ay", ".a") if group == "acceleration" else ".alpha")
            ]
            peak = max((float(np.max(np.abs(passed[c]), initial=0.0)) for c in cols), default=0.0)
            if len(bound[group]) and np.max(bound[group]) > 0.1 * allowed[group] * peak:  # type: ignore[index]
                return True
        return False

    return fine


def _extrapolated_roundoff(
    res: Result, passed: Result, size: float, pair: _Pair, k: int, rho: float
) -> dict[str, np.ndarray]:
    """The round-off of :func:`_extrapolated`'s rates: the head run's for its ``k`` samples, then
    (4/3)·b(h) + (1/3)·b(2h) for r_h + (r_h − r_2h)/3."""
    head = _roundoff(res, passed, size, pair.h_head, rho)
    b_h, b_2h = _roundoff(res, passed, size, pair.h, rho), _roundoff(res, passed, size, 2 * pair.h, rho)
    out = {}
    for g, v in head.items():
        out[g] = np.concatenate([v[:k], (4.0 * b_h[g][k:] + b_2h[g][k:]) / 3.0])
    return out


def _roundoff(res: Result, passed: Result, size: float, h: float, spectral_radius: float) -> dict[str, np.ndarray]:
    """The rates' round-off per sample (tolerances.integrator_roundoff) from Exudyn's own conditioning κ."""
    kappa = np.asarray(passed.health.get("cond", np.zeros(0)), float)
    kappa = np.pad(kappa, (0, max(0, len(res) - len(kappa))), mode="edge") if len(kappa) else np.zeros(len(res))

    def peak(ends: tuple[str, ...]) -> float:
        return max((float(np.max(np.abs(res[c]), initial=0.0)) for c in res.columns if c.endswith(ends)), default=0.0)

    length, angle = peak((".x", ".y")), peak((".theta",))
    return integrator_roundoff(kappa[: len(res)], length, size, angle, h, spectral_radius)


def _dynamic_result(
    mech: Mechanism, engine: str, model: em.ExudynModel, times: np.ndarray, records: _Records, complete: bool
) -> Result:
    """The samples found in the sensor rows (all of them if ``complete``, else the leading ones recorded)."""
    q, qd, qdd = _at_samples(mech, engine, times, records, complete)
    return _result(mech, engine, model, times[: len(q)], q, qd, qdd)


def _at_samples(
    mech: Mechanism, engine: str, times: np.ndarray, records: _Records, complete: bool
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(q, q̇, q̈) at the samples found in the sensor rows (all of them if ``complete``, else the leading ones)."""
    n = records.model.n_ode2
    if records.t:
        t_all = np.concatenate(records.t)
        Q, QD, QDD = (np.concatenate(r) for r in records.rows)
    else:
        t_all = np.zeros(0)
        Q = QD = QDD = np.zeros((0, n))
    span = max(float(times[-1] - min(times[0], 0.0)), 1e-300)
    idx: list[int] = []
    for t in times:
        hits = np.nonzero(np.abs(t_all - t) <= 1e-9 * max(span, 1.0))[0]
        if hits.size == 0:
            if complete:
                raise RuntimeError(f"{mech.name}: {engine}: no sensor record at the sample t = {t:.9g} s")
            break
        idx.append(int(hits[-1]))  # a run restarted at a sample repeats it: take the latest
    ii = np.asarray(idx, int)
    return Q[ii], QD[ii], QDD[ii]


# ---------------------------------------------------------------- output


def _result(
    mech: Mechanism,
    engine: str,
    model: em.ExudynModel,
    times: np.ndarray,
    Q: np.ndarray,
    QD: np.ndarray,
    QDD: np.ndarray,
    cond: np.ndarray | None = None,
    iters: np.ndarray | None = None,
) -> Result:
    """Rigid-body kinematics of every output quantity from the node histories (displacements + reference)."""
    nt = len(times)
    ref = model.reference_vector()
    Qt = Q + ref[None, :]
    bodies = model.bodies

    def node(name: str) -> tuple[np.ndarray, ...]:
        i = model.moving[name].ode2
        return (
            Qt[:, i[0]],
            Qt[:, i[1]],
            Qt[:, i[2]],
            QD[:, i[0]],
            QD[:, i[1]],
            QD[:, i[2]],
            QDD[:, i[0]],
            QDD[:, i[1]],
            QDD[:, i[2]],
        )

    def point_on(body: str, local: tuple[float, float] | np.ndarray) -> tuple[np.ndarray, ...]:
        """(x, y, vx, vy, ax, ay) of a body-fixed point."""
        if body not in model.moving:
            x, y = float(local[0]), float(local[1])
            z = np.zeros(nt)
            return x + z, y + z, z, z.copy(), z.copy(), z.copy()
        c = model.local_rel_com(body, local)
        x, y, th, vx, vy, om, ax, ay, al = node(body)
        cs, sn = np.cos(th), np.sin(th)
        rx, ry = cs * c[0] - sn * c[1], sn * c[0] + cs * c[1]  # R(θ)·c
        return (
            x + rx,
            y + ry,
            vx - om * ry,
            vy + om * rx,
            ax - al * ry - om * om * rx,
            ay + al * rx - om * om * ry,
        )

    links = {}
    for name in mech.moving_links:
        _, _, th, _, _, om, _, _, al = node(name)
        links[name] = (th, om, al)

    points = {}
    for name in mech.tracked_points:
        body = mech.body_of_point(name)
        points[name] = point_on(body, bodies[body].local[name])

    sliders = {}
    for name, sl in mech.sliders.items():
        px, py, pvx, pvy, pax, pay = point_on(name, (0.0, 0.0))  # the block frame origin is its joint
        g = bodies[sl.guide]
        u_loc = em.rot(g.theta0).T @ np.asarray(sl.axis, float)  # the axis in the guide frame
        ox, oy, ovx, ovy, oax, oay = point_on(sl.guide, (0.0, 0.0))  # guide origin (world origin for ground)
        if sl.guide in model.moving:
            _, _, th, _, _, om, _, _, al = node(sl.guide)
        else:
            th, om, al = np.zeros(nt), np.zeros(nt), np.zeros(nt)
        cs, sn = np.cos(th), np.sin(th)
        ux, uy = cs * u_loc[0] - sn * u_loc[1], sn * u_loc[0] + cs * u_loc[1]
        udx, udy = -om * uy, om * ux  # u̇ = ω × u
        uddx, uddy = -al * uy - om * om * ux, al * ux - om * om * uy
        dx, dy = px - ox, py - oy
        dvx, dvy = pvx - ovx, pvy - ovy
        dax, day = pax - oax, pay - oay
        s = dx * ux + dy * uy
        v = dvx * ux + dvy * uy + dx * udx + dy * udy
        a = dax * ux + day * uy + 2 * (dvx * udx + dvy * udy) + dx * uddx + dy * uddy
        sliders[name] = (s, v, a)

    health = {}
    if cond is not None:
        health["cond"] = np.asarray(cond, float)
    if iters is not None:
        health["newton_iterations"] = np.asarray(iters, float)
    return Result.from_arrays(mech.name, engine, times, links=links, points=points, sliders=sliders, health=health)
