"""Teaching quantities (vloop.teaching) against references written out by hand here.

Naming of the four-bar (both catalog four-bars lay the ground along +x from O2 = (0, 0)):
a = |O2A| crank l2 (body 2), b = |AB| coupler l3 (body 3), c = |O4B| rocker l4 (body 4),
d = |O2O4| ground (body 1), θ2 the crank's angle from +x. Slider-crank: crank a = |O2A| (l2),
rod b = |AB| (l3), block l4 at B on the line y = e. Positions for the references come from
the hand-derived closed forms of validators/ (never from vloop's loop equations), and every
instant centre is rebuilt here by intersecting the two lines Kennedy's theorem names.

Tolerances: 1e-9 of the mechanism's size (positions), 1e-9 rad (angles), 1e-9 relative (ratios).
Measured (2 cores, numpy 2): instant centres vs the hand intersections ≤ 1.2e-15 of the size, Kennedy vs
the velocity field ≤ 3.1e-13 (textbook four-bar), angles ≤ 7e-16 rad, dead centres ≤ 7e-16 rad,
strokes and time ratios ≤ 1.3e-15 relative.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from pathlib import Path

import numpy as np
import pytest

import vloop
from validators.analytic import fourbar as analytic_fourbar
from validators.analytic import slider_crank as analytic_slider_crank
from vloop.cli import main as vloop_main
from vloop.teaching import centres as C
from vloop.teaching import report

MECH = Path(__file__).resolve().parents[1] / "mechanisms"
CATALOG = sorted(MECH.glob("*.toml"))
TWO_PI = 2 * math.pi


def load(stem: str) -> vloop.Mechanism:
    return vloop.load(MECH / f"{stem}.toml")


def solved(mech: vloop.Mechanism) -> vloop.Result:
    try:
        return vloop.solve(mech)
    except vloop.MotionError as exc:  # the past-limit file: every sample before its limit
        return exc.partial


def xy(res: vloop.Result, name: str) -> np.ndarray:
    return res[f"{name}.x"] + 1j * res[f"{name}.y"]


def cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u.real * v.imag - u.imag * v.real


def intersection(p1: np.ndarray, p2: np.ndarray, p3: np.ndarray, p4: np.ndarray, scale: float) -> np.ndarray:
    """Lines p1p2 and p3p4 meet at p1 + t·(p2 − p1), t = ((p3 − p1) × (p4 − p3)) / ((p2 − p1) × (p4 − p3)).

    Returned in unit homogeneous form (x/L, y/L, w) so that parallel lines (a centre at infinity,
    direction p2 − p1) need no special case: multiply through by the denominator.
    """
    d1, d2 = p2 - p1, p4 - p3
    den = cross(d1, d2)
    num = p1 * den + cross(p3 - p1, d2) * d1
    h = np.stack([num.real / scale, num.imag / scale, den], axis=-1)
    return h / np.linalg.norm(h, axis=-1, keepdims=True)


def homogeneous_of(ic: vloop.teaching.InstantCentres, a: str, b: str) -> np.ndarray:
    return ic.centres.h[:, ic.centres.index(a, b)]


# ---------------------------------------------------------------- instant centres: closed forms


@pytest.mark.parametrize(
    "stem", ["fourbar_textbook_example", "fourbar_crank_rocker_open", "fourbar_crank_rocker_crossed"]
)
def test_fourbar_I13_I24_are_the_intersections_of_kennedys_lines(stem: str) -> None:
    mech = load(stem)
    ref = analytic_fourbar.solve(mech)
    O2, A, B, O4 = (xy(ref, j) for j in ("O2", "A", "B", "O4"))
    L = mech.scale
    i13 = intersection(O2, A, O4, B, L)  # I12 = O2, I23 = A; I14 = O4, I34 = B
    i24 = intersection(A, B, O2, O4, L)  # I23 = A, I34 = B; I12 = O2, I14 = O4
    ic = vloop.instant_centres(mech, vloop.solve(mech))
    assert np.max(C.distance(homogeneous_of(ic, "ground", "l3"), i13)) <= 1e-9
    assert np.max(C.distance(homogeneous_of(ic, "l2", "l4"), i24)) <= 1e-9
    assert (ic.source == 1).all()  # a four-bar: Kennedy's theorem reaches every pair at every sample
    # in plain coordinates, wherever the centre is within 100 mechanism sizes
    for (a, b), h in ((("ground", "l3"), i13), (("l2", "l4"), i24)):
        x, y, inf = ic.position(a, b)
        near = np.abs(h[:, 2]) * 100 >= np.hypot(h[:, 0], h[:, 1])
        ref_xy = (h[near, 0] + 1j * h[near, 1]) * L / h[near, 2]
        assert near.sum() > len(near) // 2 and not inf[near].any()
        assert np.max(np.abs(x[near] + 1j * y[near] - ref_xy)) <= 1e-9 * L


@pytest.mark.parametrize("stem", ["slider_crank_offset", "slider_crank_offset_crossed"])
def test_slider_crank_I13_I24_and_the_centres_at_infinity(stem: str) -> None:
    mech = load(stem)
    ref = analytic_slider_crank.solve(mech)
    O2, A, B = (xy(ref, j) for j in ("O2", "A", "B"))
    L = mech.scale
    up = 1j * np.ones_like(B)  # the block slides along x: I14 is at infinity along y
    i13 = intersection(O2, A, B, B + up, L)  # I12 = O2, I23 = A; I34 = B, I14 ⟂ axis through B
    i24 = intersection(A, B, O2, O2 + up, L)  # I23 = A, I34 = B; I12 = O2, I14 ⟂ axis through O2
    res = vloop.solve(mech)
    ic = vloop.instant_centres(mech, res)
    assert np.max(C.distance(homogeneous_of(ic, "ground", "l3"), i13)) <= 1e-9
    assert np.max(C.distance(homogeneous_of(ic, "l2", "l4"), i24)) <= 1e-9
    # I24 in plain numbers: on the rod's line at x = 0 (the rod is never vertical: b > a + |e|)
    x, y, inf = ic.position("l2", "l4")
    y_ref = A.imag + (0 - A.real) * (B.imag - A.imag) / (B.real - A.real)
    assert not inf.any() and np.max(np.abs(x)) <= 1e-9 * L and np.max(np.abs(y - y_ref)) <= 1e-9 * L
    # I14 (ground, block) at infinity, perpendicular to the sliding axis: direction (0, 1)
    x, y, inf = ic.position("ground", "l4")
    assert inf.all() and np.allclose(x, 0.0, atol=1e-15) and np.allclose(y, 1.0, atol=1e-15)


def test_fivebar_kennedy_reaches_only_the_pins_and_the_velocity_field_fills_the_rest() -> None:
    mech = load("fivebar_two_cranks")
    res = vloop.solve(mech)
    ic = vloop.instant_centres(mech, res)
    pins = {("ground", "l2"), ("l2", "l3"), ("l3", "l4"), ("l4", "l5"), ("ground", "l5")}
    assert set(ic.kennedy.unreachable()) == set(ic.pairs) - pins
    assert set(ic.from_velocity_field()) == set(ic.pairs) - pins
    for p, pair in enumerate(ic.pairs):
        assert (ic.source[:, p] == (1 if pair in pins else 2)).all(), pair
    # a two-input five-bar: I13 follows from the two crank rates, not from the geometry — check it
    # through its definition, the same velocity seen from the ground (zero) and from the coupler l3
    x, y, inf = ic.position("ground", "l3")
    A, vA = xy(res, "A"), res["A.vx"] + 1j * res["A.vy"]
    v3 = vA + 1j * res["l3.omega"] * (x + 1j * y - A)
    assert not inf.any() and np.max(np.abs(v3)) <= 1e-9 * np.max(np.abs(vA))


DOUBLE_BUTTERFLY = """
name = "double_butterfly"
[joints]
O  = [0.0, 0.0]
G3 = [-4.0, 0.3]
G4 = [4.2, -0.2]
Q3 = [-1.1, 0.9]
Q4 = [1.2, 1.1]
R1 = [-4.3, 4.1]
R2 = [-2.0, 4.3]
S  = [0.2, 6.1]
U1 = [4.4, 3.9]
U2 = [2.1, 4.2]
[links]
ground = { joints = ["O", "G3", "G4"], ground = true }
T2 = { joints = ["O", "Q3", "Q4"] }
T3 = { joints = ["R1", "R2", "S"] }
T4 = { joints = ["S", "U1", "U2"] }
b13 = { joints = ["G3", "R1"] }
b14 = { joints = ["G4", "U1"] }
b23 = { joints = ["Q3", "R2"] }
b24 = { joints = ["Q4", "U2"] }
[[drivers]]
link = "T2"
pivot = "O"
omega = 0.2
[time]
start = 0.0
stop = 1.0
step = 0.01
"""


def test_double_butterfly_one_input_kennedy_reaches_only_the_pins() -> None:
    # The double butterfly (Foster & Pennock): an eight-bar of mobility 1 whose four ternary links
    # pair up in two "butterflies" (ground–T2 and T3–T4 pinned directly, every other connection
    # through a binary link). No four-link loop exists, so no two bodies share two neighbours and
    # Kennedy's theorem cannot find a single secondary centre: 10 pins, 18 pairs from the velocity field.
    mech = vloop.loads(DOUBLE_BUTTERFLY)
    res = vloop.solve(mech)
    ic = vloop.instant_centres(mech, res)
    pins = {tuple(sorted(mech.bodies_at(j))) for j in mech.joints}
    assert len(ic.pairs) == 28 and len(pins) == 10
    assert {tuple(sorted(p)) for p in ic.kennedy.unreachable()} == {tuple(sorted(p)) for p in ic.pairs} - pins
    assert ((ic.source == 1) | (ic.source == 2)).all() and (ic.source == 2).sum(axis=1).tolist() == [18] * len(res)
    # Kennedy's theorem as a check instead of a construction: for every three bodies, the three centres
    # (most of them from the velocity field here) lie on one line, det[h_ab; h_bc; h_ac] = 0
    h = {pair: ic.centres.h[:, p] for p, pair in enumerate(ic.pairs)}
    h |= {(b, a): v for (a, b), v in list(h.items())}
    worst = max(
        np.max(np.abs(np.linalg.det(np.stack([h[a, b], h[b, c], h[a, c]], axis=1))))
        for a, b, c in itertools.combinations(mech.body_names, 3)
    )
    assert worst <= 1e-9


# ---------------------------------------------------------------- instant centres: every catalog file


@pytest.mark.parametrize("path", CATALOG, ids=lambda p: p.stem)
def test_kennedy_agrees_with_the_velocity_field_and_centres_have_one_velocity(path: Path) -> None:
    mech = vloop.load(path)
    res = solved(mech)
    ken = vloop.teaching.kennedy_centres(mech, res)
    vel = vloop.teaching.velocity_centres(mech, res)
    both = ken.found & vel.found
    assert both.mean() > 0.45  # every pair somewhere (the five-bar: its pins only)
    assert np.max(C.distance(ken.h, vel.h)[both]) <= 1e-9
    # I_ab seen from a and from b: v_a(I) − v_b(I) = 0, in homogeneous form w·Δv(P) + j·Δω·(x − w·P) = 0
    # (finite or not), relative to the mechanism's own peak speed; rigid-body velocities from the
    # Result's point velocities and ω, not from either construction
    L = mech.scale
    omega = {b: (res[f"{b}.omega"] if b != mech.ground else np.zeros(len(res))) for b in mech.body_names}
    peak = max(np.max(np.abs(res[f"{j}.vx"] + 1j * res[f"{j}.vy"])) for j in mech.joints) + L * max(
        np.max(np.abs(w)) for w in omega.values()
    )
    for p, (a, b) in enumerate(ken.pairs):
        h = ken.h[:, p]
        ok = ken.found[:, p]
        X, w = (h[:, 0] + 1j * h[:, 1]) * L, h[:, 2]

        def v_at(body: str, X: np.ndarray, w: np.ndarray) -> np.ndarray:  # w·v_body(X/w), from its first joint P
            if body == mech.ground:
                return np.zeros(len(res), complex)
            P = mech.sliders[body].joint if body in mech.sliders else mech.links[body].joints[0]
            return w * (res[f"{P}.vx"] + 1j * res[f"{P}.vy"]) + 1j * omega[body] * (X - w * xy(res, P))

        slip = np.abs(v_at(a, X, w) - v_at(b, X, w))[ok]
        assert np.max(slip, initial=0.0) <= 1e-9 * peak, (a, b)


# ---------------------------------------------------------------- transmission angle


@pytest.mark.parametrize(
    "stem", ["fourbar_textbook_example", "fourbar_crank_rocker_open", "fourbar_crank_rocker_crossed"]
)
def test_fourbar_transmission_angle_is_the_law_of_cosines(stem: str) -> None:
    mech = load(stem)
    res = vloop.solve(mech)
    bodies = mech.bodies()
    a = bodies["l2"].local["A"][0]
    b = bodies["l3"].local["B"][0]
    c = bodies["l4"].local["B"][0]
    d = math.dist(mech.joints["O2"], mech.joints["O4"])
    th2 = res["l2.theta"]
    mu_ref = np.arccos((b * b + c * c - a * a - d * d + 2 * a * d * np.cos(th2)) / (2 * b * c))
    (ta,) = vloop.transmission_angles(mech, res)
    assert ta.dyad.kind == "RRR" and ta.dyad.joint == "B" and set(ta.dyad.ends) == {"A", "O4"}
    assert np.max(np.abs(ta.raw - mu_ref)) <= 1e-9
    assert np.max(np.abs(ta.folded - np.minimum(mu_ref, np.pi - mu_ref))) <= 1e-9
    ex = ta.extremes()
    k = int(np.argmin(np.minimum(mu_ref, np.pi - mu_ref)))
    assert ex["min"]["sample"] == k and ex["min"]["t"] == res.t[k]
    # over a crank turn cos μ is monotonic in cos θ2: the extremes sit at θ2 = 0 and π
    cyc = vloop.teaching.cycle(mech)
    (dc,) = cyc.dyads
    at0, atpi = (np.arccos((b * b + c * c - a * a - d * d + s * 2 * a * d) / (2 * b * c)) for s in (1, -1))
    fold = [min(m, math.pi - m) for m in (at0, atpi)]
    top = math.pi / 2 if at0 <= math.pi / 2 <= atpi else max(fold)  # raw μ runs over [μ(0), μ(π)]
    assert abs(dc.min - min(fold)) <= 1e-9 and abs(dc.max - top) <= 1e-9
    where = (0.0, math.pi)[int(np.argmin(fold))]
    assert abs(math.remainder(dc.min_input - where, TWO_PI)) <= 1e-4  # a flat minimum: its place to √ε


@pytest.mark.parametrize("stem", ["slider_crank_offset", "slider_crank_offset_crossed"])
def test_slider_crank_pressure_angle(stem: str) -> None:
    mech = load(stem)
    res = vloop.solve(mech)
    a, b, e = 2.0, 6.0, 1.0  # the files' crank, rod and offset
    # B on y = e: b·sin θ3 = e − a·sin θ2; the rod's acute angle with the sliding axis is |asin(·)|
    pressure_ref = np.abs(np.arcsin((e - a * np.sin(res["l2.theta"])) / b))
    (ta,) = vloop.transmission_angles(mech, res)
    assert ta.dyad.kind == "RRP" and ta.dyad.bodies == ("l3", "l4")
    assert np.max(np.abs(ta.pressure - pressure_ref)) <= 1e-9
    assert np.max(np.abs(ta.folded - (np.pi / 2 - pressure_ref))) <= 1e-9


def test_whitworth_slot_and_ram_angles() -> None:
    mech = load("whitworth_quick_return")
    res = vloop.solve(mech)
    slot, ram = vloop.transmission_angles(mech, res)
    assert slot.dyad.kind == "RPR" and ram.dyad.kind == "RRP"
    # the slot runs through the lever's pivot O4: the block pushes normal to the slot, the lever's
    # point under A moves normal to O4A, which is the slot: μ = 90° throughout
    assert np.max(np.abs(slot.folded - np.pi / 2)) <= 1e-9
    # the arm O4C = 80 lies along the slot on the far side from A; rod CD = 200, ram line y = −50:
    # the rod's angle with the ram line has sine |y_C + 50|/200, y_C + 50 = −80·(y_A + 50)/|A − O4|
    A = 100 * np.exp(1j * res["l2.theta"])
    yC = -80 * (A.imag + 50) / np.abs(A - (-50j))
    assert np.max(np.abs(ram.pressure - np.arcsin(np.abs(yC) / 200))) <= 1e-9


# ---------------------------------------------------------------- stroke, time ratio, dead centres


def test_offset_slider_crank_stroke_and_time_ratio() -> None:
    mech = load("slider_crank_offset")
    r, ell, e = 2.0, 6.0, 1.0
    stroke = math.sqrt((ell + r) ** 2 - e * e) - math.sqrt((ell - r) ** 2 - e * e)
    beta = math.asin(e / (ell - r)) - math.asin(e / (ell + r))
    cyc = vloop.teaching.cycle(mech)
    out = cyc.outputs["l4"]
    assert cyc.full_turn and abs(out.travel - stroke) <= 1e-9 * stroke
    assert abs(out.time_ratio - (math.pi + beta) / (math.pi - beta)) <= 1e-9
    # the dead centres: crank and rod in line, extended (sin θ2 = e/(l + r)) and folded (θ2 = π + asin(e/(l − r)))
    ext, fold = math.asin(e / (ell + r)), math.pi + math.asin(e / (ell - r))
    got = sorted(rest.input % TWO_PI for rest in out.rests)
    assert np.allclose(got, sorted([ext, fold]), atol=1e-9, rtol=0)
    assert vloop.stroke(mech, "l4") == pytest.approx(stroke, rel=1e-9)


def test_whitworth_time_ratio_two_and_ram_stroke() -> None:
    mech = load("whitworth_quick_return")
    a, d = 100.0, 50.0  # crank and pivot distance |O2O4|: (π + 2 asin(d/a))/(π − 2 asin(d/a)) = 240°/120°
    g = 2 * math.asin(d / a)
    cyc = vloop.teaching.cycle(mech)
    ram = cyc.outputs["l6"]
    assert abs(ram.time_ratio - (math.pi + g) / (math.pi - g)) <= 1e-9
    assert abs(ram.time_ratio - 2.0) <= 1e-9
    assert abs(ram.travel - 2 * 80.0) <= 1e-9 * 160  # lever horizontal at both ends: D = ±80 + 200
    assert cyc.outputs["l4"].travel is None  # the Whitworth lever turns fully
    assert vloop.time_ratio(mech, "l6") == pytest.approx(2.0, abs=1e-9)


def test_inverted_slider_crank_rocker_time_ratio() -> None:
    mech = load("inverted_slider_crank")
    a, d = 40.0, 100.0  # the rocker rests with the slot tangent to the crank circle: asin(a/d)
    g = 2 * math.asin(a / d)
    out = vloop.teaching.cycle(mech).outputs["l4"]
    assert abs(out.time_ratio - (math.pi + g) / (math.pi - g)) <= 1e-9
    assert abs(out.travel - g) <= 1e-9  # the swing: the slot turns by 2·asin(a/d) between its rests


@pytest.mark.parametrize("stem", ["fourbar_textbook_example", "fourbar_crank_rocker_open"])
def test_crank_rocker_dead_centres_where_crank_and_coupler_are_collinear(stem: str) -> None:
    mech = load(stem)
    bodies = mech.bodies()
    a, b, c = (bodies[n].local[j][0] for n, j in (("l2", "A"), ("l3", "B"), ("l4", "B")))
    d = math.dist(mech.joints["O2"], mech.joints["O4"])
    expected = []
    for f, flip in ((a + b, 0.0), (b - a, math.pi)):  # extended, folded: |O2B| = b ± a
        psi = math.acos((d * d + f * f - c * c) / (2 * d * f))  # angle at O2 (B above the ground line)
        gamma = math.acos((d * d + c * c - f * f) / (2 * d * c))  # angle at O4
        expected.append(((psi + flip) % TWO_PI, math.pi - gamma))  # crank angle, rocker angle θ4
    rests = sorted(
        ((r.input % TWO_PI, r.value % TWO_PI) for r in vloop.dead_centres(mech, ["l4"])), key=lambda x: x[0]
    )  # fmt: skip
    assert np.allclose(rests, sorted(expected), atol=1e-9, rtol=0)
    d1 = (expected[1][0] - expected[0][0]) % TWO_PI
    assert vloop.time_ratio(mech, "l4") == pytest.approx(max(d1, TWO_PI - d1) / min(d1, TWO_PI - d1), abs=1e-9)


def test_nongrashof_toggles_are_the_limit_positions() -> None:
    mech = load("fourbar_nongrashof_past_limit")
    lim = math.acos((3.0**2 + 6.0**2 - (4.0 + 4.5) ** 2) / (2 * 3.0 * 6.0))  # coupler and rocker collinear
    cyc = vloop.teaching.cycle(mech)
    assert not cyc.full_turn
    assert np.allclose([tg.input for tg in cyc.toggles], [-lim, lim], atol=1e-9, rtol=0)
    assert all(tg.dyad == "B" and tg.folded < 1e-9 for tg in cyc.toggles)  # μ = 0 at the toggle


def test_triple_rocker_swing_and_transmission_angle_at_the_located_limits() -> None:
    """The non-Grashof four-bar (a = 3, b = 4, c = 4.5, d = 6): the rocker's swing runs from its dead centre
    (crank and coupler in line, |O2B| = a + b) to the toggle at the lower limit (coupler and rocker in line,
    |AO4| = b + c), by the law of cosines: θ4 = π − γ, cos γ = (d² + c² − (a + b)²)/(2dc), and θ4 = π + φ,
    cos φ = (d² + (b + c)² − a²)/(2d(b + c)): swing φ + γ = 95.6189°. Taken one grid step short of the toggle
    it was 93.2039°, and the minimum transmission angle 5.3890° (0° at the toggles). The limits are located to
    1e-12 of the range and the toggle's configuration is exact to that (measured: swing 1.1e-12 rad)."""
    a, b, c, d = 3.0, 4.0, 4.5, 6.0
    gamma = math.acos((d * d + c * c - (a + b) ** 2) / (2 * d * c))
    phi = math.acos((d * d + (b + c) ** 2 - a * a) / (2 * d * (b + c)))
    lim = math.acos((a * a + d * d - (b + c) ** 2) / (2 * a * d))
    for stem in ("fourbar_nongrashof_past_limit", "fourbar_nongrashof_rocking"):
        cyc = vloop.teaching.cycle(load(stem))
        assert abs(cyc.outputs["l4"].travel - (phi + gamma)) <= 1e-9, stem
        assert abs(vloop.stroke(load(stem), "l4") - (phi + gamma)) <= 1e-9
        (mu,) = cyc.dyads
        assert mu.min <= 1e-9 and abs(abs(mu.min_input) - lim) <= 1e-9  # μ = 0 at a toggle, not 5.3890°
        assert all(tg.folded <= 1e-9 for tg in cyc.toggles)
        assert abs(mu.max - math.pi / 2) <= 1e-12  # the coupler and rocker square to each other inside the range
        cos_mu = (b * b + c * c - a * a - d * d + 2 * a * d * math.cos(mu.max_input)) / (2 * b * c)
        assert abs(cos_mu) <= 1e-12  # ... where the law of cosines gives μ = 90°


