"""The loop equations as ``vloop loops`` prints them, plain and LaTeX, checked by evaluating the printed text.

The printed equation of every catalog file is parsed by a small evaluator written here for what vloop prints
(sums of ``m·e^{…}`` terms; an exponent is a sum of products of j, numbers, π, θ_NAME and parenthesised
sums, with ``/`` — read as mathematics reads it, so ``e^{j θ + π}`` is e^{jθ}·e^{π}, not e^{j(θ + π)}), and
evaluated at t = 0 with every quantity taken from the joints' positions there, not from vloop's loops:

* θ of a link: the direction from its first to its second joint (atan2 of their positions);
* s of a slider: its joint's position along the axis from the guide's origin (the world origin on the ground,
  else the guide's first joint), the axis turned with the guide;
* a letter's length: |Y − X| for the legend's ``|X→Y (body)|``, where X or Y may be ``line of S`` (the point
  s = 0 of slider S's line) or the ground joint at the world origin; ``offset of S``: the distance from the
  guide's origin to that point.

Each loop then closes to round-off (``--exact`` prints every number as the shortest text that reads back to the
same double: measured ≤ 7.1e-16 of the mechanism's size), and within the printed precision without it (angles
to 4 decimals: |Σ| ≤ Σ |v|·(5e-5 + 5e-6 relative for the lengths' 6 digits)). The plain and the LaTeX forms
come from one structure; both are evaluated.
"""

from __future__ import annotations

import cmath
import math
import re
from pathlib import Path

import numpy as np
import pytest

import vloop
from tests.conftest import MECHANISMS, mechanism_files
from vloop.cli import main
from vloop.compiler import compile_system
from vloop.method.branches import branch_name

TOKEN = re.compile(
    r"\s+|\\,|·|(?P<theta>\\theta_\{\\mathrm\{(?P<tex>[^}]*)\}\}|θ_(?P<plain>[A-Za-z0-9_\-]+))"
    r"|(?P<pi>\\pi|π)|(?P<num>\d+(?:\.\d*)?(?:e[-+]?\d+)?)|(?P<op>[+/(){}^])|(?P<j>j)|(?P<e>e)"
    r"|(?P<letter>[a-z]\d*)"
)


def tokens(text: str) -> list[tuple[str, str]]:
    out, pos = [], 0
    while pos < len(text):
        m = TOKEN.match(text, pos)
        assert m is not None, f"cannot read {text[pos : pos + 30]!r}"
        pos = m.end()
        kind = next((k for k in ("theta", "pi", "num", "op", "j", "e", "letter") if m.group(k)), None)
        if kind == "theta":
            out.append(("theta", (m.group("tex") or m.group("plain")).replace("\\_", "_")))
        elif kind:
            out.append((kind, m.group(kind)))
    return out


class Expression:
    """Sums of products, as mathematics reads them: ``a + b``, juxtaposition multiplies, ``x/y`` divides."""

    def __init__(self, toks: list[tuple[str, str]], values: dict) -> None:
        self.toks, self.k, self.values = toks, 0, values

    def peek(self) -> tuple[str, str] | None:
        return self.toks[self.k] if self.k < len(self.toks) else None

    def take(self, want: str | None = None) -> tuple[str, str]:
        tok = self.toks[self.k]
        assert want is None or tok[1] == want, (tok, want)
        self.k += 1
        return tok

    def total(self) -> complex:
        value = self.product()
        while self.peek() == ("op", "+"):
            self.take()
            value += self.product()
        return value

    def product(self) -> complex:
        value = self.factor()
        while (tok := self.peek()) is not None and tok not in (("op", "+"), ("op", ")"), ("op", "}")):
            if tok == ("op", "/"):
                self.take()
                value /= self.factor()
            else:
                value *= self.factor()
        return value

    def factor(self) -> complex:
        kind, text = self.take()
        if kind == "num":
            return complex(float(text))
        if kind == "pi":
            return complex(math.pi)
        if kind == "j":
            return 1j
        if kind == "theta":
            return complex(self.values["theta"][text])
        if kind == "letter":
            return complex(self.values["length"][text])
        if kind == "e":  # e^{…}
            self.take("^")
            self.take("{")
            power = self.total()
            self.take("}")
            return cmath.exp(power)
        assert text in "({", text
        value = self.total()
        self.take(")" if text == "(" else "}")
        return value


def evaluate(equation: str, values: dict) -> tuple[complex, float]:
    """(Σ of the printed vectors, Σ of their lengths) at ``values``."""
    terms = Expression(tokens(equation), values)
    total, size = 0j, 0.0
    while terms.peek() is not None:
        v = terms.product()
        total, size = total + v, size + abs(v)
        if terms.peek() == ("op", "+"):
            terms.take()
    return total, size


