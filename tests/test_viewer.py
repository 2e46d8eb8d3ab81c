"""The interactive viewer: its geometry, its page data, and the page itself in real headless Chromium.

References used here are independent of the page's own drawing code:

* joint positions, velocities and accelerations from ``vloop.solve`` run separately at t = 1.0 s
  (the page draws from the Result it was given);
* each body's joint coordinates in its own frame from ``Mechanism.bodies()`` (the test composes
  them with the SVG transform it reads back: what is drawn must reach the joints);
* the eight-bar's loop vectors at t = 0 written out by hand from the paper's Table 1
  (a = 3, b = 5, c = 4; θ2 = π/2);
* for the loop chains, the Result's joint columns (the chain is built from the θ and s columns only).

Tolerances: the page writes every number with JavaScript's shortest round-trip form, so drawn
positions equal the Result's to round-off (~1e-15 of the size); the claim is 1e-6 of the
mechanism size, which also absorbs the 2e-16 s between t[20] = 20·0.05 and 1.0. Chains are built
with a different summation order than the solver's positions: 1e-12 of the size.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pytest

import vloop
from vloop.cli import main
from vloop.method.equations import describe
from vloop.views.geometry import body_poses, loop_chains
from vloop.views.view import ViewError, build_payload, inline, render, solve_for_view, unpack, write_view

from .conftest import MECHANISMS, mechanism_files

CHROMIUM = Path("/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--no-first-run", "--disable-sync",
]  # fmt: skip
EIGHTBAR = MECHANISMS / "eightbar.toml"
STOPPED = MECHANISMS / "fourbar_nongrashof_past_limit.toml"
T_CHECK = 1.0  # s: the instant the checks read


@pytest.fixture(scope="module")
def eightbar() -> tuple[vloop.Mechanism, vloop.Result]:
    mech = vloop.load(EIGHTBAR)
    return mech, vloop.solve(mech)


class FakeForces:
    """The forces interface the viewer accepts, with made-up smooth values [N, N·m]."""

    def __init__(self, result: vloop.Result) -> None:
        t = result.t
        self.t = t.copy()
        self.columns = {
            "l2.torque": 12.0 * np.sin(3 * t) + 4.0,
            "A:l2>l3.fx": 40.0 * np.cos(3 * t),
            "A:l2>l3.fy": 25.0 * np.sin(3 * t) - 10.0,
            "A:l2>l3.mag": np.hypot(40.0 * np.cos(3 * t), 25.0 * np.sin(3 * t) - 10.0),
            "B:l3>l4.fx": -30.0 + 5 * t,
            "B:l3>l4.fy": 15.0 * np.cos(2 * t),
            "l4.normal": 15.0 * np.cos(2 * t),
            "shaking.fx": np.sin(t),
            "shaking.fy": np.cos(t),
            "shaking.moment": 0.5 * t,
        }
        self.arrows = [("A", "A:l2>l3.fx", "A:l2>l3.fy", "F23"), ("B", "B:l3>l4.fx", "B:l3>l4.fy", "F34")]


# ------------------------------------------------------------------ geometry (no browser)


@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_loop_chains_close_and_pass_through_the_joints(path: Path) -> None:
    mech = vloop.load(path)
    system = vloop.compile(mech)
    result, _ = solve_for_view(mech)
    chains = loop_chains(system, result)
    assert len(chains) == len(system.loops) >= 1
    printed = [line for line in describe(system).splitlines() if line.startswith("loop ")]
    tol = 1e-12 * mech.scale
    for chain in chains:
        z = chain.vertices
        assert z.shape == (len(result), len(chain.vectors) + 1)
        closure = np.abs(z[:, -1] - z[:, 0]).max()
        assert closure <= tol, f"loop {chain.number} does not close: {closure / mech.scale:.2g} of the size"
        names = [j for _, j in chain.joints]
        assert set(names) >= {j for j in chain.label.split("–") if j in mech.joints and j != chain.start} - {"O"}
        for k, joint in chain.joints:
            drawn = z[:, k]
            solved = result[f"{joint}.x"] + 1j * result[f"{joint}.y"]
            assert np.abs(drawn - solved).max() <= tol, f"loop {chain.number}: vertex {k} is not on {joint}"
        assert f"loop {chain.number} ({chain.label}):  {chain.equation}" in printed
        assert all(v.letter for v in chain.vectors)


def test_eightbar_loops_by_hand() -> None:
    """Paper, Table 1 at t = 0: θ2 = 90°, A = (0, 3), B = (4, 0), C = (8, k), D = (8, −k), k = √(6.15² − 4²)."""
    mech = vloop.load(EIGHTBAR)
    result = vloop.solve(mech, times=np.array([0.0]))
    chains = loop_chains(vloop.compile(mech), result)
    k = math.sqrt(6.15**2 - 4**2)
    expected = {
        1: [0, 3j, 4, 0],  # a·e^{jθ2} + b·e^{jθ3} + c·e^{jπ} = 0: O2 → A → B → O2
        2: [0, 4, 8 + k * 1j, 8, 0],  # c, d to C, f down the line x = 8 by k, g back along x
        3: [0, 4, 8 - k * 1j, 8, 0],
    }
    for chain in chains:
        assert np.allclose(chain.vertices[0], expected[chain.number], atol=1e-12), chain.number
    assert [v.letter for v in chains[0].vectors] == ["a", "b", "c"]
    assert [(v.link, v.slider, v.r) for v in chains[0].vectors][:2] == [("l2", None, 3.0), ("l3", None, 5.0)]
    assert chains[0].vectors[2].slider == "l4"


@pytest.mark.parametrize("name", ["eightbar", "whitworth_quick_return", "sixbar_watt2", "inverted_slider_crank"])
def test_bodies_drawn_in_their_frames_reach_their_joints(name: str) -> None:
    """pose(t) ∘ (body-frame coordinates from the file) = the solved joint positions: the drawing is rigid."""
    mech = vloop.load(MECHANISMS / f"{name}.toml")
    result = vloop.solve(mech)
    poses = body_poses(mech, result)
    for body in mech.bodies().values():
        x, y, th = poses[body.name].T
        for joint, (lx, ly) in body.local.items():
            wx = x + np.cos(th) * lx - np.sin(th) * ly
            wy = y + np.sin(th) * lx + np.cos(th) * ly
            err = np.hypot(wx - result[f"{joint}.x"], wy - result[f"{joint}.y"]).max()
            assert err <= 1e-9 * mech.scale, f"{body.name} misses {joint} by {err:.3g}"


# ------------------------------------------------------------------ page data (no browser)


def test_payload_numbers_are_the_results_exactly(eightbar) -> None:
    mech, result = eightbar
    data = build_payload(mech, result)
    cols = unpack(data["data"])
    assert np.array_equal(cols["t"], result.t)
    for name, values in result.columns.items():
        assert np.array_equal(cols[name], values), name  # bit for bit: every sample, no decimation
    assert np.array_equal(cols["health.cond"], result.health["cond"])
    assert all(np.isfinite(v).all() for v in cols.values())
    assert data["samples"] == len(result) == 48


def test_page_sizes_within_budget(eightbar) -> None:
    mech, result = eightbar
    assert len(render(mech, result).encode()) < 1_000_000
    for name in ("eightbar", "jansen_pair"):
        m = vloop.load(MECHANISMS / f"{name}.toml")
        big = vloop.solve(m, times=np.linspace(m.times[0], m.times[-1], 5000))
        size = len(render(m, big).encode())
        assert size < 5_000_000, f"{name} at 5,000 samples: {size / 1e6:.2f} MB"


def test_page_is_deterministic_and_offline(eightbar) -> None:
    mech, result = eightbar
    page = render(mech, result, forces=FakeForces(result))
    assert page == render(mech, result, forces=FakeForces(result))
    assert _offline_problems(page) == []  # a CSP; the SVG namespace is a name, not a request
    assert page.count("<script") == 2  # the data (not executed) and the viewer


def _offline_problems(page: str) -> list[str]:
    """What makes a page not offline: a missing CSP, an address, an import or a url() (the SVG namespace is a name)."""
    problems = [] if "default-src 'none'" in page and "script-src 'sha256-" in page else ["no CSP"]
    scrubbed = page.replace('"http://www.w3.org/2000/svg"', "")
    return problems + re.findall(r"https?://|//cdn|@import|url\(", scrubbed)


def test_inline_viewer_is_the_page_in_a_sandboxed_frame(eightbar) -> None:
    """For a notebook: the same page, whole, in an iframe's srcdoc, sandboxed to scripts only (no same origin)."""
    import html as html_module

    mech, result = eightbar
    cell = inline(mech, result)._repr_html_()
    frame = re.fullmatch(
        r'<iframe title="vloop viewer" sandbox="allow-scripts" style="[^"]*" srcdoc="([^"]*)"></iframe>', cell
    )
    assert frame is not None and "allow-same-origin" not in cell
    page = html_module.unescape(frame.group(1))
    assert page == render(mech, result)
    assert _offline_problems(page) == []  # the same check as every vloop view page
    assert not re.search(r"https?://|//cdn|@import|url\(", cell.replace(frame.group(1), ""))  # and its frame
    with pytest.raises(ViewError, match="height must be"):
        inline(mech, result, height=10**400)
    stopped = inline(vloop.load(STOPPED))  # solved here: the page shows where it stopped
    assert "cannot assemble at t = 1.73 s" in html_module.unescape(stopped._repr_html_())


