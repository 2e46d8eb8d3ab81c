"""A run whose [time] starts late gives the row a run from t = 0 gives at the same t, unwrapped angles included.

The run from 0 is sampled coarsely up to the late start (vloop inserts its own internal samples so the
inputs move at most 10° per sample and every link's turns are counted); the late run reaches its start
by a short path plus whole crank turns (winding numbers). Both must agree sample by sample: positions
and rates to round-off, and unwrapped angles exactly to the turn (θ − θ_crank stays bounded for links
that turn with the crank, e.g. a drag link's follower).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import vloop
from tests.conftest import MECHANISMS


def drag_link(ground: float, crank: float, coupler: float, follower: float, th2: float, omega: float) -> dict:
    """A Grashof four-bar with the ground shortest (every moving link turns fully), assembled at θ2."""
    A = (crank * math.cos(th2), crank * math.sin(th2))
    dx, dy = ground - A[0], -A[1]
    D = math.hypot(dx, dy)
    k = (coupler**2 - follower**2 + D * D) / (2 * D)  # distance from A to the foot of B along A→O4
    h = math.sqrt(max(coupler**2 - k * k, 0.0))
    B = (A[0] + (k * dx - h * dy) / D, A[1] + (k * dy + h * dx) / D)
    return {
        "name": "drag_link",
        "joints": {"O2": [0.0, 0.0], "O4": [ground, 0.0], "A": list(A), "B": list(B)},
        "links": {
            "ground": {"joints": ["O2", "O4"], "ground": True},
            "crank": {"joints": ["O2", "A"]},
            "coupler": {"joints": ["A", "B"]},
            "follower": {"joints": ["O4", "B"]},
        },
        "drivers": [{"link": "crank", "omega": omega}],
        "time": {"times": [0.0]},
    }


def compare_late(mech: vloop.Mechanism, t0: float, h: float, n: int = 8) -> None:
    late_times = t0 + h * np.arange(n)
    late = vloop.solve(mech, times=late_times)
    coarse = np.unique(np.linspace(0.0, t0, 50, endpoint=False))
    coarse = coarse[coarse < t0]
    early = vloop.solve(mech, times=np.concatenate([coarse, late_times]))
    for c in late.columns:
        a, b = late[c], early[c][-n:]
        scale = max(1.0, float(np.max(np.abs(b))))
        assert np.max(np.abs(a - b)) <= 4 * np.spacing(scale) + 1e-12 * scale, (c, t0, np.max(np.abs(a - b)))


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    ground=st.floats(0.5, 1.0),
    extra=st.floats(0.3, 1.5),
    th2=st.floats(0.0, 2 * math.pi),
    omega=st.floats(-3.0, 3.0).filter(lambda w: abs(w) > 0.2),
    t0=st.floats(0.0, 2000.0),
)
def test_drag_link_late_start_equals_run_from_zero(ground, extra, th2, omega, t0):
    crank, follower = ground + extra, ground + 0.8 * extra + 0.2
    coupler = crank + follower - ground - 0.1  # s + l < p + q: Grashof, ground shortest: a drag link
    mech = vloop.from_dict(drag_link(ground, crank, coupler, follower, th2, omega))
    compare_late(mech, t0, 0.013)
    late = vloop.solve(mech, times=t0 + 0.013 * np.arange(8))
    for link in ("coupler", "follower"):  # they turn once per crank turn: θ − θ_crank stays within a turn
        assert np.max(np.abs(late[f"{link}.theta"] - late["crank.theta"])) < 2 * math.pi + 1e-9


def test_drag_link_a_million_seconds_late():
    mech = vloop.from_dict(drag_link(1.0, 3.0, 3.5, 3.0, math.pi / 2, 0.2))
    compare_late(mech, 1.0e6, 0.1)
    late = vloop.solve(mech, times=1.0e6 + 0.1 * np.arange(8))
    assert np.max(np.abs(late["follower.theta"] - late["crank.theta"])) < 2 * math.pi


@pytest.mark.parametrize("name", ["fourbar_crank_rocker_open", "fivebar_two_cranks", "slider_crank_offset", "eightbar"])
def test_catalog_files_started_late(name):
    mech = vloop.load(MECHANISMS / f"{name}.toml")
    for t0 in (0.37, 41.3):
        try:
            compare_late(mech, t0, 0.01)
        except vloop.MotionError:  # the five-bar's second crank is a rocker whose motion ends: both runs must stop
            with pytest.raises(vloop.MotionError):
                vloop.solve(mech, times=t0 + 0.01 * np.arange(8))


@pytest.mark.parametrize("turns", [3, 12])  # up to 8 wraps of an angle are counted one by one, more at once
def test_unwrapped_angles_of_a_drag_link_against_the_hand_closed_form(turns):
    """The follower and coupler of a drag link turn with the crank: their unwrapped θ over many turns equals the
    hand closed form (B from the law of cosines as in drag_link(), atan2, numpy's np.unwrap) to 1e-12 rad."""
    ground, crank, coupler, follower, omega = 1.0, 3.0, 3.5, 3.0, 2.0
    mech = vloop.from_dict(drag_link(ground, crank, coupler, follower, 0.3, omega))
    t = np.linspace(0.0, turns * 2 * math.pi / omega, 100 * turns + 1)
    res = vloop.solve(mech, times=t)
    th2 = 0.3 + omega * t
    ax, ay = crank * np.cos(th2), crank * np.sin(th2)
    dx, dy = ground - ax, -ay
    D = np.hypot(dx, dy)
    k = (coupler**2 - follower**2 + D * D) / (2 * D)
    h = np.sqrt(coupler**2 - k * k)
    bx, by = ax + (k * dx - h * dy) / D, ay + (k * dy + h * dx) / D
    th4 = np.unwrap(np.arctan2(by, bx - ground))
    th3 = np.unwrap(np.arctan2(by - ay, bx - ax))
    for name, ref in (("follower", th4), ("coupler", th3)):
        got = res[f"{name}.theta"]
        ref = ref + 2 * math.pi * round((got[0] - ref[0]) / (2 * math.pi))  # the file's turn at t = 0
        assert np.max(np.abs(got - ref)) < 1e-12 * turns * 2 * math.pi, name
        assert got[-1] - got[0] == pytest.approx(turns * 2 * math.pi, abs=1e-9)  # one turn per crank turn
