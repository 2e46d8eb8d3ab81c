"""Sweeping a non-Grashof input between its limits: limits against the law of cosines."""

from __future__ import annotations

import math

import numpy as np
import pytest

import vloop
from tests.conftest import MECHANISMS
from validators import analytic
from validators.analytic import fourbar as analytic_fourbar
from vloop.cli import main
from vloop.compare import assert_histories_close
from vloop.sweep import feasible_range, rocking, sweep

PAST_LIMIT = MECHANISMS / "fourbar_nongrashof_past_limit.toml"


def test_limits_match_the_law_of_cosines():
    mech = vloop.load(PAST_LIMIT)
    lo, hi, full = feasible_range(mech)
    assert not full
    exact = math.acos((3**2 + 6**2 - (4 + 4.5) ** 2) / (2 * 3 * 6))  # |A − O4| = b + c
    assert abs(hi - exact) < 1e-9 and abs(lo + exact) < 1e-9
    assert sorted(th % (2 * math.pi) for th in (lo, hi)) == pytest.approx(
        sorted(analytic_fourbar.limit_angles(mech)), abs=1e-9
    )


def test_rocking_sweep_matches_the_closed_form_on_one_branch():
    mech = vloop.load(PAST_LIMIT)
    res = sweep(mech, margin=1e-3)
    theta = res["l2.theta"]
    span = res.meta["sweep"]["upper"] - res.meta["sweep"]["lower"]
    assert theta.max() == pytest.approx(res.meta["sweep"]["upper"] - 1e-3 * span)
    assert theta.min() == pytest.approx(res.meta["sweep"]["lower"] + 1e-3 * span)
    assert theta[0] == pytest.approx(theta[-1]) == pytest.approx(math.pi / 3)
    assert np.all(res.health["branch"] == res.health["branch"][0])  # one assembly branch throughout
    assert_histories_close(res, analytic.solve(rocking(mech, margin=1e-3)), rtol=1e-9, min_columns=20)


def test_a_crank_that_turns_fully_is_swept_over_one_turn():
    res = sweep(vloop.load(MECHANISMS / "fourbar_crank_rocker_open.toml"))
    assert res["l2.theta"][-1] - res["l2.theta"][0] == pytest.approx(2 * math.pi)


def test_cli_sweep(tmp_path, capsys):
    assert main(["run", str(PAST_LIMIT), "--sweep", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    lim = 2.429420866  # ±139.1956°, printed as angles in [0°, 360°) with the counter-clockwise travel between them
    assert f"rocks between the limits of θ_l2 from {2 * math.pi - lim:.10g} rad (220.8044°) counter-clockwise " in out
    assert f"to {lim:.10g} rad (139.1956°), a travel of 278.391" in out
    rows = np.loadtxt(tmp_path / "results.csv", delimiter=",", skiprows=1)
    assert rows.shape[0] > 800 and np.all(np.isfinite(rows))
