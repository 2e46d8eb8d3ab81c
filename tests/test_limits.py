"""Limit positions: a non-Grashof four-bar driven past its limit stops at the right sample."""

from __future__ import annotations

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
