"""Driver inputs as functions of time: x(t), ẋ(t), ẍ(t) for every driver.

This is part of the mechanism's description (what the user prescribes), so every
engine evaluates the inputs with this one function.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .errors import MechanismError
from .model import Driver, Mechanism, Profile


def evaluate(driver: Driver, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Input value, rate and acceleration at times ``t`` [s].

    Without a profile: x = x0 + v0·t + a0·t²/2. With a profile: one interpolant x(t) through the
    rows, and the rate and acceleration are its derivatives ẋ(t), ẍ(t) (so that every engine, a time
    integrator included, sees one motion, not three tables). At the profile's own times x, ẋ, ẍ are
    the given columns: θ (or s) only, a not-a-knot cubic spline; with ω (or v), a cubic Hermite spline
    (ẍ then jumps at the rows); with ω and α (or v and a), a quintic Hermite spline (C², the columns'
    motion to O(h⁶) for smooth data); with α but no ω, the quintic Hermite spline through the rates of
    the cubic spline at the rows. Two rows that repeat a value with rates of opposite signs (a rocked sweep
    exported as a table: arriving at its extreme, leaving it) are a reversal there: the input rests at that value
    between them (no polynomial overshoot past the table's extreme; :func:`reversals`). Raises MechanismError if
    ``t`` leaves the profile's time range.
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
    xs = _interpolant(p)
    out = [xs(t), xs(t, 1), xs(t, 2)]
    k = np.clip(np.searchsorted(p.t, t), 0, len(p.t) - 1)
    on_row = p.t[k] == t  # the given columns exactly, not the polynomial's round-off
    for values, column in zip(out, (p.x, p.v, p.a), strict=True):
        if column is not None:
            values[on_row] = column[k[on_row]]
    return out[0], out[1], out[2]


def _interpolant(p: Profile) -> Any:
    """The profile's x(t) as a piecewise polynomial (callable as ``xs(t, order)``), built once per profile."""
    hit = _BUILT.get(id(p))
    if hit is not None and hit[0] is p:
        return hit[1]
    from scipy.interpolate import CubicHermiteSpline, CubicSpline, PPoly  # only profiles need scipy (slow import)

    if p.a is None:
        xs = CubicSpline(p.t, p.x) if p.v is None else CubicHermiteSpline(p.t, p.x, p.v)
    else:
        v = CubicSpline(p.t, p.x)(p.t, 1) if p.v is None else p.v
        xs = PPoly(_quintic_hermite(p.t, p.x, v, p.a), p.t)
    rest = reversals(p)
    if rest.any():  # (a copy of the coefficients: the spline's own are not written to)
        xs = PPoly(xs.c.copy(), xs.x)
        xs.c[:, rest] = 0.0
        xs.c[-1, rest] = p.x[:-1][rest]
    if len(_BUILT) >= 64:
        _BUILT.clear()
    _BUILT[id(p)] = (p, xs)  # the profile is kept alive with it, so its id is not reused
    return xs


_BUILT: dict[int, tuple[Profile, Any]] = {}


REPEAT_RTOL = 1e-12  # two rows' values this close (of the larger of |x| and the profile's range) repeat a value


def reversals(p: Profile) -> np.ndarray:
    """Per interval between rows: whether its two rows repeat a value with given rates of opposite signs — the
    input arrives at an extreme and leaves it (how a rocked sweep is exported: its extreme row twice, ω before and
    after the reversal). Any polynomial through both rates overshoots past that value between them (by about
    |ω|·Δt/4: the table's extreme is not where the input turns); the input rests at the value instead."""
    if p.v is None or len(p.x) < 2:
        return np.zeros(max(len(p.x) - 1, 0), bool)
    scale = np.maximum(np.maximum(np.abs(p.x[:-1]), np.abs(p.x[1:])), np.ptp(p.x))
    return (np.abs(np.diff(p.x)) <= REPEAT_RTOL * scale) & (p.v[:-1] * p.v[1:] < 0)


def _quintic_hermite(t: np.ndarray, x: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """PPoly coefficients (highest power first) of the quintic through x, ẋ, ẍ at both ends of every interval."""
    h = np.diff(t)
    x0, x1, v0, v1, a0, a1 = x[:-1], x[1:], v[:-1], v[1:], a[:-1], a[1:]
    dx = x1 - x0
    c3 = (20 * dx - (8 * v1 + 12 * v0) * h - (3 * a0 - a1) * h**2) / (2 * h**3)
    c4 = (-30 * dx + (14 * v1 + 16 * v0) * h + (3 * a0 - 2 * a1) * h**2) / (2 * h**4)
    c5 = (12 * dx - 6 * (v1 + v0) * h - (a0 - a1) * h**2) / (2 * h**5)
    return np.stack([c5, c4, c3, 0.5 * a0, v0, x0])


def polynomial(x0: Any, v0: Any, a0: Any, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """x = x0 + v0·t + a0·t²/2 and ẋ = v0 + a0·t [rad or length; per s]: an input given by its numbers (arrays
    broadcast against t: one set of numbers per variant)."""
    return x0 + v0 * t + 0.5 * a0 * t * t, v0 + a0 * t


def evaluate_all(mech: Mechanism, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Arrays of shape (len(t), n_drivers): inputs, rates, accelerations."""
    cols = [evaluate(d, t) for d in mech.drivers]
    return tuple(np.stack([c[i] for c in cols], axis=1) for i in range(3))  # type: ignore[return-value]
