"""The cross-validation harness: run every engine on every mechanism, compare, summarize.

    validation = run([...paths], engines=("vloop", "pinocchio", "analytic"))
    summary = to_summary(validation)          # the summary.json structure (schema: summary.schema.json)

Each engine reads the Mechanism and returns the same Result type; every engine is compared
with vloop, and every engine (vloop included) with the closed form where one exists. An engine
that fails on a mechanism does not stop the others: the failure is recorded. A run that stops
part-way (a limit position) is compared on the samples every engine solved; it passes when
the engines stop within one sample of each other and agree before that.
"""

from __future__ import annotations

import datetime as _dt
import importlib.metadata
import platform
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import vloop
from vloop.compare import Comparison, compare
from vloop.errors import MechanismError, MotionError, VloopError
from vloop.mechanism import Mechanism
from vloop.result import Result

from .forces_engines import with_forces
from .tolerances import TOLERANCES, tolerance

SCHEMA = "vloop-validation-summary/1"
ENGINES = ("vloop", "analytic", "pinocchio", "exudyn-kinematic", "exudyn-dynamic")
REFERENCES = ("vloop", "analytic")


def _engine_fn(name: str) -> Callable[[Mechanism], Result]:
    if name == "vloop":
        return lambda m: vloop.solve(m)
    if name == "analytic":
        from . import analytic

        return lambda m: analytic.solve(m)
    if name == "pinocchio":
        from . import pinocchio

        return lambda m: pinocchio.solve(m)
    if name in ("exudyn-kinematic", "exudyn-dynamic"):
        from . import exudyn

        mode = name.split("-", 1)[1]
        return lambda m: exudyn.solve(m, mode=mode)
    raise ValueError(f"unknown engine '{name}' (known: {', '.join(ENGINES)})")


def engine_applies(name: str, mech: Mechanism) -> bool:
    """Whether an engine has anything to say about ``mech`` (closed forms exist for some only)."""
    if name == "analytic":
        from . import analytic

        return analytic.available(mech)
    return True


@dataclass
class EngineRun:
    """One engine on one mechanism: its Result (the partial one if it stopped), or why it has none."""

    engine: str
    status: str  # "ok" | "stopped" (motion could not be completed) | "error" | "skipped"
    result: Result | None = None
    message: str = ""
    seconds: float = 0.0
    worker: str = ""  # who ran the task (vloop.runner: "local:HOST:PID" or the Dask worker)
    task_seconds: float = 0.0  # the task's wall time where it ran (engine + its imports), s
    n_samples: int | None = None  # kept when the Result is dropped to save memory

    @property
    def samples(self) -> int:
        if self.result is not None:
            return len(self.result)
        return self.n_samples or 0

    def drop_result(self) -> None:
        """Forget the Result (a passing corpus run needs only its numbers in the summary)."""
        self.n_samples, self.result = self.samples, None


@dataclass
class CheckedComparison:
    """A Comparison with its tolerance, the samples compared and a verdict."""

    engine: str
    reference: str
    comparison: Comparison | None
    samples: int
    passed: bool
    message: str
    rtol: float | dict[str, float]


@dataclass
class MechanismValidation:
    path: str
    name: str
    mechanism: Mechanism | None
    runs: dict[str, EngineRun] = field(default_factory=dict)
    checks: list[CheckedComparison] = field(default_factory=list)
    error: str = ""  # the file itself is bad
    corpus: dict[str, Any] | None = None  # the generated file's sidecar (validators.corpus): family, seed, expectations
    expectation: dict[str, Any] | None = None  # what the sidecar expected of every engine, and what happened

    @property
    def passed(self) -> bool:
        return (
            not self.error
            and all(c.passed for c in self.checks)
            and all(r.status in ("ok", "stopped", "skipped") for r in self.runs.values())
            and (self.expectation is None or self.expectation["passed"])
        )


@dataclass
class Validation:
    items: list[MechanismValidation]
    engines: tuple[str, ...]
    started: str
    seconds: float
    versions: dict[str, str]
    runner: dict[str, Any] = field(default_factory=dict)  # how the tasks ran (vloop.runner settings)

    @property
    def passed(self) -> bool:
        return all(it.passed for it in self.items)

    @property
    def bad_input(self) -> bool:
        return any(it.error for it in self.items)