@pytest.mark.parametrize(
    "stem", ["fourbar_textbook_example", "fourbar_crank_rocker_open", "fourbar_crank_rocker_crossed"]
)
def test_crank_rocker_transmission_angle_extremes_with_crank_and_ground_in_line(stem: str) -> None:
    """A crank-rocker's transmission angle is extreme with crank and ground in line (cos μ is linear in cos θ2):
    at θ2 = 0, cos μ = (b² + c² − (d − a)²)/(2bc), at θ2 = π, (b² + c² − (d + a)²)/(2bc); folded to [0, 90°], its
    peak is 90° where cos μ = 0 if μ passes 90°, at cos θ2 = (a² + d² − b² − c²)/(2ad)."""
    mech = load(stem)
    bodies = mech.bodies()
    a, b, c = (bodies[n].local[j][0] for n, j in (("l2", "A"), ("l3", "B"), ("l4", "B")))
    d = math.dist(mech.joints["O2"], mech.joints["O4"])
    ends = {
        x: math.acos((b * b + c * c - (d - a * math.cos(x)) ** 2 - (a * math.sin(x)) ** 2) / (2 * b * c))
        for x in (0.0, math.pi)
    }
    folded = {x: min(m, math.pi - m) for x, m in ends.items()}
    (mu,) = vloop.teaching.cycle(mech).dyads
    lo = min(folded, key=folded.get)
    assert abs(mu.min - folded[lo]) <= 1e-12 and abs(math.remainder(mu.min_input - lo, TWO_PI)) <= 1e-9
    if (ends[0.0] - math.pi / 2) * (ends[math.pi] - math.pi / 2) < 0:
        square = math.acos((a * a + d * d - b * b - c * c) / (2 * a * d))  # ± this
        assert abs(mu.max - math.pi / 2) <= 1e-12
        assert min(abs(math.remainder(mu.max_input - x, TWO_PI)) for x in (square, -square)) <= 1e-9
    else:
        hi = max(folded, key=folded.get)
        assert abs(mu.max - folded[hi]) <= 1e-12 and abs(math.remainder(mu.max_input - hi, TWO_PI)) <= 1e-9


