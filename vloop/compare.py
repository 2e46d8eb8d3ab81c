"""Compare two Results quantity by quantity.

For each column both Results have, the error is e(t) = |a(t) − b(t)| (angles
modulo 2π), and the check is ``max e ≤ atol + rtol·scale`` where ``scale`` is the
peak magnitude of that quantity over the run (the larger of the two engines'),
and ``atol = floor·group_scale`` guards quantities that are identically zero:
``group_scale`` is the peak over all quantities of the same kind (all point
positions, all angular velocities, ...), ``floor`` defaults to 1e-12 (round-off). An angular
acceleration's scale is at least the angular velocities' peak squared (its natural magnitude: α is a
difference of O(ω²) terms).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .result import Result

ZERO_FLOOR = 1e-9  # a quantity whose peak is below this fraction of its group's peak is "identically zero"

# field -> (group, human name)
_GROUP = {
    "theta": ("angle", "angle"),
    "omega": ("angular velocity", "angular velocity"),
    "alpha": ("angular acceleration", "angular acceleration"),
    "x": ("position", "x"),
    "y": ("position", "y"),
    "s": ("position", "displacement"),
    "vx": ("velocity", "vx"),
    "vy": ("velocity", "vy"),
    "v": ("velocity", "velocity"),
    "ax": ("acceleration", "ax"),
    "ay": ("acceleration", "ay"),
    "a": ("acceleration", "acceleration"),
    # forces (vloop.forces): N and N·m
    "fx": ("force", "fx"),
    "fy": ("force", "fy"),
    "mag": ("force", "magnitude"),
    "force": ("force", "driver force"),
    "normal": ("force", "normal force"),
    "torque": ("moment", "driver torque"),
    "moment": ("moment", "moment"),
}


@dataclass(frozen=True)
class QuantityError:
    """Errors of one quantity (column) between two engines."""

    column: str
    group: str
    max_abs: float
    scale: float
    rel: float  # max_abs / max(scale, ZERO_FLOOR·group peak)
    rms: float
    t_at_max: float
    tol: float  # allowed max_abs
    passed: bool


@dataclass
class Comparison:
    """All quantity errors between ``engine_a`` and reference ``engine_b``."""

    mechanism: str
    engine_a: str
    engine_b: str
    rtol: float | dict[str, float]
    errors: list[QuantityError]

    @property
    def passed(self) -> bool:
        return all(e.passed for e in self.errors)

    @property
    def failures(self) -> list[QuantityError]:
        return [e for e in self.errors if not e.passed]

    def worst(self, group: str | None = None) -> QuantityError | None:
        errs = [e for e in self.errors if group is None or e.group == group]
        return max(errs, key=lambda e: e.max_abs / e.tol if e.tol > 0 else math.inf, default=None)

    def max_rel_by_group(self) -> dict[str, float]:
        out: dict[str, float] = {}
        for e in self.errors:
            out[e.group] = max(out.get(e.group, 0.0), e.rel)
        return out

    def describe(self, e: QuantityError) -> str:
        return (
            f"{self.mechanism}: {self.engine_a} vs {self.engine_b}: {e.column} off by {e.max_abs:.3g} "
            f"at t = {e.t_at_max:.6g} s ({e.rel:.3g} of its peak {e.scale:.3g}; allowed {e.tol:.3g})"
        )

    def message(self, limit: int = 8) -> str:
        fails = sorted(self.failures, key=lambda e: -e.max_abs / max(e.tol, 1e-300))
        lines = [self.describe(e) for e in fails[:limit]]
        if len(fails) > limit:
            lines.append(f"... and {len(fails) - limit} more")
        return (
            "\n".join(lines) if lines else f"{self.mechanism}: {self.engine_a} vs {self.engine_b}: all within tolerance"
        )


def _field(col: str) -> str:
    return col.rsplit(".", 1)[1]


def group_of(column: str) -> str:
    """The quantity group of a column: "angle", "velocity", ... (KeyError for "t" or health columns)."""
    return _GROUP[_field(column)][0]


def error_series(a: Result, b: Result, column: str, n: int | None = None) -> np.ndarray:
    """|a − b| of one column over the first ``n`` samples (all by default), angles modulo 2π."""
    d = np.asarray(a[column][:n], float) - np.asarray(b[column][:n], float)
    if _GROUP[_field(column)][0] == "angle":
        d = (d + math.pi) % (2 * math.pi) - math.pi
    return np.abs(d)


def compare(
    a: Result,
    b: Result,
    rtol: float | dict[str, float],
    *,
    floor: float | dict[str, float] = 1e-12,
    columns: list[str] | None = None,
    floor_t: dict[str, np.ndarray] | None = None,
    atol_t: dict[str, np.ndarray] | None = None,
) -> Comparison:
    """Compare ``a`` against reference ``b`` on their shared columns.

    ``rtol`` is one number or a dict by group (``"position"``, ``"velocity"``,
    ``"acceleration"``, ``"angle"``, ``"angular velocity"``, ``"angular acceleration"``);
    so is ``floor``, the absolute allowance as a fraction of the group's peak (an integrator's
    error on a quantity that is zero in theory is of the order of its group's error, not zero).
    ``floor_t`` adds a floor per sample and group (arrays as long as the Results, fractions of the
    group's peak): an allowance that depends on the configuration, such as the conditioning next to a
    change point; ``atol_t`` an absolute allowance per sample and group (an engine's own reported error
    bound). The sample times must agree (to 1e-9 of the run's length).
    """
    if len(a.t) != len(b.t) or (len(a.t) and not np.allclose(a.t, b.t, rtol=0, atol=1e-9 * max(1.0, np.ptp(b.t)))):
        raise ValueError(
            f"{a.engine} and {b.engine} were sampled at different times ({len(a.t)} vs {len(b.t)} samples)"
        )
    cols = columns if columns is not None else [c for c in b.columns if c in a.columns and _field(c) in _GROUP]
    groups = [_GROUP[_field(c)][0] for c in cols]
    n = len(b.t)
    if not cols:
        return Comparison(a.mechanism or b.mechanism, a.engine, b.engine, rtol, [])
    E, peaks, scale, gpeak, group_scale = _differences(a, b, cols, groups, n)
    tol_t = _allowed(groups, scale, gpeak, rtol, floor, floor_t, atol_t, n)
    # per column, the sample whose error is the largest fraction of its allowance (one allowance: the largest error)
    k = np.argmax(E / np.maximum(tol_t, 1e-300), axis=1) if n else np.zeros(len(cols), int)
    rows = np.arange(len(cols))
    mx = E[rows, k] if n else np.zeros(len(cols))
    tol = tol_t[rows, k] if n else _allowed(groups, scale, gpeak, rtol, floor, None, None, 1)[:, 0]
    rms = np.sqrt(np.mean(E * E, axis=1)) if n else np.zeros(len(cols))
    # a quantity that stays at zero (a ground pin's velocity) is measured against its group instead
    ref = np.maximum(scale, ZERO_FLOOR * np.array([group_scale[g] for g in groups]))
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.where(ref > 0, mx / np.where(ref > 0, ref, 1.0), np.where(mx == 0, 0.0, np.inf))
    t_at = b.t[k] if n else np.zeros(len(cols))
    errors = [
        QuantityError(c, g, float(m_), float(pk), float(re), float(rm), float(tt), float(tl), bool(m_ <= tl))
        for c, g, m_, pk, re, rm, tt, tl in zip(cols, groups, mx, peaks, rel, rms, t_at, tol, strict=True)
    ]
    return Comparison(a.mechanism or b.mechanism, a.engine, b.engine, rtol, errors)


def _differences(
    a: Result, b: Result, cols: list[str], groups: list[str], n: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, dict[str, float]]:
    """Every column at once (rows = columns): |a − b| (angles modulo 2π; inf where not finite), each column's
    peak, the scale its error is measured against, its group's peak, and each group's peak by name."""
    A = np.array([np.asarray(a[c][:n], float) for c in cols]).reshape(len(cols), n)
    B = np.array([np.asarray(b[c][:n], float) for c in cols]).reshape(len(cols), n)
    D = A - B
    angle = np.array([g == "angle" for g in groups])
    D[angle] = (D[angle] + math.pi) % (2 * math.pi) - math.pi
    E = np.abs(D)
    peaks = np.maximum(np.max(np.abs(A), axis=1, initial=0.0), np.max(np.abs(B), axis=1, initial=0.0))
    group_scale: dict[str, float] = {}
    for g, pk in zip(groups, peaks.tolist(), strict=True):
        group_scale[g] = max(group_scale.get(g, 0.0), pk)
    # an angular acceleration is a difference of O(ω²) terms: its natural magnitude is the angular velocities'
    # peak squared, the scale its error is measured against when its own peak is smaller (a parallelogram at
    # constant ω has α ≡ 0: 1e-9 of that is not round-off)
    natural = {"angular acceleration": group_scale.get("angular velocity", 0.0) ** 2}
    E = np.where(np.isfinite(E), E, np.inf)
    scale = np.array([max(pk, natural.get(g, 0.0)) for g, pk in zip(groups, peaks.tolist(), strict=True)])
    gpeak = np.array([max(group_scale[g], natural.get(g, 0.0)) for g in groups])
    return E, peaks, scale, gpeak, group_scale


def _allowed(
    groups: list[str],
    scale: np.ndarray,
    gpeak: np.ndarray,
    rtol: float | dict[str, float],
    floor: float | dict[str, float],
    floor_t: dict[str, np.ndarray] | None,
    atol_t: dict[str, np.ndarray] | None,
    n: int,
) -> np.ndarray:
    """(columns, samples): floor·group peak + rtol·scale, plus the per-sample floors and allowances."""
    f = np.array([floor.get(g, 1e-12) if isinstance(floor, dict) else floor for g in groups])
    r = np.array([rtol.get(g, 0.0) if isinstance(rtol, dict) else rtol for g in groups])
    tol_t = np.broadcast_to((f * gpeak + r * scale)[:, None], (len(groups), n))
    if floor_t is None and atol_t is None:
        return tol_t
    tol_t = tol_t.copy()
    for row, g in enumerate(groups):
        if floor_t is not None and g in floor_t:
            tol_t[row] += np.asarray(floor_t[g], float)[:n] * gpeak[row]
        if atol_t is not None and g in atol_t:
            tol_t[row] += np.asarray(atol_t[g], float)[:n]
    return tol_t


def assert_histories_close(
    a: Result,
    b: Result,
    rtol: float | dict[str, float],
    *,
    floor: float | dict[str, float] = 1e-12,
    columns: list[str] | None = None,
    min_columns: int = 1,
) -> Comparison:
    """Raise AssertionError naming the quantity, the time and how far off, if any column fails."""
    cmp = compare(a, b, rtol, floor=floor, columns=columns)
    if len(cmp.errors) < min_columns:
        raise AssertionError(f"{a.engine} vs {b.engine}: only {len(cmp.errors)} shared quantities to compare")
    if not cmp.passed:
        raise AssertionError(cmp.message())
    return cmp
