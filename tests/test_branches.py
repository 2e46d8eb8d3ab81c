"""Assembly branches: recorded at t = 0, chosen in the file, and approximate coordinates."""

from __future__ import annotations

import math

import numpy as np
import pytest

import vloop
from tests.conftest import MECHANISMS
from vloop.compare import assert_histories_close
from vloop.method.branches import branch_name


def with_solver(path, table: str) -> vloop.Mechanism:
    return vloop.loads(path.read_text() + f"\n[solver]\n{table}\n", source=str(path))


def test_the_t0_branch_is_recorded():
    for name, expected in (("fourbar_crank_rocker_open", "open"), ("fourbar_crank_rocker_crossed", "crossed")):
        system = vloop.compile(vloop.load(MECHANISMS / f"{name}.toml"))
        assert branch_name(system, system.blocks[0], system.q0) == expected
    eb = vloop.compile(vloop.load(MECHANISMS / "eightbar.toml"))
    assert branch_name(eb, eb.blocks[0], eb.q0) is None  # a triangle with a slider: no four-bar naming
    assert [b.sigma for b in eb.blocks] == [-1.0, -1.0, -1.0]


def test_choose_crossed_in_the_file():
    """The open four-bar's file with branches = { 1 = "crossed" } moves exactly like the crossed file
    (checked against the closed form of the crossed one, an independent reference)."""
    from validators import analytic

    mech = with_solver(MECHANISMS / "fourbar_crank_rocker_open.toml", 'branches = { 1 = "crossed" }')
    system = vloop.compile(mech)
    assert branch_name(system, system.blocks[0], system.q0) == "crossed"
    assert system.assembly["moved"] > 1.0  # B is mirrored across the line A–O4
    res = vloop.solve(system)
    crossed = vloop.load(MECHANISMS / "fourbar_crank_rocker_crossed.toml")
    assert_histories_close(res, analytic.solve(crossed), rtol=1e-9, min_columns=20)
    assert 0 <= res["l3.theta"][0] < 2 * math.pi and 0 <= res["l4.theta"][0] < 2 * math.pi
    # asking for the branch it is already on changes nothing
    same = vloop.compile(with_solver(MECHANISMS / "fourbar_crank_rocker_open.toml", 'branches = { 1 = "open" }'))
    assert np.array_equal(same.q0, vloop.compile(vloop.load(MECHANISMS / "fourbar_crank_rocker_open.toml")).q0)


def test_flip_a_slider_crank():
    from validators import analytic

    mech = with_solver(MECHANISMS / "slider_crank_offset.toml", 'branches = { 1 = "flip" }')
    res = vloop.solve(mech)
    other = vloop.load(MECHANISMS / "slider_crank_offset_crossed.toml")
    assert_histories_close(res, analytic.solve(other), rtol=1e-9, min_columns=10)


@pytest.mark.parametrize(
    ("table", "needle"),
    [
        ('branches = { 7 = "flip" }', "there is no loop 7"),
        ('branches = { 1 = "crossed" }', "not a four-joint loop"),
        ('branches = { 1 = "sideways" }', "branches must map loop numbers"),
    ],
)
def test_branch_errors(table, needle):
    with pytest.raises(vloop.MechanismError, match=needle):
        vloop.compile(with_solver(MECHANISMS / "slider_crank_offset.toml", table))


def test_rounded_coordinates_are_assembled_and_reported():
    """A and B typed to 2 decimals, the links' lengths and the crank's θ0 stated exactly: vloop
    assembles the exact configuration (the closure of the typed one is ~1e-3 of the size) and
    reports how far the joints moved; the motion is then the exact one (closed form, 1e-9)."""
    from validators import analytic

    path = MECHANISMS / "fourbar_crank_rocker_open.toml"
    text = path.read_text()
    exact = vloop.load(path)
    for j in ("A", "B"):
        x, y = exact.joints[j]
        text = text.replace(f"{j}  = [{x!r}, {y!r}]", f"{j}  = [{round(x, 2)}, {round(y, 2)}]")
    assert "A  = [1.0, 1.73]" in text
    text = text.replace("omega = 2.0", f"theta0 = {math.pi / 3!r}\nomega = 2.0")
    system = vloop.compile(vloop.loads(text))  # within the default assembly tolerance (1e-3 of the size)
    assert 1e-3 < system.assembly["moved"] < 0.02
    assert system.assembly["closure"] < 1e-14
    res = vloop.solve(system)
    ref = analytic.solve(exact)
    cols = [c for c in ref.columns if not c.startswith("P.")]  # P's offset on the coupler was typed rounded too
    assert_histories_close(res, ref, rtol=1e-9, columns=cols, min_columns=20)
    # typed to 1 decimal the closure is ~6e-3 of the size: refused, naming the loop and the closure
    coarse = text.replace("A  = [1.0, 1.73]", "A  = [1.0, 1.7]").replace("B  = [6.09, 4.92]", "B  = [6.1, 4.9]")
    with pytest.raises(vloop.MechanismError, match=r"do not close loop 1 \(O2–A–B–O4\).*off by"):
        vloop.compile(vloop.loads(coarse))
