"""The studio's page: the viewer's page (its HTML, style and script) with the studio's panel and script added.

Both scripts are inline and allowed by their hashes; the page may connect only to its own host's WebSocket
(``connect``), or to nothing (the notebook widget's copy talks through the kernel)."""

from __future__ import annotations

import base64
import hashlib
import html
from pathlib import Path

from vloop.views.view import ASSETS

STATIC = Path(__file__).resolve().parent / "static"


def asset(name: str) -> str:
    return (STATIC / name).read_text(encoding="utf-8")


def viewer_asset(name: str) -> str:
    return (ASSETS / name).read_text(encoding="utf-8")


def _digest(script: str) -> str:
    return base64.b64encode(hashlib.sha256(script.encode("utf-8")).digest()).decode("ascii")


def render(connect: str, token: str, title: str = "vloop studio") -> str:
    """The studio page for a browser: ``connect`` is the WebSocket origin it may reach (``ws://127.0.0.1:PORT``)."""
    viewer, studio = viewer_asset("viewer.js"), asset("studio.js")
    csp = (
        f"default-src 'none'; script-src 'sha256-{_digest(viewer)}' 'sha256-{_digest(studio)}'; "
        f"style-src 'unsafe-inline'; img-src data:; connect-src {connect}"
    )
    page = viewer_asset("page.html")
    values = {
        "__CSP__": html.escape(csp, quote=True),
        "__TITLE__": html.escape(title),
        "__HEADING__": "vloop studio",
        "__NAME__": "draw, drag and design",
        "/*__CSS__*/": viewer_asset("viewer.css") + "\n" + asset("studio.css"),
        "__DATA__": "",
        "/*__JS__*/": viewer,
    }
    for key, value in values.items():
        page = page.replace(key, value, 1)
    panel = asset("panel.html").replace("__TOKEN__", html.escape(token, quote=True))
    page = page.replace("<main>", panel + "\n<main>", 1)
    return page.replace("</body>", f"<script>{studio}</script>\n</body>", 1)


def widget_parts() -> dict[str, str]:
    """What the notebook widget puts in its cell: the panel, the style and both scripts."""
    return {
        "css": viewer_asset("viewer.css") + "\n" + asset("studio.css"),
        "body": viewer_asset("page.html").split("<body>", 1)[1].split("<script", 1)[0],
        "panel": asset("panel.html").replace("__TOKEN__", ""),
        "viewer": viewer_asset("viewer.js"),
        "studio": asset("studio.js"),
    }
