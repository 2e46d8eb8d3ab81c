"""The instructors' HTML report: content, self-containment, and a real render in headless Chromium.

One report is built for the module (three catalog mechanisms, engines vloop, analytic and
pinocchio, an animated GIF each, one engine failure injected and one unreadable file) and
every test reads it. The browser tests open it in Debian's Chromium with no network use:
one run dumps the DOM after a probe script has drawn every <img> onto a canvas (which forces
a full decode) and counted its inked pixels, another takes a screenshot that is checked for
size and content.
"""

from __future__ import annotations

import html
import json
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from markupsafe import escape
from PIL import Image

import vloop
from reports.html import write_report
from validators import harness
from vloop.method.equations import describe

from .conftest import MECHANISMS

NAMES = ("eightbar", "fourbar_nongrashof_past_limit", "whitworth_quick_return")
ENGINES = ("vloop", "analytic", "pinocchio")
INJECTED = "RuntimeError: synthetic engine failure injected by test_report"
BAD_FILE = "broken_on_purpose"


@dataclass
class Built:
    validation: harness.Validation
    path: Path
    text: str


@pytest.fixture(scope="module")
def built(tmp_path_factory: pytest.TempPathFactory) -> Built:
    tmp = tmp_path_factory.mktemp("report")
    bad = tmp / f"{BAD_FILE}.toml"
    bad.write_text('name = "broken_on_purpose"\n[joints]\nA = [0, "x"]\n', encoding="utf-8")
    v = harness.run([*(MECHANISMS / f"{n}.toml" for n in NAMES), bad], engines=ENGINES)
    # an engine that fails outright must be shown, not hidden: replace whitworth's Pinocchio run
    item = next(it for it in v.items if it.name == "whitworth_quick_return")
    item.runs["pinocchio"] = failed = harness.EngineRun("pinocchio", "error", None, INJECTED, 0.01)
    item.checks = [c for c in item.checks if c.engine != "pinocchio"]
    item.checks.append(harness.check(failed, item.runs["vloop"], item.name))
    path = write_report(v, harness.to_summary(v), tmp / "out", animate=True)
    return Built(v, path, path.read_text(encoding="utf-8"))


def _section(text: str, name: str) -> str:
    m = re.search(rf'<section class="mech" id="m\d+-{re.escape(name)}">(.*?)</section>', text, re.S)
    assert m, f"no section for {name}"
    return m.group(1)


# ------------------------------------------------------------------ content


def test_report_is_self_contained(built: Built) -> None:
    text = built.text
    assert built.path.name == "report.html"
    assert not re.search(r"https?://", text), "the report references the network"
    assert not re.search(r"<(link|script|iframe|object|embed)\b", text, re.I)
    assert "@import" not in text and "url(" not in text
    sources = re.findall(r'\bsrc="([^"]*)"', text)
    assert sources and all(s.startswith(("data:image/png;base64,", "data:image/gif;base64,")) for s in sources)
    hrefs = re.findall(r'\bhref="([^"]*)"', text)
    inside = [h for h in hrefs if h.startswith("#")]
    viewers = [h for h in hrefs if not h.startswith("#")]
    assert inside and all(re.fullmatch(r"viewer/m\d+-[\w-]+\.html", h) for h in viewers), "links inside the page only"
    for h in inside[1:]:
        assert f'id="{h[1:]}"' in text, f"dangling link {h}"
    assert built.path.stat().st_size < 4e6


def test_each_solved_mechanism_links_its_viewer_page(built: Built) -> None:
    for item in built.validation.items:
        links = re.findall(r'href="(viewer/[^"]+)"', _section(built.text, item.name))
        if item.error:
            assert not links
            continue
        assert len(links) == 1
        page = (built.path.parent / links[0]).read_text(encoding="utf-8")
        assert f'"name":"{item.name}"' in page and "default-src 'none'" in page
        stopped = item.runs["vloop"].status == "stopped"
        assert ('"error":null' not in page) == stopped


def test_front_page(built: Built) -> None:
    text = built.text
    front = text[: text.index('<section class="mech"')]
    assert "FAILED" in front  # the injected failure and the bad file fail the run
    for e in ENGINES:
        assert f'<span class="mono">{e}</span>' in front
    for k, v in built.validation.versions.items():
        assert f"{k} {v}" in front
    rows = re.findall(r"<tr>\s*<td><a href=\"#(m\d+-[^\"]+)\">", front)
    assert [r.split("-", 1)[1] for r in rows] == [*NAMES, BAD_FILE]


def test_each_section_has_its_loops_and_equations(built: Built) -> None:
    for item in built.validation.items:
        if item.error:
            continue
        sec = _section(built.text, item.name)
        system = vloop.compile(item.mechanism)
        assert system.loops
        for lp in system.loops:
            assert f"loop {lp.index + 1} ({lp.label})" in sec
        assert str(escape(describe(system))) in sec
        assert sec.count("data:image/png;base64,") >= 3  # drawing, histories, errors
        assert sec.count("data:image/gif;base64,") == 1


