"""The mechanism catalog: classic linkages of a kinematics course, each with an independent reference.

* Every catalog file is documented, assembles at t = 0 as written, runs with ``vloop run``,
  keeps every link rigid (ternary links included) and matches its hand-derived closed form
  (validators/analytic/*.py) within 1e-9 of each quantity's peak (measured: ~1e-14).
* The textbook four-bar's t = 0 values are worked out here by hand.
* Whitworth and inverted slider-crank time ratios: closed form vs the geometric formula.
* The five-bar's mobility 2, the Jansen pair's six loops, the rocking non-Grashof input.

Finite differences over every catalog file are in tests/test_solver.py; the Jansen pair also
gets a sharper five-point check here.
"""

from __future__ import annotations

import cmath
import math
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import brentq

import vloop
from validators import analytic
from validators.analytic import fourbar as analytic_fourbar
from validators.analytic import inverted_slider_crank as analytic_inverted_slider_crank
from validators.analytic import whitworth as analytic_whitworth
from vloop.cli import main as vloop_main
from vloop.compare import assert_histories_close

MECH = Path(__file__).resolve().parents[1] / "mechanisms"

# catalog file -> the closed form that must be picked for it (validators/analytic/<NAME>.py)
CATALOG = {
    "fourbar_textbook_example": "fourbar",
    "inverted_slider_crank": "inverted_slider_crank",
    "whitworth_quick_return": "whitworth",
    "sixbar_watt2": "sixbar_watt2",
    "sixbar_stephenson3": "sixbar_stephenson3",
    "fivebar_two_cranks": "fivebar",
    "jansen_pair": "jansen",
    "fourbar_nongrashof_rocking": "fourbar",
}
ALL_GROUPS = {"angle", "angular velocity", "angular acceleration", "position", "velocity", "acceleration"}


def load(stem: str) -> vloop.Mechanism:
    return vloop.load(MECH / f"{stem}.toml")


# ---------------------------------------------------------------- every catalog file


@pytest.mark.parametrize("stem", CATALOG)
def test_catalog_file_is_documented_assembles_and_runs(stem: str, tmp_path: Path) -> None:
    path = MECH / f"{stem}.toml"
    header = []
    for line in path.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        header.append(line)
    assert len(header) >= 8, f"{stem}: the header comment should say what it is, its dimensions and its source"
    mech = vloop.load(path)
    assert mech.name == stem and mech.title
    assert 100 <= len(mech.times) <= 400
    # assemblable as written: the t = 0 assembly moves no joint by more than round-off
    system = vloop.compile(mech)
    assert system.assembly["moved"] <= 1e-12 * mech.scale
    assert vloop_main(["run", str(path), "--out", str(tmp_path)]) == 0
    rows = np.loadtxt(tmp_path / "results.csv", delimiter=",", skiprows=1, ndmin=2)
    assert rows.shape[0] == len(mech.times)


@pytest.mark.parametrize("stem", CATALOG)
def test_catalog_matches_closed_form(stem: str) -> None:
    """vloop vs the hand-derived closed form: every angle, rate, joint and slider, rtol = 1e-9."""
    mech = load(stem)
    mod = analytic.closed_form_for(mech)
    assert mod is not None and mod.NAME == CATALOG[stem]
    res = vloop.solve(mech)
    ref = analytic.solve(mech, res.t)
    assert ref.meta["closed_form"] == CATALOG[stem]
    assert set(ref.columns) == set(res.columns)  # the closed form gives every output quantity
    cmp = assert_histories_close(res, ref, rtol=1e-9, min_columns=len(res.columns))
    assert {e.group for e in cmp.errors} == ALL_GROUPS


@pytest.mark.parametrize("stem", CATALOG)
def test_every_link_stays_rigid(stem: str) -> None:
    """Every pair of joints on every link (ternary links too) keeps its t = 0 distance."""
    mech = load(stem)
    res = vloop.solve(mech)
    for lk in mech.links.values():
        if lk.ground:
            continue
        b = mech.bodies()[lk.name]
        for i, p in enumerate(lk.joints):
            for q in lk.joints[i + 1 :]:
                d0 = math.dist(b.local[p], b.local[q])
                d = np.hypot(res[f"{q}.x"] - res[f"{p}.x"], res[f"{q}.y"] - res[f"{p}.y"])
                assert np.max(np.abs(d - d0)) < 1e-12 * mech.scale, f"{stem}: {lk.name} {p}{q}"