def test_hostile_title_and_names_stay_text(tmp_path: Path) -> None:
    text = EIGHTBAR.read_text(encoding="utf-8").replace(
        'title = "Eight-bar', 'title = "</script><script>alert(1)</script> /*__JS__*/ __DATA__ & Eight-bar'
    )
    mech = vloop.loads(text, source=str(tmp_path / "eightbar.toml"))
    page = render(mech, vloop.solve(mech))
    assert page.count("<script") == 2 and "alert(1)</script>" not in page.split('id="vloop-data">')[0]
    assert "&lt;/script&gt;&lt;script&gt;alert(1)" in page  # the heading, escaped
    data = page.split('id="vloop-data">', 1)[1].split("</script>", 1)[0]
    assert "</script" not in data and "\\u003c/script\\u003e" in data


def test_non_finite_values_are_refused(eightbar) -> None:
    mech, result = eightbar
    bad = result.head(len(result))
    bad.columns["l5.omega"] = bad.columns["l5.omega"].copy()
    bad.columns["l5.omega"][7] = np.nan
    with pytest.raises(ViewError, match=r"l5\.omega is not finite at sample 7 \(t = 0\.35 s\)"):
        render(mech, bad)
    forces = FakeForces(result)
    forces.columns["B:l3>l4.fy"] = forces.columns["B:l3>l4.fy"].copy()
    forces.columns["B:l3>l4.fy"][3] = np.inf
    with pytest.raises(ViewError, match=r"force:B:l3>l4\.fy is not finite at sample 3"):
        render(mech, result, forces=forces)


def test_forces_must_match_the_run(eightbar) -> None:
    mech, result = eightbar
    forces = FakeForces(result)
    forces.t = forces.t[:-1]
    with pytest.raises(ViewError, match="not given at the result's 48 samples"):
        render(mech, result, forces=forces)
    forces = FakeForces(result)
    forces.arrows = [("Q", "B:l3>l4.fx", "B:l3>l4.fy", "F")]
    with pytest.raises(ViewError, match="no such joint"):
        render(mech, result, forces=forces)
    forces.arrows = [("B", "B:l3>l4.fx", "nope.fy", "F")]
    with pytest.raises(ViewError, match=r"no column 'nope\.fy'"):
        render(mech, result, forces=forces)


class _Forces:
    def __init__(self, t, columns, arrows=()) -> None:
        self.t, self.columns, self.arrows = t, columns, list(arrows)


@pytest.mark.parametrize(
    ("t", "column", "arrows", "message"),
    [
        (None, ["a"] * 48, (), r"force:x is not an array of numbers"),
        (None, [[1.0, 2.0]] * 48, (), r"force:x has shape \(48, 2\), expected \(48,\)"),
        (None, np.full(48, np.inf), (), r"force:x is not finite at sample 0"),
        (None, [10**400] * 48, (), r"force:x is not an array of numbers"),
        (None, np.full(48, 1e308), (), None),
        (None, np.full(48, 5e-324), (), None),  # subnormal: finite, accepted
        (None, np.full(48, -0.0), (), None),
        (np.full(48, np.nan), np.zeros(48), (), r"not given at the result's 48 samples"),
        ("abc", np.zeros(48), (), r"forces\.t is not an array of numbers"),
        (None, np.zeros(48), [("A", "x")], r"force arrow 0: expected \(point, fx column, fy column, label\)"),
        (None, np.zeros(48), [("A", "x", ["x"], "F")], r"force arrow 0: expected"),
    ],
)
def test_hostile_forces(eightbar, t, column, arrows, message) -> None:
    mech, result = eightbar
    forces = _Forces(result.t if t is None else t, {"x": column}, arrows)
    if message is None:
        assert "force:x" in build_payload(mech, result, forces=forces)["data"]["columns"]
    else:
        with pytest.raises(ViewError, match=message):
            build_payload(mech, result, forces=forces)


