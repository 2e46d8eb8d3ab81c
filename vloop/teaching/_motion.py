"""Rigid-body motion of every body, read from a Result (shared by the teaching quantities).

A body's motion is known from one of its points (position and velocity from the Result's
``NAME.x|y|vx|vy`` columns) and its angular velocity ω (``NAME.omega``; the ground's is 0):
the point of the body at world position X moves with v(X) = v_P + j·ω·(X − P) (complex numbers,
j·z turns z by +90°).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..drivers import evaluate, evaluate_all
from ..errors import MechanismError
from ..model import Mechanism, Profile
from ..result import Result


def point(result: Result, name: str) -> np.ndarray:
    """Position of a joint or tracer point as complex numbers [length]."""
    return result[f"{name}.x"] + 1j * result[f"{name}.y"]


def point_velocity(result: Result, name: str) -> np.ndarray:
    """Velocity of a joint or tracer point as complex numbers [length/s]."""
    return result[f"{name}.vx"] + 1j * result[f"{name}.vy"]


def reference_joint(mech: Mechanism, body: str) -> str:
    """The joint a body's motion is read from: its first joint (a block's own joint)."""
    if body in mech.sliders:
        return mech.sliders[body].joint
    return mech.links[body].joints[0]


def omega(mech: Mechanism, result: Result, body: str) -> np.ndarray:
    """Angular velocity of a body [rad/s, CCW +]; 0 for the ground."""
    if body == mech.ground:
        return np.zeros(len(result.t))
    return result[f"{body}.omega"]


def single_driver(mech: Mechanism, what: str) -> None:
    """Raise MechanismError unless the mechanism has exactly one driver (``what`` needs one input)."""
    if len(mech.drivers) != 1:
        raise MechanismError(
            f"{mech.name}: {what} needs exactly one driver (the file has {len(mech.drivers)})", entry="drivers"
        )


def input_rate(mech: Mechanism, result: Result) -> np.ndarray:
    """The single driver's rate at the result's samples [rad/s or length/s]."""
    return evaluate(mech.drivers[0], result.t)[1]


def at_rest(rate: np.ndarray) -> np.ndarray:
    """Samples where an input rate is zero (or so small that ratios to it would overflow)."""
    peak = float(np.max(np.abs(rate), initial=0.0))
    return np.abs(rate) <= 1e-200 * peak if peak > 0 else np.ones(rate.shape, bool)


def unit_rate_result(mech: Mechanism, result: Result) -> Result:
    """The run re-solved through the same input values with a unit input rate at every sample.

    The solver's positions depend on the input values only, and its velocities are linear in the
    input rate, so this Result's velocities are the velocity coefficients d(·)/dx of the run's
    configurations (x the input) — defined where the run's own input is at rest (ẋ = 0), where the
    Result's velocities are all zero and carry no ratio. One driver only. The input follows a cubic
    Hermite profile through the run's input values with unit rates, so it passes the same values.
    """
    single_driver(mech, "a velocity coefficient")
    from .. import solve

    d = mech.drivers[0]
    t = np.asarray(result.t, float)
    if len(t) == 0 or t[0] < 0:
        raise MechanismError(f"{mech.name}: velocity coefficients need samples from t >= 0", entry="time")
    if t[0] > 0:  # walk in from the assembly instant t = 0 on the run's own input
        h = t[1] - t[0] if len(t) > 1 else t[0] / 16
        lead = np.linspace(0.0, t[0], int(min(100_000, max(1, math.ceil(t[0] / h)))) + 1)[:-1]
    else:
        lead = np.zeros(0)
    tt = np.concatenate([lead, t])
    x = evaluate(d, tt)[0]
    profile = Profile(tt, x, np.ones_like(tt), np.zeros_like(tt), source="unit rate")
    driver = dataclasses.replace(d, profile=profile, v0=1.0, a0=0.0)
    unit = solve(dataclasses.replace(mech, drivers=(driver,), times=tt), times=tt)
    return _tail(unit, len(lead)) if len(lead) else unit


def _tail(res: Result, start: int) -> Result:
    return Result(
        res.mechanism,
        res.engine,
        res.t[start:],
        {k: v[start:] for k, v in res.columns.items()},
        {k: v[start:] for k, v in res.health.items()},
        dict(res.meta),
    )


def inputs(mech: Mechanism, result: Result) -> np.ndarray:
    """Driver values at the result's samples, shape (n_samples, n_drivers) [rad or length]."""
    if not mech.drivers:
        return np.zeros((len(result.t), 0))
    return evaluate_all(mech, result.t)[0]
