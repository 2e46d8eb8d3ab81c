"""The studio's session without a browser: a drawing made by messages runs as the catalog's file does, a drag past a
limit stops at the limit and says so, locks hold, undo/redo restore, files stay inside the folder.

References: mechanisms/fourbar_textbook_example.toml (a = 40, b = 120, c = 80, d = 100 mm, θ₂(0) = 40°, ω₂ = 25
rad/s, α₂ = 15 rad/s², 0.5 s at 2.5 ms). A drag moves one joint and the others stay: dragging O4 along +x to
(d, 0) makes the ground d and the rocker c(d) = |B − (d, 0)| with B where it is; the crank stops turning fully
when its far position (θ₂ = π) stretches O4–A past b + c: d + a = b + c(d) (solved here by brentq).
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
import pytest

import vloop
from vloop.studio.session import Session

from .conftest import MECHANISMS

TEXTBOOK = MECHANISMS / "fourbar_textbook_example.toml"


def ok(reply: dict) -> dict:
    assert reply["ok"], reply
    return reply


def draw_textbook(s: Session) -> None:
    """The textbook four-bar from nothing: rough clicks, then typed coordinates, lengths, driver and time."""
    ok(s.handle({"op": "add_joint", "x": 1.0, "y": -2.0, "ground": True, "name": "O2"}))
    ok(s.handle({"op": "add_joint", "x": 97.0, "y": 3.0, "ground": True, "name": "O4"}))
    ok(s.handle({"op": "add_joint", "x": 28.0, "y": 27.0, "name": "A"}))
    ok(s.handle({"op": "add_joint", "x": 140.0, "y": 70.0, "name": "B"}))
    for joints in (["O2", "A"], ["A", "B"], ["O4", "B"]):
        ok(s.handle({"op": "add_link", "joints": joints}))
    ok(s.handle({"op": "set_joint", "joint": "O2", "x": 0, "y": 0}))
    ok(s.handle({"op": "set_joint", "joint": "O4", "x": 100, "y": 0}))
    ok(s.handle({"op": "set_meta", "name": "fourbar_textbook_example", "units": "mm"}))
    ok(s.handle({"op": "set_driver", "link": "l2", "omega": 25, "alpha": 15, "theta0": math.radians(40)}))
    for link, length in (("l2", 40), ("l3", 120), ("l4", 80)):
        ok(s.handle({"op": "set_length", "link": link, "length": length}))
    ok(s.handle({"op": "set_time", "start": 0, "stop": 0.5, "step": 0.0025}))


def assert_same_run(a: vloop.Result, b: vloop.Result, rtol: float = 1e-12) -> None:
    """Every column equal within rtol of that column's peak (round-off of the same closed forms)."""
    assert np.array_equal(a.t, b.t)
    assert set(a.columns) == set(b.columns)
    for k, col in a.columns.items():
        scale = max(np.abs(col).max(), np.abs(b.columns[k]).max(), 1e-300)
        assert np.abs(col - b.columns[k]).max() <= rtol * scale, k


def test_a_drawing_made_by_messages_runs_as_the_catalog_file(tmp_path: Path) -> None:
    s = Session(tmp_path)
    draw_textbook(s)
    info = s.frame.info
    assert info["mobility"] == {"L": 4, "J": 4, "M": 1, "drivers": 1}
    assert info["grashof"][0]["class"] == "Grashof crank-rocker"
    assert info["transmission"][0]["dyad"] == "B"
    ok(s.handle({"op": "save", "path": "drawn.toml"}))
    saved = vloop.load(tmp_path / "drawn.toml")
    assert_same_run(vloop.solve(saved), vloop.solve(vloop.load(TEXTBOOK)))
    assert vloop.dumps(vloop.load(tmp_path / "drawn.toml")) == vloop.dumps(saved)  # loading it back: the same


def info_branches(path: Path) -> dict[int, str]:
    """The branch text `vloop info` prints for each loop at t = 0 ("open (B left of A→O4)", "E right of P→O6")."""
    import contextlib
    import io
    import re

    from vloop.cli import main

    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["info", str(path)]) == 0
    found = re.findall(r"loop (\d+) assembly branch at t = 0: sigma = [+-]1: (.+)", out.getvalue())
    return {int(n): text.strip() for n, text in found}


