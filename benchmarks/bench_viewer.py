"""The viewer page: its size, how fast it opens, and the cost of a frame while playing, in headless Chromium.

    python benchmarks/bench_viewer.py                     # eight-bar and Jansen pair, 48/201 and 5,000 samples
    python benchmarks/bench_viewer.py --seconds 5

For each page: its size, Python's time to build it, the browser's time from navigation to the
first drawn frame (decoding every column included), then it plays for ``--seconds`` at 1× with
every overlay on (loops, velocity, acceleration, paths, labels) and reports

* draw: the page's own work per frame (every body transform, pin, label, loop arrow and
  velocity/acceleration arrow updated; plots' cursors; the numbers panel), measured inside the
  page with performance.now(), as a fraction of the 16.7 ms a 60 Hz frame allows;
* frames: requestAnimationFrame callbacks per second (headless Chromium paces them at the
  display rate it emulates, 60 Hz, when the page keeps up).

The baseline is the frame budget itself (16.7 ms), which does not depend on the machine.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402
from vloop.views.view import render  # noqa: E402

CHROMIUM_ARGS = [
    "--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
    "--disable-component-update", "--no-first-run", "--disable-sync",
]  # fmt: skip
BUDGET_MS = 1000 / 60


def pages(folder: Path) -> list[tuple[str, Path, float]]:
    out = []
    for name in ("eightbar", "jansen_pair"):
        mech = vloop.load(ROOT / "mechanisms" / f"{name}.toml")
        for n in (None, 5000):
            times = None if n is None else np.linspace(mech.times[0], mech.times[-1], n)
            result = vloop.solve(mech, times=times)
            t0 = time.perf_counter()
            text = render(mech, result)
            built = time.perf_counter() - t0
            path = folder / f"{name}_{len(result)}.html"
            path.write_text(text, encoding="utf-8")
            out.append((f"{name}, {len(result)} samples", path, built))
    return out


def measure(browser, path: Path, seconds: float) -> dict[str, float]:
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    t0 = time.perf_counter()
    page.goto(path.as_uri())
    page.wait_for_selector("body[data-ready]", state="attached", timeout=60_000)
    opened = time.perf_counter() - t0
    for layer in ("vel", "acc", "paths"):
        page.click(f'[data-overlay="{layer}"]')
    page.evaluate("() => { const s = vloopViewer.stats; s.frames = 0; s.k = 0; s.drawMs.fill(0); vloopViewer.play(); }")
    page.wait_for_timeout(seconds * 1000)
    stats = page.evaluate(
        "() => { vloopViewer.pause(); const s = vloopViewer.stats;"
        " return {frames: s.frames, draws: Array.from(s.drawMs.slice(0, Math.min(s.k, s.drawMs.length)))}; }"
    )
    page.close()
    draws = np.array(stats["draws"]) if stats["draws"] else np.zeros(1)
    return {
        "open_s": opened,
        "fps": stats["frames"] / seconds,
        "draw_mean": float(draws.mean()),
        "draw_p95": float(np.percentile(draws, 95)),
        "draw_max": float(draws.max()),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=3.0)
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    with tempfile.TemporaryDirectory(prefix="vloop-bench-viewer-") as tmp, sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
        print(f"{'page':32s} {'size':>9s} {'build':>7s} {'open':>7s} {'frames/s':>9s} "
              f"{'draw mean':>10s} {'p95':>7s} {'max':>7s}  (draw as a fraction of the 16.7 ms frame)")  # fmt: skip
        for label, path, built in pages(Path(tmp)):
            m = measure(browser, path, args.seconds)
            print(
                f"{label:32s} {path.stat().st_size / 1e6:7.2f}MB {built:6.2f}s {m['open_s']:6.2f}s {m['fps']:9.1f} "
                f"{m['draw_mean'] / BUDGET_MS:10.3f} {m['draw_p95'] / BUDGET_MS:7.3f} {m['draw_max'] / BUDGET_MS:7.3f}"
            )
        browser.close()


if __name__ == "__main__":
    main()
