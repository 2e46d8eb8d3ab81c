"""The paper's eight-bar: Table 1 at t = 0, loop structure, mobility."""

from __future__ import annotations

import math

import numpy as np
import pytest

import vloop
from vloop.method.equations import describe
from vloop.method.loops import loop_jacobian


@pytest.fixture(scope="module")
def system(request):
    from tests.conftest import MECHANISMS

    return vloop.compile(vloop.load(MECHANISMS / "eightbar.toml"))


def test_table1_at_t0(system):
    """Paper, Table 1: θ3 = 5.6397 (≡ −0.6435), θ5 = 0.8627, θ7 = 5.4205 rad, k = g = 4.6715 m, c = 4."""
    res = vloop.solve(system, np.array([0.0]))
    assert res["l3.theta"][0] % (2 * math.pi) == pytest.approx(5.6397, abs=5e-5)
    assert math.remainder(res["l3.theta"][0], 2 * math.pi) == pytest.approx(-0.6435, abs=5e-5)
    assert res["l5.theta"][0] == pytest.approx(0.8627, abs=5e-5)
    assert res["l7.theta"][0] % (2 * math.pi) == pytest.approx(5.4205, abs=5e-5)
    assert res["l6.s"][0] == pytest.approx(4.6715, abs=5e-5)  # k
    assert res["l8.s"][0] == pytest.approx(4.6715, abs=5e-5)  # g
    assert res["l4.s"][0] == pytest.approx(4.0, abs=1e-12)  # c
    # the typed 4.6715 is the paper's rounding; the rods' exact 6.15 gives k = sqrt(6.15² − 4²)
    assert res["l6.s"][0] == pytest.approx(math.sqrt(6.15**2 - 16), abs=1e-12)
    assert system.assembly["moved"] == pytest.approx(4.6715 - math.sqrt(6.15**2 - 16), rel=1e-6)


def test_three_loops_of_two_unknowns(system):
    """Paper: L = 8, J = 10, three loops O2AB, BCE, BDE, each with two unknowns; M = 1."""
    mech = system.mechanism
    assert mech.gruebler() == (8, 10, 1)
    assert len(system.loops) == 3
    assert [len(b.unknowns) for b in system.blocks] == [2, 2, 2]
    assert [b.kind for b in system.blocks] == ["RRP", "RRP", "RRP"]
    names = [sorted(system.var_name(v) for v in b.unknowns) for b in system.blocks]
    assert names == [["s_l4", "θ_l3"], ["s_l6", "θ_l5"], ["s_l8", "θ_l7"]]
    # loop 1 takes the crank's θ2; loops 2 and 3 take c (s_l4) from loop 1, as in the paper
    loop_vars = [sorted(system.var_name(v) for v in system.loops[b.loops[0]].variables) for b in system.blocks]
    assert loop_vars[0] == ["s_l4", "θ_l2", "θ_l3"]
    assert loop_vars[1] == ["s_l4", "s_l6", "θ_l5"]
    assert loop_vars[2] == ["s_l4", "s_l8", "θ_l7"]
    # mobility from the Jacobian's rank at t = 0: 6 unknowns, full rank, so exactly 1 input fixes the motion
    J = loop_jacobian(system, system.q0, [0, 1, 2], list(system.unknowns))
    assert J.shape == (6, 6)
    assert np.linalg.matrix_rank(J) == 6
    assert len(system.q0) - np.linalg.matrix_rank(J) == 1


def test_loops_text_like_the_paper(system):
    text = describe(system)
    assert "loop 1 (O2–A–B):  a·e^{jθ_l2} + b·e^{jθ_l3} + c·e^{jπ} = 0" in text
    assert "f·e^{j3π/2}" in text  # the paper's k·e^{j3π/2}
    assert "unknown: θ_l3, c; input: θ_l2" in text
    latex = describe(system, latex=True)
    assert r"a\,e^{j \theta_{\mathrm{l2}}} + b\,e^{j \theta_{\mathrm{l3}}} + c\,e^{j \pi} &= 0" in latex


def test_health_is_clean(system):
    res = vloop.solve(system)
    assert len(res) == 48
    assert res.health["residual"].max() < 1e-14
    assert np.all(res.health["branch"] == res.health["branch"][0])
    assert 1 < res.health["cond"].max() < 100
