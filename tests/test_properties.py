"""Property tests (hypothesis): random linkages on random branches, file round trips, a loader fuzz.

Independent checks only: link lengths from the output joint positions (rigidity, i.e. the loops
close), five-point central differences of positions and velocities, and the sign of the dyad's
triangle (its assembly branch) from the output positions.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import vloop

N = 2001  # samples over one crank turn
PROPS = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def five_point(x: np.ndarray, h: float) -> np.ndarray:
    return (x[:-4] - 8 * x[1:-3] + 8 * x[3:-1] - x[4:]) / (12 * h)


def check_rates(res: vloop.Result, names: list[str], tol: float = 1e-6) -> None:
    """v and a against central differences: with one crank turn in 2000 steps the h⁴ truncation is
    below 1e-7 of the peak for these proportions (the fastest harmonic turns < 0.05 rad per step)."""
    h = res.t[1] - res.t[0]
    for n in names:
        for q, dq in (("x", "vx"), ("y", "vy"), ("vx", "ax"), ("vy", "ay")):
            a, b = res[f"{n}.{q}"], res[f"{n}.{dq}"]
            peak = max(np.max(np.abs(res[f"{n}.vx"] if dq.startswith("v") else res[f"{n}.ax"])), 1e-12)
            peak = max(peak, np.max(np.abs(res[f"{n}.vy"] if dq.startswith("v") else res[f"{n}.ay"])))
            err = np.max(np.abs(five_point(a, h) - b[2:-2]))
            assert err <= tol * peak, f"{n}.{dq}: {err:.3g} vs finite differences ({err / peak:.2g} of peak)"


def fourbar(a: float, b: float, c: float, d: float, th2: float, sigma: int, omega: float, alpha: float) -> dict:
    A = (a * math.cos(th2), a * math.sin(th2))
    O4 = (d, 0.0)
    f = math.dist(A, O4)
    # B on the circles |B − A| = b, |B − O4| = c, on side sigma of the line A → O4
    u = ((O4[0] - A[0]) / f, (O4[1] - A[1]) / f)
    x = (b * b - c * c + f * f) / (2 * f)
    y = sigma * math.sqrt(max(b * b - x * x, 0.0))
    B = (A[0] + x * u[0] - y * u[1], A[1] + x * u[1] + y * u[0])
    turn = 2 * math.pi / abs(omega)
    return {
        "name": "fourbar",
        "joints": {"O2": [0.0, 0.0], "A": list(A), "B": list(B), "O4": list(O4)},
        "links": {
            "ground": {"joints": ["O2", "O4"], "ground": True},
            "crank": {"joints": ["O2", "A"]},
            "coupler": {"joints": ["A", "B"]},
            "rocker": {"joints": ["O4", "B"]},
        },
        "drivers": [{"link": "crank", "pivot": "O2", "omega": omega, "alpha": alpha}],
        "time": {"times": np.linspace(0.0, turn, N).tolist()},
    }


@PROPS
@given(
    d=st.floats(4.0, 10.0),
    shortest=st.floats(0.5, 1.5),
    b_frac=st.floats(0.0, 1.0),
    th2=st.floats(0.0, 2 * math.pi),
    sigma=st.sampled_from([-1, 1]),
    omega=st.floats(0.5, 5.0) | st.floats(-5.0, -0.5),
)
def test_random_grashof_crank_rockers(d, shortest, b_frac, th2, sigma, omega):
    a = shortest
    # Grashof with the crank shortest: a + l < p + q with margin, rocker c and coupler b around d
    c = 0.6 * d + b_frac * 0.6 * d
    b = d + c - 0.6 * d  # b + c > d + a comfortably, |b − c| < d − a
    s, l_ = a, max(b, c, d)
    assume(s + l_ < (b + c + d - l_) - 0.2 * a)
    assume(abs(b - c) < d - a - 0.1 and b + c > d + a + 0.1)
    mech = vloop.from_dict(fourbar(a, b, c, d, th2, sigma, omega, 0.0))
    res = vloop.solve(mech)
    A = res["A.x"] + 1j * res["A.y"]
    B = res["B.x"] + 1j * res["B.y"]
    O4 = res["O4.x"] + 1j * res["O4.y"]
    scale = mech.scale
    for p, q, ln in ((0, A, a), (A, B, b), (O4, B, c)):
        assert np.max(np.abs(np.abs(q - p) - ln)) <= 1e-10 * scale
    # the assembly branch: side of B relative to the line A → O4, the same at every sample
    side = np.sign(((O4 - A).conjugate() * (B - A)).imag)
    assert np.all(side == sigma)
    assert np.all(res.health["branch"] == res.health["branch"][0])
    check_rates(res, ["A", "B"])


@PROPS
@given(
    a=st.floats(0.5, 2.0),
    extra=st.floats(0.5, 5.0),
    e=st.floats(-1.0, 1.0),
    th2=st.floats(0.0, 2 * math.pi),
    sigma=st.sampled_from([-1, 1]),
    omega=st.floats(0.5, 5.0),
    alpha_frac=st.floats(-0.1, 0.1),
)
def test_random_offset_slider_cranks(a, extra, e, th2, sigma, omega, alpha_frac):
    b = a + abs(e) + extra  # the crank turns fully
    alpha = alpha_frac * omega * omega  # about one turn over the run, whatever the acceleration
    A = (a * math.cos(th2), a * math.sin(th2))
    dx = math.sqrt(b * b - (e - A[1]) ** 2)
    B = (A[0] + sigma * dx, e)
    text = {
        "joints": {"O2": [0.0, 0.0], "A": list(A), "B": list(B)},
        "links": {
            "ground": {"joints": ["O2"], "ground": True},
            "crank": {"joints": ["O2", "A"]},
            "rod": {"joints": ["A", "B"]},
        },
        "sliders": {"blk": {"joint": "B", "guide": "ground", "axis": [1.0, 0.0]}},
        "drivers": [{"link": "crank", "pivot": "O2", "omega": omega, "alpha": alpha}],
        "time": {"times": np.linspace(0.0, 2 * math.pi / omega, N).tolist()},
    }
    mech = vloop.from_dict(text)
    res = vloop.solve(mech)
    A_ = res["A.x"] + 1j * res["A.y"]
    B_ = res["B.x"] + 1j * res["B.y"]
    assert np.max(np.abs(np.abs(B_ - A_) - b)) <= 1e-10 * mech.scale
    assert np.max(np.abs(res["B.y"] - e)) <= 1e-10 * mech.scale
    assert np.all(np.sign(res["B.x"] - res["A.x"]) == sigma)  # the branch: B stays on its side of A
    assert np.allclose(res["blk.s"], res["B.x"], atol=1e-12 * mech.scale)
    check_rates(res, ["B"])


@PROPS
@given(
    a=st.floats(0.5, 2.0),
    gap=st.floats(0.3, 4.0),
    th2=st.floats(0.0, 2 * math.pi),
    sigma=st.sampled_from([-1, 1]),
    omega=st.floats(0.5, 5.0),
)
def test_random_inverted_slider_cranks(a, gap, th2, sigma, omega):
    """The block pinned to the crank at A slides along a rocker pivoted at O4 (an inverse slider).
    The block passes the pivot at gap·a: the closer, the sharper the rocker's swing (its ω peaks near
    1/gap times the crank's), which the 2000-step differences resolve for gap ≥ 0.3."""
    d = a * (1 + gap)  # the crank turns fully, the block never reaches the pivot
    A = (a * math.cos(th2), a * math.sin(th2))
    r = (A[0] - d, A[1])
    n = math.hypot(*r)
    axis = [sigma * r[0] / n, sigma * r[1] / n]  # s = sigma·|A − O4|: the branch
    text = {
        "joints": {"O2": [0.0, 0.0], "A": list(A), "O4": [d, 0.0]},
        "links": {
            "ground": {"joints": ["O2", "O4"], "ground": True},
            "crank": {"joints": ["O2", "A"]},
            "rocker": {"joints": ["O4"]},
        },
        "sliders": {"blk": {"joint": "A", "guide": "rocker", "axis": axis}},
        "drivers": [{"link": "crank", "pivot": "O2", "omega": omega}],
        "time": {"times": np.linspace(0.0, 2 * math.pi / omega, N).tolist()},
    }
    mech = vloop.from_dict(text)
    res = vloop.solve(mech)
    A_ = res["A.x"] + 1j * res["A.y"]
    dist = np.abs(A_ - d)
    assert np.max(np.abs(np.abs(res["blk.s"]) - dist)) <= 1e-10 * mech.scale
    assert np.all(np.sign(res["blk.s"]) == sigma)
    # the block's axis (the rocker's direction) points along O4 → A (or against it, sigma = −1)
    u = np.exp(1j * res["rocker.theta"])
    assert np.max(np.abs(sigma * u * dist - (A_ - d))) <= 1e-10 * mech.scale
    h = res.t[1] - res.t[0]
    for q, dq in (
        ("rocker.theta", "rocker.omega"),
        ("rocker.omega", "rocker.alpha"),
        ("blk.s", "blk.v"),
        ("blk.v", "blk.a"),
    ):
        peak = np.max(np.abs(res[dq]))
        assert np.max(np.abs(five_point(res[q], h) - res[dq][2:-2])) <= 1e-6 * peak, dq


