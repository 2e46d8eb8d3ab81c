"""Limit positions: a non-Grashof four-bar driven past its limit stops at the right sample."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import vloop
from tests.conftest import MECHANISMS
from validators.analytic import fourbar as analytic_fourbar
from vloop.cli import main
from vloop.compare import assert_histories_close

PATH = MECHANISMS / "fourbar_nongrashof_past_limit.toml"


def test_stops_at_the_first_sample_past_the_limit():
    mech = vloop.load(PATH)
    (lim,) = [th for th in analytic_fourbar.limit_angles(mech) if th < math.pi]  # the one ahead of θ2(0) = π/3
    # hand check of the closed form: law of cosines, |A − O4| = b + c at the limit
    assert math.cos(lim) == pytest.approx((3**2 + 6**2 - 8.5**2) / (2 * 3 * 6), abs=1e-14)
    d = mech.drivers[0]
    theta = d.x0 + d.v0 * mech.times
    first_bad = int(np.argmax(theta > lim))
    assert first_bad == 173
    with pytest.raises(vloop.MotionError) as info:
        vloop.solve(mech)
    err = info.value
    assert err.sample == first_bad
    assert err.time == pytest.approx(mech.times[first_bad])
    assert err.driver_value[0] == pytest.approx(theta[first_bad])
    assert "t = 1.73 s" in str(err) and "θ_l2 = 2.4312 rad" in str(err) and "loop 1 (O2–A–B–O4)" in str(err)
    # the limit itself, located by bisection (to 1e-12 of the input range), against the closed form: 1e-9 rad
    assert abs(err.limit_value[0] - lim) < 1e-9
    # the rows before the failure are kept and correct (closed form, 1e-9 of scale)
    assert len(err.partial) == first_bad
    ref = analytic_fourbar.solve(mech, mech.times[:first_bad])
    assert_histories_close(err.partial, ref, rtol=1e-9, min_columns=20)


def test_newton_path_stops_at_the_same_sample():
    mech = vloop.load(PATH)
    with pytest.raises(vloop.MotionError) as info:
        vloop.solve(mech, method="newton")
    assert info.value.sample in (172, 173)  # Newton may refuse the last sample next to the toggle
    assert abs(info.value.limit_value[0] - 2.4294208664636154) < 1e-6


def test_cli_writes_the_rows_before_the_failure(tmp_path, capsys):
    code = main(["run", str(PATH), "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert code == 2
    assert err.count("\n") == 1 and "cannot assemble at t = 1.73 s (sample 173 of 301)" in err
    assert "wrote 173 rows" in err
    rows = np.loadtxt(tmp_path / "results.csv", delimiter=",", skiprows=1)
    assert rows.shape[0] == 173
    assert np.all(np.isfinite(rows))
    assert rows[-1, 0] == pytest.approx(1.72)


# ---------------------------------------------------------------- limits located at the discriminant's root
#
# The triple rocker of fourbar_nongrashof_past_limit.toml (a = 3, b = 4, c = 4.5, d = 6, O2 at the origin, O4 on
# +x), by hand (law of cosines):
# - the input's limits: |A − O4| = b + c, cos θ_lim = (a² + d² − (b + c)²)/(2·a·d): θ = ±θ_lim;
# - the rocker there points from O4 to A (A–B–O4 collinear, B between): θ4 = π ∓ γ with
#   cos γ = (d² + (b + c)² − a²)/(2·d·(b + c)) (the angle at O4 of the triangle O2–O4–A);
# - the rocker's dead centre inside the range (crank and coupler stretched, |O2B| = a + b): θ4 = π − ρ with
#   cos ρ = (d² + c² − (a + b)²)/(2·d·c); the rocker swings from π − ρ to π + γ: swing = γ + ρ;
# - the transmission angle at a limit (coupler and rocker collinear) is 0.
A_, B_, C_, D_ = 3.0, 4.0, 4.5, 6.0
THETA_LIM = math.acos((A_**2 + D_**2 - (B_ + C_) ** 2) / (2 * A_ * D_))
GAMMA = math.acos((D_**2 + (B_ + C_) ** 2 - A_**2) / (2 * D_ * (B_ + C_)))
RHO = math.acos((D_**2 + C_**2 - (A_ + B_) ** 2) / (2 * D_ * C_))


@pytest.mark.parametrize("stop,step", [(3.0, 0.01), (2000.0, 0.5)])
def test_a_limit_is_located_to_round_off_however_long_the_run(stop, step):
    """The limit is the root of the dyad's discriminant, not a bisection to a fraction of the run's input range
    (2000 s at 0.8 rad/s: 1e-12 of 1600 rad was 2.3e-10 rad): θ_lim to 4 ulps, its time θ_lim − π/3 over ω."""
    mech = vloop.load(PATH)
    mech = dataclasses.replace(mech, times=np.arange(0.0, stop + step / 2, step))
    with pytest.raises(vloop.MotionError) as info:
        vloop.solve(mech)
    err = info.value
    assert abs(err.limit_value[0] - THETA_LIM) <= 4 * np.spacing(THETA_LIM)
    assert err.limit_time == pytest.approx((THETA_LIM - math.pi / 3) / 0.8, rel=4e-16, abs=0)


def test_a_triple_rockers_swing_and_toggles_to_round_off():
    """The input cycle (vloop.teaching): range ±θ_lim, the rocker's swing γ + ρ and its angles at both limits,
    each to 1e-12 relative of the hand values above; the transmission angle at each toggle 0 to 1e-12 rad — and so
    is each single branch at the located limit (the bisection left it √Δx off: 3.9e-6 rad)."""
    from vloop.teaching import input_cycle

    mech = vloop.load(PATH)
    cyc = input_cycle.cycle(mech)
    assert cyc.lower == pytest.approx(-THETA_LIM, rel=1e-12, abs=0)
    assert cyc.upper == pytest.approx(THETA_LIM, rel=1e-12, abs=0)
    assert cyc.outputs["l4"].travel == pytest.approx(GAMMA + RHO, rel=1e-12, abs=0)
    assert [t.folded for t in cyc.toggles] == [pytest.approx(0.0, abs=1e-12)] * 2
    walks, _, _, _ = input_cycle._walks(mech, 720)
    for walk in walks:
        at = walk.solve(np.array([walk.end]), rtol=math.inf)  # one branch, at the limit the solver located
        assert at["l2.theta"][0] == pytest.approx(walk.sense * THETA_LIM, rel=1e-12, abs=0)
        assert at["l4.theta"][0] == pytest.approx(math.pi - walk.sense * GAMMA, rel=1e-12, abs=0)
        mu = math.remainder(at["l3.theta"][0] - at["l4.theta"][0], math.pi)  # coupler ∥ rocker: 0 (mod π)
        assert abs(mu) <= 1e-12


FOLDED = """
name = "folded_toggle"
units = "m"
[joints]
O2 = [0.0, 0.0]
A = [-2.0, 0.0]
B = [{bx!r}, {by!r}]
O4 = [4.5, 0.0]
[links]
ground = {{ joints = ["O2", "O4"], ground = true }}
crank = {{ joints = ["O2", "A"], length = 2.0 }}
coupler = {{ joints = ["A", "B"], length = 6.0 }}
rocker = {{ joints = ["O4", "B"], length = 3.0 }}
[[drivers]]
link = "crank"
pivot = "O2"
omega = -1.0
[time]
start = 0.0
stop = 3.0
step = 0.01
"""


def test_a_folded_toggle_is_located_to_round_off():
    """Another triple rocker (a = 2, b = 6, c = 3, d = 4.5: s + l = 8 > 7.5) whose input stops where coupler and
    rocker fold, |A − O4| = b − c = 3 (b + c = 9 is out of reach): by hand, cos θ_lim = (a² + d² − 3²)/(2·a·d),
    and there B lies on the line A→O4 beyond O4, so the rocker points along O4 − A: θ4 = −γ with
    cos γ = (d² + 3² − a²)/(2·d·3). Driven from θ = π clockwise, the run stops at θ_lim (4 ulps); the configuration
    at the located limit has θ4 = −γ and the coupler along the rocker to 1e-12."""
    p = (36.0 - 9.0 + 6.5**2) / (2 * 6.5)  # B's foot along A→O4 at θ = π (|A − O4| = 6.5), its height √(b² − p²)
    mech = vloop.loads(FOLDED.format(bx=-2.0 + p, by=math.sqrt(36.0 - p * p)))
    lim = math.acos((2.0**2 + 4.5**2 - 3.0**2) / (2 * 2.0 * 4.5))
    gamma = math.acos((4.5**2 + 3.0**2 - 2.0**2) / (2 * 4.5 * 3.0))
    with pytest.raises(vloop.MotionError) as info:
        vloop.solve(mech)
    err = info.value
    assert abs(err.limit_value[0] - lim) <= 4 * np.spacing(lim)
    at = vloop.solve(mech, np.array([0.0, err.limit_time]), rtol=math.inf)
    assert at["rocker.theta"][1] == pytest.approx(-gamma, rel=1e-12, abs=0)
    assert abs(math.remainder(at["coupler.theta"][1] - at["rocker.theta"][1], math.pi)) <= 1e-12