def test_slider_crank_transmission_angle_extremes() -> None:
    """Offset slider-crank (r = 2, l = 6, e = 1): the rod leans by asin((r·sin θ2 − e)/l), most at θ2 = 270°
    (μ = 90° − asin((r + e)/l) = 60°) and not at all where r·sin θ2 = e (μ = 90°, θ2 = 30° or 150°)."""
    r, ell, e = 2.0, 6.0, 1.0
    (mu,) = vloop.teaching.cycle(load("slider_crank_offset")).dyads
    assert abs(mu.min - (math.pi / 2 - math.asin((r + e) / ell))) <= 1e-12
    assert abs(math.remainder(mu.min_input - 1.5 * math.pi, TWO_PI)) <= 1e-9
    assert abs(mu.max - math.pi / 2) <= 1e-12
    assert min(abs(math.remainder(mu.max_input - x, TWO_PI)) for x in (math.pi / 6, 5 * math.pi / 6)) <= 1e-9


def mirrored(mech: vloop.Mechanism, reverse: bool = True) -> vloop.Mechanism:
    """The mechanism's mirror image in the x-axis (y → −y, slider axes too), the crank turning the other way."""
    data = vloop.mechanism.to_dict(mech)
    data["joints"] = {j: [x, -y] for j, (x, y) in data["joints"].items()}
    for sl in data.get("sliders", {}).values():
        sl["axis"] = [sl["axis"][0], -sl["axis"][1]]
    for p in data.get("points", {}).values():
        p["at"] = [p["at"][0], -p["at"][1]]
    for dr in data["drivers"]:
        dr.pop("theta0", None)
        for k in ("omega", "alpha"):
            if k in dr and reverse:
                dr[k] = -dr[k]
    return vloop.from_dict(data, source=f"mirror of {mech.name}")


