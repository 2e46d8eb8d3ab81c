"""A chunk's solved rows as a Result: the named columns, the health columns, the change points passed, and
the MotionError that says where and why a run stops."""

from __future__ import annotations

from typing import Any

import numpy as np

from ..errors import MotionError
from ..method.assembly import redundancy_text
from ..method.loops import LoopSystem
from ..result import Result
from .accuracy import ILL_FRACTION, error_bound
from .context import Failure, Run, Solved
from .data import TWO_PI, State
from .grid import Grid
from .plans import block_plans, system_sums
from .sums import Sum


def chunk_result(run: Run, state: State, grid: Grid, n_ok: int, solved: Solved) -> tuple[Result, list[np.ndarray]]:
    """The Result of a chunk's solved rows, and the arrays its columns are taken from (to check finiteness)."""
    system = run.system
    mech = system.mechanism
    rows = grid.out[grid.skip :][grid.out[grid.skip :] < n_ok]  # the requested samples solved
    points, loops = system_sums(system)
    k = _as_slice(rows)
    P, V, A = (points.by_column(state, k, what) for what in ("p", "v", "a"))  # (points, rows) each
    cols: dict[str, np.ndarray] = {}

    def column(state: np.ndarray, j: int) -> np.ndarray:  # a state column's rows, as an array of its own
        return state[k, j].copy() if isinstance(k, slice) and run.sink is None else state[k, j]

    for name, a, offset in system.link_outputs:
        if a >= 0:
            cols[f"{name}.theta"] = state.theta[k, a] + offset
            cols[f"{name}.omega"] = column(state.omega, a)
            cols[f"{name}.alpha"] = column(state.alpha, a)
        else:
            cols[f"{name}.theta"] = np.full(len(rows), offset % TWO_PI)
            cols[f"{name}.omega"] = np.zeros(len(rows))
            cols[f"{name}.alpha"] = np.zeros(len(rows))
    for i, name in enumerate(system.point_names):
        cols[f"{name}.x"], cols[f"{name}.y"] = P[i].real, P[i].imag
        cols[f"{name}.vx"], cols[f"{name}.vy"] = V[i].real, V[i].imag
        cols[f"{name}.ax"], cols[f"{name}.ay"] = A[i].real, A[i].imag
    for i, name in enumerate(system.slider_names):
        cols[f"{name}.s"], cols[f"{name}.v"], cols[f"{name}.a"] = (
            column(q, i) for q in (state.s, state.s_dot, state.s_ddot)
        )
    if run.sink is not None:  # (the sink copies each column once: a state column is given as a view)
        cols = {name: run.sink.put(name, grid.offset + grid.skip, v) for name, v in cols.items()}
    sources = [P, V, A, *(getattr(state, name)[k] for name in ("theta", "omega", "alpha", "s", "s_dot", "s_ddot"))]
    t = grid.t[rows]
    seen = grid.t[grid.out[: grid.skip + len(rows)]]  # requested times solved in this chunk and the one before
    span = np.array([run.t_start, seen[-1]]) if len(seen) else np.zeros(0)
    return Result(
        mech.name,
        "vloop",
        t,
        cols,
        _health(run, state, grid.t[grid.out[: grid.skip + len(rows)]], rows, solved, loops),
        {
            "blocks": [b.kind for b in system.blocks],
            "assembly": system.assembly,
            "units": mech.units,  # the lengths' unit (Result.to_pandas)
            **_events_meta(run, span),
            **_redundancy(system),
        },
    ), sources


def _as_slice(rows: np.ndarray) -> slice | np.ndarray:
    """Consecutive rows as a slice (state arrays are then read as views, not copied)."""
    if len(rows) and int(rows[-1]) - int(rows[0]) + 1 == len(rows):
        return slice(int(rows[0]), int(rows[-1]) + 1)
    return rows


