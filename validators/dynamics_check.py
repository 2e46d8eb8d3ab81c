"""``vloop simulate`` against Exudyn's and Pinocchio's time integration of the same model and loads.

    rows = compare(mech, span=0.2)        # one row per (engine, column): worst difference and its tolerance

Each engine integrates at two steps and returns Richardson's correction (validators.dynamics_exudyn: Exudyn's
generalized-α, second order; validators.dynamics_pinocchio: RK4 on the constrained tree, fourth order), so
its error is known: after the correction what is left is the next order, a fraction O(Ω·h) of the
correction, Ω the fastest rate of the motion [1/s] (every body's |ω| and √|α|, the motor's and dampers' time
constants and the springs' frequencies: :func:`_rate`) and h the step. Measured with the steps below over the
catalog's mechanisms with masses (columns whose correction is at least 1e-3 of the largest): remainder /
correction ≤ 0.21 (Exudyn: 0.01 on the eight-bar, 0.11 on Watt II, 0.21 on the four-bar's motor transient),
≤ 0.17 (Pinocchio: 0.02 to 0.17); the tolerance allows 0.5. vloop's own
error (solve_ivp at rtol = atol = 1e-12, the tables ~1e-14) and the engines' round-off are covered by a floor
of 1e-9 of the group's peak (the largest |θ| of any body for angles, the largest |ω| for speeds: a slider
block's θ is constant, its own peak 0).

    |vloop − (engine + correction)| ≤ 0.5·max|correction| + 1e-9·peak        (each θ and ω column)

Steps: Ω·h = 0.01 for Exudyn (its correction then ~1e-5 of the peak), and at least 40 steps before the first
compared row (generalized-α's start-up transient, damped by ~0.64 per step, is not an O(h²) error:
validators.exudyn.MIN_STEPS_TO_SAMPLE); Ω·h = 0.02 for Pinocchio (RK4: its correction ~1e-7 of the peak).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from vloop.mechanism import Mechanism
from vloop.model import Dynamics

REMAINDER = 0.5  # |remainder| ≤ REMAINDER·|correction| (measured ≤ 0.21 and ≤ 0.17: see the module notes)
FLOOR = 1e-9  # of each column's peak: vloop's own error and round-off
SAMPLES = 21  # rows compared over the span
STEPS = {"exudyn-simulate": 0.01, "pinocchio-simulate": 0.02}  # Ω·h of each engine


@dataclass(frozen=True)
class Row:
    """One column's comparison: the worst |vloop − corrected engine|, its tolerance, the correction's size."""

    engine: str
    column: str
    worst: float
    tolerance: float
    correction: float

    @property
    def passed(self) -> bool:
        return self.worst <= self.tolerance


def compare(mech: Mechanism, span: float = 0.2, engines: tuple[str, ...] = tuple(STEPS)) -> list[Row]:
    """Every body's θ and ω over [0, span] s from vloop.simulate and each engine (see the module notes)."""
    import vloop

    from . import dynamics_exudyn, dynamics_pinocchio
    from . import exudyn as vexu

    mech = mech if mech.dynamics is not None else dataclasses.replace(mech, dynamics=Dynamics())
    times = np.linspace(0.0, span, SAMPLES)
    run = vloop.simulate(mech, times, rtol=1e-12, atol=1e-12)
    sim = run.result
    omega = _rate(run)
    angles = max(float(np.abs(sim[c]).max()) for c in sim.columns if c.endswith(".theta"))
    speeds = max(float(np.abs(sim[c]).max()) for c in sim.columns if c.endswith(".omega"))
    rows = []
    for engine in engines:
        run = dynamics_exudyn.simulate if engine == "exudyn-simulate" else dynamics_pinocchio.simulate
        spacing = times[1] - times[0]
        per_row = max(2, 2 * math.ceil(spacing * max(omega, 1e-9) / STEPS[engine] / 2))  # even: h and 2h fit
        if engine == "exudyn-simulate":  # generalized-α's start-up transient is gone after 40 steps
            per_row = max(per_row, vexu.MIN_STEPS_TO_SAMPLE)
        h = spacing / per_row
        res, corr = run(mech, times, h)
        for col in res.columns:
            if not col.endswith((".theta", ".omega")) or col not in sim.columns:
                continue
            c = float(np.abs(corr[col]).max())
            worst = float(np.abs(res[col] + corr[col] - sim[col]).max())
            tol = REMAINDER * c + FLOOR * (speeds if col.endswith(".omega") else angles)
            rows.append(Row(engine, col, worst, tol, c))
    return rows


