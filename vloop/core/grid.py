"""The internal sample grid of a run: the requested times, with rows inserted where an input moves far.

Between two requested samples an input moves at most MAX_INPUT_STEP per internal row, so the other links'
turns are counted right, change points are seen and Newton continues from near.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import MotionError
from ..method.loops import LoopSystem
from .context import Failure, Run, input_units
from .linalg import row_max


@dataclass(frozen=True)
class Grid:
    """The internal sample grid: the lead-in from t = 0, the requested times, and rows inserted
    between requested samples so the inputs move at most MAX_INPUT_STEP per row (turns of the
    other links are then counted right, change points found, Newton continued from near)."""

    t: np.ndarray
    out: np.ndarray  # internal row of each requested sample (increasing)
    inputs: tuple | None = None  # the inputs (X, XD, XDD) at t, where internal_grid has evaluated them already
    skip: int = 0  # leading requested samples already given by the chunk before (its last one)
    offset: int = 0  # index in the whole run of the requested sample at out[0]
    total: int = 0  # requested samples in the whole run

    @property
    def first(self) -> int:
        return int(self.out[0])

    def requested_before(self, row: int) -> int:
        """How many requested samples come before internal row ``row``."""
        return int(np.searchsorted(self.out, row))


MAX_INPUT_STEP = math.radians(10)  # per internal row: of a crank (or 1/36 of the size for a slider input)


MAX_INSERTED = 10_000_000


def _within_one_step(mech: Any, h: np.ndarray, XD: np.ndarray, units: np.ndarray) -> bool:
    """Whether no input can move more than MAX_INPUT_STEP between two samples, by one bound: with drivers
    x = x0 + v0·t + a0·t²/2 (no profile) ẋ is linear, so |Δx| and the rates' trapezoid over a step are at most
    h·max|ẋ| at its ends ≤ max h · max|ẋ| (profiles can peak between samples: they take the row-by-row test)."""
    if any(d.profile is not None for d in mech.drivers):
        return False
    with np.errstate(invalid="ignore", over="ignore"):
        bound = float(np.max(h)) * float(np.max(np.max(np.abs(XD), axis=0) / units))
    return bound <= MAX_INPUT_STEP  # (False where not finite: the row-by-row test then sorts it out)


def _as_requested(lead: np.ndarray, times: np.ndarray, inputs: tuple) -> Grid:
    """The lead-in followed by the requested times, no rows inserted (the inputs at them kept without a lead-in)."""
    if not len(lead):
        return Grid(times, np.arange(len(times)), inputs=inputs)
    return Grid(np.concatenate([lead, times]), len(lead) + np.arange(len(times)))


def internal_grid(run: Run, lead: np.ndarray, times: np.ndarray, insert: bool = True) -> Grid:
    """Lead-in + requested times, with rows inserted where an input moves more than MAX_INPUT_STEP (unless not
    ``insert``: a run on a chart, :mod:`vloop.core.charts`)."""
    mech = run.system.mechanism
    n = len(times)
    if not insert:
        return _as_requested(lead, times, None)
    steps = np.ones(max(n - 1, 0), np.int64)
    if mech.drivers and n > 1:
        X, XD, XDD = run.inputs(times)
        units = input_units(mech, mech.scale / (2 * math.pi))
        h = np.diff(times)[:, None]
        if _within_one_step(mech, h, XD, units):
            return _as_requested(lead, times, (X, XD, XDD))
        travel = input_travel(X, XD, h, units)
        need = np.ceil(row_max(travel) / MAX_INPUT_STEP)
        need = np.where(np.isfinite(need) & (need <= MAX_INSERTED), need, 1.0)  # absurd inputs: refused later
        if need.sum() - len(need) > MAX_INSERTED:
            raise MotionError(
                f"{mech.name}: the inputs travel {float(travel.sum(axis=0).max()):.4g} rad (or sizes) over the run; "
                f"counting the other links' turns needs at most {math.degrees(MAX_INPUT_STEP):g}° per internal "
                f"sample, which would take {int(need.sum()):,} samples (more than {MAX_INSERTED:,}): shorten the run",
                entry="time",
            )
        steps = np.maximum(need, 1).astype(np.int64)
        if int(steps.sum()) == n - 1:  # no row to insert
            return _as_requested(lead, times, (X, XD, XDD))
    inner, starts = insert_rows(times, steps)
    return Grid(np.concatenate([lead, inner]), len(lead) + starts)


def input_travel(X: np.ndarray, XD: np.ndarray, h: np.ndarray, units: np.ndarray) -> np.ndarray:
    """How far each input moves over each interval between samples (axis −2), at most, in ``units``: |Δx|, or
    the trapezoid of its rate |ẋ| over the interval h."""
    return np.maximum(np.abs(np.diff(X, axis=-2)), 0.5 * h * (np.abs(XD[..., 1:, :]) + np.abs(XD[..., :-1, :]))) / units


def insert_rows(times: np.ndarray, steps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The times with ``steps[i]`` − 1 rows inserted evenly between times i and i + 1, and the row of each given
    time (which is kept exactly)."""
    n = len(times)
    starts = np.concatenate([[0], np.cumsum(steps)]).astype(np.int64)  # internal index of each given time
    k = np.arange(starts[-1])
    seg = np.repeat(np.arange(len(steps)), steps)
    frac = (k - starts[seg]) / steps[seg]
    inner = np.append(times[seg] + frac * (times[seg + 1] - times[seg]), times[-1]) if n > 1 else times.copy()
    inner[starts] = times
    return inner, starts


def too_large(rtol: float) -> float:
    """The smallest crank angle [rad] whose floating-point spacing exceeds ``rtol``: spacing(x) = 2^(e − 52) on
    [2^e, 2^(e+1)), which exceeds rtol from 2^(⌊log2 rtol⌋ + 53) on."""
    return 2.0 ** (math.floor(math.log2(rtol)) + 53) if 0 < rtol < math.inf else math.inf


def check_inputs(
    system: LoopSystem, X: np.ndarray, XD: np.ndarray, XDD: np.ndarray, off: int, rtol: float
) -> Failure | None:
    """The first sample whose driver inputs are not finite, or whose crank angle is too large to
    resolve to ``rtol`` (its floating-point spacing exceeds rtol radians)."""
    mech = system.mechanism
    bad = ~np.isfinite(X) | ~np.isfinite(XD) | ~np.isfinite(XDD)
    largest = too_large(rtol)
    for j, d in enumerate(mech.drivers):
        if d.kind == "crank":
            bad[off:, j] |= np.abs(X[off:, j]) >= largest
    rows = np.nonzero(row_max(bad) if bad.shape[1] else np.zeros(len(bad), bool))[0]
    if not len(rows):
        return None
    r = int(rows[0])
    j = int(np.argmax(bad[r]))
    d = mech.drivers[j]
    vals = (X[r, j], XD[r, j], XDD[r, j])
    if np.all(np.isfinite(vals)):
        why = f"the input {d.symbol} = {X[r, j]:.6g} rad is too large to resolve to rtol = {rtol:g} rad"
    else:
        which = ("value", "rate", "acceleration")[int(np.argmin(np.isfinite(vals)))]
        why = f"the input's {which} is not finite (an overflow: the driver's numbers are too large)"
    return Failure(r, None, why)
