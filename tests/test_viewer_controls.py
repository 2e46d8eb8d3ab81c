"""The viewer's reading controls: the arrows' scale, colours that tell accelerations from loop vectors in both
themes, controls that fit a notebook's frame, wrapped angles in the θ plot, a playback speed a person can follow.

References: the textbook four-bar (mechanisms/fourbar_textbook_example.toml, ω₂ = 25 rad/s: 3.98 turns/s at 1×,
crank θ from 0.70 to 15.1 rad over the run); the arrow scale is a plain multiplier (an arrow's length is
k · |v| with k set from the run's peak, so doubling the control doubles every arrow).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

import vloop
from vloop.views.view import inline, write_view

from .conftest import MECHANISMS
from .test_viewer import browser, open_page  # noqa: F401  (fixtures shared with the viewer tests)

TEXTBOOK = MECHANISMS / "fourbar_textbook_example.toml"


@pytest.fixture(scope="module")
def textbook_page(tmp_path_factory) -> tuple[Path, vloop.Mechanism, vloop.Result]:
    mech = vloop.load(TEXTBOOK)
    res = vloop.solve(mech)
    return write_view(mech, res, tmp_path_factory.mktemp("controls") / "textbook.html"), mech, res


@pytest.fixture(scope="module")
def light_page(browser, textbook_page):  # noqa: F811
    """One light page for the checks that only read it (a page per test costs a second each)."""
    ctx = browser.new_context(viewport={"width": 1400, "height": 1000})
    page = ctx.new_page()
    page.goto(textbook_page[0].resolve().as_uri())
    page.wait_for_selector("body[data-ready]", state="attached", timeout=20_000)
    yield page
    ctx.close()


def _rgb(text: str) -> tuple[float, ...]:
    return tuple(float(v) for v in re.findall(r"[\d.]+", text)[:3])


def test_arrow_scale_control_multiplies_every_arrow(open_page, textbook_page) -> None:  # noqa: F811
    path, mech, res = textbook_page
    page = open_page(path).page
    page.locator('[data-overlay="vel"]').click()
    k1 = page.evaluate("vloopViewer.scales().vel")
    v = math.hypot(res["B.vx"][0], res["B.vy"][0])
    assert k1 * v <= 0.25 * mech.scale * (1 + 1e-12)  # the run's longest arrow is a quarter of the size
    page.select_option("#arrow-scale", "4")
    k4 = page.evaluate("vloopViewer.scales().vel")
    assert k4 == pytest.approx(4 * k1, rel=1e-12)
    legend = page.locator('[data-scale-for="vel"]')
    assert float(legend.get_attribute("data-scale")) == pytest.approx(k4, rel=1e-12)


def test_dark_accelerations_differ_from_the_loop_colour(open_page, textbook_page) -> None:  # noqa: F811
    """Accelerations and the first vector loop (Okabe–Ito orange, #E69F00) must not share a colour in either theme:
    their RGB distance is over 60 of 441 (light: vermilion #D55E00, 67; dark: #FF6F61, 111)."""
    path, _, _ = textbook_page
    for dark in (False, True):
        page = open_page(path, dark=dark).page
        page.locator('[data-overlay="acc"]').click()
        acc = _rgb(page.locator("path.v-acc").first.evaluate("e => getComputedStyle(e).stroke"))
        loop = _rgb(page.locator('[data-loop="1"] path.v-arrow').first.evaluate("e => getComputedStyle(e).stroke"))
        assert math.dist(acc, loop) > 60, (dark, acc, loop)


def test_the_controls_fit_in_a_notebook_frame(browser, textbook_page, tmp_path: Path) -> None:  # noqa: F811
    """The inline frame (its default height) at a 1,200 px wide notebook shows the time and overlay controls
    whole, without scrolling inside the frame."""
    _, mech, res = textbook_page
    view = inline(mech, res)
    host = tmp_path / "notebook.html"
    host.write_text(f"<!DOCTYPE html><html><body style='margin:0'>{view._repr_html_()}</body></html>")
    ctx = browser.new_context(viewport={"width": 1200, "height": 1000})
    page = ctx.new_page()
    page.goto(host.resolve().as_uri())
    frame = page.frame_locator("iframe")
    frame.locator("body[data-ready]").wait_for(state="attached", timeout=20_000)
    for sel in ("#controls", "#overlays"):
        bottom = frame.locator(sel).evaluate("e => e.getBoundingClientRect().bottom")
        assert bottom <= view.height, (sel, bottom, view.height)
    ctx.close()


def test_a_cranks_angle_is_plotted_wrapped(light_page, textbook_page) -> None:
    """The crank's θ runs 0.70 → 15.1 rad; drawn wrapped, every θ curve spans the plot's height, and the tooltip
    still reads the unwrapped value."""
    _, _, res = textbook_page
    assert res["l2.theta"].max() - res["l2.theta"].min() > 2 * math.pi
    page = light_page
    plot = page.locator('[data-plot="Links:theta"]')
    assert "wrapped" in plot.locator("text.ylabel").text_content()
    labels = [float(t) for t in plot.locator("text.tick").all_text_contents() if re.fullmatch(r"-?[\d.]+", t)]
    y_ticks = [v for v in labels if abs(v) <= 4]
    assert max(y_ticks) <= math.pi + 0.5 and min(y_ticks) >= -math.pi - 0.5
    d = plot.locator('path[data-series="l2"]').get_attribute("d")
    assert d.count("M") >= 3  # one piece per turn: the seam is not drawn across the plot


def test_default_speed_follows_the_fastest_link(light_page, textbook_page) -> None:
    """At most half a turn per second by default: the crank speeds up from 25 to 32.5 rad/s (5.17 turns/s at 1×), so
    0.05× (0.26 turns/s; 0.1× would be 0.52)."""
    _, _, res = textbook_page
    page = light_page
    speed = page.evaluate("vloopViewer.speed")
    turns = max(abs(res[f"{n}.omega"]).max() for n in ("l2", "l3", "l4")) / (2 * math.pi)
    assert turns == pytest.approx(32.5 / (2 * math.pi), rel=1e-9)
    assert speed == 0.05 and speed * turns <= 0.5 < 0.1 * turns
    assert page.locator("#speed").input_value() == "0.05"
