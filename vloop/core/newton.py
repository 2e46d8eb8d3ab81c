"""Newton blocks, vectorized over samples.

A block whose loops are not one of the closed-form dyads (an Assur group of class III, coupled
loops, a whole system under ``method="newton"``) is solved for every sample of a run in passes:

1. **Coarse continuation.** Rows about COARSE_STEP of input travel apart are solved one after the
   other: Taylor predictor x + ẋ·h + ẍ·h²/2 from the previous coarse row (ẋ, ẍ exact linear
   solves), Newton–Raphson with the analytic Jacobian. A coarse step is accepted only if it
   converged, closes every equation, keeps the Jacobian's determinant sign (the assembly branch)
   and lands within JUMP of the predicted increment; else the rows in between are continued one
   by one (finer continuation, where the old sample-by-sample rules apply and decide).
2. **Dense rows, all at once.** Every other row starts from the quintic Hermite interpolant of its
   coarse neighbours (positions, rates, accelerations). A square block takes one Newton step there
   with the inverse Jacobians of all rows at once (:func:`vloop.core.linalg.invert_last`: Gauss–Jordan with
   the stack as the last axis, ~3× LAPACK's per-matrix calls at n ≤ 8), then chord steps with the
   same inverses until the steps fall below LOOSE; the loop sums are evaluated from the rows' known
   factors gathered once (:class:`_Rows`). A row must converge, close, keep the branch's determinant
   sign and stay near its prediction; an interval with a row that does not is continued one by one, on
   to the coarse row that ends it: where that continuation does not land on it (the coarse pass reached
   another assembly that passed its checks), the run goes on from there.
3. **Factor.** The Jacobian at every solved row, its (pseudo-)inverse, determinant sign and
   condition number, shared by the rates and the health columns: one more Newton step whose size is
   the convergence test. The condition number is an upper bound where that decides (Frobenius, then
   (Σσ⁸)^⅛), the exact 2-norm one wherever it reaches the flag level (σ_max of J and of J⁻¹ from their
   Gram matrices' powers, bracketed to 1e-12; eigenvalues or SVD where that fails), so flags and refusals
   follow the 2-norm rule exactly.

Under a chart of the run (:mod:`vloop.core.charts`: its one input travels over its range many times) passes 1
and 2 are one: every row starts from the chart's quintic Hermite interpolant at its input value and is
checked as a dense row; a row that fails sends the chunk back to the passes above (ChartMiss).

Rectangular blocks (more equations than unknowns: consistent redundant constraints) take
Gauss–Newton steps and least-squares rates; the residual of every equation is checked.

A determinant that changes sign between two rows while Newton converges onto the Taylor-predicted
(smooth) continuation is a change point (the branches cross): it is located by bisection on the
determinant and reported like a closed-form dyad's; any other sign change is a branch flip, an error.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .accuracy import EPS
from .charts import ChartMiss, hermite, interval_moves
from .context import ChangePoint, Failure, Run, change_point_choices, impose_drivers
from .data import TWO_PI, State
from .linalg import (
    apply_last,
    cond_2norm,
    condition_last,
    condition_rows,
    det_sign,
    invert_last,
    invert_rows,
    least_squares_rows,
    pinv_rows,
    sum_squares,
    svd_cond,
)
from .plans import Plan, store_rates
from .sums import known_rhs

COARSE_STEP = math.radians(15)  # motion between coarse rows (rad; sliders: 2π per mechanism size)
WINDOW = 8  # coarse rows predicted from one anchor and solved together
JUMP = 0.5  # a step that corrects the predicted increment by more than this fraction is not trusted
WINDOW_ITER = 8  # Newton iterations a window of coarse rows gets: a row needing more is not trusted (halving decides)
LOOSE = 1e-8  # dense rows iterate to this step; the next (quadratic) one is then at round-off
FRESH = 1e-14  # a last step above this (relative) refreshes the Jacobian the rates are taken from
CLOSURE = 1e-9  # a solved row closes every equation to this fraction of the mechanism size
LOCATE_STEPS = 40  # bisection steps locating a Newton block's change point
SUBSTEPS = 16  # a step whose branch sign flipped far from its prediction is re-walked in this many


@dataclass
class Factor:
    """The block Jacobian at every solved row and what rates and health take from it."""

    J: np.ndarray  # (rows, 2m, nu)
    inv: np.ndarray  # (rows, nu, 2m): J⁻¹, or (JᵀJ)⁻¹Jᵀ for a rectangular block (least squares)
    cond: np.ndarray  # condition number, angle columns divided by the mechanism size (see condition_rows)
    sign: np.ndarray  # sign of det J (+1 for a rectangular block: no branch sign)


class NewtonBlock:
    """Index data to evaluate one Newton block's residual and Jacobian on any set of rows."""

    def __init__(self, plan: Plan, n_angles: int, scale: float) -> None:
        na = n_angles
        unk = plan.block.unknowns
        self.plan = plan
        self.nu = len(unk)
        self.m2 = 2 * plan.C.shape[0]
        self.square = self.m2 == self.nu
        self.ia = np.array([u for u, v in enumerate(unk) if v < na], int)
        self.isl = np.array([u for u, v in enumerate(unk) if v >= na], int)
        self.acol = np.array([v for v in unk if v < na], int)
        self.scol = np.array([v - na for v in unk if v >= na], int)
        nt = len(plan.ang)
        D = np.zeros((2 * nt, plan.C.shape[0], self.nu), complex)
        for u, (v, mask) in enumerate(zip(unk, plan.masks, strict=True)):
            # ∂z/∂θ = j·z for every term turning with θ; ∂z/∂s = e for the slider's own term
            D[np.nonzero(mask)[0] + (0 if v < na else nt), :, u] = plan.C.T[mask]
        self.D = D.reshape(2 * nt, -1)
        self.colscale = np.where([v < na for v in unk], 1.0 / scale, 1.0)
        self.scale = scale
        # per term: the position in x of its unknown angle and of its unknown slider (-1: none)
        where = {v: u for u, v in enumerate(unk)}
        self.t_ua = np.array([where.get(int(a), -1) if a >= 0 else -1 for a in plan.ang], int)
        self.t_us = np.array([where.get(int(q) + na, -1) if q >= 0 else -1 for q in plan.sl], int)
        self.dep = np.nonzero((self.t_ua >= 0) | (self.t_us >= 0))[0]  # the terms the unknowns move
        self.known = np.setdiff1d(np.arange(nt), self.dep)
        self._jacobian_entries(plan)

    def _jacobian_entries(self, plan: Plan) -> None:
        """J[l, u] = Σ_t C[l, t]·(j·z_t if u is t's angle; e_t if u is t's slider), as sums of signed rows of
        Re z, Im z, Re e, Im e over the moved terms: (entry of J, part, term, coefficient), by entry."""
        m, nu = self.m2 // 2, self.nu
        ent = []
        for k, t in enumerate(self.dep):
            for lp in np.nonzero(plan.C[:, t])[0]:
                c = float(plan.C[lp, t])
                if self.t_ua[t] >= 0:  # j·z = −Im z + j·Re z
                    ent += [(lp * nu + int(self.t_ua[t]), 1, k, -c), ((lp + m) * nu + int(self.t_ua[t]), 0, k, c)]
                if self.t_us[t] >= 0:
                    ent += [(lp * nu + int(self.t_us[t]), 2, k, c), ((lp + m) * nu + int(self.t_us[t]), 3, k, c)]
        self.j_entries = sorted(ent)

    def read(self, state: State, rows: np.ndarray) -> np.ndarray:
        x = np.empty((len(rows), self.nu))
        x[:, self.ia] = state.theta[rows][:, self.acol]
        x[:, self.isl] = state.s[rows][:, self.scol]
        return x

    def read_last(self, state: State, n: int) -> np.ndarray:
        """The unknowns on rows 0..n-1, batch-last (nu, n)."""
        x = np.empty((self.nu, n))
        x[self.ia] = state.theta[:n, self.acol].T
        x[self.isl] = state.s[:n, self.scol].T
        return x

    def put(self, state: State, rows: np.ndarray | slice, x: np.ndarray, cis: np.ndarray | None = None) -> None:
        """Store x (rows, nu) at the rows; ``cis``: e^{jθ} of its angles if known (rows, angles)."""
        r = rows if isinstance(rows, slice) else rows[:, None]
        if len(self.ia):
            th = x[:, self.ia]
            state.theta[r, self.acol] = th
            state.e[r, self.acol] = np.cos(th) + 1j * np.sin(th) if cis is None else cis
        if len(self.isl):
            state.s[r, self.scol] = x[:, self.isl]

    def residual_jacobian(self, state: State, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """[Re; Im] of the block's loop sums (rows, 2m) and their Jacobian (rows, 2m, nu). Constants per row
        (variants): each row summed on its own (einsum's loops; a BLAS product's rounding depends on how many
        rows it is given)."""
        plan = self.plan
        z, e = state.term_vectors(rows, plan.ang, plan.sl, *plan.term_values(rows))
        ze = np.concatenate([1j * z, e], axis=1)
        if plan.per_row:
            F, Jc = np.einsum("rt,tm->rm", z, plan.Ct), np.einsum("rt,tk->rk", ze, self.D)
        else:
            F, Jc = z @ plan.Ct, ze @ self.D
        Jc = Jc.reshape(len(rows), -1, self.nu)
        return np.concatenate([F.real, F.imag], axis=1), np.concatenate([Jc.real, Jc.imag], axis=1)

    def factor(self, state: State, rows: np.ndarray, rtol: float, tol: float) -> tuple[Factor, np.ndarray, np.ndarray]:
        """The Factor at the state's rows, the closure residual of each (fraction of the size) and whether
        the Newton step from there is below tol·(1 + |x|); that last step is applied (J is kept: it moves
        by the step, round-off for a converged row)."""
        F, J = self.residual_jacobian(state, rows)
        inv = pinv_rows(J)  # by SVD when rectangular: normal equations would square the condition number
        cond = condition_rows(J * self.colscale, inv / self.colscale[:, None], rtol)
        res = np.max(np.abs(F), axis=1, initial=0.0) / self.scale
        dx = -(inv @ F[..., None])[..., 0]
        x = self.read(state, rows) + dx
        with np.errstate(invalid="ignore"):
            step = np.max(np.abs(dx), axis=1, initial=0.0) / (1.0 + np.max(np.abs(x), axis=1, initial=0.0))
        conv = step <= tol
        fresh = step <= FRESH  # J at the rows that moved more is refreshed by the caller (rates use it)
        finite = np.all(np.isfinite(x), axis=1)
        self.put(state, rows[finite], x[finite])
        return Factor(J, inv, cond, self.chain_sign(J, inv)), res, conv & fresh

    def chain_sign(self, J: np.ndarray, inv: np.ndarray) -> np.ndarray:
        """det J's sign on consecutive rows without a determinant per row: where ‖J_{k−1}⁻¹(J_k − J_{k−1})‖_F < 1
        every eigenvalue of J_{k−1}⁻¹J_k = I + E lies within 1 of 1, so det J_k has det J_{k−1}'s sign; rows
        where that bound fails (near a singular row) get their determinant computed."""
        if not self.square or len(J) < 2:
            return det_sign(J)
        step = inv[:-1] @ (J[1:] - J[:-1])
        with np.errstate(invalid="ignore"):
            close = np.sum(step * step, axis=(1, 2)) < 0.25  # ‖E‖_F < 1/2: a margin for round-off
        exact = np.concatenate([[0], np.nonzero(~close)[0] + 1])
        sign = np.full(len(J), np.nan)
        sign[exact] = det_sign(J[exact])
        last = np.maximum.accumulate(np.where(np.isnan(sign), 0, np.arange(len(J))))
        return sign[last]


class _Rows:
    """A square block's loop sums on rows 0..n-1 as functions of its unknowns alone, batch-last (x[u, row]):
    what the unknowns do not move (the other terms' sum, every moved term's known length and direction) is
    gathered once, so a Newton iteration costs a few small products over the rows."""

    def __init__(self, blk: NewtonBlock, state: State, n: int) -> None:
        plan, d = blk.plan, blk.dep
        cis, lengths = state.e[:n], state.s[:n]
        kn = blk.known
        # batch-last and C-contiguous: arithmetic on a transposed view is several times slower
        self.F0 = np.ascontiguousarray(
            (((plan.r[kn] + lengths[:, plan.sl[kn]]) * (plan.cd[kn] * cis[:, plan.ang[kn]])) @ plan.Ct[kn]).T
        )
        ua, us = blk.t_ua[d], blk.t_us[d]
        # a moved term's known direction and length (column -1 of E and S: the padding, 1 and 0)
        self.direction = np.ascontiguousarray((plan.cd[d] * cis[:, np.where(ua >= 0, -1, plan.ang[d])]).T)
        self.length = np.ascontiguousarray((plan.r[d] + lengths[:, np.where(us >= 0, -1, plan.sl[d])]).T)
        self.ta = np.nonzero(ua >= 0)[0]
        self.ta_u = np.searchsorted(blk.ia, ua[self.ta])  # which unknown angle turns each of those terms
        self.ts, self.xs = np.nonzero(us >= 0)[0], us[us >= 0]
        self.Cd = np.ascontiguousarray(plan.Ct[d].T)
        self.blk = blk
        self.th: np.ndarray | None = None  # the unknown angles of the last evaluation and e^{jθ} there
        self.cis: np.ndarray | None = None

    def turn(self, th: np.ndarray) -> np.ndarray:
        """e^{jθ} of the unknown angles (na, n): from the last one times e^{jδ} by its series where every
        δ = θ − θ_last is small (Newton's corrections: cos and sin cost ~40 products each), else afresh."""
        if self.th is not None:
            d = th - self.th
            with np.errstate(invalid="ignore"):
                small = bool(np.all(np.abs(d) <= SERIES))
            if small:
                self.th, self.cis = th.copy(), self.cis * _cis_series(d)
                return self.cis
        self.th, self.cis = th.copy(), np.cos(th) + 1j * np.sin(th)
        return self.cis

    def eval(self, x: np.ndarray, jac: bool, J: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
        """[Re; Im] of the loop sums at x (2m, n) and, if ``jac``, their Jacobian (2m, nu, n), written into J
        if given (one this method wrote before: its structural zeros are not rewritten)."""
        blk = self.blk
        e, ln = self.direction, self.length
        with np.errstate(invalid="ignore"):
            if len(self.ta):
                e = e.copy()
                cis = self.turn(x[blk.ia])
                for t, u in zip(self.ta, self.ta_u, strict=True):
                    e[t] *= cis[u]
            if len(self.ts):
                ln = ln.copy()
                ln[self.ts] += x[self.xs]
            z = ln * e
            F = self.F0 + self.Cd @ z
            if not jac:
                return np.concatenate([F.real, F.imag]), None
        if J is None:
            J = np.zeros((blk.m2, blk.nu, x.shape[1]))
        Jf = J.reshape(blk.m2 * blk.nu, -1)  # entries no term reaches stay 0 (a reused J keeps them)
        parts = (z.real, z.imag, e.real, e.imag)
        last = -1
        with np.errstate(invalid="ignore", over="ignore"):
            for dest, part, k, c in blk.j_entries:  # row by row: no stack-sized temporaries
                if dest != last:
                    np.multiply(parts[part][k], c, out=Jf[dest])
                else:
                    Jf[dest] += c * parts[part][k]
                last = dest
        return np.concatenate([F.real, F.imag]), J


SERIES = 0.05  # angle corrections up to this (rad) update e^{jθ} by the series (its error < 1e-19 there)


def _cis_series(d: np.ndarray) -> np.ndarray:
    """e^{jd} for |d| ≤ SERIES by its Taylor series, to d⁹ (the first term left out, d¹⁰/10!, is < 3e-20),
    or to d³ where every |d| ≤ 1e-4 (then d⁴/24 < 5e-18)."""
    d2 = d * d
    if np.all(np.abs(d) <= 1e-4):
        return (1.0 - 0.5 * d2) + 1j * (d - d * d2 * (1 / 6))
    c = 1.0 + d2 * (-1 / 2 + d2 * (1 / 24 + d2 * (-1 / 720 + d2 * (1 / 40320))))
    s = d * (1.0 + d2 * (-1 / 6 + d2 * (1 / 120 + d2 * (-1 / 5040 + d2 * (1 / 362880)))))
    return c + 1j * s


def newton_rows(
    residual: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    x: np.ndarray,
    tol: float,
    max_iter: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Batched Newton–Raphson from ``x`` (rows, nu): ``residual(act, x_act)`` stores x_act on the rows ``act`` and
    gives their residuals and Jacobians (F, J); a row stops as its step falls below tol·(1 + |x|) (least squares
    where J has more rows than columns). Returns (solution, converged mask); the caller stores the finite rows."""
    x = x.copy()
    conv = np.zeros(len(x), bool)
    act = np.arange(len(x))
    for _ in range(max_iter):
        F, J = residual(act, x[act])
        dx = least_squares_rows(J, -F)
        xa = x[act] + dx
        x[act] = xa
        finite = np.all(np.isfinite(xa), axis=1)
        with np.errstate(invalid="ignore"):
            done = finite & (np.max(np.abs(dx), axis=1) <= tol * (1.0 + np.max(np.abs(xa), axis=1)))
        conv[act[done]] = True
        act = act[finite & ~done]
        if not len(act):
            break
    return x, conv


def newton(
    blk: NewtonBlock, state: State, rows: np.ndarray, x: np.ndarray, tol: float, max_iter: int
) -> tuple[np.ndarray, np.ndarray]:
    """Batched Newton from ``x`` on ``rows``: (solution, converged mask); rows stop as their step falls
    below tol·(1 + |x|)."""

    def residual(act: np.ndarray, xa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        blk.put(state, rows[act], xa)
        return blk.residual_jacobian(state, rows[act])

    x, conv = newton_rows(residual, x, tol, max_iter)
    good = np.all(np.isfinite(x), axis=1)
    blk.put(state, rows[good], x[good])
    return x, conv


def factor_rates(plan: Plan, state: State, k: slice, inv: np.ndarray, what: str) -> np.ndarray:
    """Rates of a Newton block from its factored Jacobians (J⁻¹, or the least-squares (JᵀJ)⁻¹Jᵀ)."""
    return (inv @ known_rhs(plan.vel_sum if what == "v" else plan.total, state, k, what)[..., None])[..., 0]


# ------------------------------------------------------------------ the block over a run


class _Ctx:
    """One Newton block being solved on rows 0..n-1 of a state (row 0 assembled)."""

    def __init__(self, run: Run, state: State, t_grid: np.ndarray, i: int, plan: Plan, n: int) -> None:
        self.run, self.state, self.t_grid, self.i, self.plan, self.n = run, state, t_grid, i, plan, n
        cache = run.system.cache.setdefault("newton", {})
        if i not in cache:
            cache[i] = NewtonBlock(plan, run.system.n_angles, run.scale)
        self.blk: NewtonBlock = cache[i]
        self.na = run.system.n_angles
        self.xd = np.zeros((n, self.blk.nu))  # rates at the rows continued one by one (predictors)
        self.xdd = np.zeros((n, self.blk.nu))
        self.weak = np.zeros(n, bool)  # rows whose rates are too ill-conditioned to predict from
        self.prev = np.full(n, -1)  # the row each row was continued from

    def expected_sign(self, rows: np.ndarray) -> np.ndarray:
        """The determinant sign of the run's assembly branch at these rows (flipped after change points)."""
        ref = self.run.newton_sign.get(self.i)
        return ref * self.run.sigma(self.i, self.t_grid[rows])

    def rates_rows(self, rows: np.ndarray, J: np.ndarray) -> None:
        """ẋ and ẍ of the block at these rows (exact linear solves; least squares for a redundant block), kept
        for the Taylor predictor; a row too ill-conditioned to predict from is marked weak."""
        plan, state, na, blk = self.plan, self.state, self.na, self.blk
        X = invert_rows(J) if blk.square else None  # one inverse for both right-hand sides
        for what, out in (("v", self.xd), ("a", self.xdd)):
            rhs = known_rhs(plan.total, state, rows, what)
            val = least_squares_rows(J, rhs) if X is None else (X @ rhs[..., None])[..., 0]
            out[rows] = val
            if what == "v":
                store_rates(plan, state, rows, val, "v", na)
        store_rates(plan, state, rows, np.zeros((len(rows), blk.nu)), "v", na)
        Js = J * blk.colscale
        if X is None:
            cond = cond_2norm(Js) if Js.shape[1] == Js.shape[2] else svd_cond(Js)
        else:  # the Frobenius bound, the exact 2-norm one where it decides
            with np.errstate(invalid="ignore", over="ignore"):
                Xs = X / blk.colscale[:, None]
                cond = np.sqrt(sum_squares(Js) * sum_squares(Xs))
            exact = np.nonzero(~(cond * cond * EPS <= self.run.rtol))[0]
            if len(exact):
                cond[exact] = cond_2norm(Js[exact])
        # next to a singular row (a change point) the rates are not accurate enough to predict from
        finite = np.all(np.isfinite(self.xd[rows]), axis=1) & np.all(np.isfinite(self.xdd[rows]), axis=1)
        self.weak[rows] = ~(cond * cond * EPS <= self.run.rtol) | ~finite

    def rates_at(self, k: int, J: np.ndarray) -> None:
        """:meth:`rates_rows` at row k alone."""
        self.rates_rows(np.array([k]), J[None])

    def inputs(self) -> np.ndarray:
        """The value of the run's one input (a crank's θ [rad], a slider's s) on rows 0..n-1."""
        v = self.run.system.drivers[0]
        return self.state.theta[: self.n, v] if v < self.na else self.state.s[: self.n, v - self.na]


def solve_block(
    run: Run, state: State, t_grid: np.ndarray, i: int, plan: Plan, n: int
) -> tuple[Failure | None, Factor]:
    """Solve Newton block ``i`` on rows 0..n-1; returns (the first failure or None, the Factor of the rows
    before it). Rows from the failure on are left unsolved. Under a chart of the run (:mod:`vloop.core.charts`)
    every row is predicted from it at once (:func:`_from_chart`), else continued from row 0."""
    ctx = _Ctx(run, state, t_grid, i, plan, n)
    blk = ctx.blk
    _, J0 = blk.residual_jacobian(state, np.array([0]))
    if i not in run.newton_sign:
        run.newton_sign[i] = float(det_sign(J0)[0] or 1.0) * float(run.sigma(i, t_grid[:1])[0])
    if n > 1:
        ctx.rates_at(0, J0[0])
    if run.chart is not None and n > 1:
        return None, _from_chart(ctx)
    start = 0
    while True:  # (again from a coarse row found on another branch than the rows before it lead to)
        coarse, n_ok, failure = _coarse_pass(ctx, start)
        coarse = np.concatenate([np.arange(start), coarse[coarse < n_ok]])
        rows = _between(coarse, n_ok)
        j, pred, move = _predict(ctx, coarse, rows)
        factor, res, conv, far = _settle(ctx, rows, pred, move, n_ok)
        bad = _bad_rows(ctx, rows, factor, res, conv, far) if len(rows) else np.zeros(0, bool)
        if not bad.any():
            return failure, factor
        start = 0
        for jj in np.unique(j[bad]):  # continue those intervals one row at a time
            lo, hi = int(coarse[jj]), int(coarse[jj + 1])
            for k in range(lo + 1, hi + 1):  # ... and on to the coarse row after them: do they lead to it?
                f = _step(ctx, k - 1, k, strict=False) if k < hi else _joins(ctx, k)
                if f is not None:
                    n_ok, failure = (k, f) if isinstance(f, Failure) else (n_ok, failure)
                    start = k if f is True else 0
                    break
            if start or (failure is not None and failure.sample <= hi):
                break
        if not start:
            factor, _, _ = _refactor(blk, state, n_ok, run)
            return failure, factor


def _joins(ctx: _Ctx, k: int) -> Failure | bool | None:
    """Continue from row k − 1 to coarse row k: None where it lands where the coarse pass put row k (that row kept
    as it was), True where it does not (the coarse pass jumped to another solution there: row k now holds the
    continued one), or the step's failure."""
    state, blk = ctx.state, ctx.blk
    kept = [getattr(state, name)[k].copy() for name in State.FIELDS]
    carried = (ctx.xd[k].copy(), ctx.xdd[k].copy(), ctx.weak[k], ctx.prev[k])
    x = blk.read(state, np.array([k]))[0]
    f = _step(ctx, k - 1, k, strict=False)
    if f is not None:
        return f
    stepped = blk.read(state, np.array([k]))[0]
    if np.max(np.abs(stepped - x)) > 1e-8 * (1.0 + np.max(np.abs(x))):
        return True
    for name, values in zip(State.FIELDS, kept, strict=True):
        getattr(state, name)[k] = values
    ctx.xd[k], ctx.xdd[k], ctx.weak[k], ctx.prev[k] = carried
    return None


def _from_chart(ctx: _Ctx) -> Factor:
    """Rows 1..n-1 solved at once from the run's chart (its quintic Hermite interpolant at each row's input), each
    checked as a row between coarse rows is (converged, closed, near its prediction, on the run's branch): the
    Factor of rows 0..n-1. Raises ChartMiss if a row fails a check (the chunk is then solved without the chart)."""
    blk, na = ctx.blk, ctx.na
    cols = np.empty(blk.nu, int)  # the block's unknowns among the chart's variables (angles, then sliders)
    cols[blk.ia], cols[blk.isl] = blk.acol, na + blk.scol
    rows = np.arange(1, ctx.n)
    pred, move = ctx.run.chart.predict(ctx.inputs()[rows], cols)
    factor, res, conv, far = _settle(ctx, rows, pred, move, ctx.n)
    if _bad_rows(ctx, rows, factor, res, conv, far).any():
        raise ChartMiss(f"block {ctx.i}: a row predicted from the chart fails a check")
    return factor


def _settle(
    ctx: _Ctx, rows: np.ndarray, pred: np.ndarray | None, move: np.ndarray | None, n: int
) -> tuple[Factor, np.ndarray, np.ndarray, np.ndarray]:
    """Newton on ``rows`` from their predictions (batch-last), then the Factor of rows 0..n-1 (one more step
    where the last one was above tol, its Jacobian refreshed): (Factor, closure, converged, far per row)."""
    run, state, blk = ctx.run, ctx.state, ctx.blk
    if blk.square and n:
        far, factor, res, conv = _dense_square(ctx, rows, pred, move, n)
    else:
        far = _dense_newton(ctx, rows, pred, move)
        factor, res, conv = blk.factor(state, np.arange(n), run.rtol, run.tol)
    again = np.nonzero(~conv)[0]
    if len(again):  # one more step where the last one was above tol: its Jacobian is refreshed too
        fac2, res2, conv2 = blk.factor(state, again, run.rtol, run.tol)
        for name in ("J", "inv", "cond", "sign"):
            getattr(factor, name)[again] = getattr(fac2, name)
        res[again], conv[again] = np.maximum(res[again], res2), conv2
    return factor, res, conv, far


def _bad_rows(
    ctx: _Ctx, rows: np.ndarray, factor: Factor, res: np.ndarray, conv: np.ndarray, far: np.ndarray
) -> np.ndarray:
    """Rows solved from a prediction that do not converge, close, stay near it, on the run's branch."""
    return ~conv[rows] | far | ~(res[rows] <= CLOSURE) | (factor.sign[rows] != ctx.expected_sign(rows))


def _refactor(blk: NewtonBlock, state: State, n: int, run: Run) -> tuple[Factor, np.ndarray, np.ndarray]:
    """The Factor of rows 0..n-1 as they stand (a last Newton step applied)."""
    if blk.square and n:
        return _factor_square(_Rows(blk, state, n), state, blk.read_last(state, n), run.rtol, run.tol)
    return blk.factor(state, np.arange(n), run.rtol, run.tol)


def _input_travel(ctx: _Ctx) -> np.ndarray:
    """Cumulative travel [rad; sliders: 2π per mechanism size] of the block's known variables over the rows."""
    state, n, system = ctx.state, ctx.n, ctx.run.system
    na = system.n_angles
    mine = set()
    for li in ctx.plan.block.loops:
        mine.update(system.loops[li].variables)
    travel = np.zeros(max(n - 1, 0))
    for v in sorted(mine - set(ctx.plan.block.unknowns)):
        d = np.diff(state.theta[:n, v]) if v < na else np.diff(state.s[:n, v - na]) * (TWO_PI / ctx.run.scale)
        travel = np.maximum(travel, np.abs(d))
    return np.concatenate([[0.0], np.cumsum(travel)])


def _next_row(ctx: _Ctx, a: int, cum: np.ndarray) -> int:
    """The furthest row after ``a`` that the block's unknowns (by their Taylor series at a) and its inputs
    reach within COARSE_STEP of travel."""
    unit = np.where(ctx.blk.colscale < 1.0, 1.0, TWO_PI / ctx.run.scale)  # angles: rad; sliders: 2π per size
    h_max = math.inf
    for v, acc in zip((np.abs(ctx.xd[a]) * unit).tolist(), (np.abs(ctx.xdd[a]) * unit).tolist(), strict=True):
        # a handful of unknowns: Python floats cost less than a dozen numpy calls; NaN never wins
        if acc > 0:
            h = (math.sqrt(v * v + 2 * acc * COARSE_STEP) - v) / acc
        elif v > 0:
            h = COARSE_STEP / v
        else:
            continue
        h_max = h if h < h_max else h_max
    b = int(np.searchsorted(ctx.t_grid[: ctx.n], ctx.t_grid[a] + h_max, side="right")) - 1
    b = min(b, int(np.searchsorted(cum, cum[a] + COARSE_STEP, side="right")) - 1, ctx.n - 1)
    return max(b, a + 1)


def _coarse_pass(ctx: _Ctx, start: int = 0) -> tuple[np.ndarray, int, Failure | None]:
    """Adaptive continuation from row ``start`` (solved, its rates known): from each solved row, the furthest row
    the predictor is trusted to reach; an untrusted step is halved, down to single rows where the sample-by-sample
    rules decide. Returns (the rows solved on the way, from ``start``; rows solved; failure)."""
    cum = _input_travel(ctx)
    coarse = [start]
    a = start
    while a < ctx.n - 1:
        b = _next_row(ctx, a, cum)
        ahead = _window(ctx, a, b, cum)
        if len(ahead):
            coarse.extend(ahead.tolist())
            a = int(ahead[-1])
            continue
        while True:
            f = _step(ctx, a, b, strict=b - a > 1)
            if f is None:
                break
            if b == a + 1:
                return np.array(coarse), b, f
            b = a + (b - a) // 2
        coarse.append(b)
        a = b
    return np.array(coarse), ctx.n, None


def _window(ctx: _Ctx, a: int, b: int, cum: np.ndarray) -> np.ndarray:
    """Up to WINDOW coarse rows ahead of row ``a``, (b − a) rows apart (closer where the inputs pass k·COARSE_STEP
    of travel sooner), predicted from a's Taylor series and solved together; returns the leading rows that pass
    every check of a strict step (their rates computed)."""
    run, state, blk, t_grid = ctx.run, ctx.state, ctx.blk, ctx.t_grid
    if ctx.weak[a] or b - a < 2:
        return np.zeros(0, int)
    k = np.arange(1, WINDOW + 1)
    # the k-th row: k steps of b − a, or less where the inputs travel faster than at a (a driver speeding up)
    reach = np.searchsorted(cum, cum[a] + COARSE_STEP * k, side="right") - 1
    rows = np.unique(np.minimum(np.minimum(a + (b - a) * k, reach), ctx.n - 1))
    rows = rows[rows > a]
    if len(rows) < 2:
        return np.zeros(0, int)
    h = (t_grid[rows] - t_grid[a])[:, None]
    x_a = blk.read(state, np.array([a]))
    incr = ctx.xd[a] * h + 0.5 * ctx.xdd[a] * h * h
    pred = x_a + incr
    x, conv = newton(blk, state, rows, pred, run.tol, min(run.max_iter, WINDOW_ITER))
    F, J = blk.residual_jacobian(state, rows)
    with np.errstate(invalid="ignore"):
        res = np.max(np.abs(F), axis=1) / run.scale
    ok = conv & (res <= CLOSURE) & ~_far(blk, x - pred, incr, x_a) & (det_sign(J) == ctx.expected_sign(rows))
    m = int(np.argmin(ok)) if not ok.all() else len(rows)
    if m == 0:
        return np.zeros(0, int)
    rows, J = rows[:m], J[:m]
    ctx.rates_rows(rows, J)
    ctx.prev[rows] = np.concatenate([[a], rows[:-1]])
    return rows


def _step(ctx: _Ctx, a: int, k: int, strict: bool) -> Failure | None:
    """Continue from solved row ``a`` (its rates known) to row ``k``. Strict: any doubt returns a
    failure (the caller refines); otherwise a branch sign change may be a change point."""
    run, state, blk, t_grid = ctx.run, ctx.state, ctx.blk, ctx.t_grid
    h = t_grid[k] - t_grid[a]
    x_a = blk.read(state, np.array([a]))[0]
    if ctx.weak[a]:  # the secant through the row before instead of the (unreliable) Taylor series
        b = ctx.prev[a]
        incr = (x_a - blk.read(state, np.array([b]))[0]) * (h / (t_grid[a] - t_grid[b])) if b >= 0 else np.zeros(blk.nu)
    else:
        incr = ctx.xd[a] * h + 0.5 * ctx.xdd[a] * h * h
    pred = x_a + incr
    rows = np.array([k])
    x, conv = newton(blk, state, rows, pred[None], run.tol, run.max_iter)
    F, J = blk.residual_jacobian(state, rows)
    res = float(np.max(np.abs(F))) / run.scale if np.all(np.isfinite(F)) else math.inf
    far = bool(_far(blk, x - pred, incr[None], x_a[None])[0])
    sign = float(det_sign(J)[0])
    flipped = sign != float(ctx.expected_sign(rows)[0])
    if strict:
        if not conv[0] or res > CLOSURE or far or flipped:
            return Failure(k, ctx.plan.block.loops[0], "untrusted coarse step")
    else:
        if not conv[0] or res > CLOSURE or not np.all(np.isfinite(J)):
            worst = ctx.plan.block.loops[
                int(np.argmax(np.abs(F[0]) if np.all(np.isfinite(F)) else 0)) % len(ctx.plan.block.loops)
            ]
            return Failure(k, worst, f"Newton did not converge (closure {res:.2g} of the mechanism size)")
        if flipped and sign != 0 and far and run.detect:  # Newton may have jumped: follow the path in small steps
            smooth = _smooth_to(ctx, a, k)
            if smooth is not None:
                blk.put(state, rows, smooth[None])
                F, J = blk.residual_jacobian(state, rows)
                sign = float(det_sign(J)[0])
                flipped, far = sign != float(ctx.expected_sign(rows)[0]), False
        if flipped and sign != 0:
            if not (run.detect and not far and _passes_change_point(ctx, a, k)):
                return Failure(
                    k,
                    ctx.plan.block.loops[0],
                    "the assembly branch flipped (the Jacobian changed sign): a toggle was crossed",
                )
        elif sign == 0:
            return Failure(k, ctx.plan.block.loops[0], "the loop Jacobian is singular (a toggle)")
    ctx.rates_at(k, J[0])
    ctx.prev[k] = a
    return None


def _passes_change_point(ctx: _Ctx, a: int, k: int) -> bool:
    """Between rows a and k the determinant changed sign on the smooth continuation: locate where
    (bisection on det J along the continuation from row a) and record the change point."""
    run, i = ctx.run, ctx.i
    choices = change_point_choices(run.system, run.system.loops[ctx.plan.block.loops[0]].index + 1)
    if "other" in choices:
        return False  # only a closed-form dyad can be sent onto the other branch
    lo, hi = float(ctx.t_grid[a]), float(ctx.t_grid[k])
    s_lo = float(ctx.expected_sign(np.array([a]))[0])
    for _ in range(LOCATE_STEPS):
        mid = 0.5 * (lo + hi)
        d = _det_at(ctx, a, mid)
        if d is None:
            break
        if np.sign(d) == s_lo:
            lo = mid
        else:
            hi = mid
        if hi - lo <= 1e-12 * (ctx.t_grid[k] - ctx.t_grid[a]):
            break
    run.events.setdefault(i, []).append(ChangePoint(i, 0.5 * (lo + hi), True, True))
    return True


def _smooth_to(ctx: _Ctx, a: int, k: int) -> np.ndarray | None:
    """The block's unknowns at row k reached from row a along the continuous path: Newton at intermediate
    times, each predicted by the secant through the two before, the step halved wherever a solve corrects
    its prediction by more than JUMP of the move (a path bending fast next to a singular point); None if the
    step falls below 2⁻¹⁶ of the interval or a solve does not converge."""
    t_a, t_k = float(ctx.t_grid[a]), float(ctx.t_grid[k])
    span = t_k - t_a
    t, dt = t_a, span / SUBSTEPS
    x_prev = ctx.blk.read(ctx.state, np.array([a]))[0]
    rate = ctx.xd[a]
    while t < t_k - 1e-12 * span:
        dt = min(dt, t_k - t)
        guess = x_prev + rate * dt
        x = _solve_at(ctx, a, t + dt, guess)
        if x is None or bool(_far(ctx.blk, (x - guess)[None], (rate * dt)[None], x_prev[None])[0]):
            dt *= 0.5
            if dt < span / 2**16:
                return None
            continue
        rate, x_prev, t = (x - x_prev) / dt, x, t + dt
        dt *= 1.5
    return x_prev


def _trial_at(ctx: _Ctx, a: int, t: float) -> State | None:
    """A two-row state: row 0 a copy of row a, row 1 at time t with the inputs there and the blocks before this
    one solved (None if one of them cannot be)."""
    run = ctx.run
    sub_run = dataclasses.replace(run, detect=False, check=False, rates=False)
    trial = State(2, run.system.n_angles, len(run.system.slider_names))
    for name in ("e", "theta", "s", "omega", "alpha", "s_dot", "s_ddot"):
        getattr(trial, name)[0] = getattr(ctx.state, name)[a]
    grid = np.array([ctx.t_grid[a], t])
    impose_drivers(run.system, trial, *run.inputs(grid))
    if ctx.i > 0 and sub_run.blocks(sub_run, trial, grid, 2, upto=ctx.i - 1).n_ok < 2:
        return None
    return trial


def _solve_at(ctx: _Ctx, a: int, t: float, guess: np.ndarray) -> np.ndarray | None:
    """The block's unknowns at time t by Newton from ``guess`` (earlier blocks solved there from row a)."""
    trial = _trial_at(ctx, a, t)
    if trial is None:
        return None
    x, conv = newton(ctx.blk, trial, np.array([1]), guess[None], ctx.run.tol, ctx.run.max_iter)
    return x[0] if conv[0] else None


def _det_at(ctx: _Ctx, a: int, t: float) -> float | None:
    """det J of the block at time t, reached by Newton from row a's Taylor predictor (None: no convergence)."""
    run = ctx.run
    trial = _trial_at(ctx, a, t)
    if trial is None:
        return None
    h = t - ctx.t_grid[a]
    x_a = ctx.blk.read(ctx.state, np.array([a]))[0]
    pred = x_a + ctx.xd[a] * h + 0.5 * ctx.xdd[a] * h * h
    _, conv = newton(ctx.blk, trial, np.array([1]), pred[None], run.tol, run.max_iter)
    if not conv[0]:
        return None
    _, J = ctx.blk.residual_jacobian(trial, np.array([1]))
    return float(np.linalg.det(J[0])) if ctx.blk.square else 1.0


def _far(blk: NewtonBlock, correction: np.ndarray, move: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Rows whose Newton correction exceeds JUMP of the predicted move (largest component, angles in rad,
    sliders in 2π per mechanism size): the predictor is not trusted to have led to the same branch."""
    unit = np.where(blk.colscale < 1.0, 1.0, TWO_PI / blk.scale)
    with np.errstate(invalid="ignore"):
        c = np.max(np.abs(correction) * unit, axis=1)
        m = np.max(np.abs(move) * unit, axis=1) + 1e-9 * (1.0 + np.max(np.abs(x) * unit, axis=1))
        return ~(c <= JUMP * m)


def _predict(ctx: _Ctx, coarse: np.ndarray, rows: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The interval of each row between coarse rows (coarse[j] < row < coarse[j + 1]), its prediction by the
    quintic Hermite interpolant of its neighbours' positions, rates and accelerations (error ~ step⁶), batch-last
    (nu, rows), and the move a correction is measured against (:func:`_far_dense`)."""
    if not len(rows):
        return rows, None, None
    xc = ctx.blk.read(ctx.state, coarse).T
    j = np.searchsorted(coarse, rows) - 1  # interval of each row: coarse[j] < row < coarse[j + 1]
    tc = ctx.t_grid[coarse]
    pred = hermite(tc, xc, ctx.xd[coarse].T, ctx.xdd[coarse].T, ctx.t_grid[rows], j, ordered=True)
    return j, pred, _moves(ctx.blk, xc)[j]


def _moves(blk: NewtonBlock, xc: np.ndarray) -> np.ndarray:
    """:func:`charts.interval_moves` of the block's unknowns (angles in rad, sliders in 2π per mechanism size)."""
    return interval_moves(xc, np.where(blk.colscale < 1.0, 1.0, TWO_PI / blk.scale))


def _far_dense(blk: NewtonBlock, correction: np.ndarray, move: np.ndarray) -> np.ndarray:
    """:func:`_far` for rows solved from an interpolant (batch-last: correction (nu, rows)), each against the
    move of its interval (:func:`_moves`)."""
    unit = np.where(blk.colscale < 1.0, 1.0, TWO_PI / blk.scale)[:, None]
    with np.errstate(invalid="ignore"):
        return ~(np.max(np.abs(correction) * unit, axis=0) <= JUMP * move)


def _dense_newton(ctx: _Ctx, rows: np.ndarray, pred: np.ndarray | None, move: np.ndarray | None) -> np.ndarray:
    """Newton on ``rows`` at once from their predictions (nu, rows), until the steps fall below LOOSE: the step
    the Factor then takes is the convergence test. Returns whether each is far from its prediction."""
    if not len(rows):
        return np.zeros(0, bool)
    x, _ = newton(ctx.blk, ctx.state, rows, pred.T, LOOSE, ctx.run.max_iter)
    return _far_dense(ctx.blk, x.T - pred, move)


CHORD = 3  # chord steps (the inverse at the prediction reused) before a dense row is left to plain Newton


def _dense_square(
    ctx: _Ctx, rows: np.ndarray, pred: np.ndarray | None, move: np.ndarray | None, n_ok: int
) -> tuple[np.ndarray, Factor, np.ndarray, np.ndarray]:
    """:func:`_dense_newton` and the Factor of rows 0..n_ok-1 for a square block, batch-last: one Newton step
    from the predictions, then chord steps with the same inverses (a prediction off by δ converges by a
    factor ~cond·δ per step), plain Newton for the few rows still above LOOSE after CHORD of them; then the
    factor. Returns (far, Factor, closure, converged and fresh)."""
    run, state, blk = ctx.run, ctx.state, ctx.blk
    ev = _Rows(blk, state, n_ok)
    x = blk.read_last(state, n_ok)
    far = np.zeros(0, bool)
    J = np.zeros((blk.m2, blk.nu, n_ok))  # J and J⁻¹ buffers, shared with the factor (fresh pages cost faults)
    X = np.empty((blk.nu, blk.m2, n_ok))
    if len(rows):
        x[:, rows] = pred
        F, _ = ev.eval(x, True, J)
        invert_last(J, out=X)
        for _ in range(CHORD):
            with np.errstate(invalid="ignore"):
                dx = -apply_last(X, F)
                x += dx
                act = ~(_step_size(dx, x) <= LOOSE) & np.all(np.isfinite(x), axis=0)
            if not act.any():
                break
            F, _ = ev.eval(x, False)
        else:
            sub = np.nonzero(act)[0]
            x[:, sub] = newton(blk, state, sub, x[:, sub].T, LOOSE, run.max_iter)[0].T
        far = _far_dense(blk, x[:, rows] - pred, move)
        del F  # not kept through the factor
    factor, res, conv = _factor_square(ev, state, x, run.rtol, run.tol, J, X)
    return far, factor, res, conv


def _between(coarse: np.ndarray, n: int) -> np.ndarray:
    """The rows 0..n-1 that are not coarse rows (np.setdiff1d sorts: ~5× slower)."""
    dense = np.ones(n, bool)
    dense[coarse] = False
    return np.flatnonzero(dense)


def _step_size(dx: np.ndarray, x: np.ndarray) -> np.ndarray:
    """A Newton step relative to its row (batch-last): max |dx| / (1 + max |x|)."""
    return np.max(np.abs(dx), axis=0, initial=0.0) / (1.0 + np.max(np.abs(x), axis=0, initial=0.0))


def _factor_square(
    ev: _Rows,
    state: State,
    x: np.ndarray,
    rtol: float,
    tol: float,
    J: np.ndarray | None = None,
    X: np.ndarray | None = None,
) -> tuple[Factor, np.ndarray, np.ndarray]:
    """:meth:`NewtonBlock.factor` on rows 0..n-1 of a square block at x (batch-last), by
    :func:`vloop.core.linalg.invert_last`: the Factor, the closure of each row and whether its last step was
    below tol and FRESH (it is applied).
    J, X: buffers for the Jacobian (one :meth:`_Rows.eval` wrote) and its inverse."""
    blk = ev.blk
    F, J = ev.eval(x, True, J)
    X, sign = invert_last(J, out=X)
    cond = condition_last(J, X, blk.colscale, rtol)
    sign[~np.all(np.isfinite(J), axis=(0, 1))] = np.nan  # as numpy's det gives it
    with np.errstate(invalid="ignore"):
        res = np.max(np.abs(F), axis=0, initial=0.0) / blk.scale
        dx = -apply_last(X, F)
        x = x + dx
        step = _step_size(dx, x)
    cis = None
    if len(blk.ia) and ev.cis is not None and np.all(np.abs(dx[blk.ia]) <= SERIES):
        cis = (ev.cis * _cis_series(dx[blk.ia])).T  # e^{jθ} carried along, not recomputed
    finite = np.all(np.isfinite(x), axis=0)
    if finite.all():
        blk.put(state, slice(0, x.shape[1]), x.T, cis)
    else:
        rows = np.nonzero(finite)[0]
        blk.put(state, rows, x[:, rows].T, None if cis is None else cis[rows])
    factor = Factor(J.transpose(2, 0, 1), X.transpose(2, 0, 1), cond, sign)
    return factor, res, (step <= tol) & (step <= FRESH)
