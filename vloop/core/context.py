"""What one solve shares besides its state: the system, the inputs, the options, the change points found.

:class:`Run` is handed to every block's solve; probes (a few rows solved again at other times, to locate a
limit or a change point) share its change points. :class:`Solved` is what a pass over the blocks gives;
:class:`Failure` says why a sample cannot be solved.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..drivers import evaluate_all
from ..method.loops import LoopSystem
from ..model import Mechanism
from .data import State
from .plans import block_plans


class Failure(Exception):
    """Why sample ``sample`` cannot be solved; ``loop`` (index) where a loop is to blame. ``at``: where the failure
    was found between rows ``sample`` − 1 and ``sample`` (a time where the loop cannot close, with the drivers'
    values there), when row ``sample`` itself may well close: the input passes a narrow limit gap between them."""

    def __init__(self, sample: int, loop: int | None, why: str, at: tuple[float, np.ndarray] | None = None) -> None:
        self.sample, self.loop, self.why, self.at = sample, loop, why, at


@dataclass
class Inputs:
    """The drivers' values, rates and accelerations at internal grid times.

    From ``t_first`` on: the file's drivers. Before it, a path in input space x0 + u·R with
    u = (t − lead_from)/span: the lead-in of a run that starts late (from the inputs at t = 0
    to those at ``t_first`` less their whole crank turns, see :mod:`vloop.core.solver`), or the one-turn
    probe that measures winding numbers (``t_first`` = ∞).
    """

    mech: Mechanism
    t_first: float = -math.inf
    lead_from: float = 0.0
    span: float = 1.0
    x0: np.ndarray | None = None
    R: np.ndarray | None = None

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, float)
        m = len(self.mech.drivers)
        if m and len(t) and t[0] >= self.t_first:  # (ascending) every time is the file's own: no lead-in path
            return evaluate_all(self.mech, t)
        X, XD, XDD = np.zeros((len(t), m)), np.zeros((len(t), m)), np.zeros((len(t), m))
        if m == 0:
            return X, XD, XDD
        real = t >= self.t_first
        if real.any():
            X[real], XD[real], XDD[real] = evaluate_all(self.mech, t[real])
        if not real.all():
            u = (t[~real] - self.lead_from) / self.span
            X[~real] = self.x0 + u[:, None] * self.R
            XD[~real] = self.R / self.span
        return X, XD, XDD


@dataclass(frozen=True)
class ChangePoint:
    """Where block ``block``'s assembly branches meet (a change point), or where a redundant block's
    Jacobian loses rank on its one smooth branch (kind "singular"), at internal time ``time``."""

    block: int
    time: float
    flip: bool  # whether σ changes there (True on the smooth continuation of a crossing)
    smooth: bool  # whether this continuation is the one whose velocities stay continuous
    kind: str = "change point"


@dataclass
class Run:
    """What one solve needs besides the state arrays; probes share ``events`` with their run."""

    system: LoopSystem
    inputs: Inputs
    scale: float
    tol: float
    max_iter: int
    rtol: float
    events: dict[int, list[ChangePoint]] = field(default_factory=dict)
    detect: bool = True  # look for change points (the main run only)
    check: bool = True  # refuse ill-conditioned samples and branch flips
    rates: bool = True
    newton_sign: dict[int, float] = field(default_factory=dict)  # det sign of each Newton block's t = 0 branch
    tail: bool = True  # the rows end the run (not a chunk followed by another)
    t_start: float = 0.0  # the run's first requested time
    memory_budget: Any = None  # as given to solve() (bytes or text), else from the environment or the file
    sink: Any = None  # solve()'s whole-run output columns, filled chunk by chunk (vloop.core.solver)
    blocks: Callable[..., Any] | None = None  # the solver's block runner, for probes (set by vloop.core.solver)
    chart: Any = None  # the run's chart over its one input, where one is drawn (vloop.core.charts)

    def sigma(self, i: int, t: np.ndarray) -> np.ndarray:
        """Assembly branch (±1) of closed-form block ``i`` at times ``t``: σ at t = 0, flipped after each event."""
        sigma = np.full(len(t), block_plans(self.system)[i].block.sigma)
        flips = [ev.time for ev in self.events.get(i, ()) if ev.flip]
        if flips:  # flipped once for each event before t
            sigma[np.searchsorted(np.sort(flips), t) % 2 == 1] *= -1.0
        return sigma


@dataclass
class Solved:
    n_ok: int
    failure: Failure | None
    conds: list[np.ndarray]
    signs: list[np.ndarray]
    discs: list[np.ndarray]  # closed-form blocks' discriminants h (None for Newton blocks)
    at_change: np.ndarray  # rows whose rates were taken across a change point


def fail(out: Solved, failure: Failure) -> None:
    """Keep the earliest failure; rows from it on are not solved."""
    if failure.sample < out.n_ok:
        out.n_ok, out.failure = failure.sample, failure


def impose_drivers(system: LoopSystem, state: State, X: np.ndarray, XD: np.ndarray, XDD: np.ndarray) -> None:
    na = system.n_angles
    for j, v in enumerate(system.drivers):
        if v < na:
            state.theta[:, v] = X[:, j]
            np.cos(X[:, j], out=state.e[:, v].real)
            np.sin(X[:, j], out=state.e[:, v].imag)
            state.omega[:, v], state.alpha[:, v] = XD[:, j], XDD[:, j]
        else:
            state.s[:, v - na], state.s_dot[:, v - na], state.s_ddot[:, v - na] = X[:, j], XD[:, j], XDD[:, j]


def initial_state(system: LoopSystem, n: int) -> State:
    """A state of n rows whose row 0 is the t = 0 assembly."""
    na, ns = system.n_angles, len(system.slider_names)
    state = State(n, na, ns)
    state.theta[0, :] = system.q0[:na]
    state.e[0, :na] = np.exp(1j * system.q0[:na])
    state.s[0, :ns] = system.q0[na:]
    return state


def input_units(mech: Mechanism, slider_unit: float) -> np.ndarray:
    """What each input's move is measured in: 1 rad for a crank, ``slider_unit`` (a length) for a slider."""
    return np.array([1.0 if d.kind == "crank" else slider_unit for d in mech.drivers])


def change_point_choices(system: LoopSystem, loop_number: int) -> list[str]:
    """``[solver] change_points`` for a loop: "smooth" (default) or "other", or a list for successive ones."""
    spec = system.mechanism.options.get("change_points", {}).get(loop_number, "smooth")
    return [spec] if isinstance(spec, str) else list(spec)
