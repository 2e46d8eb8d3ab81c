"""vloop export: the drawing at time T (SVG, PDF) and the links as parts (DXF), with their refusals.

References, independent of the writers:

* DXF: read back with ezdxf; every part's pivot-hole centres are as far apart as the link's stated lengths
  (where the file states them) and as its joints in ``vloop.solve`` at T (a rigid body keeps its distances);
  the assembly layer's centre lines end at the joints ``vloop.solve`` gives at T; $INSUNITS is the file's unit;
* SVG: parsed as XML, every joint and link named in a <text>, no reference outside the file, and rendered by
  headless Chromium with no error and no network request (as tests/test_viewer.py opens pages);
* bad --at values: one line on stderr, exit 2, nothing written.
"""

from __future__ import annotations

import itertools
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import vloop
from vloop.cli import main
from vloop.views.export import DXF_UNITS, configuration, export

from .conftest import MECHANISMS, mechanism_files

ezdxf = pytest.importorskip("ezdxf", reason="DXF export needs ezdxf (pip install -e '.[export]')")
CHROMIUM = Path("/usr/bin/chromium")


def _at(mech: vloop.Mechanism) -> float:
    """An instant inside the run (a third of the way; before a limit where the motion stops)."""
    return float(mech.times[len(mech.times) // 3 if "past_limit" not in mech.name else 10])


@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_dxf_parts_keep_every_pivot_distance(path: Path, tmp_path: Path) -> None:
    mech = vloop.load(path)
    at = _at(mech)
    ref = vloop.solve(mech, times=np.array([at]))
    dxf = export(mech, tmp_path, at, "dxf")
    doc = ezdxf.readfile(dxf)
    assert doc.header["$INSUNITS"] == DXF_UNITS.get(mech.units, 0)
    msp = doc.modelspace()
    tol = 1e-12 * mech.scale
    parts = 0
    for name, lk in mech.links.items():
        joints = [j for j in lk.joints if not lk.ground or len(mech.bodies_at(j)) > 1]
        if len(joints) < 2:
            continue
        parts += 1
        holes = [complex(c.dxf.center.x, c.dxf.center.y) for c in msp.query(f'CIRCLE[layer=="PART-{name}"]')]
        assert len(holes) == len(joints), name
        got = sorted(abs(a - b) for a, b in itertools.combinations(holes, 2))
        p = {j: complex(ref[f"{j}.x"][0], ref[f"{j}.y"][0]) for j in joints}
        want = sorted(abs(p[a] - p[b]) for a, b in itertools.combinations(joints, 2))
        assert np.allclose(got, want, rtol=0, atol=1e-9 * mech.scale), (name, got, want)
        if lk.length is not None:
            assert abs(got[0] - lk.length) <= tol, name
        radii = {c.dxf.radius for c in msp.query(f'CIRCLE[layer=="PART-{name}"]')}
        assert len(radii) == 1 and 0 < radii.pop() < 0.1 * mech.scale, name
    assert parts >= 1
    ends = {complex(e.dxf.start.x, e.dxf.start.y) for e in msp.query('LINE[layer=="ASSEMBLY"]')}
    ends |= {complex(e.dxf.end.x, e.dxf.end.y) for e in msp.query('LINE[layer=="ASSEMBLY"]')}
    at_joints = [complex(ref[f"{j}.x"][0], ref[f"{j}.y"][0]) for j in mech.joints]
    assert all(min(abs(e - p) for p in at_joints) <= 1e-9 * mech.scale for e in ends)


def test_dxf_ternary_plate_by_hand(tmp_path: Path) -> None:
    """The Watt II's rocker l4: O4B = 4, O4C = 3, BC by the law of cosines with the 130° between them (m)."""
    mech = vloop.load(MECHANISMS / "sixbar_watt2_dimensions.toml")
    doc = ezdxf.readfile(export(mech, tmp_path, 1.0, "dxf"))
    holes = [complex(c.dxf.center.x, c.dxf.center.y) for c in doc.modelspace().query('CIRCLE[layer=="PART-l4"]')]
    bc = math.sqrt(4**2 + 3**2 - 2 * 4 * 3 * math.cos(math.radians(130)))
    got = sorted(abs(a - b) for a, b in itertools.combinations(holes, 2))
    assert np.allclose(got, sorted([4.0, 3.0, bc]), rtol=0, atol=1e-12)
    assert doc.header["$INSUNITS"] == 6  # metres


@pytest.mark.parametrize("stem", ["eightbar", "whitworth_quick_return", "jansen_pair", "sixbar_watt2_dimensions"])
def test_svg_is_xml_names_everything_and_is_the_same_every_time(stem: str, tmp_path: Path) -> None:
    mech = vloop.load(MECHANISMS / f"{stem}.toml")
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    first, second = export(mech, tmp_path / "a", 0.5, "svg"), export(mech, tmp_path / "b", 0.5, "svg")
    text = first.read_text(encoding="utf-8")
    assert text == second.read_text(encoding="utf-8")
    root = ET.fromstring(text)
    assert root.tag == "{http://www.w3.org/2000/svg}svg"
    words = {"".join(t.itertext()).strip() for t in root.iter("{http://www.w3.org/2000/svg}text")}
    assert set(mech.tracked_points) <= words and {n for n, lk in mech.links.items() if not lk.ground} <= words
    assert set(mech.sliders) <= words
    scrubbed = re.sub(r'(xmlns(:\w+)?="|"-//W3C//DTD SVG 1\.1//EN"\s+")http://www\.w3\.org/[^"]*"', "", text)
    assert not re.search(r"https?://|//cdn|@import|url\((?!#)", scrubbed)  # only namespace names: no request


def test_pdf_is_a_pdf_and_the_same_every_time(tmp_path: Path) -> None:
    mech = vloop.load(MECHANISMS / "eightbar.toml")
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    a, b = export(mech, tmp_path / "a", 1.0, "pdf"), export(mech, tmp_path / "b", 1.0, "pdf")
    assert a.read_bytes()[:5] == b"%PDF-" and a.read_bytes() == b.read_bytes()


def test_svg_renders_in_chromium_without_errors(tmp_path: Path) -> None:
    if not CHROMIUM.exists():
        pytest.skip("Debian's chromium is not installed at /usr/bin/chromium")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    files = []
    for stem in ("eightbar", "whitworth_quick_return", "jansen_pair"):
        (tmp_path / stem).mkdir()
        files.append(export(vloop.load(MECHANISMS / f"{stem}.toml"), tmp_path / stem, 0.5, "svg"))
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=["--headless", "--no-sandbox"])
        page = browser.new_page(viewport={"width": 900, "height": 700})
        problems, requests = [], []
        page.on("console", lambda m: m.type in ("error", "warning") and problems.append(m.text))
        page.on("pageerror", lambda e: problems.append(str(e)))

        def route(r) -> None:
            if r.request.url.startswith("file:"):
                r.continue_()
            else:
                requests.append(r.request.url)
                r.abort()

        page.route("**/*", route)
        for f in files:
            page.goto(f.resolve().as_uri())
            box = page.locator("svg").first.bounding_box()
            assert box is not None and box["width"] > 200 and box["height"] > 50
            shot = page.screenshot()
            assert len(shot) > 5_000  # drawn, not blank
            assert page.locator("text").count() >= 5
        browser.close()
    assert problems == [] and requests == []


@pytest.mark.parametrize(
    "at", ["nan", "inf", "-inf", "-1", "2.36", "1e308", "1e400", "10" * 200, "abc", "", "0x1p-3", "[1]", "[[0.5]]"]
)
def test_bad_at_is_one_line_and_exit_2(at: str, tmp_path: Path, capsys) -> None:
    out = tmp_path / "o"
    assert main(["export", str(MECHANISMS / "eightbar.toml"), f"--at={at}", "--format", "svg", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--at" in err and "Traceback" not in err, err
    assert not out.exists() or not any(out.iterdir())


def test_at_the_ends_of_the_run_and_a_motion_that_stops_before_it(tmp_path: Path, capsys) -> None:
    path = MECHANISMS / "eightbar.toml"
    for at in ("0", "-0", "5e-324", "2.35"):
        assert main(["export", str(path), "--at", at, "--format", "pdf", "--out", str(tmp_path / at)]) == 0
        assert (tmp_path / at / "eightbar.pdf").is_file()
    capsys.readouterr()
    stopped = MECHANISMS / "fourbar_nongrashof_past_limit.toml"
    assert main(["export", str(stopped), "--at", "2.5", "--format", "dxf", "--out", str(tmp_path / "s")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the input is past a limit position" in err
    assert not any((tmp_path / "s").iterdir())


def test_the_one_sample_configuration_is_the_run_at_that_time() -> None:
    mech = vloop.load(MECHANISMS / "whitworth_quick_return.toml")
    run = vloop.solve(mech)
    k = 37
    one = configuration(mech, run.t[k])
    for name, col in run.columns.items():
        assert abs(one[name][0] - col[k]) <= 1e-9 * max(1.0, np.abs(col).max()), name


@pytest.mark.parametrize("hole", [0, -0.0, 1e308, float("nan"), float("inf"), 10**400, "x", [[1.0]], True])
def test_bad_hole_diameters_are_refused(hole: object, tmp_path: Path) -> None:
    from vloop.views.export import ExportError, write_dxf

    mech = vloop.load(MECHANISMS / "eightbar.toml")
    with pytest.raises(ExportError, match="a diameter greater than 0"):
        write_dxf(mech, configuration(mech, 1.0), tmp_path / "x.dxf", hole=hole)
    assert not (tmp_path / "x.dxf").exists()
