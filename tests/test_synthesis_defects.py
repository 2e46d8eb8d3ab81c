"""Synthesis names each defect as docs/synthesis.md defines it, on linkages built here to have exactly that defect.

Each case is a four-bar drawn by the test's own geometry (circle intersections, the side of the diagonal A–O4
chosen by hand), its arcs of input angles by the law of cosines written here (|AO4|² = a² + d² − 2ad·cos θ within
[(b − c)², (b + c)²]), and three coupler poses at crank angles placed by hand on a chosen arc and assembly side.
Motion generation gets the four-bar's own ground pivots as the free choices, so its own-pivot candidate is the
drawn linkage; the test asserts the defect's name, and where the candidate's run reaches a pose, that the
closed form (validators/analytic/fourbar.py) puts the coupler there at the instant the candidate states.

* circuit — positions on different circuits (a crank-rocker's two assemblies; a rocker-driven Grashof
  linkage's two arcs);
* branch — one circuit, different branches (a triple rocker's arc, both sides of the diagonal; the same on one
  arc of a rocker-driven Grashof linkage, which was once named "circuit");
* order — one branch, met in another order (the triple rocker with poses at −55.71°, 110.27°, −0.38°: turning
  counter-clockwise meets pose 3 before pose 2, and clockwise the input would have to pass the gap of its arc);
* none — a crank-rocker's poses in order on one assembly.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import vloop.synthesis as syn
from validators.analytic import fourbar as analytic_fourbar
from vloop.synthesis.circuits import classify, screen
from vloop.synthesis.linkages import FOURBAR

from .test_synthesis import TOL, assert_recovered, circle_meet, own_pair


def build(a: float, b: float, c: float, d: float, thetas_deg, sides, tracer=complex(0.4, 0.5)):
    """Poses of a four-bar O2 = 0, O4 = (d, 0), crank a at each θ (degrees), B on side ``sides[k]`` of A → O4, a
    tracer P = A + (B − A)·tracer; returns (coordinates at pose 1, poses [[x, y, θ3]])."""
    out = []
    for th, s in zip(thetas_deg, sides, strict=True):
        A = a * np.exp(1j * math.radians(th))
        B = circle_meet(A, b, complex(d), c, s)
        out.append({"O2": 0j, "A": A, "B": B, "O4": complex(d), "P": A + (B - A) * tracer})
    rows = [[z["P"].real, z["P"].imag, float(np.angle(z["B"] - z["A"]))] for z in out]
    return out[0], rows


def arc_limits(a: float, b: float, c: float, d: float) -> tuple[float, float]:
    """cos θ bounds of the crank's reachable angles (this test's own law of cosines)."""
    return (a * a + d * d - (b + c) ** 2) / (2 * a * d), (a * a + d * d - (b - c) ** 2) / (2 * a * d)


def synthesized(a, b, c, d, thetas, sides) -> syn.Candidate:
    coords, rows = build(a, b, c, d, thetas, sides)
    out = syn.motion(rows, dyads=[{"fixed": (0.0, 0.0)}, {"fixed": (d, 0.0)}])
    cand = own_pair(out, coords, max(a, b, c, d))
    assert_recovered(cand, coords, max(a, b, c, d))
    return cand


# a triple rocker (s + l = 2.5 > p + q = 2.247): its crank rocks on one arc about θ = 0, |θ| ≤ 126.85°, where
# coupler and rocker stretch (|AO4| = b + c); folded (|b − c| = 0.153) is below |a − d| = 0.5: never reached
TRIPLE = (1.0, 1.2, 1.047, 1.5)
# a Grashof crank-rocker (crank 0.3 shortest, 0.3 + 1.3 < 1.0 + 1.2): the crank turns fully, two assemblies
CRANK_ROCKER = (0.3, 1.0, 1.2, 1.3)
# the same kind of Grashof linkage driven from its rocker (0.8; crank 0.3 as the output): two arcs, θ between
# ±44.05° and ±91.79°, each with both assembly sides
ROCKER_DRIVEN = (0.8, 1.0, 0.3, 1.0)


def test_the_hand_built_linkages_are_what_they_claim():
    lo, hi = arc_limits(*TRIPLE)
    assert hi >= 1 and -1 < lo and math.degrees(math.acos(lo)) == pytest.approx(126.85, abs=0.01)
    lo, hi = arc_limits(*CRANK_ROCKER)
    assert lo <= -1 and hi >= 1
    lo, hi = arc_limits(*ROCKER_DRIVEN)
    assert -1 < lo < hi < 1
    assert [math.degrees(math.acos(v)) for v in (hi, lo)] == pytest.approx([44.05, 91.79], abs=0.01)


def test_order_defect_on_a_triple_rockers_arc():
    """Poses at −55.71°, 110.27°, −0.38° on one branch: counter-clockwise the crank meets pose 3 (−0.38°) before
    pose 2; clockwise it would leave its arc (limit at −126.85°) before pose 2. An order defect, never a branch
    defect: the candidate turns counter-clockwise, its run reaches all three poses (errors round-off), at the
    instants 165.98° and 55.33° of crank turn, where the closed form agrees."""
    thetas = (-55.71, 110.27, -0.38)
    c = synthesized(*TRIPLE, thetas, (1, 1, 1))
    assert c.defects == ("order",) and not c.solution
    assert c.mechanism.drivers[0].v0 == 1.0
    assert np.degrees(c.times) == pytest.approx([0.0, 165.98, 55.33], abs=1e-9)
    assert np.max(c.errors) <= TOL * 1.5 and np.max(c.angle_errors) <= TOL
    res = analytic_fourbar.solve(c.mechanism, np.sort(c.times))
    crank = np.degrees(np.angle(np.exp(1j * res["crank.theta"])))
    assert crank == pytest.approx(sorted([-55.71, -0.38, 110.27]), abs=1e-9)
    assert "counter-clockwise: 1, 3, 2" in " ".join(c.notes)


def test_branch_defect_on_a_triple_rockers_arc():
    """Three poses on the triple rocker's one arc, the second with B on the other side of A → O4: one circuit,
    two branches (a toggle between them): a branch defect."""
    c = synthesized(*TRIPLE, (-55.71, 20.0, 60.0), (1, -1, 1))
    assert c.defects == ("branch",) and not c.solution
    assert "position 2 is on the other branch" in " ".join(c.notes)


def test_branch_defect_on_one_arc_of_a_grashof_linkage():
    """A Grashof linkage driven from its rocker, three poses on one arc (50°, 60°, 70°), the third on the other
    side: the same circuit, the other branch — a branch defect, not a circuit defect."""
    c = synthesized(*ROCKER_DRIVEN, (50.0, 60.0, 70.0), (1, 1, -1))
    assert c.grashof.startswith("Grashof") and c.defects == ("branch",)


def test_circuit_defect_across_a_grashof_linkages_arcs():
    """The rocker-driven Grashof linkage with pose 3 on its other arc (−55°): the linkage must be taken apart."""
    c = synthesized(*ROCKER_DRIVEN, (50.0, 65.0, -55.0), (1, 1, 1))
    assert c.defects == ("circuit",) and "the input's two arcs" in " ".join(c.notes)


def test_circuit_defect_across_a_crank_rockers_assemblies():
    """A crank-rocker (full turn: each assembly a circuit) with pose 2 on the other assembly: a circuit defect;
    its run meets pose 2's crank angle on its own circuit, far from the pose."""
    c = synthesized(*CRANK_ROCKER, (0.0, 90.0, 200.0), (1, -1, 1))
    assert c.defects == ("circuit",)
    assert c.errors[1] > 0.05 and abs(c.errors[2]) <= TOL * 1.3


