"""Design studies: grids and Monte-Carlo tolerance analysis over thousands of variants, with sensitivities.

    res = vloop.study("mechanisms/fourbar_textbook_example.toml",
                      [{"name": "links.l3.length", "tolerance": {"dist": "uniform", "half_width": 0.05}},
                       {"name": "links.l4.length", "tolerance": {"dist": "normal", "sigma": 0.02}}],
                      ["l4.theta.range", "l4.alpha.peak", "transmission_angle.min", "l4.theta.series"],
                      samples=10_000, seed=1)
    res.table                  # one row per variant: parameter values, outputs, assembled, stopped_at, reason
    res.summary                # per output: nominal, linearized σ, Monte-Carlo mean, σ ± its error, percentiles
    res.sensitivity            # d(output)/d(parameter) at the nominal design(s), central differences
    res.bands                  # series outputs over the motion: nominal, linearized σ, Monte-Carlo percentiles

**Variants.** A parameter is a number of the mechanism file (:mod:`vloop.core.variants`): grid values (the
study takes every combination, the first parameter slowest) and/or a tolerance (``samples`` Monte-Carlo
draws, uniform in ±half_width or normal with σ, drawn up front from ``seed``; every grid point gets the
same draws). All variants share the nominal structure and are solved together (:mod:`vloop.core.batch`); a
variant that does not assemble at t = 0 on the nominal branch, or whose motion stops, is reported in its
row (``assembled``, ``completed``, ``stopped_at`` [s], ``stopped_sample``, ``reason``) with null outputs,
and the others go on.

**Outputs.** A quantity (a Result column ``l4.theta``, ``B.ay``, ``s1.v``; ``B.speed`` = |v|,
``B.acceleration`` = |a|; ``transmission_angle`` — the smallest folded transmission angle over the
dyads at each sample, :mod:`vloop.teaching`, or ``transmission_angle.JOINT`` for one dyad; ``B.path`` —
the point's path as two list columns; ``grashof`` — the class of the first four-bar loop, or
``grashof.N`` of loop N, with a boolean ``.is_grashof`` (s + l ≤ p + q)) and a stat over the requested
samples (range, min, max, peak = max |x|, mean, rms, start, end, or series = the whole history as a list).

**Sensitivity.** d(output)/d(parameter) by central differences over extra variants solved in the same
batch (step 6e-6 of the parameter's size: truncation and round-off both near 1e-10 of the output), at the
nominal design — the file's, or each grid point of a tolerance study (``sensitivity = "nominal"``), at
every variant (``"each"``: columns ``d(OUTPUT)/d(PARAMETER)``) or nowhere. The linearized standard
deviation of an output is √Σ (∂y/∂p·σ_p)² over the toleranced parameters (σ = half_width/√3 for uniform);
beside it the Monte-Carlo one with its sampling error √((κ − 1)/(4n))·σ (κ: the sample's kurtosis).

**Scale-out.** Variants are split into chunks run by :func:`vloop.runner.run_tasks`: in this process, on
a local Dask cluster (``workers``) or a scheduler (``scheduler``). Every random value is drawn up front
and the internal time grid is shared, and the batch never mixes variants in one arithmetic operation, so
the chunking — and the machine that runs a chunk — never changes a number.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..core import batch
from ..core.batch import Outcomes
from ..core.variants import ParamRef, VariantModel, resolve
from ..errors import MechanismError, VloopError
from ..files.schema import Problems
from ..files.writers import finite_or_null
from ..method.equations import grashof_class
from ..model import Mechanism
from ..result import Result, html_table
from .studyfile import OutputSpec, StudySpec, from_dict, output_unit, quantity_kind

TASKS_PER_WORKER = 4  # chunks per Dask worker thread when the chunk size is automatic
LOCAL_CHUNK = 2048  # variants per task in this process (progress granularity; never changes a number)
PERCENTILES = (2.5, 50.0, 97.5)


# ---------------------------------------------------------------- the public entry point


def study(
    mechanism: Mechanism | str | Path,
    params: Any,
    outputs: Any,
    *,
    times: Any = None,
    samples: int | None = None,
    seed: int = 0,
    sensitivity: str = "nominal",
    chunk: int | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool | None = None,
    memory_budget: Any = None,
) -> StudyResult:
    """Solve every variant of ``mechanism`` the parameters describe and report ``outputs`` per variant.

    ``params``: a list of parameter tables as in a study file (``{"name": "links.l3.length", "values": [...]}``,
    ``start/stop/num``, ``tolerance = {"dist": "uniform", "half_width": ...}``) or a dict name → values or
    table. ``outputs``: quantities with an optional stat, as strings (``"l4.theta.range"``) or tables.
    ``times`` [s] (default: the file's); ``samples`` Monte-Carlo draws from ``seed``; ``sensitivity``
    "nominal" | "each" | "none"; ``chunk`` variants per task; ``scheduler`` / ``workers`` run the chunks on
    Dask; ``memory_budget`` (bytes or "2G", as :func:`vloop.solve`) refuses a study that would not fit before it is
    built. Lengths in the file's units, angles in rad. Raises MechanismError for a bad parameter or output.
    """
    if not isinstance(mechanism, Mechanism):
        from .. import load  # (assembled at t = 0 if written from dimensions)

        mechanism = load(mechanism)
    data: dict[str, Any] = {"parameters": _param_tables(params), "outputs": _output_tables(outputs)}
    for key, val in (("samples", samples), ("chunk", chunk)):
        if val is not None:
            data[key] = val
    data["seed"], data["sensitivity"] = seed, sensitivity
    spec = from_dict(data, mechanism, source="vloop.study")
    if times is not None:
        spec = dataclasses.replace(spec, times=_check_times(times))
    from ..files.options import OPTIONS  # the command line's parsers: one check for --workers and workers=

    scheduler = OPTIONS["scheduler"].parse(scheduler) if scheduler is not None else None
    workers = OPTIONS["workers"].parse(workers) if workers is not None else None
    return run(spec, scheduler=scheduler, workers=workers, progress=progress, memory_budget=memory_budget)


def _param_tables(params: Any) -> list:
    if isinstance(params, dict):
        return [
            {"name": k, **(v if isinstance(v, dict) else {"values": list(np.atleast_1d(v))})} for k, v in params.items()
        ]
    return [dict(p) if isinstance(p, dict) else p for p in params] if isinstance(params, list | tuple) else params


def _output_tables(outputs: Any) -> list:
    return [outputs] if isinstance(outputs, str) else list(outputs) if isinstance(outputs, list | tuple) else outputs


def _check_times(times: Any) -> np.ndarray:
    try:
        t = np.asarray(times, float)
    except (TypeError, ValueError, OverflowError):
        raise MechanismError("times must be a 1-D array of numbers [s]", entry="time") from None
    if t.ndim != 1 or not len(t) or not np.all(np.isfinite(t)) or np.any(np.diff(t) <= 0):
        raise MechanismError("times must be a non-empty, finite, strictly increasing 1-D array [s]", entry="time")
    return t


# ---------------------------------------------------------------- the plan: every design to solve


@dataclass
class _Plan:
    """Every design the study solves, as rows of parameter values, and what each row is for."""

    refs: tuple[ParamRef, ...]
    values: np.ndarray  # (n_designs, P)
    n_variants: int  # the table's rows are the first n_variants designs
    grid_index: np.ndarray | None  # base of each variant (grid studies)
    draw_index: np.ndarray | None  # draw of each variant (tolerance studies)
    base_rows: np.ndarray  # design row of each base (a grid point, or the nominal)
    sens_at: np.ndarray  # design rows the sensitivity is taken at
    sens_rows: np.ndarray  # (len(sens_at), P, 2): rows of the +h and −h designs
    steps: np.ndarray  # (P,) central-difference steps
    sigma: np.ndarray  # (P,) standard deviation of each parameter's tolerance (0: exact)
    invalid: dict[int, str] = field(default_factory=dict)  # designs refused before solving


def design_count(spec: StudySpec) -> tuple[int, int]:
    """(variants, designs) of a study from its sizes alone — the rows :func:`plan` builds (variants, the bases of a
    tolerance study, the nominal of a grid study's sensitivity, two neighbours per parameter and sensitivity point)."""
    P = len(spec.parameters)
    grid = math.prod(len(p.values) for p in spec.parameters if p.values is not None)
    draws = spec.samples or 0
    variants = grid * draws if draws else grid
    bases = grid if draws else 0
    if spec.sensitivity == "none" or not P:
        points, nominal = 0, 0
    elif spec.sensitivity == "each":
        points, nominal = variants + bases, 0
    else:
        points, nominal = (grid, 0) if draws else (1, 1)
    return variants, variants + bases + nominal + 2 * P * points


def references(spec: StudySpec) -> tuple[ParamRef, ...]:
    """The file's number each parameter names."""
    return tuple(resolve(spec.mechanism, p.name, f"parameters[{i}]") for i, p in enumerate(spec.parameters))


def plan(spec: StudySpec, refs: tuple[ParamRef, ...] | None = None) -> _Plan:
    """The designs of a study: variants (grid × draws), bases, and the central-difference neighbours."""
    refs = references(spec) if refs is None else refs
    nominal = np.array([r.nominal for r in refs], float)
    bases = _bases(spec, nominal)
    draws = _draws(spec, refs)
    if draws is not None:
        B, D = len(bases), len(draws)
        with np.errstate(over="ignore", invalid="ignore"):
            variants = np.repeat(bases, D, axis=0) + np.tile(draws, (B, 1))
        grid_index = np.repeat(np.arange(B), D) if any(p.values for p in spec.parameters) else None
        draw_index = np.tile(np.arange(D), B)
    else:
        variants, grid_index, draw_index = bases, (np.arange(len(bases)) if len(bases) > 1 else None), None
    _check_finite(spec, refs, variants)
    rows = [variants]
    n = len(variants)
    if draws is not None:
        base_rows = np.arange(n, n + len(bases))
        rows.append(bases)
        n += len(bases)
    else:
        base_rows = np.arange(len(bases))
    sens_at = _sensitivity_points(spec, draws is not None, base_rows, len(variants))
    if spec.sensitivity == "nominal" and draws is None and spec.parameters and not len(sens_at):
        rows.append(nominal[None, :])  # a grid study's sensitivity: at the file's design
        sens_at = np.array([n])
        n += 1
    designs = np.concatenate(rows, axis=0)
    steps = np.array([r.fd_step() for r in refs])
    P = len(refs)
    plus = designs[sens_at][:, None, :] + np.diag(steps)[None, :, :]
    minus = designs[sens_at][:, None, :] - np.diag(steps)[None, :, :]
    sens_rows = n + np.arange(2 * P * len(sens_at)).reshape(len(sens_at), P, 2)
    pairs = np.stack([plus, minus], axis=2).reshape(-1, P)
    designs = np.concatenate([designs, pairs], axis=0)
    sigma = np.array([p.tolerance.sigma if p.tolerance else 0.0 for p in spec.parameters])
    out = _Plan(refs, designs, len(variants), grid_index, draw_index, base_rows, sens_at, sens_rows, steps, sigma)
    out.invalid = _invalid(refs, designs)
    return out


def _bases(spec: StudySpec, nominal: np.ndarray) -> np.ndarray:
    """Every combination of the grid values (the first parameter slowest), the others at their nominal."""
    grids = [(i, np.asarray(p.values, float)) for i, p in enumerate(spec.parameters) if p.values is not None]
    if not grids:
        return nominal[None, :].copy()
    total = math.prod(len(v) for _, v in grids)
    out = np.tile(nominal, (total, 1))
    inner = total
    for i, v in grids:
        inner //= len(v)  # each value repeats once per combination of the later parameters
        out[:, i] = np.tile(np.repeat(v, inner), total // (len(v) * inner))
    return out


def _draws(spec: StudySpec, refs: tuple[ParamRef, ...]) -> np.ndarray | None:
    """The Monte-Carlo deviations (samples, P), drawn up front from the seed in parameter order."""
    if not spec.samples:
        return None
    rng = np.random.default_rng(spec.seed)
    out = np.zeros((spec.samples, len(refs)))
    for i, p in enumerate(spec.parameters):
        if p.tolerance is None:
            continue
        with np.errstate(over="ignore", invalid="ignore"):
            if p.tolerance.dist == "uniform":
                out[:, i] = rng.uniform(-1.0, 1.0, spec.samples) * p.tolerance.width
            else:
                out[:, i] = rng.standard_normal(spec.samples) * p.tolerance.width
    return out


def _check_finite(spec: StudySpec, refs: tuple[ParamRef, ...], variants: np.ndarray) -> None:
    bad = ~np.all(np.isfinite(variants), axis=0)
    if bad.any():
        i = int(np.argmax(bad))
        raise MechanismError(
            f"{spec.source}: [parameters[{i}]] {refs[i].name}: its values with the tolerance's deviations overflow "
            "(too large for floating-point numbers)",
            entry=f"parameters[{i}]",
        )


def _sensitivity_points(spec: StudySpec, tolerant: bool, base_rows: np.ndarray, n_variants: int) -> np.ndarray:
    if spec.sensitivity == "none" or not spec.parameters:
        return np.zeros(0, int)
    if spec.sensitivity == "each":
        return np.concatenate([np.arange(n_variants), base_rows if tolerant else np.zeros(0, int)])
    return base_rows if tolerant else np.zeros(0, int)


def _invalid(refs: tuple[ParamRef, ...], designs: np.ndarray) -> dict[int, str]:
    """Designs that cannot be a mechanism: a length that is not positive (a tolerance's draw or a step below 0)."""
    out = {}
    for i, r in enumerate(refs):
        if r.positive:
            for row in np.nonzero(~(designs[:, i] > 0))[0]:
                out.setdefault(int(row), f"{r.name} = {designs[row, i]:.6g} is not a positive length")
    return out


# ---------------------------------------------------------------- chunks: the same function in-process or on Dask


@dataclass(frozen=True)
class _Task:
    """One chunk of designs: everything a worker needs (picklable). The compiled model travels with the chunk,
    so every worker solves with the very arrays this process compiled (no recompile, no hash-order doubt)."""

    model: VariantModel
    values: np.ndarray
    invalid: dict[int, str]
    grid: batch.Grid
    outputs: tuple[OutputSpec, ...]


def run_chunk(task: _Task) -> dict[str, Any]:
    """Solve one chunk of designs and reduce each to its outputs (a module-level function: Dask pickles it)."""
    model = task.model
    n = len(task.values)
    ok = np.array([i not in task.invalid for i in range(n)], bool)
    res = batch.solve(model, task.values[ok], task.grid, needed_columns(model, task.outputs))
    out = Outcomes.empty(n, len(model.system.point_names), model.system.n_vars)
    out.fill(ok, res)
    for i, why in task.invalid.items():
        out.reason[i] = why
    full: dict[str, np.ndarray] = {}
    rows = np.nonzero(ok)[0]
    per = max(1, batch.ROWS // max(len(task.grid.times), 1))  # blocks as small as the batch's (see batch.ROWS)
    for lo in range(0, len(rows), per):
        part = {c: v[lo : lo + per] for c, v in res.columns.items()}
        for name, arr in _reduce(model, task.outputs, part, task.grid.times).items():
            if name not in full:
                full[name] = np.full((n, *arr.shape[1:]), np.nan)
            full[name][rows[lo : lo + per]] = arr
    for lo in range(0, n, per):
        for name, arr in _static(model, task.outputs, task.values[lo : lo + per], ok[lo : lo + per]).items():
            if name not in full:
                full[name] = np.empty(n, arr.dtype)
            full[name][lo : lo + per] = arr
    return {"status": out, "values": full}


# ---------------------------------------------------------------- outputs from the columns


def needed_columns(model: VariantModel, outputs: tuple[OutputSpec, ...]) -> list[str]:
    """The Result columns the outputs are computed from."""
    cols: list[str] = []
    for o in outputs:
        kind = quantity_kind(model.mechanism, o.quantity)
        if kind == "column":
            cols.append(o.quantity)
        elif kind == "magnitude":
            p, f = o.quantity.rsplit(".", 1)
            cols += [f"{p}.vx", f"{p}.vy"] if f == "speed" else [f"{p}.ax", f"{p}.ay"]
        elif kind == "path":
            p = o.quantity.rsplit(".", 1)[0]
            cols += [f"{p}.x", f"{p}.y"]
        elif kind == "transmission":
            for d in _dyads(model, o.quantity):
                joints = [d.joint, *(e for e in d.ends if e)]
                cols += [f"{j}.{c}" for j in joints for c in ("x", "y")]
                if d.kind != "RRR":
                    cols.append(f"{d.bodies[1] if d.kind == 'RRP' else d.bodies[0]}.theta")
    return list(dict.fromkeys(cols))


def _dyads(model: VariantModel, quantity: str) -> list:
    """The dyads a transmission-angle quantity covers (all, or the one at the joint it names)."""
    from ..teaching.transmission import dyads

    found, _ = dyads(model.system)
    if quantity != "transmission_angle":
        label = quantity.split(".", 1)[1]
        found = [d for d in found if d.label == label]
    return found


def check_outputs(model: VariantModel, spec: StudySpec) -> None:
    """Outputs the mechanism cannot give: a transmission angle without dyads, a Grashof class without a four-bar."""
    for i, o in enumerate(spec.outputs):
        kind = quantity_kind(model.mechanism, o.quantity)
        if kind == "transmission" and not _dyads(model, o.quantity):
            from ..teaching.transmission import dyads

            labels = ", ".join(d.label for d in dyads(model.system)[0]) or "none: its blocks are solved by Newton"
            raise MechanismError(
                f"{spec.source}: [outputs[{i}]] {o.quantity}: no such dyad (dyads: {labels})", entry=f"outputs[{i}]"
            )
        if kind == "class" and _fourbar_loop(model, o.quantity) is None:
            raise MechanismError(
                f"{spec.source}: [outputs[{i}]] {o.quantity}: no four-bar loop (ground and three pinned links) there",
                entry=f"outputs[{i}]",
            )


def _reduce(
    model: VariantModel, outputs: tuple[OutputSpec, ...], cols: dict[str, np.ndarray], t: np.ndarray
) -> dict[str, np.ndarray]:
    """Each output of each design (NaN where the motion did not complete): scalars (n,), series (n, N)."""
    out: dict[str, np.ndarray] = {}
    for o in outputs:
        kind = quantity_kind(model.mechanism, o.quantity)
        if kind == "class":
            continue
        if kind == "path":
            p = o.quantity.rsplit(".", 1)[0]
            out[f"{o.name}.x"], out[f"{o.name}.y"] = cols[f"{p}.x"], cols[f"{p}.y"]
            continue
        out[o.name] = _stat(_history(model, o, cols, t), o.stat)
    return out


def _history(model: VariantModel, o: OutputSpec, cols: dict[str, np.ndarray], t: np.ndarray) -> np.ndarray:
    """A quantity over the requested samples, (n, N)."""
    kind = quantity_kind(model.mechanism, o.quantity)
    if kind == "column":
        return cols[o.quantity]
    if kind == "magnitude":
        p, f = o.quantity.rsplit(".", 1)
        a, b = (f"{p}.vx", f"{p}.vy") if f == "speed" else (f"{p}.ax", f"{p}.ay")
        return np.hypot(cols[a], cols[b])
    from ..teaching.transmission import raw_angle

    view = Result("", "study", t, cols)
    folded = [
        np.minimum(r, np.pi - r) for r in (raw_angle(model.mechanism, view, d) for d in _dyads(model, o.quantity))
    ]
    return np.minimum.reduce(folded)


def _stat(x: np.ndarray, stat: str) -> np.ndarray:
    """A statistic over the samples (axis 1) of each row, or the whole series."""
    x = np.ascontiguousarray(x)
    if stat == "series":
        return x
    if stat == "range":
        return np.max(x, axis=1) - np.min(x, axis=1)
    if stat == "peak":
        return np.max(np.abs(x), axis=1)
    if stat == "rms":
        return np.sqrt(np.mean(x * x, axis=1))
    if stat in ("start", "end"):
        return x[:, 0 if stat == "start" else -1].copy()
    return {"min": np.min, "max": np.max, "mean": np.mean}[stat](x, axis=1)


def _static(model: VariantModel, outputs: tuple[OutputSpec, ...], values: np.ndarray, ok: np.ndarray) -> dict:
    """Outputs that depend on the dimensions only (the Grashof class): every valid design, assembled or not."""
    out: dict[str, np.ndarray] = {}
    for o in outputs:
        if quantity_kind(model.mechanism, o.quantity) != "class":
            continue
        cls = np.full(len(values), "", object)
        is_g = np.zeros(len(values), bool)
        if ok.any():
            c, g = grashof(model, model.designs(values[ok]), _fourbar_loop(model, o.quantity))
            cls[ok], is_g[ok] = c, g
        out[o.name], out[f"{o.name}.is_grashof"] = cls, is_g
    return out


def _fourbar_loop(model: VariantModel, quantity: str) -> tuple[int, list[int]] | None:
    """(loop, its four owners: ground, input side, coupler, output side) of the four-bar loop a grashof quantity
    names; the input side is the driven link where one is driven (else the loop's traversal decides)."""
    sys = model.system
    want = int(quantity.split(".", 1)[1]) - 1 if "." in quantity else None
    for lp in sys.loops:
        if want is not None and lp.index != want:
            continue
        terms = np.nonzero(sys.C[lp.index])[0]
        if np.any(sys.t_sl[terms] >= 0):
            continue
        order = list(dict.fromkeys(int(sys.t_ang[t]) for t in lp.terms))
        if len(order) == 4 and -1 in order:
            k = order.index(-1)
            order = order[k:] + order[:k]
            if order[3] in sys.drivers and order[1] not in sys.drivers:  # the driven link is the input side
                order = [order[0], order[3], order[2], order[1]]
            return lp.index, order
    return None


def grashof(model: VariantModel, d: Any, loop: tuple[int, list[int]]) -> tuple[np.ndarray, np.ndarray]:
    """Grashof class and s + l ≤ p + q of a four-bar loop for every design (as vloop.method.equations.grashof does)."""
    sys = model.system
    li, owners = loop
    coef = sys.C[li]
    lengths = []
    for a in owners:
        vec = 0j
        for t in np.nonzero((coef != 0) & (sys.t_ang == a))[0]:
            vec = vec + coef[t] * d.r[:, t] * d.cd[:, t]  # the owner's vectors turn together: |Σ| is its length
        lengths.append(np.abs(vec) * np.ones(len(d)))
    return grashof_class(np.stack(lengths, axis=1))


# ---------------------------------------------------------------- the run


def run(
    spec: StudySpec,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    progress: bool | None = None,
    memory_budget: Any = None,
) -> StudyResult:
    """Solve a study (in this process, or on Dask with ``scheduler`` / ``workers``) and gather its tables. The
    memory it needs is estimated from its sizes and checked against ``memory_budget`` before anything is built."""
    from ..compiler import compile_system
    from ..runner import run_tasks

    t0 = time.perf_counter()
    mech = spec.mechanism
    refs = references(spec)
    model = VariantModel.build(mech, compile_system(mech), refs)
    check_outputs(model, spec)
    times = spec.times if spec.times is not None else np.asarray(mech.times, float)
    check_memory(spec, model, len(times), memory_budget)
    p = plan(spec, refs)
    valid = np.array([i not in p.invalid for i in range(len(p.values))], bool)
    grid = (
        batch.make_grid(model, model.designs(p.values[valid]), times)
        if valid.any()
        else batch.make_grid(model, model.designs(model.nominal_values()[None, :]), times)
    )
    size = _chunk_size(spec, len(p.values), scheduler, workers)
    shipped = dataclasses.replace(model, system=dataclasses.replace(model.system, cache=dict(model.system.cache)))
    shipped.system.cache.pop("plans", None)  # the solver's plans are rebuilt where the chunk runs
    tasks = [
        _Task(
            shipped,
            p.values[lo : lo + size],
            {i - lo: w for i, w in p.invalid.items() if lo <= i < lo + size},
            grid,
            spec.outputs,
        )
        for lo in range(0, len(p.values), size)
    ]
    outcomes = run_tasks(run_chunk, tasks, scheduler=scheduler, workers=workers, progress=progress, label="variants")
    failed = [o for o in outcomes if not o.ok]
    if failed:
        raise VloopError(f"{spec.source}: a chunk of the study failed: {failed[0].error}", entry="study")
    status = Outcomes.join([o.value["status"] for o in outcomes])
    values = {k: np.concatenate([o.value["values"][k] for o in outcomes]) for k in outcomes[0].value["values"]}
    return _gather(spec, p, model, status, values, times, time.perf_counter() - t0)


def _chunk_size(spec: StudySpec, n: int, scheduler: str | None, workers: int | None) -> int:
    if spec.chunk:
        return spec.chunk
    if scheduler or workers:
        return max(64, math.ceil(n / (TASKS_PER_WORKER * (workers or 4))))
    return LOCAL_CHUNK


def check_memory(spec: StudySpec, model: VariantModel, n_times: int, explicit: Any = None) -> int:
    """Refuse (MemoryBudgetError) a study whose designs and tables would not fit the memory budget
    (vloop.files.budget: ``explicit``, VLOOP_MEMORY_BUDGET, the file's [solver] memory_budget, half the available
    memory), estimated from its sizes before anything is built. Returns the estimate [bytes]."""
    from ..files.budget import MemoryBudgetError, budget, fmt_size

    _, n = design_count(spec)
    series = sum(
        2 if quantity_kind(model.mechanism, o.quantity) == "path" else (o.stat == "series") for o in spec.outputs
    )
    per_design = len(spec.parameters) + len(spec.outputs) + 16 + model.system.n_vars + 2 * len(model.system.point_names)
    need = n * per_design * 8
    need = 3 * (need + n * series * n_times * 8) + batch.ROWS * 400
    limit, source = budget(explicit, spec.mechanism.options)
    if need > limit:
        raise MemoryBudgetError(
            f"{spec.source}: the study's {n:,} designs to solve need about {fmt_size(need)}, more than the memory "
            f"budget of {fmt_size(limit)} ({source}): fewer samples or grid values, fewer series outputs, or a larger "
            "budget (--memory-budget, VLOOP_MEMORY_BUDGET)",
            entry="study",
        )
    return need


# ---------------------------------------------------------------- tables


@dataclass
class StudyResult:
    """A study's tables (pandas DataFrames; ``write`` saves them as Parquet):

    ``table`` one row per variant; ``summary`` per base design and scalar output (tolerance studies: nominal,
    linearized σ, Monte-Carlo statistics); ``sensitivity`` d(output)/d(parameter) per base design (scalar
    outputs); ``bands`` series outputs per base design and sample. Indexing a StudyResult indexes its table.
    """

    table: Any
    summary: Any
    sensitivity: Any
    bands: Any
    t: np.ndarray
    spec: StudySpec
    seconds: float
    counts: dict[str, int]
    _model: VariantModel = field(repr=False)
    _status: Outcomes = field(repr=False)
    _values: np.ndarray = field(repr=False)

    def __getitem__(self, key: Any) -> Any:
        return self.table[key]

    def __len__(self) -> int:
        return len(self.table)

    def __repr__(self) -> str:
        c = self.counts
        return (
            f"StudyResult({c['variants']:,} variants: {c['completed']:,} completed, {c['stopped']:,} stopped, "
            f"{c['not_assembled']:,} not assembled; {self.seconds:.2f} s)"
        )

    def _repr_html_(self) -> str:
        """A notebook's summary: the counts, the parameters, the summary table and the first variants."""
        import html

        rows = []
        for prm in self.spec.parameters:
            ref = next((r for r in self._model.params if r.name == prm.name), None)
            spread = f"{len(prm.values)} values" if prm.values else ""
            if prm.tolerance is not None:
                spread = "; ".join(x for x in (spread, _tolerance_text(prm.tolerance)) if x)
            rows.append([prm.name, ref.unit if ref else "", ref.nominal if ref else "", spread])
        parts = [
            f"<p><b>{html.escape(repr(self))}</b> on {html.escape(self.spec.mechanism.name)}</p>",
            html_table(rows, ["parameter", "unit", "nominal", "varied"], "parameters"),
        ]
        if len(self.summary):
            parts.append("<p>summary</p>" + self.summary._repr_html_())
        parts.append(f"<p>variants (the first {min(10, len(self.table))} of {len(self.table):,})</p>")
        return "".join(parts) + self.table.head(10)._repr_html_()

    def variant_mechanism(self, row: int) -> Mechanism:
        """Variant ``row`` of the table as a Mechanism of its own (its coordinates the t = 0 assembly, so it loads
        and compiles anywhere: ``vloop.save(res.variant_mechanism(i), "variant.toml")``)."""
        if not 0 <= row < self.counts["variants"]:
            raise IndexError(f"no variant {row} (the study has {self.counts['variants']})")
        st = self._status
        if not st.assembled[row]:
            return self._model.variant_mechanism(self._values[row])
        pos = dict(zip(self._model.system.point_names, st.positions[row].tolist(), strict=True))
        return self._model.variant_mechanism(self._values[row], pos, st.q0[row])

    def write(self, folder: str | Path, *, plot: bool = False, fmt: str = "parquet") -> list[Path]:
        """Write the tables (variants, summary, sensitivity, bands: those not empty) as ``fmt`` ("parquet" or
        "csv") and study.json into ``folder`` as one set (vloop.files.output.OutputSet, replacing a previous
        study's files there); with ``plot`` the pictures too. Returns the paths written."""
        from ..files.output import OutputSet

        with OutputSet(folder, owns=OWNS) as out:
            self.stage(out, plot=plot, fmt=fmt)
        return out.published

    def stage(self, out: Any, *, plot: bool = False, fmt: str = "parquet") -> None:
        """Write the study's files into an open OutputSet ``out`` (published when it closes)."""
        import json

        from ..files.writers import write_table

        units = self.units()
        for name, df in self.tables().items():
            if len(df):
                write_table(df, out.path(f"{name}.{fmt}"), fmt, units, {"study": self.spec.source})
        out.write_text("study.json", json.dumps(self.manifest(), indent=2, allow_nan=False) + "\n")
        if plot:
            from .plot import plot_study

            plot_study(self, out.stage)

    def tables(self) -> dict[str, Any]:
        """The study's tables by file name."""
        return {"variants": self.table, "summary": self.summary, "sensitivity": self.sensitivity, "bands": self.bands}

    def units(self) -> dict[str, str]:
        """The unit of every column of the tables (a column without one — an index, a flag, text — has none).
        ``[unit]``: the row's own unit, in its ``unit`` column (summary, sensitivity and bands hold several outputs;
        ``[unit]·parameter``: times the unit of the row's parameter)."""
        mech = self.spec.mechanism
        out: dict[str, str] = {r.name: r.unit for r in self._model.params}
        for o in self.spec.outputs:
            u = output_unit(mech, o) if o.stat != "class" else ""
            for col in (o.name, f"{o.name}.x", f"{o.name}.y"):
                out[col] = u
            for r in self._model.params:
                out[f"d({o.name})/d({r.name})"] = f"{u}/{r.unit}"
        out.update(stopped_at="s", t="s", max_cond="1", derivative="[unit]", sigma_contribution="[unit]·parameter")
        for col in ("nominal", "linearized_sigma", "mc_mean", "mc_sigma", "mc_sigma_error"):
            out[col] = "[unit]"
        out.update({f"mc_p{q:g}": "[unit]" for q in PERCENTILES})
        out.update({f"d/d({r.name})": f"[unit]/{r.unit}" for r in self._model.params})
        return out

    def manifest(self) -> dict[str, Any]:
        """What was run: the mechanism, parameters (with units and tolerances), outputs, counts, seed, seconds
        (study.json)."""
        s = self.spec
        units = {r.name: r.unit for r in self._model.params}
        return {
            "study": s.source,
            "mechanism": s.mechanism.name,
            "parameters": [
                {
                    "name": p.name,
                    "unit": units.get(p.name, ""),
                    "grid": len(p.values) if p.values else 0,
                    "tolerance": _tolerance_entry(p.tolerance),
                }
                for p in s.parameters
            ],
            "outputs": [{**dataclasses.asdict(o), "unit": output_unit(s.mechanism, o)} for o in s.outputs],
            "samples": s.samples,
            "seed": s.seed,
            "sensitivity": s.sensitivity,
            "times": {"count": len(self.t), "first": float(self.t[0]), "last": float(self.t[-1])},
            "counts": self.counts,
            "seconds": round(self.seconds, 3),
        }


OWNS = (
    *(f"{n}.{x}" for n in ("variants", "summary", "sensitivity", "bands") for x in ("csv", "parquet")),
    *("study.json", "band_*.png", "hist_*.png", "grid_*.png", "map_*.png"),
)  # a study's files: those of a previous study in the same folder are replaced as one set


def _tolerance_text(tol: Any) -> str:
    """A parameter's tolerance in words: uniform within ± its half width, or normal with its σ."""
    return f"uniform ± {tol.width:g}" if tol.dist == "uniform" else f"normal, σ = {tol.width:g}"


def _tolerance_entry(tol: Any) -> dict[str, Any] | None:
    """A tolerance as the study file writes it: ``half_width`` for a uniform one, ``sigma`` for a normal one."""
    if tol is None:
        return None
    return {"dist": tol.dist, "half_width" if tol.dist == "uniform" else "sigma": tol.width}


def _gather(
    spec: StudySpec,
    p: _Plan,
    model: VariantModel,
    st: Outcomes,
    values: dict[str, np.ndarray],
    t: np.ndarray,
    seconds: float,
) -> StudyResult:
    """The study's tables from every design's outcome and outputs."""
    n = p.n_variants
    table = _variants_table(spec, p, st, values, n)
    sens = _derivatives(spec, p, values)
    if spec.sensitivity == "each":
        _add_each(table, spec, p, sens, n)
    summary = _summary(spec, p, values, sens, st)
    sensitivity = _sensitivity_table(spec, p, model, sens)
    bands = _bands(spec, p, values, sens, st, t)
    table, summary, sensitivity, bands = map(finite_or_null, (table, summary, sensitivity, bands))
    stopped = int(np.sum(st.assembled[:n] & ~st.completed[:n]))
    counts = {
        "variants": n,
        "completed": int(np.sum(st.completed[:n])),
        "stopped": stopped,
        "not_assembled": int(np.sum(~st.assembled[:n])),
        "designs_solved": len(p.values),
        "single_runs": sum(s == "single" for s in st.solver),
    }
    return StudyResult(table, summary, sensitivity, bands, t, spec, seconds, counts, model, st, p.values)


def _scalar_outputs(spec: StudySpec) -> list[OutputSpec]:
    return [o for o in spec.outputs if o.stat not in ("series", "path", "class")]


def _series_names(spec: StudySpec) -> list[str]:
    out = []
    for o in spec.outputs:
        if o.stat == "series":
            out.append(o.name)
        elif o.stat == "path":
            out += [f"{o.name}.x", f"{o.name}.y"]
    return out


def _variants_table(spec: StudySpec, p: _Plan, st: Outcomes, values: dict[str, np.ndarray], n: int) -> Any:
    import pandas as pd

    cols: dict[str, Any] = {"variant": np.arange(n)}
    if p.grid_index is not None:
        cols["grid"] = p.grid_index
    if p.draw_index is not None:
        cols["draw"] = p.draw_index
    for i, r in enumerate(p.refs):
        cols[r.name] = p.values[:n, i]
    done = st.completed[:n]
    for o in spec.outputs:
        if o.stat == "class":
            cols[o.name] = values[o.name][:n]
            cols[f"{o.name}.is_grashof"] = values[f"{o.name}.is_grashof"][:n]
        elif o.stat == "path":
            for ax in ("x", "y"):
                arr = values[f"{o.name}.{ax}"][:n]
                cols[f"{o.name}.{ax}"] = [row.tolist() if ok else None for row, ok in zip(arr, done, strict=True)]
        elif o.stat == "series":
            arr = values[o.name][:n]
            cols[o.name] = [row.tolist() if ok else None for row, ok in zip(arr, done, strict=True)]
        else:
            cols[o.name] = np.where(done, values[o.name][:n], np.nan)
    cols["assembled"] = st.assembled[:n]
    cols["completed"] = done
    cols["stopped_at"] = np.where(st.assembled[:n] & ~done, st.stopped_at[:n], np.nan)
    cols["stopped_sample"] = pd.array(np.where(st.assembled[:n] & ~done, st.stopped_sample[:n], -1), dtype="Int64")
    cols["stopped_sample"][cols["stopped_sample"] < 0] = pd.NA
    cols["reason"] = st.reason[:n]
    cols["solver"] = [s or None for s in st.solver[:n]]
    cols["max_cond"] = st.max_cond[:n]
    return pd.DataFrame(cols)


def _derivatives(spec: StudySpec, p: _Plan, values: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """d(output)/d(parameter) at every sensitivity point: (points, P) for scalars, (points, P, N) for series;
    NaN where a neighbour did not complete."""
    out = {}
    names = [o.name for o in _scalar_outputs(spec)] + _series_names(spec)
    for name in names:
        y = values[name]
        plus, minus = y[p.sens_rows[..., 0]], y[p.sens_rows[..., 1]]
        h = p.steps.reshape((1, -1) + (1,) * (y.ndim - 1))
        out[name] = (plus - minus) / (2.0 * h)
    return out


def _add_each(table: Any, spec: StudySpec, p: _Plan, sens: dict[str, np.ndarray], n: int) -> None:
    for o in _scalar_outputs(spec):
        for i, r in enumerate(p.refs):
            table[f"d({o.name})/d({r.name})"] = sens[o.name][:n, i]


def _lin_sigma(p: _Plan, d: np.ndarray) -> np.ndarray:
    """√Σ (∂y/∂p·σ_p)² over the toleranced parameters; ``d`` (P,) or (P, N) gives a number or (N,)."""
    x = np.abs(d * p.sigma.reshape((-1,) + (1,) * (d.ndim - 1)))
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        big = np.max(x, axis=0)  # scaled so that the squares cannot overflow; NaN (a neighbour failed) stays NaN
        sigma = np.where(big > 0, big * np.sqrt(np.sum((x / np.where(big > 0, big, 1.0)) ** 2, axis=0)), 0.0)
        return np.where(np.isnan(big), np.nan, sigma)


def _summary(
    spec: StudySpec, p: _Plan, values: dict[str, np.ndarray], sens: dict[str, np.ndarray], st: Outcomes
) -> Any:
    """Per base design and scalar output of a tolerance study: the nominal, linearized and Monte-Carlo statistics."""
    import pandas as pd

    if p.draw_index is None:
        return pd.DataFrame()
    rows = []
    D = spec.samples or 0
    where = {int(r): k for k, r in enumerate(p.sens_at)}
    for b, row in enumerate(p.base_rows):
        members = np.arange(b * D, (b + 1) * D)
        done = members[st.completed[members]]
        for o in _scalar_outputs(spec):
            y = values[o.name][done]
            k = where.get(int(row))
            lin = float(_lin_sigma(p, sens[o.name][k])) if k is not None else np.nan
            rows.append(
                {
                    "grid": b,
                    **{r.name: p.values[row, i] for i, r in enumerate(p.refs)},
                    "output": o.name,
                    "unit": output_unit(spec.mechanism, o),
                    "nominal": values[o.name][row] if st.completed[row] else np.nan,
                    "linearized_sigma": lin,
                    **_mc_stats(y),
                    "completed": len(done),
                    "draws": D,
                }
            )
    return pd.DataFrame(rows)


def _mc_stats(y: np.ndarray) -> dict[str, float]:
    """Monte-Carlo mean, standard deviation and its sampling error √((κ − 1)/(4n))·σ, percentiles."""
    n = len(y)
    if n < 2:
        return {
            "mc_mean": np.nan,
            "mc_sigma": np.nan,
            "mc_sigma_error": np.nan,
            **{f"mc_p{q:g}": np.nan for q in PERCENTILES},
        }
    mean = float(np.mean(y))
    sd = float(np.std(y, ddof=1))
    m2 = float(np.mean((y - mean) ** 2))
    kurt = float(np.mean((y - mean) ** 4)) / (m2 * m2) if m2 > 0 else 3.0
    err = sd * math.sqrt(max(kurt - 1.0, 0.0) / (4 * n))
    pct = np.percentile(y, PERCENTILES)
    return {
        "mc_mean": mean,
        "mc_sigma": sd,
        "mc_sigma_error": err,
        **{f"mc_p{q:g}": float(v) for q, v in zip(PERCENTILES, pct, strict=True)},
    }


def _sensitivity_table(spec: StudySpec, p: _Plan, model: VariantModel, sens: dict[str, np.ndarray]) -> Any:
    """d(output)/d(parameter) of every scalar output at the nominal design(s) (not each variant: see the table)."""
    import pandas as pd

    rows = []
    at = p.base_rows if p.draw_index is not None else p.sens_at[p.sens_at >= p.n_variants]
    where = {int(r): k for k, r in enumerate(p.sens_at)}
    units = {o.name: output_unit(model.mechanism, o) for o in spec.outputs}
    for b, row in enumerate(at):
        k = where.get(int(row))
        if k is None:
            continue
        for o in _scalar_outputs(spec):
            for i, r in enumerate(p.refs):
                d = float(sens[o.name][k, i])
                rows.append(
                    {
                        "base": b,
                        "output": o.name,
                        "parameter": r.name,
                        "derivative": d,
                        "unit": f"{units[o.name]}/{r.unit}",
                        "sigma_contribution": abs(d) * p.sigma[i],
                    }
                )
    return pd.DataFrame(rows)


def _bands(
    spec: StudySpec, p: _Plan, values: dict[str, np.ndarray], sens: dict[str, np.ndarray], st: Outcomes, t: np.ndarray
) -> Any:
    """Series outputs over the motion per base design: nominal, linearized σ, Monte-Carlo mean/σ/percentiles,
    and the derivative with respect to each parameter at every sample."""
    import pandas as pd

    names = _series_names(spec)
    if not names:
        return pd.DataFrame()
    where = {int(r): k for k, r in enumerate(p.sens_at)}
    at = p.base_rows if p.draw_index is not None else p.sens_at
    unit_of = {f"{o.name}{x}": output_unit(spec.mechanism, o) for o in spec.outputs for x in ("", ".x", ".y")}
    frames = []
    D = spec.samples or 0
    for b, row in enumerate(at):
        k = where.get(int(row))
        for name in names:
            cols: dict[str, Any] = {
                "base": b,
                "output": name,
                "unit": unit_of[name],
                "sample": np.arange(len(t)),
                "t": t,
                "nominal": values[name][row] if st.completed[row] else np.full(len(t), np.nan),
            }
            if k is not None:
                d = sens[name][k]  # (P, N)
                if p.draw_index is not None:
                    cols["linearized_sigma"] = _lin_sigma(p, d)
                for i, r in enumerate(p.refs):
                    cols[f"d/d({r.name})"] = d[i]
            if p.draw_index is not None:
                members = np.arange(b * D, (b + 1) * D)
                y = values[name][members[st.completed[members]]]
                if len(y) > 1:
                    cols["mc_mean"], cols["mc_sigma"] = y.mean(0), y.std(0, ddof=1)
                    for q, v in zip(PERCENTILES, np.percentile(y, PERCENTILES, axis=0), strict=True):
                        cols[f"mc_p{q:g}"] = v
            frames.append(pd.DataFrame(cols))
    return pd.concat(frames, ignore_index=True) if frames else pd.DataFrame()


def load_and_run(path: str | Path, **options: Any) -> StudyResult:
    """Read a study file and run it (``scheduler``, ``workers``, ``progress`` as :func:`run`)."""
    from .studyfile import load

    return run(load(path), **options)


__all__ = ["Problems", "StudyResult", "grashof", "load_and_run", "plan", "run", "run_chunk", "study"]
