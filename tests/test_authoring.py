"""Mechanisms written from dimensions: vloop assembles t = 0 itself, and the result is the mechanism the
coordinates describe.

References, independent of the authoring step:

* every catalog file's own run (its coordinates are its assembly): the file is rewritten from its dimensions
  here — lengths, a ternary link's two sides and angle, slider offsets and angles, points and centres of
  mass in their bodies' frames, all read from the original's body frames — with every moving joint's
  coordinates replaced by a hint off by up to ±20 % per coordinate, and every result column must agree
  to 1e-12 of its size;
* for the Watt II written without any moving coordinate, hand geometry: every pin distance against the
  stated lengths, the angle B–O4–C, the crank angle, and the side of each four-bar's diagonal its middle
  joint lies on (the branch name), by a cross product written out here;
* ambiguous and impossible dimension sets: refused with one line and exit code 2.
"""

from __future__ import annotations

import cmath
import copy
import dataclasses
import functools
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest

import vloop
from vloop.authoring import assemble_mechanism
from vloop.cli import main
from vloop.files.fileformat import to_dict
from vloop.mechanism import loads as read_only

from .conftest import MECHANISMS, mechanism_files

HINT = 0.2  # each hinted coordinate off by up to this fraction of itself
TOL = 1e-12  # of each column's size: the claim for a mechanism assembled from its dimensions


def dimensions_only(path: Path, rng: np.random.Generator, hints: bool = True) -> dict:
    """The file rewritten from its dimensions: the ground's coordinates as they are, every other joint a rough hint
    (or none), every shape from the original's body frames (what its compile uses), every input stated."""
    data = tomllib.loads(path.read_text(encoding="utf-8"))
    mech = vloop.load(path)
    bodies = mech.bodies()
    at0 = vloop.solve(mech, times=np.zeros(1))
    ground = set(mech.links[mech.ground].joints)
    out = copy.deepcopy(data)
    out["joints"] = {}
    for j, xy in mech.joints.items():
        if j in ground:
            out["joints"][j] = list(xy)
        elif hints:
            out["joints"][j] = [at0[f"{j}.{c}"][0] * (1 + rng.uniform(-HINT, HINT)) for c in "xy"]
    for name, lk in mech.links.items():
        table = out["links"][name] = (
            out["links"][name] if isinstance(out["links"][name], dict) else {"joints": out["links"][name]}
        )
        if lk.ground:
            continue
        local = bodies[name].local
        if len(lk.joints) == 2:
            table["length"] = local[lk.joints[1]][0]
        else:
            u, v = local[lk.joints[2]]
            table.update(sides=[local[lk.joints[1]][0], math.hypot(u, v)], angle=math.atan2(v, u))
        _com_local(table, bodies[name])
    for name, sl in mech.sliders.items():
        table, guide = out["sliders"][name], bodies[sl.guide]
        lx, ly = _in_frame(guide, mech.joints[sl.joint])
        alpha = math.atan2(sl.axis[1], sl.axis[0]) - guide.theta0
        table["offset"] = -lx * math.sin(alpha) + ly * math.cos(alpha)
        if sl.guide != mech.ground:
            del table["axis"]
            table["angle"] = alpha
        _com_local(table, bodies[name])
    for name, p in mech.points.items():
        table = out["points"][name]
        del table["at"]
        table["local"] = list(bodies[p.link].local[name])
    for table, drv in zip(out["drivers"], mech.drivers, strict=True):
        if "profile" not in table:
            table["theta0" if drv.kind == "crank" else "s0"] = drv.x0
    return out


def _in_frame(body: vloop.mechanism.Body, xy: tuple[float, float]) -> tuple[float, float]:
    c, s = math.cos(body.theta0), math.sin(body.theta0)
    dx, dy = xy[0] - body.origin[0], xy[1] - body.origin[1]
    return c * dx + s * dy, -s * dx + c * dy


def _com_local(table: dict, body: vloop.mechanism.Body) -> None:
    if "com" in table:
        table["com_local"] = list(_in_frame(body, tuple(table.pop("com"))))


def _run(mech: vloop.Mechanism) -> tuple[vloop.Result, str | None]:
    try:
        return vloop.solve(mech), None
    except vloop.MotionError as exc:
        return exc.partial, str(exc)


