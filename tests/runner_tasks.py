"""Tasks for tests/test_runner.py, importable by Dask worker processes (a test module's functions are not)."""

from __future__ import annotations

import os
import time


def square(x: object) -> object:
    """x² for a number; "boom" raises, "crash" kills the process running it, "hang" never returns."""
    if x == "boom":
        raise RuntimeError("boom")
    if x == "crash":
        os._exit(3)  # what a segfault in compiled code looks like from outside
    if x == "hang":
        while True:
            time.sleep(0.05)
    return x * x  # type: ignore[operator]


def swallowing(x: object) -> object:
    """A task that catches every Exception, as engines do: a timeout must still get through."""
    try:
        return square(x)
    except Exception:
        return "swallowed"
