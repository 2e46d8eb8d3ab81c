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


def run_blocks(run: Run, state: State, t_grid: np.ndarray, n: int, upto: int | None = None) -> Solved:
    """Solve blocks 0..upto (default: all) in order on rows 0..n-1 (row 0 must be assembled)."""
    system = run.system
    na = system.n_angles
    out = Solved(n, None, [], [], [], np.zeros(n, bool))
    for i, plan in enumerate(block_plans(system)):
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
        k = slice(0, out.n_ok)
        cols = None
        if factor is None:
            cols = jacobian_columns(plan, state, k)  # shared by health and rates
            cond, branch_sign = dyad_health(plan, state, k, run.scale, cols)
        else:
            cond, branch_sign = factor.cond[k], factor.sign[k]
            if plan.C.shape[0] * 2 > len(plan.block.unknowns):  # redundant: one branch, singular points passed
                find_singular_points(run, state, t_grid, i, cond)
        near = near_change_point(run, i, t_grid[k], cond)
        if run.check:
            signed = branch_sign * sigma[: out.n_ok]
            bad = np.nonzero(((velocity_bound(cond) > run.rtol) | (signed != signed[0])) & ~near)[0]
            if len(bad):
                fail(out, Failure(int(bad[0]), plan.block.loops[0], _toggle_reason(cond[bad[0]], run.rtol)))
                k = slice(0, out.n_ok)
                cond, branch_sign, near = cond[k], branch_sign[k], near[k]
                cols = None if cols is None else cols.head(out.n_ok)
        out.conds.append(cond)
        out.signs.append(branch_sign)
        if out.n_ok == 0 or not run.rates:
            continue
        if factor is None:
            store_rates(plan, state, k, dyad_rates(plan, state, k, "v", cols), "v", na)
            store_rates(plan, state, k, dyad_rates(plan, state, k, "a", cols), "a", na)
        else:
            store_rates(plan, state, k, newton.factor_rates(plan, state, k, factor.inv[k], "v"), "v", na)
            store_rates(plan, state, k, newton.factor_rates(plan, state, k, factor.inv[k], "a"), "a", na)
        if near.any():
            rates_across(run, state, t_grid, i, plan, np.nonzero(near)[0], out, cond)
    out.at_change = out.at_change[: out.n_ok]
    return out


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
    if run.detect and plan.block.kind != "PP":
        n_lim = int(np.argmin(ok)) if not ok.all() else out.n_ok
        try:
            found = find_change_points(run, state, t_grid, i, h[:n_lim])
        except Failure as f:
            found = []
            fail(out, f)
        if found:
            sigma = run.sigma(i, t_grid[k])
            ok, h = closed_form(plan, state, k, sigma)
    if not ok[: out.n_ok].all():
        bad = int(np.argmin(ok))
        fail(out, Failure(bad, plan.block.loops[0], "the loop cannot close: the input is past a limit position"))
    out.discs.append(h)
    return sigma
