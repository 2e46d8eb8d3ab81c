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
    assert sources and all(s.startswith(("data:image/webp;base64,", "data:image/gif;base64,")) for s in sources)
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


def test_cells_say_the_engines_verdict_in_their_own_colour(built: Built) -> None:
    """A cell's badge is the engine's verdict on the mechanism (pass, blamed, error, ...), in the cell's colour: never
    a green "ok" over a red count."""
    front = built.text[: built.text.index('<section class="mech"')]
    cells = re.findall(r'<td class="cell (\w+)"[^>]*><span class="badge (\w+)">([^<]*)</span>', front)
    assert cells and not any(text == "ok" for _, _, text in cells)
    assert all(css == badge for css, badge, _ in cells)
    assert ("fail", "fail", "error") in cells  # whitworth's Pinocchio, which failed outright


def test_the_front_counts_the_whole_run_and_names_the_verdict():
    """A 30-mechanism corpus with one failure shows that failure only: the front still counts 29 of 30, and says
    whether the night is red (vloop may be wrong) or only a reference engine failed."""
    from reports.html import _counts, overall

    tally = {"exudyn-dynamic": {"pass": 29, "blamed": 1, "undecided": 0, "inconclusive": 0}}
    summary = {"passed": False, "red": False, "counts": {"mechanisms": 30, "passed": 29, "red": 0},
               "verdicts": {"engines": tally, "mechanisms": {"pass": 29, "blamed": 1}, "vloop_blamed": []},
               "mechanisms": [{"name": "c00022", "passed": False}]}  # fmt: skip
    assert _counts(summary, [{"passed": False}]) == {"total": 30, "passed": 29}
    front = overall(summary)
    assert (
        front["css"] == "warn" and front["text"] == "PASSED FOR VLOOP" and "exudyn-dynamic: 1 blamed" in front["note"]
    )
    red = overall(summary | {"red": True, "verdicts": {**summary["verdicts"], "vloop_blamed": ["c00022"]}})
    assert red == {"css": "fail", "text": "FAILED", "note": "vloop blamed on 1, undecided on 0"}
    assert overall({"passed": True, "red": False})["text"] == "ALL PASSED"


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
        assert sec.count("data:image/webp;base64,") >= 3  # drawing, histories, errors
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


# ------------------------------------------------------------------ size and layout


def test_figures_are_lossless_webp_of_the_palette_image(built: Built) -> None:
    """Every figure is lossless WebP (the 'VP8L' chunk), and its pixels are exactly those of the figure
    rendered and reduced to 256 colours the way a palette PNG would hold them (a figure drawn twice)."""
    import base64
    import io

    from reports.html import DPI, _new_figure, _picture

    for uri in re.findall(r'src="data:image/webp;base64,([^"]+)"', built.text):
        data = base64.b64decode(uri)
        assert data[:4] == b"RIFF" and data[8:16] == b"WEBPVP8L", "not lossless WebP"

    def figure():
        fig = _new_figure(4.0, 3.0)
        ax = fig.add_subplot()
        t = np.linspace(0.0, 1.0, 300)
        for k in range(10):
            ax.plot(t, np.sin(6 * t + k), lw=1.5, alpha=0.6 if k % 2 else 1.0, label=f"curve {k}")
        ax.legend()
        ax.set_title("ten curves, half of them translucent")
        return fig

    image = _picture(figure(), "test")
    got = Image.open(io.BytesIO(base64.b64decode(image.uri.split(",", 1)[1]))).convert("RGB")
    buf = io.BytesIO()
    figure().savefig(buf, format="png", dpi=DPI, bbox_inches="tight", pad_inches=0.08, facecolor="white")
    rgb = Image.open(buf).convert("RGB")
    want = rgb.quantize(colors=256, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE).convert("RGB")
    assert (image.width, image.height) == got.size == want.size
    assert np.array_equal(np.asarray(got), np.asarray(want))


_LAYOUT_PROBE = """
<script>
window.addEventListener("load", function () {
  var out = [];
  document.querySelectorAll("table").forEach(function (t, k) {
    var box = t.parentElement.getBoundingClientRect();
    t.querySelectorAll("th, td").forEach(function (c) {
      var r = c.getBoundingClientRect();
      if (r.width === 0) return;
      if (r.left < box.left - 0.5 || r.right > box.right + 0.5 || r.right > innerWidth)
        out.push({table: t.id || t.className || String(k), cell: c.textContent.trim().slice(0, 40), right: r.right,
                  container: box.right, viewport: innerWidth});
    });
  });
  var p = document.createElement("pre");
  p.id = "layout-probe";
  p.textContent = JSON.stringify({tables: document.querySelectorAll("table").length, outside: out, width: innerWidth});
  document.body.appendChild(p);
});
</script>
"""


def test_every_table_cell_fits_at_1400_px(built: Built, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The summary with all five engine columns (the catalog's validation), the longest catalog name and a
    stopped run's STOPPED badges, and the per-group tables: every cell inside its container and the window."""
    import copy
    import dataclasses

    import reports.html as report_html

    wide = copy.deepcopy(built.validation)
    extra = ("exudyn-kinematic", "exudyn-dynamic")
    for item in wide.items:
        if item.error:
            continue
        for e in extra:  # the vloop run and its checks under the other engines' names
            item.runs[e] = dataclasses.replace(item.runs["vloop"], engine=e)
            item.checks += [dataclasses.replace(c, engine=e) for c in item.checks if c.engine == "pinocchio"]
    summary = harness.to_summary(wide) | {"engines": [*ENGINES, *extra]}
    blank = report_html.Image("data:image/webp;base64,", 10, 10, "figure")
    monkeypatch.setattr(report_html, "_picture", lambda fig, alt, dpi=0: blank)  # layout only: no figure pixels
    text = report_html.render(wide, summary)
    assert text.count('<th class="mono" style="text-align:center">') == 5 and "STOPPED".lower() in text
    page = tmp_path / "wide.html"
    page.write_text(text.replace("</body>", _LAYOUT_PROBE + "</body>"), encoding="utf-8")
    run = _browse(page, "--window-size=1400,1000", "--virtual-time-budget=5000", "--dump-dom")
    m = re.search(r'<pre id="layout-probe">(.*?)</pre>', run.stdout, re.S)
    assert m, f"the probe did not run (exit {run.returncode}): {run.stderr[-1500:]}"
    found = json.loads(html.unescape(m.group(1)))
    assert found["width"] == 1400 and found["tables"] >= 2 + len(NAMES)
    assert found["outside"] == [], found["outside"][:5]
