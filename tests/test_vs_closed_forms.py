"""vloop against the hand-derived closed forms (validators/analytic/*.py), within 1e-12 of each quantity's peak
(and 1e-12 of its group's peak for quantities near zero: vloop.compare), on both paths: closed-form dyads and one Newton block."""

from __future__ import annotations

import pytest

import vloop
from tests.conftest import mechanism_files
from validators import analytic
from vloop.compare import assert_histories_close

WITH_CLOSED_FORM = [p for p in mechanism_files() if analytic.available(vloop.load(p))]


def test_the_issue_mechanisms_have_closed_forms():
    names = {p.stem for p in WITH_CLOSED_FORM}
    assert {"eightbar", "fourbar_crank_rocker_open", "fourbar_crank_rocker_crossed"} <= names
    assert {"slider_crank_offset", "slider_crank_offset_crossed"} <= names


@pytest.mark.parametrize("method", ["auto", "newton"])
@pytest.mark.parametrize("path", WITH_CLOSED_FORM, ids=lambda p: p.stem)
def test_vloop_matches_closed_form(path, method):
    mech = vloop.load(path)
    try:
        res = vloop.solve(mech, method=method)
    except vloop.MotionError as exc:
        res = exc.partial
        assert len(res) > 10
    ref = analytic.solve(mech, res.t)
    cmp = assert_histories_close(res, ref, rtol=1e-12, min_columns=10)
    # every quantity the closed form gives is compared: angles, rates, joints, sliders
    groups = {e.group for e in cmp.errors}
    assert {"angle", "angular velocity", "angular acceleration", "position", "velocity", "acceleration"} <= groups
