"""Bad input (issue: core, item 3): one clear line naming the entry, exit code 2, no traceback."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import vloop
from vloop.cli import main

FOURBAR = """
name = "fb"
[joints]
O2 = [0.0, 0.0]
A = [0.0, 2.0]
B = [5.0, 4.0]
O4 = [7.0, 0.0]
[links]
ground = { joints = ["O2", "O4"], ground = true }
crank = { joints = ["O2", "A"] }
coupler = { joints = ["A", "B"] }
rocker = { joints = ["O4", "B"] }
[[drivers]]
link = "crank"
pivot = "O2"
omega = 1.0
[time]
start = 0.0
stop = 1.0
step = 0.1
"""


def edit(old: str, new: str, text: str = FOURBAR) -> str:
    assert old in text, old
    return text.replace(old, new)


CASES = {
    "toml_syntax": (
        edit('crank = { joints = ["O2", "A"] }', 'crank = { joints = ["O2", "A" }'),
        ["TOML syntax error", "line 10"],
    ),
    "unknown_joint": (
        edit('coupler = { joints = ["A", "B"] }', 'coupler = { joints = ["A", "Q"] }'),
        ["[links.coupler]", "unknown joint 'Q'"],
    ),
    "unknown_link_in_driver": (edit('link = "crank"', 'link = "krank"'), ["drivers[0]", "unknown link 'krank'"]),
    "unknown_guide": (
        FOURBAR + '[sliders]\nS = { joint = "B", guide = "nowhere", axis = [1.0, 0.0] }\n',
        ["[sliders.S]", "unknown guide"],
    ),
    "duplicate_key": (
        edit(
            'rocker = { joints = ["O4", "B"] }', 'rocker = { joints = ["O4", "B"] }\nrocker = { joints = ["O4", "B"] }'
        ),
        ["TOML syntax error"],
    ),
    "duplicate_point_name": (
        FOURBAR + '[points]\nA = { link = "coupler", at = [1.0, 1.0] }\n',
        ["[points.A]", "duplicate name"],
    ),
    "duplicate_slider_name": (
        FOURBAR + '[sliders]\nrocker = { joint = "B", guide = "ground", axis = [1.0, 0.0] }\n',
        ["[sliders.rocker]", "duplicate name"],
    ),
    "joint_twice_on_link": (
        edit('coupler = { joints = ["A", "B"] }', 'coupler = { joints = ["A", "B", "A"] }'),
        ["[links.coupler]", "names joint A twice"],
    ),
    "link_without_joints": (
        edit('coupler = { joints = ["A", "B"] }', "coupler = { joints = [] }"),
        ["[links.coupler]", "has no joints"],
    ),
    "zero_length_link": (edit("B = [5.0, 4.0]", "B = [0.0, 2.0]"), ["[links.coupler]", "coincide", "zero-length"]),
    "disconnected": (
        FOURBAR.replace("[[drivers]]", 'floating = { joints = ["P", "Q"] }\n[[drivers]]')
        .replace("[links]", "[links]")
        .replace("O4 = [7.0, 0.0]", "O4 = [7.0, 0.0]\nP = [10.0, 0.0]\nQ = [11.0, 0.0]"),
        ["disconnected", "floating"],
    ),
    "driver_on_ground": (edit('link = "crank"', 'link = "ground"'), ["drivers[0]", "is the ground"]),
    "driver_on_block": (
        FOURBAR.replace('rocker = { joints = ["O4", "B"] }', "")
        .replace("[[drivers]]", '[sliders]\nblk = { joint = "B", guide = "ground", axis = [1.0, 0.0] }\n[[drivers]]')
        .replace('link = "crank"', 'link = "blk"'),
        ["drivers[0]", "slider block", "cannot turn"],
    ),
    "pivot_not_first": (edit('pivot = "O2"', 'pivot = "A"'), ["drivers[0]", "must be the first joint"]),
    "mobility_too_high": (
        edit(
            'coupler = { joints = ["A", "B"] }',
            'coupler = { joints = ["A", "B"] }\nextra = { joints = ["B", "E"] }\nother = { joints = ["E", "O4"] }',
        )
        .replace("O4 = [7.0, 0.0]", "O4 = [7.0, 0.0]\nE = [7.0, 5.0]")
        .replace('rocker = { joints = ["O4", "B"] }', ""),
        ["mobility mismatch", "Gruebler", "= 2", "give exactly 2 drivers"],
    ),
    "mobility_too_low": (
        FOURBAR + '[[drivers]]\nlink = "rocker"\npivot = "O4"\nomega = 1.0\n',
        ["mobility mismatch", "Gruebler", "= 1", "2 drivers are given", "remove a driver"],
    ),
    "structure": (
        edit("[[drivers]]", 'brace = { joints = ["A", "O4"] }\n[[drivers]]'),
        ["mobility mismatch", "rigid structure"],
    ),
    "no_close_at_t0": (
        edit('coupler = { joints = ["A", "B"] }', 'coupler = { joints = ["A", "B"], length = 6.0 }'),
        ["[joints]", "do not close loop 1", "O2–A–B–O4", "off by"],
    ),
    "theta0_far_off": (
        edit("omega = 1.0", "omega = 1.0\ntheta0 = 0.0"),
        ["do not close loop 1", "theta0/s0 differ from the coordinates"],
    ),
    "non_finite_coordinate": (edit("B = [5.0, 4.0]", "B = [5.0, nan]"), ["[joints.B]", "non-finite"]),
    "non_finite_omega": (edit("omega = 1.0", "omega = inf"), ["drivers[0]", "'omega' is not finite"]),
    "zero_step": (edit("step = 0.1", "step = 0.0"), ["[time]", "step must be positive"]),
    "negative_step": (edit("step = 0.1", "step = -0.1"), ["[time]", "step must be positive"]),
    "absurd_step": (edit("step = 0.1", "step = 1e-9"), ["[time]", "more than the memory budget"]),
    "zero_axis": (
        FOURBAR.replace('rocker = { joints = ["O4", "B"] }', "").replace(
            "[[drivers]]", '[sliders]\nblk = { joint = "B", guide = "ground", axis = [0.0, 0.0] }\n[[drivers]]'
        ),
        ["[sliders.blk]", "axis has zero length"],
    ),
    "wrong_type": (edit("A = [0.0, 2.0]", 'A = "north"'), ["[joints.A]", "expected a pair of numbers"]),
    "missing_links": ("name = 'x'\n[joints]\nA = [0.0, 0.0]\n", ["[links]", "missing or empty"]),
    "typo_key": (edit("ground = true", "grund = true"), ["[links.ground]", "unknown key 'grund'"]),
    "floating_link": (
        edit(
            'coupler = { joints = ["A", "B"] }', 'coupler = { joints = ["A", "B"] }\ndangling = { joints = ["B", "E"] }'
        ).replace("O4 = [7.0, 0.0]", "O4 = [7.0, 0.0]\nE = [9.0, 9.0]"),
        ["mobility mismatch", "= 2"],
    ),
    "missing_drivers": (FOURBAR.split("[[drivers]]")[0] + "[time]\nstop = 1.0\nstep = 0.1\n", ["[drivers]", "missing"]),
    "missing_time": (FOURBAR.split("[time]")[0], ["[time]", "missing"]),
    "wrong_type_omega": (edit("omega = 1.0", 'omega = "fast"'), ["drivers[0]", "'omega' must be a number"]),
    "profile_both": (
        edit("omega = 1.0", "omega = 1.0\nprofile = { t = [0.0, 1.0], theta = [1.57, 1.6] }"),
        ["'omega' and 'profile' both given"],
    ),
    "profile_column_missing": (
        edit("omega = 1.0", "profile = { t = [0.0, 1.0], angle = [1.57, 1.6] }"),
        ["profile needs columns 't' and 'theta'"],
    ),
}

# an isosceles slider-crank (crank = rod = 1) reaches its change point at t = 1 s. Both the closed-form path
# (tests/test_change_points.py) and the Newton-only path asked for here (tests/test_chunks_and_budgets.py) continue through
# it on the smooth branch.
ISOSCELES = f"""
name = "isosceles"
[joints]
O2 = [0.0, 0.0]
A = [{math.cos(0.3)!r}, {math.sin(0.3)!r}]
B = [{2 * math.cos(0.3)!r}, 0.0]
[links]
ground = {{ joints = ["O2"], ground = true }}
crank = {{ joints = ["O2", "A"] }}
rod = {{ joints = ["A", "B"] }}
[sliders]
blk = {{ joint = "B", guide = "ground", axis = [1.0, 0.0] }}
[[drivers]]
link = "crank"
pivot = "O2"
omega = {math.pi / 2 - 0.3!r}
[time]
start = 0.0
stop = 2.0
step = 0.1
[solver]
method = "newton"
"""
# mid-run: a triple rocker whose crank cannot pass θ = 2.4294 rad (law of cosines), reached after sample 172
PAST_LIMIT = (Path(__file__).parents[1] / "mechanisms" / "fourbar_nongrashof_past_limit.toml").read_text()


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_cli(case, tmp_path, capsys):
    text, needles = CASES[case]
    f = tmp_path / "bad.toml"
    f.write_text(text)
    out = tmp_path / "out"
    code = main(["run", str(f), "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("vloop: error: ")
    for n in needles:
        assert n in lines[0], f"{n!r} not in {lines[0]!r}"
    assert not (out / "results.csv").exists()  # nothing solved, nothing written


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_api_raises_the_one_error_type(case, tmp_path):
    """The same catalogue through the Python API: a vloop.MechanismError naming its entry."""
    text, needles = CASES[case]
    f = tmp_path / "bad.toml"
    f.write_text(text)
    with pytest.raises(vloop.VloopError) as info:
        vloop.solve(vloop.load(f))
    assert isinstance(info.value, vloop.MechanismError)
    assert all(n in str(info.value) for n in needles)
    assert info.value.entry
    assert info.value.partial is None


@pytest.mark.parametrize(
    ("text", "sample", "why"),
    [(PAST_LIMIT, 173, "past a limit position")],
    ids=["limit"],
)
def test_mid_run_failures_keep_the_solved_rows(text, sample, why, tmp_path, capsys):
    f = tmp_path / "run.toml"
    f.write_text(text)
    with pytest.raises(vloop.MotionError) as info:
        vloop.solve(vloop.load(f))
    err = info.value
    assert err.sample == sample and why in str(err)
    assert err.time == pytest.approx(vloop.load(f).times[sample])
    assert len(err.partial) == sample and all(np.all(np.isfinite(v)) for v in err.partial.columns.values())
    code = main(["run", str(f), "--out", str(tmp_path / "o")])
    line = capsys.readouterr().err
    assert code == 2 and line.count("\n") == 1 and why in line and f"wrote {sample} rows" in line
    rows = np.loadtxt(tmp_path / "o" / "results.csv", delimiter=",", skiprows=1, ndmin=2)
    assert rows.shape[0] == sample and np.all(np.isfinite(rows))


def test_no_traceback_from_the_console_script(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text(CASES["unknown_joint"][0])
    proc = subprocess.run(
        [sys.executable, "-m", "vloop.cli", "run", str(f), "--out", str(tmp_path)], capture_output=True, text=True
    )
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert proc.stderr.count("\n") == 1
    assert "unknown joint 'Q'" in proc.stderr


def test_missing_file(tmp_path, capsys):
    assert main(["info", str(tmp_path / "nope.toml")]) == 2
    assert "cannot read file" in capsys.readouterr().err


def test_tabulated_profile_with_non_monotonic_time(tmp_path, capsys):
    (tmp_path / "p.csv").write_text("t,theta\n0,1.5708\n0.2,1.7\n0.1,1.8\n")
    f = tmp_path / "bad.toml"
    f.write_text(edit("omega = 1.0", 'profile = "p.csv"').replace("[time]\nstart = 0.0\nstop = 1.0\nstep = 0.1\n", ""))
    assert main(["run", str(f), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "not strictly increasing" in err and "row 3" in err


def test_good_file_loads(tmp_path):
    f = tmp_path / "ok.toml"
    f.write_text(FOURBAR)
    res = vloop.solve(vloop.load(f))
    assert len(res) == 11


if __name__ == "__main__":
    sys.exit(pytest.main([__file__]))