def versions() -> dict[str, str]:
    out = {"python": platform.python_version(), "vloop": vloop.__version__}
    for dist in ("numpy", "scipy", "networkx", "pin", "exudyn", "matplotlib"):
        try:
            out[dist] = importlib.metadata.version(dist)
        except importlib.metadata.PackageNotFoundError:
            out[dist] = "not installed"
    return out


def run_engine(name: str, mech: Mechanism) -> EngineRun:
    """Run one engine; a MotionError gives status "stopped" with its partial Result."""
    if not engine_applies(name, mech):
        return EngineRun(name, "skipped", message="no closed form for this structure")
    t0 = time.perf_counter()
    try:
        res = with_forces(name, _engine_fn(name))(mech)
        return EngineRun(name, "ok", res, seconds=time.perf_counter() - t0)
    except MotionError as exc:
        return EngineRun(name, "stopped", exc.partial, str(exc), time.perf_counter() - t0)
    except ValueError as exc:  # the closed forms' LimitPositionError is a ValueError with .partial
        partial = getattr(exc, "partial", None)
        status = "stopped" if partial is not None else "error"
        return EngineRun(name, status, partial, str(exc), time.perf_counter() - t0)
    except ImportError as exc:
        return EngineRun(name, "error", None, f"{name} is not installed ({exc})", time.perf_counter() - t0)
    except Exception as exc:  # an engine's failure must not stop the others; it is reported
        return EngineRun(name, "error", None, f"{type(exc).__name__}: {exc}", time.perf_counter() - t0)


def _extent(r: EngineRun) -> str:
    return f"stopped after {r.samples}" if r.status == "stopped" else f"ran all {r.samples}"


def check(a: EngineRun, b: EngineRun, mech_name: str) -> CheckedComparison | None:
    """Compare run ``a`` against reference run ``b`` under the stated tolerance."""
    if (a.engine, b.engine) not in TOLERANCES or a.status == "skipped" or b.status == "skipped":
        return None
    tol = tolerance(a.engine, b.engine)
    if a.result is None or b.result is None:
        missing = a if a.result is None else b
        return CheckedComparison(
            a.engine, b.engine, None, 0, False, f"{missing.engine} gave no result: {missing.message}", tol.rtol
        )
    n = min(a.samples, b.samples)
    msg = ""
    passed = True
    if a.status != b.status or abs(a.samples - b.samples) > 1:
        if a.status == "stopped" or b.status == "stopped":
            passed = abs(a.samples - b.samples) <= 1 and a.status == b.status
            if not passed:
                msg = f"{a.engine} {_extent(a)} samples, {b.engine} {_extent(b)}"
    if a.status == "stopped" or b.status == "stopped":
        # Approaching a limit position every rate grows without bound and every engine's conditioning
        # with it (a time integrator's most of all): compare the first 90 % of what both solved.
        n = max(int(0.9 * (n - 1)), 0)
    cmp = compare(a.result.head(n), b.result.head(n), tol.rtol, floor=tol.floor)
    if not cmp.passed:
        passed = False
        msg = "; ".join(filter(None, [msg, cmp.message(limit=3).replace("\n", "; ")]))
    return CheckedComparison(a.engine, b.engine, cmp, n, passed, msg or "within tolerance", tol.rtol)


def _checks(item: MechanismValidation, engines: tuple[str, ...]) -> None:
    """Compare every engine with every reference run (vloop, then the closed form)."""
    for ref in REFERENCES:
        if ref not in item.runs:
            continue
        for name in engines:
            if name == ref or name not in item.runs:
                continue
            c = check(item.runs[name], item.runs[ref], item.name)
            if c is not None:
                item.checks.append(c)


