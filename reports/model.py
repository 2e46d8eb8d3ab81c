"""What the reports read of a validation, as protocols: the harness (validators/) writes these, reports read them.

The dependency goes one way: ``validators.validate`` (the command) calls the reports; reports never import
validators. A report takes any objects with these attributes — ``validators.harness``'s dataclasses are one such
set — or, for the corpus and history pages, the plain data of summary.json and the comparison dataset.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, Protocol

from vloop.compare import Comparison
from vloop.mechanism import Mechanism
from vloop.result import Result


class Run(Protocol):
    """One engine on one mechanism: its Result (None when it has none), status, message, time [s]."""

    engine: str
    status: str  # "ok" | "stopped" | "error" | "skipped"
    result: Result | None
    message: str
    seconds: float

    @property
    def samples(self) -> int: ...


class Check(Protocol):
    """One comparison of an engine against a reference, under its tolerance."""

    engine: str
    reference: str
    comparison: Comparison | None
    samples: int
    passed: bool
    message: str
    rtol: float | dict[str, float]


class Verdict(Protocol):
    """The consensus on a mechanism (status, blamed engines, each engine's own verdict and reasons)."""

    status: str
    blamed: tuple[str, ...]
    reason: str
    engines: dict[str, str]
    reasons: dict[str, str]
    inconclusive: dict[str, str]

    def as_dict(self) -> dict[str, Any]: ...


class Item(Protocol):
    """One mechanism's validation."""

    path: str
    name: str
    mechanism: Mechanism | None
    runs: Mapping[str, Run]
    checks: Sequence[Check]
    error: str
    verdict: Verdict | None
    inconclusive: dict[str, str]

    @property
    def passed(self) -> bool: ...


class Validation(Protocol):
    """The items shown, the engines, when it started, how long it took, the libraries' versions."""

    items: Sequence[Item]
    engines: tuple[str, ...]
    started: str
    seconds: float
    versions: dict[str, str]

    @property
    def passed(self) -> bool: ...