# ---------------------------------------------------------------- quantities from the joints' positions


def positions(mech: vloop.Mechanism) -> dict[str, complex]:
    res = vloop.solve(mech, times=np.zeros(1))
    return {p: complex(res[f"{p}.x"][0], res[f"{p}.y"][0]) for p in mech.tracked_points}


def guide_frame(mech: vloop.Mechanism, at: dict[str, complex], slider: str) -> tuple[complex, complex]:
    """(the guide's origin, the slider's axis as a unit complex) at t = 0."""
    sl = mech.sliders[slider]
    axis = complex(*sl.axis) / abs(complex(*sl.axis))
    if mech.links[sl.guide].ground:
        return 0j, axis
    j0, j1 = mech.links[sl.guide].joints[:2]
    typed = complex(*mech.joints[j1]) - complex(*mech.joints[j0])
    turned = (at[j1] - at[j0]) / typed  # the guide's turn from the typed coordinates, times a length ratio
    return at[j0], axis * turned / abs(turned)


def values_at_t0(mech: vloop.Mechanism, legend: list[str]) -> dict:
    at = positions(mech)
    theta = {}
    for name, lk in mech.links.items():
        if not lk.ground and len(lk.joints) >= 2:
            d = at[lk.joints[1]] - at[lk.joints[0]]
            theta[name] = math.atan2(d.imag, d.real)
    s = {}
    for name, sl in mech.sliders.items():
        origin, u = guide_frame(mech, at, name)
        s[name] = ((at[sl.joint] - origin) * u.conjugate()).real
    origin_joint = next((j for j in mech.links[mech.ground].joints if abs(complex(*mech.joints[j])) == 0), "O")

    def point(name: str) -> complex:
        if name.startswith("line of "):
            sl = name[len("line of ") :]
            u = guide_frame(mech, at, sl)[1]
            return at[mech.sliders[sl].joint] - s[sl] * u
        return 0j if name == origin_joint and name not in at else at.get(name, 0j if name == "O" else at[name])

    length = {}
    for item in legend:
        letter, what = item.split(" = ", 1)
        if what.startswith("s_"):
            length[letter] = s[what.split(" ")[0][2:]]
        elif what.startswith("|offset of "):
            sl = what[len("|offset of ") :].split("|")[0]
            length[letter] = abs(point(f"line of {sl}") - guide_frame(mech, at, sl)[0])
        else:
            a, b = re.match(r"\|(.*)→(.*) \(.*\)\|", what).groups()
            length[letter] = abs(point(b) - point(a))
        printed = float(what.rsplit(" = ", 1)[1]) if " = " in what else None
        length[f"printed {letter}"] = printed
    return {"theta": theta, "s": s, "length": length}


def loops_and_legend(text: str, latex: bool) -> tuple[list[tuple[str, str]], list[str]]:
    """[(label, left side)], legend lines, read from ``vloop loops`` output."""
    if latex:
        lines = text.splitlines()
        eqs = [re.match(r"(.*) &= 0 && \\text\{loop \d+ \((.*)\)\}", line.rstrip(" \\")) for line in lines]
        return [(m.group(2), m.group(1)) for m in eqs if m], lines[-1][2:].split("; ")
    body, _, legend = text.partition("\nwhere\n")
    eqs = re.findall(r"^loop \d+ \((.*)\):  (.*) = 0$", body, re.M)
    return eqs, [line.strip() for line in legend.splitlines() if line.strip()]


