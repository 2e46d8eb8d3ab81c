"""Many variants of one mechanism solved together: variants × samples through the core's own algorithms.

    model = VariantModel.build(mech, vloop.compile(mech), tuple(resolve(mech, n, n) for n in names))
    grid = make_grid(model, model.designs(values), times)        # internal times shared by every variant
    out = solve(model, values, grid, ["B.x", "B.y", "l4.theta"])  # columns (variants, samples), a status each
    out.completed, out.reason, out.columns["B.x"]

or, in one call from a compiled system, :func:`solve_variants`.

Every variant shares the nominal LoopSystem's structure; its own numbers are per-variant term constants
(r, e^{jδ}), driver numbers and frame offsets (:class:`vloop.core.variants.Designs`). The variants' samples
are stacked into one state (:class:`vloop.core.data.State`, variant by variant) and solved by the functions a
single run calls:

* closed-form dyads (:mod:`vloop.core.dyads`: positions, health, rates) on every row of every variant at once,
  each row with its variant's constants (:func:`vloop.core.sums.per_row`), on the nominal branch σ;
* Newton blocks by the single run's continuation (:func:`vloop.core.newton.solve_block`), variant by variant on
  its own constants; each variant's t = 0 assembly continued from the nominal design (term vectors and driver
  numbers blended in ASSEMBLY_STEPS steps, Newton on the nominal branch: the sign of its Jacobian's determinant);
* change points searched as the single run searches them: the dips of each variant's discriminants
  (:func:`vloop.core.changepoints.candidate_minima`), every dip of every variant zoomed on at once
  (:func:`~.changepoints.locate_minima`); a variant with a change point is left to the single run.

A variant's numbers come from its own rows only (elementwise over rows: no matrix product across them, every
complex temporary below numpy's in-place threshold, see ROWS), so how many variants are solved together never
changes a number.

A variant the batch is not sure of is *doubtful*: its motion passes a limit (the loop stops closing), a dip of a
dyad's discriminant where the branches meet (a change point) or a block cannot close (a limit between samples),
a sample whose velocity error bound cond²·ε exceeds SURE·rtol (the single run refuses at rtol), a branch sign
change, a Newton continuation that fails, inputs too large to resolve or moving too far per sample, a
non-finite number. ``doubtful="single"`` (the default) solves it again on its own with the single-run solver
(:func:`vloop.core.solver.solve` on the variant's LoopSystem: same structure, its own constants), which locates
limits, passes change points and says why a motion stops, exactly as ``vloop.solve`` of that variant's file
would; ``doubtful="fail"`` reports it as not completed (reason :data:`DOUBTFUL`, columns NaN) without that
second solve — for a search that only wants what the batch takes as it is. A variant that does not assemble
at t = 0 on the nominal branch is reported, not solved.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Self

import numpy as np

from ..drivers import evaluate, polynomial
from ..errors import MotionError, VloopError
from ..method.loops import LoopSystem
from ..model import Mechanism
from . import newton
from .accuracy import DEFAULT_MAX_ITER, DEFAULT_RTOL, DEFAULT_TOL, velocity_bound
from .blocks import run_blocks
from .changepoints import CHANGE_GAP, candidate_minima, eta_of_rates, locate_minima
from .context import Inputs, Run, impose_drivers, input_units
from .data import TWO_PI, State
from .dyads import closed_form, dyad_health, dyad_rates, jacobian_columns
from .grid import MAX_INPUT_STEP, input_travel, insert_rows, too_large
from .linalg import det_sign
from .plans import Plan, block_plans, store_rates, system_sums
from .solver import MAX_LEAD
from .solver import solve as solve_system
from .sums import per_row
from .variants import Designs, VariantModel, resolve

# Variants × internal samples solved together. NumPy computes ``a * tmp`` in place as ``tmp * a`` when the
# temporary is 256 KiB or more, and a complex product (fused multiply-add) is not bitwise symmetric: keeping
# every complex (variants × samples) array below that size makes a variant's numbers independent of how many
# variants it is solved with — the chunking never changes a number. (The state stays in cache, too.)
ROWS = 16_000
ASSEMBLY_STEPS = 16  # continuation steps from the nominal design to a variant (t = 0, Newton blocks)
SURE = 0.1  # a sample whose velocity error bound cond²·ε exceeds this fraction of rtol is left to the single run
MAX_GRID_FACTOR = 64  # internal samples allowed per requested one (plus a lead-in allowance)
DOUBTFUL = 'doubtful: not solved on its own (solve(..., doubtful="fail"))'


# ---------------------------------------------------------------- the shared internal grid and the inputs


@dataclass(frozen=True)
class Grid:
    """Internal times shared by every variant: t[0] = 0 (the assembly), then rows up to every requested
    time with rows inserted where any variant's input moves more than MAX_INPUT_STEP; ``out`` the internal
    row of each requested time."""

    t: np.ndarray
    out: np.ndarray
    times: np.ndarray


def make_grid(model: VariantModel, designs: Designs, times: np.ndarray) -> Grid:
    """The internal grid for ``times`` [s] (strictly increasing) that serves every one of ``designs``."""
    times = np.asarray(times, float)
    lead = times[0] != 0.0
    seq = np.concatenate([[0.0], times]) if lead else times
    steps = np.ones(max(len(seq) - 1, 0), np.int64)
    if model.mechanism.drivers and len(seq) > 1:
        steps = np.maximum(_steps_needed(model, designs, seq, lead), 1).astype(np.int64)
    t, starts = insert_rows(seq, steps)
    return Grid(t, starts[1:] if lead else starts, times)


def _steps_needed(model: VariantModel, designs: Designs, seq: np.ndarray, lead: bool) -> np.ndarray:
    """Internal rows each interval of ``seq`` needs so that no variant's input moves more than MAX_INPUT_STEP per
    row, capped at MAX_GRID_FACTOR (MAX_LEAD for a lead-in from t = 0): a variant whose inputs move farther is
    doubtful (see _impose). Evaluated in blocks of variants."""
    mech = model.mechanism
    units = input_units(mech, mech.scale / TWO_PI)
    h = np.diff(seq)[None, :, None]
    need = np.ones(len(seq) - 1)
    per = max(1, ROWS // len(seq))
    for lo in range(0, len(designs), per):
        X, XD, _ = _inputs(model, designs.take(slice(lo, lo + per)), seq)
        with np.errstate(invalid="ignore", over="ignore"):
            most = np.ceil(np.nanmax(input_travel(X, XD, h, units), axis=(0, 2)) / MAX_INPUT_STEP)
        need = np.maximum(need, np.where(np.isfinite(most), most, 1.0))  # absurd inputs: those variants doubtful
    cap = np.full(len(need), float(MAX_GRID_FACTOR))
    if lead:
        cap[0] = MAX_LEAD
    return np.minimum(need, cap)


def _inputs(model: VariantModel, d: Designs, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drivers' x, ẋ, ẍ per variant at times ``t`` (n,) or, per variant, (V, n): arrays (V, n, n_drivers), as
    vloop.drivers evaluates them."""
    mech = model.mechanism
    V, m = len(d), len(mech.drivers)
    X, XD, XDD = (np.zeros((V, np.shape(t)[-1], m)) for _ in range(3))
    for j, drv in enumerate(mech.drivers):
        if drv.profile is not None:
            X[:, :, j], XD[:, :, j], XDD[:, :, j] = evaluate(drv, t)
            continue
        X[:, :, j], XD[:, :, j] = polynomial(d.x0[:, j : j + 1], d.v0[:, j : j + 1], d.a0[:, j : j + 1], t)
        XDD[:, :, j] = d.a0[:, j : j + 1]
    return X, XD, XDD


