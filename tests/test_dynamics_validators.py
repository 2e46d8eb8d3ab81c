"""vloop.simulate against two independent time integrations of the same model and loads: Exudyn's
generalized-α on its own multibody model, Pinocchio's constrained forward dynamics on the cut tree (RK4).

Each engine runs at two steps and corrects itself by Richardson's extrapolation; the tolerance is what that
correction leaves (the next order: at most 0.5 of the correction, measured ≤ 0.21) plus 1e-9 of the group's
peak for vloop's own integration (validators/dynamics_check.py says where each number comes from). The catalog's mechanisms with masses (mechanisms/*dynamics*.toml): the four-bar with its
[dynamics] section by default, the eight-bar and Watt II under a motor line in the slow suite.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import pytest

import vloop
from validators import dynamics_check
from vloop.model import Dynamics, Spring

MECH = Path(__file__).resolve().parents[1] / "mechanisms"


def _check(mech: vloop.Mechanism, span: float) -> None:
    rows = dynamics_check.compare(mech, span)
    engines = {r.engine for r in rows}
    assert engines == set(dynamics_check.STEPS)
    bad = [r for r in rows if not r.passed]
    assert not bad, bad[:3]
    # the engines did see the motion: their own errors are real numbers, well above the floor
    assert max(r.correction for r in rows if r.engine == "exudyn-simulate") > 0


def test_the_textbook_fourbar_with_its_motor_and_damper() -> None:
    _check(vloop.load(MECH / "fourbar_textbook_dynamics.toml"), 0.05)


@pytest.mark.slow
@pytest.mark.parametrize("stem", ["eightbar_dynamics", "sixbar_watt2_dynamics"])
def test_the_catalogs_mechanisms_with_masses_under_a_motor(stem: str) -> None:
    mech = vloop.load(MECH / f"{stem}.toml")
    crank = mech.links[mech.drivers[0].target].joints  # a spring from the crank's pivot to its pin: k, c act
    dyn = Dynamics(motor=(2000.0, 5.0), springs=(Spring("rotational", (mech.drivers[0].target, "ground"), k=10.0,
                                                        c=1.0, joint=crank[0]),))  # fmt: skip
    _check(dataclasses.replace(mech, dynamics=dyn), 0.2)
