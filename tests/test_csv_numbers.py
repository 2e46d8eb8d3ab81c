"""Every CSV vloop writes holds each number as the shortest text that reads back to the same value.

The reference is Python's own ``repr(float)`` (the shortest round-trip digits, Steele & White / Ryu): each
field must read back bit for bit to the number in memory and carry no more significant digits than
``repr`` of that number. The time grid is the decimal one the file states: step 0.05 gives 0.35, the double
nearest 7 × 0.05 as written (the floating product 7 * 0.05 is 0.35000000000000003).
"""

from __future__ import annotations

import re
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

import vloop
from tests.conftest import MECHANISMS
from vloop.cli import main
from vloop.files.fileformat import time_grid


def significant(text: str) -> int:
    """Significant digits of a decimal number's text (sign, point and exponent left out)."""
    mantissa = re.split("[eE]", text.lstrip("+-"))[0].replace(".", "").lstrip("0").rstrip("0")
    return max(len(mantissa), 1)


def fields(path: Path) -> tuple[list[str], list[list[str]]]:
    lines = path.read_text(encoding="utf-8").splitlines()
    return lines[0].split(","), [line.split(",") for line in lines[1:]]


def assert_shortest(path: Path, expected: dict[str, np.ndarray], dtype: type = np.float64) -> None:
    """Every field of ``path`` reads back to the value in memory and is no longer than its repr."""
    header, rows = fields(path)
    for name, col in expected.items():
        texts = [row[header.index(name)] for row in rows]
        back = np.array([float(x) for x in texts], dtype)
        assert np.array_equal(back, np.asarray(col, dtype)), f"{path.name} {name} does not read back"
        for x, v in zip(texts, np.asarray(col, dtype).tolist(), strict=True):
            shortest = str(np.float32(v)) if dtype is np.float32 else repr(float(v))
            assert significant(x) <= significant(shortest), f"{path.name} {name}: {x!r} is longer than {shortest!r}"


@pytest.mark.parametrize("pyarrow", [True, False], ids=["pyarrow", "python"])
def test_results_forces_extras_and_health_csv_are_shortest_round_trip(tmp_path, monkeypatch, pyarrow):
    if not pyarrow:
        monkeypatch.setitem(sys.modules, "pyarrow", None)  # the fallback writer (pyarrow is optional)
    path = MECHANISMS / "eightbar_dynamics.toml"
    assert main(["run", str(path), "--out", str(tmp_path), "--extras"]) == 0
    mech = vloop.load(path)
    res = vloop.solve(mech)
    forces = vloop.solve_forces(mech, res)
    assert_shortest(tmp_path / "results.csv", {"t": res.t, **res.columns})
    assert_shortest(tmp_path / "forces.csv", {"t": forces.t, **forces.columns})
    extras = vloop.teaching.extras(mech, res)
    assert_shortest(tmp_path / "extras.csv", {"t": res.t, **extras})
    assert_shortest(
        tmp_path / "health.csv", {k: res.health[k[7:]] for k in ("health.residual", "health.cond")}, np.float32
    )
    decimal = [k / 20 for k in range(48)]  # 0.35 (7/20 rounded once), never 0.35000000000000003 (7 * 0.05)
    assert res.t.tolist() == decimal and "0.35000000000000003" not in repr(decimal)
    for name in ("results.csv", "forces.csv", "extras.csv", "health.csv"):
        assert_shortest(tmp_path / name, {"t": decimal})
    res.to_csv(tmp_path / "api.csv", health=True)
    assert_shortest(tmp_path / "api.csv", {"t": res.t, **res.columns})
    assert vloop.Result.read_csv(tmp_path / "api.csv").columns.keys() == res.columns.keys()


def test_the_time_grid_is_the_decimal_one_the_file_states():
    """start + k·step rounded once from the decimals as written (exact rational arithmetic as the reference)."""
    for start, step, n in ((0.0, 0.05, 48), (0.1, 0.001, 1000), (-1.5, 0.3, 50), (2.0, 1e-7, 100), (0.0, 0.0025, 400)):
        got = time_grid(start, step, n)
        want = [float(Fraction(repr(start)) + k * Fraction(repr(step))) for k in range(n)]
        assert got.tolist() == want
    third = 1 / 3  # no short decimal: start + k·step in floating point
    assert time_grid(0.0, third, 4).tolist() == [0.0, third, 2 * third, 3 * third]
    assert time_grid(0.0, 5e-324, 3).tolist() == [0.0, 5e-324, 1e-323]
    assert time_grid(0.0, 1e308, 1).tolist() == [0.0] and time_grid(1.0, 1e20, 2).tolist() == [1.0, 1e20]
