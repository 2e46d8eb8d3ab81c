"""The studio's drag: a pointer event's round trip to a redrawn frame, and the page during a validation.

    python benchmarks/bench_studio.py                 # textbook four-bar and eight-bar, 360 samples, 40 drags each
    python benchmarks/bench_studio.py --drags 80 --no-validate

For each mechanism the studio is served by ``vloop studio FOLDER --no-browser`` in its own process (as a person
runs it) and opened in headless Chromium (Debian's). A joint is dragged by real pointer events, one at a time: each
round trip runs from the
``pointermove`` handler (performance.now() in the page) through the WebSocket, the session's solve of every
displayed sample (vloop's core) and the viewer's redraw, to the next animation frame after the new drawing — the
frame the person sees. Reported: median, 95th percentile and their ratio, against the issue's targets (median ≤ 30 ms
for the four-bar, ≤ 80 ms for the eight-bar, p95 ≤ 2 × median). The baseline measured in the same process is the
session's own work per drag (Session.handle, no browser): the round trip's ratio to it is the cost of the page and
the socket. Then a validation (Pinocchio and Exudyn, ``vloop validate`` in a child process) is started from the
page's "check" button while a drag goes on, and every frame interval is recorded until the verdict shows: the longest
must stay under 100 ms.
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from vloop.studio.session import Session  # noqa: E402

CHROMIUM_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
                 "--disable-component-update", "--no-first-run", "--disable-sync"]  # fmt: skip
CASES = {  # catalog name: (joint dragged, its path: centre and radius of a small circle [file units], target ms)
    "fourbar_textbook_example": ("B", (143.19, 67.34), 3.0, 30.0),
    "eightbar": ("C", (8.0, 4.6715), 0.15, 80.0),
}


def session_baseline(name: str, joint: str, centre: tuple, radius: float, n: int) -> list[float]:
    """Session.handle of the same drags, no browser and no socket [ms]."""
    s = Session(None)
    s.handle({"op": "open", "catalog": name})
    out = []
    for k in range(n):
        a = 2 * np.pi * k / n
        t0 = time.perf_counter()
        r = s.handle({"op": "drag", "joint": joint, "x": centre[0] + radius * np.cos(a),
                      "y": centre[1] + radius * np.sin(a), "gesture": 1})  # fmt: skip
        out.append(1e3 * (time.perf_counter() - t0))
        assert r["ok"] and not r["state"].get("limit"), r.get("error") or r["state"].get("limit")
    return out


def screen(page, x: float, y: float) -> tuple[float, float]:
    js = (
        "([x, y]) => { const p = new DOMPoint(x, -y)"
        ".matrixTransform(document.getElementById('view').getScreenCTM()); return [p.x, p.y]; }"
    )
    return tuple(page.evaluate(js, [x, y]))


def drags(page, joint: str, centre: tuple, radius: float, n: int) -> list[float]:
    """n drags of ``joint`` around a small circle by real pointer events, each waited for [ms, round trip]."""
    page.click('.s-tool[data-tool="drag"]')
    page.mouse.move(*screen(page, *centre))
    page.mouse.down()
    for k in range(n):
        a = 2 * np.pi * k / n
        done = page.evaluate("vloopStudio.stats.drags.length")
        page.mouse.move(*screen(page, centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)))
        page.wait_for_function("n => vloopStudio.stats.drags.length > n", arg=done, timeout=30_000)
    page.mouse.up()
    return page.evaluate("vloopStudio.stats.drags.slice()")[-n:]


def during_validation(page, joint: str, centre: tuple, radius: float) -> tuple[float, int, str]:
    """Start a validation, keep dragging until its verdict shows; the longest frame interval [ms] and frame count."""
    page.evaluate("""() => { window.gaps = []; let last = performance.now();
        const tick = (now) => {
          window.gaps.push(now - last); last = now; if (!window.stopGaps) requestAnimationFrame(tick); };
        window.stopGaps = false; requestAnimationFrame(tick); }""")
    page.click("#s-validate")
    page.mouse.move(*screen(page, *centre))
    page.mouse.down()
    k = 0
    while page.locator("#s-verdict").is_hidden():
        a = 2 * np.pi * k / 24
        page.mouse.move(*screen(page, centre[0] + radius * np.cos(a), centre[1] + radius * np.sin(a)))
        page.wait_for_timeout(30)
        k += 1
        if k > 6000:
            raise TimeoutError("no verdict after 6,000 drags")
    page.mouse.up()
    gaps = page.evaluate("window.stopGaps = true, window.gaps.slice(1)")
    return max(gaps), len(gaps), page.locator("#s-verdict").inner_text().splitlines()[0]


def serve(folder: str) -> tuple[subprocess.Popen, str]:
    """``vloop studio FOLDER --no-browser`` as its own process (as a person runs it); its printed address."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    cmd = [sys.executable, "-m", "vloop.cli", "studio", folder, "--no-browser"]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, env=env)
    for line in proc.stdout:
        if "?token=" in line:
            return proc, line.strip()
    raise RuntimeError("vloop studio printed no address")