# ---------------------------------------------------------------- what a batch shares, and each variant's status


@dataclass
class _Batch:
    """What solving a model's variants shares: the model, the solver options, the mechanism size the checks
    are relative to, and each Newton block's determinant sign at the nominal t = 0 assembly (its branch)."""

    model: VariantModel
    scale: float
    tol: float
    max_iter: int
    rtol: float
    newton_sign: dict[int, float] = field(default_factory=dict)

    @classmethod
    def build(cls, model: VariantModel) -> _Batch:
        mech, system = model.mechanism, model.system
        opts = mech.options
        out = cls(
            model,
            mech.scale,
            float(opts.get("tol", DEFAULT_TOL)),
            int(opts.get("max_iter", DEFAULT_MAX_ITER)),
            float(opts.get("rtol", DEFAULT_RTOL)),
        )
        newton_blocks = [(i, p) for i, p in enumerate(block_plans(system)) if p.block.kind == "newton"]
        if newton_blocks:
            state = State(1, system.n_angles, len(system.slider_names))
            impose_drivers(system, state, *(x[0] for x in _inputs(model, _nominal(model), np.zeros(1))))
            _put_variables(state, system, system.q0[None, :], drivers=False)
            for i, plan in newton_blocks:
                _, J = newton.NewtonBlock(plan, system.n_angles, out.scale).residual_jacobian(state, np.zeros(1, int))
                out.newton_sign[i] = float(det_sign(J)[0] or 1.0)
        return out

    def variant_run(self, d: Designs, v: int) -> Run:
        """A single run's context on variant v's own constants (its system has the nominal structure)."""
        system, mech = self.model.system, self.model.mechanism
        drivers = tuple(
            dataclasses.replace(drv, x0=float(d.x0[v, j]), v0=float(d.v0[v, j]), a0=float(d.a0[v, j]))
            for j, drv in enumerate(mech.drivers)
        )
        own = dataclasses.replace(system, t_r=d.r[v].copy(), t_delta=d.delta[v].copy(), cache={})
        run = Run(own, Inputs(dataclasses.replace(mech, drivers=drivers)), self.scale, self.tol, self.max_iter,
                  self.rtol, detect=False, newton_sign=dict(self.newton_sign))  # fmt: skip
        run.blocks = run_blocks
        return run


