"""The one exception family vloop raises for bad input and impossible motion.

Every error carries a one-line message that names what went wrong and where
(the file entry, the time, the driver value), so the CLI can print it as is.
A motion error also carries the samples solved before the failure.
"""

from __future__ import annotations

from typing import Any


class VloopError(Exception):
    """Base of every error vloop reports to a user (CLI exit code 2).

    Attributes:
        entry: the file entry concerned (e.g. ``"links.l3"``), if any.
        time: the time [s] of the failing sample, if any.
        sample: index of the failing sample in the requested times, if any.
        driver_value: the driver input(s) at the failing sample, if any.
        partial: a :class:`vloop.result.Result` with every sample solved before
            the failure (motion errors), else ``None``.
    """

    def __init__(
        self,
        message: str,
        *,
        entry: str | None = None,
        time: float | None = None,
        sample: int | None = None,
        driver_value: Any = None,
        partial: Any = None,
    ) -> None:
        super().__init__(message)
        self.message = message
        self.entry = entry
        self.time = time
        self.sample = sample
        self.driver_value = driver_value
        self.partial = partial

    def __str__(self) -> str:
        return self.message


class MechanismError(VloopError):
    """The mechanism file is malformed, inconsistent, or cannot be assembled at t = 0."""


class MotionError(VloopError):
    """The motion cannot be completed: limit position, toggle, branch flip, no convergence."""


class SynthesisError(VloopError):
    """A synthesis task that is malformed or cannot be met: too few positions for the method, coincident poses,
    a function undefined on its range, free choices that admit no linkage."""
