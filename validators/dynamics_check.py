"""``vloop simulate`` against Exudyn's and Pinocchio's time integration of the same model and loads.

    rows = compare(mech, span=0.2)        # one row per (engine, column): worst difference and its tolerance

Each engine integrates at two steps and returns Richardson's correction (validators.dynamics_exudyn: Exudyn's
generalized-α, second order; validators.dynamics_pinocchio: RK4 on the constrained tree, fourth order), so
its error is known: after the correction what is left is the next order, |remainder| ≤ C·(Ω·h)·|correction|,
Ω the largest angular speed of the run [rad/s] and h the step. Measured on the catalog: C ≈ 0.25 (Exudyn),
C ≈ 5 (Pinocchio); the tolerance takes C = 20 for both. vloop's own error (solve_ivp at rtol = atol =
1e-12, the tables ~1e-14) is covered by a floor of 1e-9 of each column's peak.

    |vloop − (engine + correction)| ≤ 20·Ω·h·max|correction| + 1e-9·peak        (each θ and ω column)

Steps: Ω·h = 0.01 for Exudyn (its correction then ~1e-5 of the peak), 0.005 for Pinocchio.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from vloop.mechanism import Mechanism
from vloop.model import Dynamics

REMAINDER = 20.0  # C in |remainder| ≤ C·Ω·h·|correction| (measured 0.25 and 5: see the module notes)
FLOOR = 1e-9  # of each column's peak: vloop's own error and round-off
SAMPLES = 21  # rows compared over the span
STEPS = {"exudyn-simulate": 0.01, "pinocchio-simulate": 0.005}  # Ω·h of each engine


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

    mech = mech if mech.dynamics is not None else dataclasses.replace(mech, dynamics=Dynamics())
    times = np.linspace(0.0, span, SAMPLES)
    sim = vloop.simulate(mech, times, rtol=1e-12, atol=1e-12).result
    omega = max(float(np.abs(sim[f"{b}.omega"]).max()) for b in mech.moving_links if f"{b}.omega" in sim)
    rows = []
    for engine in engines:
        run = dynamics_exudyn.simulate if engine == "exudyn-simulate" else dynamics_pinocchio.simulate
        spacing = times[1] - times[0]
        per_row = max(2, 2 * math.ceil(spacing * max(omega, 1e-9) / STEPS[engine] / 2))  # even: h and 2h fit
        h = spacing / per_row
        res, corr = run(mech, times, h)
        for col in res.columns:
            if not col.endswith((".theta", ".omega")) or col not in sim.columns:
                continue
            c = float(np.abs(corr[col]).max())
            worst = float(np.abs(res[col] + corr[col] - sim[col]).max())
            tol = REMAINDER * omega * h * c + FLOOR * float(np.abs(sim[col]).max())
            rows.append(Row(engine, col, worst, tol, c))
    return rows


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
