"""The new file fields (mass, inertia, com, gravity, [[loads]]): round trips, hostile values, the CLI.

Every bad value gives one MechanismError line naming the entry (CLI: exit 2, no traceback); edge
values that are valid (0, −0, 5e-324, 1e308) load, and an overflow at solve time is a ForceError
naming the quantity and the sample, never a NaN or inf in forces.csv.
"""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest

import vloop
from vloop.cli import main as vloop_main
from vloop.mechanism import to_dict

MECH = Path(__file__).resolve().parents[1] / "mechanisms"
HOSTILE = [float("nan"), float("inf"), -float("inf"), 10**400, "1.0", [1.0], [[1.0, 2.0]], True, None, {"a": 1}]


def base() -> dict:
    """The engine file as a dict (profile inline), the template every case edits."""
    return to_dict(vloop.load(MECH / "slider_crank_engine.toml"))


def refused(data: dict, entry: str, match: str = "") -> str:
    with pytest.raises(vloop.MechanismError) as exc:
        vloop.from_dict(data)
    msg = str(exc.value)
    assert f"[{entry}]" in msg and "\n" not in msg, msg
    assert match in msg, msg
    return msg


# ---------------------------------------------------------------- round trip


def test_round_trip_keeps_masses_gravity_and_loads(tmp_path: Path) -> None:
    for stem in ("slider_crank_engine", "eightbar_dynamics", "fourbar_textbook_dynamics", "sixbar_watt2_dynamics"):
        m1 = vloop.load(MECH / f"{stem}.toml")
        vloop.save(m1, tmp_path / "m.toml")
        m2 = vloop.load(tmp_path / "m.toml")
        assert (m1.masses, m1.gravity, m1.loads) == (m2.masses, m2.gravity, m2.loads)
        assert m1.loads[0].profile is None or m2.loads[0].profile.source == "inline"


def test_defaults() -> None:
    data = base()
    del data["links"]["l3"]["com"]
    del data["sliders"]["l4"]["inertia"]
    data["links"]["l2"] = {"joints": ["O2", "A"], "inertia": 0.5}  # inertia only: a massless flywheel
    mech = vloop.from_dict(data)
    assert mech.masses["l3"].com == pytest.approx((0.1155, 0.0))  # the mean of the rod's joints A and B
    assert mech.masses["l4"].inertia == 0.0 and mech.masses["l2"].mass == 0.0
    assert mech.loads[0].body == "l4"  # a load at a slider's joint acts on the block


@pytest.mark.parametrize("value", [0, -0.0, 5e-324, 1e308])
def test_valid_edge_values_load(value: float) -> None:
    data = base()
    data["links"]["l3"]["mass"] = value
    data["links"]["l3"]["inertia"] = value
    data["gravity"] = [value, value]
    data["loads"].append({"link": "l3", "torque": value})
    mech = vloop.from_dict(data)
    assert mech.masses["l3"].mass == float(value) and str(mech.masses["l3"].mass) != "-0.0"


# ---------------------------------------------------------------- hostile values, every field


@pytest.mark.parametrize("value", HOSTILE)
@pytest.mark.parametrize("key", ["mass", "inertia"])
def test_bad_mass_and_inertia(key: str, value: object) -> None:
    data = base()
    data["links"]["l3"][key] = value
    refused(data, "links.l3", key)
    data = base()
    data["sliders"]["l4"][key] = value
    refused(data, "sliders.l4", key)


@pytest.mark.parametrize("key", ["mass", "inertia"])
def test_negative_mass_and_inertia(key: str) -> None:
    data = base()
    data["links"]["l2"][key] = -1.0
    refused(data, "links.l2", "must not be negative")


@pytest.mark.parametrize("value", [*HOSTILE, [0.0], [0.0, 1.0, 2.0], [float("nan"), 0.0], [10**400, 0.0], ["0", 0.0]])
def test_bad_com(value: object) -> None:
    data = base()
    data["links"]["l3"]["com"] = value
    refused(data, "links.l3", "com")


@pytest.mark.parametrize("value", [*HOSTILE, [0.0], [0.0, -9.81, 0.0], [float("inf"), 0.0], [[0.0], [9.81]], 9.81])
def test_bad_gravity(value: object) -> None:
    data = base()
    data["gravity"] = value
    refused(data, "gravity", "gravity")


@pytest.mark.parametrize("value", [*HOSTILE, [0.0], [1.0, 2.0, 3.0], [float("nan"), 0.0], [10**400, 0.0]])
def test_bad_force(value: object) -> None:
    data = base()
    data["loads"] = [{"point": "B", "force": value}]
    refused(data, "loads[0]", "force")


@pytest.mark.parametrize("value", HOSTILE)
def test_bad_torque(value: object) -> None:
    data = base()
    data["loads"] = [{"link": "l2", "torque": value}]
    refused(data, "loads[0]", "torque")


