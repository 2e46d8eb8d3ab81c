"""Hostile numbers at every key of a file written from dimensions, through `vloop assemble` and `vloop run`.

The files: the Watt II of mechanisms/sixbar_watt2_dimensions.toml with hints for B and D (a ternary by two sides
and an angle, named branches), and the offset and inverted slider-cranks rewritten from their dimensions by
tests/test_authoring.py (slider offsets, a slider angle on a moving guide, rough hints; the offset one also driven
by its slider, s0 = 5 m). Each example puts one value
— 0, -0, ±1e308, 5e-324, nan, ±inf, 10**400, a string, a nested array — at one key (every number and every
coordinate pair of the file) and asserts the rule of the house: exit 0 with finite output, or exit 2 with one line
on stderr naming the file and the key (or the joint), no traceback, nothing written. A value that is hostile
wherever it stands (not a finite number, or beyond every length and angle the solver takes) must be refused by
its key on the dimension-first path (coordinates, hints, lengths, sides, angles, offsets, the input at t = 0).

The size a hint or a length is measured against comes from the dimensions and the ground pivots only
(vloop.files.dimensions.dimension_size): a hint at 1e300 is refused as a hint, by its joint, not reported as
every link having zero length.
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import subprocess
import sys
import tempfile
import tomllib
from pathlib import Path

import numpy as np
import pytest
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import vloop
from vloop.cli import main

from .conftest import MECHANISMS
from .test_authoring import dimensions_only
from .test_hostile import finite_csv

ROOT = Path(__file__).resolve().parents[1]
PLAUSIBLE = [0, -0.0, 5e-324]  # a valid number: it may describe a mechanism, or one that cannot close
HOSTILE = [*PLAUSIBLE, 1e308, -1e308, math.nan, math.inf, -math.inf, 10**400, "a", [[1.0, 2.0]]]
DIMENSION_PATH = ("joints", "links", "sliders", "points")  # and the input at t = 0 (theta0, s0)


def _files() -> dict[str, dict]:
    watt = tomllib.loads((MECHANISMS / "sixbar_watt2_dimensions.toml").read_text(encoding="utf-8"))
    drawn = tomllib.loads((MECHANISMS / "sixbar_watt2.toml").read_text(encoding="utf-8"))["joints"]
    watt["joints"].update({j: drawn[j] for j in ("B", "D")})  # hints where the coordinates draw them
    files = {"watt": watt}
    for stem in ("slider_crank_offset", "inverted_slider_crank"):
        files[stem] = dimensions_only(MECHANISMS / f"{stem}.toml", np.random.default_rng(1))
    files["actuated"] = copy.deepcopy(files["slider_crank_offset"])
    files["actuated"]["drivers"] = [{"slider": "l4", "s0": 5.0, "v": 0.1, "a": 0.0}]  # the input at t = 0 a length
    for data in files.values():
        data["time"] = {"start": 0.0, "stop": 0.1, "step": 0.05}  # three samples: the rule, not the motion
    return files


def _keys(node, at: tuple = ()):
    """Every number of the file and every list of numbers (a coordinate pair, sides), as a path."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _keys(v, (*at, k))
    elif isinstance(node, list):
        if node and all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in node):
            yield at
        for i, v in enumerate(node):
            yield from _keys(v, (*at, i))
    elif isinstance(node, (int, float)) and not isinstance(node, bool):
        yield at


FILES = _files()
CASES = [(name, path) for name, data in FILES.items() for path in _keys(data)]


def _put(data: dict, path: tuple, value) -> dict:
    out = copy.deepcopy(data)
    node = out
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return out