def _nominal(model: VariantModel) -> Designs:
    return model.designs(model.nominal_values()[None, :])


@dataclass
class _Flags:
    """Per variant: assembled at t = 0, taken by the batch, why not (first reason), worst condition number."""

    assembled: np.ndarray
    regular: np.ndarray
    why: list[str]
    cond: np.ndarray

    @classmethod
    def new(cls, V: int) -> _Flags:
        return cls(np.ones(V, bool), np.ones(V, bool), [""] * V, np.ones(V))

    def refuse(self, mask: np.ndarray, why: str) -> None:
        """These variants do not assemble at t = 0 (the first reason is kept)."""
        for v in np.nonzero(mask & self.assembled)[0]:
            self.why[v] = why
        self.assembled &= ~mask
        self.regular &= ~mask

    def doubt(self, mask: np.ndarray) -> None:
        """These variants are doubtful (module notes)."""
        self.regular &= ~mask


# ---------------------------------------------------------------- the state of many variants


def _put_variables(state: State, system: LoopSystem, q: np.ndarray, drivers: bool = True) -> None:
    """Row 0 of every variant set to its variables q (variants, n_vars); the drivers' left as they are unless
    ``drivers``."""
    na = system.n_angles
    for v in range(system.n_vars):
        if v in system.drivers and not drivers:
            continue
        if v < na:
            state.per_variant("theta")[:, 0, v] = q[:, v]
            state.per_variant("e")[:, 0, v] = np.exp(1j * q[:, v])  # as a single run's t = 0 row (initial_state)
        else:
            state.per_variant("s")[:, 0, v - na] = q[:, v]


def _impose(batch: _Batch, state: State, d: Designs, t: np.ndarray, checked: bool = True) -> np.ndarray:
    """Drivers' inputs into the state (every variant at times t); returns the variants whose inputs cannot be
    resolved (non-finite, a crank angle whose floating-point spacing exceeds rtol: the single run refuses those
    samples) or, ``checked``, move more than MAX_INPUT_STEP per row (turns would be miscounted)."""
    model = batch.model
    system = model.system
    X, XD, XDD = _inputs(model, d, t)
    bad = ~(np.isfinite(X) & np.isfinite(XD) & np.isfinite(XDD)).all(axis=(1, 2))
    if checked and np.ndim(t) == 1 and len(t) > 1 and system.drivers:
        units = input_units(model.mechanism, batch.scale / TWO_PI)
        with np.errstate(invalid="ignore", over="ignore"):
            bad |= ~np.all(input_travel(X, XD, np.diff(t)[None, :, None], units) <= MAX_INPUT_STEP * (1 + 1e-9), (1, 2))
    crank = np.array([drv.kind == "crank" for drv in model.mechanism.drivers], bool)
    with np.errstate(invalid="ignore"):
        bad |= np.any(np.abs(X[:, :, crank]) >= too_large(batch.rtol), axis=(1, 2))
    rows = len(d) * X.shape[1]
    impose_drivers(system, state, X.reshape(rows, -1), XD.reshape(rows, -1), XDD.reshape(rows, -1))
    return bad


