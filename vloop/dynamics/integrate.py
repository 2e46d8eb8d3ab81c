"""Forward dynamics: integrate (q, q̇) with scipy's solve_ivp, then recover every position by the loop solve.

    sim = vloop.simulate(mech)               # the file's [dynamics] and [time] rows
    sim.result["l4.theta"], sim.energy["residual"], sim.result["l2.torque"]

The rows' kinematics are vloop's run with the integrated input as a tabulated driver (x, ẋ, ẍ at every
row), so every column, health and message is the kinematic run's. The energy table compares, at every
row, the kinetic energy and the potentials computed from those exact kinematics with the works
integrated along the motion: residual = (T + V) − (T₀ + V₀) − (W_input + W_loads + W_dampers).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import MechanismError, MotionError
from ..model import Dynamics, Mechanism, Profile, length_factor
from ..result import Result
from .equations import Model, compile_model
from .limits import ENTER, from_u, to_u
from .tables import G_PREFIX, augmented

ENERGY_COLUMNS = ("kinetic", "gravity", "springs", "work_input", "work_loads", "work_dampers", "residual")


@dataclass
class Simulation:
    """A simulated motion: ``result`` (every link and point, health, the input's torque column
    ``INPUT.torque`` [N·m] or ``INPUT.force`` [N]), ``energy`` (columns of ENERGY_COLUMNS [J] over ``t``),
    ``turns`` (times [s] at which the input has turned by a whole turn from its start, a crank's), the model,
    and ``message``: why the run stopped early ("" if it reached the last row)."""

    mechanism: Mechanism
    result: Result
    energy: dict[str, np.ndarray]
    model: Model
    turns: np.ndarray = field(default_factory=lambda: np.zeros(0))
    message: str = ""
    ode: Any = None  # solve_ivp's answer (its dense output: ``ode.sol``)

    @property
    def t(self) -> np.ndarray:
        return self.result.t

    @property
    def stop(self) -> tuple[float, float] | None:
        """(t [s], the input there [its units]) where the motion reached a limit position, else None."""
        return getattr(self.ode, "stop", None)


def simulate(
    mech: Mechanism, times: np.ndarray | None = None, *, dynamics: Dynamics | None = None, **changes: Any
) -> Simulation:
    """The motion of a one-input mechanism under its loads from its state at t = 0, at ``times`` [s] ≥ 0
    (default: [dynamics] stop and step, else the file's [time]). ``dynamics``: instead of the file's
    [dynamics]; ``changes``: fields of it replaced (e.g. ``flywheel=0.05``, ``method="Radau"``). Raises
    MotionError (``.partial``: the Simulation up to the stop) when the motion reaches a limit of the input."""
    dyn = dynamics if dynamics is not None else (mech.dynamics or Dynamics())
    dyn = dataclasses.replace(dyn, **changes) if changes else dyn
    _check(mech)
    times = np.asarray(_rows(mech, dyn) if times is None else times, float)
    if len(times) == 0 or times[0] < 0 or np.any(np.diff(times) <= 0):
        raise MechanismError(f"{mech.name}: [time] for a simulation: increasing times from t ≥ 0", entry="time")
    if len(mech.drivers) == 2:
        return _simulate_two(mech, dyn, times)
    model = compile_model(mech, dyn)
    ode, message = _integrate(model, times)
    sim = _outputs(model, ode, message)
    if message:
        err = MotionError(message, entry="dynamics", time=float(sim.t[-1]) if len(sim.t) else 0.0, partial=sim)
        if sim.stop is not None:  # as the kinematic run's: where the limit was reached
            err.limit_time, err.limit_value = sim.stop[0], [sim.stop[1]]
        raise err
    return sim


def _rows(mech: Mechanism, dyn: Dynamics) -> np.ndarray:
    """The simulated rows: 0, step, … stop of [dynamics], else the file's [time]."""
    if dyn.stop is None or dyn.step is None:
        return mech.times
    from ..files.fileformat import time_grid

    return time_grid(0.0, dyn.step, math.floor(dyn.stop / dyn.step + 0.5) + 1)


def _check(mech: Mechanism) -> None:
    """One or two inputs and known units: else a MechanismError naming what is missing."""
    if len(mech.drivers) not in (1, 2):
        raise MechanismError(
            f"{mech.name}: forward dynamics needs one or two inputs (this mechanism has {len(mech.drivers)} drivers)",
            entry="dynamics",
        )
    try:
        length_factor(mech.units)
    except KeyError:
        raise MechanismError(
            f"{mech.name}: dynamics needs a known length unit, got {mech.units!r}", entry="units"
        ) from None


def initial_state(model: Model) -> tuple[float, float]:
    """(q0, q̇0) [SI]: the [dynamics] position and rate, else the driver's at t = 0."""
    d, dyn = model.mechanism.drivers[0], model.dynamics
    x = dyn.position if dyn.position is not None else d.x0
    v = dyn.rate if dyn.rate is not None else d.v0
    return float(x) * model.qscale, float(v) * model.qscale


@dataclass
class Motion:
    """The integrated motion on q over its pieces: solve_ivp's answers on q, or on u = √|q − q_lim| at a limit
    (``side`` 0 lower, 1 upper; None on q). ``t``, ``y`` (q, q̇ and the works, SI) and ``qdd`` at the rows."""

    model: Model
    pieces: list[tuple[int | None, Any]]
    t: np.ndarray = field(init=False)
    y: np.ndarray = field(init=False)
    qdd: np.ndarray = field(init=False)
    stop: tuple[float, float] | None = None  # (t [s], the input [its units]) where the motion reached a limit

    def __post_init__(self) -> None:
        rows = [self._rows(side, ode.t, ode.y) for side, ode in self.pieces]
        self.t = np.concatenate([ode.t for _, ode in self.pieces])
        self.y = np.concatenate([r[0] for r in rows], axis=1) if rows else np.zeros((5, 0))
        self.qdd = np.concatenate([r[1] for r in rows]) if rows else np.zeros(0)

    @property
    def nfev(self) -> int:
        """Right-hand side evaluations over the pieces."""
        return sum(int(ode.nfev) for _, ode in self.pieces)

    @property
    def t_events(self) -> list:
        return self.pieces[0][1].t_events

    @property
    def y_events(self) -> list:
        return self.pieces[0][1].y_events

    def sol(self, t: Any) -> np.ndarray:
        """The state (q, q̇, works) at times t [s] from the pieces' dense outputs ((5,) at a scalar t)."""
        scalar = np.ndim(t) == 0
        t = np.atleast_1d(np.asarray(t, float))
        ends = np.array([ode.sol.t_max for _, ode in self.pieces])
        k = np.minimum(np.searchsorted(ends, t), len(self.pieces) - 1)
        out = np.zeros((5, len(t)))
        for i, (side, ode) in enumerate(self.pieces):
            sel = k == i
            if np.any(sel):
                out[:, sel] = self._rows(side, t[sel], ode.sol(t[sel]))[0]
        return out[:, 0] if scalar else out

    def _rows(self, side: int | None, t: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """States (5, n) on q and q̈ at the rows of a piece (converted from u at a limit)."""
        fun = self.model.rhs if side is None else self.model.rhs_near(side)
        acc = np.array([fun(ti, yi)[1] for ti, yi in zip(t, y.T, strict=True)], float)
        if side is None:
            return y, acc
        q_lim, sigma = self.model.tables.limits[side] * self.model.qscale, (-1.0, 1.0)[side]
        q, qd, qdd = from_u(y[0], y[1], acc, q_lim, sigma)
        return np.vstack([q, qd, y[2:]]), qdd


def _integrate(model: Model, times: np.ndarray) -> tuple[Motion, str]:
    """solve_ivp over [0, last row], the rows as t_eval: on q, switching to u = √|q − q_lim| near a limit
    (and back), where the motion stops if it reaches the limit itself (u = 0)."""
    tab = model.tables
    q0, v0 = initial_state(model)
    if tab.limits is not None and not tab.limits[0] * model.qscale < q0 < tab.limits[1] * model.qscale:
        raise MechanismError(
            f"{model.mechanism.name}: the input at t = 0 ({q0 / model.qscale:.10g}) is outside its range "
            f"[{tab.limits[0]:.10g}, {tab.limits[1]:.10g}] (limit positions)",
            entry="dynamics.position",
        )
    t0, y, side = 0.0, [q0, v0, 0.0, 0.0, 0.0], _zone(model, q0)
    if side is not None:
        y[:2] = _to_side(model, side, q0, v0)
    pieces: list[tuple[int | None, Any]] = []
    while True:
        fun, events = _piece(model, side, q0)
        ode = _ivp(model, fun, (t0, float(times[-1])), y, times[times > t0] if pieces else times, events)
        pieces.append((side, ode))
        if ode.status == 0 or tab.period is not None:
            return Motion(model, pieces), ""
        k = 0 if len(ode.t_events[0]) else 1
        t0, y = float(ode.t_events[k][0]), list(ode.y_events[k][0])
        if side is not None and k == 0:  # u = 0: the limit
            motion = Motion(model, pieces)
            q_lim, sigma = tab.limits[side] * model.qscale, (-1.0, 1.0)[side]
            motion.stop = (t0, (q_lim - sigma * y[0] * y[0]) / model.qscale)
            return motion, _limit_message(model, motion)
        if t0 >= float(times[-1]):  # (a switch at the last row: nothing is left to integrate)
            return Motion(model, pieces), ""
        if side is None:
            side = k
            y[:2] = _to_side(model, side, y[0], y[1])
        else:
            q_lim, sigma = tab.limits[side] * model.qscale, (-1.0, 1.0)[side]
            y[:2] = [float(x) for x in from_u(np.float64(y[0]), np.float64(y[1]), np.float64(0.0), q_lim, sigma)[:2]]
            side = None


def _zone(model: Model, q: float) -> int | None:
    """The limit (0 lower, 1 upper) whose tables on u the input's q [SI] is within (None: on q)."""
    lim = model.tables.limits
    if lim is None:
        return None
    for side, sigma in ((0, -1.0), (1, 1.0)):
        if sigma * (lim[side] * model.qscale - q) < ENTER * model.ends[side].hi ** 2:
            return side
    return None


def _to_side(model: Model, side: int, q: float, qd: float) -> list[float]:
    """(u, u̇) at a limit of (q, q̇) [SI]."""
    return list(to_u(q, qd, model.tables.limits[side] * model.qscale, (-1.0, 1.0)[side]))


def _piece(model: Model, side: int | None, q0: float) -> tuple[Any, list]:
    """The right-hand side and the events of a piece: on q, entering either limit's zone (or a whole turn of a
    crank); on u, reaching the limit (u = 0) or leaving the zone (u = u_end)."""
    tab = model.tables
    if tab.limits is None:
        return model.rhs, [lambda t, y: math.sin(0.5 * (y[0] - q0))]  # a whole turn from the start (and back)
    if side is None:
        qs = model.qscale
        lower = lambda t, y: y[0] - tab.limits[0] * qs - ENTER * model.ends[0].hi ** 2  # noqa: E731
        upper = lambda t, y: tab.limits[1] * qs - y[0] - ENTER * model.ends[1].hi ** 2  # noqa: E731
        events = [lower, upper]
    else:
        end = model.ends[side].hi
        events = [lambda t, y: y[0], lambda t, y: y[0] - end]
    for e, direction in zip(events, (-1, -1) if side is None else (-1, 1), strict=True):
        e.terminal, e.direction = True, direction  # type: ignore[attr-defined]
    return (model.rhs if side is None else model.rhs_near(side)), events


def _ivp(model: Model, fun: Any, span: tuple[float, float], y: list[float], rows: np.ndarray, events: list) -> Any:
    """One piece of solve_ivp, at the [dynamics] method and tolerances (the works are not error-controlled)."""
    from scipy.integrate import solve_ivp

    dyn = model.dynamics
    ode = solve_ivp(
        fun, span, y, method=dyn.method, t_eval=rows, rtol=dyn.rtol,
        atol=[dyn.atol, dyn.atol, np.inf, np.inf, np.inf], events=events, dense_output=True,
    )  # fmt: skip
    if ode.status < 0:
        raise MotionError(f"{model.mechanism.name}: the integrator failed: {ode.message}", entry="dynamics")
    return ode


def _limit_message(model: Model, motion: Motion) -> str:
    """The stop at a limit, named as the kinematic run names it."""
    mech, (t, x), rows = model.mechanism, motion.stop, len(motion.t)
    kept = f"{rows} earlier sample{'s' if rows != 1 else ''} kept" if rows else "no sample kept"
    return (
        f"{mech.name}: the motion reaches the input's limit position at t = {t:.10g} s, "
        f"{mech.drivers[0].value_text(x, mech.units)}: the loop cannot close past it; {kept}"
    )


def _outputs(model: Model, ode: Any, message: str) -> Simulation:
    """The rows' exact kinematics (the loop solve with the integrated input), the input's torque, the energy."""
    from .. import solve

    mech, qs = model.mechanism, model.qscale
    t, y = ode.t, ode.y
    qdd = ode.qdd
    d = mech.drivers[0]
    aug = augmented(mech)
    if len(t) == 0:
        result = Result(mech.name, "vloop.simulate", t, {})
        return Simulation(mech, result, {k: np.zeros(0) for k in ENERGY_COLUMNS}, model, message=message, ode=ode)
    lead, profile = _profile(float(d.x0), t, y[0] / qs, y[1] / qs, qdd / qs)
    run = dataclasses.replace(aug, drivers=(dataclasses.replace(d, profile=profile),), times=t + lead, dynamics=None)
    try:
        exact = solve(run, t + lead)
    except MotionError as exc:
        raise MotionError(f"{exc.message} (the simulated motion)", entry="dynamics", time=exc.time) from None
    energy = _energy(model, exact, y)
    torque = np.array([model.input_torque(ti, yi) for ti, yi in zip(t, y[1], strict=True)])
    cols = {k: v for k, v in exact.columns.items() if not k.startswith(G_PREFIX)}
    cols[f"{d.target}.{'torque' if d.kind == 'crank' else 'force'}"] = torque
    meta = {**exact.meta, "dynamics": {"tables_error": model.tables.error, "method": model.dynamics.method}}
    result = Result(mech.name, "vloop.simulate", t, cols, dict(exact.health), meta)
    turns = _whole_turns(ode, model) if model.tables.period is not None else np.zeros(0)
    return Simulation(mech, result, energy, model, np.asarray(turns, float), message, ode)


def _simulate_two(mech: Mechanism, dyn: Dynamics, times: np.ndarray) -> Simulation:
    """A two-input mechanism (vloop.dynamics.twoinput): the rows' exact kinematics with both inputs tabulated as
    integrated (q, q̇, q̈ at every row), and the energy (kinetic and gravity; no work is done on it)."""
    from .. import solve
    from .twoinput import integrate

    model, ode = integrate(mech, dyn, times)
    t, y = ode.t, ode.y
    qdd = np.array([model.rhs(ti, yi)[2:] for ti, yi in zip(t, y.T, strict=True)]).T
    drivers = tuple(
        dataclasses.replace(d, profile=Profile(t, y[i], y[2 + i], qdd[i], source="simulate"))
        for i, d in enumerate(model.aug.drivers)
    )
    exact = solve(dataclasses.replace(model.aug, drivers=drivers, times=t, dynamics=None), t)
    zeros = np.zeros_like(t)
    energy = _energy(model, exact, np.vstack([zeros, zeros, zeros, zeros, zeros]))  # type: ignore[arg-type]
    cols = {k: v for k, v in exact.columns.items() if not k.startswith(G_PREFIX)}
    meta = {**exact.meta, "dynamics": {"method": dyn.method, "calls": model.calls}}
    result = Result(mech.name, "vloop.simulate", t, cols, dict(exact.health), meta)
    return Simulation(mech, result, energy, model, ode=ode)  # type: ignore[arg-type]


def _whole_turns(ode: Any, model: Model) -> np.ndarray:
    """The times [s] the input first reaches each new whole turn from its start (q − q0 = ±2π, ±4π, …): the
    events where the count of turns changes to one not reached before (a swing back through the start is none)."""
    q0 = initial_state(model)[0]
    out, seen = [], {0}
    for t, y in zip(ode.t_events[0], ode.y_events[0], strict=True):
        k = round((y[0] - q0) / model.tables.period)
        if k not in seen:
            seen.add(k)
            out.append(t)
    return np.asarray(out, float)


def _profile(x0: float, t: np.ndarray, x: np.ndarray, v: np.ndarray, a: np.ndarray) -> tuple[float, Profile]:
    """The integrated input as a driver's table (x, ẋ, ẍ at every row) and the rows' delay in it: a run
    starting away from the coordinates' input x0 is led in from x0 (at rest) to its first row, as a late
    start is, over 1 s or the time its initial rate would take, so that the t = 0 assembly is the file's."""
    if abs(x[0] - x0) <= 1e-12 * max(1.0, abs(x0)):
        return 0.0, Profile(t, x, v, a, source="simulate")
    lead = 1.0 if v[0] == 0 else min(1.0, abs(x[0] - x0) / abs(v[0]))
    z = np.zeros(1)
    return lead, Profile(
        np.concatenate([z, t + lead]),
        np.concatenate([[x0], x]),
        np.concatenate([z, v]),
        np.concatenate([z, a]),
        source="simulate",
    )


def _energy(model: Model, exact: Result, y: np.ndarray) -> dict[str, np.ndarray]:
    """Kinetic energy and potentials from the exact kinematics; the works from the integration [J]."""
    mech = model.mechanism
    f = length_factor(mech.units)
    g = mech.gravity or (0.0, 0.0)
    kinetic = 0.5 * model.dynamics.flywheel * y[1] ** 2
    gravity = np.zeros_like(kinetic)
    for b, mp in mech.masses.items():
        p = G_PREFIX + b
        if f"{p}.x" not in exact.columns:
            continue
        vx, vy = exact[f"{p}.vx"] * f, exact[f"{p}.vy"] * f
        kinetic = kinetic + 0.5 * mp.mass * (vx * vx + vy * vy) + 0.5 * mp.inertia * exact[f"{b}.omega"] ** 2
        gravity = gravity - mp.mass * (g[0] * exact[f"{p}.x"] + g[1] * exact[f"{p}.y"]) * f
    springs = np.zeros_like(kinetic)
    for i, s in enumerate(model.dynamics.springs):
        springs = springs + 0.5 * s.k * (_stretch(mech, exact, s, f) - model.rest[i]) ** 2
    works = y[2] + y[3] + y[4]
    total = kinetic + gravity + springs
    residual = total - total[0] - works
    return dict(zip(ENERGY_COLUMNS, (kinetic, gravity, springs, y[2], y[3], y[4], residual), strict=True))


def _stretch(mech: Mechanism, exact: Result, s: Any, f: float) -> np.ndarray:
    """A spring's relative angle θ_a − θ_b [rad] or length |PQ| [m] from the exact kinematics."""
    if s.kind == "rotational":
        a, b = (exact[f"{n}.theta"] if n != mech.ground else 0.0 for n in s.ends)
        return np.asarray(a - b, float)
    p, q = s.ends
    return np.hypot(exact[f"{p}.x"] - exact[f"{q}.x"], exact[f"{p}.y"] - exact[f"{q}.y"]) * f