def test_branch_names_come_from_the_loop_text(tmp_path: Path) -> None:
    """The studio names a branch as `vloop info` prints it (the side of the dyad's diagonal at t = 0)."""
    s = Session(tmp_path)
    ok(s.handle({"op": "open", "catalog": "fourbar_crank_rocker_crossed"}))
    names = info_branches(MECHANISMS / "fourbar_crank_rocker_crossed.toml")
    assert names[1].startswith("crossed (") and s.frame.info["loops"][0]["branch"] == names[1]


def test_a_drag_past_a_limit_stops_there_and_says_so(tmp_path: Path) -> None:
    """The drag to d = 250 stops within 2⁻¹² of the move (150 mm · 2⁻¹² = 0.04 mm) below the limit d* where
    d + a = b + c(d) (d* = 147.47 mm), and the reply says why."""
    from scipy.optimize import brentq

    s = Session(tmp_path)
    ok(s.handle({"op": "open", "catalog": "fourbar_textbook_example"}))
    r = ok(s.handle({"op": "drag", "joint": "O4", "x": 250.0, "y": 0.0, "gesture": 1}))
    x = s.doc["joints"]["O4"][0]
    bx, by = 143.18998821048504, 67.33962368753009
    limit = brentq(lambda d: d + 40 - 120 - math.hypot(d - bx, by), 100, 250, xtol=1e-12)
    assert limit - 150 / 2**12 <= x <= limit, (x, limit)
    assert "O4 stopped at" in r["state"]["limit"] and "limit" in r["state"]["limit"]
    assert s.frame.error is None  # what is shown runs
    ok(s.handle({"op": "undo"}))
    assert s.doc["joints"]["O4"] == [100.0, 0.0]
    ok(s.handle({"op": "redo"}))
    assert s.doc["joints"]["O4"][0] == x


def test_a_drag_restates_lengths_and_one_gesture_is_one_undo(tmp_path: Path) -> None:
    s = Session(tmp_path)
    ok(s.handle({"op": "open", "catalog": "fourbar_textbook_example"}))
    for k in range(5):
        ok(s.handle({"op": "drag", "joint": "B", "x": 140.0 + k, "y": 70.0, "gesture": 7}))
    b, a, o4 = (s.frame.mech.joints[j] for j in ("B", "A", "O4"))
    assert s.doc["links"]["l3"]["length"] == pytest.approx(math.dist(a, b), rel=1e-12)
    assert s.doc["links"]["l4"]["length"] == pytest.approx(math.dist(o4, b), rel=1e-12)
    assert len(s.undo) == 2  # the open, then the one gesture
    ok(s.handle({"op": "undo"}))
    assert s.doc["joints"]["B"] == pytest.approx([143.18998821048504, 67.33962368753009], rel=1e-12)


def test_locks_hold(tmp_path: Path) -> None:
    s = Session(tmp_path)
    ok(s.handle({"op": "open", "catalog": "fourbar_textbook_example"}))
    ok(s.handle({"op": "lock", "kind": "joints", "name": "O4"}))
    r = s.handle({"op": "drag", "joint": "O4", "x": 110, "y": 0})
    assert not r["ok"] and "locked" in r["error"]
    ok(s.handle({"op": "lock", "kind": "links", "name": "l4"}))
    ok(s.handle({"op": "drag", "joint": "B", "x": 150, "y": 90, "gesture": 1}))
    assert math.dist(s.frame.mech.joints["B"], (100, 0)) == pytest.approx(80, rel=1e-12)  # B on the rocker's circle
    r = s.handle({"op": "set_length", "link": "l4", "length": 70})
    assert not r["ok"] and "locked" in r["error"]