def _constants(system: LoopSystem, d: Designs, samples: int) -> LoopSystem:
    """The system with each variant's term constants on its ``samples`` rows."""
    return per_row(system, np.ascontiguousarray(d.r.T), np.ascontiguousarray(d.cd.T), samples)


# ---------------------------------------------------------------- the blocks in order


def _where(system: LoopSystem, plan: Plan) -> str:
    loop = system.loops[plan.block.loops[0]]
    return f"loop {loop.index + 1} ({loop.label})"


def _solve_blocks(batch: _Batch, system: LoopSystem, state: State, d: Designs, grid: Grid, flags: _Flags) -> None:
    """Every block in order on every row of every variant (``system``: the per-row constants of ``d``); the
    worst condition number is taken over the requested rows, as the single run's health."""
    runs: dict[int, Run] = {}
    for i, plan in enumerate(block_plans(system)):
        if plan.block.kind == "newton":
            _newton_block(batch, state, d, grid, i, flags, runs)
        else:
            _dyad_block(batch, system, state, d, grid, i, plan, flags)


def _dyad_block(
    batch: _Batch, system: LoopSystem, state: State, d: Designs, grid: Grid, i: int, plan: Plan, flags: _Flags
) -> None:
    """A closed-form dyad on every row of every variant: positions on the nominal branch, the change points it
    may pass, health and rates."""
    V, n, na = state.variants, state.samples, system.n_angles
    rows = slice(0, V * n)
    ok, h = closed_form(plan, state, rows, np.full(V * n, plan.block.sigma))
    ok = ok.reshape(V, n)
    flags.refuse(~ok[:, 0], f"cannot assemble at t = 0: {_where(system, plan)} cannot close (its links cannot reach)")
    flags.doubt(~ok.all(axis=1))  # a limit: the single run locates it
    if plan.block.kind != "PP":
        flags.doubt(_change_points_possible(batch, d, grid, i, h.reshape(V, n), flags))
    cols = jacobian_columns(plan, state, rows)
    cond, sign = (x.reshape(V, n) for x in dyad_health(plan, state, rows, batch.scale, cols))
    flags.doubt(np.any(velocity_bound(cond) > SURE * batch.rtol, axis=1) | np.any(sign != sign[:, :1], axis=1))
    flags.cond = np.maximum(flags.cond, np.max(cond[:, grid.out], axis=1))
    for what in ("v", "a"):
        store_rates(plan, state, rows, dyad_rates(plan, state, rows, what, cols), what, na)


