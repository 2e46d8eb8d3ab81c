"""Branch names: "open" / "crossed" name the two assemblies of a dyad, one each, constant along a circuit.

References, independent of vloop's naming:

* the textbook's side test written out here: the middle joint M of the dyad P–M–Q to the left of the line from
  its input-side end P to its frame-side end Q is "open" (Norton, ch. 4: the four-bar O2–A–B–O4, B left of
  A→O4), the positions intersected by hand (two circles);
* every four-joint loop of the catalog and of generated mechanisms (validators/corpus.py): each file rewritten
  from its dimensions (tests/test_authoring.py), its hints exact, with ``[solver] branches`` set to the names
  ``vloop info`` prints: the assembly must be the drawn one (every joint within 1e-9 of the size), and each
  name's opposite alone must give the other assembly (the names tell the two apart).
"""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np
import pytest
import tomli_w

import vloop
from tests.conftest import MECHANISMS, mechanism_files
from tests.test_authoring import dimensions_only
from vloop.authoring import assemble_mechanism
from vloop.cli import _info_loops, main
from vloop.mechanism import loads as read_only
from vloop.method.branches import branch_name, branch_sigma, dyad_branch

SAME = 1e-9  # of the size: the drawn assembly reproduced (the closed forms reassemble it to ~1e-14)
LINE = re.compile(
    r"loop (\d+) assembly branch at t = 0: sigma = [+-]1: (open|crossed) \((\w+) (left|right) of (\w+)→(\w+)\)"
)


class _Exact:
    """A generator whose hints are exact (dimensions_only's rough hints without the noise)."""

    @staticmethod
    def uniform(lo: float, hi: float) -> float:
        return 0.0


def _left(p: complex, q: complex, m: complex) -> bool:
    return ((q - p).conjugate() * (m - p)).imag > 0


# ---------------------------------------------------------------- the leg of Jansen's linkage, by hand

LEG = """
name = "leg"
[joints]
O2 = [0.0, 0.0]
O4 = [-38.0, -7.8]
{b}
[links]
ground = {{ joints = ["O2", "O4"], ground = true }}
crank = {{ joints = ["O2", "A"], length = 15.0 }}
coupler = {{ joints = ["A", "B"], length = 50.0 }}
rocker = {{ joints = ["O4", "B"], length = 41.5 }}
[[drivers]]
link = "crank"
theta0 = 0.0
omega = 1.0
[time]
start = 0.0
stop = 6.0
step = 0.5
{solver}
"""


def _leg_assemblies() -> dict[str, complex]:
    """B for the crank at θ2 = 0 (A = (15, 0)): the two intersections of |B − A| = 50, |B − O4| = 41.5, named by
    the side of A→O4 (left: open)."""
    a, o4, r1, r2 = 15 + 0j, -38 - 7.8j, 50.0, 41.5
    d = abs(o4 - a)
    x = (r1**2 - r2**2 + d**2) / (2 * d)  # along A→O4 from A
    h = math.sqrt(r1**2 - x**2)
    u = (o4 - a) / d
    left, right = a + u * (x + 1j * h), a + u * (x - 1j * h)
    assert _left(a, o4, left) and not _left(a, o4, right)
    return {"open": left, "crossed": right}


