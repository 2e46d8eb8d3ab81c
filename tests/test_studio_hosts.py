"""The studio's two hosts over one session: the notebook widget answers exactly as Session.handle does (its front end
drawn by the same scripts, in chromium, talking to the widget in this process), and `vloop studio` starts, refuses
bad arguments in one line (exit 2) and stops cleanly on Ctrl-C."""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import urllib.request
from pathlib import Path

import pytest

import vloop

from .conftest import MECHANISMS

pytest.importorskip("anywidget", reason="the studio's extra is not installed (pip install -e '.[studio]')")
ROOT = Path(__file__).parents[1]
TEXTBOOK = MECHANISMS / "fourbar_textbook_example.toml"


class Wire:
    """What the notebook's front end would receive: every message the widget sends."""

    def __init__(self, widget) -> None:
        self.sent: list[dict] = []
        widget.send = lambda content, buffers=None: self.sent.append(json.loads(content["text"]))


def test_the_widget_is_the_session() -> None:
    from vloop.studio.session import Session

    mech = vloop.load(TEXTBOOK)
    widget = vloop.studio(mech)
    wire = Wire(widget)
    twin = Session(None, vloop.mechanism.to_dict(mech))
    for msg in ({"op": "state", "id": 1}, {"op": "drag", "joint": "B", "x": 150.0, "y": 80.0, "id": 2, "gesture": 1},
                {"op": "undo", "id": 3}, {"op": "save", "path": "x.toml", "id": 4}, {"op": "nope", "id": 5}):  # fmt: skip
        widget._receive(widget, {"text": json.dumps(msg)}, [])
        assert wire.sent[-1] == json.loads(json.dumps(twin.handle(msg), default=str)), msg
    widget._receive(widget, {"text": "{not json"}, [])
    assert wire.sent[-1]["ok"] is False
    assert not wire.sent[3]["ok"] and "without a folder" in wire.sent[3]["error"]  # no folder: no file access


def test_the_widget_front_end_talks_to_the_kernel(tmp_path: Path) -> None:
    """The widget's ESM rendered in chromium with a stand-in for the notebook's model: each message the page sends is
    answered by the widget's own handler in this process, and the page draws the answers."""
    chromium = Path("/usr/bin/chromium")
    if not chromium.exists():
        pytest.skip("Debian's chromium is not installed at /usr/bin/chromium")
    sync_api = pytest.importorskip("playwright.sync_api", reason="playwright is not installed")
    widget = vloop.studio(vloop.load(TEXTBOOK))
    host = tmp_path / "notebook.html"
    host.write_text("<!DOCTYPE html><html><body><div id='cell'></div></body></html>")
    (tmp_path / "widget.mjs").write_text(widget._esm)
    args = ["--headless", "--no-sandbox", "--disable-gpu", "--allow-file-access-from-files"]
    with sync_api.sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=str(chromium), args=args)
        page = browser.new_page(viewport={"width": 1400, "height": 1000})
        problems: list[str] = []
        page.on("pageerror", lambda e: problems.append(str(e)))
        outbox: list[str] = []
        widget.send = lambda content, buffers=None: outbox.append(content["text"])

        def kernel(text: str) -> None:  # the kernel's side of model.send
            widget._receive(widget, {"text": text}, [])

        page.expose_function("kernel", kernel)
        page.goto(host.resolve().as_uri())
        page.evaluate(
            """async ([url, parts]) => {
              const handlers = [];
              const model = { get: () => parts, send: (m) => window.kernel(m.text), on: (ev, fn) => handlers.push(fn) };
              window.deliver = (text) => handlers.forEach((fn) => fn({ text }));
              const mod = await import(url);
              mod.default.render({ model, el: document.getElementById("cell") });
            }""",
            [(tmp_path / "widget.mjs").resolve().as_uri(), widget.parts],
        )
        for _ in range(200):  # deliver the kernel's replies until the page has drawn the mechanism
            while outbox:
                page.evaluate("t => window.deliver(t)", outbox.pop(0))
            if page.evaluate(
                "!!document.body.dataset.studioReady && document.querySelectorAll('circle[data-handle]').length === 4"
            ):
                break
            page.wait_for_timeout(50)
        ax, ay = (float(page.locator('circle[data-joint="A"]').get_attribute(a)) for a in ("cx", "cy"))
        browser.close()
    assert problems == []
    a = math.radians(40)
    assert math.hypot(ax - 40 * math.cos(a), -ay - 40 * math.sin(a)) < 1e-9 * 40  # A at θ₂ = 40°, r = 40 mm


def _studio(*args: str, cwd: Path) -> subprocess.Popen:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen([sys.executable, "-m", "vloop.cli", "studio", *args], cwd=cwd, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)  # fmt: skip


def test_the_command_refuses_bad_arguments(tmp_path: Path) -> None:
    for args, words in ((["nowhere"], "no such file or folder"), (["--port", "99999"], "port number")):
        proc = _studio(*args, "--no-browser", cwd=tmp_path)
        _, err = proc.communicate(timeout=60)
        assert proc.returncode == 2 and words in err and "Traceback" not in err and len(err.strip().splitlines()) == 1


def test_the_command_serves_then_stops_on_ctrl_c(tmp_path: Path) -> None:
    (tmp_path / "m.toml").write_text(TEXTBOOK.read_text())
    proc = _studio("m.toml", "--no-browser", cwd=tmp_path)
    try:
        url = next(line.strip() for line in proc.stdout if "?token=" in line)
        assert url.startswith("http://127.0.0.1:")
        page = urllib.request.urlopen(url, timeout=30).read().decode()
        assert "vloop studio" in page
        with pytest.raises(urllib.error.HTTPError):
            urllib.request.urlopen(url.split("?")[0], timeout=30)
    finally:
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
    assert proc.returncode == 0 and "Traceback" not in err, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.toml"]
