"""Tests of the hand-derived closed forms (validators.analytic*) against real numbers.

* The eight-bar at t = 0 reproduces the paper's Table 1 to its printed digits,
  and a few t = 0 rates worked out by hand from Eqs. 4–5.
* Every closed form's rates agree with central differences of its own
  positions (and accelerations with central differences of its velocities).
* Four-bar and slider-crank t = 0 values against the law of cosines / rigid-link
  conditions written out here by hand.
* The non-Grashof limit angle satisfies the toggle condition, and the closed
  form stops exactly at the first sample beyond it.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

import vloop
from validators import analytic
from validators.analytic import eightbar as analytic_eightbar
from validators.analytic import fourbar as analytic_fourbar
from validators.analytic import slider_crank as analytic_slider_crank
from validators.analytic.common import LimitPositionError
from vloop.mechanism import Profile
from vloop.result import Result

MECH = Path(__file__).resolve().parents[1] / "mechanisms"
EPS = np.finfo(float).eps
TWO_PI = 2 * math.pi

FILES = {
    "eightbar": "eightbar",
    "fourbar_crank_rocker_open": "fourbar",
    "fourbar_crank_rocker_crossed": "fourbar",
    "slider_crank_offset": "slider_crank",
    "slider_crank_offset_crossed": "slider_crank",
    "fourbar_nongrashof_past_limit": "fourbar",
}


def load(name: str) -> vloop.Mechanism:
    return vloop.load(MECH / f"{name}.toml")


def with_driver(mech: vloop.Mechanism, **changes: object) -> vloop.Mechanism:
    drv = dataclasses.replace(mech.drivers[0], **changes)
    return dataclasses.replace(mech, drivers=(drv,))


# ---------------------------------------------------------------- the paper's eight-bar


def test_eightbar_reproduces_table1_at_t0() -> None:
    res = analytic.solve(load("eightbar"))
    assert res.engine == "analytic" and res.meta["closed_form"] == "eightbar"
    assert res.t[0] == 0.0
    assert res["l2.theta"][0] == pytest.approx(math.pi / 2, abs=1e-15)
    # Table 1, to the printed digits
    assert round(res["l3.theta"][0] % TWO_PI, 4) == 5.6397
    assert round(res["l3.theta"][0] % TWO_PI - TWO_PI, 4) == -0.6435
    assert round(res["l5.theta"][0] % TWO_PI, 4) == 0.8627
    assert round(res["l7.theta"][0] % TWO_PI, 4) == 5.4205
    assert round(res["l4.s"][0], 4) == 4.0  # c
    assert round(res["l6.s"][0], 4) == 4.6715  # k
    assert round(res["l8.s"][0], 4) == 4.6715  # g
    assert res["l4.theta"][0] == 0.0 and res["l6.theta"][0] == pytest.approx(math.pi / 2)
    assert res["l8.theta"][0] == pytest.approx(3 * math.pi / 2)
    # the exact values behind the rounded ones: tan θ3 = −3/4, k = √(6.15² − 4²)
    assert res["l3.theta"][0] == pytest.approx(TWO_PI - math.atan2(3, 4), abs=1e-14)
    assert res["l6.s"][0] == pytest.approx(math.sqrt(6.15**2 - 16), abs=1e-14)
    assert res["l5.theta"][0] == pytest.approx(math.acos(4 / 6.15), abs=1e-14)


def test_eightbar_t0_rates_by_hand() -> None:
    """Eq. 4–5 at θ2 = π/2, ω2 = 3, α2 = 0: cos θ2 = 0, so ω3 = 0 and ċ = −a·ω2 = −9;
    α3 = a·ω2²/(b·cos θ3) = 27/4; c̈ = −b·α3·sin θ3 = 5·6.75·0.6 = 20.25;
    ω5 = ċ/k, k = √(6.15² − 16)."""
    res = analytic.solve(load("eightbar"))
    k = math.sqrt(6.15**2 - 16)
    assert res["l3.omega"][0] == pytest.approx(0.0, abs=1e-14)
    assert res["l4.v"][0] == pytest.approx(-9.0, abs=1e-13)
    assert res["B.vx"][0] == pytest.approx(-9.0, abs=1e-13) and res["B.vy"][0] == 0.0
    assert res["l3.alpha"][0] == pytest.approx(6.75, abs=1e-13)
    assert res["l4.a"][0] == pytest.approx(20.25, abs=1e-12)
    assert res["l5.omega"][0] == pytest.approx(-9.0 / k, abs=1e-13)
    assert res["A.vx"][0] == pytest.approx(-9.0, abs=1e-13)  # v_A = j·ω2·a·e^{jπ/2} = −9
    assert res["A.ay"][0] == pytest.approx(-27.0, abs=1e-13)  # −ω2²·a


def test_eightbar_symmetry_and_constraints() -> None:
    """Fig. 1 is symmetric about the x-axis: θ7 = −θ5, g = k, at every t; B stays on
    y = 0, C and D on x = 8 (v_By = v_Cx = v_Dx = 0, as in the paper's Discussion)."""
    res = analytic.solve(load("eightbar"))
    d = (res["l5.theta"] + res["l7.theta"] + math.pi) % TWO_PI - math.pi
    assert np.max(np.abs(d)) < 1e-13
    np.testing.assert_allclose(res["l8.s"], res["l6.s"], atol=1e-13)
    for col in ("B.y", "B.vy", "B.ay", "C.vx", "C.ax", "D.vx", "D.ax"):
        assert np.max(np.abs(res[col])) < 1e-12, col
    np.testing.assert_allclose(res["C.x"], 8.0, atol=1e-14)
    # links keep their lengths: |AB| = 5, |BC| = 6.15
    for p, q, length in (("A", "B", 5.0), ("B", "C", 6.15), ("B", "D", 6.15), ("O2", "A", 3.0)):
        dist = np.hypot(res[f"{q}.x"] - res[f"{p}.x"], res[f"{q}.y"] - res[f"{p}.y"])
        np.testing.assert_allclose(dist, length, atol=1e-13)


def test_eightbar_loop1_matches_independent_slider_crank_form() -> None:
    """Loop 1 of the eight-bar (paper's Eq. 3 form) equals the general slider-crank
    derivation (rotated-frame form) for the same crank, rod and line, with α2 ≠ 0."""
    eb = with_driver(load("eightbar"), a0=-2.5)
    text = """
        name = "sc"
        [joints]
        O2 = [0.0, 0.0]
        A = [0.0, 3.0]
        B = [4.0, 0.0]
        [links]
        ground = { joints = ["O2"], ground = true }
        l2 = ["O2", "A"]
        l3 = ["A", "B"]
        [sliders]
        l4 = { joint = "B", guide = "ground", axis = [1.0, 0.0] }
        [[drivers]]
        link = "l2"
        omega = 3.0
        alpha = -2.5
        [time]
        start = 0.0
        stop = 2.35
        step = 0.05
    """
    sc = vloop.loads(text)
    a, b = analytic.solve(eb), analytic.solve(sc)
    assert b.meta["closed_form"] == "slider_crank"
    for col in ("l3.theta", "l3.omega", "l3.alpha", "l4.s", "l4.v", "l4.a", "B.x", "B.ax", "A.ay"):
        np.testing.assert_allclose(a[col], b[col], rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(b[col]))))