def reversed_crank(mech: vloop.Mechanism) -> vloop.Mechanism:
    d = mech.drivers[0]
    return dataclasses.replace(mech, drivers=(dataclasses.replace(d, v0=-d.v0, a0=-d.a0),))


def test_slow_stroke_sense_follows_the_crank_sense() -> None:
    """Offset slider-crank (r = 2, l = 6, e = 1, block on y = e): extended dead centre (s max) at
    θ_e = asin(e/(l + r)), folded (s min) at θ_f = π + asin(e/(l − r)); counter-clockwise from θ_e to θ_f is π + β,
    β = asin(e/(l − r)) − asin(e/(l + r)) > 0. Crank CCW (ω > 0): the stroke with s decreasing takes π + β, the slow
    one. Crank CW (ω < 0): it takes π − β, so the slow stroke is s increasing. The mirror image (e → −e) driven
    the other way moves as the original does: slow stroke s decreasing."""
    r, ell, e = 2.0, 6.0, 1.0
    beta = math.asin(e / (ell - r)) - math.asin(e / (ell + r))
    ratio = (math.pi + beta) / (math.pi - beta)
    mech = load("slider_crank_offset")
    cases = {"ccw": (mech, -1), "cw": (reversed_crank(mech), +1), "mirror, cw": (mirrored(mech), -1)}
    cases["mirror, ccw"] = (mirrored(mech, reverse=False), +1)
    for what, (m, sense) in cases.items():
        out = vloop.teaching.cycle(m).outputs["l4"]
        assert out.slow_sense == sense, what
        assert abs(out.time_ratio - ratio) <= 1e-12, what
    lines = report.info_lines(reversed_crank(mech))
    assert any(f"time ratio {ratio:.10g} (slow stroke with l4 increasing)" in line for line in lines), lines