def _change_points_possible(batch: _Batch, d: Designs, grid: Grid, i: int, h: np.ndarray, flags: _Flags) -> np.ndarray:
    """The variants where block ``i``'s discriminants h (variants, samples) dip to a change point (located as the
    single run locates it, every dip of every variant at once), or where a block cannot close in a dip (a limit
    between samples), or where blocks before it are solved by Newton (probing through them is the single run's)."""
    found = candidate_minima(h, tail=True, t=grid.t)
    found = found[flags.regular[found[:, 0]]]
    out = np.zeros(len(d), bool)
    if not len(found):
        return out
    if any(p.block.kind == "newton" for p in block_plans(batch.model.system)[:i]):
        out[found[:, 0]] = True
        return out
    v, lo, hi = found.T
    a, b = grid.t[lo], grid.t[hi]
    mech = batch.model.mechanism
    _, XD, _ = _inputs(batch.model, d.take(v), (0.5 * (a + b))[:, None])
    eta = eta_of_rates(XD[:, 0, :], input_units(mech, batch.scale), b - a)
    cannot = np.zeros(len(v), bool)  # a bracket where a block cannot close at some probe: a limit between samples

    def probe_h(which: np.ndarray, times: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        h, solvable = _probe_dyads(batch, d.take(v[which]), times, i)
        cannot[which[~solvable]] = True
        return h, solvable

    _, h_min = locate_minima(probe_h, a, b, eta, batch.scale)  # every bracket of every variant zoomed at once
    with np.errstate(invalid="ignore"):
        meets = ~(2.0 * np.sqrt(h_min) > CHANGE_GAP * batch.scale)  # a change point (or a limit): the single run's
    out[v[meets | cannot]] = True
    return out


def _probe_dyads(batch: _Batch, d: Designs, times: np.ndarray, upto: int) -> tuple[np.ndarray, np.ndarray]:
    """Block ``upto``'s discriminants at ``times`` (one row of times per design: (designs, times)), the blocks
    0..upto solved there in closed form; and whether every one of them closes at every time."""
    model = batch.model
    system = model.system
    C, p = times.shape
    probes = _constants(system, d, p)
    state = State(p, system.n_angles, len(system.slider_names), C)
    _impose(batch, state, d, times, checked=False)
    ok = np.ones(C * p, bool)
    for plan in block_plans(probes)[: upto + 1]:
        closes, h = closed_form(plan, state, slice(0, C * p), np.full(C * p, plan.block.sigma))
        ok &= closes
    return h.reshape(C, p), ok.reshape(C, p).all(axis=1)


def _newton_block(
    batch: _Batch, state: State, d: Designs, grid: Grid, i: int, flags: _Flags, runs: dict[int, Run]
) -> None:
    """A Newton block, variant by variant: the single run's continuation over its samples (row 0 assembled),
    on its own constants; a variant whose continuation fails, or that reaches a doubtful sample, is doubtful."""
    n, na = state.samples, batch.model.system.n_angles
    for v in np.nonzero(flags.regular)[0].tolist():
        run = runs.setdefault(v, batch.variant_run(d, v))
        plan = block_plans(run.system)[i]
        own = state.rows(slice(v * n, (v + 1) * n))
        failure, factor = newton.solve_block(run, own, grid.t, i, plan, n)
        expected = run.newton_sign[i] * plan.block.sigma
        if (
            failure is not None
            or np.any(velocity_bound(factor.cond) > SURE * batch.rtol)
            or np.any(factor.sign != expected)
        ):
            flags.doubt(np.arange(len(d)) == v)
            continue
        flags.cond[v] = max(flags.cond[v], float(np.max(factor.cond[grid.out])))
        rows = slice(0, n)
        for what in ("v", "a"):
            store_rates(plan, own, rows, newton.factor_rates(plan, own, rows, factor.inv, what), what, na)


# ---------------------------------------------------------------- the t = 0 assembly of Newton blocks


def _assemble_newton(batch: _Batch, d: Designs, flags: _Flags) -> np.ndarray:
    """The t = 0 values of every variable: for the Newton blocks' unknowns, continued from the nominal assembly
    to each variant in ASSEMBLY_STEPS steps (term vectors and driver numbers blended), on the nominal branch
    throughout; closed forms need none (their branch σ defines them): the starting guess of the coordinates."""
    if not batch.newton_sign:
        return d.q_start
    system = batch.model.system
    newton_vars = _newton_variables(system)
    nominal = _nominal(batch.model)
    current = np.broadcast_to(system.q0, d.q_start.shape).copy()
    for step in range(1, ASSEMBLY_STEPS + 1):
        blended = d if step == ASSEMBLY_STEPS else nominal.blend(d, step / ASSEMBLY_STEPS)
        current = _assemble_at(batch, blended, np.where(newton_vars, current, d.q_start), flags)
    return np.where(newton_vars, current, d.q_start)


def _newton_variables(system: LoopSystem) -> np.ndarray:
    """Which variables Newton blocks solve for."""
    out = np.zeros(system.n_vars, bool)
    for plan in block_plans(system):
        if plan.block.kind == "newton":
            out[list(plan.block.unknowns)] = True
    return out


def _assemble_at(batch: _Batch, d: Designs, start: np.ndarray, flags: _Flags) -> np.ndarray:
    """Every block at t = 0 for every assembled variant of ``d`` (Newton from ``start``, refused where it does not
    converge, close or keep the nominal branch); the variables there (variants, n_vars)."""
    system = batch.model.system
    V, na = len(d), system.n_angles
    state = State(1, na, len(system.slider_names), V)
    _impose(batch, state, d, np.zeros(1), checked=False)
    _put_variables(state, system, start, drivers=False)
    for i, plan in enumerate(block_plans(_constants(system, d, 1))):
        where = _where(system, plan)
        if plan.block.kind != "newton":
            ok, _ = closed_form(plan, state, slice(0, V), np.full(V, plan.block.sigma))
            flags.refuse(~ok, f"cannot assemble at t = 0: {where} cannot close (its links cannot reach)")
            continue
        block = newton.NewtonBlock(plan, na, batch.scale)
        rows = np.nonzero(flags.assembled)[0]
        unknowns = list(plan.block.unknowns)
        _, converged = newton.newton(block, state, rows, start[rows][:, unknowns], batch.tol, batch.max_iter)
        F, J = block.residual_jacobian(state, rows)
        with np.errstate(invalid="ignore"):
            closes = np.max(np.abs(F), axis=1) / batch.scale <= newton.CLOSURE
        bad = np.zeros(V, bool)
        bad[rows] = ~(converged & closes & (det_sign(J) == batch.newton_sign[i]))
        flags.refuse(
            bad,
            f"cannot assemble at t = 0 on the nominal branch: Newton on {where} does not converge there from the "
            "nominal design, or lands on another branch",
        )
    return np.concatenate([state.theta, state.s[:, :-1]], axis=1)


# ---------------------------------------------------------------- outputs


def columns(system: LoopSystem, state: State, d: Designs, rows: np.ndarray, names: list[str]) -> dict[str, np.ndarray]:
    """The Result columns ``names`` (``LINK.theta``, ``POINT.ax``, ``SLIDER.v`` ...) at each variant's internal
    ``rows``, (variants, len(rows)); ``system``: the per-row constants of ``d``."""
    V, n = state.variants, state.samples
    rows = np.asarray(rows)
    every = len(rows) == n and np.array_equal(rows, np.arange(n))  # every row: read as views, not gathered
    k = slice(0, V * n) if every else (np.arange(V)[:, None] * n + rows[None, :]).reshape(-1)
    links = {name: (a, j) for j, (name, a, _) in enumerate(system.link_outputs)}
    points: dict[str, np.ndarray] = {}
    out: dict[str, np.ndarray] = {}
    for col in names:
        ent, fld = col.rsplit(".", 1)
        if ent in links and fld in ("theta", "omega", "alpha"):
            a, j = links[ent]
            if a < 0:
                val = (d.out_offset[:, j, None] % TWO_PI) if fld == "theta" else np.zeros((V, 1))
                out[col] = np.broadcast_to(val, (V, len(rows))).copy()
            else:
                arr = {"theta": state.theta, "omega": state.omega, "alpha": state.alpha}[fld][k, a].reshape(V, -1)
                out[col] = arr + d.out_offset[:, j, None] if fld == "theta" else arr
        elif ent in system.slider_names and fld in ("s", "v", "a"):
            i = system.slider_names.index(ent)
            out[col] = {"s": state.s, "v": state.s_dot, "a": state.s_ddot}[fld][k, i].reshape(V, -1)
        else:
            what = {"x": "p", "y": "p", "vx": "v", "vy": "v", "ax": "a", "ay": "a"}[fld]
            if what not in points:
                points[what] = system_sums(system)[0].by_column(state, k, what)
            z = points[what][system.point_names.index(ent)].reshape(V, -1)
            out[col] = z.imag.copy() if fld.endswith("y") else z.real.copy()
    return out


def column_names(system: LoopSystem) -> list[str]:
    """Every Result column a solve of this system gives."""
    cols = [f"{name}.{f}" for name, _, _ in system.link_outputs for f in ("theta", "omega", "alpha")]
    cols += [f"{p}.{f}" for p in system.point_names for f in ("x", "y", "vx", "vy", "ax", "ay")]
    cols += [f"{s}.{f}" for s in system.slider_names for f in ("s", "v", "a")]
    return cols


@dataclass
class Outcomes:
    """Per variant: whether it assembled, whether the motion completed, where it stopped and why, the worst
    condition number, which solver gave it ("batch" or "single"), and its t = 0 joint positions and variables."""

    assembled: np.ndarray
    completed: np.ndarray
    stopped_at: np.ndarray
    stopped_sample: np.ndarray
    reason: list[str]
    max_cond: np.ndarray
    solver: list[str]
    positions: np.ndarray  # (V, n_points) complex, t = 0
    q0: np.ndarray  # (V, n_vars): the assembled variables at t = 0 (NaN where not assembled)

    @classmethod
    def empty(cls, n: int, n_points: int, n_vars: int) -> Self:
        """n variants that did not assemble (a subclass's other fields at their defaults)."""
        return cls(
            np.zeros(n, bool),
            np.zeros(n, bool),
            np.full(n, np.nan),
            np.full(n, -1, np.int64),
            [""] * n,
            np.full(n, np.nan),
            [""] * n,
            np.full((n, n_points), np.nan + 0j),
            np.full((n, n_vars), np.nan),
        )

    def fill(self, rows: np.ndarray, res: Outcomes) -> None:
        """Take ``res``'s variants into the rows where ``rows`` (a mask) is set."""
        idx = np.nonzero(rows)[0]
        for name in ("assembled", "completed", "stopped_at", "stopped_sample", "max_cond", "positions", "q0"):
            getattr(self, name)[idx] = getattr(res, name)
        for k, i in enumerate(idx):
            self.reason[i], self.solver[i] = res.reason[k], res.solver[k]

    @classmethod
    def join(cls, parts: list[Outcomes]) -> Outcomes:
        return cls(
            *(
                [x for p in parts for x in getattr(p, f.name)]
                if f.name in ("reason", "solver")
                else np.concatenate([getattr(p, f.name) for p in parts])
                for f in dataclasses.fields(Outcomes)
            )
        )


@dataclass
class BatchOut(Outcomes):
    """What a batch gives for V variants: the Outcomes and the columns (V, n requested samples), NaN where a
    variant has no motion."""

    columns: dict[str, np.ndarray] = field(default_factory=dict)


def solve(
    model: VariantModel, values: np.ndarray, grid: Grid, names: list[str], *, doubtful: str = "single"
) -> BatchOut:
    """Solve the variants whose parameter values are the rows of ``values`` (variants, parameters) on ``grid``;
    columns ``names`` (``LINK.theta``, ``POINT.x``, ``SLIDER.v`` …) at the grid's requested times, (variants,
    samples), NaN where a variant has no motion; and each variant's status (:class:`Outcomes`).

    ``doubtful``: what happens to a variant the batch is not sure of (module notes): "single" (the default)
    solves it again with the single-run solver, which locates its limits and change points; "fail" reports it
    as not completed (reason :data:`DOUBTFUL`, columns NaN) without solving it again — for a search that only
    wants the variants the batch takes as they are (a synthesis scoring a random population, where many
    variants reach limits and each single run would cost more than the whole batch)."""
    if doubtful not in ("single", "fail"):
        raise ValueError(f"doubtful must be 'single' or 'fail', got {doubtful!r}")
    batch = _Batch.build(model)
    values = np.atleast_2d(np.asarray(values, float))
    V = len(values)
    system = model.system
    out = BatchOut.empty(V, len(system.point_names), system.n_vars)
    out.columns = {c: np.full((V, len(grid.out)), np.nan) for c in names}
    per = max(1, ROWS // max(len(grid.t), 1))
    for lo in range(0, V, per):
        with np.errstate(all="ignore"):
            _solve_chunk(batch, values[lo : lo + per], grid, names, out, lo, doubtful == "single")
    return out


def solve_variants(
    system: LoopSystem,
    parameters: Sequence[str],
    values: Any,
    columns: Sequence[str],
    times: Any = None,
    *,
    doubtful: str = "single",
) -> BatchOut:
    """Variants of a compiled mechanism (``vloop.compile(mech)``) that differ in the numbers ``parameters`` names
    (``links.l3.length``, ``joints.B.x``, ``drivers.l2.omega`` …: :mod:`vloop.core.variants`), one row of
    ``values`` each, solved together at ``times`` [s] (default: the file's): the ``columns`` asked (variants,
    samples) and each variant's status. ``doubtful`` as :func:`solve`. A caller that solves the same parameters
    again and again (a search) builds the :class:`VariantModel` once and calls :func:`make_grid` and
    :func:`solve` itself."""
    mech = system.mechanism
    model = VariantModel.build(mech, system, tuple(resolve(mech, name, name) for name in parameters))
    values = np.atleast_2d(np.asarray(values, float))
    times = np.asarray(mech.times if times is None else times, float)
    return solve(model, values, make_grid(model, model.designs(values), times), list(columns), doubtful=doubtful)


def _solve_chunk(
    batch: _Batch, values: np.ndarray, grid: Grid, names: list[str], out: BatchOut, lo: int, resolve: bool
) -> None:
    """Variants lo, lo + 1, … (the rows of ``values``) into ``out``: the batch's numbers, the doubtful ones
    solved again on their own where ``resolve``."""
    model, system = batch.model, batch.model.system
    d = model.designs(values)
    V, n = len(d), len(grid.t)
    flags = _Flags.new(V)
    start = _assemble_newton(batch, d, flags)
    state = State(n, system.n_angles, len(system.slider_names), V)
    flags.doubt(_impose(batch, state, d, grid.t))
    _put_variables(state, system, start, drivers=False)
    constants = _constants(system, d, n)
    _solve_blocks(batch, constants, state, d, grid, flags)
    cols = columns(constants, state, d, grid.out, names)
    for arr in cols.values():
        flags.doubt(~np.all(np.isfinite(arr), axis=1))
    positions = columns(constants, state, d, np.zeros(1, int), [f"{p}.{f}" for p in system.point_names for f in "xy"])
    pos = np.stack([positions[f"{p}.x"][:, 0] + 1j * positions[f"{p}.y"][:, 0] for p in system.point_names], 1) \
        if system.point_names else np.zeros((V, 0), complex)  # fmt: skip
    q0 = np.concatenate([state.per_variant("theta")[:, 0], state.per_variant("s")[:, 0, :-1]], axis=1)
    q0 = np.where(_newton_variables(system), start, q0)  # the assembly the Newton blocks continued from
    _record(out, slice(lo, lo + V), flags, cols, pos, q0)
    for v in range(V):
        if flags.regular[v] or not flags.assembled[v]:
            continue
        if resolve:
            _single(model, values[v], d.take(slice(v, v + 1)), q0[v], pos[v], grid, names, out, lo + v)
        else:
            out.reason[lo + v] = DOUBTFUL


def _record(out: BatchOut, rows: slice, flags: _Flags, cols: dict, pos: np.ndarray, q0: np.ndarray) -> None:
    """A chunk's variants into ``out``: the columns of those the batch took, every one's status."""
    ok = flags.regular
    for c, arr in cols.items():
        out.columns[c][rows][ok] = arr[ok]
    out.assembled[rows] = flags.assembled
    out.completed[rows] = ok
    out.max_cond[rows] = np.where(ok, flags.cond, np.nan)
    out.positions[rows] = np.where(flags.assembled[:, None], pos, np.nan)
    out.q0[rows] = np.where(flags.assembled[:, None], q0, np.nan)
    for v, i in enumerate(range(rows.start, rows.stop)):
        if ok[v]:
            out.solver[i] = "batch"
        elif not flags.assembled[v]:
            out.reason[i] = flags.why[v]


def variant_system(
    model: VariantModel, values: np.ndarray, d: Designs, q0: np.ndarray, positions: np.ndarray
) -> tuple[Mechanism, LoopSystem]:
    """The variant's own Mechanism (coordinates at its t = 0 assembly) and LoopSystem (the nominal structure
    with its constants), as ``vloop.compile`` of that variant's file would give them."""
    nominal = model.system
    mech = model.variant_mechanism(values, dict(zip(nominal.point_names, positions.tolist(), strict=True)), q0)
    outputs = tuple((name, a, float(d.out_offset[0, j])) for j, (name, a, _) in enumerate(nominal.link_outputs))
    system = dataclasses.replace(
        nominal,
        mechanism=mech,
        t_r=d.r[0].copy(),
        t_delta=d.delta[0].copy(),
        q0=np.asarray(q0, float),
        coords_q=d.coords_q[0].copy(),
        link_outputs=outputs,
        cache={},
    )
    return mech, system


def _single(
    model: VariantModel,
    values: np.ndarray,
    d: Designs,
    q0: np.ndarray,
    pos: np.ndarray,
    grid: Grid,
    names: list[str],
    out: BatchOut,
    v: int,
) -> None:
    """Solve one variant with the single-run solver; record its columns or where and why it stopped."""

    out.solver[v] = "single"
    try:
        _, system = variant_system(model, values, d, q0, pos)
        res = solve_system(system, grid.times)
    except MotionError as exc:
        out.reason[v] = str(exc)
        t_stop = getattr(exc, "limit_time", None)
        out.stopped_at[v] = t_stop if t_stop is not None else (exc.time if exc.time is not None else np.nan)
        out.stopped_sample[v] = exc.sample if exc.sample is not None else 0
        return
    except VloopError as exc:
        out.reason[v] = str(exc)
        out.stopped_sample[v] = 0
        return
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:  # numbers no solver can work with
        out.reason[v] = f"{model.mechanism.name}: this variant cannot be solved ({type(exc).__name__}: {exc})"
        out.stopped_sample[v] = 0
        return
    for c in names:
        out.columns[c][v] = res.columns[c]
    out.completed[v] = True
    out.max_cond[v] = float(np.max(res.health["cond"])) if len(res.health.get("cond", ())) else np.nan