def test_files_stay_inside_the_folder(tmp_path: Path) -> None:
    root = tmp_path / "work"
    root.mkdir()
    outside = tmp_path / "outside"
    outside.mkdir()
    (root / "out").symlink_to(outside)
    (root / "link.toml").symlink_to(TEXTBOOK)
    s = Session(root)
    ok(s.handle({"op": "open", "catalog": "fourbar_textbook_example"}))
    for path in ("../x.toml", "/tmp/x.toml", "out/x.toml", "link.toml", "a/../../x.toml", "x.py", "", "\x00.toml"):
        r = s.handle({"op": "save", "path": path})
        assert not r["ok"], path
        r = s.handle({"op": "open", "path": path})
        assert not r["ok"], path
    for fmt in ("svg", "dxf"):
        assert not s.handle({"op": "export", "format": fmt, "path": f"out/x.{fmt}"})["ok"]
    assert list(outside.iterdir()) == []
    ok(s.handle({"op": "export", "format": "svg", "path": "x.svg"}))
    assert (root / "x.svg").read_text().lstrip().startswith("<?xml")
    assert sorted(os.listdir(root)) == ["link.toml", "out", "x.svg"]
    assert "link.toml" not in ok(s.handle({"op": "files"}))["files"]


def test_malformed_messages_get_an_error_reply(tmp_path: Path) -> None:
    s = Session(tmp_path)
    for msg in (None, 3, [], {}, {"op": 5}, {"op": "nope"}, {"op": "drag"}, {"op": "add_joint", "x": "a"},
                {"op": "add_joint", "x": float("nan"), "y": 0}, {"op": "add_link", "joints": "AB"},
                {"op": "set_time", "start": 1, "stop": 0, "step": 1}, {"op": "take", "index": 3},
                {"op": "targets", "points": [[1, 2, 3, 4]]}, {"op": "validate"}):  # fmt: skip
        r = s.handle(msg)
        assert r["ok"] is False and isinstance(r["error"], str) and r["error"], msg


def test_a_function_generator_taken_into_the_editor_meets_f(tmp_path: Path) -> None:
    """y = log10(x), x in [1, 2], input 0.5 → 2.0 rad, output 4.0 → 5.5 rad: at the three Chebyshev points
    x_k = 1.5 − 0.5·cos((2k − 1)π/6) the taken linkage, driven from θ₂ = 0.5 rad at 1 rad/s, has its rocker at
    θ_out(x_k) = 4.0 + 1.5·log10(x_k)/log10(2) (Freudenstein's θ₄; vloop's rocker θ runs O4→B, π from it)."""
    s = Session(tmp_path)
    msg = {"op": "synthesize", "kind": "function", "expr": "log10(x)", "x_range": [1, 2], "input_range": [0.5, 2.0],
           "output_range": [4.0, 5.5], "count": 1}  # fmt: skip
    r = ok(s.finish(msg, s.job(msg)()))
    assert len(r["candidates"]) == 1
    ok(s.handle({"op": "take", "index": 0}))
    mech = s.frame.mech
    xk = 1.5 - 0.5 * np.cos((2 * np.arange(1, 4) - 1) * np.pi / 6)
    t_in, t_out = 0.5 + 1.5 * (xk - 1), 4.0 + 1.5 * np.log10(xk) / np.log10(2)
    drv = mech.drivers[0]
    res = vloop.solve(mech, (t_in - drv.x0) / drv.v0)
    gap = np.mod(res.link("rocker").theta - t_out, 2 * np.pi) - np.pi
    assert np.abs(gap).max() <= 1e-9, gap
    with pytest.raises(vloop.VloopError, match=r"synthesize\.expr"):
        s.job({**msg, "expr": "__import__('os')"})


def test_a_slider_crank_drawn_by_messages_runs_as_the_catalog_file(tmp_path: Path) -> None:
    """mechanisms/slider_crank_offset.toml (crank 2, rod 6 m, the guide the line y = 1 along +x, θ₂(0) = 45°,
    ω₂ = 4 rad/s, α₂ = 1 rad/s², 3 s at 10 ms) drawn from nothing: the same run to 1e-12 of each column's peak."""
    s = Session(tmp_path)
    ok(s.handle({"op": "set_meta", "units": "m", "name": "slider_crank_offset"}))
    ok(s.handle({"op": "add_joint", "x": 0.1, "y": 0.0, "ground": True, "name": "O2"}))
    ok(s.handle({"op": "add_joint", "x": 1.3, "y": 1.5, "name": "A"}))
    ok(s.handle({"op": "add_joint", "x": 7.0, "y": 1.2, "name": "B"}))
    ok(s.handle({"op": "add_link", "joints": ["O2", "A"]}))
    ok(s.handle({"op": "add_link", "joints": ["A", "B"]}))
    ok(s.handle({"op": "add_slider", "joint": "B", "angle": 0.0}))
    ok(s.handle({"op": "set_joint", "joint": "O2", "x": 0, "y": 0}))
    ok(s.handle({"op": "set_joint", "joint": "B", "x": 7.0, "y": 1.0}))  # the guide's line: y = 1
    ok(s.handle({"op": "set_time", "start": 0, "stop": 3, "step": 0.01}))
    ok(s.handle({"op": "set_driver", "link": "l2", "omega": 4, "alpha": 1, "theta0": math.radians(45)}))
    for link, length in (("l2", 2), ("l3", 6)):
        ok(s.handle({"op": "set_length", "link": link, "length": length}))
    assert s.frame.error is None and s.frame.draft is None
    ok(s.handle({"op": "save", "path": "slider.toml"}))
    assert_same_run(vloop.solve(vloop.load(tmp_path / "slider.toml")),
                    vloop.solve(vloop.load(MECHANISMS / "slider_crank_offset.toml")))  # fmt: skip