# ---------------------------------------------------------------- finite differences

H = 1e-4  # [s] central-difference step


def stencil(centers: np.ndarray) -> np.ndarray:
    """Times c − H, c, c + H for every center (strictly increasing: centers ≥ 0.01 s apart)."""
    return np.stack([centers - H, centers, centers + H], axis=1).ravel()


@dataclasses.dataclass(frozen=True)
class FDCheck:
    """Worst disagreement of one rate with central differences over a run."""

    ratio: float  # max |FD − rate| / allowed (truncation + rounding bound)
    rel: float  # max |FD − rate| / peak of the rate (of the vector's magnitude for a point)
    refined_ratio: float  # the same after removing the leading truncation term h²/6·x'''
    refined_rel: float


def fd_errors(res: Result) -> dict[str, FDCheck]:
    """Check every rate column of ``res`` (sampled on :func:`stencil`) against central differences.

    Central difference: (x(t+h) − x(t−h))/(2h) = ẋ(t) + h²/6·x'''(t) + O(h⁴), so the truncation
    error is at most h²/6·max|x'''|; x''' is estimated from the closed form's own ẍ by
    (ẍ₊ − ẍ₋)/(2h) (and ẋ''' = x⁗ by (ẍ₊ − 2ẍ₀ + ẍ₋)/h²). Rounding adds about k·ε·max|x|/h, k the
    few ulps of error of a closed-form value, |x| the magnitude of the whole vector for a
    point's x/y (an identically zero component still carries the other's round-off).
    Allowed: 2·h²/6·max|x'''| + 50·ε·max|x|/h.
    Refined: FD − h²/6·x''' − ẋ is O(h⁴)·x⁽⁵⁾/120 (≈ 1e-16·x⁽⁵⁾, negligible here) plus rounding,
    including the estimate's own (h²/6 times ε·|ẍ|/h or 4ε·|ẍ|/h²); allowed: 50·ε·max|x|/h + 5·ε·max|ẍ|.
    A wrong rate (or a sign slip in an α2, ω² or Coriolis-like term) fails both.
    """
    out = {}
    triples = [(f"{n}.theta", f"{n}.omega", f"{n}.alpha", None) for n in res.names("link")]
    triples += [(f"{n}.{x}", f"{n}.v{x}", f"{n}.a{x}", n) for n in res.names("point") for x in "xy"]
    triples += [(f"{n}.s", f"{n}.v", f"{n}.a", None) for n in res.names("slider")]
    for x_c, v_c, a_c, point in triples:
        x, v, a = (res[c].reshape(-1, 3) for c in (x_c, v_c, a_c))
        if point is None:
            size = [float(np.max(np.abs(q))) for q in (x, v, a)]
        else:
            size = [float(np.max(np.hypot(res[f"{point}.{p}x"], res[f"{point}.{p}y"]))) for p in ("", "v", "a")]
        jerk = (a[:, 2] - a[:, 0]) / (2 * H)
        snap = (a[:, 2] - 2 * a[:, 1] + a[:, 0]) / H**2
        for val, der, third, mag, dmag, col in (
            (x, v, jerk, size[0], size[1], v_c),
            (v, a, snap, size[1], size[2], a_c),
        ):
            fd = (val[:, 2] - val[:, 0]) / (2 * H)
            err = float(np.max(np.abs(fd - der[:, 1])))
            refined = float(np.max(np.abs(fd - H**2 / 6 * third - der[:, 1])))
            allowed = 2 * H**2 / 6 * float(np.max(np.abs(third))) + 50 * EPS * mag / H
            allowed_refined = 50 * EPS * mag / H + 5 * EPS * size[2]
            out[col] = FDCheck(
                err / allowed if err > 0 else 0.0,
                err / dmag if dmag > 0 else err,
                refined / allowed_refined if refined > 0 else 0.0,
                refined / dmag if dmag > 0 else refined,
            )
    return out