# ---------------------------------------------------------------- the textbook four-bar


def test_textbook_fourbar_t0_by_hand() -> None:
    """a = 40, b = 120, c = 80, d = 100 mm, θ2 = 40°, ω2 = 25 rad/s, α2 = 15 rad/s², open branch.

    Positions, law of cosines on the diagonal f = |A − O4| (O2 at the origin, O4 = (d, 0)):
      f² = a² + d² − 2ad·cos θ2 = 11600 − 8000·cos 40° = 5471.6445,  f = 73.97056 mm;
      the diagonal seen from O4: ψ = atan2(a sin θ2, a cos θ2 − d) = 159.65996°;
      angle A–O4–B: cos γ = (c² + f² − b²)/(2cf) = −2528.3555/11835.290,  γ = 102.33508°;
      open branch: θ4 = ψ − γ = 57.32488°;  B = O4 + c·e^{jθ4},  θ3 = arg(B − A) = 20.29788°.
    Velocities, real and imaginary parts of j·a·ω2·e^{jθ2} + j·b·ω3·e^{jθ3} − j·c·ω4·e^{jθ4} = 0:
      −b sin θ3·ω3 + c sin θ4·ω4 = a ω2 sin θ2,   b cos θ3·ω3 − c cos θ4·ω4 = −a ω2 cos θ2
      → ω3 = −4.120914 rad/s, ω4 = 6.997985 rad/s (Cramer's rule below).
    Accelerations, the same matrix with right-hand sides
      a α2 sin θ2 + a ω2² cos θ2 + b ω3² cos θ3 − c ω4² cos θ4,
      −a α2 cos θ2 + a ω2² sin θ2 + b ω3² sin θ3 − c ω4² sin θ4
      → α3 = 296.0892 rad/s², α4 = 470.1335 rad/s².
    """
    a, b, c, d = 40.0, 120.0, 80.0, 100.0
    th2, w2, al2 = math.radians(40.0), 25.0, 15.0
    f2 = a * a + d * d - 2 * a * d * math.cos(th2)
    f = math.sqrt(f2)
    psi = math.atan2(a * math.sin(th2), a * math.cos(th2) - d)
    gam = math.acos((c * c + f2 - b * b) / (2 * c * f))
    th4 = psi - gam
    bx, by = d + c * math.cos(th4), c * math.sin(th4)
    th3 = math.atan2(by - a * math.sin(th2), bx - a * math.cos(th2))
    m11, m12, m21, m22 = -b * math.sin(th3), c * math.sin(th4), b * math.cos(th3), -c * math.cos(th4)
    det = m11 * m22 - m12 * m21

    def cramer(r1: float, r2: float) -> tuple[float, float]:
        return (r1 * m22 - m12 * r2) / det, (m11 * r2 - r1 * m21) / det

    w3, w4 = cramer(a * w2 * math.sin(th2), -a * w2 * math.cos(th2))
    s2, c2, s3, c3, s4, c4 = (fn(x) for x in (th2, th3, th4) for fn in (math.sin, math.cos))
    al3, al4 = cramer(
        a * al2 * s2 + a * w2 * w2 * c2 + b * w3 * w3 * c3 - c * w4 * w4 * c4,
        -a * al2 * c2 + a * w2 * w2 * s2 + b * w3 * w3 * s3 - c * w4 * w4 * s4,
    )
    # the hand calculation, written out
    assert f == pytest.approx(73.97056, abs=1e-5)
    assert math.degrees(th3) == pytest.approx(20.29788, abs=1e-5)
    assert math.degrees(th4) == pytest.approx(57.32488, abs=1e-5)
    assert (w3, w4) == pytest.approx((-4.120914, 6.997985), abs=1e-6)
    assert (al3, al4) == pytest.approx((296.0892, 470.1335), abs=1e-4)
    # vloop at t = 0
    mech = load("fourbar_textbook_example")
    assert analytic.closed_form_for(mech) is analytic_fourbar
    assert analytic_fourbar.grashof(mech) == "crank-rocker"
    res = vloop.solve(mech)
    assert res.t[0] == 0.0
    got = [res[f"{n}.{q}"][0] for q in ("theta", "omega", "alpha") for n in ("l3", "l4")]
    want = [th3, th4, w3, w4, al3, al4]
    for g, w in zip(got, want, strict=True):
        assert g == pytest.approx(w, rel=1e-12, abs=1e-12)
    assert res["l2.omega"][0] == 25.0 and res["l2.alpha"][0] == 15.0