def run(name: str, args: argparse.Namespace, browser) -> None:
    joint, centre, radius, target = CASES[name]
    base = session_baseline(name, joint, centre, radius, args.drags)
    proc, url = serve(tempfile.mkdtemp(prefix="vloop-bench-"))
    page = browser.new_page(viewport={"width": 1400, "height": 1000})
    page.goto(url)
    page.wait_for_selector("body[data-studio-ready]", state="attached", timeout=30_000)
    page.select_option("#f-catalog [name=catalog]", name)
    before = page.evaluate("document.body.dataset.studioReady")
    page.click("#f-catalog button:not([name])")
    page.wait_for_function("b => document.body.dataset.studioReady !== b", arg=before)
    samples = page.evaluate("vloopViewer.samples")
    drags(page, joint, centre, radius, 5)  # warm-up: the page's first layouts, the solver's caches
    trips = drags(page, joint, centre, radius, args.drags)
    med, p95 = statistics.median(trips), float(np.percentile(trips, 95))
    bmed = statistics.median(base)
    print(f"{name}: {samples} samples, {args.drags} drags of {joint}")
    print(f"  round trip  median {med:6.1f} ms (target ≤ {target:.0f}: {'ok' if med <= target else 'OVER'}), "
          f"p95 {p95:6.1f} ms, p95/median {p95 / med:.2f} ({'ok' if p95 <= 2 * med else 'OVER'} ≤ 2)")  # fmt: skip
    print(f"  baseline    Session.handle median {bmed:6.1f} ms (same process): round trip / baseline {med / bmed:.2f}")
    replies = page.evaluate("vloopStudio.stats.replies.slice()")[-args.drags :]
    server = page.evaluate("vloopStudio.stats.server.slice()")[-args.drags :]
    later = page.evaluate("vloopStudio.stats.later.slice()")[-args.drags :]
    loads = np.array(page.evaluate("vloopStudio.stats.loads.slice()")[-args.drags :])
    print(
        f"  where       reply in {statistics.median(replies):.1f} ms (session {statistics.median(server):.1f} ms "
        "in the server, the rest socket and JSON); page's redraw median "
        f"[decode, scene, plots, numbers, draw] = {np.round(np.median(loads, axis=0), 1).tolist()} ms, then plots "
        f"and numbers after the frame {statistics.median(later):.1f} ms"
    )
    if args.validate:
        worst, frames, verdict = during_validation(page, joint, centre, radius)
        print(f"  validation  {verdict!r}; {frames} frames, longest {worst:.1f} ms "
              f"({'ok' if worst <= 100 else 'OVER'} ≤ 100)")  # fmt: skip
    page.close()
    proc.send_signal(signal.SIGINT)  # Ctrl-C: the server stops cleanly
    proc.wait(30)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--drags", type=int, default=40)
    ap.add_argument("--no-validate", dest="validate", action="store_false")
    ap.add_argument("--only", choices=sorted(CASES))
    args = ap.parse_args()
    from playwright.sync_api import sync_playwright

    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path="/usr/bin/chromium", args=CHROMIUM_ARGS)
        for name in [args.only] if args.only else CASES:
            run(name, args, browser)
        browser.close()


if __name__ == "__main__":
    main()