def _rate(run: Any) -> float:
    """Ω [1/s], the fastest rate of the motion: every body's |ω| and √|α|, the motor's and the dampers' time
    constants and the springs' frequencies on the smallest generalized inertia (from vloop's tables: J and each
    spring's s′ at the nodes)."""
    res, model = run.result, run.model
    rates = [float(np.abs(res[c]).max()) for c in res.columns if c.endswith(".omega")]
    rates += [math.sqrt(float(np.abs(res[c]).max())) for c in res.columns if c.endswith(".alpha")]
    tab, dyn = model.tables, model.dynamics
    j_min = float(tab.coef[:, 0, 5].min())
    slope2 = (tab.dcoef[:, model.springs, 4] ** 2).max(axis=0) if len(model.springs) else np.zeros(0)
    if dyn.motor is not None:
        rates.append(abs(dyn.motor[0] / (dyn.motor[1] * tab.qscale)) / j_min)
    rates.append(float(model.damping @ slope2) / j_min if len(slope2) else 0.0)
    rates.append(math.sqrt(float(model.stiffness @ slope2) / j_min) if len(slope2) else 0.0)
    return max(rates)


def lines(name: str, rows: list[Row]) -> list[str]:
    """A short report: per engine, the worst column against its tolerance."""
    out = []
    for engine in dict.fromkeys(r.engine for r in rows):
        mine = [r for r in rows if r.engine == engine]
        worst = max(mine, key=lambda r: r.worst / r.tolerance)
        verdict = "pass" if all(r.passed for r in mine) else "FAIL"
        out.append(
            f"  {name}: simulate vs {engine}: {verdict} (worst {worst.column}: {worst.worst:.2g} against a tolerance "
            f"of {worst.tolerance:.2g}; the engine's own correction {worst.correction:.2g})"
        )
    return out


def summary_entries(rows: list[Row]) -> list[dict]:
    """summary.json's "dynamics" of one mechanism: per engine, the worst column (the largest worst/tolerance)
    with its difference, tolerance and the engine's correction [rad, rad/s], and the verdict over every column."""
    out = []
    for engine in dict.fromkeys(r.engine for r in rows):
        mine = [r for r in rows if r.engine == engine]
        worst = max(mine, key=lambda r: r.worst / r.tolerance)
        out.append(
            {
                "engine": engine,
                "column": worst.column,
                "worst": worst.worst if math.isfinite(worst.worst) else None,  # (no number: a failure)
                "tolerance": worst.tolerance,
                "correction": worst.correction,
                "columns": len(mine),
                "verdict": "pass" if all(r.passed for r in mine) else "fail",
            }
        )
    return out


def attach(entry: dict, got: list[dict] | None) -> dict:
    """A mechanism's summary entry with its forward-dynamics comparisons ("dynamics"); a failed one fails the
    mechanism, as it fails the exit code."""
    if got:
        entry["dynamics"] = got
        entry["passed"] = entry.get("passed", True) and not any(e["verdict"] == "fail" for e in got)
    return entry


def add_to_summary(summary: dict, entries: dict[str, list[dict]]) -> None:
    """Each compared mechanism's entries (by its file) as its "dynamics" (:func:`attach`); a failed one fails the
    summary too."""
    for mech in summary.get("mechanisms", []):
        attach(mech, entries.get(mech.get("file")))
        if not mech.get("passed", True):
            summary["passed"] = False