def _worst(a: vloop.Result, b: vloop.Result, scale: float) -> float:
    """The largest difference of any column, as a fraction of the column's size (lengths: at least the
    mechanism's)."""
    assert set(a.columns) == set(b.columns) and np.array_equal(a.t, b.t)
    worst = 0.0
    for name, x in a.columns.items():
        size = max(float(np.abs(x).max(initial=0.0)), scale if name.endswith((".x", ".y", ".s")) else 0.0, 1e-300)
        worst = max(worst, float(np.abs(x - b[name]).max(initial=0.0)) / size)
    return worst


# ---------------------------------------------------------------- the catalog from its dimensions


@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_every_catalog_file_from_its_dimensions_and_rough_hints(path: Path) -> None:
    rng = np.random.default_rng(sum(map(ord, path.stem)))
    original = vloop.load(path)
    draft = read_only(vloop.dumps(original), source=str(path))  # (a written file: profiles inline)
    data = dimensions_only(path, rng)
    mech = vloop.from_dict(data, source=str(path), base_dir=path.parent)
    assert mech.from_dimensions and not draft.unplaced
    hinted = [j for j in data["joints"] if j not in original.links[original.ground].joints]
    if hinted:  # the hints really were rough: the assembly moved them
        moved = max(math.dist(data["joints"][j], mech.joints[j]) for j in hinted)
        assert moved > 1e-3 * original.scale
    (ref, ref_error), (res, error) = _run(original), _run(mech)
    assert (error is None) == (ref_error is None) and len(res) == len(ref)
    assert _worst(ref, res, original.scale) <= TOL


def test_the_watt_six_bar_from_dimensions_only_is_the_catalog_one() -> None:
    dims = vloop.load(MECHANISMS / "sixbar_watt2_dimensions.toml")
    coords = vloop.load(MECHANISMS / "sixbar_watt2.toml")
    assert dims.from_dimensions and not coords.from_dimensions
    assert _worst(vloop.solve(coords), vloop.solve(dims), coords.scale) <= TOL


def test_the_watt_six_bar_assembly_by_hand_geometry() -> None:
    """Distances, the ternary's angle, the crank angle and both four-bars' shapes, from the joint coordinates."""
    m = vloop.load(MECHANISMS / "sixbar_watt2_dimensions.toml")
    p = {j: complex(*xy) for j, xy in m.joints.items()}
    for a, b, length in (("O2", "A", 2), ("A", "B", 6), ("O4", "B", 4), ("O4", "C", 3), ("C", "D", 4), ("O6", "D", 4)):
        assert abs(abs(p[a] - p[b]) - length) <= 1e-14 * m.scale, (a, b)
    turn = np.angle((p["C"] - p["O4"]) / (p["B"] - p["O4"]))
    assert abs(turn - math.radians(-130)) <= 1e-14
    assert abs(np.angle(p["A"] - p["O2"]) - math.pi / 6) <= 1e-15

    def crosses(a: complex, b: complex, c: complex, d: complex) -> bool:
        side = lambda u, v, w: ((v - u).conjugate() * (w - u)).imag  # noqa: E731
        return side(a, b, c) * side(a, b, d) < 0 and side(c, d, a) * side(c, d, b) < 0

    def crossed(q: list[complex]) -> bool:
        return crosses(q[0], q[1], q[2], q[3]) or crosses(q[1], q[2], q[3], q[0])

    def left(a: complex, b: complex, m: complex) -> bool:  # m to the left of the line a→b
        return ((b - a).conjugate() * (m - a)).imag > 0

    assert not crossed([p["O2"], p["A"], p["B"], p["O4"]]) and left(p["A"], p["O4"], p["B"])  # loop 1 "open"
    # loop 2 "open" (D left of C→O6) although its quadrilateral crosses itself at this instant
    assert crossed([p["O4"], p["C"], p["D"], p["O6"]]) and left(p["C"], p["O6"], p["D"])


# ---------------------------------------------------------------- vloop assemble: the round trip