# ---------------------------------------------------------------- quick return


def _roots(fn, t: np.ndarray) -> list[float]:
    """Sign changes of fn over the grid t, refined with brentq."""
    v = np.array([fn(x) for x in t]) if callable(fn) and len(t) < 50 else fn(t)
    idx = np.flatnonzero(np.sign(v[:-1]) * np.sign(v[1:]) < 0)
    return [float(brentq(lambda x: float(fn(np.array([x]))[0]), t[k], t[k + 1], xtol=1e-15)) for k in idx]


def test_whitworth_time_ratio() -> None:
    """Time ratio of the Whitworth layout (lever turns fully: d < r; ram line through O4 ⟂ O2O4).

    The ram stops where rod and arm lie along its line, i.e. where the lever is horizontal, i.e.
    where the crank pin crosses y = −d: r·sin φ = −d, φ = −asin(d/r) or π + asin(d/r). At constant
    crank speed: ratio = (π + 2·asin(d/r))/(π − 2·asin(d/r)) = 2 for r = 100, d = 50 mm. (The
    formula with asin(r/d) is the oscillating crank-shaper's, where d > r; see the next test.)
    """
    mech = load("whitworth_quick_return")
    r = math.dist(mech.joints["O2"], mech.joints["A"])
    d = math.dist(mech.joints["O2"], mech.joints["O4"])
    omega = mech.drivers[0].v0
    assert (r, d) == (100.0, 50.0) and mech.drivers[0].a0 == 0.0
    period = 2 * math.pi / omega

    def ram_v(t: np.ndarray) -> np.ndarray:
        return analytic_whitworth.solve(mech, t)["l6.v"]

    t1, t2 = _roots(ram_v, np.linspace(0.0, period, 801))
    ends = analytic_whitworth.solve(mech, np.array([t1, t2]))
    forward = ends["l6.s"][1] > ends["l6.s"][0]  # the ram moves +x from t1 to t2
    slow, fast = (t2 - t1, period - (t2 - t1)) if forward else (period - (t2 - t1), t2 - t1)
    formula = (math.pi + 2 * math.asin(d / r)) / (math.pi - 2 * math.asin(d / r))
    assert formula == pytest.approx(2.0, abs=1e-15)
    assert slow / fast == pytest.approx(formula, rel=1e-10)
    assert analytic_whitworth.time_ratio(r, d) == pytest.approx(formula, rel=1e-15)
    # at the ends of the stroke the lever lies along the ram line and the crank is at −30° / 210°
    assert np.allclose(np.sin(ends["l4.theta"]), 0.0, atol=1e-10)
    crank = np.degrees(ends["l2.theta"]) % 360
    assert sorted(crank) == pytest.approx([210.0, 330.0], abs=1e-8)
    # stroke = 2 × lever arm (80 mm); vloop finds the same ends
    assert abs(ends["l6.s"][1] - ends["l6.s"][0]) == pytest.approx(160.0, abs=1e-9)
    assert vloop.solve(mech, np.array([t1, t2]))["l6.v"] == pytest.approx([0.0, 0.0], abs=1e-9)


