"""The studio in a browser (Playwright driving Debian's chromium, headless), as a person uses it.

- Draw the textbook four-bar by clicks (two pivots, two pins, three links) and typed numbers (pivot coordinates,
  lengths, the driver, the time), drag its crank, save: the saved file's run equals
  mechanisms/fourbar_textbook_example.toml's to 1e-12 of each column's peak (same closed forms, same samples).
- Drag a pivot far out: the drag stops at the limit and the page says so.
- Click target points, find linkages, take the first candidate: its tracer, as drawn, passes through every point
  within the synthesis's tolerance (1 % of the points' size) plus the drawing's chord error.
Screenshots of each state are written to the test's folder; the first test runs by default, the other two under
``-m slow`` (a synthesis and a limit's bisection take ~10 s each here).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import vloop

from .conftest import MECHANISMS

pytest.importorskip("starlette", reason="the studio's extra is not installed (pip install -e '.[studio]')")
CHROMIUM = Path("/usr/bin/chromium")
ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update"]
TEXTBOOK = MECHANISMS / "fourbar_textbook_example.toml"


@pytest.fixture(scope="module")
def chromium():
    if not CHROMIUM.exists():
        pytest.skip("Debian's chromium is not installed at /usr/bin/chromium (apt-get install chromium; .ci/run does)")
    sync_api = pytest.importorskip(
        "playwright.sync_api", reason="playwright is not installed (pip install -e '.[dev]')"
    )
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        yield browser
        browser.close()


@pytest.fixture
def studio(chromium, tmp_path: Path):
    """A studio served on an empty folder, and a page open on it (console errors and other requests recorded)."""
    from vloop.studio.server import Background
    from vloop.studio.session import Session

    served = Background(Session(tmp_path))
    ctx = chromium.new_context(viewport={"width": 1400, "height": 1000})
    page = ctx.new_page()
    problems: list[str] = []
    page.on("console", lambda m: m.type in ("error", "warning") and problems.append(f"{m.type}: {m.text}"))
    page.on("pageerror", lambda e: problems.append(f"pageerror: {e}"))
    page.route(
        "**/*",
        lambda r: (
            r.continue_()
            if r.request.url.startswith(f"http://127.0.0.1:{served.port}/")
            else (problems.append(r.request.url), r.abort())
        ),
    )
    page.goto(served.url)
    page.wait_for_selector("body[data-studio-ready]", state="attached", timeout=20_000)
    yield page, tmp_path
    ctx.close()
    served.stop()
    assert problems == [], problems


def settle(page, before: str | None = None) -> None:
    """Wait until the page has drawn a reply newer than ``before``."""
    page.wait_for_function("b => document.body.dataset.studioReady !== b", arg=before, timeout=30_000)


def screen(page, x: float, y: float) -> tuple[float, float]:
    """Where the drawing's world point (x, y) is on the screen."""
    return tuple(
        page.evaluate(
            "([x, y]) => { const p = new DOMPoint(x, -y).matrixTransform(document.getElementById('view').getScreenCTM()); return [p.x, p.y]; }",
            [x, y],
        )
    )


def act(page, fn) -> None:
    before = page.evaluate("document.body.dataset.studioReady")
    fn()
    settle(page, before)


def tool(page, name: str) -> None:
    page.click(f'.s-tool[data-tool="{name}"]')


def click_at(page, x: float, y: float) -> None:
    act(page, lambda: page.mouse.click(*screen(page, x, y)))


def handle(page, name: str) -> None:
    act(page, lambda: page.click(f'circle[data-handle="{name}"]'))


def typed(page, form: str, values: dict[str, str]) -> None:
    for field, value in values.items():
        sel = f"#{form} [name={field}]"
        if page.locator(sel).evaluate("e => e.tagName") == "SELECT":
            page.select_option(sel, value)
        else:
            page.fill(sel, value)
    act(page, lambda: page.click(f"#{form} button:not([name])"))


def draw_textbook(page) -> None:
    tool(page, "pivot")
    click_at(page, 2, -3)
    click_at(page, 96, 4)
    tool(page, "joint")
    click_at(page, 27, 29)
    click_at(page, 138, 72)
    tool(page, "link")
    for a, b in (("O1", "J1"), ("J1", "J2"), ("O2", "J2")):
        page.click(f'circle[data-handle="{a}"]')
        handle(page, b)
    typed(page, "f-joint", {"name": "O1", "x": "0", "y": "0"})
    typed(page, "f-joint", {"name": "O2", "x": "100", "y": "0"})
    for link, length in (("l2", "40"), ("l3", "120"), ("l4", "80")):
        typed(page, "f-length", {"link": link, "length": length})
    typed(page, "f-time", {"start": "0", "stop": "0.5", "step": "0.0025"})
    typed(page, "f-driver", {"link": "l2", "theta0": "40", "omega": "25", "alpha": "15"})


