"""A progress bar on stderr for long runs: shown after about a second, only when stderr is a terminal.

Uses tqdm when it is installed; otherwise (or when stderr is redirected, e.g. in a pipeline or CI)
nothing is printed.
"""

from __future__ import annotations

import sys
from typing import Any

SHOW_AFTER = 1.0  # seconds: a run faster than this shows no bar


class Progress:
    """``update(n)`` after each chunk of ``n`` samples; ``close()`` at the end (also a context manager)."""

    def __init__(self, total: int, desc: str, unit: str = "samples") -> None:
        self._bar: Any = None
        stream = sys.stderr
        if total <= 0 or stream is None or not getattr(stream, "isatty", lambda: False)():
            return
        try:
            from tqdm import tqdm
        except ImportError:
            return
        self._bar = tqdm(
            total=total, desc=desc, unit=unit, unit_scale=True, delay=SHOW_AFTER, file=stream, leave=False,
            dynamic_ncols=True,
        )  # fmt: skip

    def update(self, n: int) -> None:
        if self._bar is not None:
            self._bar.update(n)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.close()
            self._bar = None

    def __enter__(self) -> Progress:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