def test_mirror_images_have_equal_time_ratios() -> None:
    """The eight-bar's sliders l6 and l8 are mirror images: both rest where l4 does (crank and coupler in line,
    θ2 = π and 2π), where the rods also stand upright — the slider's rate vanishes like the cube of the distance
    there, and taken by its own sign l8's rest came out 2.4e-8 rad off (time ratio 1.000000015). Each time
    ratio is 1 to round-off; and a crank-rocker and its mirror image (crank turning the other way) give the same
    time ratio, (π + α)/(π − α) with α = Δ − π, Δ the crank's turn between the rocker's dead centres."""
    cyc = vloop.teaching.cycle(load("eightbar"))
    for name in ("l4", "l6", "l8"):
        assert abs(cyc.outputs[name].time_ratio - 1.0) <= 1e-12, name
        assert [abs(math.remainder(x.input, math.pi)) <= 1e-12 for x in cyc.outputs[name].rests] == [True, True]
    assert [x.input for x in cyc.outputs["l6"].rests] == [x.input for x in cyc.outputs["l8"].rests]
    mech = load("fourbar_crank_rocker_open")
    bodies = mech.bodies()
    a, b, c = (bodies[n].local[j][0] for n, j in (("l2", "A"), ("l3", "B"), ("l4", "B")))
    d = math.dist(mech.joints["O2"], mech.joints["O4"])
    ext = math.acos((d * d + (a + b) ** 2 - c * c) / (2 * d * (a + b)))  # |O2B| = a + b, B above the ground line
    fold = math.pi + math.acos((d * d + (b - a) ** 2 - c * c) / (2 * d * (b - a)))  # |O2B| = b − a
    alpha = abs((fold - ext) - math.pi)
    want = (math.pi + alpha) / (math.pi - alpha)
    got = [vloop.time_ratio(m, "l4") for m in (mech, mirrored(mech))]
    assert abs(got[0] - want) <= 1e-12 and abs(got[1] - got[0]) <= 1e-12