def test_failed_and_stopped_runs_are_shown(built: Built) -> None:
    sec = _section(built.text, "whitworth_quick_return")
    assert str(escape(INJECTED)) in sec
    assert re.search(r'<tr class="run-error">\s*<td class="mono">pinocchio</td>', sec)
    assert "pinocchio gave no result" in sec  # its comparison failed, and says why
    stopped = _section(built.text, "fourbar_nongrashof_past_limit")
    item = next(it for it in built.validation.items if it.name == "fourbar_nongrashof_past_limit")
    assert item.runs["vloop"].status == "stopped"
    assert stopped.count('class="run-stopped"') == len(ENGINES)
    assert str(escape(item.runs["vloop"].message.splitlines()[0])) in stopped


def test_unreadable_file_gets_a_section(built: Built) -> None:
    item = next(it for it in built.validation.items if it.error)
    sec = _section(built.text, BAD_FILE)
    assert "could not be loaded" in sec
    assert str(escape(item.error)) in sec


# ------------------------------------------------------------------ in a real browser

_PROBE = """
<img alt="control: broken on purpose" src="data:image/png;base64,iVBORw0KGgoAAAANSUhEUgAAAAEAAAAB">
<script>
window.addEventListener("load", function () {
  var out = Array.prototype.map.call(document.images, function (im) {
    var r = {alt: im.alt, w: im.naturalWidth, h: im.naturalHeight, drawn: false, inked: 0};
    try {
      var c = document.createElement("canvas");
      c.width = im.naturalWidth; c.height = im.naturalHeight;
      var g = c.getContext("2d");
      g.drawImage(im, 0, 0);
      var d = g.getImageData(0, 0, c.width, c.height).data, ink = 0;
      for (var i = 0; i < d.length; i += 4) { if (d[i + 3] > 0 && d[i] + d[i + 1] + d[i + 2] < 600) ink++; }
      r.drawn = true; r.inked = ink / (d.length / 4);
    } catch (e) { r.error = String(e); }
    return r;
  });
  var p = document.createElement("pre");
  p.id = "image-probe";
  p.textContent = JSON.stringify({title: document.title, images: out});
  document.body.appendChild(p);
});
</script>
"""


def _chromium() -> str:
    exe = shutil.which("chromium") or ("/usr/bin/chromium" if Path("/usr/bin/chromium").exists() else None)
    if exe is None:
        pytest.skip("chromium not installed: apt-get install -y chromium (CI's .ci/run installs it)")
    return exe


def _browse(page: Path, *args: str) -> subprocess.CompletedProcess[str]:
    """Headless Chromium on a local file, fresh profile, nothing fetched from the network."""
    with tempfile.TemporaryDirectory(prefix="vloop-chromium-") as profile:
        cmd = [
            _chromium(), "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
            "--disable-background-networking", "--disable-component-update", "--disable-sync",
            "--disable-dev-shm-usage", "--hide-scrollbars", f"--user-data-dir={profile}", *args, page.as_uri(),
        ]  # fmt: skip
        return subprocess.run(cmd, capture_output=True, text=True, timeout=60, check=False)


def test_every_image_decodes_in_chromium(built: Built) -> None:
    probe = built.path.with_name("probe.html")
    probe.write_text(built.text.replace("</body>", _PROBE + "</body>"), encoding="utf-8")
    run = _browse(probe, "--virtual-time-budget=10000", "--dump-dom")
    m = re.search(r'<pre id="image-probe">(.*?)</pre>', run.stdout, re.S)
    assert m, f"the probe did not run (exit {run.returncode}): {run.stderr[-1500:]}"
    found = json.loads(html.unescape(m.group(1)))
    assert found["title"].startswith("vloop cross-validation report")
    *images, control = found["images"]
    assert control["alt"].startswith("control") and not control["drawn"], "the probe must catch a broken image"
    sizes = [(int(w), int(h)) for w, h in re.findall(r'<img src="data:[^"]*" width="(\d+)" height="(\d+)"', built.text)]
    assert len(images) == len(sizes) == built.text.count("<img ")
    assert len(images) >= 4 * (len(NAMES))
    for img, (w, h) in zip(images, sizes, strict=True):
        assert img["drawn"], f"{img['alt']}: {img.get('error')}"
        assert (img["w"], img["h"]) == (w, h), f"{img['alt']}: decoded at {img['w']}×{img['h']}, expected {w}×{h}"
        assert 0.005 < img["inked"] < 0.6, f"{img['alt']}: {img['inked']:.1%} of its pixels are drawn"


def test_screenshot_in_chromium(built: Built, tmp_path: Path) -> None:
    shot = tmp_path / "report.png"
    width, height = 1280, 2600  # the front page and the first mechanism's drawing
    run = _browse(built.path, f"--screenshot={shot}", f"--window-size={width},{height}")
    assert shot.exists(), f"no screenshot (exit {run.returncode}): {run.stderr[-1500:]}"
    img = Image.open(shot).convert("RGB")
    assert img.size == (width, height)
    px = np.asarray(img, dtype=float)
    assert px.std() > 20, "the screenshot is blank"
    assert np.mean(px.sum(axis=2) < 600) > 0.03, "too little drawn for a page of tables and figures"

    r, g, b = px[..., 0], px[..., 1], px[..., 2]
    fail_bg = (np.abs(r - 0xFD) < 6) & (np.abs(g - 0xE7) < 6) & (np.abs(b - 0xEA) < 6)
    assert fail_bg.sum() > 2000, "the red FAILED banner and cells are not rendered"
    orange = (r > 190) & (g > 110) & (g < 185) & (b < 120)  # slider blocks, in the drawing and the animation
    assert orange.sum() > 200, "the mechanism drawing is not rendered"
