"""A griffe extension for the API reference: Sphinx roles in docstrings (:func:`x`, :class:`~a.B`) shown as code.

vloop's docstrings name other objects the Sphinx way; Markdown would print the role itself
(":func:" before the code span). The role is dropped and a leading ``~`` (Sphinx: show the last part
only) applied, so the reader sees ``x`` and ``B``.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:py:)?(?:func|meth|class|mod|attr|data|exc|obj|const):`(~?)([^`]+)`")


def plain(text: str) -> str:
    """The docstring with every Sphinx role replaced by a code span of its target."""
    return _ROLE.sub(lambda m: f"`{m.group(2).rsplit('.', 1)[-1] if m.group(1) else m.group(2)}`", text)


class SphinxRoles(griffe.Extension):
    """Rewrites each object's docstring once, when griffe has loaded it."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = plain(obj.docstring.value)
