"""Dimensional synthesis (vloop.synthesis): round trips, every written candidate re-solved independently,
defects detected, bad synthesis files refused.

Independent references: the test's own four-bars (coordinates drawn here, the assembly branch by the
test's own circle intersection), their poses and angles from the hand-derived closed form
(validators/analytic/fourbar.py), and the closed form again on every written candidate. Tolerances: the
exact methods recover dimensions to 1e-9 of the four-bar's size (round-off of a 2×2 or 3×3 solve and of
a Newton polish is ~1e-14; 1e-9 leaves room for ill-conditioned draws); optimization candidates are
held to the error they report plus 1e-9 of the size.
"""

from __future__ import annotations

import importlib
import math
import re

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import vloop
import vloop.synthesis as syn
from validators.analytic import fourbar as analytic_fourbar
from vloop.cli import main
from vloop.synthesis import spec as synth_spec
from vloop.synthesis.linkages import FOURBAR

FEW = settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
MANY = settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
TOL = 1e-9


# ---------------------------------------------------------------- the test's own four-bars


def circle_meet(a: complex, ra: float, b: complex, rb: float, side: int) -> complex:
    """The point at ra from a and rb from b, on side ``side`` of the line a → b (the test's own geometry)."""
    f = abs(b - a)
    u = (b - a) / f
    x = (ra * ra - rb * rb + f * f) / (2 * f)
    return a + u * complex(x, side * math.sqrt(max(ra * ra - x * x, 0.0)))


@st.composite
def grashof_fourbars(draw):
    """A crank-rocker (s + l < p + q by a margin, crank shortest): O2 anywhere, ground at any angle, a tracer P
    on the coupler, the crank at any angle on either branch; returns its coordinates."""
    d = draw(st.floats(0.6, 1.6))
    a = draw(st.floats(0.15, 0.45)) * d
    b = draw(st.floats(0.8, 1.6)) * d
    c = draw(st.floats(0.7, 1.5)) * d
    s, *pq, lg = sorted([a, b, c, d])
    assume(a == s and s + lg < sum(pq) - 0.1 * d)
    O2 = complex(draw(st.floats(-1, 1)), draw(st.floats(-1, 1)))
    O4 = O2 + d * np.exp(1j * draw(st.floats(-math.pi, math.pi)))
    A = O2 + a * np.exp(1j * draw(st.floats(-math.pi, math.pi)))
    B = circle_meet(A, b, O4, c, draw(st.sampled_from([-1, 1])))
    P = A + (B - A) * complex(draw(st.floats(-0.5, 1.5)), draw(st.floats(0.2, 1.0)) * draw(st.sampled_from([-1, 1])))
    return {"O2": O2, "A": A, "B": B, "O4": O4, "P": complex(P)}


def size_of(coords: dict[str, complex]) -> float:
    return max(abs(coords[q] - coords[p]) for p, q in (("O2", "A"), ("A", "B"), ("O4", "B"), ("O2", "O4")))


def closed_form(coords: dict[str, complex], times: np.ndarray) -> vloop.Result:
    mech = FOURBAR.mechanism(coords, name="truth", omega=1.0, times=times)
    return analytic_fourbar.solve(mech, times)


def poses(coords: dict[str, complex], times: np.ndarray) -> list[list[float]]:
    """The coupler's poses (P and the coupler's angle) at ``times`` [s] (any order), by the closed form."""
    order = np.argsort(times)
    res = closed_form(coords, np.asarray(times)[order])
    rows = np.stack([res["P.x"], res["P.y"], res["coupler.theta"]], 1)
    out = np.empty_like(rows)
    out[order] = rows
    return out.tolist()


def pivots(c: syn.Candidate) -> dict[str, complex]:
    return {j: complex(*c.mechanism.joints[j]) for j in ("O2", "A", "B", "O4")}


def own_pair(result: syn.Candidates, coords: dict[str, complex], size: float) -> syn.Candidate:
    """The candidate whose ground pivots are the four-bar's own, its crank driving."""
    for c in result:
        p = pivots(c)
        if abs(p["O2"] - coords["O2"]) <= TOL * size and abs(p["O4"] - coords["O4"]) <= TOL * size:
            return c
    raise AssertionError(f"no candidate has the pivots {coords['O2']:.6g}, {coords['O4']:.6g}")


def assert_recovered(c: syn.Candidate, coords: dict[str, complex], size: float) -> None:
    p = pivots(c)
    for j in ("O2", "A", "B", "O4"):
        assert abs(p[j] - coords[j]) <= TOL * size, (
            f"{j}: {p[j]} vs {coords[j]} ({abs(p[j] - coords[j]) / size:.2g} of size)"
        )


# ---------------------------------------------------------------- round trips


def _instants(draw, n: int) -> np.ndarray:
    """n crank angles over most of a turn, at least 0.3 rad apart (well-separated poses)."""
    gaps = [draw(st.floats(0.3, 1.2)) for _ in range(n - 1)]
    assume(sum(gaps) < 2 * math.pi - 0.3)
    return np.concatenate([[0.0], np.cumsum(gaps)])