def test_the_legs_two_assemblies_get_one_name_each(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    """The drawn leg (B = (−24.0135, 31.2721)) is "crossed" (B right of A→O4); each name assembles its own B."""
    by_hand = _leg_assemblies()
    assert abs(by_hand["crossed"] - (-24.0135 + 31.2721j)) < 1e-4  # the drawing of jansen_pair's left leg
    assert abs(by_hand["open"] - (-13.3499 - 41.1860j)) < 1e-4
    drawn = tmp_path / "leg.toml"
    drawn.write_text(
        LEG.format(b=f"A = [15.0, 0.0]\nB = [{by_hand['crossed'].real!r}, {by_hand['crossed'].imag!r}]", solver="")
    )
    assert main(["info", str(drawn)]) == 0
    assert "loop 1 assembly branch at t = 0: sigma = -1: crossed (B right of A→O4)" in capsys.readouterr().out
    for name, b in by_hand.items():
        mech = vloop.loads(LEG.format(b="", solver=f'[solver]\nbranches = {{ 1 = "{name}" }}'))
        got = complex(*mech.joints["B"])
        assert abs(got - b) <= 1e-12 * mech.scale, name
        system = vloop.compile(mech)
        assert branch_name(system, system.blocks[0], system.q0) == name


def test_the_name_belongs_to_the_circuit_not_the_instant() -> None:
    """A Grashof crank-rocker's open circuit over a whole turn: the name stays "open" although the quadrilateral
    O2–A–B–O4 crosses itself over part of the turn (the instant test named those samples "crossed")."""
    mech = vloop.load(MECHANISMS / "fourbar_crank_rocker_open.toml")
    res = vloop.solve(mech, times=np.linspace(0, 2 * math.pi / abs(mech.drivers[0].v0), 181))
    p = {j: res[f"{j}.x"] + 1j * res[f"{j}.y"] for j in ("A", "B")}
    o2, o4 = (complex(*mech.joints[j]) for j in ("O2", "O4"))
    assert np.all(((o4 - p["A"]).conj() * (p["B"] - p["A"])).imag > 0)  # B left of A→O4 at every sample

    def crosses(a, b, c, d):
        side = lambda u, v, w: (np.conj(v - u) * (w - u)).imag  # noqa: E731
        return (side(a, b, c) * side(a, b, d) < 0) & (side(c, d, a) * side(c, d, b) < 0)

    self_crossing = crosses(o2, p["A"], p["B"], o4) | crosses(p["A"], p["B"], o4, o2)
    assert 0 < self_crossing.sum() < len(res.t)  # both looks occur on the one circuit
    system = vloop.compile(mech)
    for i in np.flatnonzero(self_crossing)[:5]:
        q = system.q0.copy()
        q[[system.angle_links.index(n) for n in ("l2", "l3", "l4")]] = [
            res[f"{n}.theta"][i] for n in ("l2", "l3", "l4")
        ]
        assert branch_name(system, system.blocks[0], q) == "open"


def test_on_the_line_no_name_is_picked() -> None:
    """At a toggle (B on the line A→O4) the side is 0: no name, and branch_name refuses."""
    system = vloop.compile(vloop.load(MECHANISMS / "fourbar_crank_rocker_open.toml"))
    block = system.blocks[0]
    q = system.q0.copy()
    q[2] = q[1]  # coupler and rocker in line: θ4 = θ3 puts B on the line through A and O4's direction
    b = dyad_branch(system, block, q)
    assert b is not None and b.side == 0 and b.name is None and "on the line" in b.text()
    with pytest.raises(vloop.MechanismError, match="neither open nor crossed"):
        branch_name(system, block, q)


def test_names_refused_where_they_do_not_apply() -> None:
    """A five-joint loop's dyad, a slider-crank: 'open'/'crossed' refused, naming the loop."""
    s3 = vloop.compile(vloop.load(MECHANISMS / "sixbar_stephenson3.toml"))
    with pytest.raises(vloop.MechanismError, match=r"loop 2 \(O2–A–P–E–O6\) is not a four-joint loop"):
        branch_sigma(s3, s3.blocks[1], "open")
    assert dyad_branch(s3, s3.blocks[1], s3.q0).text() == "E right of P→O6"


# ---------------------------------------------------------------- the names info prints, reassembled


def _printed(system: vloop.LoopSystem) -> dict[int, tuple[str, str]]:
    """loop number → (name, middle joint), as `vloop info` prints them; each checked against the drawing: the side
    printed is the side of the line the middle joint lies on, "open" the left, and a ground pivot is the line's end
    (the frame side) wherever one of the two ends is one."""
    mech = system.mechanism
    ground = set(mech.links[mech.ground].joints)
    out = {}
    for line in _info_loops(system):
        if m := LINE.search(line):
            name, middle, side, p, q = m[2], m[3], m[4], m[5], m[6]
            at = {j: complex(*mech.joints[j]) for j in (p, middle, q)}
            assert _left(at[p], at[q], at[middle]) == (side == "left") == (name == "open"), line
            assert not (p in ground and q not in ground), line
            out[int(m[1])] = (name, middle)
    return out


def _at_start(mech: vloop.Mechanism) -> dict[str, complex]:
    res = vloop.solve(mech, times=np.zeros(1))
    return {j: complex(res[f"{j}.x"][0], res[f"{j}.y"][0]) for j in mech.joints}


def _reassembled(path: Path) -> tuple[int, float, float]:
    """(named loops, worst distance of the named assembly, least distance of a flipped one) over the joints, as
    fractions of the size: the names ``vloop info`` prints given to the file itself (the compiler's branches), and
    to the file rewritten from its dimensions (``vloop assemble``; where its links have at most three joints)."""
    mech = vloop.load(path)
    printed = _printed(vloop.compile(mech))
    if not printed:
        return 0, 0.0, math.inf
    drawn = _at_start(mech)
    writable = all(len(lk.joints) <= 3 for lk in mech.links.values() if not lk.ground)
    data = dimensions_only(path, _Exact()) if writable else None

    def assembled(names: dict[int, str]) -> list[dict[str, complex]]:
        table = {str(k): v for k, v in names.items()}
        out = [_at_start(dataclasses.replace(mech, options={**mech.options, "branches": dict(names)}))]
        if data is not None:
            data.setdefault("solver", {})["branches"] = table
            closed, _ = assemble_mechanism(read_only(tomli_w.dumps(data), source="dims", base_dir=path.parent))
            out.append({j: complex(*xy) for j, xy in closed.joints.items()})
        return out

    names = {k: v[0] for k, v in printed.items()}
    worst = max(abs(p[j] - drawn[j]) for p in assembled(names) for j in drawn) / mech.scale
    apart = math.inf
    for k, (name, middle) in printed.items():
        try:  # the other name: the dyad's other assembly, or none where a later loop cannot close with it
            others = assembled({**names, k: "crossed" if name == "open" else "open"})
        except vloop.MechanismError as exc:
            assert "cannot" in str(exc) and f"loop {k} " not in str(exc), str(exc)
            continue
        apart = min(apart, *(abs(p[middle] - drawn[middle]) / mech.scale for p in others))
    return len(printed), worst, apart


@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_catalog_names_reassemble_the_drawn_configuration(path: Path, tmp_path: Path) -> None:
    named, worst, apart = _reassembled(path)
    assert worst <= SAME and (named == 0 or apart > 1e-6)
    if path.stem == "jansen_pair":
        assert named == 6


def _corpus_check(n: int, seed: int, tmp_path: Path) -> tuple[int, float, float]:
    from validators import corpus

    items, _ = corpus.generate(n, seed)
    total, worst, apart = 0, 0.0, math.inf
    for it in items:
        path = tmp_path / f"{it.name}.toml"
        path.write_text(it.text)
        named, w, a = _reassembled(path)
        assert w <= SAME and (named == 0 or a > 1e-6), it.name
        total, worst, apart = total + named, max(worst, w), min(apart, a)
    return total, worst, apart


def test_generated_names_reassemble_the_drawn_configuration(tmp_path: Path) -> None:
    total, _, _ = _corpus_check(20, 2031, tmp_path)
    assert total >= 10  # four-joint loops among the 20 (four-bars, Watt II, Stephenson, attached dyads)


@pytest.mark.slow
def test_300_generated_names_reassemble_the_drawn_configuration(tmp_path: Path) -> None:
    total, worst, apart = _corpus_check(300, 2032, tmp_path)
    print(f"300 generated: {total} named loops, worst {worst:.2g} of the size, flipped ones apart ≥ {apart:.2g}")
    assert total >= 150


def test_the_documented_picture_is_made_by_its_script(tmp_path: Path) -> None:
    """docs/make_branches_png.py draws docs/branches.png from vloop's own names (it asserts each name it draws)."""
    import runpy

    script = runpy.run_path(str(MECHANISMS.parent / "docs" / "make_branches_png.py"))
    out = script["main"](tmp_path / "branches.png")
    assert out.stat().st_size > 10_000 and (MECHANISMS.parent / "docs" / "branches.png").is_file()