def test_exports_are_the_export_commands_files(tmp_path: Path) -> None:
    """SVG and PDF of the drawing at the displayed sample, DXF parts (with ezdxf): each file a real one of its kind."""
    s = Session(tmp_path)
    ok(s.handle({"op": "open", "catalog": "fourbar_textbook_example"}))
    ok(s.handle({"op": "export", "format": "pdf", "path": "m.pdf", "sample": 100}))
    assert (tmp_path / "m.pdf").read_bytes().startswith(b"%PDF")
    assert not s.handle({"op": "export", "format": "pdf", "path": "m.pdf", "sample": 360})["ok"]
    pytest.importorskip("ezdxf", reason="the export extra is not installed")
    ok(s.handle({"op": "export", "format": "dxf", "path": "m.dxf"}))
    assert "SECTION" in (tmp_path / "m.dxf").read_text()


def test_a_watt_six_bar_with_a_plate_drawn_by_messages_runs_as_the_catalog_file(tmp_path: Path) -> None:
    """mechanisms/sixbar_watt2.toml: the ternary rocker l4 typed as sides O4B = 4, O4C = 3 and the angle B–O4–C =
    −130°, the other lengths typed, the pins clicked within 0.3 m of the catalog's drawing (which picks the branches);
    the same run to 1e-12 of each column's peak."""
    s = Session(tmp_path)
    ok(s.handle({"op": "set_meta", "units": "m", "name": "sixbar_watt2"}))
    for name, x, y in (("O2", 0, 0), ("O4", 5, 0), ("O6", 12, -4)):
        ok(s.handle({"op": "add_joint", "x": x, "y": y, "ground": True, "name": name}))
    for name, x, y in (("A", 1.9, 0.8), ("B", 7.1, 3.5), ("C", 5.6, -2.7), ("D", 9.5, -1.2)):
        ok(s.handle({"op": "add_joint", "x": x, "y": y, "name": name}))
    for joints in (["O2", "A"], ["A", "B"], ["O4", "B", "C"], ["C", "D"], ["O6", "D"]):
        ok(s.handle({"op": "add_link", "joints": joints}))
    assert list(s.doc["links"]) == ["ground", "l2", "l3", "l4", "l5", "l6"]
    ok(s.handle({"op": "set_time", "start": 0, "stop": 4, "step": 0.02}))
    ok(s.handle({"op": "set_driver", "link": "l2", "omega": 2, "alpha": 0.5, "theta0": math.radians(30)}))
    ok(s.handle({"op": "set_sides", "link": "l4", "sides": [4, 3], "angle": math.radians(-130)}))
    for link, length in (("l2", 2), ("l3", 6), ("l5", 4), ("l6", 4)):
        ok(s.handle({"op": "set_length", "link": link, "length": length}))
    names = info_branches(MECHANISMS / "sixbar_watt2.toml")  # the names `vloop info` prints for the catalog's file
    assert s.frame.error is None and {lp["number"]: lp["branch"] for lp in s.frame.info["loops"]} == names
    ok(s.handle({"op": "save", "path": "watt.toml"}))
    assert_same_run(vloop.solve(vloop.load(tmp_path / "watt.toml")),
                    vloop.solve(vloop.load(MECHANISMS / "sixbar_watt2.toml")))  # fmt: skip
