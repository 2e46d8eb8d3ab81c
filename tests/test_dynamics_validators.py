"""vloop.simulate against two independent time integrations of the same model and loads: Exudyn's
generalized-α on its own multibody model, Pinocchio's constrained forward dynamics on the cut tree (RK4).

Each engine runs at two steps and corrects itself by Richardson's extrapolation; the tolerance is what that
correction leaves (the next order: at most 0.5 of the correction, measured ≤ 0.21) plus 1e-9 of the group's
peak for vloop's own integration (validators/dynamics_check.py says where each number comes from). The catalog's mechanisms with masses (mechanisms/*dynamics*.toml): the four-bar with its
[dynamics] section by default, the eight-bar and Watt II under a motor line in the slow suite.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import jsonschema
import pytest

import vloop
from validators import dynamics_check, harness
from vloop.cli import main
from vloop.model import Dynamics, Spring

MECH = Path(__file__).resolve().parents[1] / "mechanisms"
SCHEMA = json.loads((Path(harness.__file__).parent / "summary.schema.json").read_text())


def _check(mech: vloop.Mechanism, span: float) -> list[dynamics_check.Row]:
    rows = dynamics_check.compare(mech, span)
    engines = {r.engine for r in rows}
    assert engines == set(dynamics_check.STEPS)
    bad = [r for r in rows if not r.passed]
    assert not bad, bad[:3]
    # the engines did see the motion: their own errors are real numbers, well above the floor
    assert max(r.correction for r in rows if r.engine == "exudyn-simulate") > 0
    return rows


def test_the_textbook_fourbar_with_its_motor_and_damper() -> None:
    rows = _check(vloop.load(MECH / "fourbar_textbook_dynamics.toml"), 0.05)
    # summary.json's "dynamics" of the mechanism: per engine its worst column (largest worst/tolerance), valid
    entries = dynamics_check.summary_entries(rows)
    jsonschema.validate(entries, {"$ref": "#/$defs/mechanism/properties/dynamics", "$defs": SCHEMA["$defs"]})
    assert [e["engine"] for e in entries] == list(dynamics_check.STEPS)
    for e in entries:
        mine = [r for r in rows if r.engine == e["engine"]]
        worst = max(mine, key=lambda r: r.worst / r.tolerance)
        assert (e["column"], e["worst"], e["tolerance"], e["columns"]) == (worst.column, worst.worst, worst.tolerance,
                                                                         len(mine))  # fmt: skip
        assert e["verdict"] == "pass" and e["worst"] <= e["tolerance"]
    summary = {"passed": True, "mechanisms": [{"file": "a.toml"}, {"file": "b.toml"}]}
    dynamics_check.add_to_summary(summary, {"b.toml": entries})
    assert "dynamics" not in summary["mechanisms"][0] and summary["mechanisms"][1]["dynamics"] == entries
    dynamics_check.add_to_summary(summary, {"a.toml": [{**entries[0], "verdict": "fail"}]})
    assert summary["passed"] is False  # as the exit code: a failed dynamics comparison fails the validation


@pytest.mark.slow
def test_validate_writes_the_dynamics_verdict_into_the_summary(tmp_path: Path) -> None:
    """`vloop validate` on a file with [dynamics]: the verdict printed, in summary.json (valid) and the exit code."""
    path = MECH / "fourbar_textbook_dynamics.toml"
    code = main(["validate", str(path), "--engines", "vloop,pinocchio", "--out", str(tmp_path), "--no-report"])
    summary = json.loads((tmp_path / "summary.json").read_text())
    jsonschema.validate(summary, SCHEMA)
    (mech,) = summary["mechanisms"]
    (entry,) = mech["dynamics"]
    assert entry["engine"] == "pinocchio-simulate" and entry["columns"] == 6  # θ and ω of l2, l3, l4
    assert entry["verdict"] == "pass" and 0 <= entry["worst"] <= entry["tolerance"]
    assert code == 0 and summary["passed"] is True


@pytest.mark.slow
@pytest.mark.parametrize("stem", ["eightbar_dynamics", "sixbar_watt2_dynamics"])
def test_the_catalogs_mechanisms_with_masses_under_a_motor(stem: str) -> None:
    mech = vloop.load(MECH / f"{stem}.toml")
    crank = mech.links[mech.drivers[0].target].joints  # a spring from the crank's pivot to its pin: k, c act
    dyn = Dynamics(motor=(2000.0, 5.0), springs=(Spring("rotational", (mech.drivers[0].target, "ground"), k=10.0,
                                                        c=1.0, joint=crank[0]),))  # fmt: skip
    _check(dataclasses.replace(mech, dynamics=dyn), 0.2)