@settings(max_examples=200, deadline=None)
@given(
    d=st.floats(4.0, 10.0),
    th2=st.floats(0.0, 2 * math.pi),
    sigma=st.sampled_from([-1, 1]),
    omega=st.floats(0.5, 5.0),
    n=st.integers(2, 50),
)
def test_mechanism_files_round_trip(d, th2, sigma, omega, n, tmp_path_factory):
    data = fourbar(1.0, d, 0.8 * d, d, th2, sigma, omega, 0.25)
    data["time"] = {"start": 0.0, "stop": 1.0, "step": 1.0 / n}
    data["points"] = {"P": {"link": "coupler", "at": [0.5, 0.5]}}
    m1 = vloop.from_dict(data)
    path = tmp_path_factory.mktemp("rt") / "m.toml"
    vloop.save(m1, path)
    m2 = vloop.load(path)
    assert (m1.joints, m1.links, m1.sliders, m1.points) == (m2.joints, m2.links, m2.sliders, m2.points)
    assert np.array_equal(m1.times, m2.times)
    assert [(x.kind, x.target, x.pivot, x.x0, x.v0, x.a0) for x in m1.drivers] == [
        (x.kind, x.target, x.pivot, x.x0, x.v0, x.a0) for x in m2.drivers
    ]


# --------------------------------------------------------------------------- loader fuzz

