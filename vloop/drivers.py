"""Driver inputs as functions of time: x(t), ẋ(t), ẍ(t) for every driver.

This is part of the mechanism's description (what the user prescribes), so every
engine evaluates the inputs with this one function.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import MechanismError
from .model import Driver, Mechanism


def evaluate(driver: Driver, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Input value, rate and acceleration at times ``t`` [s].

    Without a profile: x = x0 + v0·t + a0·t²/2. With a profile: values at the
    profile's own times are used as given; between them θ (or s) follows a cubic
    Hermite spline through the given rates when the profile has them, else a
    not-a-knot cubic spline, and rates/accelerations are its derivatives unless
    the profile gives them (then they are interpolated the same way).
    Raises MechanismError if ``t`` leaves the profile's time range.
    """
    t = np.asarray(t, float)
    p = driver.profile
    if p is None:
        x, v = polynomial(driver.x0, driver.v0, driver.a0, t)
        return x, v, np.full_like(t, driver.a0)
    lo, hi = p.t[0], p.t[-1]
    span = hi - lo
    bad = (t < lo - 1e-12 * span) | (t > hi + 1e-12 * span)
    if np.any(bad):
        k = int(np.argmax(bad))
        raise MechanismError(
            f"[{driver.entry}] time t = {t[k]:g} s is outside the profile's range [{lo:g}, {hi:g}] s",
            entry=driver.entry,
            time=float(t[k]),
        )
    from scipy.interpolate import CubicHermiteSpline, CubicSpline  # only profiles need scipy (slow import)

    if p.v is not None:
        xs = CubicHermiteSpline(p.t, p.x, p.v)
        if p.a is not None:
            vs = CubicHermiteSpline(p.t, p.v, p.a)
            return xs(t), vs(t), vs(t, 1)
        return xs(t), xs(t, 1), xs(t, 2)
    xs = CubicSpline(p.t, p.x)
    x, v, a = xs(t), xs(t, 1), xs(t, 2)
    if p.a is not None:
        a = CubicSpline(p.t, p.a)(t)
    return x, v, a


def polynomial(x0: Any, v0: Any, a0: Any, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x = x0 + v0·t + a0·t²/2 and ẋ = v0 + a0·t [rad or length; per s]: an input given by its numbers (arrays
    broadcast against t: one set of numbers per variant)."""
    return x0 + v0 * t + 0.5 * a0 * t * t, v0 + a0 * t


def evaluate_all(mech: Mechanism, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arrays of shape (len(t), n_drivers): inputs, rates, accelerations."""
    cols = [evaluate(d, t) for d in mech.drivers]
    return tuple(np.stack([c[i] for c in cols], axis=1) for i in range(3))  # type: ignore[return-value]