def expectation(item: MechanismValidation) -> dict[str, Any] | None:
    """What a generated file's sidecar promises, checked against every engine's run.

    Every engine that ran must return exactly the expected number of samples: all of them for a run
    clear of limits, the recorded stop sample K for a run into a limit (computed by the generator from
    the closed-form limit angle, not by running an engine), with the status to match; and where the
    generator says a closed form exists, the analytic engine must not be skipped.
    """
    side = item.corpus
    if not side or "expect" not in side:
        return None
    want = int(side["expect"]["samples"])
    stop = side["expect"].get("stop_sample")
    problems, observed = [], {}
    for name, r in item.runs.items():
        observed[name] = r.samples if r.status in ("ok", "stopped") else None
        if r.status == "skipped":
            if name == "analytic" and side.get("closed_form"):
                problems.append("analytic skipped, but the family has a closed form")
            continue
        if r.status == "error":
            continue  # reported as the engine's failure already
        if r.samples != want or (r.status == "stopped") != (stop is not None):
            what = f"stop at sample {stop}" if stop is not None else f"run all {want} samples"
            problems.append(f"{name} {_extent(r)} samples, expected to {what}")
    return {
        "samples": want,
        "stop_sample": stop,
        "observed": observed,
        "passed": not problems,
        "message": "; ".join(problems) or "as expected",
    }


def _finalize(item: MechanismValidation, engines: tuple[str, ...], keep_results: bool) -> None:
    item.runs = {e: item.runs[e] for e in engines if e in item.runs}
    _checks(item, engines)
    item.expectation = expectation(item)
    if not keep_results and item.corpus is not None and item.passed:
        for r in item.runs.values():
            r.drop_result()


def validate_mechanism(
    path: str | Path,
    engines: Iterable[str],
    *,
    progress: Callable[[str], None] | None = None,
    mechanism: Mechanism | None = None,
    corpus: dict[str, Any] | None = None,
) -> MechanismValidation:
    """Every engine on one mechanism file (in this process), each compared with vloop and with the closed form."""
    path = Path(path)
    try:
        mech = mechanism or vloop.load(path)
    except VloopError as exc:
        return MechanismValidation(str(path), path.stem, None, error=str(exc))
    item = MechanismValidation(str(path), mech.name, mech, corpus=corpus)
    engines = tuple(engines)
    for name in engines:
        run = run_engine(name, mech)
        item.runs[name] = run
        if progress:
            progress(_run_line(item.name, run))
    _finalize(item, engines, keep_results=True)
    return item


def _run_line(name: str, run: EngineRun) -> str:
    extra = f" ({run.message.splitlines()[0][:120]})" if run.status in ("error", "stopped") and run.message else ""
    return f"{name}: {run.engine} {run.status} in {run.seconds:.2f} s{extra}"


def engine_task(task: tuple[str, Mechanism]) -> EngineRun:
    """One task of a validation run (what a Dask worker executes): one engine on one mechanism."""
    name, mech = task
    return run_engine(name, mech)


def load_items(paths: Iterable[str | Path]) -> list[MechanismValidation]:
    """Load every file (a bad one becomes an item with its error) and its corpus sidecar, if any."""
    from validators.corpus import read_sidecar

    items = []
    for p in paths:
        path = Path(p)
        try:
            mech = vloop.load(path)
            side = read_sidecar(path)
        except VloopError as exc:
            items.append(MechanismValidation(str(path), path.stem, None, error=str(exc)))
            continue
        items.append(MechanismValidation(str(path), mech.name, mech, corpus=side))
    return items


def run(
    paths: Iterable[str | Path],
    engines: Iterable[str] = ENGINES,
    *,
    progress: Callable[[str], None] | None = None,
    scheduler: str | None = None,
    workers: int | None = None,
    timeout: float | None = None,
    bar: bool | None = None,
    keep_results: bool = False,
) -> Validation:
    """Validate every mechanism file with every engine, each (mechanism, engine) one task of vloop.runner.

    In this process by default; ``workers=N`` on a local Dask cluster of N processes, ``scheduler=ADDRESS``
    on a running one. A task that fails, crashes its worker or passes ``timeout`` [s] is that engine's
    error. ``progress`` gets one line per finished task; ``bar`` as :func:`vloop.runner.run_tasks`'s
    ``progress``. Results of generated files that pass are dropped once compared (``keep_results=False``)
    so that a corpus of thousands fits in memory; the summary keeps their numbers.
    """
    from vloop.runner import run_tasks

    engines = tuple(engines)
    for e in engines:
        if e not in ENGINES:
            raise MechanismError(f"unknown engine '{e}' (known: {', '.join(ENGINES)})", entry="engines")
    started = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    t0 = time.perf_counter()
    items = load_items(paths)
    tasks = [(k, e) for k, it in enumerate(items) if it.mechanism is not None for e in engines]
    waiting = {k: len(engines) for k, _ in tasks}

    def on_done(out: Any) -> None:
        k, name = tasks[out.index]
        item = items[k]
        run_ = out.value if out.ok else EngineRun(name, "error", None, out.error, out.seconds)
        run_.worker, run_.task_seconds = out.worker, out.seconds
        item.runs[name] = run_
        out.value = None
        if progress:
            progress(_run_line(item.name, run_))
        waiting[k] -= 1
        if waiting[k] == 0:
            _finalize(item, engines, keep_results)

    run_tasks(
        engine_task,
        [(e, items[k].mechanism) for k, e in tasks],
        scheduler=scheduler,
        workers=workers,
        timeout=timeout,
        progress=bar,
        on_done=on_done,
        label="validate",
    )
    mode = "scheduler" if scheduler else "local-cluster" if workers else "in-process"
    runner = {"mode": mode, "workers": workers, "scheduler": scheduler, "timeout": timeout, "tasks": len(tasks)}
    return Validation(items, engines, started, time.perf_counter() - t0, versions(), runner)