# ---------------------------------------------------------------- velocity ratio, mechanical advantage


def test_velocity_ratio_by_the_angular_velocity_ratio_theorem() -> None:
    mech = load("fourbar_textbook_example")
    ref = analytic_fourbar.solve(mech)
    O2, A, B, O4 = (xy(ref, j) for j in ("O2", "A", "B", "O4"))
    h = intersection(A, B, O2, O4, mech.scale)
    I24 = (h[:, 0] + 1j * h[:, 1]) * mech.scale / h[:, 2]
    # I24 is a point of l2 and of l4: j·ω2·(I24 − O2) = j·ω4·(I24 − O4)
    ratio = ((I24 - O2) / (I24 - O4)).real
    res = vloop.solve(mech)
    assert np.max(np.abs(vloop.velocity_ratio(mech, res, "l4") - ratio)) <= 1e-9 * np.max(np.abs(ratio))
    assert np.allclose(vloop.mechanical_advantage(mech, res, "l4") * ratio, 1.0, rtol=1e-9, atol=0)


def test_slider_velocity_ratio_and_the_input_at_rest() -> None:
    mech = load("slider_crank_offset")
    at_rest = dataclasses.replace(mech.drivers[0], v0=0.0)  # starts from rest: ω2(0) = 0
    mech = dataclasses.replace(mech, drivers=(at_rest,))
    res = vloop.solve(mech)
    assert res["l2.omega"][0] == 0.0
    ref = analytic_slider_crank.solve(mech)
    O2, A, B = (xy(ref, j) for j in ("O2", "A", "B"))
    h = intersection(A, B, O2, O2 + 1j, mech.scale)
    I24 = (h[:, 0] + 1j * h[:, 1]) * mech.scale / h[:, 2]
    vr_ref = -(I24 - O2).imag  # the block moves with the point I24 of the crank: v = Re(j·ω2·(I24 − O2))
    vr = vloop.velocity_ratio(mech, res, "l4")  # [m/rad]; MA = F/T [1/m]
    assert np.max(np.abs(vr - vr_ref)) <= 1e-9 * np.max(np.abs(vr_ref))
    vel = vloop.teaching.velocity_centres(mech, res)  # at t = 0 from the configuration's coefficients
    assert vel.found[0].all() and np.max(C.distance(vel.h[0], vloop.teaching.kennedy_centres(mech, res).h[0])) <= 1e-9


