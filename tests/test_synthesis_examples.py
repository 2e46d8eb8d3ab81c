"""Published worked examples of dimensional synthesis, reproduced from their printed numbers.

Source (the only one whose printed digits could be read, see the report of the branch that added this file):
Haijun Su, *ME 3751: Kinematics and mechanisms, Lecture 12 — Analytical synthesis of 4-bar with three rocker
positions* (The Ohio State University; reading: Waldron & Kinzel, §3.1–3.2), slides 12 ("Lecture Problem: 3
Position Synthesis") and 13 ("Solution"); published as "Lecture 12 Three position synthesis.pdf" in
github.com/haijunsu-osu/rocker_synthesis_4bar.

Printed on slide 12: θ = 35.02°, 67.50°, 100.0° (input), φ = 91.21°, 101.79°, 117.19° (output), r1 = 4.5 in.
Printed on slide 13: the system [1 cos φ_i −cos θ_i]·z = cos(θ_i − φ_i) as

    [1 −0.0210 −0.8189] [1 −0.2043 −0.3827] [1 −0.4569 0.1732],  right-hand side 0.5566, 0.8262, 0.9552,

z1 = 5.150, z2 = 11.20, z3 = 5.321; r2 = 1/z2 = 0.0893, r4 = 1/z3 = 0.1879, r3 = √(1 + r2² + r4² − 2 r2 r4 z1) =
0.9329; R2 = 0.4018 in, R3 = 4.198 in, R4 = 0.8456 in.

The slide's z1, z2, z3 are vloop's Freudenstein K3, K1, K2 (K1 cos θ4 − K2 cos θ2 + K3 = cos(θ2 − θ4): divide
the slide's equation through; z2 = r1/r2 = d/a, z3 = r1/r4 = d/c, z1 = (1 + r2² + r4² − r3²)/(2 r2 r4)).
"""

from __future__ import annotations

import itertools
import math

import numpy as np

import vloop
import vloop.synthesis as syn
from validators.analytic import fourbar as analytic_fourbar
from vloop.synthesis.function import chebyshev
from vloop.synthesis.linkages import lengths

THETA_PRINTED = (35.02, 67.50, 100.0)  # [deg], slide 12
PHI_PRINTED = np.array([91.21, 101.79, 117.19])  # [deg], slide 12
MINUS_COS_THETA_PRINTED = (-0.8189, -0.3827, 0.1732)  # slide 13, third column
RHS_PRINTED = (0.5566, 0.8262, 0.9552)  # slide 13, cos(θ_i − φ_i)
R_PRINTED = {"crank": 0.4018, "coupler": 4.198, "rocker": 0.8456}  # [in], slide 13
R1 = 4.5  # [in]


def test_the_input_angles_are_chebyshev_spaced():
    """Three Chebyshev precision points over 30°–105°, by hand: x_j = 67.5° − 37.5°·cos((2j − 1)·30°) =
    67.5° ∓ 37.5°·(√3/2) = 35.024°, 67.500°, 99.976° — the printed 35.02°, 67.50°, 100.0° to the decimals printed
    (two, two, one). The slide solved with these unrounded angles: its column −cos θ_i, printed −0.8189,
    −0.3827, 0.1732, is −cos(35.024°), −cos(67.5°), −cos(99.976°) to four decimals (−cos(100.0°) would print
    0.1736). vloop's Chebyshev spacing reproduces both printed rows."""
    theta = chebyshev(30.0, 105.0, 3)
    assert [round(float(v), d) for v, d in zip(theta, (2, 2, 1), strict=True)] == list(THETA_PRINTED)
    assert [round(float(-math.cos(math.radians(v))), 4) for v in theta] == list(MINUS_COS_THETA_PRINTED)


def _by_hand(phi_deg: np.ndarray) -> np.ndarray:
    """The slide's 3×3 system solved by the test (Cramer's rule), θ Chebyshev-spaced: (z1, z2, z3, R2, R3, R4)."""
    th = np.radians(67.5 + 37.5 * np.cos(np.array([5, 3, 1]) * math.pi / 6))
    ph = np.radians(phi_deg)
    A = np.stack([np.ones(3), np.cos(ph), -np.cos(th)], 1)
    b = np.cos(th - ph)
    det = np.linalg.det(A)
    z = [np.linalg.det(np.where(np.arange(3)[None, :] == k, b[:, None], A)) / det for k in range(3)]
    r2, r4 = 1.0 / z[1], 1.0 / z[2]
    r3 = math.sqrt(1.0 + r2 * r2 + r4 * r4 - 2.0 * r2 * r4 * z[0])
    return np.array([*z, R1 * r2, R1 * r3, R1 * r4])