@pytest.mark.parametrize(
    "load,match",
    [
        ({"point": "Q", "force": [1.0, 0.0]}, "unknown point 'Q'"),
        ({"point": ["B"], "force": [1.0, 0.0]}, "unknown point"),
        ({"link": "l9", "torque": 1.0}, "unknown link 'l9'"),
        ({"link": "ground", "torque": 1.0}, "is the ground"),
        ({"point": "G", "force": [1.0, 0.0]}, "on the ground only"),  # a tracer point on the ground
        ({"point": "B", "link": "l2", "force": [1.0, 0.0]}, "'B' is not on 'l2'"),
        ({"point": "B", "torque": 1.0}, "a torque needs a link and no point"),
        ({"link": "l2", "force": [1.0, 0.0]}, "a force needs a point"),
        ({"point": "B", "force": [1.0, 0.0], "torque": 1.0}, "give one of"),
        ({"point": "B"}, "give one of"),
        ({"torque": 1.0}, "needs the link"),
        ({"point": "B", "force": [1.0, 0.0], "mass": 2.0}, "unknown key 'mass'"),
        ({"point": "B", "force": [1.0, 0.0], "profile": {"t": [0, 1], "fx": [0, 1], "fy": [0, 0]}}, "both given"),
        ({"point": "B", "profile": {"t": [0, 1], "fx": [0, 1]}}, "columns 't', 'fx' and 'fy'"),
        ({"point": "B", "profile": {"t": [0, 1], "torque": [0, 1]}}, "needs columns 't' and 'fx'"),
        ({"link": "l2", "profile": {"t": [0, 1], "fx": [0, 1], "fy": [0, 0]}}, "needs columns 't' and 'torque'"),
        ({"link": "l2", "profile": {"t": [1, 0], "torque": [0, 1]}}, "not strictly increasing"),
        ({"link": "l2", "profile": {"t": [0, 1], "torque": [0, float("nan")]}}, "finite numbers"),
        ({"link": "l2", "profile": {"t": [0, 1], "torque": [0, 10**400]}}, "finite numbers"),
        ({"link": "l2", "profile": {"t": [0], "torque": [0]}}, "at least two rows"),
        ({"link": "l2", "profile": "missing.csv"}, "cannot read profile"),
        ({"link": "l2", "profile": 3}, "CSV file name or a table"),
        ("B", "must be a table"),
    ],
)
def test_bad_loads(load: object, match: str) -> None:
    data = base()
    data["points"] = {"G": {"link": "ground", "at": [0.0, -0.1]}}
    data["loads"] = [load]
    refused(data, "loads[0]", match)


def test_loads_must_be_an_array_of_tables() -> None:
    data = base()
    data["loads"] = {"point": "B", "force": [1.0, 0.0]}
    refused(data, "loads", "array of tables")


def test_no_mass_on_the_ground() -> None:
    data = base()
    data["links"]["ground"]["mass"] = 1.0
    refused(data, "links.ground", "the ground does not move")


def test_forces_need_a_known_length_unit() -> None:
    data = base()
    data["units"] = "furlong"
    refused(data, "units", "forces need a length unit")
    data = copy.deepcopy(data)
    for key in ("loads", "gravity"):
        data.pop(key)
    for table in [*data["links"].values(), *data["sliders"].values()]:
        for k in ("mass", "inertia", "com"):
            table.pop(k, None)
    assert vloop.from_dict(data).units == "furlong"  # kinematics alone do not need it


def test_every_problem_is_reported_at_once() -> None:
    data = base()
    data["links"]["l2"]["mass"] = -1.0
    data["gravity"] = "down"
    msg = refused(data, "links.l2")
    assert "[gravity]" in msg


# ---------------------------------------------------------------- command line


def test_cli_writes_forces_only_with_masses_or_loads(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert vloop_main(["run", str(MECH / "fourbar_textbook_dynamics.toml"), "--out", str(tmp_path / "a")]) == 0
    rows = np.loadtxt(tmp_path / "a" / "forces.csv", delimiter=",", skiprows=1)
    assert rows.shape == (201, 1 + 1 + 4 * 3 + 3) and np.all(np.isfinite(rows))
    assert "forces.csv" in capsys.readouterr().out
    assert vloop_main(["run", str(MECH / "fourbar_textbook_example.toml"), "--out", str(tmp_path / "b")]) == 0
    assert not (tmp_path / "b" / "forces.csv").exists()


def test_cli_plot_adds_the_forces_figure(tmp_path: Path) -> None:
    assert vloop_main(["run", str(MECH / "slider_crank_engine.toml"), "--out", str(tmp_path), "--plot"]) == 0
    png = tmp_path / "forces.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 20_000
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []  # no temporary files


def test_cli_partial_run_keeps_the_forces_of_the_solved_rows(tmp_path: Path) -> None:
    data = to_dict(vloop.load(MECH / "fourbar_nongrashof_past_limit.toml"))
    data["links"]["l3"].update(mass=2.0, inertia=0.1)
    data["gravity"] = [0.0, -9.81]
    vloop.save(vloop.from_dict(data), tmp_path / "m.toml")
    assert vloop_main(["run", str(tmp_path / "m.toml"), "--out", str(tmp_path / "out")]) == 2
    rows = np.loadtxt(tmp_path / "out" / "forces.csv", delimiter=",", skiprows=1)
    assert rows.shape[0] == 173 and np.all(np.isfinite(rows))


@pytest.mark.parametrize(
    "edit,match",
    [
        (("mass = 0.55", "mass = -0.55"), "[links.l3] 'mass' must not be negative"),
        (("gravity = [0.0, -9.81]", "gravity = [0.0, nan]"), "[gravity] 'gravity' is not finite"),
        (('point = "B"', 'point = "Z"'), "[loads[0]] unknown point 'Z'"),
        (("mass = 2.5", "mass = 1e308"), "is not finite at t = "),
    ],
)
def test_cli_bad_values_exit_2_with_one_line(tmp_path: Path, capsys: pytest.CaptureFixture, edit, match) -> None:
    text = (MECH / "slider_crank_engine.toml").read_text().replace(*edit)
    path = tmp_path / "m.toml"
    path.write_text(text)
    (tmp_path / "slider_crank_engine_gas.csv").write_text((MECH / "slider_crank_engine_gas.csv").read_text())
    assert vloop_main(["run", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert match in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "out" / "forces.csv").exists()