# ------------------------------------------------------------------ summary.json


def _num(x: float) -> float | str:
    return float(x) if np.isfinite(x) else "inf"


def _badness(q: dict[str, Any]) -> float:
    """A quantity's error as a fraction of what is allowed."""
    err = q["max_abs"] if isinstance(q["max_abs"], float) else np.inf
    return err / max(q["allowed"], 1e-300)


def _comparison_entry(c: CheckedComparison) -> dict[str, Any]:
    """One comparison of summary.json: its verdict and every quantity's errors (non-finite as "inf")."""
    q = []
    if c.comparison is not None:
        for e in c.comparison.errors:
            q.append(
                {
                    "quantity": e.column,
                    "group": e.group,
                    "max_abs": _num(e.max_abs),
                    "max_rel": _num(e.rel),
                    "rms": _num(e.rms),
                    "t_at_max": e.t_at_max,
                    "peak": e.scale,
                    "allowed": e.tol,
                    "passed": e.passed,
                }
            )
    return {
        "engine": c.engine,
        "reference": c.reference,
        "samples": c.samples,
        "passed": c.passed,
        "message": c.message,
        "worst": max(q, key=_badness, default=None),
        "quantities": q,
    }


def to_summary(v: Validation) -> dict[str, Any]:
    """The machine-readable summary (documented by validators/summary.schema.json)."""
    mechs = []
    for it in v.items:
        entry: dict[str, Any] = {"name": it.name, "file": it.path, "passed": it.passed}
        if it.error:
            entry["error"] = it.error
            entry.update(samples=None, loops=None, mobility=None, runs={}, comparisons=[])
            mechs.append(entry)
            continue
        m = it.mechanism
        L, J, M = m.gruebler()
        entry.update(samples=len(m.times), loops=J - L + 1, mobility=M)
        entry["runs"] = {
            name: {
                "status": r.status,
                "samples": r.samples,
                "seconds": r.seconds,
                "message": r.message,
                "worker": r.worker,
                "task_seconds": r.task_seconds,
            }
            for name, r in it.runs.items()
        }
        if it.corpus is not None:
            entry["corpus"] = _corpus_entry(it)
        entry["comparisons"] = [_comparison_entry(c) for c in it.checks]
        mechs.append(entry)
    out = {
        "schema": SCHEMA,
        "created": v.started,
        "seconds": v.seconds,
        "passed": v.passed,
        "engines": list(v.engines),
        "versions": v.versions,
        "tolerances": {f"{a} vs {b}": t.as_dict() for (a, b), t in TOLERANCES.items()},
        "mechanisms": mechs,
    }
    if v.runner:
        out["runner"] = v.runner
    corpus = [it.corpus for it in v.items if it.corpus is not None]
    if corpus:
        out["corpus"] = {
            "seeds": sorted({int(c["seed"]) for c in corpus}),
            "mechanisms": len(corpus),
            "families": _count(f"{c['family']}/{c['variant']}" for c in corpus),
            "limit_runs": sum(1 for c in corpus if c["expect"].get("stop_sample") is not None),
        }
    return out


def _count(keys: Iterable[str]) -> dict[str, int]:
    out: dict[str, int] = {}
    for k in keys:
        out[k] = out.get(k, 0) + 1
    return dict(sorted(out.items()))