NAMES = {"O2": "O1", "O4": "O2", "A": "J1", "B": "J2"}  # the textbook's joints, as the clicks named them


def test_draw_drag_the_crank_save_and_run_as_the_textbook(studio) -> None:
    page, folder = studio
    draw_textbook(page)
    assert page.locator("#s-problem").is_hidden()
    info = page.locator("#s-info").inner_text()
    assert "M = 3(4−1) − 2·4 = 1" in info and "Grashof crank-rocker" in info and "open" in info
    assert page.locator("g[data-body]").count() == 3 and page.locator("circle[data-handle]").count() == 4
    page.screenshot(path=str(folder / "drawn.png"))
    # drag the crank's pin a quarter turn about its pivot: the drawing goes to the sample at that angle
    tool(page, "drag")
    th0 = page.evaluate("vloopViewer.column('l2.theta')[vloopViewer.index]")
    start = screen(page, 40 * math.cos(th0), 40 * math.sin(th0))
    page.mouse.move(*start)
    page.mouse.down()
    for k in range(1, 11):
        a = th0 + k * math.pi / 20
        page.mouse.move(*screen(page, 40 * math.cos(a), 40 * math.sin(a)))
    page.mouse.up()
    i = page.evaluate("vloopViewer.index")
    th = page.evaluate("vloopViewer.column('l2.theta')[vloopViewer.index]")
    assert i > 0 and abs(math.remainder(th - (th0 + math.pi / 2), 2 * math.tau)) < 0.1
    ax, ay = (float(page.locator('circle[data-joint="J1"]').get_attribute(a)) for a in ("cx", "cy"))
    assert math.hypot(ax - 40 * math.cos(th), -ay - 40 * math.sin(th)) < 1e-9 * 40
    page.screenshot(path=str(folder / "crank.png"))
    tool(page, "lock")
    act(page, lambda: page.click('g[data-body="l4"]'))
    assert page.evaluate("vloopStudio.state.locks.links") == ["l4"]
    assert page.locator('g[data-body="l4"][data-locked]').count() == 1
    page.fill("#f-file [name=path]", "drawn.toml")
    page.click("#f-file button[name=save]")
    page.wait_for_function("() => document.body.dataset.studioStatus.startsWith('saved')")
    drawn, book = vloop.solve(vloop.load(folder / "drawn.toml")), vloop.solve(vloop.load(TEXTBOOK))
    assert np.array_equal(drawn.t, book.t)
    for col, ref in book.columns.items():
        name, q = col.split(".")
        mine = drawn[f"{NAMES.get(name, name)}.{q}"]
        assert np.abs(mine - ref).max() <= 1e-12 * max(np.abs(ref).max(), 1.0), col


@pytest.mark.slow  # ~10 s: the limit's bisection (12 solves) at each step past it; the session test is fast
def test_a_pivot_dragged_past_a_limit_stops_and_says_so(studio) -> None:
    page, folder = studio
    page.select_option("#f-catalog [name=catalog]", "fourbar_textbook_example")
    act(page, lambda: page.click("#f-catalog button:not([name])"))
    page.mouse.move(*screen(page, 100, 0))
    page.mouse.down()
    for x in np.linspace(100, 260, 9)[1:]:
        before = page.evaluate("document.body.dataset.studioReady")
        page.mouse.move(*screen(page, x, 0))
        settle(page, before)
    page.mouse.up()
    limit = page.locator("#s-limit")
    limit.wait_for(state="visible")
    assert "O4 stopped at" in limit.inner_text() and "limit" in limit.inner_text()
    x = page.evaluate("vloopStudio.state.doc.joints.O4[0]")
    assert 140 < x < 160  # the limit by hand (tests/test_studio_session.py): d + a = b + c(d), d* = 147.5 mm
    page.screenshot(path=str(folder / "limit.png"))


TARGETS = [(0, 30), (30, 60), (60, 45), (90, 0), (45, -15)]