def test_no_defect_in_order_on_one_assembly():
    """The crank-rocker's poses at 0°, 90°, 200° on one assembly: a solution; the closed form at its instants
    puts the tracer on each pose to round-off."""
    _, rows = build(*CRANK_ROCKER, (0.0, 90.0, 200.0), (1, 1, 1))
    c = synthesized(*CRANK_ROCKER, (0.0, 90.0, 200.0), (1, 1, 1))
    assert c.defects == () and c.solution
    res = analytic_fourbar.solve(c.mechanism, c.times)
    z = res["P.x"] + 1j * res["P.y"]
    assert np.max(np.abs(z - np.array([r[0] + 1j * r[1] for r in rows]))) <= TOL


def test_function_generation_runs_into_its_cranks_limit():
    """Freudenstein through three pairs of the triple rocker (crank 0°, 40°, 80°; its own rocker angles): its own
    linkage, no defect over an input range of 0°..80°; asked to turn the input to 150°, past its limit at
    126.85°, a branch defect whose note names the crank's arc."""
    rows = []
    for th in (0.0, 40.0, 80.0):
        z, _ = build(*TRIPLE, (th,), (1,))
        rows.append([math.radians(th), float(np.angle(z["B"] - z["O4"]))])
    ok = syn.function(pairs=rows, ground=TRIPLE[3])
    assert ok[0].defects == () and ok[0].dims["crank"] == pytest.approx(TRIPLE[0], rel=1e-9)
    far = syn.function(pairs=rows, ground=TRIPLE[3], input_range=(0.0, math.radians(150.0)))
    assert far[0].defects == ("branch",)
    assert "rocks between -126.85° and 126.85°" in " ".join(far[0].notes)
    assert FOURBAR.name == far[0].topology


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.filter_too_much])
@given(
    lengths=st.tuples(*[st.floats(0.2, 2.0)] * 4),
    thetas=st.lists(st.floats(-math.pi, math.pi), min_size=3, max_size=5),
    sides=st.lists(st.sampled_from([-1, 1]), min_size=5, max_size=5),
)
def test_the_population_screen_is_the_same_rule(lengths, thetas, sides):
    """circuits.screen (a search's whole population at once) and circuits.classify (one linkage) agree on random
    four-bars placed at random reachable crank angles and sides: a row passes the screen exactly when classify
    names no defect, with the same direction and instants."""
    a, b, c, d = lengths
    gaps = np.abs(np.angle(np.exp(1j * (np.array(thetas)[:, None] - np.array(thetas)[None, :]))))
    assume(np.all(gaps[np.triu_indices(len(thetas), 1)] > 1e-9))  # two positions at one input angle have no order
    configs = []
    for th, s in zip(thetas, sides, strict=False):
        A = a * np.exp(1j * th)
        f = abs(d - A)
        assume(abs(b - c) + 1e-3 < f < b + c - 1e-3)
        configs.append({"O2": 0j, "A": A, "B": circle_meet(A, b, complex(d), c, s), "O4": complex(d)})
    verdict = classify(FOURBAR, configs)
    rows = {k: np.array([[z[k] for z in configs]]) for k in ("O2", "A", "B", "O4")}
    omega, times, ok = screen(FOURBAR, rows)
    assert bool(ok[0]) == (verdict.kind == "")
    if ok[0]:
        assert omega[0] == verdict.omega and times[0] == pytest.approx(verdict.times, abs=1e-12)
