"""The blocks of a system solved in order over rows 0..n−1 of a state: positions, health, checks and rates.

Closed-form dyads are solved for every row at once, on the branch σ fixed at t = 0 and flipped after each
change point (found here on the main run: :mod:`vloop.core.changepoints`); Newton blocks by continuation
(:mod:`vloop.core.newton`). A row whose velocities the Jacobian's condition cannot deliver to rtol, or whose
branch sign flips, stops the run there (a toggle) unless it sits next to a change point, where the rates are
interpolated across it.
"""

from __future__ import annotations

import numpy as np

from . import newton
from .accuracy import velocity_bound
from .changepoints import find_change_points, find_singular_points, near_change_point, rates_across
from .context import Failure, Run, Solved, fail
from .data import State
from .dyads import closed_form, dyad_health, dyad_rates, jacobian_columns
from .plans import Plan, block_plans, store_rates


def run_blocks(
    run: Run, state: State, t_grid: np.ndarray, n: int, upto: int | None = None, rated: np.ndarray | None = None
) -> Solved:
    """Solve blocks 0..upto (default: all) in order on rows 0..n-1 (row 0 must be assembled).

    ``rated``: the rows (ascending) whose rates and health are wanted (default: every row). A closed-form
    dyad's other rows get positions and the discriminant only (cond 1 and no branch sign there): for a dyad
    det J vanishes only where h does, which the change-point search watches on every row; Newton blocks and
    the dyads a Newton block follows (its predictor reads their rates) are rated on every row.
    """
    system = run.system
    plans = block_plans(system)
    out = Solved(n, None, [], [], [], np.zeros(n, bool))
    for i, plan in enumerate(plans):
        if upto is not None and i > upto:
            break
        factor = None
        if plan.block.kind == "newton":
            failure, factor = newton.solve_block(run, state, t_grid, i, plan, out.n_ok)
            if failure is not None:
                fail(out, failure)
            out.discs.append(None)
            sigma = run.sigma(i, t_grid[: out.n_ok])
        else:
            sigma = dyad_positions(run, state, t_grid, i, plan, out)
        if out.n_ok == 0:
            break
        some = rated is not None and factor is None and all(p.block.kind != "newton" for p in plans[i + 1 :])
        rows = _rated(rated if some else None, 0, out.n_ok)
        _health_and_rates(run, state, t_grid, i, plan, out, factor, sigma, rows)
    out.at_change = out.at_change[: out.n_ok]
    return out


def _rated(rated: np.ndarray | None, first: int, n: int) -> np.ndarray | slice:
    """Row 0 and the ``rated`` rows before n (a slice of every row when ``rated`` is None)."""
    if rated is None:
        return slice(first, n)
    rows = rated[: np.searchsorted(rated, n)]
    return rows if len(rows) and rows[0] == 0 else np.concatenate([[0], rows]).astype(rows.dtype)


def _health_and_rates(
    run: Run,
    state: State,
    t_grid: np.ndarray,
    i: int,
    plan: Plan,
    out: Solved,
    factor: newton.Factor | None,
    sigma: np.ndarray,
    rows: np.ndarray | slice,
) -> None:
    """Block ``i``'s condition number and branch sign on ``rows`` (a toggle or a branch flip there stops the
    run), then its rates there (across a change point where the Jacobian is singular)."""
    na = run.system.n_angles
    n = out.n_ok
    every = isinstance(rows, slice)
    cols = None
    if factor is None:
        cols = jacobian_columns(plan, state, rows)  # shared by health and rates
        cond, branch_sign = dyad_health(plan, state, rows, run.scale, cols)
    else:
        cond, branch_sign = factor.cond[rows], factor.sign[rows]
        if plan.C.shape[0] * 2 > len(plan.block.unknowns):  # redundant: one branch, singular points passed
            find_singular_points(run, state, t_grid, i, cond)
    near = near_change_point(run, i, t_grid[rows], cond)  # (rows: a slice of every row, or the rated rows)
    if run.check:
        signed = branch_sign * sigma[rows]
        if factor is None:  # on a toggle to round-off (h = 0: the branches coincide) det J has no sign to keep
            signed = np.where(out.discs[i][rows] == 0, signed[0], signed)
        bad = np.nonzero(((velocity_bound(cond) > run.rtol) | (signed != signed[0])) & ~near)[0]
        if len(bad):
            m = int(bad[0])
            row = m if every else int(rows[m])
            fail(out, Failure(row, plan.block.loops[0], _toggle_reason(cond[m], run.rtol)))
            n, rows = out.n_ok, (slice(0, out.n_ok) if every else rows[:m])
            cond, branch_sign, near = cond[:m], branch_sign[:m], near[:m]
            cols = None if cols is None else cols.head(m)
    if every:
        out.conds.append(cond)
        out.signs.append(branch_sign)
    else:  # (cond 1 where not rated: nothing refused there, nothing flagged)
        full_cond, full_sign = np.ones(n), np.full(n, np.nan)
        full_cond[rows], full_sign[rows] = cond, branch_sign
        out.conds.append(full_cond)
        out.signs.append(full_sign)
    if n == 0 or not run.rates:
        return
    for what in ("v", "a"):
        if factor is None:
            vals = dyad_rates(plan, state, rows, what, cols)
        else:
            vals = newton.factor_rates(plan, state, rows, factor.inv[rows], what)
        store_rates(plan, state, rows, vals, what, na)
    if near.any():
        rates_across(run, state, t_grid, i, plan, (np.flatnonzero(near) if every else rows[near]), out, out.conds[-1])


def _toggle_reason(cond: float, rtol: float) -> str:
    return (
        f"the mechanism reaches a toggle (singular Jacobian: condition number {cond:.3g}, so the velocities "
        f"could be wrong by cond²·ε = {min(float(velocity_bound(cond)), 1.0):.2g} of their size, "
        f"more than rtol = {rtol:g})"
    )


def dyad_positions(run: Run, state: State, t_grid: np.ndarray, i: int, plan: Plan, out: Solved) -> np.ndarray:
    """Solve block ``i``'s positions on rows 0..out.n_ok-1 (finding change points on the main run)."""
    k = slice(0, out.n_ok)
    sigma = run.sigma(i, t_grid[k])
    ok, h = closed_form(plan, state, k, sigma)
    if run.detect and run.chart is None and plan.block.kind != "PP":  # (a chart has seen none on the way)
        n_lim = int(np.argmin(ok)) if not ok.all() else out.n_ok
        found, failure = find_change_points(run, state, t_grid, i, h[:n_lim])
        if failure is not None:
            fail(out, failure)
        if found:
            sigma = run.sigma(i, t_grid[k])
            ok, h = closed_form(plan, state, k, sigma)
    if not ok[: out.n_ok].all():
        bad = int(np.argmin(ok))
        fail(out, Failure(bad, plan.block.loops[0], "the loop cannot close: the input is past a limit position"))
    out.discs.append(h)
    return sigma