# ------------------------------------------------------------------ command line


def test_view_command_writes_the_page(tmp_path: Path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(tmp_path)
    assert main(["view", str(EIGHTBAR)]) == 0
    page = tmp_path / "out" / "eightbar" / "eightbar.html"
    assert page.is_file() and "wrote out/eightbar/eightbar.html" in capsys.readouterr().out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]
    assert main(["run", str(EIGHTBAR), "--out", "r", "--html"]) == 0
    assert (tmp_path / "r" / "eightbar.html").read_text(encoding="utf-8") == page.read_text(encoding="utf-8")


def test_view_command_on_a_stopped_motion(tmp_path: Path, capsys) -> None:
    assert main(["view", str(STOPPED), "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("vloop: error: fourbar_nongrashof_past_limit: cannot assemble at t = 1.73 s")
    assert "the page shows the motion up to its last assembled instant" in err and "Traceback" not in err
    data = _data_of(tmp_path / "fourbar_nongrashof_past_limit.html")
    assert data["samples"] == 173 and "cannot assemble at t = 1.73 s" in data["error"]
    assert main(["run", str(STOPPED), "--out", str(tmp_path / "run"), "--html"]) == 2
    assert (tmp_path / "run" / "fourbar_nongrashof_past_limit.html").is_file()


def test_view_command_bad_file(tmp_path: Path, capsys) -> None:
    bad = tmp_path / "bad.toml"
    bad.write_text('[joints]\nA = [0, "x"]\n', encoding="utf-8")
    assert main(["view", str(bad), "--out", str(tmp_path)]) == 2
    assert "vloop: error:" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.html"))


def test_view_command_opens_the_browser_only_when_asked(tmp_path: Path, monkeypatch) -> None:
    import webbrowser

    opened: list[str] = []
    monkeypatch.setattr(webbrowser, "open", lambda uri, *a, **k: opened.append(uri))
    assert main(["view", str(EIGHTBAR), "--out", str(tmp_path)]) == 0
    assert opened == []
    assert main(["view", str(EIGHTBAR), "--out", str(tmp_path), "--open"]) == 0
    assert opened == [(tmp_path / "eightbar.html").resolve().as_uri()]


def _chain(tmp_path: Path, dyads: int, samples: int) -> Path:
    """A chain of ``dyads`` RRR dyads on a crank (benchmarks/bench_compile.py) over ``samples`` samples."""
    import sys as _sys

    _sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
    from bench_compile import dyad_chain

    data = vloop.mechanism.to_dict(dyad_chain(dyads))
    data["time"] = {"start": 0.0, "stop": 1.0, "step": 1.0 / (samples - 1)}
    path = tmp_path / "chain.toml"
    vloop.save(vloop.from_dict(data), path)
    return path


def test_a_long_runs_page_is_bounded_by_its_bytes(tmp_path: Path, monkeypatch, capsys) -> None:
    """A page holds at most MAX_PAGE_BYTES of sample data (worst case 8·4/3 bytes a value): a longer run is solved
    at every sample and the page carries every k-th one and the last, with the exact values of those samples
    (a direct solve at the same instants agrees to 1e-12 of each column's peak) and a note that says so."""
    from vloop.views import view

    monkeypatch.setattr(view, "MAX_PAGE_BYTES", 1 << 20)
    f = _chain(tmp_path, 5, 20_001)
    assert main(["view", str(f), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    page = tmp_path / "o" / "chain5.html"
    data = _data_of(page)
    thin = data["thinned"]
    n_cols = len(data["data"]["columns"])
    assert thin["of"] == 20_001 and thin["every"] > 1
    assert thin["shown"] * n_cols * view.VALUE_BYTES <= 1 << 20  # the bound, from the estimate's own terms
    assert f"20001 samples (the page carries {thin['shown']})" in out
    cols = unpack(data["data"])
    rows = view.page_rows(20_001, thin["every"])
    assert len(cols["t"]) == thin["shown"] == len(rows) and rows[-1] == 20_000
    mech = vloop.load(f)
    assert np.array_equal(cols["t"], mech.times[rows])
    direct = vloop.solve(mech, times=mech.times[rows])
    for name, ref in direct.columns.items():
        assert np.max(np.abs(cols[name] - ref)) <= 1e-12 * max(np.max(np.abs(ref)), 1.0), name
    assert "carries" in (Path(view.__file__).parent / "viewer" / "viewer.js").read_text()
    small = view.build_payload(vloop.load(EIGHTBAR), vloop.solve(vloop.load(EIGHTBAR)))
    assert small["thinned"] is None  # a page that fits carries every sample


@pytest.mark.slow
def test_a_41_link_chain_at_100000_samples_gives_a_bounded_page(tmp_path: Path, capsys) -> None:
    """The case that wrote a 137 MiB page: now at most MAX_PAGE_BYTES of data plus the page's fixed part."""
    from vloop.views import view

    f = _chain(tmp_path, 20, 100_000)
    assert len(vloop.load(f).links) == 42  # 41 moving links and the ground
    assert main(["view", str(f), "--out", str(tmp_path / "o")]) == 0
    size = (tmp_path / "o" / "chain20.html").stat().st_size
    assert size <= view.MAX_PAGE_BYTES + (2 << 20), size
    assert _data_of(tmp_path / "o" / "chain20.html")["thinned"]["of"] == 100_000


def _data_of(path: Path) -> dict:
    import json

    text = path.read_text(encoding="utf-8")
    return json.loads(text.split('id="vloop-data">', 1)[1].split("</script>", 1)[0])


# ------------------------------------------------------------------ in a real browser


@dataclass
class Opened:
    page: object
    url: str
    requests: list[str] = field(default_factory=list)
    problems: list[str] = field(default_factory=list)


@pytest.fixture(scope="module")
def browser():
    if not CHROMIUM.exists():
        pytest.skip("Debian's chromium is not installed at /usr/bin/chromium (apt-get install chromium; .ci/run does)")
    sync_api = pytest.importorskip(
        "playwright.sync_api", reason="playwright is not installed (pip install -e '.[dev]')"
    )
    with sync_api.sync_playwright() as pw:
        b = pw.chromium.launch(executable_path=str(CHROMIUM), args=CHROMIUM_ARGS)
        yield b
        b.close()


@pytest.fixture
def open_page(browser):
    """Open a page from file:// with every other request recorded and aborted, console errors collected."""
    contexts = []

    def _open(path: Path, *, dark: bool = False, bypass_csp: bool = True) -> Opened:
        ctx = browser.new_context(
            viewport={"width": 1400, "height": 1000}, color_scheme="dark" if dark else "light", bypass_csp=bypass_csp
        )
        contexts.append(ctx)
        opened = Opened(ctx.new_page(), path.resolve().as_uri())

        def route(r) -> None:
            if r.request.url == opened.url:
                r.continue_()
            else:
                opened.requests.append(r.request.url)
                r.abort()

        ctx.route("**/*", route)
        page = opened.page
        page.on("console", lambda m: m.type in ("error", "warning") and opened.problems.append(f"{m.type}: {m.text}"))
        page.on("pageerror", lambda e: opened.problems.append(f"pageerror: {e}"))
        page.goto(opened.url)
        page.wait_for_selector("body[data-ready]", state="attached", timeout=20_000)  # no eval: the CSP forbids it
        return opened

    yield _open
    for ctx in contexts:
        ctx.close()


@pytest.fixture(scope="module")
def eightbar_page(tmp_path_factory, eightbar) -> Path:
    mech, result = eightbar
    return write_view(mech, result, tmp_path_factory.mktemp("viewer") / "eightbar.html", forces=FakeForces(result))


def _xy(page, selector: str, attrs=("cx", "cy")) -> tuple[float, float]:
    el = page.locator(selector)
    x, y = (float(el.get_attribute(a)) for a in attrs)
    return x, -y  # SVG y points down


def _tip(d: str) -> tuple[float, float]:
    """An arrow path's tip (its fourth point: shaft start, shaft end, head corner, tip, head corner), model units."""
    nums = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:e[-+]?\d+)?", d)]
    return nums[6], -nums[7]


def _set_time_slider(page, index: int) -> None:
    """What dragging the slider does: set its value and fire 'input'."""
    page.locator("#time").evaluate(
        "(el, i) => { el.value = String(i); el.dispatchEvent(new Event('input', {bubbles: true})); }", index
    )


def test_drawn_joints_match_an_independent_solve(open_page, eightbar_page, eightbar) -> None:
    mech, result = eightbar
    k = int(np.argmin(np.abs(result.t - T_CHECK)))
    ref = vloop.solve(mech, times=np.array([T_CHECK]))
    tol = 1e-6 * mech.scale
    o = open_page(eightbar_page)
    page = o.page
    _set_time_slider(page, k)
    assert page.evaluate("vloopViewer.index") == k
    assert page.locator("#time-text").text_content().startswith("t = 1 s")
    for joint in "ABCD":
        x, y = _xy(page, f'circle[data-joint="{joint}"]')
        assert math.hypot(x - ref[f"{joint}.x"][0], y - ref[f"{joint}.y"][0]) <= tol, joint
    # the links themselves: each body's transform applied to its joints' body-frame coordinates
    for body in mech.bodies().values():
        if body.kind == "ground":
            continue
        tf = page.locator(f'g[data-body="{body.name}"]').get_attribute("transform")
        tx, ty, deg = (float(v) for v in re.fullmatch(r"translate\((\S+) (\S+)\) rotate\((\S+)\)", tf).groups())
        x0, y0, th = tx, -ty, -math.radians(deg)
        for joint, (lx, ly) in body.local.items():
            wx = x0 + math.cos(th) * lx - math.sin(th) * ly
            wy = y0 + math.sin(th) * lx + math.cos(th) * ly
            assert math.hypot(wx - ref[f"{joint}.x"][0], wy - ref[f"{joint}.y"][0]) <= tol, (body.name, joint)
    # the numbers panel holds the run's own values at this sample, to the last bit
    for col in ("l3.theta", "l5.omega", "l7.alpha", "l4.s", "l6.v", "l8.a", "C.ay"):
        cell = page.locator(f'td[data-col="{col}"]').first
        assert float(cell.get_attribute("data-value")) == result[col][k], col
        assert abs(float(cell.get_attribute("data-value")) - ref[col][0]) <= 1e-9 * max(1, abs(ref[col][0])), col
    assert o.requests == [] and o.problems == []


def test_overlays_draw_what_they_claim(open_page, eightbar_page, eightbar) -> None:
    mech, result = eightbar
    k = int(np.argmin(np.abs(result.t - T_CHECK)))
    ref = vloop.solve(mech, times=np.array([T_CHECK]))
    forces = FakeForces(result)
    tol = 1e-6 * mech.scale
    o = open_page(eightbar_page)
    page = o.page
    page.evaluate(f"vloopViewer.setIndex({k})")

    def shown(layer: str) -> bool:
        return page.locator(f'g[data-layer="{layer}"]').get_attribute("display") != "none"

    for layer in ("vel", "acc", "paths", "forces"):
        assert not shown(layer)
        page.click(f'[data-overlay="{layer}"]')
        assert shown(layer) and page.locator(f'[data-overlay="{layer}"]').get_attribute("aria-pressed") == "true"
    # loops (on at start): every vector's tip is the chain's vertex computed in Python
    assert shown("loops")
    for chain in loop_chains(vloop.compile(mech), result):
        arrows = page.locator(f'g[data-loop="{chain.number}"] path.v-arrow')
        assert arrows.count() == len(chain.vectors)
        for n in range(arrows.count()):
            tip = _tip(arrows.nth(n).get_attribute("d"))
            want = chain.vertices[k, n + 1]
            assert abs(complex(*tip) - want) <= tol, (chain.number, n)
    assert page.locator("#loop-legend .row").count() == 3
    assert "a·e" in page.locator("#loop-legend").text_content()
    # velocity and acceleration arrows: tip = point + scale × vector, the scale read from the legend
    for layer, (qx, qy) in (("vel", ("vx", "vy")), ("acc", ("ax", "ay"))):
        scale = float(page.locator(f'[data-scale-for="{layer}"]').get_attribute("data-scale"))
        for joint in "ABCD":
            tip = _tip(page.locator(f'g[data-layer="{layer}"] path[data-point="{joint}"]').get_attribute("d"))
            want = (
                ref[f"{joint}.x"][0] + scale * ref[f"{joint}.{qx}"][0],
                ref[f"{joint}.y"][0] + scale * ref[f"{joint}.{qy}"][0],
            )
            assert math.dist(tip, want) <= tol, (layer, joint)
    # reaction arrows from the (fake) forces
    scale = float(page.locator('[data-scale-for="forces"]').get_attribute("data-scale"))
    for point, fx, fy, label in forces.arrows:
        tip = _tip(page.locator(f'path[data-force="{label}"]').get_attribute("d"))
        want = (
            result[f"{point}.x"][k] + scale * forces.columns[fx][k],
            result[f"{point}.y"][k] + scale * forces.columns[fy][k],
        )
        assert math.dist(tip, want) <= tol, label
    # joint paths: one curve per moving point, starting where the point starts
    paths = page.locator('g[data-layer="paths"] path')
    assert paths.count() == 4  # A, B, C, D move; O2 does not
    d = page.locator('path[data-path="C"]').get_attribute("d")
    x0, y0 = (float(v) for v in re.match(r"M(\S+) (\S+)L", d).groups())
    assert math.hypot(x0 - result["C.x"][0], -y0 - result["C.y"][0]) <= tol
    # the driver-torque plot and the numbers panel's forces
    assert page.locator('[data-plot="driver torque on l2:"] path.curve').count() == 1
    cell = page.locator('td[data-col="force:B:l3>l4.fx"]')
    assert float(cell.get_attribute("data-value")) == forces.columns["B:l3>l4.fx"][k]
    # and off again
    for layer in ("loops", "vel", "acc", "paths", "forces", "labels"):
        page.click(f'[data-overlay="{layer}"]')
        assert page.locator(f'g[data-layer="{layer}"]').get_attribute("display") == "none"
    assert o.requests == [] and o.problems == []


def test_plots_follow_the_cursor_and_move_the_time(open_page, eightbar_page) -> None:
    o = open_page(eightbar_page)
    page = o.page
    cursor = page.locator('[data-plot="Links:theta"] .cursor')
    x_start = float(cursor.get_attribute("data-x"))
    page.focus("#time")
    for _ in range(30):
        page.keyboard.press("ArrowRight")
    assert page.evaluate("vloopViewer.index") == 30
    x_30 = float(cursor.get_attribute("data-x"))
    box = page.locator('[data-plot="Links:theta"]').bounding_box()
    assert cursor.bounding_box()["x"] + 0.75 == pytest.approx(box["x"] + x_30, abs=0.5)  # drawn where it says
    assert x_30 > x_start and cursor.get_attribute("data-index") == "30"
    # every plot's cursor sits at the same time
    for plot in page.locator("[data-plot] .cursor").all():
        assert plot.get_attribute("data-index") == "30"
    # clicking a plot where sample 30 is drawn brings the time back there
    page.keyboard.press("Home")
    assert page.evaluate("vloopViewer.index") == 0
    svg = page.locator('[data-plot="Links:theta"] svg')
    box = svg.bounding_box()
    width = float(svg.get_attribute("viewBox").split()[2])
    page.mouse.move(box["x"] + x_30 * box["width"] / width, box["y"] + box["height"] / 2)
    tip = page.locator('[data-plot="Links:theta"] .tooltip')
    assert tip.is_visible() and "rad" in tip.text_content() and "t = 1.5 s" in tip.text_content()
    page.mouse.click(box["x"] + x_30 * box["width"] / width, box["y"] + box["height"] / 2)
    assert page.evaluate("vloopViewer.index") == 30
    # space plays and pauses; playing moves the time forward
    page.keyboard.press("Home")
    page.keyboard.press("Space")
    assert page.evaluate("vloopViewer.playing")
    page.wait_for_function("vloopViewer.index >= 3", timeout=5000)
    page.keyboard.press("Space")
    assert not page.evaluate("vloopViewer.playing")
    assert o.requests == [] and o.problems == []


def test_playback_zoom_and_single_loops(open_page, eightbar_page, eightbar) -> None:
    n = len(eightbar[1])
    o = open_page(eightbar_page)
    page = o.page
    page.select_option("#speed", "5")
    # repeat (on by default): playing past the end starts again from the beginning
    page.evaluate(f"vloopViewer.setIndex({n - 2}); vloopViewer.play()")
    page.wait_for_function(f"vloopViewer.index < {n - 2}", timeout=5000)
    assert page.evaluate("vloopViewer.playing")
    page.click("#play")
    assert not page.evaluate("vloopViewer.playing")
    # without repeat: it stops on the last sample
    page.click("#repeat")
    assert page.locator("#repeat").get_attribute("aria-pressed") == "false"
    page.evaluate(f"vloopViewer.setIndex({n - 4}); vloopViewer.play()")
    page.wait_for_function("!vloopViewer.playing", timeout=5000)
    assert page.evaluate("vloopViewer.index") == n - 1
    # zoom with the wheel about the cursor, pan by dragging, double-click fits again
    view = page.locator("#view")
    home = view.get_attribute("viewBox")
    box = view.bounding_box()
    cx, cy = box["x"] + box["width"] / 2, box["y"] + box["height"] / 2
    page.mouse.move(cx, cy)
    page.mouse.wheel(0, -300)
    zoomed = [float(v) for v in view.get_attribute("viewBox").split()]
    assert zoomed[2] < float(home.split()[2])
    page.mouse.down()
    page.mouse.move(cx + 100, cy + 40)
    page.mouse.up()
    panned = [float(v) for v in view.get_attribute("viewBox").split()]
    assert panned[0] < zoomed[0] and panned[1] < zoomed[1] and panned[2] == zoomed[2]
    view.dblclick()
    assert view.get_attribute("viewBox") == home
    # each loop can be hidden on its own
    page.click("#loop-details summary")
    page.click('[data-loop-toggle="2"]')
    assert page.locator('g[data-loop="2"]').get_attribute("display") == "none"
    assert page.locator('g[data-loop="1"]').get_attribute("display") != "none"
    assert page.locator('#loop-legend [data-loop="2"]').is_hidden()
    assert "b = |A→B (l3)| = 5" in page.locator("#loop-details").text_content()
    assert o.requests == [] and o.problems == []


def test_screenshots_at_three_instants(open_page, eightbar_page, eightbar, tmp_path: Path) -> None:
    from PIL import Image

    o = open_page(eightbar_page)
    n = len(eightbar[1])
    shots = []
    for k in (0, n // 3, 2 * n // 3):
        o.page.evaluate(f"vloopViewer.setIndex({k})")
        path = tmp_path / f"eightbar_{k:03d}.png"
        o.page.locator("#view-wrap").screenshot(path=str(path))
        shots.append(np.asarray(Image.open(path).convert("L"), float))
    for img in shots:
        assert img.std() > 10 and (img < 128).mean() > 0.004, "a blank drawing"
    for a, b in ((0, 1), (1, 2), (0, 2)):
        assert np.mean(np.abs(shots[a] - shots[b]) > 40) > 0.003, "the mechanism did not move"
    o.page.screenshot(path=str(tmp_path / "eightbar_page.png"), full_page=True)
    assert o.requests == [] and o.problems == []


def test_copy_and_display_options(open_page, eightbar_page, eightbar) -> None:
    result = eightbar[1]
    o = open_page(eightbar_page, dark=True)
    page = o.page
    bg = page.evaluate("getComputedStyle(document.body).backgroundColor")
    assert bg == "rgb(21, 24, 28)"  # dark by the system's preference
    page.click("#theme")
    assert page.evaluate("getComputedStyle(document.body).backgroundColor") == "rgb(255, 255, 255)"

    def label_px() -> float:  # the labels' size on screen: model units / (model units per pixel)
        return float(page.locator('[data-layer="labels"]').get_attribute("font-size")) / page.evaluate(
            "vloopViewer.unitsPerPixel"
        )

    assert label_px() == pytest.approx(14)
    root_px = page.evaluate("parseFloat(getComputedStyle(document.documentElement).fontSize)")
    page.click("#large")
    assert label_px() == pytest.approx(21)
    assert page.evaluate("parseFloat(getComputedStyle(document.documentElement).fontSize)") == pytest.approx(
        1.5 * root_px
    )
    page.evaluate("vloopViewer.setIndex(5)")
    page.click("#copy")
    text = page.evaluate("vloopViewer.lastCopy")
    rows = {line.split("\t")[0]: line.split("\t")[1:] for line in text.strip().splitlines()[1:]}
    assert float(rows["t"][0]) == result.t[5]
    for col, values in result.columns.items():
        assert float(rows[col][0]) == values[5], col
    assert rows["l3.omega"][1] == "rad/s" and rows["B:l3>l4.fx"][1] == "N" and rows["l2.torque"][1] == "N·m"
    assert o.requests == [] and o.problems == []


def test_the_page_forbids_network_requests(open_page, eightbar_page) -> None:
    o = open_page(eightbar_page, bypass_csp=False)
    result = o.page.evaluate("fetch('https://example.org/x').then(() => 'fetched', () => 'refused')")
    assert result == "refused" and o.requests == []
    assert any("Content Security Policy" in p for p in o.problems)


def test_stopped_motion_shows_the_last_instant_and_the_message(open_page, tmp_path: Path) -> None:
    mech = vloop.load(STOPPED)
    result, error = solve_for_view(mech)
    path = write_view(mech, result, tmp_path / "stopped.html", error=error)
    o = open_page(path)
    page = o.page
    banner = page.locator("#error")
    assert banner.is_visible() and "cannot assemble at t = 1.73 s" in banner.text_content()
    assert page.evaluate("vloopViewer.index") == len(result) - 1 == 172
    x, y = _xy(page, 'circle[data-joint="B"]')
    assert math.hypot(x - result["B.x"][-1], y - result["B.y"][-1]) <= 1e-9 * mech.scale
    assert o.requests == [] and o.problems == []


@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_every_catalog_page_runs_without_error(open_page, tmp_path: Path, path: Path) -> None:
    mech = vloop.load(path)
    result, error = solve_for_view(mech)
    page_file = write_view(mech, result, tmp_path / f"{mech.name}.html", error=error)
    o = open_page(page_file)
    page = o.page
    for layer in ("vel", "acc", "paths"):
        page.click(f'[data-overlay="{layer}"]')
    page.evaluate(f"vloopViewer.setIndex({len(result) // 2})")
    page.keyboard.press("ArrowRight")
    assert page.locator("circle[data-joint]").count() == len(mech.tracked_points)
    assert page.locator("#error").is_visible() == (error is not None)
    assert o.requests == [] and o.problems == [], o.problems


CRANK = """
name = "crank"
[joints]
O = [0, 0]
A = [1, 0]
[links]
ground = { joints = ["O"], ground = true }
l2 = { joints = ["O", "A"] }
[[drivers]]
link = "l2"
pivot = "O"
omega = 1.0
[time]
start = 0
stop = 1
step = 0.1
"""


def test_pages_with_no_loop_or_a_single_sample(open_page, tmp_path: Path) -> None:
    """A lone crank (no loop at all), and a run whose first sample is already past the limit
    (nothing solved: the page shows the t = 0 assembly and says so)."""
    crank = vloop.loads(CRANK, source=str(tmp_path / "crank.toml"))
    late_text = re.sub(r"\[time\][^\[]*", "[time]\nstart = 2.0\nstop = 2.5\nstep = 0.1\n", STOPPED.read_text())
    late = vloop.loads(late_text, source=str(STOPPED), base_dir=MECHANISMS)
    for mech, samples in ((crank, 11), (late, 1)):
        result, error = solve_for_view(mech)
        assert len(result) == samples and (error is None) == (mech is crank)
        o = open_page(write_view(mech, result, tmp_path / f"{mech.name}.html", error=error))
        page = o.page
        for layer in ("vel", "acc", "paths", "loops"):
            page.click(f'[data-overlay="{layer}"]')
        page.keyboard.press("Space")
        page.keyboard.press("ArrowRight")
        assert page.locator("circle[data-joint]").count() == len(mech.tracked_points)
        if mech is late:
            assert "shown at the t = 0 assembly" in page.locator("#error").text_content()
            assert page.locator("[data-plot] circle").count() == 3 * 3  # one dot per link and plot
        assert o.requests == [] and o.problems == [], o.problems


def test_inline_viewer_runs_in_its_sandboxed_frame(browser, eightbar, tmp_path: Path) -> None:
    """A notebook-like host page holding the inline viewer: the page inside draws the joints where the Result has
    them, with no error and no request beyond the host file."""
    mech, result = eightbar
    host = tmp_path / "notebook.html"
    host.write_text(f"<!DOCTYPE html><html><body><h1>cell</h1>{inline(mech, result)._repr_html_()}</body></html>")
    ctx = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = ctx.new_page()
    requests, problems = [], []

    def route(r) -> None:
        if r.request.url in (host.resolve().as_uri(), "about:srcdoc"):
            r.continue_()
        else:
            requests.append(r.request.url)
            r.abort()

    ctx.route("**/*", route)
    page.on("console", lambda m: m.type in ("error", "warning") and problems.append(f"{m.type}: {m.text}"))
    page.on("pageerror", lambda e: problems.append(f"pageerror: {e}"))
    page.goto(host.resolve().as_uri())
    viewer = page.frame_locator("iframe")
    viewer.locator("body[data-ready]").wait_for(state="attached", timeout=20_000)
    assert viewer.locator("circle[data-joint]").count() == len(mech.tracked_points)
    frame = next(f for f in page.frames if f is not page.main_frame)
    x, y = (float(frame.locator('circle[data-joint="B"]').get_attribute(a)) for a in ("cx", "cy"))
    assert math.hypot(x - result["B.x"][0], -y - result["B.y"][0]) <= 1e-9 * mech.scale
    ctx.close()
    assert requests == [] and problems == [], (requests, problems)


def test_targets_are_drawn_where_they_are(open_page, tmp_path: Path) -> None:
    """A synthesis's targets (points, and poses with their angle) are drawn as numbered crosses centred on
    them, inside the fitted view."""
    mech = vloop.load(MECHANISMS / "fourbar_textbook_example.toml")
    result, _ = solve_for_view(mech)
    targets = [(150.0, 40.0), (120.0, 90.0, 0.5), (-20.0, -30.0)]
    o = open_page(write_view(mech, result, tmp_path / "targets.html", targets=targets))
    crosses = o.page.locator("path[data-target]")
    assert crosses.count() == 3
    for k, t in enumerate(targets):
        nums = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?(?:e[-+]?\d+)?", crosses.nth(k).get_attribute("d"))]
        assert (nums[0] + nums[2]) / 2 == pytest.approx(t[0], abs=1e-9 * mech.scale)
        assert -(nums[1] + nums[3]) / 2 == pytest.approx(t[1], abs=1e-9 * mech.scale)
        assert (len(nums) == 12) == (len(t) == 3)  # a pose adds its angle's tick
    box = [float(v) for v in o.page.locator("#view").get_attribute("viewBox").split()]
    assert box[0] < -20.0 and box[1] < 30.0  # the far target is inside the view (SVG y down)
    assert o.requests == [] and o.problems == [], o.problems


def test_readme_screenshot_is_committed() -> None:
    shot = Path(__file__).resolve().parents[1] / "docs" / "viewer.png"
    assert shot.is_file() and shot.stat().st_size < 200_000


# ------------------------------------------------------------------ what the picture shows


def _screen(page, x: float, y: float) -> tuple[float, float]:
    """A model point's position on the page [CSS px], through the drawing's own transform."""
    return tuple(
        page.evaluate(
            "([x, y]) => { const p = new DOMPoint(x, -y).matrixTransform(document.getElementById('view').getScreenCTM());"
            " return [p.x, p.y]; }",
            [x, y],
        )
    )


def _segment_distance(p: complex, a: complex, b: complex) -> float:
    ab = b - a
    s = 0.0 if ab == 0 else min(1.0, max(0.0, ((p - a) * ab.conjugate()).real / abs(ab) ** 2))
    return abs(p - (a + s * ab))


def _path_point_inside_a_plate(mech, result, clearance: float) -> tuple[int, str, complex]:
    """(sample shown, plate, a sample of some point's path) with the path sample inside the plate drawn at
    the shown sample, ``clearance`` away from the plate's edges, every other link's bar and every joint."""
    z = {p: result[f"{p}.x"] + 1j * result[f"{p}.y"] for p in mech.tracked_points}
    plates = [n for n, lk in mech.links.items() if not lk.ground and len(lk.joints) == 3]
    for i in range(0, len(result), 10):
        for plate in plates:
            a, b, c = (z[j][i] for j in mech.links[plate].joints)
            bars = [[z[j][i] for j in lk.joints] for n, lk in mech.links.items() if not lk.ground and n != plate]
            for path in z.values():
                for q in path:
                    w = np.array([((b - a) * (q - a).conjugate()).imag, ((c - b) * (q - b).conjugate()).imag,
                                  ((a - c) * (q - c).conjugate()).imag])  # fmt: skip
                    inside = np.all(w > 0) or np.all(w < 0)
                    edges = min(_segment_distance(q, u, v) for u, v in ((a, b), (b, c), (c, a)))
                    others = min(_segment_distance(q, s[0], s[-1]) for s in bars)
                    joints = min(abs(q - zz[i]) for zz in z.values())
                    if inside and min(edges, others, joints) > clearance:
                        return i, plate, q
    raise AssertionError("no path sample lies inside a plate")


def test_paths_are_drawn_over_the_plates(open_page, tmp_path: Path) -> None:
    """Stephenson III: the coupler curves run across the ternary coupler l3 (in the catalog's Watt II they
    stay outside its rocker plate); a path's pixels inside the plate are the path's colour (#009E73 at
    75 % over the plate), not the plate's (#c9d6e8)."""
    from io import BytesIO

    from PIL import Image

    mech = vloop.load(MECHANISMS / "sixbar_stephenson3.toml")
    result = vloop.solve(mech)
    o = open_page(write_view(mech, result, tmp_path / "stephenson3.html"))
    page = o.page
    for layer in ("loops", "labels"):  # nothing else over the paths
        page.click(f'[data-overlay="{layer}"]')
    page.click('[data-overlay="paths"]')
    order = page.evaluate("[...document.querySelectorAll('#view > g')].map((g) => g.dataset.layer)")
    assert order.index("paths") > max(order.index("bodies"), order.index("blocks"))
    assert order.index("paths") < order.index("pins")
    upp = page.evaluate("vloopViewer.unitsPerPixel")
    i, plate, q = _path_point_inside_a_plate(mech, result, clearance=14 * upp)
    page.evaluate(f"vloopViewer.setIndex({i})")
    x, y = _screen(page, q.real, q.imag)
    shot = Image.open(BytesIO(page.screenshot(clip={"x": x - 2, "y": y - 2, "width": 5, "height": 5})))
    px = np.asarray(shot.convert("RGB"), float).reshape(-1, 3)
    greenest = px[np.argmax(px[:, 1] - px[:, 0])]
    assert greenest[1] - greenest[0] > 80 and greenest[0] < 120, f"{plate} hides the path at {q}: {greenest}"
    assert o.requests == [] and o.problems == []


def _overlap(a: dict, b: dict) -> bool:
    return (
        a["x"] < b["x"] + b["width"]
        and b["x"] < a["x"] + a["width"]
        and a["y"] < b["y"] + b["height"]
        and b["y"] < a["y"] + a["height"]
    )


def test_scale_legend_never_covers_the_drawing(open_page, eightbar_page) -> None:
    o = open_page(eightbar_page)
    page = o.page
    for layer in ("vel", "acc", "forces"):
        page.click(f'[data-overlay="{layer}"]')
    for large in (False, True):
        if large:
            page.click("#large")
        page.wait_for_timeout(100)  # the resize observer's frame
        legend = page.locator("#scale-legend").bounding_box()
        view = page.locator("#view").bounding_box()
        wrap = page.locator("#view-wrap").bounding_box()
        assert page.locator("#scale-legend .row").count() == 3
        assert not _overlap(legend, view), (large, legend, view)
        assert wrap["y"] <= legend["y"] and legend["y"] + legend["height"] <= wrap["y"] + wrap["height"] + 0.5
        for layer in ("bodies", "pins", "vel", "acc", "forces", "labels"):  # the drawing, as rendered
            box = page.locator(f'g[data-layer="{layer}"]').bounding_box()
            assert box is not None and not _overlap(legend, box), (large, layer)
        # the sizes meant to stay constant on screen follow the drawing's new size
        upp = page.evaluate("vloopViewer.unitsPerPixel")
        vb = [float(v) for v in page.locator("#view").get_attribute("viewBox").split()]
        assert upp == pytest.approx(max(vb[2] / view["width"], vb[3] / view["height"]), rel=1e-3)
    assert o.requests == [] and o.problems == []


def _kind(col: str) -> str:
    q = col.rsplit(".", 1)[-1]
    return {"x": "length", "y": "length", "s": "length", "vx": "velocity", "vy": "velocity", "v": "velocity",
            "ax": "acceleration", "ay": "acceleration", "a": "acceleration"}.get(q, q)  # fmt: skip


def test_numbers_read_against_their_scale_on_one_line(open_page, eightbar_page, eightbar) -> None:
    """Every value: within 1e-6 of its kind's peak over the run (7 digits), round-off (≤ 1e-12 of that peak)
    shown as 0, at most 7 significant digits, no exponent for a value above 1e-6 of the peak, one line.
    At t = 0 the paper's eight-bar has θ2 = 90°: A = (0, 3) exactly, A moves along x, and the coupler l3
    translates (A and B both move along x), so A.x, A.vy, A.ax and ω3 are 0 by hand."""
    result = eightbar[1]
    peaks: dict[str, float] = {}
    for col, v in result.columns.items():
        peaks[_kind(col)] = max(peaks.get(_kind(col), 0.0), float(np.abs(v).max()))
    o = open_page(eightbar_page)
    page = o.page
    for large in (False, True):
        if large:
            page.click("#large")
        for k in (0, 17, 33):
            page.evaluate(f"vloopViewer.setIndex({k})")
            cells = page.evaluate(
                """() => [...document.querySelectorAll('#numbers td.num')].map((td) => {
                  const r = document.createRange(); r.selectNodeContents(td);
                  return {col: td.dataset.col, text: td.textContent, value: +td.dataset.value, lines: r.getClientRects().length,
                          overflow: td.scrollWidth - td.clientWidth};
                })"""
            )
            for c in cells:
                assert c["lines"] == 1 and c["overflow"] <= 0, c
                col = c["col"]
                if col.startswith(("force:", "health.")):
                    continue
                shown, value = float(c["text"]), c["value"]
                degrees = value != float(result[col][k])  # the θ [°] column: the same column in degrees
                peak = peaks[_kind(col)] * (180 / math.pi if degrees else 1.0)
                assert abs(shown - value) <= 1e-6 * peak, c
                if abs(value) <= 1e-12 * peak:
                    assert c["text"] == "0", c
                digits = re.sub(r"e.*$", "", c["text"]).lstrip("-").replace(".", "").lstrip("0")
                assert len(digits) <= 7, c
                if abs(value) > 1e-6 * peak:
                    assert "e" not in c["text"], c
    page.evaluate("vloopViewer.setIndex(0)")
    for col in ("A.x", "A.vy", "A.ax", "l3.omega"):
        assert abs(result[col][0]) < 1e-13 * peaks[_kind(col)]  # round-off, not a value
        assert page.locator(f'td[data-col="{col}"]').first.text_content() == "0", col
    assert o.requests == [] and o.problems == []


def test_coincident_plot_series_are_dashed_and_named(open_page, eightbar_page, eightbar) -> None:
    result = eightbar[1]
    assert np.abs(result["l6.s"] - result["l8.s"]).max() < 1e-9  # mirror images (paper, Fig. 1)
    o = open_page(eightbar_page)
    page = o.page
    toggle = page.locator('[data-series-toggle="l8"]')
    assert toggle.get_attribute("data-coincides") == "l6" and "l8 (= l6)" in toggle.text_content()
    assert page.locator('[data-series-toggle="l4"]').get_attribute("data-coincides") is None
    for q in ("s", "v", "a"):
        plot = page.locator(f'[data-plot="Sliders:{q}"]')
        dash = {n: plot.locator(f'path[data-series="{n}"]').get_attribute("stroke-dasharray") for n in ("l6", "l8")}
        assert dash["l6"] is None and dash["l8"], dash
    assert page.locator('[data-series-toggle="l7"]').get_attribute("data-coincides") is None  # θ7 ≠ θ5
    assert o.requests == [] and o.problems == []