def _separated(coords: dict, t: np.ndarray) -> None:
    """Discard draws where a dyad's link barely turns between two poses, absolutely or relative to the coupler
    (the inverted positions of its pivot then nearly coincide): its pivot is an ill-conditioned intersection —
    round-off grows like 1/turn² — which tests the draw, not the method."""
    res = closed_form(coords, t)
    for link in ("crank", "rocker"):
        for th in (res[f"{link}.theta"], res[f"{link}.theta"] - res["coupler.theta"]):
            gaps = np.abs(np.angle(np.exp(1j * (th[:, None] - th[None, :]))))[np.triu_indices(len(t), 1)]
            assume(np.min(gaps) >= 0.05)


def _two_positions(coords: dict, data) -> None:
    t = _instants(data.draw, 2)
    _separated(coords, t)
    res = closed_form(coords, t)
    beta = float(res["crank.theta"][1] - res["crank.theta"][0])
    gamma = float(res["rocker.theta"][1] - res["rocker.theta"][0])
    dyads = [{"fixed": (coords["O2"].real, coords["O2"].imag), "rotations": [beta]},
             {"fixed": (coords["O4"].real, coords["O4"].imag), "rotations": [gamma]}]  # fmt: skip
    out = syn.motion(poses(coords, t), dyads=dyads)
    assert_recovered(own_pair(out, coords, size_of(coords)), coords, size_of(coords))


def _three_positions(coords: dict, data) -> None:
    t = _instants(data.draw, 3)
    _separated(coords, t)
    dyads = [{"fixed": (coords[k].real, coords[k].imag)} for k in ("O2", "O4")]
    out = syn.motion(poses(coords, t), dyads=dyads)
    c = own_pair(out, coords, size_of(coords))
    assert_recovered(c, coords, size_of(coords))
    assert c.solution and c.grashof == "Grashof crank-rocker"
    assert np.max(c.errors) <= TOL * size_of(coords) and np.max(c.angle_errors) <= TOL


def _five_positions(coords: dict, data) -> None:
    t = _instants(data.draw, 5)
    out = syn.motion(poses(coords, t))
    assert_recovered(own_pair(out, coords, size_of(coords)), coords, size_of(coords))


@FEW
@given(grashof_fourbars(), st.data())
def test_motion_round_trip_two_positions(coords, data):
    """Two poses of a four-bar's coupler, its own ground pivots and link rotations as the free choices
    (standard dyad form): the moving pivots, hence every dimension, come back to 1e-9 of the size."""
    _two_positions(coords, data)


@FEW
@given(grashof_fourbars(), st.data())
def test_motion_round_trip_three_positions(coords, data):
    """Three poses, its own ground pivots as the free choices (circle point = circumcentre of the inverted
    centre point): the four-bar comes back to 1e-9 of its size, a defect-free crank-rocker."""
    _three_positions(coords, data)


