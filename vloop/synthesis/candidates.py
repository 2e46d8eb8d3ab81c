"""What a synthesis returns: candidate linkages, each re-solved by vloop and checked, ranked in a table.

A candidate is a *solution* only if it has no defect (:mod:`vloop.synthesis.defects`); solutions are ranked
first (rank 1, 2, …: largest error at a precision position, as a fraction of the task's size, then the larger
minimum transmission angle); defective candidates follow without a rank, their defects named.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..model import Mechanism


@dataclass(frozen=True)
class Task:
    """What was asked: the method, the targets (points (N,) complex; poses add ``angles`` (N,) [rad]; a function
    generator's ``outputs`` (N,) of output column ``output``), the task's ``size`` that relative errors refer to
    (in the errors' own unit: the targets' size [length], or the output's range [rad or length]) and what it is
    (``scale``), and whether the method is exact (its candidates pass through every position to round-off)."""

    method: str
    size: float
    exact: bool
    points: np.ndarray | None = None
    angles: np.ndarray | None = None
    outputs: np.ndarray | None = None
    output: str = ""
    units: str = "m"
    function: Any = None  # (f, x range, y range, input range, output range) of a function generator
    timing: np.ndarray | None = None
    scale: str = "the targets' size"

    @property
    def count(self) -> int:
        for v in (self.points, self.outputs):
            if v is not None:
                return len(v)
        return 0


@dataclass
class Candidate:
    """One synthesized linkage, re-solved over its motion.

    ``mechanism`` runs as it is (closed t = 0 coordinates; its [time] covers the working motion and every
    precision instant); ``times`` [s] and ``inputs`` [rad] say when and at which input angle each precision
    position is reached; ``errors`` the distance [length] (function generation: output error [rad or length])
    there, ``angle_errors`` [rad] the guided body's angle error (motion generation); ``defects`` and ``notes``
    what is wrong and why; ``min_transmission`` [rad] over the working motion; ``structural_error`` a function
    generator's largest |y − f(x)| over its range as a fraction of the y range; ``search_error`` the optimizer's
    own figure."""

    name: str
    method: str
    topology: str
    mechanism: Mechanism
    input: str
    guided: str
    tracer: str | None
    times: np.ndarray
    inputs: np.ndarray
    errors: np.ndarray
    size: float
    defects: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()
    angle_errors: np.ndarray | None = None
    grashof: str = ""
    full_rotation: bool = False
    min_transmission: float = math.nan
    structural_error: float | None = None
    search_error: float | None = None
    dims: dict[str, float] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def solution(self) -> bool:
        """No defect: it passes through its positions on one branch, in order, as required."""
        return not self.defects

    @property
    def error(self) -> float:
        """The largest error at a precision position, unit-free: a fraction of the task's size (the targets' size,
        or a function generator's output range; a pose's angle error counts in rad, as a fraction of 1 rad); NaN
        where a position was not reached."""
        e = np.asarray(self.errors, float)
        if self.angle_errors is not None:
            e = np.maximum(e, np.abs(self.angle_errors) * self.size)
        if not len(e) or not np.all(np.isfinite(e)):
            return math.nan
        return float(np.max(np.abs(e)) / self.size)


@dataclass
class Candidates:
    """A synthesis's result: the task and its candidates, ranked (solutions first)."""

    task: Task
    items: list[Candidate]
    seconds: float = 0.0
    log: list[str] = field(default_factory=list)
    curves: dict[str, np.ndarray] = field(default_factory=dict)  # Burmester's centre- and circle-point curves
    note: str = ""  # why there are fewer candidates than asked

    def __post_init__(self) -> None:
        self.items = rank(self.items)

    def __iter__(self) -> Iterator[Candidate]:
        return iter(self.items)

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, i: int) -> Candidate:
        return self.items[i]

    def keep(self, name: str, count: int | None = None) -> Candidates:
        """Keep the ``count`` first-ranked candidates (all by default), named NAME_1, NAME_2, … in rank order
        (their mechanisms too); returns self."""
        import dataclasses

        self.items = self.items[: max(count, 1)] if count is not None else self.items
        for k, c in enumerate(self.items):
            c.name = f"{name}_{k + 1}"
            c.mechanism = dataclasses.replace(c.mechanism, name=c.name)
        return self

    @property
    def solutions(self) -> list[Candidate]:
        return [c for c in self.items if c.solution]

    @property
    def best(self) -> Candidate | None:
        """The first-ranked solution (None when every candidate is defective)."""
        sols = self.solutions
        return sols[0] if sols else None

    def table(self) -> Any:
        """One row per candidate (pandas DataFrame): rank (solutions only), name, solution, defects, errors,
        Grashof class, minimum transmission angle, the instant and input angle of each precision position,
        the link lengths."""
        import pandas as pd

        rows = [_row(c, k + 1 if c.solution else None, self.task.scale) for k, c in enumerate(self.items)]
        return pd.DataFrame(rows)


def shortfall(method: str, asked: int, found: int, *, dyads: bool = False, poses: int = 0) -> str:
    """Why a synthesis returns fewer candidates than asked."""
    got = f"{found} candidate{'s' if found != 1 else ''} of the {asked} asked"
    if method == "function":
        return f"{got}: function generation's equation is linear, so the precision points fix one linkage"
    if method == "motion" and dyads:
        return f"{got}: the free choices given fix one four-bar (either dyad driving)"
    if method == "motion" and poses == 5:
        return f"{got}: five poses have at most four Burmester points; every pair of those found is a candidate"
    if method == "motion":
        return f"{got}: no more distinct four-bars in the region meet the poses in order (widen region, refine grid)"
    return f"{got}: the searches found no more distinct linkages within the tolerance (more restarts may find more)"


def rank(items: list[Candidate]) -> list[Candidate]:
    """Solutions first, by error then larger minimum transmission angle; then defective ones by error."""

    def key(c: Candidate) -> tuple:
        err = c.error if math.isfinite(c.error) else math.inf
        mu = c.min_transmission if math.isfinite(c.min_transmission) else 0.0
        return (not c.solution, len(c.defects), round(err, 12), -mu)

    return sorted(items, key=key)


def _row(c: Candidate, rank_: int | None, error_of: str) -> dict[str, Any]:
    row: dict[str, Any] = {
        "rank": rank_,
        "name": c.name,
        "method": c.method,
        "linkage": c.topology,
        "solution": c.solution,
        "defects": "; ".join(c.defects),
        "error": c.error,
        "max_error": float(np.nanmax(np.abs(c.errors))) if np.any(np.isfinite(c.errors)) else math.nan,
        "search_error": c.search_error,
        "structural_error": c.structural_error,
        "error_of": error_of,
        "grashof": c.grashof,
        "full_rotation": c.full_rotation,
        "min_transmission_angle": c.min_transmission,
        "input": c.input,
        "guided": c.guided,
        "tracer": c.tracer or "",
    }
    for k in range(len(c.times)):
        row[f"t{k + 1}"] = float(c.times[k])
        row[f"input{k + 1}"] = float(c.inputs[k])
        row[f"error{k + 1}"] = float(c.errors[k])
        if c.angle_errors is not None:
            row[f"angle_error{k + 1}"] = float(c.angle_errors[k])
    row.update({f"length.{k}": v for k, v in c.dims.items()})
    row["notes"] = " | ".join(c.notes)
    return row