@pytest.mark.slow  # ~15 s: a synthesis in a fresh worker process
def test_a_candidate_from_clicked_points_passes_through_them(studio) -> None:
    page, folder = studio
    tool(page, "target")
    for x, y in TARGETS:
        click_at(page, x, y)
    assert page.evaluate("vloopStudio.state.targets.length") == len(TARGETS)
    page.fill("#f-synth [name=count]", "2")
    page.click("#f-synth button:not([name])")
    page.wait_for_selector(".cand [data-take]", timeout=120_000)
    assert page.locator("path[data-candidate]").count() >= 1
    page.screenshot(path=str(folder / "candidates.png"))
    act(page, lambda: page.click('[data-take="0"]'))
    tracer = page.evaluate("vloopStudio.state.payload.tracers[0]")
    xs = np.array(page.evaluate(f"Array.from(vloopViewer.column('{tracer}.x'))"))
    ys = np.array(page.evaluate(f"Array.from(vloopViewer.column('{tracer}.y'))"))
    size = max(np.ptp([p[0] for p in TARGETS]), np.ptp([p[1] for p in TARGETS]))
    chord = np.hypot(np.diff(xs), np.diff(ys)).max()  # the drawn polyline's longest step
    for x, y in TARGETS:
        near = np.hypot(xs - x, ys - y).min()
        assert near <= 0.01 * size + chord, (x, y, near, chord)
    assert page.locator("path[data-target]").count() == len(TARGETS)
    page.screenshot(path=str(folder / "taken.png"))


@pytest.mark.slow  # a validation: ~6 s of engines in a child process
def test_check_shows_the_validation_verdict(studio) -> None:
    page, _ = studio
    page.select_option("#f-catalog [name=catalog]", "fourbar_textbook_example")
    act(page, lambda: page.click("#f-catalog button:not([name])"))
    page.click("#s-validate")
    page.locator("#s-verdict [data-verdict]").wait_for(state="visible", timeout=300_000)
    assert page.locator("#s-verdict [data-verdict]").get_attribute("data-verdict") == "pass"
    engines = set(page.locator("#s-verdict [data-engine]").evaluate_all("es => es.map((e) => e.dataset.engine)"))
    assert {"pinocchio", "exudyn-kinematic", "analytic"} <= engines


@pytest.mark.slow  # a synthesis in a fresh worker process
def test_a_function_generator_designed_in_the_page_is_taken_into_the_editor(studio) -> None:
    """The design form's function task (y = log10(x), its default ranges): one candidate, taken, drawn and described
    as a four-bar (mobility 1, one loop)."""
    page, _ = studio
    page.select_option("#f-synth [name=kind]", "function")
    assert page.locator("#f-synth [name=expr]").is_visible() and page.locator("#f-synth [name=angles]").is_hidden()
    page.fill("#f-synth [name=count]", "1")
    page.click("#f-synth button:not([name])")
    page.wait_for_selector(".cand [data-take]", timeout=120_000)
    act(page, lambda: page.click('[data-take="0"]'))
    assert page.locator("circle[data-handle]").count() == 4 and page.locator("g[data-body]").count() == 3
    assert "M = 3(4−1) − 2·4 = 1" in page.locator("#s-info").inner_text()


def test_plots_and_numbers_catch_up_after_a_stream_of_drags(studio) -> None:
    """Drags sent as fast as the pointer moves (plots redrawn a slice per frame, a pass at most every 100 ms): once
    the pointer rests, the coupler's θ plot has been redrawn, and the numbers (once scrolled into view) show the last
    reply: at t = 0, B's x and y are where the session put joint B."""
    page, _ = studio
    page.select_option("#f-catalog [name=catalog]", "fourbar_textbook_example")
    before = page.evaluate("document.body.dataset.studioReady")
    page.click("#f-catalog button:not([name])")
    settle(page, before)
    plot = page.locator('[data-plot="Links:theta"] path[data-series="l3"]')
    d0 = plot.get_attribute("d")
    tool(page, "drag")
    page.mouse.move(*screen(page, 143.19, 67.34))
    page.mouse.down()
    for k in range(1, 16):
        page.mouse.move(*screen(page, 143.19 + 0.3 * k, 67.34 - 0.2 * k))
    page.mouse.up()
    page.wait_for_timeout(300)  # the last reply drawn, then its plots' passes (a slice per frame)
    page.locator("#numbers").scroll_into_view_if_needed()  # numbers out of view are brought up to date in view
    page.wait_for_function(
        "() => { const b = vloopStudio.state.doc.joints.B, c = (q) => document.querySelector(`td[data-col='B.${q}']`);"
        " return vloopViewer.index === 0 && Number(c('x').dataset.value) === vloopViewer.column('B.x')[0]"
        " && Math.abs(vloopViewer.column('B.x')[0] - b[0]) <= 1e-9 * Math.abs(b[0])"
        " && Math.abs(Number(c('y').dataset.value) - b[1]) <= 1e-9 * Math.abs(b[1]); }",
        timeout=10_000,
    )
    bx = page.evaluate("vloopStudio.state.doc.joints.B[0]")
    assert abs(bx - 143.19) > 0.1  # the drags moved B
    assert plot.get_attribute("d") != d0