def _corpus_entry(it: MechanismValidation) -> dict[str, Any]:
    """A generated file's identity (family, seed, index: enough to rebuild it) and its expectation check."""
    c = it.corpus or {}
    keys = ("family", "variant", "drive", "seed", "index", "closed_form", "change_point")
    entry: dict[str, Any] = {k: c[k] for k in keys if k in c}
    entry["expect"] = it.expectation or {}
    return entry


# ------------------------------------------------------------------ the comparison table (Parquet)

TABLE_COLUMNS = (
    "mechanism", "file", "family", "variant", "drive", "corpus_seed", "corpus_index", "mechanism_passed",
    "engine", "reference", "comparison_passed", "samples", "engine_status", "engine_seconds", "engine_worker",
    "quantity", "group", "max_abs", "max_rel", "rms", "t_at_max", "peak", "allowed", "ratio", "passed",
)  # fmt: skip


def _float(x: Any) -> float:
    return float("inf") if isinstance(x, str) else float(x)


def comparison_rows(summary: dict[str, Any]) -> list[dict[str, Any]]:
    """One row per mechanism × engine × reference × quantity (a comparison without a result: one row, no quantity).

    Errors as in summary.json (file units, rad, s); ``ratio`` = max_abs / allowed (> 1 fails); "inf" is +inf.
    """
    rows = []
    for m in summary.get("mechanisms", []):
        c = m.get("corpus") or {}
        base = {
            "mechanism": m["name"],
            "file": m["file"],
            "family": c.get("family", "catalog"),
            "variant": c.get("variant", ""),
            "drive": c.get("drive", ""),
            "corpus_seed": c.get("seed"),
            "corpus_index": c.get("index"),
            "mechanism_passed": m["passed"],
        }
        for comp in m.get("comparisons", []):
            run = m.get("runs", {}).get(comp["engine"], {})
            head = {
                **base,
                "engine": comp["engine"],
                "reference": comp["reference"],
                "comparison_passed": comp["passed"],
                "samples": comp["samples"],
                "engine_status": run.get("status", ""),
                "engine_seconds": run.get("seconds"),
                "engine_worker": run.get("worker", ""),
            }
            empty = dict.fromkeys(("quantity", "group", "max_abs", "max_rel", "rms", "t_at_max", "peak", "allowed"))
            if not comp["quantities"]:
                rows.append({**head, **empty, "ratio": None, "passed": comp["passed"]})
            for q in comp["quantities"]:
                err, allowed = _float(q["max_abs"]), float(q["allowed"])
                rows.append(
                    {
                        **head,
                        "quantity": q["quantity"],
                        "group": q["group"],
                        "max_abs": err,
                        "max_rel": _float(q["max_rel"]),
                        "rms": _float(q["rms"]),
                        "t_at_max": q["t_at_max"],
                        "peak": q["peak"],
                        "allowed": allowed,
                        "ratio": err / allowed if allowed > 0 else (0.0 if err == 0 else float("inf")),
                        "passed": q["passed"],
                    }
                )
    return rows


def comparison_table(summary: dict[str, Any]) -> Any:
    """The rows of :func:`comparison_rows` as a pandas DataFrame with fixed columns and dtypes."""
    import pandas as pd

    df = pd.DataFrame(comparison_rows(summary), columns=list(TABLE_COLUMNS))
    for col in ("corpus_seed", "corpus_index", "samples"):
        df[col] = df[col].astype("Int64")
    for col in ("engine_seconds", "max_abs", "max_rel", "rms", "t_at_max", "peak", "allowed", "ratio"):
        df[col] = df[col].astype("float64")
    for col in ("mechanism_passed", "comparison_passed", "passed"):
        df[col] = df[col].astype("boolean")
    return df


def write_parquet(summary: dict[str, Any], path: str | Path) -> Path:
    """Write the comparison table as Parquet (pyarrow; ``pip install 'vloop[parquet]'``) through vloop.files.output."""
    import io

    from vloop.files.output import write_bytes

    try:
        import pyarrow  # noqa: F401
    except ImportError as exc:
        raise VloopError(f"writing {path} needs pyarrow: pip install 'vloop[parquet]' ({exc})", entry="out") from None
    buf = io.BytesIO()
    comparison_table(summary).to_parquet(buf, index=False, engine="pyarrow")
    return write_bytes(path, buf.getvalue())