@pytest.mark.parametrize("stem", ["sixbar_watt2_dimensions", "whitworth_quick_return", "fourbar_textbook_dynamics"])
def test_assemble_writes_a_file_that_loads_to_the_same_mechanism(stem: str, tmp_path: Path, capsys) -> None:
    path = MECHANISMS / f"{stem}.toml"
    if stem != "sixbar_watt2_dimensions":  # rewritten from its dimensions with rough hints
        text = vloop.dumps(vloop.from_dict(dimensions_only(path, np.random.default_rng(7)), source=str(path)))
        path = tmp_path / f"{stem}.toml"
        path.write_text(_as_hints(text, read_only(text)), encoding="utf-8")
    fixed = tmp_path / "fixed.toml"
    assert main(["assemble", str(path), "--out", str(fixed)]) == 0
    out = capsys.readouterr().out
    assert f"wrote {fixed}" in out and "loop 1 (" in out
    first, again = vloop.load(path), vloop.load(fixed)
    _same_numbers(to_dict(first), to_dict(again), 1e-15 * first.scale)
    assert _worst(vloop.solve(first), vloop.solve(again), first.scale) <= 1e-14
    again_text = fixed.read_text(encoding="utf-8")
    assert main(["assemble", str(fixed), "--out", str(tmp_path / "again.toml")]) == 0  # a fixed point: the same text
    assert (tmp_path / "again.toml").read_text(encoding="utf-8").split("\n", 1)[1] == again_text.split("\n", 1)[1]


WITH_COMMENTS = """# A four-bar from its dimensions, commented as a user writes it.
name = "commented"   # the name
units = "mm"

[joints]          # ground pivots, and a rough B
O2 = [0, 0]       # crank pivot, as integers
O4 = [7.0, 0.0]
B = [6, 5]        # rough: the assembly moves it

[links]
ground = { joints = ["O2", "O4"], ground = true }
l2 = { joints = ["O2", "A"], length = 2.0 }   # crank
l3 = { joints = ["A", "B"], length = 6.0 }
l4 = { joints = ["O4", "B"], length = 5.0 }

[[drivers]]
link = "l2"
theta0 = 1.0471975511965976   # 60 deg
omega = 3.0

[time]            # one turn, as a range (never a list of 201 times)
start = 0.0
stop = 2.0
step = 0.01

[solver]
tol = 1e-12
branches = { 1 = "crossed" }   # the other assembly than the hint's
"""


def test_assemble_keeps_the_users_text(tmp_path: Path, capsys) -> None:
    """Comments, [time] as a range and every other line survive; only the moving joints' coordinates change (A
    added, B closed), [solver] branches is taken out with a comment; the file re-reads to the same Mechanism as the
    assembly, and B is the crossed one (right of A→O4, by hand)."""
    src = tmp_path / "commented.toml"
    src.write_text(WITH_COMMENTS, encoding="utf-8")
    fixed = tmp_path / "fixed.toml"
    assert main(["assemble", str(src), "--out", str(fixed)]) == 0
    capsys.readouterr()
    text = fixed.read_text(encoding="utf-8")
    old, new = WITH_COMMENTS.splitlines(), text.splitlines()[1:]
    assert text.splitlines()[0].startswith("# commented: assembled at t = 0 by vloop assemble")
    changed = [line for line in old if line not in new]
    assert changed == [
        "B = [6, 5]        # rough: the assembly moves it",
        'branches = { 1 = "crossed" }   # the other assembly than the hint\'s',
    ]
    added = [line for line in new if line not in old]
    assert len(added) == 3 and added[0].startswith("B = [") and added[0].endswith("# rough: the assembly moves it")
    assert added[1].startswith("A = [") and added[2].startswith('# branches = { 1 = "crossed" }')
    assert (
        "[time]            # one turn, as a range (never a list of 201 times)\nstart = 0.0\nstop = 2.0\nstep = 0.01\n"
        in text
    )
    closed, _ = assemble_mechanism(read_only(WITH_COMMENTS, source=str(src)))
    again = read_only(text, source=str(src))
    assert again.options == {"tol": 1e-12} and closed.options == again.options  # branches: now in the coordinates
    assert to_dict(again) == to_dict(closed) and np.array_equal(again.times, closed.times)
    a, b, o4 = (complex(*again.joints[j]) for j in ("A", "B", "O4"))
    assert ((o4 - a).conjugate() * (b - a)).imag < 0  # B right of A→O4: crossed
    assert vloop.load(fixed).joints == again.joints  # loading assembles it again: nothing moves


def _as_hints(text: str, mech: vloop.Mechanism) -> str:
    """A written mechanism's text with its moving joints moved off by 10 % (its dimensions unchanged)."""
    data = tomllib.loads(text)
    for j in data["joints"]:
        if j not in mech.links[mech.ground].joints:
            data["joints"][j] = [x * 1.1 + 0.05 * mech.scale for x in data["joints"][j]]
    import tomli_w

    return tomli_w.dumps(data)