def test_ratio_inputs_are_checked() -> None:
    mech = load("slider_crank_offset")
    res = vloop.solve(mech)
    with pytest.raises(vloop.MechanismError, match="unknown output 'nope'"):
        vloop.velocity_ratio(mech, res, "nope")
    with pytest.raises(vloop.MechanismError, match="unknown output 'ground'"):
        vloop.velocity_ratio(mech, res, "ground")
    five = load("fivebar_two_cranks")
    with pytest.raises(vloop.MechanismError, match="exactly one driver"):
        vloop.velocity_ratio(five, vloop.solve(five), "l3")
    for bad in (1, ["l4"], float("nan"), "", "l4 "):
        with pytest.raises(vloop.MechanismError, match="unknown output"):
            vloop.velocity_ratio(mech, res, bad)
    for bad in (0, -0, 15, 1e308, float("nan"), float("inf"), 10**400, "720", [720], True):
        with pytest.raises(ValueError, match="samples must be an integer"):
            vloop.teaching.cycle(mech, samples=bad)
    with pytest.raises(vloop.VloopError, match=r"l4.mechanical_advantage is not finite at t = 0\.01 s \(sample 1\)"):
        report._check_finite(mech, res, {"l4.mechanical_advantage": np.array([1.0, np.inf])})


# ---------------------------------------------------------------- command line


