"""The tutorials work as written, and the student's quotes numbers that are right.

docs/tutorials/student.md: its mechanism file, its commands and its Python run in a fresh folder against this
checkout; every figure of its table "vloop against the hand" is checked twice — the hand column against the
formulas it states, evaluated here independently of vloop (law of cosines, the velocity loop, the transmission
angle, the dead centres), and the vloop column against what the commands wrote and printed — each to the
half-unit of the last digit quoted. The other tutorials' commands run under ``-m slow`` (a synthesis, the
validators, a corpus).
"""

from __future__ import annotations

import math
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).parents[1]
TUTORIALS = ROOT / "docs" / "tutorials"


def _blocks(page: Path, lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```\n", page.read_text(encoding="utf-8"), re.S | re.M)


def _run(command: str, cwd: Path) -> subprocess.CompletedProcess:
    """One shell line of a tutorial: ``vloop …`` and ``python …`` run with this interpreter and this checkout."""
    words = shlex.split(command)
    exe = {"vloop": [sys.executable, "-m", "vloop.cli"], "python": [sys.executable]}[words[0]]
    env = {"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin", "HOME": str(cwd)}
    proc = subprocess.run([*exe, *words[1:]], cwd=cwd, env=env, capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0 and "Traceback" not in proc.stderr, f"{command}\n{proc.stdout}\n{proc.stderr}"
    return proc


def _commands(page: Path) -> list[str]:
    lines = [ln.strip() for b in _blocks(page, "sh") for ln in b.splitlines()]
    return [ln for ln in lines if ln and not ln.startswith("#")]


# ---------------------------------------------------------------- the student's four-bar, by hand

A, B, C, D = 30.0, 80.0, 60.0, 70.0  # crank, coupler, rocker, ground [mm] (the tutorial's file)
THETA2, OMEGA2 = math.radians(60.0), 10.0


def _hand() -> dict[str, float]:
    """The tutorial's section 3, formula by formula (degrees, mm, rad/s)."""
    zA = A * complex(math.cos(THETA2), math.sin(THETA2))
    delta = D - zA
    f = abs(delta)
    gamma = math.acos((B * B + f * f - C * C) / (2 * B * f))  # the angle at A, law of cosines
    th3 = math.atan2(delta.imag, delta.real) + gamma  # B above the diagonal A→O4
    zB = zA + B * complex(math.cos(th3), math.sin(th3))
    th4 = math.atan2(zB.imag, zB.real - D)
    w3 = A * OMEGA2 * math.sin(th4 - THETA2) / (B * math.sin(th3 - th4))
    w4 = A * OMEGA2 * math.sin(th3 - THETA2) / (C * math.sin(th3 - th4))
    mu = [math.degrees(math.acos((B * B + C * C - g * g) / (2 * B * C))) for g in (D - A, D + A)]
    dead = [180.0 - math.degrees(math.acos((D * D + C * C - r * r) / (2 * D * C))) for r in (B + A, B - A)]
    crank = []
    for th4_dead, folded in zip(dead, (False, True), strict=True):
        zb = D + C * complex(math.cos(math.radians(th4_dead)), math.sin(math.radians(th4_dead)))
        crank.append(math.degrees(math.atan2(zb.imag, zb.real)) + (180.0 if folded else 0.0))
    one_way = crank[1] - crank[0]
    return {
        "θ₃ at t = 0": math.degrees(th3),
        "θ₄ at t = 0": math.degrees(th4),
        "B at t = 0 (x)": zB.real,
        "B at t = 0 (y)": zB.imag,
        "ω₃ at t = 0": w3,
        "ω₄ at t = 0": w4,
        "μ_min": mu[0],
        "μ_max": mu[1],
        "rocker swing": dead[1] - dead[0],
        "time ratio": one_way / (360.0 - one_way),
    }


def _vloop(results: Path, info: str) -> dict[str, tuple[float, float]]:
    """The same quantities from what vloop wrote (results.csv, first row: t = 0, full precision) and printed
    (vloop info, rounded), each with half a unit of the last digit it was given to (0 for the CSV's)."""
    names = results.read_text(encoding="utf-8").splitlines()[0].split(",")
    first = dict(zip(names, np.loadtxt(results, delimiter=",", skiprows=1, ndmin=2)[0], strict=True))
    assert first["t"] == 0.0

    def printed(pattern: str) -> tuple[float, float]:
        found = re.search(pattern, info)
        assert found, f"vloop info no longer prints {pattern}\n{info}"
        return _quoted(found.group(1))

    return {
        "θ₃ at t = 0": (math.degrees(first["coupler.theta"]), 0.0),
        "θ₄ at t = 0": (math.degrees(first["rocker.theta"]), 0.0),
        "B at t = 0 (x)": (first["B.x"], 0.0),
        "B at t = 0 (y)": (first["B.y"], 0.0),
        "ω₃ at t = 0": (first["coupler.omega"], 0.0),
        "ω₄ at t = 0": (first["rocker.omega"], 0.0),
        "μ_min": printed(r"transmission angle at B .*?: min ([\d.]+)°"),
        "μ_max": printed(r"transmission angle at B .*?, max ([\d.]+)°"),
        "rocker swing": printed(r"rocker: swing [\d.]+ rad \(([\d.]+)°\)"),
        "time ratio": printed(r"time ratio ([\d.]+)"),
    }


def _quoted(cell: str) -> tuple[float, float]:
    """(value, half a unit of its last digit) of a table cell such as "−1.01612 rad/s" or "22.8121°"."""
    text = re.match(r"[−-]?\d+(\.\d+)?", cell.strip()).group(0).replace("−", "-")
    decimals = len(text.split(".")[1]) if "." in text else 0
    return float(text), 0.5 * 10.0**-decimals


def test_the_student_tutorial_runs_and_its_numbers_are_right(tmp_path: Path) -> None:
    page = TUTORIALS / "student.md"
    (toml,) = _blocks(page, "toml")
    (tmp_path / "my_fourbar.toml").write_text(toml, encoding="utf-8")
    commands = _commands(page)
    assert commands == ["vloop info my_fourbar.toml", "vloop run my_fourbar.toml --out out/my_fourbar"]
    info = _run(commands[0], tmp_path).stdout
    _run(commands[1], tmp_path)
    assert "Grashof crank-rocker" in info and "Gruebler M = 3(L-1) - 2J = 3(4-1) - 2*4 = 1" in info

    hand, ours = _hand(), _vloop(tmp_path / "out" / "my_fourbar" / "results.csv", info)
    rows = re.findall(r"^\| ([^|]+?) \| ([^|]+?) \| ([^|]+?) \| [^|]+ \|$", page.read_text(encoding="utf-8"), re.M)
    table = {name: (h, v) for name, h, v in rows if name in hand}
    assert set(table) == set(hand), sorted(set(hand) ^ set(table))
    for name, (hand_cell, vloop_cell) in table.items():
        h, h_half = _quoted(hand_cell)
        v, v_half = _quoted(vloop_cell)
        assert abs(hand[name] - h) <= h_half, f"{name}: by hand {hand[name]!r}, the page says {hand_cell}"
        got, rounding = ours[name]
        assert abs(got - v) <= v_half + 1e-12, f"{name}: vloop {got!r}, the page says {vloop_cell}"
        assert abs(hand[name] - got) <= 1e-9 * max(1.0, abs(hand[name])) + rounding, name  # a real agreement

    (script,) = _blocks(page, "python")
    (shown,) = _blocks(page, "text")
    (tmp_path / "read.py").write_text(script, encoding="utf-8")
    assert _run("python read.py", tmp_path).stdout == shown


# ---------------------------------------------------------------- the other tutorials, run as written


def _setup_designer(work: Path, page: Path) -> None:
    """The designer writes loop.toml, my_loop.toml and check_path.py from the page's blocks."""
    task, linkage = _blocks(page, "toml")
    (work / "loop.toml").write_text(task, encoding="utf-8")
    (work / "my_loop.toml").write_text(linkage, encoding="utf-8")
    (script,) = _blocks(page, "python")
    (work / "check_path.py").write_text(script, encoding="utf-8")


@pytest.mark.slow
@pytest.mark.parametrize("name", ["instructor", "designer", "nightly"])
def test_a_tutorial_runs_as_written(name: str, tmp_path: Path) -> None:
    """Every shell line of the page runs (exit 0, no traceback) in a folder holding the catalog and the
    notebooks, and writes what the page says it writes; the designer's rounded linkage passes within 1.5 mm
    of every target (the page says ≤ 1.0 mm), the nightly's Python reads the summary it describes."""
    pytest.importorskip("pinocchio", reason="pip install -e '.[validate]'")
    page = TUTORIALS / f"{name}.md"
    shutil.copytree(ROOT / "mechanisms", tmp_path / "mechanisms")
    shutil.copytree(ROOT / "docs", tmp_path / "docs", ignore=shutil.ignore_patterns("site*"))
    if name == "designer":
        _setup_designer(tmp_path, page)
    outputs = []
    for command in _commands(page):
        if command.startswith("jupyter lab"):
            continue  # opens a browser: the front end's presence is tests/test_notebooks.py's
        if command.startswith("jupyter"):
            pytest.importorskip("nbconvert", reason="pip install -e '.[notebooks]'")
            words = shlex.split(command)
            jupyter = Path(sys.executable).with_name("jupyter")
            env = {"PYTHONPATH": str(ROOT), "PATH": f"{jupyter.parent}:/usr/bin:/bin", "HOME": str(tmp_path)}
            proc = subprocess.run(
                [str(jupyter), *words[1:]], cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600
            )
            assert proc.returncode == 0, proc.stderr[-3000:]
            continue
        outputs.append(_run(command, tmp_path).stdout)
    written = set(re.findall(r"`(out/[^`\s]+)`", page.read_text(encoding="utf-8")))
    missing = sorted(p for p in written if not (tmp_path / p).exists())
    assert not missing, missing
    if name == "designer":
        gaps = [float(g) for g in outputs[-3].split(":")[1].split(",")]  # check_path.py, before the exports
        assert len(gaps) == 5 and max(gaps) <= 1.5, gaps
    if name == "nightly":
        (script,) = _blocks(page, "python")
        (tmp_path / "read.py").write_text(script, encoding="utf-8")
        lines = _run("python read.py", tmp_path).stdout.splitlines()
        assert lines[0] == "flags: []" and lines[-1] == "vloop blamed on: nothing", lines
        assert all(re.fullmatch(r"\w[\w-]*: 12 pass, 0 blamed, 0 undecided", ln) for ln in lines[1:-1]), lines