KEYS = ["name", "joints", "links", "sliders", "points", "drivers", "time", "solver", "title", "units",
        "joint", "guide", "axis", "link", "at", "pivot", "omega", "alpha", "theta0", "profile", "slider",
        "v", "a", "s0", "start", "stop", "step", "times", "ground", "length", "method", "tol", "t", "theta",
        "A", "B", "O2", "crank"]  # fmt: skip
scalars = (
    st.none()
    | st.booleans()
    | st.integers(-5, 5)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.sampled_from(KEYS)
    | st.text(max_size=5)
)
values = st.recursive(
    scalars,
    lambda children: st.lists(children, max_size=4) | st.dictionaries(st.sampled_from(KEYS), children, max_size=5),
    max_leaves=25,
)


@settings(max_examples=300, deadline=None)
@given(st.dictionaries(st.sampled_from(KEYS), values, max_size=8))
def test_fuzz_structures_end_in_vloop_error_or_a_mechanism(data):
    data = {k: v for k, v in data.items() if v is not None}
    try:
        mech = vloop.from_dict(data)
    except vloop.VloopError as exc:
        assert str(exc) and "\n" not in str(exc)
        return
    assert isinstance(mech, vloop.Mechanism)


@settings(max_examples=300, deadline=None)
@given(st.text(max_size=200))
def test_fuzz_text_ends_in_vloop_error_or_a_mechanism(text):
    try:
        vloop.loads(text)
    except vloop.VloopError as exc:
        assert str(exc)


@settings(max_examples=200, deadline=None)
@given(st.data())
def test_fuzz_mutated_eightbar(data):
    """Single-token mutations of a valid file: a vloop error or a mechanism, never another exception."""
    from tests.conftest import MECHANISMS

    text = (MECHANISMS / "eightbar.toml").read_text()
    tokens = text.split(" ")
    i = data.draw(st.integers(0, len(tokens) - 1))
    tokens[i] = data.draw(st.sampled_from(["", "nan", "-1", "0", "[]", "{}", '"x"', "inf", "1e308", "true", "[0.0]"]))
    try:
        mech = vloop.loads(" ".join(tokens))
        try:
            vloop.solve(mech)
        except vloop.VloopError:
            pass
    except vloop.VloopError as exc:
        assert str(exc)