def test_inverted_slider_crank_quick_return() -> None:
    """The rocker's limits: crank ⟂ slot, crank at ±acos(a/d) from O2→O4; swings π ± 2·asin(a/d)."""
    mech = load("inverted_slider_crank")
    a = math.dist(mech.joints["O2"], mech.joints["A"])
    d = math.dist(mech.joints["O2"], mech.joints["O4"])
    t = np.linspace(0.0, mech.times[-1], 601)

    def rocker_w(tt: np.ndarray) -> np.ndarray:
        return analytic_inverted_slider_crank.solve(mech, tt)["l4.omega"]

    roots = _roots(rocker_w, t)
    assert len(roots) >= 2
    ends = analytic_inverted_slider_crank.solve(mech, np.array(roots[:2]))
    # crank perpendicular to the slot (the block's θ is the slot direction)
    assert np.allclose(np.cos(ends["l2.theta"] - ends["l3.theta"]), 0.0, atol=1e-12)
    assert np.allclose(np.cos(ends["l2.theta"]), a / d, atol=1e-12)
    swing = float(ends["l2.theta"][1] - ends["l2.theta"][0])
    ratio = max(swing, 2 * math.pi - swing) / min(swing, 2 * math.pi - swing)
    assert ratio == pytest.approx(analytic_inverted_slider_crank.time_ratio(a, d), rel=1e-10)
    assert ratio == pytest.approx((math.pi + 2 * math.asin(0.4)) / (math.pi - 2 * math.asin(0.4)), rel=1e-12)


@pytest.mark.parametrize("offset", [0.0, 15.0])
def test_inverted_slider_crank_variants(offset: float) -> None:
    """One-joint guide (rocker = its pivot only) and a slot offset from the pivot: vloop = closed form."""
    zA, zO4 = complex(34.64101615137755, 19.999999999999996), 100.0 + 0.0j
    delta = zA - zO4
    u = complex(delta / abs(delta) * cmath.exp(-1j * math.asin(offset / abs(delta))))  # u × (A − O4) = offset
    text = f"""
        name = "isc_variant"
        [joints]
        O2 = [0.0, 0.0]
        A = [{zA.real!r}, {zA.imag!r}]
        O4 = [100.0, 0.0]
        [links]
        ground = {{ joints = ["O2", "O4"], ground = true }}
        l2 = {{ joints = ["O2", "A"], length = 40.0 }}
        l4 = {{ joints = ["O4"] }}
        [sliders]
        l3 = {{ joint = "A", guide = "l4", axis = [{u.real!r}, {u.imag!r}] }}
        [[drivers]]
        link = "l2"
        omega = 10.0
        alpha = 5.0
        [time]
        start = 0.0
        stop = 0.6
        step = 0.003
    """
    mech = vloop.loads(text)
    ref = analytic.solve(mech)
    assert ref.meta["closed_form"] == "inverted_slider_crank"
    assert ref.meta["offset"] == pytest.approx(offset, abs=1e-12)
    assert_histories_close(vloop.solve(mech), ref, rtol=1e-9, min_columns=20)


# ---------------------------------------------------------------- five-bar, mobility 2


def test_fivebar_has_mobility_two_and_solves_with_two_drivers() -> None:
    mech = load("fivebar_two_cranks")
    L, J, M = mech.gruebler()
    assert (L, J, M) == (5, 5, 2)
    assert len(mech.drivers) == 2
    res = vloop.solve(mech)
    # the second crank reverses mid-run: ω5 = 3 − 6t changes sign at t = 0.5 s
    w5 = res["l5.omega"]
    assert w5[0] == pytest.approx(3.0) and w5[-1] == pytest.approx(-6.0)
    k = int(np.argmin(np.abs(res.t - 0.5)))
    assert res.t[k] == pytest.approx(0.5) and abs(w5[k]) < 1e-12
    assert np.ptp(np.sign(w5)) == 2
    assert_histories_close(res, analytic.solve(mech, res.t), rtol=1e-9, min_columns=len(res.columns))


def test_fivebar_with_one_driver_is_refused() -> None:
    text = (MECH / "fivebar_two_cranks.toml").read_text(encoding="utf-8")
    first = text.index("[[drivers]]")
    second = text.index("[[drivers]]", first + 1)
    one = text[:second] + text[text.index("[time]") :]
    assert one.count("[[drivers]]") == 1
    with pytest.raises(vloop.MechanismError, match="mobility mismatch"):
        vloop.loads(one, source="fivebar_one_driver.toml", base_dir=MECH)


# ---------------------------------------------------------------- many loops: the Jansen pair