def _health(run: Run, state: State, t: np.ndarray, rows: np.ndarray, solved: Solved, loops: Sum) -> dict:
    """Per requested sample (``rows``): closure residual, worst block condition number, branch signature,
    flags. ``t``: the times of the rows, after the last sample of the chunk before if there is one."""
    system = run.system
    k = _as_slice(rows)
    residual = np.zeros(len(rows))
    if len(system.loops):
        F = loops.by_column(state, k, "p").view(float) * (1.0 / run.scale)  # in sizes: the squares cannot overflow
        np.sqrt(np.max(F[:, 0::2] * F[:, 0::2] + F[:, 1::2] * F[:, 1::2], axis=0), out=residual)
    cond = np.ones(len(rows))
    if solved.conds:
        cond = solved.conds[0][k].copy()
        for c in solved.conds[1:]:
            np.maximum(cond, c[k], out=cond)
    branch = np.zeros(len(rows), np.int64)
    for bit, branch_sign in enumerate(solved.signs):
        branch |= (branch_sign[k] > 0).astype(np.int64) << bit
    at_change = solved.at_change[k] if len(solved.at_change) else np.zeros(len(rows), bool)
    change = at_change.astype(np.int8)
    skip = len(t) - len(rows)  # t starts with the chunk before's last sample, if any
    for evs in run.events.values():
        for ev in evs:
            j = int(np.searchsorted(t, ev.time))
            if 0 < j < len(t) and j >= skip:
                change[j - skip] = 1
    ill = error_bound(cond) > ILL_FRACTION * run.rtol
    ill &= ~at_change
    return {
        "residual": residual,
        "cond": cond,
        "branch": branch,
        "ill_conditioned": ill.astype(np.int8),
        "change_point": change,
    }


def _redundancy(system: LoopSystem) -> dict[str, str]:
    """For a redundant linkage, the line that says so (its reactions are indeterminate)."""
    info = system.assembly.get("redundancy")
    return {"redundancy": redundancy_text(info, system)} if info else {}


def _events_meta(run: Run, t: np.ndarray) -> dict[str, Any]:
    """The change points passed within the requested times (loop, time, inputs, which continuation)."""
    system = run.system
    out = []
    for i, evs in sorted(run.events.items()):
        loop = system.loops[block_plans(system)[i].block.loops[0]]
        for ev in evs:
            if not len(t) or not t[0] <= ev.time <= t[-1]:
                continue
            x = run.inputs(np.array([ev.time]))[0][0]
            out.append(
                {
                    "loop": loop.index + 1,
                    "label": loop.label,
                    "time": ev.time,
                    "inputs": {d.symbol: float(v) for d, v in zip(system.mechanism.drivers, x, strict=True)},
                    "continued": "smooth" if ev.smooth else "other",
                    "kind": ev.kind,
                }
            )
    return {"change_points": sorted(out, key=lambda e: e["time"]), "rtol": run.rtol}


def motion_error(
    system: LoopSystem,
    f: Failure,
    grid: Grid,
    X: np.ndarray,
    partial: Result,
    limit: tuple[float, np.ndarray] | None = None,
) -> MotionError:
    """The MotionError for failure ``f`` at internal row f.sample; ``sample`` is the first requested one lost."""
    mech = system.mechanism
    t, x = (float(grid.t[f.sample]), X[f.sample]) if f.at is None else f.at
    n_req = grid.total or len(grid.out)
    j = grid.requested_before(f.sample)
    jg = j + grid.offset  # in the whole run
    drv = ", ".join(d.value_text(x[i], mech.units, 6) for i, d in enumerate(mech.drivers))
    if f.sample < grid.first:
        where = "before the first requested time (on the way from the t = 0 assembly)"
    elif j < len(grid.out) and grid.out[j] == f.sample and f.at is None:
        where = f"at t = {t:.6g} s (sample {jg} of {n_req})"
    else:
        where = f"at t = {t:.6g} s (between samples {jg - 1} and {jg} of {n_req})"
    kept = f"{jg} earlier sample{'s' if jg != 1 else ''} kept" if jg else "no sample kept"
    lim = ""
    if limit is not None:
        vals = ", ".join(d.value_text(limit[1][i], mech.units) for i, d in enumerate(mech.drivers))
        lim = f" (last assembled at t = {limit[0]:.10g} s, {vals})"
    at = f": loop {f.loop + 1} ({system.loops[f.loop].label})" if f.loop is not None else ""
    err = MotionError(
        f"{mech.name}: cannot assemble {where}, {drv}{at}: {f.why}{lim}; {kept}",
        entry=f"loop {f.loop + 1}" if f.loop is not None else "drivers",
        time=t if f.sample >= grid.first else None,
        sample=jg if f.sample >= grid.first else None,
        driver_value=x.tolist() if len(X) else None,
        partial=partial,
    )
    err.limit_time = limit[0] if limit is not None else None
    err.limit_value = limit[1].tolist() if limit is not None else None
    return err


def first_non_finite(result: Result) -> tuple[int, str] | None:
    """(row, column) of the first non-finite output value, if any (searched column by column only where a sum
    over the arrays the columns come from is not finite: a NaN or ±∞ anywhere makes it so)."""
    first = None
    for name, col in result.columns.items():
        bad = ~np.isfinite(col)
        if bad.any():
            r = int(np.argmax(bad))
            if first is None or r < first[0]:
                first = (r, name)
    return first