def fd_cases() -> list[tuple[str, vloop.Mechanism, np.ndarray]]:
    cases = []
    for name in FILES:
        m = load(name)
        centers = m.times
        if name == "fourbar_nongrashof_past_limit":
            centers = centers[centers <= 1.6]  # stay 0.1 rad of input clear of the limit (t = 1.728 s)
        cases.append((name, m, centers))
    eb = load("eightbar")
    cases.append(("eightbar, alpha2 = 1.5", with_driver(eb, a0=1.5), eb.times))
    return cases


@pytest.mark.parametrize("case", fd_cases(), ids=lambda c: c[0])
def test_rates_match_central_differences(case: tuple[str, vloop.Mechanism, np.ndarray]) -> None:
    name, mech, centers = case
    res = analytic.solve(mech, stencil(centers))
    errs = fd_errors(res)
    assert len(errs) >= 12
    bad = {c: e for c, e in errs.items() if e.ratio > 1.0 or e.refined_ratio > 1.0}
    assert not bad, f"{name}: central differences disagree: {bad}"
    # in figures: within 1e-6 of each rate's peak (h = 1e-4 s), and 1e-10 once the
    # leading h²/6 truncation term is taken off (measured ≲ 6e-7 and ≲ 2e-11)
    assert max(e.rel for e in errs.values()) < 1e-6
    assert max(e.refined_rel for e in errs.values()) < 1e-10


# ---------------------------------------------------------------- four-bar by hand