def test_run_extras_info_and_plot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    path = MECH / "whitworth_quick_return.toml"
    assert vloop_main(["run", str(path), "--out", str(tmp_path), "--extras", "--plot"]) == 0
    header = (tmp_path / "extras.csv").read_text(encoding="utf-8").splitlines()[0].split(",")
    assert {"ic.ground.l5.x", "ic.ground.l5.inf", "ic.l4.l3.source", "mu.A.folded", "mu.D.pressure"} <= set(header)
    assert {"l6.velocity_ratio", "l6.mechanical_advantage", "l4.velocity_ratio"} <= set(header)
    data = np.loadtxt(tmp_path / "extras.csv", delimiter=",", skiprows=1)
    assert np.isfinite(data).all() and len(data) == 201
    assert (tmp_path / "transmission.png").stat().st_size > 10_000
    assert not list(tmp_path.glob(".*.tmp"))
    capsys.readouterr()
    assert vloop_main(["info", str(path)]) == 0
    text = capsys.readouterr().out
    assert "l6: stroke 160 mm, time ratio 2 (slow stroke with l6 increasing)" in text
    assert "Kennedy's theorem reaches all 15 pairs" in text
    assert vloop_main(["run", str(path), "--out", str(tmp_path / "bad"), "--ma", "l6,zz"]) == 2
    assert "unknown output 'zz'" in capsys.readouterr().err and not (tmp_path / "bad").exists()


def test_plain_import_reaches_the_teaching_subpackage_on_first_use() -> None:
    """docs/teaching.md: ``import vloop`` then ``vloop.teaching.cycle(mech)``, in a fresh interpreter; ``import
    vloop`` alone does not import the teaching subpackage (it stays light)."""
    import subprocess
    import sys

    code = (
        "import sys, vloop\n"
        "light = not any(m.startswith('vloop.teaching') for m in sys.modules)\n"
        f"mech = vloop.load({str(MECH / 'slider_crank_offset.toml')!r})\n"
        "print(light, repr(vloop.teaching.cycle(mech).outputs['l4'].time_ratio))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    r, ell, e = 2.0, 6.0, 1.0  # the offset slider-crank's closed form (test_offset_slider_crank_stroke_and_time_ratio)
    beta = math.asin(e / (ell - r)) - math.asin(e / (ell + r))
    assert out[0] == "True"
    assert abs(float(out[1]) - (math.pi + beta) / (math.pi - beta)) <= 1e-9
    with pytest.raises(AttributeError, match="no attribute 'no_such_part'"):
        vloop.no_such_part  # noqa: B018


ANGLE_PRINTED = r"(-?\d+(?:\.\d+)?(?:e[-+]?\d+)?) rad \((-?\d+\.\d+)°\)"


def test_every_angle_the_command_line_prints_is_in_zero_to_360(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Angles are printed in [0°, 360°) (rad in [0, 2π)), whatever turn the input starts or ends on: the textbook
    four-bar starts at θ2 = 40°, so its dead centres are found at 40° + travel (the extended one at 384.1468° before
    wrapping); a run past the limit names the input; ``run --sweep`` prints the limits of the rocking input."""
    import re

    mech = load("fourbar_textbook_example")
    a, b, c, d = 40.0, 120.0, 80.0, 100.0  # crank and coupler in line, extended: |O2B| = a + b, B above O2O4
    extended = math.acos((d * d + (a + b) ** 2 - c * c) / (2 * d * (a + b)))
    texts = []
    for args in (
        ["info", str(MECH / "fourbar_textbook_example.toml")],
        ["info", str(MECH / "fourbar_nongrashof_past_limit.toml")],
        ["run", "--sweep", str(MECH / "fourbar_nongrashof_past_limit.toml"), "--out", str(tmp_path / "sweep")],
        ["run", str(MECH / "fourbar_nongrashof_past_limit.toml"), "--out", str(tmp_path / "past")],
    ):
        vloop_main(args)
        captured = capsys.readouterr()
        texts.append(captured.out + captured.err)
    printed = [(r, float(g)) for text in texts for r, g in re.findall(ANGLE_PRINTED, text)]
    assert len(printed) >= 20
    for text, deg in printed:
        rad = float(text)
        assert 0.0 <= rad < TWO_PI and 0.0 <= deg < 360.0, (rad, deg)
        digits = len(text.split("e")[0].replace(".", "").lstrip("0")) or 1  # rad: half a unit of its last digit
        last = 0.5 * 10.0 ** (math.floor(math.log10(rad)) - digits + 1) if rad else 0.0
        assert abs(math.degrees(rad) - deg) <= 0.5e-4 + math.degrees(last), text  # one angle, printed twice
    rests = re.findall(r"dead centre at θ_l2 = (\S+) rad \((\S+)°\): l4 at rest", texts[0])
    rest = [r for r in rests if abs(float(r[0]) - extended) <= 1e-9]  # 24.1468°, was 384.1468°
    assert len(rests) == 2 and len(rest) == 1 and rest[0][1] == "24.1468"
    assert mech.drivers[0].value_text(2 * math.pi + extended, "mm") == f"θ_l2 = {rest[0][0]} rad (24.1468°)"
    lim = math.acos((3.0**2 + 6.0**2 - 8.5**2) / (2 * 3.0 * 6.0))  # the non-Grashof input's limits, ±139.1956°
    assert f"from {TWO_PI - lim:.10g} rad (220.8044°) counter-clockwise to {lim:.10g} rad (139.1956°)" in texts[2]
    assert vloop.model.angle_text(-1e-12) == "0 rad (0.0000°)"  # within the printed precision of a full turn