def test_freudenstein_three_precision_points_ohio_state_lecture_12():
    """vloop's function generator through the slide's three pairs (θ Chebyshev-spaced, φ as printed), ground
    O2O4 = r1 = 4.5 in.

    By hand (the test's own Cramer's rule on the slide's system): z = 5.1571, 11.2159, 5.3287; R2 = 0.40122,
    R3 = 4.19875, R4 = 0.84448 in. vloop's K3, K1, K2 and link lengths equal these to 1e-12 (relative).

    Against the printed digits: the right-hand side's second and third entries (0.8262, 0.9552) are reproduced to
    four decimals. The system is ill-conditioned (the three rows nearly dependent: κ(A) ≈ 320), so the printed
    φ's — rounded to 0.01°, ±0.005° — fix z and the lengths only to a band: solving at the eight corners of the
    box φ_i ± 0.005° gives R2 ∈ [0.3936, 0.4088], R3 ∈ [4.1938, 4.2038], R4 ∈ [0.8296, 0.8592] in and
    z2 ∈ [11.01, 11.43]. The printed answer (slide 13, from its own rounded entries) and vloop's both lie inside
    every band: the printed R3 = 4.198 is reproduced to 4.199 (the band is ±0.12 %), R2 and R4 to 0.14 %, which is
    all the printed inputs determine. (The slide's first entries, −0.0210 and 0.5566, are cos(91.203°) and
    cos(35.024° − 91.203°): it solved with φ1 unrounded; printed to 0.01° it reads 91.21°.)"""
    theta = chebyshev(30.0, 105.0, 3)
    pairs = np.radians(np.stack([theta, PHI_PRINTED], 1))
    out = syn.function(pairs=pairs.tolist(), ground=R1, name="osu_lecture12")
    cand = out[0]
    assert cand.solution, cand.defects
    got = lengths(cand.mechanism)
    hand = _by_hand(PHI_PRINTED)
    for key, k in (("crank", 3), ("coupler", 4), ("rocker", 5)):
        assert abs(got[key] - hand[k]) <= 1e-12 * hand[k], key
    rhs = np.cos(np.radians(theta - PHI_PRINTED))
    assert [round(float(v), 4) for v in rhs[1:]] == list(RHS_PRINTED[1:])
    band = np.array([_by_hand(PHI_PRINTED + 0.005 * np.array(s)) for s in itertools.product((-1, 1), repeat=3)])
    lo, hi = band.min(0), band.max(0)
    assert lo[1] <= 11.20 <= hi[1] and lo[0] <= 5.150 <= hi[0] and lo[2] <= 5.321 <= hi[2]
    for key, k in (("crank", 3), ("coupler", 4), ("rocker", 5)):
        assert lo[k] <= R_PRINTED[key] <= hi[k], key
        assert lo[k] <= got[key] <= hi[k], key
    assert f"{got['coupler']:.4g}" == "4.199" and abs(got["coupler"] - R_PRINTED["coupler"]) <= 0.0012 * R1


def test_lecture_12_generator_moves_through_its_pairs():
    """The generator's file, run by vloop and by the closed-form four-bar (validators/analytic/fourbar.py) at
    the instants it states: the rocker turns by φ2 − φ1 and φ3 − φ1 (printed angles) while the crank turns by
    θ2 − θ1 and θ3 − θ1, to 1e-9 rad — one assembly branch, no defect."""
    theta = chebyshev(30.0, 105.0, 3)
    pairs = np.radians(np.stack([theta, PHI_PRINTED], 1))
    cand = syn.function(pairs=pairs.tolist(), ground=R1)[0]
    for res in (
        vloop.solve(cand.mechanism, np.asarray(cand.times)),
        analytic_fourbar.solve(cand.mechanism, cand.times),
    ):
        crank, rocker = res["crank.theta"], res["rocker.theta"]
        assert np.max(np.abs((crank - crank[0]) - (pairs[:, 0] - pairs[0, 0]))) <= 1e-9
        assert np.max(np.abs((rocker - rocker[0]) - (pairs[:, 1] - pairs[0, 1]))) <= 1e-9