@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_printed_loops_close_at_t0(path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    mech = vloop.load(path)
    for exact in (True, False):
        for latex in (False, True):
            assert main(["loops", str(path), *(["--latex"] if latex else []), *(["--exact"] if exact else [])]) == 0
            eqs, legend = loops_and_legend(capsys.readouterr().out, latex)
            assert len(eqs) == len(compile_system(mech).loops) and legend
            values = values_at_t0(mech, legend)
            for letter, r in list(values["length"].items()):
                if letter.startswith("printed ") and r is not None:  # the legend's lengths, from the joints
                    ours = values["length"][letter[len("printed ") :]]
                    assert abs(r - ours) <= (2e-15 if exact else 5e-6) * max(abs(ours), mech.scale * 1e-3), letter
            for label, eq in eqs:
                total, size = evaluate(eq, values)
                bound = 2e-15 * mech.scale if exact else size * 6e-5
                assert abs(total) <= bound, f"{path.stem} loop {label} ({'LaTeX' if latex else 'text'}): {eq} ≠ 0"


def test_a_shifted_angle_keeps_its_parentheses_in_latex(capsys: pytest.CaptureFixture[str]) -> None:
    """The rocker's vector O4→B walked backwards: c·e^{j(θ_l4 + π)} in both forms (once c\\,e^{j θ + π})."""
    assert main(["loops", "--latex", str(MECHANISMS / "fourbar_textbook_example.toml")]) == 0
    assert r"c\,e^{j (\theta_{\mathrm{l4}} + \pi)}" in capsys.readouterr().out
    assert main(["loops", str(MECHANISMS / "fourbar_textbook_example.toml")]) == 0
    assert "c·e^{j(θ_l4 + π)}" in capsys.readouterr().out
    wrong = r"c\,e^{j \theta_{\mathrm{l4}} + \pi}"  # what the evaluator makes of the text without them
    assert abs(evaluate(wrong, {"theta": {"l4": 1.0}, "length": {"c": 1.0}})[0] - cmath.exp(1j + math.pi)) < 1e-12


# ---------------------------------------------------------------- where the world origin is


def translated(mech: vloop.Mechanism, dx: float, dy: float, branches: dict | None = None) -> vloop.Mechanism:
    data = vloop.mechanism.to_dict(mech)
    data["joints"] = {j: [x + dx, y + dy] for j, (x, y) in data["joints"].items()}
    for p in data.get("points", {}).values():
        p["at"] = [p["at"][0] + dx, p["at"][1] + dy]
    if branches:
        data.setdefault("solver", {})["branches"] = branches
    return vloop.from_dict(data, source=f"{mech.name} moved by ({dx}, {dy})")


OFFSETS = [(0.0, 0.0), (3.7, -1.25), (-1e3, 2e3), (1e-3, 0.0)]


@pytest.mark.parametrize("stem", ["fourbar_textbook_example", "fourbar_crank_rocker_open", "sixbar_watt2"])
def test_loops_do_not_depend_on_where_the_origin_is(stem: str) -> None:
    """A pin-jointed linkage moved anywhere prints the same loops (one ground vector between two ground pivots,
    O2→O4, as textbooks write it; never two from the world origin) and names the same branches."""
    mech = vloop.load(MECHANISMS / f"{stem}.toml")
    texts = set()
    for dx, dy in OFFSETS:
        system = compile_system(translated(mech, dx, dy))
        text = vloop.method.equations.describe(system)
        texts.add(text.split("\n", 1)[1])  # the heading names the file
        assert branch_name(system, system.blocks[0], system.q0) == "open"
    assert len(texts) == 1, texts
    assert "O2→O4 (ground)" in texts.pop()


def test_translated_four_bar_takes_branch_names() -> None:
    """The open crank-rocker moved off the origin and asked for its crossed branch assembles as the catalog's
    crossed file does (same linkage), moved: joints and angles agree to round-off over the run."""
    open_, crossed = (vloop.load(MECHANISMS / f"fourbar_crank_rocker_{b}.toml") for b in ("open", "crossed"))
    dx, dy = 12.5, -7.25
    moved = translated(open_, dx, dy, {"1": "crossed"})
    res, ref = vloop.solve(moved), vloop.solve(crossed)
    for j in ("A", "B"):
        assert np.max(np.abs(res[f"{j}.x"] - dx - ref[f"{j}.x"])) <= 1e-12 * 20
        assert np.max(np.abs(res[f"{j}.y"] - dy - ref[f"{j}.y"])) <= 1e-12 * 20
    for lk in ("l3", "l4"):
        assert np.max(np.abs(np.angle(np.exp(1j * (res[f"{lk}.theta"] - ref[f"{lk}.theta"]))))) <= 1e-12
    watt = translated(vloop.load(MECHANISMS / "sixbar_watt2.toml"), dx, dy, {"2": "crossed"})
    system = compile_system(watt)
    assert system.loops[1].label == "O4–C–D–O6"
    assert branch_name(system, system.blocks[1], system.q0) == "crossed"


def test_sliders_keep_measuring_from_the_world_origin() -> None:
    """The offset slider-crank moved: its loop still closes through O2 (O2–A–B, the ground's vector from O2 to the
    slider's line) and s is still the block's position along the axis from the world origin (the file contract)."""
    mech = vloop.load(MECHANISMS / "slider_crank_offset.toml")
    dx, dy = 2.5, -4.0
    system = compile_system(translated(mech, dx, dy))
    assert [lp.label for lp in system.loops] == ["O2–A–B"]
    res, ref = vloop.solve(system), vloop.solve(mech)
    assert np.max(np.abs(res["l4.s"] - (ref["l4.s"] + dx))) <= 1e-12 * 10  # axis +x: s grows by dx