@pytest.mark.parametrize("branch", ["open", "crossed"])
def test_fourbar_t0_by_law_of_cosines(branch: str) -> None:
    """a = 2, b = 6, c = 5, d = 7, θ2 = 60°: f² = a² + d² − 2ad·cos 60° = 39.
    At O4: cos∠O2O4A = (d² + f² − a²)/(2df) = 6/√39, cos∠AO4B = (c² + f² − b²)/(2cf) = 2.8/√39;
    θ4 = π − ∠O2O4A ∓ ∠AO4B (open: −, crossed: +). Transmission angle:
    cos μ = (b² + c² − f²)/(2bc) = 22/60, and θ4 − θ3 = ±μ."""
    mech = load(f"fourbar_crank_rocker_{branch}")
    res = analytic.solve(mech)
    f = math.sqrt(39.0)
    at_o4 = math.acos(6 / f)
    o4ab = math.acos(2.8 / f)
    th4 = math.pi - at_o4 - o4ab if branch == "open" else math.pi - at_o4 + o4ab
    mu = math.acos(22 / 60)
    assert res["l4.theta"][0] == pytest.approx(th4, abs=1e-13)
    assert th4 == pytest.approx(1.754690 if branch == "open" else 3.966426, abs=1e-6)
    d34 = (res["l4.theta"][0] - res["l3.theta"][0]) % TWO_PI
    assert d34 == pytest.approx(mu if branch == "open" else TWO_PI - mu, abs=1e-13)
    assert res.meta["branch"] == (1 if branch == "open" else -1)
    # B and the coupler point P reproduce the file's t = 0 coordinates
    for p in ("B", "P"):
        x0, y0 = mech.points[p].at if p in mech.points else mech.joints[p]
        assert res[f"{p}.x"][0] == pytest.approx(x0, abs=1e-13)
        assert res[f"{p}.y"][0] == pytest.approx(y0, abs=1e-13)


@pytest.mark.parametrize("branch", ["open", "crossed"])
def test_fourbar_t0_rates_from_rigid_link_conditions(branch: str) -> None:
    """Rigid coupler: (v_B − v_A)·(B − A) = 0 with v_B = ω4·j(B − O4), so
    ω4 = v_A·(B − A) / (j(B − O4))·(B − A), and ω3 = (v_B − v_A)·j(B − A)/b².
    v_A = j·ω2·(A − O2) with ω2 = 2. The coupler point: v_P = v_A + ω3·j(P − A)."""
    res = analytic.solve(load(f"fourbar_crank_rocker_{branch}"))
    pt = {n: complex(res[f"{n}.x"][0], res[f"{n}.y"][0]) for n in ("A", "B", "O4", "P")}
    A, B, O4, P = pt["A"], pt["B"], pt["O4"], pt["P"]

    def dot(u: complex, v: complex) -> float:
        return (u.conjugate() * v).real

    vA = 2j * A
    w4 = dot(vA, B - A) / dot(1j * (B - O4), B - A)
    vB = w4 * 1j * (B - O4)
    w3 = dot(vB - vA, 1j * (B - A)) / 36.0
    vP = vA + w3 * 1j * (P - A)
    assert res["l4.omega"][0] == pytest.approx(w4, abs=1e-13)
    assert res["l3.omega"][0] == pytest.approx(w3, abs=1e-13)
    assert complex(res["P.vx"][0], res["P.vy"][0]) == pytest.approx(vP, abs=1e-13)
    assert res["l2.alpha"][0] == 0.5


def test_fourbar_open_and_crossed_are_mirror_images_of_the_same_chain() -> None:
    """The two assemblies of one input: B mirrored across the diagonal A–O4 at every t."""
    o, c = analytic.solve(load("fourbar_crank_rocker_open")), analytic.solve(load("fourbar_crank_rocker_crossed"))
    np.testing.assert_allclose(o["A.x"], c["A.x"], atol=1e-15)
    A = o["A.x"] + 1j * o["A.y"]
    u = (7.0 - A) / np.abs(7.0 - A)
    Bo, Bc = o["B.x"] + 1j * o["B.y"], c["B.x"] + 1j * c["B.y"]
    mirrored = A + u * np.conj((Bo - A) / u)
    np.testing.assert_allclose(Bc, mirrored, atol=1e-12)
    assert analytic_fourbar.grashof(load("fourbar_crank_rocker_open")) == "crank-rocker"
    assert analytic_fourbar.limit_angles(load("fourbar_crank_rocker_open")) == ()