def test_jansen_pair_loop_count() -> None:
    mech = load("jansen_pair")
    L, J, M = mech.gruebler()
    assert (L, J, M) == (14, 19, 1)
    assert len(vloop.compile(mech).loops) == J - L + 1 == 6


def test_jansen_pair_rates_match_five_point_differences() -> None:
    """(−x(t+2h) + 8x(t+h) − 8x(t−h) + x(t−2h))/(12h) = ẋ(t) + O(h⁴·x⁽⁵⁾/30).

    h = 1e-4 s, ω = 2π rad/s: (ωh)⁴/30 ≈ 5e-15 times the harmonic factor k⁴ (the feet's sharp
    corners, k ≲ 10: ~1e-10); round-off ε·|x|/h is ~1e-12 of the rates. Measured worst: 5e-11 of
    the peak (the foot triangles' α). Allowed: 1e-8 of the quantity's peak.
    """
    mech = load("jansen_pair")
    h = 1e-4
    centers = np.linspace(0.01, 0.99, 50)
    res = vloop.solve(mech, (centers[:, None] + h * np.arange(-2, 3)).ravel())
    pairs = [(f"{n}.{x}", f"{n}.{dx}") for n in res.names("link") for x, dx in (("theta", "omega"), ("omega", "alpha"))]
    pairs += [
        (f"{n}.{x}", f"{n}.{dx}")
        for n in res.names("point")
        for x, dx in (("x", "vx"), ("y", "vy"), ("vx", "ax"), ("vy", "ay"))
    ]
    checked = 0
    for q, dq in pairs:
        peak = float(np.max(np.abs(res[dq])))
        if peak == 0.0:  # ground points
            continue
        x = res[q].reshape(-1, 5)
        fd = (x[:, 0] - 8 * x[:, 1] + 8 * x[:, 3] - x[:, 4]) / (12 * h)
        err = float(np.max(np.abs(fd - res[dq].reshape(-1, 5)[:, 2])))
        assert err <= 1e-8 * peak, f"{dq}: five-point difference off by {err:.3g} ({err / peak:.2g} of its peak)"
        checked += 1
    assert checked == 2 * 13 - 1 + 4 * 11  # 13 moving links (the crank's α is 0), 11 moving joints


# ---------------------------------------------------------------- the non-Grashof pair


def test_nongrashof_rocking_and_past_limit_are_the_same_linkage() -> None:
    rock, past = load("fourbar_nongrashof_rocking"), load("fourbar_nongrashof_past_limit")
    dr, dp = analytic_fourbar.dims(rock), analytic_fourbar.dims(past)
    assert (dr.a, dr.b, dr.c, dr.d, dr.theta1) == (dp.a, dp.b, dp.c, dp.d, dp.theta1) == (3.0, 4.0, 4.5, 6.0, 0.0)
    assert analytic_fourbar.grashof(rock) == "non-Grashof (triple rocker)"
    lim = math.acos((3.0**2 + 6.0**2 - 8.5**2) / (2 * 3.0 * 6.0))
    assert lim == pytest.approx(2.4294209, abs=1e-7)
    assert sorted(x if x < math.pi else x - 2 * math.pi for x in analytic_fourbar.limit_angles(rock)) == (
        pytest.approx([-lim, lim], abs=1e-12)
    )
    # the tabulated input rocks strictly inside the limits and reverses
    prof = rock.drivers[0].profile
    assert prof is not None and prof.v is not None and prof.a is not None
    assert np.max(np.abs(prof.x)) == pytest.approx(2.2, abs=1e-12) and np.max(np.abs(prof.x)) < lim - 0.2
    assert np.ptp(np.sign(prof.v)) == 2
    np.testing.assert_allclose(prof.x, 2.2 * np.sin(np.pi * prof.t), atol=1e-15)
    # rocking: the whole run solves, reaching both sides; constant speed past the limit: vloop stops
    res = vloop.solve(rock)
    assert len(res) == len(rock.times) and res["l2.theta"].max() > 2.1 and res["l2.theta"].min() < -2.1
    with pytest.raises(vloop.MotionError):
        vloop.solve(past)