@settings(max_examples=3, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(grashof_fourbars(), st.data())
def test_motion_round_trip_five_positions(coords, data):
    """Five poses, no free choice (Burmester): one pair of Burmester points is the four-bar's own pivots,
    with its own moving pivots as their circle points, to 1e-9 of the size."""
    _five_positions(coords, data)


@pytest.mark.slow
@MANY
@given(grashof_fourbars(), st.data())
def test_motion_round_trips_many(coords, data):
    _two_positions(coords, data)
    _three_positions(coords, data)


@pytest.mark.slow
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(grashof_fourbars(), st.data())
def test_motion_round_trip_five_positions_many(coords, data):
    _five_positions(coords, data)


def _function_round_trip(coords: dict, data) -> None:
    t = _instants(data.draw, 3)
    res = closed_form(coords, t)
    ground = coords["O4"] - coords["O2"]
    th1 = math.atan2(ground.imag, ground.real)
    pairs = list(zip(res["crank.theta"] - th1, res["rocker.theta"] - th1, strict=True))
    out = syn.function(pairs=pairs, ground=abs(ground))
    c = out[0]
    size = size_of(coords)
    for link, (p, q) in {"crank": ("O2", "A"), "coupler": ("A", "B"), "rocker": ("O4", "B")}.items():
        assert abs(c.dims[link] - abs(coords[q] - coords[p])) <= TOL * size, link
    assert c.solution and np.max(c.errors) <= TOL


@FEW
@given(grashof_fourbars(), st.data())
def test_function_round_trip(coords, data):
    """A four-bar's own input and output angles (from its ground line) at three instants → Freudenstein →
    its crank, coupler and rocker lengths to 1e-9 of its size; the generator meets each pair."""
    _function_round_trip(coords, data)


@pytest.mark.slow
@MANY
@given(grashof_fourbars(), st.data())
def test_function_round_trip_many(coords, data):
    _function_round_trip(coords, data)


# ---------------------------------------------------------------- defects


def _triple_rocker() -> dict[str, complex]:
    """A non-Grashof four-bar: crank a = 0.9, coupler b = 1.1, rocker c = 0.6, ground d = 0.7 along +x
    (s + l = 1.7 > p + q = 1.6), the crank at 2 rad, B above the diagonal A–O4."""
    A = 0.9 * np.exp(2j)
    B = circle_meet(A, 1.1, 0.7 + 0j, 0.6, 1)
    return {"O2": 0j, "A": A, "B": B, "O4": 0.7 + 0j, "P": A + (B - A) * complex(0.5, 0.6)}


def test_limits_of_the_triple_rocker():
    """Its crank stops where coupler and rocker fold (f = |b − c| = 0.5): cos θ = (a² + d² − f²)/(2ad) =
    (0.81 + 0.49 − 0.25)/1.26 = 0.8333…, θ = ±0.58569 rad; stretched (f = 1.7) is out of reach (cos θ < −1).
    So the crank rocks in [0.5857, 2π − 0.5857] (closed form's limit angles agree)."""
    mech = FOURBAR.mechanism(_triple_rocker(), name="t", omega=1.0, times=np.array([0.0]))
    lim = math.acos((0.81 + 0.49 - 0.25) / 1.26)
    assert sorted(analytic_fourbar.limit_angles(mech)) == pytest.approx([lim, 2 * math.pi - lim], abs=1e-12)


def test_order_defect_detected():
    """Five poses of a crank-rocker at crank angles 0, 2, 1, 3, 4 rad from the first (out of order either way
    round): the pair of Burmester points that is the four-bar's own pivots comes back, with an order defect,
    never ranked as a solution."""
    coords = {"O2": 0j, "A": 0.3 + 0.4j, "B": 1.2 + 1.1j, "O4": 1.3 + 0j, "P": 0.5 + 1.0j}
    out = syn.motion(poses(coords, np.array([0.0, 2.0, 1.0, 3.0, 4.0])))
    c = own_pair(out, coords, size_of(coords))
    assert_recovered(c, coords, size_of(coords))
    assert "order" in c.defects and not c.solution
    row = out.table().set_index("name").loc[c.name]
    assert not row["solution"] and "order" in row["defects"]


def test_circuit_defect_detected():
    """Three poses of a crank-rocker, the third on the other assembly circuit (the coupler as it is with pin B
    mirrored in the line A–O4 at that crank angle): the own-pivot linkage meets poses 1 and 2 but reaches pose
    3's crank angle on its own circuit, far from the pose — a circuit defect."""
    coords = {"O2": 0j, "A": 0.3 + 0.4j, "B": 1.2 + 1.1j, "O4": 1.3 + 0j, "P": 0.5 + 1.0j}
    res = closed_form(coords, np.array([0.0, 0.8, 1.6]))
    A, B = (complex(res[f"{k}.x"][2], res[f"{k}.y"][2]) for k in ("A", "B"))
    u = (coords["O4"] - A) / abs(coords["O4"] - A)
    B2 = A + u * ((B - A) / u).conjugate()
    P3 = A + (B2 - A) * (coords["P"] - coords["A"]) / (coords["B"] - coords["A"])
    pz = [*poses(coords, np.array([0.0, 0.8])), [P3.real, P3.imag, float(np.angle(B2 - A))]]
    out = syn.motion(pz, dyads=[{"fixed": (0.0, 0.0)}, {"fixed": (1.3, 0.0)}])
    c = own_pair(out, coords, size_of(coords))
    assert_recovered(c, coords, size_of(coords))
    assert "circuit" in c.defects and not c.solution
    assert c.errors[2] > 0.1 * size_of(coords) and abs(c.errors[1]) <= TOL * size_of(coords)


# ---------------------------------------------------------------- written candidates, re-solved independently

LOG_SPEC = """
name = "logx"
method = "function"
[function]
expression = "log10(x)"
x = [1.0, 2.0]
input = [0.5235987755982988, 2.0943951023931953]
output = [4.1887902047863905, 5.759586531581287]
"""
PATH_POINTS = [[0.41934593890973426, 1.0513270942571156], [-0.10446537637103137, 0.8670381554372484],
               [-0.32097851881852996, 0.3438328126846981], [-0.08455135714254489, 0.11120686613006159],
               [0.3738437688535382, 0.6051205522614385]]  # fmt: skip
PATH_SPEC = f"""
name = "loop"
method = "path"
seed = 2
candidates = 1
files = 1
[path]
points = {PATH_POINTS}
linkage = "fourbar"
"""
MOTION_POSES = poses(
    {"O2": 0j, "A": 0.3 + 0.4j, "B": 1.2 + 1.1j, "O4": 1.3 + 0j, "P": 0.5 + 1.0j}, np.array([0.0, 0.7, 1.5])
)
MOTION_SPEC = f"""
name = "guide"
method = "motion"
files = 2
[motion]
poses = {MOTION_POSES}
[[motion.dyads]]
fixed = [0.0, 0.0]
[[motion.dyads]]
fixed = [1.3, 0.0]
"""


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """vloop synth on a function, a motion and a path generation file: {method: (folder, table)}."""
    import pandas as pd

    out = {}
    for method, text in (("function", LOG_SPEC), ("motion", MOTION_SPEC), ("path", PATH_SPEC)):
        folder = tmp_path_factory.mktemp(method)
        (folder / "spec.toml").write_text(text, encoding="utf-8")
        assert main(["synth", str(folder / "spec.toml"), "--out", str(folder / "out"), "--plot", "--html"]) == 0
        out[method] = (folder / "out", pd.read_csv(folder / "out" / "candidates.csv"))
    return out


def _targets(method: str) -> tuple[np.ndarray, np.ndarray | None]:
    """What each precision position must be, computed here: the function generator's rocker angle at the
    Chebyshev x (x_j = 1.5 − 0.5·cos((2j − 1)π/6)), the poses, the path's points."""
    if method == "function":
        x = 1.5 - 0.5 * np.cos((2 * np.arange(1, 4) - 1) * math.pi / 6)
        y = np.log10(x)
        return math.radians(240) + y / math.log10(2) * math.radians(90), None
    if method == "motion":
        p = np.array(MOTION_POSES)
        return p[:, 0] + 1j * p[:, 1], p[:, 2]
    p = np.array(PATH_POINTS)
    return p[:, 0] + 1j * p[:, 1], None


def _check_passes(method: str, res: vloop.Result, row, size: float) -> None:
    n = 3 if method != "path" else 5
    times = np.array([row[f"t{k + 1}"] for k in range(n)])
    k = [int(np.argmin(np.abs(res.t - t))) for t in times]
    assert np.allclose(res.t[k], times, rtol=0, atol=1e-12)
    target, angle = _targets(method)
    if method == "function":
        # a rocker of negative length (stated in the notes) points the other way: its angle is the output + π
        flipped = "c < 0" in str(row["notes"])
        err = np.abs(np.angle(np.exp(1j * (res["rocker.theta"][k] - target - (math.pi if flipped else 0.0)))))
        assert np.max(err) <= TOL, err
        return
    z = res["P.x"][k] + 1j * res["P.y"][k]
    allowed = TOL * size if method == "motion" else row["max_error"] + TOL * size
    assert np.max(np.abs(z - target)) <= allowed
    if angle is not None:
        th = res["coupler.theta"][k]
        dth = np.angle(np.exp(1j * (th - th[0] - (angle - angle[0]))))
        assert np.max(np.abs(dth)) <= TOL


@pytest.mark.parametrize("method", ["function", "motion", "path"])
def test_written_candidates_pass_through_their_positions(written, method, tmp_path):
    """Every written mechanism file, run by `vloop run` and by the closed-form four-bar
    (validators/analytic/fourbar.py) at the instants the table states, passes through its precision
    positions: to 1e-9 of the size for the exact methods, within its reported error (+1e-9) for the search."""
    folder, table = written[method]
    rows = table[table["file"].notna() & (table["file"] != "")]
    assert len(rows) >= 1 and all(rows["solution"])
    for _, row in rows.iterrows():
        path = folder / row["file"]
        mech = vloop.load(path)
        size = max(v for k, v in row.items() if str(k).startswith("length."))
        assert main(["run", str(path), "--out", str(tmp_path / row["name"])]) == 0
        _check_passes(method, vloop.Result.read_csv(tmp_path / row["name"] / "results.csv"), row, size)
        times = np.unique(np.array([row[f"t{k + 1}"] for k in range(3 if method != "path" else 5)]))
        _check_passes(method, analytic_fourbar.solve(mech, mech.times), row, size)
        assert (folder / f"{row['name']}.html").exists()
        assert len(times) >= 3
    assert {"function": "structural_error.png", "motion": "poses.png", "path": "path.png"}[method] in {
        p.name for p in folder.iterdir()
    }


def test_written_files_state_their_instants(written):
    """The header of a written file names the instants and input angles of its precision positions, equal to
    the table's."""
    folder, table = written["path"]
    row = table[table["file"] == "loop_1.toml"].iloc[0]
    head = (folder / "loop_1.toml").read_text(encoding="utf-8").splitlines()[:6]
    stated = re.search(r"reached at t = \[(.*)\] s", "\n".join(head))
    assert stated is not None
    assert [float(v) for v in stated.group(1).split(",")] == pytest.approx(
        [row[f"t{k}"] for k in range(1, 6)], abs=1e-11
    )
    assert "tracer point: P" in head[1] and "guided body: coupler" in head[1]


# ---------------------------------------------------------------- the synthesis file and bad input


def test_every_documented_key_is_read():
    """Each key of the schema is accepted where the schema puts it (its example value), and one it does not
    name is refused."""
    for section in synth_spec.SECTIONS:
        for key in section.keys:
            if key.example is None or key.name == "method":  # the method picks the section: tested below
                continue
            data = _base(section.name)
            _table(data, section.name)[key.name] = key.example
            synth_spec.from_dict(data)
        data = _base(section.name)
        _table(data, section.name)["bogus"] = 1
        with pytest.raises(vloop.VloopError, match="unknown key 'bogus'"):
            synth_spec.from_dict(data)


def _base(section: str) -> dict:
    if section in ("motion", "dyads"):
        return {
            "method": "motion",
            "motion": {"poses": MOTION_POSES, "dyads": [{"fixed": [0.0, 0.0]}, {"fixed": [1.3, 0.0]}]},
        }
    if section == "path":
        return {"method": "path", "path": {"points": PATH_POINTS}}
    return {
        "method": "function",
        "function": {"expression": "log10(x)", "x": [1, 2], "input": [0.5, 2.0], "output": [4.1, 5.7]},
    }


def _table(data: dict, section: str) -> dict:
    if section == "synthesis":
        return data
    if section == "dyads":
        return data["motion"]["dyads"][0]
    return data[section]


BAD = [
    ("too few poses", 'method = "motion"\n[motion]\nposes = [[0, 0, 0]]', "2 to 5"),
    ("coincident poses", 'method = "motion"\n[motion]\nposes = [[0, 0, 0.5], [1, 1, 0], [0, 0, 0.5]]', "coincide"),
    (
        "six poses",
        'method = "motion"\n[motion]\nposes = [[0,0,0],[1,0,0.1],[2,0,0.2],[3,0,0.3],[4,0,0.4],[5,0,0.5]]',
        "2 to 5",
    ),
    ("too few points", 'method = "path"\n[path]\npoints = [[0, 0], [1, 1]]', "3 to 100"),
    ("coincident points", 'method = "path"\n[path]\npoints = [[0, 0], [1, 1], [0, 0]]', "coincide"),
    (
        "timing a turn",
        'method = "path"\n[path]\npoints = [[0, 0], [1, 1], [2, 0]]\ntiming = [0, 3, 7]',
        "less than one turn",
    ),
    (
        "timing not monotonic",
        'method = "path"\n[path]\npoints = [[0, 0], [1, 1], [2, 0]]\ntiming = [0, 2, 1]',
        "strictly",
    ),
    (
        "undefined on range",
        'method = "function"\n[function]\nexpression = "log(x)"\nx = [-1, 2]\ninput = [0, 1]\noutput = [0, 1]',
        "not defined",
    ),
    (
        "sqrt undefined",
        'method = "function"\n[function]\nexpression = "sqrt(1 - x)"\nx = [0, 2]\ninput = [0, 1]\noutput = [0, 1]',
        "not defined",
    ),
    (
        "same value at both ends",
        'method = "function"\n[function]\nexpression = "sin(x)"\nx = [0, 3.141592653589793]\ninput = [0, 1]\noutput = [0, 1]',
        "same value",
    ),
    (
        "code in expression",
        'method = "function"\n[function]\nexpression = "__import__(\'os\')"\nx = [1, 2]\ninput = [0, 1]\noutput = [0, 1]',
        "not allowed",
    ),
    ("nan", 'method = "path"\n[path]\npoints = [[0, nan], [1, 1], [2, 0]]', "not finite"),
    (
        "inf",
        'method = "function"\n[function]\nexpression = "x"\nx = [1, inf]\ninput = [0, 1]\noutput = [0, 1]',
        "not finite",
    ),
    (
        "10**400",
        'method = "motion"\n[motion]\nposes = [[0, 0, 0], [1, 1, 1000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000000]]',
        "too large",
    ),
    ("string", 'method = "path"\n[path]\npoints = "three points"', "list"),
    ("nested array", 'method = "path"\n[path]\npoints = [[[0, 0]], [1, 1], [2, 0]]', "[x, y]"),
    ("unknown method", 'method = "cam"', "method"),
    ("no section", 'method = "path"', "[path]"),
    ("wrong section", 'method = "path"\n[path]\npoints = [[0, 0], [1, 1], [2, 0]]\n[motion]\nposes = []', "section"),
    (
        "impossible dyad",
        'method = "motion"\n[motion]\nposes = [[0, 0, 0], [1, 0, 0], [2, 0, 0]]\n[[motion.dyads]]\nfixed = [0, 1]\n[[motion.dyads]]\nfixed = [1, 1]',
        "no dyad",
    ),
    (
        "two poses need a rotation",
        'method = "motion"\n[motion]\nposes = [[0, 0, 0], [1, 0, 0.5]]\n[[motion.dyads]]\nfixed = [0, 1]\n[[motion.dyads]]\nfixed = [1, 1]',
        "rotations",
    ),
    (
        "no four-bar for these pairs",
        'method = "function"\n[function]\npairs = [[0, 0], [0.1, 0.1], [0.2, 0.2]]',
        "precision points",
    ),
    ("generations 0", 'method = "path"\n[path]\npoints = [[0, 0], [1, 1], [2, 0]]\ngenerations = 0', "generations"),
    ("tolerance -0", 'method = "path"\n[path]\npoints = [[0, 0], [1, 1], [2, 0]]\ntolerance = -0.0', "tolerance"),
    (
        "min transmission 1e308",
        'method = "path"\nmin_transmission_angle = 1e308\n[path]\npoints = [[0, 0], [1, 1], [2, 0]]',
        "min_transmission_angle",
    ),
    (
        "ground 5e-324 then no linkage",
        'method = "function"\n[function]\nexpression = "x"\nx = [1, 2]\ninput = [0, 1]\noutput = [0, 1]\nground = 0',
        "ground",
    ),
]


@pytest.mark.parametrize("what,text,says", BAD, ids=[b[0] for b in BAD])
def test_bad_synthesis_file(tmp_path, capfd, what, text, says):
    """A malformed file or an impossible request: one line on stderr naming it, exit 2, nothing written."""
    f = tmp_path / "s.toml"
    f.write_text(text, encoding="utf-8")
    rc = main(["synth", str(f), "--out", str(tmp_path / "out")])
    err = capfd.readouterr().err
    assert rc == 2, what
    assert err.count("\n") == 1 and err.startswith("vloop: error:") and "Traceback" not in err, err
    assert says in err, err
    assert not (tmp_path / "out").exists() or not any((tmp_path / "out").iterdir())


# ---------------------------------------------------------------- the batched evaluation


def _random_population(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.uniform(-1.5, 1.5, (n, 2 * len(FOURBAR.coordinates))), np.where(rng.uniform(size=n) < 0.5, -1.0, 1.0)


def test_evaluation_is_each_files_own_motion():
    """The batched evaluation of a random population (either branch, either direction: mirrored rows
    included) gives every completed row the tracer path and coupler angle of its own file run by the closed
    form, to 1e-12 of the size."""
    from vloop.synthesis._evaluate import evaluate
    from vloop.synthesis.linkages import side

    coords, omega = _random_population(120, 3)
    times = np.linspace(0.0, 2 * math.pi, 37)
    ev = evaluate(FOURBAR, coords, omega, times, points=("P",), links=("coupler",))
    done = np.nonzero(ev.completed)[0]
    z = coords[:, 0::2] + 1j * coords[:, 1::2]
    branches = side({k: z[:, i] for i, k in enumerate(FOURBAR.coordinates)}, FOURBAR.dyads[0])
    assert len(done) >= 10 and len(set(branches[done])) == 2 and len(set(omega[done])) == 2
    for v in done[:20]:
        mech = FOURBAR.mechanism(
            dict(zip(FOURBAR.coordinates, z[v], strict=True)), name="v", omega=omega[v], times=times
        )
        ref = analytic_fourbar.solve(mech, times)
        size = max(abs(z[v] - z[v, 0]))
        assert np.max(np.abs(ref["P.x"] + 1j * ref["P.y"] - ev.points["P"][v])) <= 1e-12 * size
        assert np.max(np.abs(np.exp(1j * ref["coupler.theta"]) - np.exp(1j * ev.angles["coupler"][v]))) <= 1e-12


def test_batch_reports_doubtful_variants_as_failures():
    """batch.solve(doubtful="fail"): a variant the batch is not sure of is reported as not completed (reason
    DOUBTFUL, columns NaN) instead of solved one by one; every other variant's numbers are the same bits as
    with the default (the single-run fallback)."""
    from vloop.core import batch
    from vloop.synthesis._evaluate import _model

    coords, omega = _random_population(150, 5)
    model = _model(FOURBAR, (1.0,))
    z = coords[:, 0::2] + 1j * coords[:, 1::2]
    from vloop.synthesis.linkages import side

    keep = side({k: z[:, i] for i, k in enumerate(FOURBAR.coordinates)}, FOURBAR.dyads[0]) > 0
    values = np.concatenate([coords, omega[:, None]], 1)[keep]
    grid = batch.make_grid(model, model.designs(values), np.linspace(0.0, 2 * math.pi, 25))
    fail = batch.solve(model, values, grid, ["P.x"], doubtful="fail")
    single = batch.solve(model, values, grid, ["P.x"])
    by_batch = np.array([s == "batch" for s in single.solver])
    doubtful = np.array([s == "single" for s in single.solver])
    assert doubtful.any() and by_batch.any()
    assert np.array_equal(fail.completed, by_batch)
    assert all(fail.reason[i] == batch.DOUBTFUL for i in np.nonzero(doubtful)[0])
    assert np.all(np.isnan(fail.columns["P.x"][doubtful]))
    assert np.array_equal(fail.columns["P.x"][by_batch], single.columns["P.x"][by_batch])
    with pytest.raises(ValueError, match="doubtful"):
        batch.solve(model, values, grid, ["P.x"], doubtful="maybe")


def test_viewer_page_draws_the_targets(written):
    """A written candidate's page carries its targets (finite x, y[, angle]) and the code that draws them."""
    import json

    folder, _ = written["motion"]
    page = (folder / "guide_1.html").read_text(encoding="utf-8")
    data = json.loads(page.split('id="vloop-data">', 1)[1].split("</script>", 1)[0])
    assert "buildTargets" in page
    got = np.array([[t["x"], t["y"], t["angle"]] for t in data["targets"]])
    assert np.max(np.abs(got - np.array(MOTION_POSES))) <= 1e-15
    with pytest.raises(vloop.VloopError, match="target 1"):
        from vloop.views.view import build_payload

        mech = vloop.load(folder / "guide_1.toml")
        build_payload(mech, vloop.solve(mech), targets=[(float("nan"), 0.0)])


def _sixbar_targets() -> list[list[float]]:
    """Ten points on the path of a tracer on link CD of a Stephenson III six-bar (the catalog's, scaled by 1/5),
    at input angles 0.1 + 2πk/10, by its closed form (validators/analytic/sixbar_stephenson3.py)."""
    from validators.analytic import sixbar_stephenson3 as analytic_sixbar_stephenson3
    from vloop.synthesis.linkages import STEPHENSON3

    truth = STEPHENSON3.mechanism(STEPHENSON3.nominal, name="six", omega=1.0, times=np.array([0.0]))
    ref = analytic_sixbar_stephenson3.solve(truth, np.arange(10) * 2 * math.pi / 10 + 0.1)
    return np.stack([ref["P.x"], ref["P.y"]], 1).tolist()


@pytest.mark.slow
@pytest.mark.parametrize("seed", range(5))
def test_sixbar_where_no_fourbar_reaches(seed):
    """The ten six-bar points asked within 0.2 % of their size. A four-bar's coupler curve has nine free
    dimensions, so no four-bar passes through ten general points (Alt–Burmester); the four-bar search alone
    (300 generations, this seed) ends with its best candidate above the tolerance. With ``linkage = "auto"`` the
    Stephenson III search (seeded with those four-bars) finds a six-bar through all ten, for every seed 0–4.
    Re-solved by the six-bar's closed form and by Pinocchio at the stated instants, its tracer is within its
    reported error (+1e-9 of the size) of every point."""
    from validators import pinocchio
    from validators.analytic import sixbar_stephenson3 as analytic_sixbar_stephenson3

    points = _sixbar_targets()
    four = syn.path(points, count=1, seed=seed, linkage="fourbar", generations=300, tolerance=0.002)
    assert four.best is None and len(four) and min(c.error for c in four) > 0.002
    out = syn.path(points, count=1, seed=seed, linkage="auto", generations=300, tolerance=0.002)
    best = out.best
    assert best is not None and best.topology == "stephenson3" and best.error <= 0.002
    z = np.array([complex(*p) for p in points])
    size = out.task.size
    for engine in (analytic_sixbar_stephenson3, pinocchio):
        res = engine.solve(best.mechanism, np.asarray(best.times))
        err = np.abs(res["P.x"] + 1j * res["P.y"] - z)
        assert np.max(err) <= best.error * size + 1e-9 * size, engine.__name__


@pytest.mark.parametrize("topology", ["fourbar", "stephenson3"])
def test_polish_reaches_the_exact_linkage_from_nearby(topology):
    """The search's last step, fast: a linkage's own tracer points at five (four-bar) or ten (six-bar) input
    angles; its coordinates moved by up to 2 % of the points' size and its instants by up to 0.05 rad. The
    polish (least squares by the dogleg method, each residual and Jacobian one batched solve) lands on a linkage
    through every point to 1e-9 of the size at the instants it states, confirmed by the closed form."""
    import sys

    from validators.analytic import sixbar_stephenson3 as analytic_sixbar_stephenson3
    from vloop.synthesis.defects import Requirements
    from vloop.synthesis.linkages import STEPHENSON3

    path_module = sys.modules["vloop.synthesis.path"]
    top, engine, n = (
        (FOURBAR, analytic_fourbar, 5) if topology == "fourbar" else (STEPHENSON3, analytic_sixbar_stephenson3, 10)
    )
    truth = top.mechanism(top.nominal, name="truth", omega=1.0, times=np.array([0.0]))
    instants = np.arange(n) * 2 * math.pi / n
    ref = engine.solve(truth, instants)
    tg = path_module.targets_of(np.stack([ref["P.x"], ref["P.y"]], 1))
    p = path_module._problem(top, tg, 120, Requirements(full_rotation=True, tolerance=1e-9), 1.5)
    rng = np.random.default_rng(7)
    z = (np.array([top.nominal[k] for k in top.coordinates]) - tg.centre) / tg.size
    start = np.stack([z.real, z.imag], 1).ravel() + rng.uniform(-0.02, 0.02, 2 * len(z))
    t0 = instants + np.concatenate([[0.0], rng.uniform(-0.05, 0.05, n - 1)])
    coords, omega, t, error = path_module._polish(p, start, 1.0, t0)
    assert error <= 1e-9
    world = {k: tg.centre + tg.size * complex(coords[2 * i], coords[2 * i + 1]) for i, k in enumerate(top.coordinates)}
    mech = top.mechanism(world, name="polished", omega=omega, times=np.array([0.0]))
    res = engine.solve(mech, t)
    got = res["P.x"] + 1j * res["P.y"]
    assert np.max(np.abs(got - (tg.centre + tg.size * tg.z))) <= 1e-9 * tg.size


HOSTILE = [0, -0.0, 1e308, 5e-324, float("nan"), float("inf"), 10**400, "a string", [[1.0]]]


def _quick(section: str) -> dict:
    """A base file of the section's method that runs in a moment (a tiny search for path generation)."""
    data = _base(section)
    if data["method"] == "path":
        data["path"].update(generations=2, population=5, samples=16, linkage="fourbar")
        data["candidates"] = 1
    return data


@pytest.mark.slow
@pytest.mark.parametrize("section,key", [(s.name, k.name) for s in synth_spec.SECTIONS for k in s.keys])
def test_every_key_refuses_or_survives_hostile_values(tmp_path, capfd, section, key):
    """0, −0, 1e308, 5e-324, nan, inf, 10**400, a string, a nested array in every key: either one line and
    exit 2, or a run whose files hold only finite numbers (never a traceback)."""
    import tomli_w

    for k, value in enumerate(HOSTILE):
        data = _quick(section)
        table = _table(data, section)
        table[key] = value
        f = tmp_path / f"s{k}.toml"
        f.write_text(tomli_w.dumps(data), encoding="utf-8")
        rc = main(["synth", str(f), "--out", str(tmp_path / f"out{k}")])
        err = capfd.readouterr().err
        assert rc in (0, 2), (key, value, err)
        assert "Traceback" not in err
        if rc == 2:
            assert err.strip().count("\n") == 0 and err.startswith("vloop: error:"), (key, value, err)
        else:
            text = (tmp_path / f"out{k}" / "candidates.csv").read_text(encoding="utf-8").lower()
            assert "nan" not in text.replace("name", "") and "inf" not in text, (key, value)


# ---------------------------------------------------------------- more methods: slider-crank, least squares, four poses, timing


@FEW
@given(st.floats(0.2, 0.5), st.floats(1.2, 2.0), st.floats(-0.3, 0.3), st.floats(-math.pi, math.pi), st.data())
def test_slider_crank_function_round_trip(a, b, e, th0, data):
    """An offset slider-crank (crank a, rod b, offset e; the test's own B at t = 0) and its own crank angles and
    slider positions at three instants (closed form, validators/analytic/slider_crank.py) → the slider-crank
    function generator → a, b, e to 1e-9 of b; it meets each pair to 1e-9."""
    from validators.analytic import slider_crank as analytic_slider_crank
    from vloop.synthesis.linkages import SLIDER_CRANK

    A = a * np.exp(1j * th0)
    B = complex(A.real + math.sqrt(b * b - (e - A.imag) ** 2), e)
    mech = SLIDER_CRANK.mechanism({"O2": 0j, "A": A, "B": B}, name="sc", omega=1.0, times=np.array([0.0]))
    res = analytic_slider_crank.solve(mech, _instants(data.draw, 3))
    out = syn.function(pairs=list(zip(res["crank.theta"], res["slider.s"], strict=True)), linkage="slider-crank")
    c = out[0]
    assert abs(c.dims["crank"] - a) <= TOL * b and abs(c.dims["rod"] - b) <= TOL * b
    assert abs(c.mechanism.joints["B"][1] - e) <= TOL * b
    assert c.solution and np.max(c.errors) <= TOL * b


def test_function_by_least_squares_recovers_an_exact_generator():
    """Five pairs of the same four-bar (a = 0.3, b = 1, c = 0.8 along a ground d = 1; the test's own B): the
    over-determined Freudenstein system is consistent, and least squares gives the four-bar back to 1e-9."""
    A = 0.3 * np.exp(1j * math.pi / 3)
    coords = {"O2": 0j, "A": A, "B": circle_meet(A, 1.0, 1 + 0j, 0.8, 1), "O4": 1 + 0j, "P": A}
    res = closed_form(coords, np.array([0.0, 0.5, 1.0, 1.5, 2.0]))
    out = syn.function(pairs=list(zip(res["crank.theta"], res["rocker.theta"], strict=True)), ground=1.0)
    c = out[0]
    assert [c.dims["crank"], c.dims["coupler"], c.dims["rocker"]] == pytest.approx([0.3, 1.0, 0.8], abs=TOL)
    assert np.max(c.errors) <= TOL


FOUR_POSES_OF = {"O2": 0j, "A": 0.3 + 0.4j, "B": 1.2 + 1.1j, "O4": 1.3 + 0j, "P": 0.5 + 1.0j}


def test_four_poses_own_pivots_on_the_burmester_curves():
    """Four poses of a crank-rocker: its own ground pivots lie on the centre-point curve (the consistency
    determinant vanishes there, to round-off) with its own moving pivots as their circle points; and the
    curve found along the rays passes within 1e-9 of them."""
    motion_module = importlib.import_module("vloop.synthesis.motion")  # the package exports the function

    ps = motion_module.poses_of(poses(FOUR_POSES_OF, np.array([0.0, 0.8, 1.7, 2.6])))
    norm = {k: (v - ps.centre) / ps.size for k, v in FOUR_POSES_OF.items()}
    M, A, _ = motion_module.centre_curve(ps, rays=720, reach=50.0)
    for pivot, moving in (("O2", "A"), ("O4", "B")):
        det = np.linalg.det(motion_module._consistency(ps, np.array([norm[pivot]])))[0]
        assert abs(det) <= 1e-12
        assert abs(motion_module.circle_points(ps, np.array([norm[pivot]]))[0] - norm[moving]) <= TOL
        near = np.argmin(np.abs(M - norm[pivot]))
        assert abs(M[near] - norm[pivot]) <= 0.05  # a ray every 0.25°: the nearest sample of the curve
        assert abs(A[near] - norm[moving]) <= 0.5


@pytest.mark.slow
def test_four_poses_search_along_the_curves():
    """Four poses: the candidates searched along the centre-point curve are exact (every pose met to 1e-9 of
    the size when re-solved)."""
    pz = poses(FOUR_POSES_OF, np.array([0.0, 0.8, 1.7, 2.6]))
    size = syn.motion.__globals__["poses_of"](pz).size
    out = syn.motion(pz, grid=5, count=2)
    assert len(out.solutions) >= 1
    for c in out.solutions:
        assert np.max(c.errors) <= TOL * size and np.max(c.angle_errors) <= TOL


@pytest.mark.slow
def test_path_with_prescribed_timing():
    """Five points of a crank-rocker's coupler path at crank angles 0, 1, 2.2, 3.1, 4.5 rad from the first:
    the synthesized linkage passes each point at that input angle from the first (the closed form re-solves it
    at the stated instants: within its reported error + 1e-9 of the size, the error within 1 %)."""
    coords = {"O2": 0j, "A": 0.3 + 0.4j, "B": 1.2 + 1.1j, "O4": 1.3 + 0j, "P": 0.5 + 1.0j}
    timing = np.array([0.0, 1.0, 2.2, 3.1, 4.5])
    pts = [p[:2] for p in poses(coords, timing)]
    out = syn.path(pts, timing=timing.tolist(), count=1, seed=0, linkage="fourbar")
    c = out.best
    assert c is not None and c.error <= 0.01
    assert np.allclose(c.times, timing, atol=1e-12)
    res = analytic_fourbar.solve(c.mechanism, c.times)
    z = np.array([complex(*p) for p in pts])
    assert np.max(np.abs(res["P.x"] + 1j * res["P.y"] - z)) <= c.error * out.task.size + TOL * out.task.size
    assert np.allclose(np.diff(res["crank.theta"]), np.diff(timing) * c.mechanism.drivers[0].v0, atol=1e-12)