def test_fourbar_roles_found_by_structure_not_names() -> None:
    """Drive the same chain at the rocker with the crank-driven run's θ4, ω4, α4 as a
    profile (up to t = 1 s, before the rocker's first reversal at 1.24 s): the closed
    form (roles swapped by structure) gives back the crank's motion."""
    mech = load("fourbar_crank_rocker_open")
    ref = analytic.solve(mech)
    keep = ref.t <= 1.0
    t = ref.t[keep]
    prof = Profile(t, ref["l4.theta"][keep], ref["l4.omega"][keep], ref["l4.alpha"][keep])
    m2 = dataclasses.replace(
        mech,
        drivers=(vloop.mechanism.Driver("crank", "l4", float(prof.x[0]), pivot="O4", profile=prof),),
        times=t,
    )
    assert analytic.closed_form_for(m2) is analytic_fourbar
    res = analytic.solve(m2)
    for col in ("l2.theta", "l2.omega", "l2.alpha", "l3.omega", "l3.alpha", "P.x", "P.ay"):
        scale = max(1.0, float(np.max(np.abs(ref[col][keep]))))
        np.testing.assert_allclose(res[col], ref[col][keep], rtol=0, atol=1e-11 * scale, err_msg=col)


# ---------------------------------------------------------------- slider-crank by hand


@pytest.mark.parametrize("branch", ["open", "crossed"])
def test_slider_crank_t0_by_hand(branch: str) -> None:
    """a = 2, b = 6, line y = e = 1, θ2 = 45°, ω2 = 4, α2 = 1:
    sin θ3 = (e − a·sin 45°)/b = (1 − √2)/6; s = a·cos 45° ± b·cos θ3 (open +, crossed −).
    Rigid rod: v_B·(B − A) = v_A·(B − A) with v_B = (v, 0), so v = v_A·(B − A)/(x_B − x_A)."""
    res = analytic.solve(load("slider_crank_offset" + ("" if branch == "open" else "_crossed")))
    sgn = 1.0 if branch == "open" else -1.0
    s3 = (1 - math.sqrt(2)) / 6
    c3 = sgn * math.sqrt(1 - s3 * s3)
    assert res["l3.theta"][0] % TWO_PI == pytest.approx(math.atan2(s3, c3) % TWO_PI, abs=1e-14)
    s = math.sqrt(2) + 6 * c3
    assert res["l4.s"][0] == pytest.approx(s, abs=1e-14)
    assert s == pytest.approx(7.399899 if branch == "open" else -4.571472, abs=1e-6)
    A = complex(math.sqrt(2), math.sqrt(2))
    vA = 4j * A
    B = complex(s, 1.0)
    v = (vA.conjugate() * (B - A)).real / (B - A).real
    assert res["l4.v"][0] == pytest.approx(v, abs=1e-13)
    assert res["B.vy"][0] == pytest.approx(0.0, abs=1e-13)
    assert res.meta["offset"] == 1.0 and res.meta["branch"] == sgn
    assert np.max(np.abs(res["B.y"] - 1.0)) < 1e-14


# ---------------------------------------------------------------- non-Grashof limit


def test_nongrashof_limit_angle_is_a_toggle() -> None:
    """a = 3, b = 4, c = 4.5, d = 6 (s + l = 9 > p + q = 8.5): at the limit the coupler and
    rocker are stretched collinear, |A − O4| = b + c, i.e. cos θ2 = (9 + 36 − 72.25)/36."""
    mech = load("fourbar_nongrashof_past_limit")
    assert analytic_fourbar.grashof(mech) == "non-Grashof (triple rocker)"
    lims = analytic_fourbar.limit_angles(mech)
    assert len(lims) == 2
    hand = math.acos(-27.25 / 36)
    assert lims[0] == pytest.approx(hand, abs=1e-15) and lims[1] == pytest.approx(TWO_PI - hand, abs=1e-14)
    O4 = 6.0
    for th in lims:
        A = 3.0 * complex(math.cos(th), math.sin(th))
        f = abs(O4 - A)
        assert abs(f - 8.5) < 1e-12 * 8.5
        # B at the toggle: 4 from A towards O4; then |B − O4| = c and AB, BO4 are collinear
        B = A + 4.0 * (O4 - A) / f
        assert abs(abs(B - O4) - 4.5) < 1e-12
        assert abs(((B - A).conjugate() * (O4 - B)).imag) < 1e-12
    # approaching the limit the coupler and rocker line up: sin(θ3 − θ4) → 0 like √(θ_lim − θ2)
    near = [lims[0] - 1e-4, lims[0] - 1e-6]
    res = analytic.solve(mech, (np.array(near) - math.pi / 3) / 0.8)
    sin34 = np.abs(np.sin(res["l3.theta"] - res["l4.theta"]))
    assert sin34[1] < sin34[0] / 5 and sin34[1] < 1e-2


