"""The equation of motion of a one-input mechanism on its own coordinate q (Lagrange):

    J(q)·q̈ + ½·J′(q)·q̇² = Q(t, q, q̇),

Q the generalized force by virtual work, Q = Σ F·∂r/∂q + Σ M·∂θ/∂q [N·m per rad, or N on a slider]:

* gravity: −V′(q), V = −Σ m·g·r_G;
* the input's torque (constant or tabulated) and its motor line T0·(1 − q̇/ω0), on the input (∂x/∂q = 1);
* the file's [[loads]]: a force F at P, F·∂r_P/∂q; a torque τ on a body, τ·∂θ/∂q;
* springs and dampers on a relative angle or a distance s(q): −k·(s − s_rest)·s′ − c·s′²·q̇.

The state integrated is y = (q, q̇, W_input, W_loads, W_dampers): the three works [J] are quadratures of
their powers along the motion, for the energy balance; positions are never integrated.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..forces import load_values
from ..model import Dynamics, Mechanism, length_factor
from .limits import limit_tables
from .tables import Tables, build


@dataclass
class Model:
    """Everything the right-hand side needs: the tables and the loads as arrays over the channels."""

    mechanism: Mechanism
    dynamics: Dynamics
    tables: Tables
    springs: np.ndarray  # channel index of each spring's s(q)
    stiffness: np.ndarray  # k [N·m/rad or N/m]
    damping: np.ndarray  # c
    rest: np.ndarray  # s at rest [rad or m]
    load_weights: Callable[[float], list[tuple[int, float]]]  # Q_loads = Σ w·d(channel)/dq
    qscale: float  # metres per input unit (1 for a crank)
    ends: tuple = (None, None)  # the tables on u at the lower and upper limits (vloop.dynamics.limits)

    def input_torque(self, t: float, qd: float) -> float:
        """The input's torque [N·m] (force [N] on a slider) at time t [s] and input rate q̇ [SI]."""
        dyn = self.dynamics
        p = dyn.torque_profile
        tq = dyn.torque if p is None else float(np.interp(t, p.t, p.values[:, 0]))
        if dyn.motor is not None:
            stall, speed = dyn.motor
            tq += stall * (1.0 - qd / (speed * self.qscale))
        return tq

    def rhs(self, t: float, y: np.ndarray) -> list[float]:
        """d/dt of (q, q̇, W_input, W_loads, W_dampers)."""
        return self._motion(self.tables, t, y, 1.0)

    def rhs_near(self, side: int) -> Callable[[float, np.ndarray], list[float]]:
        """d/dt of (u, u̇, W_input, W_loads, W_dampers) at the lower (``side`` 0) or upper (1) limit, on its
        tables over u = √|q − q_lim| (vloop.dynamics.limits: q_u = −2σu)."""
        tab, sigma = self.ends[side], (-1.0, 1.0)[side]
        return lambda t, y: self._motion(tab, t, y, -2.0 * sigma * float(y[0]))

    def _motion(self, tab: Tables, t: float, y: np.ndarray, dq: float) -> list[float]:
        """The equation of motion on the tables' coordinate x (q, or u at a limit; dq = dq/dx)."""
        x, xd = float(y[0]), float(y[1])
        v, d = tab.at(x)
        q_spring = q_damp = 0.0
        for i, k, c, rest in self._springs:
            q_spring -= k * (v[i] - rest) * d[i]
            q_damp -= c * d[i] * d[i] * xd
        q_loads = sum(w * d[i] for i, w in self.load_weights(t))
        t_in = self.input_torque(t, dq * xd) * dq
        xdd = (t_in + q_loads + q_spring + q_damp - d[1] - 0.5 * d[0] * xd * xd) / v[0]
        return [xd, xdd, t_in * xd, q_loads * xd, q_damp * xd]

    @property
    def _springs(self) -> list[tuple[int, float, float, float]]:
        rows = self.__dict__.get("_spring_rows")
        if rows is None:
            rows = list(
                zip(
                    self.springs.tolist(),
                    self.stiffness.tolist(),
                    self.damping.tolist(),
                    self.rest.tolist(),
                    strict=True,
                )
            )
            self.__dict__["_spring_rows"] = rows
        return rows


def channels_of(mech: Mechanism, dyn: Dynamics) -> list[tuple[str, tuple]]:
    """The channels the springs and loads act through, named (springs first, then each load's)."""
    out: list[tuple[str, tuple]] = []
    for i, s in enumerate(dyn.springs):
        out.append((f"spring{i}", ("angle", *s.ends) if s.kind == "rotational" else ("length", *s.ends)))
    for i, ld in enumerate(mech.loads):
        if ld.kind == "torque":
            out.append((f"load{i}", ("angle", ld.body, mech.ground)))
        else:
            out += [(f"load{i}.x", ("x", ld.point)), (f"load{i}.y", ("y", ld.point))]
    return out


def compile_model(mech: Mechanism, dyn: Dynamics | None = None) -> Model:
    """The equations of motion of a one-input mechanism with masses (``dyn``: default the file's [dynamics])."""
    dyn = dyn if dyn is not None else (mech.dynamics or Dynamics())
    channels = channels_of(mech, dyn)
    tables = build(mech, channels, dyn.flywheel)
    names = tables.channels.names
    springs = np.array([names.index(f"spring{i}") for i in range(len(dyn.springs))], int)
    x0 = float(mech.drivers[0].x0) * tables.qscale
    at_drawing = tables.at(x0)[0] if tables.lo <= x0 <= tables.hi or tables.period else None
    f = length_factor(mech.units)
    rest = []
    for i, s in enumerate(dyn.springs):
        if s.rest is not None:
            rest.append(s.rest * (f if s.kind == "linear" else 1.0))
        elif at_drawing is not None:
            rest.append(float(at_drawing[springs[i]]))
        else:
            rest.append(0.0)
    k = np.array([s.k for s in dyn.springs], float)
    c = np.array([s.c for s in dyn.springs], float)
    ends = limit_tables(mech, channels, dyn.flywheel, tables)
    weights = _load_weights(mech, names)
    return Model(mech, dyn, tables, springs, k, c, np.array(rest, float), weights, tables.qscale, ends)


def _load_weights(mech: Mechanism, names: tuple[str, ...]) -> Callable[[float], list[tuple[int, float]]]:
    """weights(t): (channel, weight) pairs with Q_loads = Σ weight · d(channel)/dq (constant loads folded once)."""
    fixed = np.zeros(len(names))
    varying = []
    for i, ld in enumerate(mech.loads):
        rows = [names.index(f"load{i}")] if ld.kind == "torque" else [names.index(f"load{i}.{c}") for c in "xy"]
        if ld.profile is None:
            fixed[rows] += np.atleast_1d(np.asarray(ld.value, float))
        else:
            varying.append((rows, ld))
    constant = [(i, float(w)) for i, w in enumerate(fixed) if w != 0.0]
    if not varying:
        return lambda t: constant

    def weights(t: float) -> list[tuple[int, float]]:
        out = list(constant)
        for rows, ld in varying:
            out += zip(rows, np.atleast_1d(load_values(ld, np.array([t]))[0]).tolist(), strict=True)
        return out

    return weights
