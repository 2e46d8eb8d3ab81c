"""Hostile values at every argument of every synthesis function, at vloop synth's file and its --out, and at the
export, study and assemble front doors: one VloopError (the CLI: exit 2, one line on stderr) naming the argument,
no traceback, no NaN presented as a result, nothing written outside the output folder.

Each property replaces one argument of a call that works (fast settings) by a hostile value — huge, tiny,
non-finite, of the wrong type, a negative or huge count, a path escape, control characters — and asserts the
rule; a value that happens to be acceptable must then give a result whose figures are finite or named.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

import vloop
import vloop.synthesis as syn
from vloop.cli import main
from vloop.errors import VloopError

from .test_synthesis import LOG_SPEC, MOTION_POSES, MOTION_SPEC, PATH_POINTS

HOSTILE = [
    math.nan, math.inf, -math.inf, 1e300, -1e300, 5e-324, 0, -1, -5, 2.5, 10**9, 10**400, "a", "", "\x07\x1b[2J",
    "\ufffe", "../../escaped", "/etc/passwd", None, True, [], [[1, 2]], [1, "a"], {"a": 1}, ("a", "b"),
    [[0, 0, 0], [0, 0, 0.3], [0, 0, 0.8]], [[1e300, 0], [0, 1e300], [1, 1]], [math.nan, 1.0],
]  # fmt: skip
PROPERTY = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])

FUNCTION = {"f": "log10(x)", "x_range": (1.0, 2.0), "input_range": (0.5236, 2.0944), "output_range": (4.1888, 5.7596),
            "points": 3, "spacing": "chebyshev", "linkage": "fourbar", "ground": 1.0, "samples": 21,
            "name": "gen", "units": "mm"}  # fmt: skip
MOTION = {"poses": MOTION_POSES, "dyads": [{"fixed": (0.0, 0.0)}, {"fixed": (1.3, 0.0)}], "grid": 4, "count": 2,
          "name": "guide", "units": "m"}  # fmt: skip
PATH = {"points": PATH_POINTS, "linkage": "fourbar", "tolerance": 0.5, "count": 1, "seed": 0, "population": 5,
        "generations": 1, "samples": 16, "restarts": 1, "region": 1.5, "name": "trace", "units": "m"}  # fmt: skip
# arguments whose hostile value leaves the call valid but asks it to do other work than the fast one
EXTRA = {"function": ("precision", "pairs", "y_range", "requirements"), "motion": ("region", "requirements"),
         "path": ("timing", "requirements")}  # fmt: skip


def _one_line_naming(exc: VloopError, argument: str) -> None:
    text = str(exc)
    assert "\n" not in text and "Traceback" not in text
    names = {argument, argument.split(".")[0], {"f": "function"}.get(argument, argument)}
    assert any(n in text for n in names) or "[function.expression]" in text, (argument, text)


def _finite_or_named(result: syn.Candidates) -> None:
    """A result: every figure presented is finite, or its absence is named (a defect, a position not reached)."""
    for c in result:
        assert math.isfinite(c.error) or c.defects, (c.name, c.error)
        if c.structural_error is not None:
            assert math.isfinite(c.structural_error) or c.defects
    table = result.table()
    assert not table["error"].isin([math.inf, -math.inf]).any()


def _call(fn, base: dict, argument: str, value) -> None:
    kwargs = dict(base)
    kwargs[argument] = value
    try:
        result = fn(**kwargs)
    except VloopError as exc:
        _one_line_naming(exc, argument)
        return
    _finite_or_named(result)


@PROPERTY
@given(argument=st.sampled_from([*FUNCTION, *EXTRA["function"]]), value=st.sampled_from(HOSTILE))
def test_function_generation_arguments(argument, value):
    f = FUNCTION["f"]
    _call(lambda **kw: syn.function(kw.pop("f", f), **kw), FUNCTION, argument, value)


@PROPERTY
@given(argument=st.sampled_from([*MOTION, *EXTRA["motion"]]), value=st.sampled_from(HOSTILE))
def test_motion_generation_arguments(argument, value):
    _call(syn.motion, MOTION, argument, value)


@PROPERTY
@given(argument=st.sampled_from([*PATH, *EXTRA["path"]]), value=st.sampled_from(HOSTILE))
def test_path_generation_arguments(argument, value):
    _call(syn.path, PATH, argument, value)


@pytest.mark.parametrize("value", [None, 5, "a", {"pivots": 1}])
def test_requirements_must_be_requirements(value):
    if value is None:
        assert syn.function(**{k: v for k, v in FUNCTION.items()}, requirements=None)
        return
    with pytest.raises(VloopError, match=r"^requirements: must be a vloop\.synthesis\.Requirements"):
        syn.function(**FUNCTION, requirements=value)


@pytest.mark.parametrize(
    ("field", "value"),
    [("pivots", (0, 0, -1, 1)), ("pivots", (math.nan, 0, 1, 1)), ("links", (1, 0.5)), ("links", (0, 1)),
     ("min_transmission", math.nan), ("min_transmission", 2.0)],
)  # fmt: skip
def test_bad_requirements_name_their_field(field, value):
    with pytest.raises(VloopError, match=f"^requirements.{field}: must be"):
        syn.motion(**MOTION, requirements=syn.Requirements(**{field: value}))


@pytest.fixture(scope="module")
def small_result():
    return syn.function(**FUNCTION)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(name=st.sampled_from(["../../escaped", "a/b", "..", ".", "", "x\x00y", "\x07", "/abs", "ok-name"]),
       files=st.sampled_from([0, 1, -1, 101, 2.5, "1", None, True]))  # fmt: skip
def test_write_stays_inside_its_folder(tmp_path, small_result, name, files):
    """syn.write with a candidate renamed by hand and hostile counts: a VloopError naming the argument, or the
    files inside the folder only — nothing anywhere else under tmp_path."""
    import copy

    res = copy.deepcopy(small_result)
    res.items[0].name = name
    import tempfile

    box = Path(tempfile.mkdtemp(dir=tmp_path))
    (box / "a" / "b").mkdir(parents=True)
    before = set(Path(tmp_path).rglob("*"))
    try:
        syn.write(res, box / "a" / "b" / "out", files=files, plot=False)
    except VloopError as exc:
        assert "\n" not in str(exc) and ("files" in str(exc) or "name" in str(exc))
    after = set(Path(tmp_path).rglob("*")) - before
    assert all(str(p).startswith(str(box / "a" / "b" / "out")) for p in after), after


def test_the_escape_from_the_issue_is_refused_by_the_function(tmp_path):
    """name="../../escaped" (the functions build NAME_1.toml from it): refused before any work."""
    with pytest.raises(VloopError, match=r"^name: name .\.\./\.\./escaped. may use only"):
        syn.function(**{**FUNCTION, "name": "../../escaped"})


# ---------------------------------------------------------------- vloop synth: the file and --out

SPECS = {"function": LOG_SPEC, "motion": MOTION_SPEC}
KEYS = {
    "function": ["expression", "x", "input", "output", "points", "samples", "ground", "spacing", "precision", "y"],
    "motion": ["poses", "grid", "region"],
    "synthesis": ["name", "units", "title", "seed", "candidates", "files", "min_transmission_angle", "pivots", "links"],
}  # fmt: skip
TOML_VALUES = ["nan", "inf", "-inf", "1e300", "-1e300", "5e-324", "0", "-5", "10000000000", '"a"', '""',
               '"\\u0007\\u001b"', '"../../x"', "true", "[]", "[[1, 2]]", '[1, "a"]', "{a = 1}",
               '"1/(x-1.4995)"', '"tan(x)"', '"1e-13*x**2"']  # fmt: skip


def _spec_with(method: str, section: str, key: str, value: str) -> str:
    """The spec with ``key`` (in [section], or at top level) set to ``value`` (TOML text)."""
    lines = [ln for ln in SPECS[method].strip().splitlines() if not ln.startswith(f"{key} =")]
    if section == "synthesis":
        return f"{key} = {value}\n" + "\n".join(lines) + "\n"
    at = lines.index(f"[{method}]")
    lines.insert(at + 1, f"{key} = {value}")
    return "\n".join(lines) + "\n"


@settings(max_examples=50, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    where=st.sampled_from([("function", "function"), ("motion", "motion"), ("function", "synthesis")]),
    data=st.data(),
    value=st.sampled_from(TOML_VALUES),
)
def test_synth_file_keys(tmp_path, capfd, where, data, value):
    """vloop synth on a file with one hostile value: exit 0 (an acceptable value, no "nan" printed) or 2 with one
    line naming the file and the key, no traceback; nothing written outside --out."""
    method, section = where
    key = data.draw(st.sampled_from(KEYS[section]))
    import tempfile

    box = Path(tempfile.mkdtemp(dir=tmp_path))
    spec = box / "s.toml"
    spec.write_text(_spec_with(method, section, key, value), encoding="utf-8")
    code = main(["synth", str(spec), "--out", str(box / "out")])
    out, err = capfd.readouterr()
    assert "Traceback" not in err and "Traceback" not in out
    if code == 0:
        assert "nan" not in out.replace("nano", "")
    else:
        assert code == 2 and len(err.strip().splitlines()) == 1, err
        assert str(spec) in err and (key in err or "expression" in err), err
    assert {p.name for p in box.iterdir()} <= {"s.toml", "out"}


@pytest.mark.parametrize("out", ["FILE", "FILE/sub", "\x07bell", "a\x00b", "", " ", "x" * 5000])
@pytest.mark.parametrize("command", ["synth", "export", "assemble", "study", "run", "view", "simulate"])
def test_every_commands_out_is_checked_before_the_work(tmp_path, capfd, monkeypatch, command, out):
    """--out naming an existing file, a path through a file, control characters, NUL, empty or a name too long:
    exit 2 and one line, or (control characters are a legal name) the outputs inside that folder."""
    from .conftest import MECHANISMS

    (tmp_path / "FILE").write_text("x", encoding="utf-8")
    monkeypatch.chdir(tmp_path)  # a relative --out lands here, and the next test starts where it started
    spec = tmp_path / "s.toml"
    spec.write_text(LOG_SPEC, encoding="utf-8")
    plain, dims = MECHANISMS / "fourbar_textbook_example.toml", MECHANISMS / "sixbar_watt2_dimensions.toml"
    args = {
        "synth": ["synth", str(spec)],
        "export": ["export", str(plain), "--at", "0"],
        "assemble": ["assemble", str(dims)],
        "study": ["study", str(tmp_path / "missing.toml")],
        "run": ["run", str(plain)],
        "view": ["view", str(plain)],
        "simulate": ["simulate", str(MECHANISMS / "fourbar_textbook_dynamics.toml")],
    }[command]
    code = main([*args, "--out", out])
    _, err = capfd.readouterr()
    assert "Traceback" not in err
    if command == "assemble" and out == "FILE":  # --out is the file to write: an existing one is replaced
        assert code == 0 and "assembled at t = 0" in (tmp_path / "FILE").read_text(encoding="utf-8")
        return
    if out in ("FILE", "FILE/sub", "a\x00b", "", " ", "x" * 5000):
        assert code == 2 and len(err.strip().splitlines()) == 1 and "--out" in err, err
    written = {p for p in tmp_path.rglob("*")} - {tmp_path / "FILE", spec}
    assert all(str(p).startswith(str(tmp_path / out)) for p in written) or code == 2, written


def test_no_nan_in_a_written_table(tmp_path):
    """A five-pose synthesis with an order and a branch defect: candidates.csv has empty cells where a position
    was not reached, never the text nan."""
    from .test_synthesis import poses

    coords = {"O2": 0j, "A": 0.3 + 0.4j, "B": 1.2 + 1.1j, "O4": 1.3 + 0j, "P": 0.5 + 1.0j}
    res = syn.motion(poses(coords, np.array([0.0, 2.0, 1.0, 3.0, 4.0])))
    syn.write(res, tmp_path / "o")
    text = (tmp_path / "o" / "candidates.csv").read_text(encoding="utf-8").lower()
    assert "nan" not in text and "inf" not in text


# ---------------------------------------------------------------- messages that name the right thing

FUNCTION_FILE = 'method = "function"\n[function]\nexpression = "{e}"\nx = [{x0}, {x1}]\ninput = [0.5236, 2.0944]\n' \
    "output = [4.1888, 5.7596]\n{extra}\n"  # fmt: skip


@pytest.mark.parametrize(
    ("expression", "x0", "x1", "extra", "says"),
    [
        ("1/(x-1.4995)", 1, 2, "", "[function] 'expression': f(x) = '1/(x-1.4995)' is not defined or not bounded "
         "over x in [1, 2]: a denominator is zero (a pole) at x = 1.4995"),
        ("tan(x)", 1, 2, "", "tan's argument is an odd multiple of π/2 (a pole) at x = 1.570796"),
        ("log(x - 1)", 0.5, 2, "", "log of a number ≤ 0 at x = 0.5"),
        ("sqrt(x - 1.5)", 1, 2, "", "square root of a negative number at x = 1"),
        ("1/(x-1.5)**2", 1, 2, "", "a denominator is zero (a pole) at x = 1.5"),
        ("log10(x)", 1, 2, "ground = 1e300", "[function] 'ground' must be a length from 1e-50 to 1e+50, got 1e+300"),
        ("log10(x)", 1, 2, "samples = 0", "[function] 'samples' must be an integer from 2 to 100,000, got 0"),
    ],
)  # fmt: skip
def test_function_file_messages(tmp_path, capfd, expression, x0, x1, extra, says):
    """Poles and domains found from the expression (not from samples: 1.4995 lies between the 1,001 samples the
    range was once checked at), and out-of-range keys: exit 2, one line naming the file and the key."""
    spec = tmp_path / "f.toml"
    spec.write_text(FUNCTION_FILE.format(e=expression, x0=x0, x1=x1, extra=extra), encoding="utf-8")
    assert main(["synth", str(spec), "--out", str(tmp_path / "o")]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"vloop: error: {spec}: ") and says in err[0], err
    assert not (tmp_path / "o").exists()


def test_a_tiny_function_is_not_constant(tmp_path, capfd):
    """1e-13·x² over [1, 2]: values 1e-13 to 4e-13, not "the same value at both ends" (a relative test)."""
    spec = tmp_path / "f.toml"
    spec.write_text(FUNCTION_FILE.format(e="1e-13*x**2", x0=1, x1=2, extra=""), encoding="utf-8")
    assert main(["synth", str(spec), "--out", str(tmp_path / "o")]) == 0
    assert "1 solutions" not in capfd.readouterr().out


def test_a_path_scaled_to_1e300_names_the_key(tmp_path, capfd):
    spec = tmp_path / "p.toml"
    big = [[x * 1e300, y * 1e300] for x, y in PATH_POINTS]
    spec.write_text(f'method = "path"\n[path]\npoints = {big}\n', encoding="utf-8")
    assert main(["synth", str(spec), "--out", str(tmp_path / "o")]) == 2
    err = capfd.readouterr().err
    assert f"{spec}: [path] 'points' must be a list of 1 to 10000 [x, y] rows (x within ±1e+50" in err


def test_poses_turning_about_one_point(tmp_path, capfd):
    """poses = [[0,0,0],[0,0,0.3],[0,0,0.8]], no dyads: every pole P1k is the origin (z = D_k(z) at z = 0)."""
    spec = tmp_path / "m.toml"
    spec.write_text('method = "motion"\n[motion]\nposes = [[0,0,0],[0,0,0.3],[0,0,0.8]]\n', encoding="utf-8")
    assert main(["synth", str(spec), "--out", str(tmp_path / "o")]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "the poses all turn about one point (0, 0)" in err[0] and str(spec) in err[0]


@pytest.mark.parametrize("value", [None, 5, "", " ", "a\x00b", "/nonexistent.toml", "/etc", "x" * 5000, ["a"]])
def test_load_and_run_take_only_what_they_read(value):
    """syn.load of a hostile path, syn.run of something not a SynthSpec: one VloopError, one line."""
    with pytest.raises(VloopError) as info:
        syn.load(value)
    assert "\n" not in str(info.value)
    with pytest.raises(VloopError, match=r"^spec: must be a SynthSpec"):
        syn.run(value)


# ---------------------------------------------------------------- export, assemble and study from Python


@pytest.fixture(scope="module")
def textbook():
    from .conftest import MECHANISMS

    return vloop.load(MECHANISMS / "fourbar_textbook_example.toml")


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(argument=st.sampled_from(["mech", "folder", "at", "fmt"]), value=st.sampled_from(HOSTILE))
def test_export_arguments(tmp_path, monkeypatch, textbook, argument, value):
    """vloop.views.export.export with one hostile argument: a VloopError naming it, or a file in the folder."""
    from vloop.views.export import export

    monkeypatch.chdir(tmp_path)
    kwargs = {"mech": textbook, "folder": str(tmp_path / "out"), "at": 0.0, "fmt": "svg", argument: value}
    try:
        path = export(**kwargs)
    except VloopError as exc:
        assert "\n" not in str(exc)
        return
    assert Path(path).resolve().is_relative_to(Path(kwargs["folder"]).resolve())


@pytest.mark.parametrize("value", HOSTILE[:12])
def test_assemble_takes_a_mechanism(value):
    from vloop.authoring import assemble_mechanism

    with pytest.raises(VloopError, match=r"^mech: must be a Mechanism"):
        assemble_mechanism(value)


@settings(max_examples=40, deadline=None)
@given(
    argument=st.sampled_from(["times", "samples", "seed", "sensitivity", "chunk", "workers", "memory_budget"]),
    value=st.sampled_from(HOSTILE),
)
@example(argument="times", value=10**400)  # too large for a float: once an OverflowError out of numpy
def test_study_arguments(argument, value):
    """vloop.study with one hostile keyword: a VloopError in one line, or a result with no NaN in its table."""
    from .conftest import MECHANISMS

    kwargs = {"params": [{"name": "links.l2.length", "values": [1.0]}], "outputs": ["l3.theta"], "progress": False}
    try:
        res = vloop.study(MECHANISMS / "fourbar_textbook_example.toml", **kwargs, **{argument: value})
    except VloopError as exc:
        assert "\n" not in str(exc)
        return
    assert res.counts["variants"] >= 1
