"""Make the studio's pictures for docs/studio.md (headless Debian chromium, the studio served from this process).

python docs/make_studio_png.py          # writes docs/studio_drag.png, studio_limit.png, studio_design.png
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vloop.studio.server import Background  # noqa: E402
from vloop.studio.session import Session  # noqa: E402

ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update"]
TARGETS = [(0, 30), (30, 60), (60, 45), (90, 0), (45, -15)]


def screen(page, x: float, y: float) -> tuple[float, float]:
    js = "([x, y]) => { const p = new DOMPoint(x, -y).matrixTransform(view.getScreenCTM()); return [p.x, p.y]; }"
    return tuple(page.evaluate(js, [x, y]))


def settled(page, action) -> None:
    before = page.evaluate("document.body.dataset.studioReady")
    action()
    page.wait_for_function("b => document.body.dataset.studioReady !== b", arg=before, timeout=60_000)


def main() -> None:
    from playwright.sync_api import sync_playwright

    served = Background(Session(tempfile.mkdtemp(prefix="vloop-studio-png-")))
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path="/usr/bin/chromium", args=ARGS)
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        page.goto(served.url)
        page.wait_for_selector("body[data-studio-ready]", state="attached")
        page.select_option("#f-catalog [name=catalog]", "fourbar_textbook_example")
        settled(page, lambda: page.click("#f-catalog button:not([name])"))
        page.click('[data-overlay="vel"]')
        page.click('[data-overlay="paths"]')
        page.mouse.move(*screen(page, 143.19, 67.34))
        page.mouse.down()
        settled(page, lambda: page.mouse.move(*screen(page, 150, 90)))
        page.mouse.up()
        page.screenshot(path=str(ROOT / "docs" / "studio_drag.png"))
        page.mouse.move(*screen(page, 100, 0))
        page.mouse.down()
        for x in (120, 150, 180, 220, 260, 300):
            settled(page, lambda x=x: page.mouse.move(*screen(page, x, 0)))
        page.mouse.up()
        page.locator("#s-limit").wait_for(state="visible")
        page.click("#fit")
        page.evaluate("window.scrollTo(0, 0)")
        page.screenshot(path=str(ROOT / "docs" / "studio_limit.png"))
        settled(page, lambda: page.click("#f-catalog button[name=new]"))
        page.click('.s-tool[data-tool="target"]')
        for x, y in TARGETS:
            settled(page, lambda x=x, y=y: page.mouse.click(*screen(page, x, y)))
        page.click("#f-synth button:not([name])")
        page.wait_for_selector(".cand [data-take]", timeout=300_000)
        settled(page, lambda: page.click('[data-take="0"]'))
        page.click('[data-overlay="paths"]')
        page.click('[data-overlay="vel"]')
        page.evaluate("window.scrollTo(0, 0)")
        page.screenshot(path=str(ROOT / "docs" / "studio_design.png"))
        browser.close()
    served.stop()


if __name__ == "__main__":
    main()
