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

    @property
    def samples(self) -> int:
        return len(self.result) if self.result is not None else 0


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

    @property
    def passed(self) -> bool:
        return (
            not self.error
            and all(c.passed for c in self.checks)
            and all(r.status in ("ok", "stopped", "skipped") for r in self.runs.values())
        )


@dataclass
class Validation:
    items: list[MechanismValidation]
    engines: tuple[str, ...]
    started: str
    seconds: float
    versions: dict[str, str]

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


def validate_mechanism(
    path: str | Path,
    engines: Iterable[str],
    *,
    progress: Callable[[str], None] | None = None,
    mechanism: Mechanism | None = None,
) -> MechanismValidation:
    """Every engine on one mechanism file, each compared with vloop and with the closed form."""
    path = Path(path)
    try:
        mech = mechanism or vloop.load(path)
    except VloopError as exc:
        return MechanismValidation(str(path), path.stem, None, error=str(exc))
    item = MechanismValidation(str(path), mech.name, mech)
    engines = tuple(engines)
    for name in engines:
        run = run_engine(name, mech)
        item.runs[name] = run
        if progress:
            extra = f" ({run.message.splitlines()[0][:120]})" if run.status in ("error", "stopped") else ""
            progress(f"{mech.name}: {name} {run.status} in {run.seconds:.2f} s{extra}")
    for ref in REFERENCES:
        if ref not in item.runs:
            continue
        for name in engines:
            if name == ref or name not in item.runs:
                continue
            c = check(item.runs[name], item.runs[ref], mech.name)
            if c is not None:
                item.checks.append(c)
    return item


def run(
    paths: Iterable[str | Path],
    engines: Iterable[str] = ENGINES,
    *,
    progress: Callable[[str], None] | None = None,
) -> Validation:
    """Validate every mechanism file with every engine."""
    engines = tuple(engines)
    for e in engines:
        if e not in ENGINES:
            raise MechanismError(f"unknown engine '{e}' (known: {', '.join(ENGINES)})", entry="engines")
    started = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    t0 = time.perf_counter()
    items = []
    paths = list(paths)
    for i, p in enumerate(paths, 1):
        if progress:
            progress(f"[{i}/{len(paths)}] {Path(p).name}")
        items.append(validate_mechanism(p, engines, progress=progress))
    return Validation(items, engines, started, time.perf_counter() - t0, versions())


# ------------------------------------------------------------------ summary.json


def _num(x: float) -> float | str:
    return float(x) if np.isfinite(x) else "inf"


def _badness(q: dict[str, Any]) -> float:
    """A quantity's error as a fraction of what is allowed."""
    err = q["max_abs"] if isinstance(q["max_abs"], float) else np.inf
    return err / max(q["allowed"], 1e-300)


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
            name: {"status": r.status, "samples": r.samples, "seconds": r.seconds, "message": r.message}
            for name, r in it.runs.items()
        }
        comps = []
        for c in it.checks:
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
            worst = max(q, key=_badness, default=None)
            comps.append(
                {
                    "engine": c.engine,
                    "reference": c.reference,
                    "samples": c.samples,
                    "passed": c.passed,
                    "message": c.message,
                    "worst": worst,
                    "quantities": q,
                }
            )
        entry["comparisons"] = comps
        mechs.append(entry)
    return {
        "schema": SCHEMA,
        "created": v.started,
        "seconds": v.seconds,
        "passed": v.passed,
        "engines": list(v.engines),
        "versions": v.versions,
        "tolerances": {f"{a} vs {b}": t.as_dict() for (a, b), t in TOLERANCES.items()},
        "mechanisms": mechs,
    }
