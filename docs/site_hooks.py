"""MkDocs hooks of the documentation site (mkdocs.yml: ``hooks``).

The notebook pages (mkdocs-jupyter) carry a MathJax loader whose address is empty when no MathJax is
configured: the notebooks write their formulas in Unicode, so the empty loader is dropped rather than
pointed at a CDN (the site fetches nothing).
"""

from __future__ import annotations

import re
from typing import Any

_EMPTY_SCRIPT = re.compile(r"<script src=\"\">\s*</script>")


def on_post_page(output: str, page: Any, config: Any) -> str:
    """Drop every ``<script src="">`` (an empty address loads the page itself as a script)."""
    return _EMPTY_SCRIPT.sub("", output)