def _same_numbers(a: object, b: object, tol: float, where: str = "") -> None:
    """Two TOML structures equal, numbers to ``tol``."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and a.keys() == b.keys(), where
        for k in a:
            _same_numbers(a[k], b[k], tol, f"{where}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            _same_numbers(x, y, tol, f"{where}[{i}]")
    elif isinstance(a, float):
        assert abs(a - b) <= tol, (where, a, b)
    else:
        assert a == b, where


def test_assemble_to_standard_output_and_its_refusals(tmp_path: Path, capsys) -> None:
    assert main(["assemble", str(MECHANISMS / "sixbar_watt2_dimensions.toml")]) == 0
    captured = capsys.readouterr()
    assert (
        vloop.loads(captured.out.split("\n", 1)[1]).joints
        == vloop.load(MECHANISMS / "sixbar_watt2_dimensions.toml").joints
    )
    assert "loop 2 (O4–C–D–O6): open (D left of C→O6) (named)" in captured.err
    assert main(["assemble", str(MECHANISMS / "eightbar.toml"), "--out", str(tmp_path / "x.toml")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "not written from dimensions (links.l2 has no length" in err
    assert not (tmp_path / "x.toml").exists()


# ---------------------------------------------------------------- refusals: one line, exit 2

FOURBAR = """
name = "fb"
[joints]
O2 = [0.0, 0.0]
O4 = [7.0, 0.0]
{hints}
[links]
ground = {{ joints = ["O2", "O4"], ground = true }}
l2 = {{ joints = ["O2", "A"], length = 2.0 }}
l3 = {{ joints = ["A", "B"], length = {b} }}
l4 = {{ joints = ["O4", "B"], length = 5.0 }}
[[drivers]]
link = "l2"
{theta0}
omega = 1.0
[time]
stop = 1.0
step = 0.1
{solver}
"""


def _fourbar(tmp_path: Path, hints: str = "", b: float = 6.0, theta0: str = "theta0 = 1.0", solver: str = "") -> Path:
    path = tmp_path / "fb.toml"
    path.write_text(FOURBAR.format(hints=hints, b=b, theta0=theta0, solver=solver), encoding="utf-8")
    return path


def _refused(path: Path, capsys, *needles: str, command: str = "run") -> None:
    args = [command, str(path), "--out", str(path.parent / ("o" if command == "run" else "o.toml"))]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err


@pytest.mark.parametrize(
    ("case", "needles"),
    [
        ({}, ["loop 1 (O2–A–B–O4) has two assemblies", "give rough coordinates of B", '{ 1 = "open" }']),
        ({"b": 0.5}, ["the dimensions cannot close loop 1 (O2–A–B–O4)", "θ_l2 = 1 rad", "its links cannot reach"]),
        ({"hints": "B = [6.0, 4.0]", "theta0": ""}, ["give theta0", "A has no coordinates"]),
        ({"hints": "A = [1.2, 1.6]\nB = [6.0, 4.0]", "theta0": ""}, ["give theta0", "only hints here"]),
        ({"solver": '[solver]\nbranches = { 2 = "open" }'}, ["there is no loop 2"]),
        ({"solver": '[solver]\nbranches = { 1 = "flip" }'}, ["has two assemblies", "no joint it places"]),
    ],
    ids=["ambiguous", "cannot-close", "theta0-unplaced", "theta0-rough", "no-such-loop", "flip-without-hints"],
)
def test_ambiguous_and_impossible_dimensions_are_refused(tmp_path: Path, capsys, case: dict, needles: list) -> None:
    _refused(_fourbar(tmp_path, **case), capsys, *needles)
    _refused(_fourbar(tmp_path, **case), capsys, *needles, command="assemble")


@pytest.mark.parametrize(("choice", "crossed"), [("open", False), ("crossed", True)])
def test_a_named_branch_needs_no_hint(tmp_path: Path, choice: str, crossed: bool) -> None:
    mech = vloop.load(_fourbar(tmp_path, solver=f'[solver]\nbranches = {{ 1 = "{choice}" }}'))
    p = {j: complex(*xy) for j, xy in mech.joints.items()}
    assert abs(abs(p["B"] - p["A"]) - 6) <= 1e-14 and abs(abs(p["B"] - p["O4"]) - 5) <= 1e-14
    assert (p["B"].imag < 0) == crossed  # crossed: B below the ground line, the coupler crossing it
    assert "branches" not in mech.options  # the coordinates hold the branch now


def test_hints_choose_the_nearer_branch_and_flip_the_other(tmp_path: Path) -> None:
    below = vloop.load(_fourbar(tmp_path, hints="B = [4.0, -3.0]"))
    flipped = vloop.load(_fourbar(tmp_path, hints="B = [4.0, -3.0]", solver='[solver]\nbranches = { 1 = "flip" }'))
    assert below.joints["B"][1] < 0 < flipped.joints["B"][1]
    assert "branches" not in flipped.options


DIMENSION_ERRORS = [
    ("links.l3", {"sides": [1.0, 2.0]}, "'sides' is for ternary links"),
    ("links.l4", {"sides": [4.0, 3.0]}, "two sides need the 'angle'"),
    ("links.l4", {"sides": [4.0, 3.0, 9.0]}, "cannot form a triangle"),
    ("links.l4", {"sides": [4.0, 3.0, 2.0], "angle": 1.0}, "three sides take no angle"),
    ("links.l4", {"sides": [4.0, 3.0], "angle": 1.0, "length": 2.0}, "instead of 'length'"),
]


@pytest.mark.parametrize(("entry", "keys", "message"), DIMENSION_ERRORS)
def test_bad_dimensions_are_refused(entry: str, keys: dict, message: str) -> None:
    data = tomllib.loads((MECHANISMS / "sixbar_watt2_dimensions.toml").read_text(encoding="utf-8"))
    section, name = entry.split(".")
    table = data[section][name]
    table.pop("sides", None), table.pop("angle", None)
    table.update(keys)
    with pytest.raises(vloop.MechanismError, match=message):
        vloop.from_dict(data)


@pytest.mark.parametrize(
    "value", [0, -0.0, 1e308, 5e-324, float("nan"), float("inf"), 10**400, "x", [[1.0]], -1.0], ids=repr
)
@pytest.mark.parametrize("key", ["sides", "angle", "offset", "slider_angle", "local", "com_local"])
def test_hostile_values_of_the_new_keys(key: str, value: object) -> None:
    """Each new key with a hostile value: refused with a one-line MechanismError, or (a finite value that makes
    sense) accepted with only finite numbers in the mechanism."""
    watt = tomllib.loads((MECHANISMS / "sixbar_watt2_dimensions.toml").read_text(encoding="utf-8"))
    data, section, name, field, v = {
        "sides": (watt, "links", "l4", "sides", [value, 3.0]),
        "angle": (watt, "links", "l4", "angle", value),
        "offset": (SLIDER_CRANK, "sliders", "blk", "offset", value),
        "slider_angle": (SLIDER_CRANK, "sliders", "blk", "angle", value),
        "local": (SLIDER_CRANK, "points", "P", "local", [value, 0.5]),
        "com_local": (SLIDER_CRANK, "links", "l3", "com_local", [1.0, value]),
    }[key]
    data = copy.deepcopy(data)
    if field == "angle" and section == "sliders":
        del data[section][name]["axis"]
    data[section][name][field] = v
    try:
        mech = vloop.from_dict(data)
    except vloop.MechanismError as exc:
        assert "\n" not in str(exc)
        return
    numbers = [x for xy in (*mech.joints.values(), *(p.at for p in mech.points.values())) for x in xy]
    numbers += [x for mp in mech.masses.values() for x in mp.com]
    assert all(math.isfinite(x) for x in numbers)


SLIDER_CRANK = {  # an offset slider-crank written from dimensions: a tracer point and a mass on the rod
    "name": "sc",
    "joints": {"O2": [0.0, 0.0], "A": [0.0, 1.0], "B": [3.0, 0.3]},
    "links": {
        "ground": {"joints": ["O2"], "ground": True},
        "l2": {"joints": ["O2", "A"], "length": 1.0},
        "l3": {"joints": ["A", "B"], "length": 3.0, "mass": 1.0, "com_local": [1.5, 0.0]},
    },
    "sliders": {"blk": {"joint": "B", "guide": "ground", "axis": [1.0, 0.0], "offset": 0.2}},
    "points": {"P": {"link": "l3", "local": [1.0, 0.5]}},
    "drivers": [{"link": "l2", "theta0": 1.2, "omega": 1.0}],
    "time": {"start": 0.0, "stop": 0.5, "step": 0.1},
}


@pytest.mark.parametrize(
    ("stem", "names"),
    [
        ("whitworth_quick_return", ["sliders.l3.angle", "sliders.l6.offset", "links.l5.length", "joints.C.x"]),
        ("fourbar_crank_rocker_open", ["links.l3.length", "joints.B.y", "drivers.l2.theta0"]),
    ],
)
def test_study_variants_of_a_file_written_from_dimensions_equal_their_own_files(stem: str, names: list) -> None:
    """A design study varies the stated numbers (a slider's angle in its guide's frame, its offset, a length) and the
    hints (which move nothing): each variant equals its own file, written and loaded again."""
    path = MECHANISMS / f"{stem}.toml"
    mech = vloop.from_dict(dimensions_only(path, np.random.default_rng(3)), source=str(path))
    mech = dataclasses.replace(mech, times=mech.times[:40])
    from vloop.core.variants import resolve

    params = [{"name": n, "tolerance": {"dist": "normal", "sigma": 2e-3 * resolve(mech, n, n).typical}} for n in names]
    cols = list(vloop.solve(mech, mech.times[:2]).columns)
    res = vloop.study(mech, params, [f"{c}.series" for c in cols], samples=4, seed=5, sensitivity="none")
    assert res.table["completed"].all()
    for i in range(len(res.table)):
        own = vloop.loads(vloop.dumps(res.variant_mechanism(i)))
        assert own.from_dimensions
        ref = vloop.solve(own, mech.times)
        for c in cols:
            diff = np.asarray(res.table.loc[i, f"{c}.series"]) - ref[c]
            diff = np.angle(np.exp(1j * diff)) if c.endswith(".theta") else diff
            assert np.max(np.abs(diff)) <= 1e-11 * max(np.max(np.abs(ref[c])), 1e-9 * mech.scale), (i, c)


def test_a_redundant_linkage_from_dimensions_is_assembled_from_its_coordinates(tmp_path: Path, capsys) -> None:
    """A double parallelogram (Gruebler M = 0, mobility 1) moves only because its dimensions agree exactly: written
    from dimensions, it is assembled from its coordinates (which must then be given) and moves as the one written
    from coordinates does."""
    from tests.test_redundant import DOUBLE

    coords = vloop.loads(DOUBLE.format(o5x=6.0, stop=1.0), source="double")
    text = DOUBLE.format(o5x=6.0, stop=1.0)
    text = text.replace('crank = { joints = ["O2", "A"] }', 'crank = { joints = ["O2", "A"], length = 2.0 }')
    text = text.replace('rocker = { joints = ["O4", "B"] }', 'rocker = { joints = ["O4", "B"], length = 2.0 }')
    text = text.replace('bar = { joints = ["O5", "E"] }', 'bar = { joints = ["O5", "E"], length = 2.0 }')
    text = text.replace('["A", "B", "E"] }', '["A", "B", "E"], sides = [4.0, 6.0], angle = 0.0 }')
    text = text.replace("omega = 2.0", "theta0 = 1.5707963267948966\nomega = 2.0")
    dims = vloop.loads(text, source="double")
    assert dims.from_dimensions and not coords.from_dimensions
    assert _worst(vloop.solve(coords), vloop.solve(dims), coords.scale) <= TOL
    path = tmp_path / "double.toml"
    path.write_text(text.replace("E = [6.0, 2.0]\n", ""), encoding="utf-8")
    _refused(path, capsys, "the linkage is redundant", "give those of E")


def test_a_study_file_may_name_a_file_written_from_dimensions(tmp_path: Path) -> None:
    from vloop.studies.studyfile import load as load_study

    study = tmp_path / "s.toml"
    study.write_text(
        f'mechanism = "{(MECHANISMS / "sixbar_watt2_dimensions.toml").as_posix()}"\n'
        '[[parameters]]\nname = "links.l5.length"\nvalues = [3.9, 4.1]\n'
        '[[outputs]]\nquantity = "l6.theta"\nstat = "range"\n',
        encoding="utf-8",
    )
    spec = load_study(study)
    assert spec.mechanism.from_dimensions and not spec.mechanism.unplaced  # assembled, as vloop.load gives it
    assert spec.mechanism.joints == vloop.load(MECHANISMS / "sixbar_watt2_dimensions.toml").joints


ONE_JOINT_GUIDE = """
name = "inverted_one_joint"
units = "mm"
[joints]
O2 = [0.0, 0.0]
O4 = [100.0, 0.0]
A = [30.0, 25.0]
[links]
ground = { joints = ["O2", "O4"], ground = true }
l2 = { joints = ["O2", "A"], length = 40.0 }
l4 = { joints = ["O4"] }              # the slotted rocker: one joint, its θ is the slot's direction
[sliders]
l3 = { joint = "A", guide = "l4", axis = [-0.9, 0.4], offset = 0.0 }   # the slot drawn roughly
[[drivers]]
link = "l2"
theta0 = 0.5235987755982988
omega = 10.0
alpha = 5.0
[time]
start = 0.0
stop = 1.0
step = 0.005
"""


def test_a_block_on_a_one_joint_guide_takes_the_drawn_slot_direction() -> None:
    """The inverted slider-crank with a one-joint rocker: no joint tells its two assemblies (slot towards A or away)
    apart, the slot's drawn direction does; the motion is the catalog file's (whose rocker carries a tip joint)."""
    mech = vloop.loads(ONE_JOINT_GUIDE, source="inv")
    ref = vloop.load(MECHANISMS / "inverted_slider_crank.toml")
    assert mech.from_dimensions
    assert np.allclose(mech.sliders["l3"].axis, ref.sliders["l3"].axis, rtol=0, atol=1e-15)
    res, want = vloop.solve(mech), vloop.solve(ref)
    for c in res.columns:
        assert np.max(np.abs(res[c] - want[c])) <= TOL * max(np.max(np.abs(want[c])), ref.scale), c
    away = vloop.loads(ONE_JOINT_GUIDE.replace("[-0.9, 0.4]", "[0.9, -0.4]"), source="inv")  # drawn the other way
    assert np.allclose(away.sliders["l3"].axis, -np.asarray(ref.sliders["l3"].axis), rtol=0, atol=1e-15)


def test_points_and_centres_of_mass_given_in_their_body_s_frame() -> None:
    """A tracer point and a centre of mass stated in the rod's frame (origin A, x towards B) of a slider-crank with
    no coordinates for A: both land where the rod carries them, by hand from the assembled A and B."""
    data = copy.deepcopy(SLIDER_CRANK)
    del data["joints"]["A"]
    mech = vloop.from_dict(data)
    a, b = (complex(*mech.joints[j]) for j in ("A", "B"))
    assert abs(abs(b - a) - 3.0) <= 1e-14 and abs(b.imag - 0.2) <= 1e-15  # the rod's length, the line y = offset
    assert abs(a - complex(math.cos(1.2), math.sin(1.2))) <= 1e-15  # the crank at theta0
    u = (b - a) / abs(b - a)
    assert abs(complex(*mech.points["P"].at) - (a + u * complex(1.0, 0.5))) <= 1e-14
    assert abs(complex(*mech.masses["l3"].com) - (a + u * 1.5)) <= 1e-14
    data["points"]["A"] = data["points"].pop("P")  # a point named like a joint without coordinates
    with pytest.raises(vloop.MechanismError, match="duplicate name: 'A' is also a joint"):
        vloop.from_dict(data)


# ---------------------------------------------------------------- a Newton block: the assembly nearest the hints

S3 = MECHANISMS / "sixbar_stephenson3_output_driven.toml"


@functools.cache
def _stephenson_assemblies() -> list[dict[str, complex]]:
    """Every t = 0 assembly of the output-driven Stephenson III, enumerated by hand: D is fixed by the output rocker;
    for the crank angle θ2 over a turn, A = O2 + a·e^{jθ2}, B the dyad A–B–O4 on either side (two circles), C on the
    coupler (C − A = ρ·(B − A), ρ read from the drawing); the roots of |C − D| − l5 (sign changes on 20,000 angles,
    then brentq) are the assemblies."""
    from scipy.optimize import brentq

    m = vloop.load(S3)
    p = {j: complex(*xy) for j, xy in m.joints.items()}
    a, b, c, l5 = abs(p["A"] - p["O2"]), abs(p["B"] - p["A"]), abs(p["B"] - p["O4"]), abs(p["D"] - p["C"])
    rho = (p["C"] - p["A"]) / (p["B"] - p["A"])

    def joints(th: float, side: float) -> dict[str, complex] | None:
        A = p["O2"] + a * cmath.exp(1j * th)
        d = abs(p["O4"] - A)
        x = (b * b - c * c + d * d) / (2 * d)
        if b * b - x * x < 0:
            return None
        u = (p["O4"] - A) / d
        B = A + u * (x + side * 1j * math.sqrt(b * b - x * x))
        return {"A": A, "B": B, "C": A + rho * (B - A)}

    def f(th: float, side: float) -> float:
        j = joints(th, side)
        return math.nan if j is None else abs(j["C"] - p["D"]) - l5

    out = []
    grid = np.linspace(-math.pi, math.pi, 20_001)
    for side in (1.0, -1.0):
        vals = [f(t, side) for t in grid]
        for t0, t1, f0, f1 in zip(grid, grid[1:], vals, vals[1:], strict=False):
            if math.isfinite(f0) and math.isfinite(f1) and f0 * f1 < 0:
                out.append(joints(brentq(f, t0, t1, args=(side,), xtol=1e-15), side))
    return out


def _hinted(seed: int, spread: float) -> dict:
    global HINT
    old, HINT = HINT, spread
    try:
        return dimensions_only(S3, np.random.default_rng(seed))
    finally:
        HINT = old


def _check_nearest(data: dict, by_hand: list[dict[str, complex]]) -> str:
    """'accepted' (the assembly taken is the hand enumeration's nearest) or 'refused' (a near tie by the hand's count)."""
    import tomli_w

    hints = {j: complex(*data["joints"][j]) for j in ("A", "B", "C")}
    dist = sorted((math.sqrt(sum(abs(s[j] - hints[j]) ** 2 for j in hints)), i) for i, s in enumerate(by_hand))
    ratio = dist[1][0] / dist[0][0]
    try:
        closed, report = assemble_mechanism(read_only(tomli_w.dumps(data), source="s3"))
    except vloop.MechanismError as exc:
        assert ratio < 1.5 + 1e-9 and "less than 1.5 times as far" in str(exc), (ratio, str(exc))
        return "refused"
    assert ratio >= 1.5 - 1e-9, ratio
    nearest = by_hand[dist[0][1]]
    assert max(abs(complex(*closed.joints[j]) - nearest[j]) for j in nearest) <= 1e-9 * closed.scale
    line = report.lines(closed.units)[0]
    assert line.startswith(f"loops 1 (O2–A–B–O4) and 2 (O2–A–C–D–O6): assembly 1 of {len(by_hand)} found")
    assert f"nearest the coordinates: {dist[0][0]:.3g} m against {dist[1][0]:.3g}" in line
    return "accepted"


@pytest.mark.parametrize(("spread", "seeds"), [(0.1, range(2)), (0.2, range(2))])
def test_a_newton_block_takes_the_assembly_nearest_the_hints(spread: float, seeds: range) -> None:
    """Hints off by up to ±10 % and ±20 %: every assembly accepted is the nearest of all (hand enumeration above:
    2 assemblies), every refusal a near tie (the next nearest less than 1.5 times as far)."""
    by_hand = _stephenson_assemblies()
    assert len(by_hand) == 2
    drawn = vloop.load(S3).joints
    assert min(max(abs(s[j] - complex(*drawn[j])) for j in s) for s in by_hand) <= 1e-12 * 10  # the drawn one
    for seed in seeds:
        _check_nearest(_hinted(seed, spread), by_hand)


@pytest.mark.slow
def test_a_newton_block_over_many_draws() -> None:
    by_hand = _stephenson_assemblies()
    for spread in (0.1, 0.2):
        verdicts = [_check_nearest(_hinted(seed, spread), by_hand) for seed in range(20)]
        print(f"±{spread:.0%}: {verdicts.count('accepted')} accepted, {verdicts.count('refused')} refused of 20")


def test_hints_half_way_between_two_assemblies_are_refused() -> None:
    by_hand = _stephenson_assemblies()
    data = _hinted(0, 0.0)
    for j in ("A", "B", "C"):
        mid = (by_hand[0][j] + by_hand[1][j]) / 2
        data["joints"][j] = [mid.real, mid.imag]
    assert _check_nearest(data, by_hand) == "refused"
