"""The documentation site builds with warnings as errors, every link and anchor in it resolves, nothing in it
is fetched from the network, and the key tables in it are the schemas' own.

MkDocs' strict build checks the links written in the pages (validation settings in mkdocs.yml: links to
missing pages and missing anchors are warnings, strict makes them errors). The built HTML is then read back
to check what MkDocs does not: the links that the theme, the navigation and the API reference generate,
and that every script, stylesheet and image is a file of the site (the site works offline). The notebooks
are pages with their outputs, the API pages show no raw reST, the tutorials lead the navigation, and search
works with the site opened from disk (a headless browser).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from html import unescape
from html.parser import HTMLParser
from pathlib import Path
from urllib.parse import unquote, urlsplit

import pytest

from vloop.files import schema
from vloop.studies import studyfile
from vloop.synthesis import spec as synthspec

ROOT = Path(__file__).parents[1]
DOCS = ROOT / "docs"


class _Page(HTMLParser):
    """The ids of one HTML page, its links (a href) and the resources it loads (script, link, img, ...)."""

    def __init__(self) -> None:
        super().__init__()
        self.ids: set[str] = set()
        self.links: list[str] = []
        self.resources: list[str] = []

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        for key in ("id", "name"):
            if a.get(key):
                self.ids.add(a[key])
        if tag == "a" and a.get("href"):
            self.links.append(a["href"])
        elif tag in ("script", "img", "iframe", "source", "audio", "video") and a.get("src"):
            self.resources.append(a["src"])
        elif tag == "link" and a.get("href") and "canonical" not in (a.get("rel") or ""):
            self.resources.append(a["href"])


def _target(site: Path, page: Path, path: str) -> Path:
    """The file a link's path names: relative to the page, or to the site's root when it starts with / (the
    404 page's links, which a server shows at any depth)."""
    base = site if path.startswith("/") else page.parent
    target = (base / unquote(path).lstrip("/")).resolve()
    return target / "index.html" if target.is_dir() else target


def _read(site: Path) -> dict[Path, _Page]:
    pages = {}
    for path in site.resolve().rglob("*.html"):
        page = _Page()
        page.feed(path.read_text(encoding="utf-8"))
        pages[path.resolve()] = page
    return pages


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    pytest.importorskip("mkdocs", reason="the docs extra is not installed (pip install -e '.[docs]')")
    pytest.importorskip("mkdocstrings")
    out = tmp_path_factory.mktemp("site")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
    cmd = [sys.executable, "-m", "mkdocs", "build", "--strict", "--config-file", str(ROOT / "mkdocs.yml")]
    proc = subprocess.run(
        [*cmd, "--site-dir", str(out)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=300
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return out


def test_every_page_is_built(site):
    """Each Markdown page becomes a page of the site (mkdocs.yml's nav names them all: strict refuses a page
    left out of it), and the API reference holds the public modules."""
    for md in DOCS.rglob("*.md"):
        assert (site / md.relative_to(DOCS).with_suffix(".html")).is_file(), md
    api = (site / "api" / "vloop.html").read_text(encoding="utf-8")
    for name in ("vloop.solve", "vloop.load", "vloop.MotionError"):
        assert f'id="{name}"' in api, name
    assert ":func:" not in api and ":class:" not in api  # Sphinx roles are shown as code, not as text


def test_every_link_and_anchor_resolves(site):
    pages = _read(site)
    broken = []
    for path, page in pages.items():
        for href in page.links:
            parts = urlsplit(href)
            if parts.scheme or parts.netloc or href.startswith("mailto:"):
                continue  # a link out of the site: the reader follows it, the site never fetches it
            target = _target(site, path, parts.path) if parts.path else path
            if not target.is_file():
                broken.append(f"{path.relative_to(site)}: {href} (no such file)")
            elif parts.fragment and target.suffix == ".html" and unquote(parts.fragment) not in pages[target].ids:
                broken.append(f"{path.relative_to(site)}: {href} (no such anchor)")
    assert not broken, "\n".join(broken[:20])


def test_the_site_fetches_nothing(site):
    """Every script, stylesheet and image is a file of the site: it reads the same offline."""
    outside = []
    for path, page in _read(site).items():
        for src in page.resources:
            parts = urlsplit(src)
            if parts.scheme in ("data",):
                continue
            if parts.scheme or parts.netloc or not _target(site, path, parts.path).is_file():
                outside.append(f"{path.relative_to(site)}: {src}")
    assert not outside, "\n".join(outside[:20])


def _generated(page: str, marker: str) -> str:
    text = (DOCS / page).read_text(encoding="utf-8")
    block = re.search(rf"<!-- {marker}:begin -->\n(.*?)<!-- {marker}:end -->", text, re.S)
    assert block is not None, f"docs/{page} lost its generated key tables"
    return block.group(1)


def test_file_format_tables_are_the_schema():
    assert _generated("file-format.md", "schema") == schema.markdown(), (
        "docs/file-format.md's key tables differ from vloop/files/schema.py: regenerate them with "
        'python -c "import vloop.files.schema as s; print(s.markdown())"'
    )


def test_study_tables_are_the_study_schema():
    assert _generated("studies.md", "study-schema") == studyfile.markdown(), (
        "docs/studies.md's key tables differ from vloop/studies/studyfile.py: regenerate them with "
        'python -c "import vloop.studies.studyfile as s; print(s.markdown())"'
    )


def test_synthesis_tables_are_the_synthesis_schema():
    assert _generated("synthesis.md", "synthesis-schema") == synthspec.markdown(), (
        "docs/synthesis.md's key tables differ from vloop/synthesis/spec.py: regenerate them with "
        'python -c "import vloop.synthesis.spec as s; print(s.markdown())"'
    )


SCHEMAS = {"mechanism": schema.SECTIONS, "study": studyfile.SECTIONS, "synthesis": synthspec.SECTIONS}


@pytest.mark.parametrize("name", SCHEMAS)
def test_every_generated_row_has_its_five_cells(name):
    """Rendered by Python-Markdown (the site's renderer), each row of the key tables has exactly its five
    cells holding the key's own texts, whatever `|` they contain ("auto" | "newton", joints.J.x|y, max |x|,
    the sides |J0J1|)."""
    markdown = pytest.importorskip("markdown")
    sections = SCHEMAS[name]
    html = markdown.markdown(schema.markdown(sections), extensions=["tables"])
    rows = [re.findall(r"<td>(.*?)</td>", row, re.S) for row in re.findall(r"<tr>(.*?)</tr>", html, re.S)]
    rows = [[unescape(re.sub(r"<[^>]+>", "", cell)) for cell in row] for row in rows if row]
    expected = [[k.name, k.type, k.default, k.unit or "—", k.doc] for s in sections for k in s.keys]
    expected = [[re.sub(r"`([^`]*)`", r"\1", cell) for cell in row] for row in expected]  # `code` shows as code
    assert rows == expected


def test_the_escaped_case_is_tested():
    """The five-cell test above meets a `|` inside a cell (else it would not test the escape)."""
    keys = [k for sections in SCHEMAS.values() for s in sections for k in s.keys]
    assert any("|" in text for k in keys for text in (k.name, k.type, k.default, k.unit, k.doc))


def test_the_notebooks_are_pages_with_their_outputs(site):
    """The example notebooks are executed at build time and shown with what their cells print and draw
    (not linked as raw JSON): the lecture's hand check, its figures as images of the site, the viewer inline."""
    lecture = (site / "lecture_fourbar.html").read_text(encoding="utf-8")
    study = (site / "design_study.html").read_text(encoding="utf-8")
    assert "by hand: θ3 = 20.2979°, θ4 = 57.3249°" in lecture and "power balance" in lecture
    assert (
        len(re.findall(r'<img [^>]*src="data:image/png;base64,', lecture)) >= 3 and 'sandbox="allow-scripts"' in lecture
    )
    assert "rocker swing: nominal" in study and "StudyResult(" in study
    notebooks = (site / "notebooks.html").read_text(encoding="utf-8")
    assert 'href="lecture_fourbar.html"' in notebooks and 'href="design_study.html"' in notebooks


def test_the_api_pages_show_no_raw_markup(site):
    """Docstrings' reST literals and Sphinx roles are rendered, never shown as ``text`` or :func:`text`."""
    raw = []
    for path in sorted((site / "api").glob("*.html")):
        text = unescape(re.sub(r"<[^>]+>", "", path.read_text(encoding="utf-8")))
        raw += [f"{path.name}: {m.group(0)}" for m in re.finditer(r"``[^`\n]+``|:(func|class|mod|meth|attr):`", text)]
    assert not raw, raw[:10]


def test_the_tutorials_lead_the_navigation():
    """Four tutorials (student, instructor, designer, nightly user) under "Tutorials", first after Home."""
    import yaml

    class _Loader(yaml.SafeLoader):  # mkdocs.yml's !ENV and !!python tags, read as plain values
        pass

    _Loader.add_multi_constructor("!", lambda loader, suffix, node: None)
    _Loader.add_multi_constructor("tag:yaml.org,2002:python/", lambda loader, suffix, node: None)
    nav = yaml.load((ROOT / "mkdocs.yml").read_text(encoding="utf-8"), Loader=_Loader)["nav"]
    assert list(nav[1]) == ["Tutorials"], nav[1]
    pages = [next(iter(entry.values())) for entry in nav[1]["Tutorials"]]
    assert pages == [f"tutorials/{n}.md" for n in ("student", "instructor", "designer", "nightly")]


def test_search_works_from_disk(site):
    """Opened as a file (file://, no server), the search box finds pages: the offline plugin inlines the index
    and the worker runs in an iframe (its shim is a file of the site); the browser fetches nothing from the
    network. Chromium headless, as the other browser tests."""
    sync_api = pytest.importorskip("playwright.sync_api", reason="pip install -e '.[dev]'")
    if not Path("/usr/bin/chromium").exists():
        pytest.skip("Debian's chromium is not installed (.ci/run installs it)")
    args = ["--no-sandbox", "--disable-gpu", "--disable-background-networking", "--disable-component-update"]
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium", args=args)
        try:
            page = browser.new_page()
            requested: list[str] = []
            page.on("request", lambda r: requested.append(r.url))
            page.goto((site / "index.html").resolve().as_uri())
            page.fill("input.md-search__input", "transmission")
            page.wait_for_selector(".md-search-result__item", timeout=30_000)
            found = page.locator(".md-search-result__item").all_inner_texts()
        finally:
            browser.close()
    assert any("transmission" in item.lower() for item in found), found[:3]
    outside = [u for u in requested if urlsplit(u).scheme not in ("file", "data", "blob", "about")]
    assert not outside, outside
