"""DXF parts a laser cutter can cut, read back with ezdxf (an independent reader of bulges, arcs and text).

* every outline is a closed polyline holding its part's holes; the least web between a hole and the outline,
  measured on ezdxf's own flattening of the outline's arcs, is the stated (width − pin)/2 of material;
* with a kerf, every cut path moves by half of it (holes smaller, outlines larger): the web between the cut
  paths grows by the kerf, so the material left is the stated web;
* a coupler point is marked at the file's distances from its link's pivots (1e-9 of the size);
* a slot on a moving guide runs over the slider's travel in ``vloop.solve``'s run;
* each name on the engrave layer, measured with ezdxf's font metrics (``text_size``), lies inside its part and
  clear of every hole.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path

import numpy as np
import pytest

import vloop
from vloop.cli import main
from vloop.views.export import export

from .conftest import MECHANISMS, mechanism_files

ezdxf = pytest.importorskip("ezdxf", reason="DXF export needs ezdxf (pip install -e '.[export]')")
from ezdxf import path as dxfpath  # noqa: E402
from ezdxf.tools.text_size import text_size  # noqa: E402


def _at(mech: vloop.Mechanism) -> float:
    return float(mech.times[len(mech.times) // 3 if "past_limit" not in mech.name else 10])


def _flat(entity, size: float) -> np.ndarray:
    """The polyline's points, its arcs flattened by ezdxf to 1e-6 of the size."""
    return np.array([(v.x, v.y) for v in dxfpath.make_path(entity).flattening(1e-6 * size)])


def _distance(p: np.ndarray, ring: np.ndarray) -> float:
    a, b = ring, np.roll(ring, -1, axis=0)
    d = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.maximum(np.einsum("ij,ij->i", d, d), 1e-300), 0, 1)
    return float(np.min(np.hypot(*(a + t[:, None] * d - p).T)))