def _cli(*args) -> tuple[int, str]:
    """``vloop ARGS`` in this process (what ``python -m vloop.cli`` runs): (exit code, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, err.getvalue()


def _entry(path: tuple) -> str:
    """How a message names the key: ``[joints.B``, ``[links.l4``, ``[drivers[0]``, ``[time``."""
    if path[0] in DIMENSION_PATH:
        return f"[{path[0]}.{path[1]}"
    return f"[drivers[{path[1]}]" if path[0] == "drivers" else f"[{path[0]}"


def _on_dimension_path(path: tuple) -> bool:
    return path[0] in DIMENSION_PATH or (path[0] == "drivers" and path[2] in ("theta0", "s0"))


def _check(name: str, path: tuple, value, command: str) -> None:
    with tempfile.TemporaryDirectory() as tmp:
        f = Path(tmp) / f"{name}.toml"
        f.write_text(tomli_w.dumps(_put(FILES[name], path, value)), encoding="utf-8")
        target = Path(tmp) / ("fixed.toml" if command == "assemble" else "out")
        code, err = _cli(command, f, "--out", target)
        where = (name, path, value, command, err)
        assert "Traceback" not in err and code in (0, 2), where
        direction = "axis" in path and isinstance(value, float) and math.isfinite(value)  # normalised, not a length
        if value not in PLAUSIBLE and not direction and (_on_dimension_path(path) or not isinstance(value, float)):
            assert code == 2, where  # hostile wherever it stands: refused by its key as the file is read
            assert _entry(path) in err or (path[0] == "joints" and f" {path[1]} " in err), where
        if code == 0:
            assert "Warning" not in err, where
            if command == "assemble":
                joints = tomllib.loads(target.read_text(encoding="utf-8"))["joints"]
                assert all(math.isfinite(c) for xy in joints.values() for c in xy), where
            else:
                finite_csv(target / "results.csv")
            return
        line = err.strip()
        assert "\n" not in line and line.startswith("vloop: error: "), where
        if str(f) in line:  # refused as the file is read: nothing written
            assert not target.exists() or not any(target.iterdir()), where
        else:  # stopped while moving (a rate overflowing): named by the mechanism, the work done kept and finite
            assert f"{FILES[name].get('name', name)}:" in line and command == "run", where
            if (target / "results.csv").exists():
                finite_csv(target / "results.csv")


@settings(max_examples=60, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
@given(case=st.sampled_from(CASES), value=st.sampled_from(HOSTILE), command=st.sampled_from(["assemble", "run"]))
def test_hostile_values_at_every_key_of_a_file_written_from_dimensions(case, value, command):
    _check(*case, value, command)


@pytest.mark.slow
@pytest.mark.parametrize("command", ["assemble", "run"])
def test_every_hostile_value_at_every_key(command):
    """The property above over all its cases (93 keys × 11 values)."""
    for name, path in CASES:
        for value in HOSTILE:
            _check(name, path, value, command)


def test_the_keys_cover_every_kind_of_dimension():
    """The sampled keys hold a ground pivot, a hint, a length, a ternary's sides and angle, a slider's offset and
    its angle on a moving guide, and the input at t = 0."""
    flat = {(p[0], p[-1] if len(p) > 2 else None) for _, p in CASES}
    hints = {p[1] for n, p in CASES if p[0] == "joints" and p[1] not in ("O2", "O4", "O6")}
    assert {"B", "D", "A"} <= hints
    assert {("links", "length"), ("links", "angle"), ("sliders", "offset"), ("sliders", "angle")} <= flat
    assert (
        ("drivers", "theta0") in flat
        and ("drivers", "s0") in flat
        and any(p[:3] == ("links", "l4", "sides") for _, p in CASES)
    )


def _hint_file(tmp: Path) -> Path:
    data = _put(FILES["watt"], ("joints", "B"), [1e300, 0.0])
    f = tmp / "hint.toml"
    f.write_text(tomli_w.dumps(data), encoding="utf-8")
    return f


def test_a_hint_at_1e300_is_refused_as_a_hint_by_python_m_vloop_cli(tmp_path):
    """The real entry point (a process of its own), both commands: one line naming the file, the joint and the
    factor; not "every link has zero length … O2 and O4 coincide"; nothing written."""
    f = _hint_file(tmp_path)
    for command, out in (("assemble", tmp_path / "fixed.toml"), ("run", tmp_path / "out")):
        proc = subprocess.run(
            [sys.executable, "-m", "vloop.cli", command, str(f), "--out", str(out)],
            capture_output=True, text=True, cwd=tmp_path, timeout=120,
        )  # fmt: skip
        assert proc.returncode == 2 and "Traceback" not in proc.stderr
        line = proc.stderr.strip()
        assert "\n" not in line and not out.exists()
        size = math.dist((0.0, 0.0), (12.0, -4.0))  # the pivots O2 and O6 of the file: the Watt II's largest span
        assert line == (
            f"vloop: error: {f}: [joints.B] hint (1e+300, 0) is {1e300 / size:.3g} times the mechanism's size "
            f"({size:.6g} m, the distance of its ground pivots O2 and O6) from the ground pivot O2: at most 1e+05 "
            "times (a typing error?)"
        )
        assert "zero-length" not in line and "coincide" not in line


def test_a_far_but_sane_hint_still_assembles_the_named_branches(tmp_path):
    """A hint 1e4 times the size away (inside the factor 1e5) is only a hint: the named branches assemble the same
    joints as the file without it (the size, and with it every tolerance of the check, ignores hints)."""
    near = vloop.load(MECHANISMS / "sixbar_watt2_dimensions.toml")
    data = _put(FILES["watt"], ("joints", "B"), [1.2e5, 0.0])
    far = vloop.from_dict(data, source="far.toml")
    for j, xy in near.joints.items():
        assert math.dist(xy, far.joints[j]) <= 1e-12 * 12.65, j


def test_a_length_far_from_the_rest_is_named_by_its_key():
    """One length 1e6 times the others and the pivots' span: refused by that link, not as the others' zero length."""
    data = _put(FILES["watt"], ("links", "l3", "length"), 6e6 * 12.65)
    try:
        vloop.from_dict(data, source="long.toml")
    except vloop.MechanismError as exc:
        text = str(exc)
    else:
        raise AssertionError("a length 6e6 sizes long was accepted")
    assert text.startswith("long.toml: [links.l3] 'length' = 7.59e+07 is 6e+06 times the rest of the mechanism's")
    assert "zero" not in text and "[links.l2]" not in text


def test_a_far_hint_loosens_no_tolerance_of_the_assembly():
    """The eight-bar from its dimensions with the hint of A 1.7e4 times its size away (inside the factor): the same
    joints as with its rough hints, to 1e-12 of the size. The assembly's tolerances are taken of a size its hints
    cannot stretch (Mechanism.reach): with the hints' own span (1.7e4 times too large) its crank's dyad read as a
    toggle ("condition number 5.13e+04") and the file was refused."""
    path = MECHANISMS / "eightbar.toml"
    data = dimensions_only(path, np.random.default_rng(3))
    near = vloop.from_dict(data, source=str(path), base_dir=path.parent)
    size = near.scale
    data["joints"]["A"] = [5e4 / 3 * size, 0.0]
    far = vloop.from_dict(data, source=str(path), base_dir=path.parent)
    assert far.reach is None and far.scale == size  # assembled: its own joints' size again
    for j, xy in near.joints.items():
        assert math.dist(xy, far.joints[j]) <= 1e-12 * size, j
