"""Driver inputs (vloop.drivers.evaluate): a tabulated profile is one motion x(t) whose rate and
acceleration are its derivatives, equal to the given columns at the profile's rows.

The reference is independent of the interpolant: the columns themselves at the rows, central finite
differences of x and ẋ between them, and the sine the columns were sampled from.
"""

from __future__ import annotations

import numpy as np
import pytest

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
