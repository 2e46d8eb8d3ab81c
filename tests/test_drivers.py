"""Driver inputs (vloop.drivers.evaluate): a tabulated profile is one motion x(t) whose rate and
acceleration are its derivatives, equal to the given columns at the profile's rows.

The reference is independent of the interpolant: the columns themselves at the rows, central finite
differences of x and ẋ between them, and the sine the columns were sampled from.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import vloop
from tests.conftest import MECHANISMS
from validators.analytic import fourbar as analytic_fourbar
from vloop.compare import assert_histories_close
from vloop.drivers import evaluate
from vloop.model import Driver, Profile

AMP, OMEGA, PHASE = 1.6, 6.75, 0.06  # θ(t) = AMP·sin(OMEGA·t + PHASE): a rocking input, as the corpus draws it
ROWS = 77  # as coarse as the corpus's profiles: OMEGA·Δt ≈ 0.08 rad between rows


def _rocking(columns: str) -> Driver:
    t = np.linspace(0.0, 1.4, ROWS)
    arg = OMEGA * t + PHASE
    x, v, a = AMP * np.sin(arg), AMP * OMEGA * np.cos(arg), -AMP * OMEGA**2 * np.sin(arg)
    prof = Profile(t, x, v if "v" in columns else None, a if "a" in columns else None)
    return Driver("crank", "crank", float(x[0]), pivot="O2", profile=prof)


@pytest.mark.parametrize("columns", ["x", "xv", "xva", "xa"])
def test_profile_rates_are_the_derivatives_of_its_angle(columns):
    d = _rocking(columns)
    p = d.profile
    x, v, a = evaluate(d, p.t)
    assert np.array_equal(x, p.x)  # the rows are used as given
    if p.v is not None:
        assert np.array_equal(v, p.v)
    if p.a is not None:
        assert np.allclose(a, p.a, rtol=0, atol=1e-12 * np.max(np.abs(p.a)))
    # between the rows (farther from them than the stencil: a spline's higher derivatives jump at its rows,
    # a cubic Hermite's acceleration too): central differences with step d, truncation d²/6 of the third
    # derivative (< 1e-9 of the peak), round-off eps·|x|/d (< 1e-10): the rate is the derivative of the
    # angle, the acceleration that of the rate
    delta = 1e-5
    t = np.linspace(0.01, 1.39, 997)
    t = t[np.min(np.abs(t[:, None] - p.t[None, :]), axis=1) > 2 * delta]
    xp, vp, _ = evaluate(d, t + delta)
    xm, vm, _ = evaluate(d, t - delta)
    x, v, a = evaluate(d, t)
    assert np.max(np.abs((xp - xm) / (2 * delta) - v)) < 1e-7 * AMP * OMEGA
    assert np.max(np.abs((vp - vm) / (2 * delta) - a)) < 1e-7 * AMP * OMEGA**2
    # and the motion is the sampled one: a quintic Hermite through θ, ω, α to O((ΩΔt)⁶)
    if columns == "xva":
        exact = np.sin(OMEGA * t + PHASE)
        assert np.max(np.abs(x - AMP * exact)) < 1e-8 * AMP
        assert np.max(np.abs(a + AMP * OMEGA**2 * exact)) < 1e-5 * AMP * OMEGA**2


# ---------------------------------------------------------------- a rocked sweep exported as a table
#
# The triple rocker of mechanisms/fourbar_nongrashof_rocking.toml (a = 3, b = 4, c = 4.5, d = 6): its input stops
# where |A − O4| = b + c, cos θ_lim = (a² + d² − (b + c)²)/(2·a·d) (law of cosines): θ_lim = 139.1956°. The table
# rocks the input 0 → +peak → −peak → 0 at |ω| = 2 rad/s, rows every 50 ms, each extreme written twice (arriving
# with ω, leaving with −ω, one row interval apart): how PMKS and others export a rocked sweep.


def _rocked_sweep(peak: float, w: float = 2.0, h: float = 0.05) -> Profile:
    rows: list[tuple[float, float, float]] = []
    t = 0.0
    for x0, x1 in ((0.0, peak), (peak, -peak), (-peak, 0.0)):
        n = max(round(abs(x1 - x0) / (w * h)), 1)
        rows += [(t + k * abs(x1 - x0) / n / w, x0 + (x1 - x0) * k / n, np.sign(x1 - x0) * w) for k in range(n + 1)]
        t = rows[-1][0] + h
    T, X, V = (np.array(c) for c in zip(*rows, strict=True))
    return Profile(T, X, V)


def _rocked(peak: float) -> tuple:
    mech = vloop.load(MECHANISMS / "fourbar_nongrashof_rocking.toml")
    prof = _rocked_sweep(peak)
    drv = dataclasses.replace(mech.drivers[0], profile=prof)
    return dataclasses.replace(mech, drivers=(drv,), times=np.linspace(0.0, prof.t[-1], 801)), prof


THETA_LIM = np.arccos((3.0**2 + 6.0**2 - 8.5**2) / (2 * 3.0 * 6.0))


def test_a_repeated_extreme_with_opposite_rates_is_a_reversal_there():
    """The input never passes the table's extreme (a cubic through +ω and −ω at one angle overshot it by
    |ω|·Δt/4 = 0.025 rad, past the limit: a feasible table refused); it rests there between the two rows, and
    every other interval is the Hermite spline as before. The run completes and matches the closed form
    (validators.analytic.fourbar, driven by the same input) to 1e-9."""
    mech, prof = _rocked(np.radians(139.0))
    d = mech.drivers[0]
    t = np.linspace(0.0, prof.t[-1], 200_001)
    x, v, a = evaluate(d, t)
    assert np.max(x) == np.max(prof.x) and np.min(x) == np.min(prof.x)  # the table's extremes, exactly
    top = np.nonzero(prof.x == np.max(prof.x))[0]
    assert list(top) == [top[0], top[0] + 1]
    inside = (t > prof.t[top[0]]) & (t < prof.t[top[1]])
    assert np.all(x[inside] == prof.x[top[0]]) and np.all(v[inside] == 0) and np.all(a[inside] == 0)
    assert np.array_equal(evaluate(d, prof.t)[1], prof.v)  # the rows' rates as given
    res = vloop.solve(mech)
    assert_histories_close(res, analytic_fourbar.solve(mech, mech.times), rtol=1e-9, floor=1e-9, min_columns=15)


def test_a_table_past_the_limit_stops_at_the_limit_never_past_its_own_extreme():
    """Peak 140.46° (past θ_lim = 139.1956°): the run stops; the limit is the law of cosines' (1e-12), and the
    input the message names lies between the limit and the table's peak (the overshoot named 140.77°)."""
    mech, prof = _rocked(np.radians(140.46))
    assert np.max(evaluate(mech.drivers[0], np.linspace(0.0, prof.t[-1], 200_001))[0]) == np.max(prof.x)
    with pytest.raises(vloop.MotionError) as info:
        vloop.solve(mech)
    err = info.value
    assert err.limit_value[0] == pytest.approx(THETA_LIM, rel=1e-12, abs=0)
    assert THETA_LIM < err.driver_value[0] <= np.max(prof.x)
    assert "139.1956°" in str(err)
