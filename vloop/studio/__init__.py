"""vloop studio: draw, drag and design a linkage in the browser or a notebook, every frame solved by vloop.

One session (:class:`~vloop.studio.session.Session`: a message dict in, a reply dict out) and two thin hosts over
it: a local web app (:mod:`vloop.studio.server`, ``vloop studio``) and a Jupyter widget (:func:`studio`).
"""

from __future__ import annotations

import sys
import types
from typing import Any


def studio(mechanism: Any = None, **options: Any) -> Any:
    """The studio inline in a notebook (an anywidget): ``vloop.studio(mech)`` as a cell's last line."""
    from .widget import Studio

    return Studio(mechanism, **options)


__all__ = ["studio"]


class _Callable(types.ModuleType):
    """``vloop.studio`` is this package once any part of it is imported: calling it opens the widget."""

    def __call__(self, mechanism: Any = None, **options: Any) -> Any:
        return studio(mechanism, **options)


sys.modules[__name__].__class__ = _Callable