def test_nongrashof_run_stops_at_first_sample_past_the_limit() -> None:
    mech = load("fourbar_nongrashof_past_limit")
    lim = analytic_fourbar.limit_angles(mech)[0]
    drv = mech.drivers[0]
    theta = drv.x0 + drv.v0 * mech.times
    k = int(np.argmax(theta > lim))
    assert k == 173 and 0.2 * len(mech.times) < k < 0.8 * len(mech.times)
    assert theta[0] == pytest.approx(math.pi / 3)
    with pytest.raises(LimitPositionError) as info:
        analytic.solve(mech)
    err = info.value
    assert isinstance(err, ValueError)
    assert err.sample == k and err.time == pytest.approx(1.73)
    assert err.input_value == pytest.approx(theta[k]) and err.limit == pytest.approx(lim)
    assert "sample 173" in str(err) and "t = 1.73 s" in str(err)
    part = err.partial
    assert part is not None and len(part) == k
    assert all(np.all(np.isfinite(v)) for v in part.columns.values())
    # the partial rows are the same as a run over the first k samples
    np.testing.assert_array_equal(part["l4.theta"], analytic.solve(mech, mech.times[:k])["l4.theta"])


# ---------------------------------------------------------------- dispatcher and output


@pytest.mark.parametrize("name", FILES)
def test_dispatcher_picks_by_structure(name: str) -> None:
    mech = load(name)
    assert analytic.available(mech)
    assert analytic.closed_form_for(mech).NAME == FILES[name]
    matches = [m.NAME for m in analytic.CLOSED_FORMS if m.applies(mech)]
    assert matches == [FILES[name]]


def test_dispatcher_refuses_unknown_structure() -> None:
    """The eight-bar driven by a linear actuator on its slider l4: no closed form here (they need a crank)."""
    text = (MECH / "eightbar.toml").read_text()
    text = text.replace(
        'link = "l2"\npivot = "O2"\nomega = 3.0   # rad/s\nalpha = 0.0   # rad/s^2', 'slider = "l4"\nv = 0.5'
    )
    mech = vloop.loads(text)
    assert mech.drivers[0].kind == "slider"
    assert not analytic.available(mech)
    assert not any(m.applies(mech) for m in (analytic_eightbar, analytic_slider_crank, analytic_fourbar))
    with pytest.raises(ValueError, match="no closed form applies"):
        analytic.solve(mech)


@pytest.mark.parametrize("name", FILES)
def test_output_columns_and_angle_anchoring(name: str) -> None:
    mech = load(name)
    times = mech.times[mech.times <= 1.5]
    res = analytic.solve(mech, times)
    cols = set(res.columns)
    bodies = mech.bodies()
    for b in mech.moving_links:
        assert {f"{b}.theta", f"{b}.omega", f"{b}.alpha"} <= cols
        # continuous, and at t = 0 the turn nearest the coordinates' angle
        assert np.max(np.abs(np.diff(res[f"{b}.theta"]))) < 0.5
        assert abs(res[f"{b}.theta"][0] - bodies[b].theta0) < 1e-4
    for p in mech.tracked_points:
        assert {f"{p}.x", f"{p}.vy", f"{p}.ay"} <= cols
    for s in mech.sliders:
        assert {f"{s}.s", f"{s}.v", f"{s}.a"} <= cols
    # a grid that does not contain t = 0 gives the same (unwrapped) values
    later = analytic.solve(mech, times[10:])
    for c in later.columns:
        np.testing.assert_allclose(later[c], res[c][10:], rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(res[c]))))
