"""Sweep the whole feasible range of a one-input mechanism, reversing the input at its limits.

A non-Grashof input cannot turn fully: it stops at a limit position (coupler and follower in
line). :func:`sweep` finds both limits by running the input forward and backward from the t = 0
assembly (each limit located by the solver's bisection), then drives the input as a rocking
motion θ0 → upper limit → lower limit → θ0 at constant speed, stopping ``margin`` short of
each limit, and solves it — on the assembly branch of the t = 0 coordinates throughout.
An input that turns fully (a crank) is swept over one turn.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .compiler import compile_system
from .core.solver import solve
from .errors import MechanismError, MotionError
from .model import Driver, Mechanism, Profile
from .result import Result

SEARCH_STEPS = 720  # samples per turn (crank) or per 2 mechanism sizes (slider) while looking for limits


def feasible_range(mech: Mechanism) -> tuple[float, float, bool]:
    """(lower, upper, full_turn): the input's limits reachable from its t = 0 value."""
    if len(mech.drivers) != 1:
        raise MechanismError(
            f"{mech.name}: a sweep needs exactly one driver (has {len(mech.drivers)})", entry="drivers"
        )
    d = mech.drivers[0]
    x0 = float(_inputs_at_zero(mech))
    span = 2 * math.pi if d.kind == "crank" else 2 * mech.scale
    limits = []
    for direction in (+1.0, -1.0):
        probe = _constant_speed(mech, x0, direction * span, SEARCH_STEPS)
        try:
            solve(compile_system(probe))
            limits.append(None)
        except MotionError as exc:
            if exc.limit_value is None:
                raise
            limits.append(float(exc.limit_value[0]))
    hi, lo = limits
    if hi is None and lo is None and d.kind == "crank":
        return x0, x0 + 2 * math.pi, True
    if hi is None or lo is None:
        raise MechanismError(
            f"{mech.name}: the input {d.symbol} is limited on one side only within ±{span:.4g}: "
            "nothing to rock between",
            entry="drivers",
        )
    return lo, hi, False


def rocking(mech: Mechanism, *, speed: float | None = None, samples: int = 801, margin: float = 1e-3) -> Mechanism:
    """The mechanism with its input rocking over its feasible range (one turn if it turns fully).

    ``speed``: |input rate| (default: the driver's |v0|, else 1 per second); ``margin``: how far short
    of each limit to reverse, as a fraction of the range. The input runs x0 → upper → lower → x0
    at constant speed, as a tabulated profile (rates given, so the reversals are exact).
    """
    d = mech.drivers[0] if len(mech.drivers) == 1 else None
    lo, hi, full = feasible_range(mech)
    x0 = float(_inputs_at_zero(mech))
    rate = abs(speed if speed is not None else (d.v0 if d is not None and d.v0 else 1.0))
    if full:
        return _constant_speed(mech, x0, 2 * math.pi, samples - 1)
    cut = margin * (hi - lo)
    top, bottom = hi - cut, lo + cut
    if not bottom < x0 < top:
        raise MechanismError(f"{mech.name}: the t = 0 input is within the margin of a limit", entry="drivers")
    knots = np.array([x0, top, bottom, x0])
    t_knots = np.concatenate([[0.0], np.cumsum(np.abs(np.diff(knots)) / rate)])
    t = np.unique(np.concatenate([np.linspace(0.0, t_knots[-1], samples), t_knots]))
    x = np.interp(t, t_knots, knots)
    v = np.where(t < t_knots[1], rate, np.where(t < t_knots[2], -rate, rate))
    profile = Profile(t, x, v, np.zeros_like(t), source="sweep")
    driver = dataclasses.replace(mech.drivers[0], x0=x0, v0=0.0, a0=0.0, profile=profile)
    return dataclasses.replace(mech, drivers=(driver,), times=t, options=dict(mech.options, sweep=(lo, hi)))


def sweep(mech: Mechanism, *, speed: float | None = None, samples: int = 801, margin: float = 1e-3) -> Result:
    """Solve :func:`rocking` (``result.meta["sweep"]`` holds the limits found)."""
    rocked = rocking(mech, speed=speed, samples=samples, margin=margin)
    res = solve(compile_system(rocked))
    if "sweep" in rocked.options:
        res.meta["sweep"] = {"lower": rocked.options["sweep"][0], "upper": rocked.options["sweep"][1]}
    return res


def _inputs_at_zero(mech: Mechanism) -> float:
    from .drivers import evaluate

    return float(evaluate(mech.drivers[0], np.zeros(1))[0][0])


def _constant_speed(mech: Mechanism, x0: float, travel: float, steps: int) -> Mechanism:
    """The mechanism with its input moving from x0 by ``travel`` at unit time per unit input."""
    d: Driver = mech.drivers[0]
    driver = dataclasses.replace(d, x0=x0, v0=math.copysign(1.0, travel), a0=0.0, profile=None)
    return dataclasses.replace(mech, drivers=(driver,), times=np.linspace(0.0, abs(travel), steps + 1))
