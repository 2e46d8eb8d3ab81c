"""Remake docs/viewer.png, the README's picture of the viewer (needs playwright and Debian's chromium).

    python docs/make_viewer_png.py

The eight-bar at t = 1.0 s with its vector loops and velocity arrows, a 1280 × 800 window,
saved as a 256-colour PNG (line art loses nothing visible; the file stays well under 200 KB).
"""

from __future__ import annotations

import io
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402
from vloop.views.view import write_view  # noqa: E402

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking"]


def main() -> None:
    from PIL import Image
    from playwright.sync_api import sync_playwright

    mech = vloop.load(ROOT / "mechanisms" / "eightbar.toml")
    result = vloop.solve(mech)
    with tempfile.TemporaryDirectory() as tmp, sync_playwright() as pw:
        page_file = write_view(mech, result, Path(tmp) / "eightbar.html")
        browser = pw.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1280, "height": 800})
        page.goto(page_file.as_uri())
        page.wait_for_selector("body[data-ready]", state="attached")
        page.evaluate("vloopViewer.setIndex(20); vloopViewer.setOverlay('vel', true)")
        png = page.screenshot()
        browser.close()
    im = Image.open(io.BytesIO(png)).convert("RGB")
    out = ROOT / "docs" / "viewer.png"
    im.quantize(colors=256, method=Image.Quantize.MEDIANCUT, dither=Image.Dither.NONE).save(out, optimize=True)
    print(f"wrote {out} ({out.stat().st_size / 1e3:.0f} kB)")


if __name__ == "__main__":
    main()