def _inside(p: np.ndarray, ring: np.ndarray) -> bool:
    x, y = ring[:, 0], ring[:, 1]
    xj, yj = np.roll(x, 1), np.roll(y, 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        crossing = ((y > p[1]) != (yj > p[1])) & (p[0] < (xj - x) * (p[1] - y) / (yj - y) + x)
    return bool(np.count_nonzero(crossing) % 2)


def _parts(doc, mech) -> dict[str, tuple[np.ndarray, list, list]]:
    """layer -> (outline ring, holes [(centre, r)], slot rings)."""
    msp = doc.modelspace()
    out = {}
    for layer in {e.dxf.layer for e in msp if e.dxf.layer.startswith("PART-")}:
        rings = [e for e in msp.query(f'LWPOLYLINE[layer=="{layer}"]')]
        assert all(e.closed for e in rings), layer
        flat = [_flat(e, mech.scale) for e in rings]
        outer = max(range(len(flat)), key=lambda i: np.ptp(flat[i][:, 0]) + np.ptp(flat[i][:, 1]))
        holes = [
            (np.array([c.dxf.center.x, c.dxf.center.y]), c.dxf.radius) for c in msp.query(f'CIRCLE[layer=="{layer}"]')
        ]
        out[layer] = (flat[outer], holes, [f for i, f in enumerate(flat) if i != outer])
    return out


FEW = ["fourbar_crank_rocker_open", "sixbar_watt2", "inverted_slider_crank", "whitworth_quick_return", "eightbar"]


@pytest.mark.parametrize("path", [MECHANISMS / f"{s}.toml" for s in FEW], ids=lambda p: p.stem)
def test_outlines_closed_around_their_holes_with_the_stated_web(path: Path, tmp_path: Path) -> None:
    _outlines(path, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_outlines_of_every_catalog_mechanism(path: Path, tmp_path: Path) -> None:
    _outlines(path, tmp_path)


def _outlines(path: Path, tmp_path: Path) -> None:
    mech = vloop.load(path)
    pin, width = 0.02 * mech.scale, 0.07 * mech.scale
    doc = ezdxf.readfile(export(mech, tmp_path, _at(mech), "dxf", pin=pin, width=width))
    parts = _parts(doc, mech)
    assert parts
    for layer, (ring, holes, slots) in parts.items():
        assert holes and all(abs(r - pin / 2) <= 1e-12 * mech.scale for _, r in holes), layer
        webs = [_distance(c, ring) - r for c, r in holes]
        assert all(_inside(c, ring) for c, _ in holes), layer
        assert min(webs) == pytest.approx((width - pin) / 2, abs=2e-6 * mech.scale), layer  # chords: 1e-6
        for s in slots:  # a slot inside the part, with at least the web around it
            assert all(_inside(p, ring) for p in s[:: max(1, len(s) // 20)]), layer
            assert min(_distance(p, ring) for p in s) >= (width - pin) / 2 - 1e-6 * mech.scale, layer


def test_kerf_moves_every_cut_path_by_half_of_it(tmp_path: Path) -> None:
    mech = vloop.load(MECHANISMS / "sixbar_watt2.toml")
    pin, width, kerf = 0.2, 0.6, 0.03  # metres
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    plain = _parts(ezdxf.readfile(export(mech, tmp_path / "a", 0.5, "dxf", pin=pin, width=width)), mech)
    cut = _parts(ezdxf.readfile(export(mech, tmp_path / "b", 0.5, "dxf", pin=pin, width=width, kerf=kerf)), mech)
    for layer, (ring, holes, _) in cut.items():
        assert all(abs(r - (pin - kerf) / 2) <= 1e-12 for _, r in holes)
        web = min(_distance(c, ring) - r for c, r in holes)
        assert web == pytest.approx((width - pin) / 2 + kerf, abs=2e-6 * mech.scale), layer
        centres = sorted(tuple(np.round(c, 9)) for c, _ in holes)
        assert centres == sorted(tuple(np.round(c, 9)) for c, _ in plain[layer][1])  # the same places


def test_coupler_point_marked_where_the_file_puts_it(tmp_path: Path) -> None:
    mech = vloop.load(MECHANISMS / "fourbar_crank_rocker_open.toml")
    doc = ezdxf.readfile(export(mech, tmp_path, 1.0, "dxf"))
    msp = doc.modelspace()
    marks = [np.array([c.dxf.center.x, c.dxf.center.y]) for c in msp.query('CIRCLE[layer=="ENGRAVE"]')]
    assert len(marks) == len(mech.points)
    for name, pt in mech.points.items():
        joints = mech.links[pt.link].joints
        holes = [np.array([c.dxf.center.x, c.dxf.center.y]) for c in msp.query(f'CIRCLE[layer=="PART-{pt.link}"]')]
        want = sorted(math.dist(pt.at, mech.joints[j]) for j in joints)
        assert any(
            np.allclose(sorted(np.hypot(*(m - h)) for h in holes), want, rtol=0, atol=1e-9 * mech.scale) for m in marks
        ), name


def test_slot_on_a_moving_guide_covers_the_travel(tmp_path: Path) -> None:
    mech = vloop.load(MECHANISMS / "inverted_slider_crank.toml")
    (sl,) = [s for s in mech.sliders.values() if s.guide != mech.ground]
    run = vloop.solve(mech)
    travel = float(np.ptp(run[f"{sl.name}.s"]))
    pin = 0.02 * mech.scale
    doc = ezdxf.readfile(export(mech, tmp_path, 0.5, "dxf", pin=pin))
    _, _, slots = _parts(doc, mech)[f"PART-{sl.guide}"]
    (slot,) = slots
    length = max(math.dist(a, b) for a, b in itertools.combinations(slot[:: max(1, len(slot) // 200)], 2))
    assert length == pytest.approx(travel + pin, abs=1e-5 * mech.scale)


@pytest.mark.parametrize("stem", ["sixbar_watt2", "inverted_slider_crank", "jansen_pair"])
def test_names_on_the_engrave_layer_inside_their_part_and_clear_of_holes(stem: str, tmp_path: Path) -> None:
    mech = vloop.load(MECHANISMS / f"{stem}.toml")
    doc = ezdxf.readfile(export(mech, tmp_path, 0.5, "dxf"))
    parts = _parts(doc, mech)
    texts = list(doc.modelspace().query('TEXT[layer=="ENGRAVE"]'))
    assert {t.dxf.text for t in texts} == {f[5:] for f in parts}
    for t in texts:
        ring, holes, slots = parts[f"PART-{t.dxf.text}"]
        size = text_size(t)
        c = np.array([t.dxf.align_point.x, t.dxf.align_point.y])
        a = math.radians(t.dxf.rotation)
        u, n = np.array([math.cos(a), math.sin(a)]), np.array([-math.sin(a), math.cos(a)])
        w, h = size.width, size.total_height
        box = [c + sx * w / 2 * u + sy * h / 2 * n for sx in (-1, 1) for sy in (-1, 1)]
        assert all(_inside(p, ring) for p in box), t.dxf.text
        edges = np.array([box[0], box[1], box[3], box[2]])
        for centre, r in holes:
            assert not _inside(centre, edges) and _distance(centre, edges) > r, t.dxf.text
        for s in slots:
            assert all(not _inside(p, edges) for p in s), t.dxf.text


def test_cli_kerf_pin_width(tmp_path: Path, capsys) -> None:
    path = MECHANISMS / "fourbar_textbook_example.toml"
    argv = ["export", str(path), "--at", "0.2", "--format", "dxf", "--pin", "2", "--width", "8", "--kerf", "0.1"]
    assert main([*argv, "--out", str(tmp_path)]) == 0
    doc = ezdxf.readfile(tmp_path / "fourbar_textbook_example.dxf")
    radii = {round(c.dxf.radius, 12) for c in doc.modelspace().query("CIRCLE") if c.dxf.layer.startswith("PART-")}
    assert radii == {0.95}
