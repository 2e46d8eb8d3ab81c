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

import dataclasses
import datetime as _dt
import importlib.metadata
import itertools
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

from .consensus import STATUSES, Verdict, decide, tally
from .engines import ENGINES as REGISTRY
from .engines import engine
from .tolerances import EPS, TOLERANCES, Tolerance, conditioning_floor, pair_tolerance, tolerance

SCHEMA = "vloop-validation-summary/1"
ENGINES = tuple(REGISTRY)  # the registered engines' names (validators/engines.py), in the order reports show them
REFERENCES = ("vloop", "analytic")


def engine_applies(name: str, mech: Mechanism) -> bool:
    """Whether an engine has anything to say about ``mech`` (closed forms exist for some only)."""
    return engine(name).applies(mech)


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
    cpu_seconds: float = 0.0  # the engine's CPU time in the process that ran it, s (not inflated by a busy machine)
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
    verdict: Verdict | None = None  # who is the odd one out when the engines disagree (validators.consensus)
    inconclusive: dict[str, str] = field(default_factory=dict)  # engine -> why it cannot resolve this mechanism

    @property
    def passed(self) -> bool:
        """Every comparison within its tolerance, every engine ran, the generator's expectations met (strict)."""
        return (
            not self.error
            and all(c.passed for c in self.checks)
            and all(r.status in ("ok", "stopped", "skipped") for r in self.runs.values())
            and (self.expectation is None or self.expectation["passed"])
        )

    @property
    def red(self) -> bool:
        """Whether vloop may be wrong here (consensus.Verdict.red): vloop blamed, or undecided."""
        if self.passed:
            return False
        return self.verdict is None or self.verdict.red


@dataclass
class Validation:
    items: list[MechanismValidation]
    engines: tuple[str, ...]
    started: str
    seconds: float
    versions: dict[str, str]
    runner: dict[str, Any] = field(default_factory=dict)  # how the tasks ran (vloop.runner settings)
    outcomes: list[Outcome] | None = None  # with a dataset: every mechanism's few numbers (items: those shown)

    @property
    def passed(self) -> bool:
        if self.outcomes is not None:
            return all(o.passed for o in self.outcomes)
        return all(it.passed for it in self.items)

    @property
    def red(self) -> bool:
        if self.outcomes is not None:
            return any(o.red for o in self.outcomes if not o.error)
        return any(it.red for it in self.items if not it.error)

    @property
    def bad_input(self) -> bool:
        if self.outcomes is not None:
            return any(o.error for o in self.outcomes)
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
    cpu0 = time.process_time()
    run = _run_engine(name, mech)
    run.cpu_seconds = time.process_time() - cpu0
    return run


def _run_engine(name: str, mech: Mechanism) -> EngineRun:
    if not engine_applies(name, mech):
        return EngineRun(name, "skipped", message="no closed form for this structure")
    t0 = time.perf_counter()
    try:
        res = engine(name).run(mech)
        budget = res.meta.get("budget")
        note = (
            f"compared on the first {budget['samples']} of {budget['of']} samples (its budget of "
            f"{budget['max_steps']} integration steps of the {budget['planned_steps']} planned)"
            if budget
            else ""
        )
        return EngineRun(name, "ok", res, note, seconds=time.perf_counter() - t0)
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


def _budgeted(r: EngineRun) -> bool:
    """Whether the run covers the first samples only, by design (a time integration's step budget)."""
    return r.status == "ok" and r.result is not None and bool(r.result.meta.get("budget"))


def _extent(r: EngineRun) -> str:
    if _budgeted(r):
        return f"ran the first {r.samples} (its step budget)"
    return f"stopped after {r.samples}" if r.status == "stopped" else f"ran all {r.samples}"


def conditioning(runs: Iterable[EngineRun]) -> np.ndarray | None:
    """Per sample, the largest Jacobian condition number the runs report (health "cond"); None if none does."""
    reported = [r.result.health for r in runs if r.result is not None]
    conds = [np.asarray(h["cond"], float) for h in reported if "cond" in h]
    if not conds:
        return None
    n = max(len(c) for c in conds)
    return np.max([np.pad(c, (0, n - len(c))) for c in conds], axis=0)


def check(
    a: EngineRun, b: EngineRun, mech_name: str, tol: Tolerance | None = None, kappa: np.ndarray | None = None
) -> CheckedComparison | None:
    """Compare run ``a`` against reference run ``b`` under the stated tolerance (or ``tol``), plus the
    conditioning floor (tolerances.conditioning_floor) of the largest condition number at each sample of the
    two engines' own (each engine's error grows with its formulation's) and of ``kappa``, the configuration's
    (vloop's, in the loops' own coordinates: what a closed form, which reports none, suffers from too)."""
    if a.status == "skipped" or b.status == "skipped" or (tol is None and (a.engine, b.engine) not in TOLERANCES):
        return None
    tol = tol or tolerance(a.engine, b.engine)
    if a.result is None or b.result is None:
        missing = a if a.result is None else b
        return CheckedComparison(
            a.engine, b.engine, None, 0, False, f"{missing.engine} gave no result: {missing.message}", tol.rtol
        )
    n = min(a.samples, b.samples)
    msg = ""
    passed = True
    prefix = (_budgeted(a) and a.samples <= b.samples) or (_budgeted(b) and b.samples <= a.samples)
    if not prefix and (a.status != b.status or abs(a.samples - b.samples) > 1):
        if a.status == "stopped" or b.status == "stopped":
            # two runs into a limit may end a sample apart; a run cut by its step budget claims no end of its own
            alike = a.status == b.status or _budgeted(a) or _budgeted(b)
            passed = abs(a.samples - b.samples) <= 1 and alike
            if not passed:
                msg = f"{a.engine} {_extent(a)} samples, {b.engine} {_extent(b)}"
    if a.status == "stopped" or b.status == "stopped":
        # Approaching a limit position every rate grows without bound and every engine's conditioning
        # with it (a time integrator's most of all): compare the first 90 % of what both solved.
        n = max(int(0.9 * (n - 1)), 0)
    own = conditioning((a, b))
    if own is not None:
        kappa = own if kappa is None else np.maximum(own[: len(kappa)], kappa[: len(own)])
    floor_t = conditioning_floor(kappa[:n]) if kappa is not None and len(kappa) >= n else None
    if floor_t is not None and "vloop" not in (a.engine, b.engine):
        # two references, each held to the bound against vloop, may differ by the sum (triangle inequality):
        # otherwise a mechanism where every engine agrees with vloop could still have no majority
        floor_t = {g: 2.0 * v for g, v in floor_t.items()}
    atol_t = _allowances(a.result, b.result, n)
    cmp = compare(a.result.head(n), b.result.head(n), tol.rtol, floor=tol.floor, floor_t=floor_t, atol_t=atol_t)
    if not cmp.passed:
        passed = False
        msg = "; ".join(filter(None, [msg, cmp.message(limit=3).replace("\n", "; ")]))
    if passed and prefix:
        msg = f"within tolerance on the first {n} samples ({(a if _budgeted(a) else b).engine}'s step budget)"
    return CheckedComparison(a.engine, b.engine, cmp, n, passed, msg or "within tolerance", tol.rtol)


def _allowances(a: Result, b: Result, n: int) -> dict[str, np.ndarray] | None:
    """The error bounds both engines report per sample and group (Result.meta["allowance"]), added up."""
    out: dict[str, np.ndarray] = {}
    for res in (a, b):
        for g, arr in (res.meta.get("allowance") or {}).items():
            arr = np.asarray(arr, float)[:n]
            out[g] = out[g] + arr if g in out else arr
    return out or None


def _checks(item: MechanismValidation, engines: tuple[str, ...]) -> None:
    """Compare every engine with every reference run (vloop, then the closed form)."""
    kappa = conditioning([item.runs["vloop"]]) if "vloop" in item.runs else None
    for ref in REFERENCES:
        if ref not in item.runs:
            continue
        for name in engines:
            if name == ref or name not in item.runs:
                continue
            c = check(item.runs[name], item.runs[ref], item.name, kappa=kappa)
            if c is not None:
                item.checks.append(c)


def expectation(item: MechanismValidation) -> dict[str, Any] | None:
    """What a generated file's sidecar promises, checked against every engine's run.

    Every engine that ran must return exactly the expected number of samples: all of them for a run
    clear of limits, the recorded stop sample K for a run into a limit (computed by the generator from
    the closed-form limit angle, not by running an engine), with the status to match; and where the
    generator says a closed form exists, the analytic engine must not be skipped. One exception, vloop's
    documented refusal (:func:`refused_before_limit`): its last samples before a limit, where the
    independent engines' own conditioning puts its velocity error bound above the accuracy it was asked for.
    """
    side = item.corpus
    if not side or "expect" not in side:
        return None
    want = int(side["expect"]["samples"])
    stop = side["expect"].get("stop_sample")
    problems, observed, partial, refused = [], {}, [], {}
    for name, r in item.runs.items():
        observed[name] = r.samples if r.status in ("ok", "stopped") else None
        if _budgeted(r) and r.samples <= (stop if stop is not None else want):
            partial.append(name)  # the first samples only, by design: nothing to check against the count
            continue
        if r.status == "skipped":
            if name == "analytic" and side.get("closed_form"):
                problems.append("analytic skipped, but the family has a closed form")
            continue
        if r.status == "error":
            continue  # reported as the engine's failure already
        if r.samples != want or (r.status == "stopped") != (stop is not None):
            why = refused_before_limit(item, name, want) if stop is not None else ""
            if why:
                refused[name] = why
                continue
            what = f"stop at sample {stop}" if stop is not None else f"run all {want} samples"
            problems.append(f"{name} {_extent(r)} samples, expected to {what}")
    return {
        "samples": want,
        "stop_sample": stop,
        "observed": observed,
        "partial": partial,
        "refused": refused,
        "passed": not problems,
        "message": "; ".join(problems) or "; ".join(["as expected", *refused.values()]),
    }


def refused_before_limit(item: MechanismValidation, name: str, stop: int) -> str:
    """Why vloop's stop before the generator's stop sample is its documented refusal, or "" if it is not.

    vloop refuses a sample whose velocities' error bound κ²·ε exceeds the accuracy asked of it (``rtol`` in its
    Result's meta); next to a limit κ grows without bound, so the last samples before the limit may be refused
    though they assemble. The refusal is accepted when, at every refused sample, each independent kinematic
    engine that solved it reports a condition number of its own constraint Jacobian (unit-free, as vloop's)
    with κ²·ε above that rtol: their evidence, not vloop's; vloop's message must give that bound as its reason.
    Any other early stop stays a failure."""
    run = item.runs.get(name)
    if name != "vloop" or run is None or run.status != "stopped" or run.result is None or run.samples >= stop:
        return ""
    if "cond²·ε" not in run.message:  # vloop stopped for another reason than its accuracy bound
        return ""
    rtol = float(run.result.meta.get("rtol", 0.0))
    kappas = []
    for other in ("pinocchio", "exudyn-kinematic"):
        o = item.runs.get(other)
        cond = None if o is None or o.result is None else o.result.health.get("cond")
        if cond is not None and len(cond) >= stop:
            kappas.append(np.asarray(cond, float)[run.samples : stop])
    if rtol <= 0 or not kappas:
        return ""
    kappa = np.min(kappas, axis=0)
    if not np.all(kappa**2 * EPS > rtol):
        return ""
    return (
        f"vloop refused samples {run.samples}-{stop - 1} before the limit (its velocity bound κ²·ε above rtol = "
        f"{rtol:g}): the independent engines' own κ there is {float(np.min(kappa)):.3g} or more "
        f"(κ²·ε ≥ {float(np.min(kappa)) ** 2 * EPS:.2g})"
    )


def _cross_checks(item: MechanismValidation) -> None:
    """Every pair of engines not compared yet, under the pair's tolerance (tolerances.pair_tolerance)."""
    done = {frozenset((c.engine, c.reference)) for c in item.checks}
    names = [e for e in ENGINES if e in item.runs and item.runs[e].status != "skipped"]
    kappa = conditioning([item.runs["vloop"]]) if "vloop" in item.runs else None
    for i, ref in enumerate(names):
        for name in names[i + 1 :]:
            if frozenset((name, ref)) not in done:
                c = check(item.runs[name], item.runs[ref], item.name, pair_tolerance(name, ref), kappa)
                if c is not None:
                    item.checks.append(c)


def verdict(item: MechanismValidation) -> Verdict:
    """Who is the odd one out (validators.consensus): all engines are compared pairwise once any disagree."""
    voters = [e for e, r in item.runs.items() if r.status != "skipped"]
    skipped = [e for e, r in item.runs.items() if r.status == "skipped"]
    if item.passed:
        return decide(voters, {}, skipped, item.inconclusive)
    _cross_checks(item)
    against = {(c.engine, c.reference): c.message for c in item.checks if not c.passed}
    exp = item.expectation
    if exp is not None and not exp["passed"]:
        want = exp["stop_sample"] if exp["stop_sample"] is not None else exp["samples"]
        refused = exp.get("refused", {})
        met = {
            e: n == want or e in refused
            for e, n in exp["observed"].items()
            if n is not None and e not in exp.get("partial", ())
        }
        for a, b in itertools.combinations(met, 2):
            if met[a] != met[b]:
                odd = a if not met[a] else b
                why = f"{odd} returned {exp['observed'][odd]} samples, the generator expects {want}"
                against.setdefault((a, b), why)
        if met and not any(met.values()) and not against:
            v = decide(voters, {}, skipped)
            v.status, v.reason = "undecided", f"every engine agrees, but not with the generator: {exp['message']}"
            return v
    return decide(voters, against, skipped, item.inconclusive)


def _second_looks(item: MechanismValidation, engines: tuple[str, ...], suspects: set[str]) -> None:
    """Each suspect reference engine (blamed or undecided by a first verdict) looks again at its own run
    (engines.Engine.second_look): a better run replaces its first and the comparisons are made again; an engine
    that finds by its own evidence that it cannot resolve the mechanism is inconclusive on it. vloop, the engine
    under test, gets no second look. Then the verdict again."""
    redo, stuck = False, {}
    for name in sorted(suspects - {"vloop"}):
        run = item.runs.get(name)
        if run is None or run.result is None or item.mechanism is None or run.status not in ("ok", "stopped"):
            continue
        try:
            look = engine(name).second_look(item.mechanism, run.result, run.status == "stopped")
        except Exception as exc:  # a second look that fails leaves the first run as it was, and says so
            run.message = "; ".join(filter(None, [run.message, f"second look failed: {type(exc).__name__}: {exc}"]))
            continue
        if look is None:
            continue
        run.message = "; ".join(filter(None, [run.message, look.note]))
        if look.result is not None:  # a run that stopped and stops again where it did keeps its status
            same_stop = run.status == "stopped" and len(look.result) == run.samples
            run.result, run.status, redo = look.result, "stopped" if same_stop else "ok", True
            if same_stop:
                stuck[name] = f"it stops before sample {run.samples} at every step it tried ({look.note})"
        elif look.inconclusive:
            item.inconclusive[name] = look.inconclusive
    if redo:
        item.checks = []
        _checks(item, engines)
        item.expectation = expectation(item)
    item.verdict = verdict(item)
    # still blamed for a stop it makes at every step, where the others go on (a change point its integrator cannot
    # cross): its own step rejections say it cannot resolve the mechanism; it does not say the others are wrong
    further = {
        n: max((r.samples for e, r in item.runs.items() if e != n and r.status == "ok"), default=0) for n in stuck
    }
    stopped_early = {
        n: why
        for n, why in stuck.items()
        if item.verdict.engines.get(n) == "blamed" and further[n] > item.runs[n].samples + 1
    }
    if stopped_early:
        item.inconclusive.update(stopped_early)
        item.verdict = verdict(item)


def _finalize(item: MechanismValidation, engines: tuple[str, ...], keep_results: bool) -> None:
    item.runs = {e: item.runs[e] for e in engines if e in item.runs}
    _checks(item, engines)
    item.expectation = expectation(item)
    item.verdict = verdict(item)
    suspects = {e for e, s in item.verdict.engines.items() if s in ("blamed", "undecided")} - {"vloop"}
    if suspects and not item.passed:
        _second_looks(item, engines, suspects)
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


@dataclass
class Task:
    """One mechanism to validate, where a worker runs it: the file (loaded there unless ``mechanism`` is given),
    the engines, the dataset folder its comparisons go to (None: the whole validation comes back), and whether a
    failure comes back whole for the report (its Results) or as a few numbers."""

    index: int
    path: str
    engines: tuple[str, ...]
    dataset: str | None = None
    keep: bool = True
    mechanism: Mechanism | None = None
    corpus: dict[str, Any] | None = None
    keep_results: bool = False


@dataclass
class Outcome:
    """What the main process keeps of a mechanism whose comparisons are in the dataset: a few numbers, and the whole
    validation when the report shows it (a file of the catalog, a failure)."""

    index: int
    name: str
    passed: bool
    red: bool
    error: str
    seconds: float
    item: MechanismValidation | None = None


def mechanism_task(task: Task) -> MechanismValidation | Outcome:
    """One task of a validation run (what a Dask worker executes): every engine on one mechanism, the comparisons,
    the verdict (with the reference engines' second looks); with a dataset, its file written and an Outcome back."""
    t0 = time.perf_counter()
    item = _loaded(task)
    if item.mechanism is not None:
        for name in task.engines:
            item.runs[name] = run_engine(name, item.mechanism)
        _finalize(item, task.engines, keep_results=task.keep_results or task.dataset is not None)
    if task.dataset is None:
        return item
    write_item(Path(task.dataset), task.index, item)
    shown = task.keep and (item.corpus is None or not item.passed)
    if not shown:
        for r in item.runs.values():
            r.drop_result()
    keep = item if shown else None
    return Outcome(task.index, item.name, item.passed, item.red, item.error, time.perf_counter() - t0, keep)


def write_item(root: Path, index: int, item: MechanismValidation) -> Path:
    """A validated mechanism's file of the dataset: its comparisons sample by sample, its summary entry."""
    from . import dataset

    pairs = []
    for c in item.checks:
        a, b = item.runs[c.engine].result, item.runs[c.reference].result
        if c.comparison is not None and a is not None and b is not None:
            pairs.append((c.engine, c.reference, a, b, c.samples))
    family = (item.corpus or {}).get("family", "catalog")
    rows = dataset.sample_columns(index, item.name, pairs)
    return dataset.write_task(root, index, family, rows, mechanism_entry(item))


def _loaded(task: Task) -> MechanismValidation:
    """The task's mechanism (read from its file unless given) and its corpus sidecar; a bad file: its error."""
    from validators.corpus import read_sidecar

    path = Path(task.path)
    if task.mechanism is not None:
        return MechanismValidation(str(path), task.mechanism.name, task.mechanism, corpus=task.corpus)
    try:
        mech = vloop.load(path)
        side = read_sidecar(path)
    except VloopError as exc:
        return MechanismValidation(str(path), path.stem, None, error=str(exc))
    return MechanismValidation(str(path), mech.name, mech, corpus=side)


def _lost(task: Task, error: str, seconds: float, worker: str) -> MechanismValidation:
    """A task that gave nothing back (its worker died, it timed out): every engine's error, judged as such."""
    item = (
        _loaded(task)
        if task.mechanism is None
        else MechanismValidation(task.path, task.mechanism.name, task.mechanism, corpus=task.corpus)
    )
    if item.mechanism is not None:
        for e in task.engines:
            item.runs[e] = EngineRun(e, "error", None, error, seconds, worker=worker)
        _finalize(item, task.engines, keep_results=False)
    return item


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
    items: list[MechanismValidation] | None = None,
    dataset: str | Path | None = None,
    skip: Iterable[int] = (),
    shown: int | None = None,
) -> Validation:
    """Validate every mechanism file with every engine, each mechanism one task of vloop.runner (its engines, its
    comparisons and its verdict where it runs).

    In this process by default; ``workers=N`` on a local Dask cluster of N processes, ``scheduler=ADDRESS`` on a
    running one. A task that fails, crashes its worker or passes ``timeout`` [s] gives every engine of its mechanism
    that error. ``progress`` gets one line per finished mechanism; ``bar`` as :func:`vloop.runner.run_tasks`'s
    ``progress``.

    Without ``dataset`` every validation comes back whole (Results of generated files that pass are dropped once
    compared, ``keep_results=False``). With ``dataset`` (a folder) each worker writes its mechanism's file there
    (:mod:`validators.dataset`) and sends back an :class:`Outcome`; ``Validation.items`` then holds only what a
    report shows — the files that are not generated, and the first ``shown`` generated failures — and
    ``Validation.outcomes`` one Outcome per mechanism: memory does not grow with the corpus. ``skip``: task
    numbers already in the dataset (a resumed run). ``items``: the files already loaded by :func:`load_items`.
    """
    from vloop.runner import run_tasks

    engines = tuple(engines)
    for e in engines:
        if e not in ENGINES:
            raise MechanismError(f"unknown engine '{e}' (known: {', '.join(ENGINES)})", entry="engines")
    started = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    t0 = time.perf_counter()
    tasks = _tasks(paths, engines, items, dataset, keep_results)
    skipped = set(skip)
    todo = [t for t in tasks if t.index not in skipped]
    state = _Gather(tasks, engines, progress, shown, dataset is not None)
    run_tasks(
        mechanism_task,
        todo,
        scheduler=scheduler,
        workers=workers,
        timeout=timeout,
        progress=bar,
        on_done=lambda out: state.done(todo[out.index], out),
        label="validate",
    )
    mode = "scheduler" if scheduler else "local-cluster" if workers else "in-process"
    runner = {"mode": mode, "workers": workers, "scheduler": scheduler, "timeout": timeout, "tasks": len(todo)}
    runner["resumed"] = len(tasks) - len(todo)
    v = Validation(state.items(), engines, started, time.perf_counter() - t0, versions(), runner)
    if dataset is not None:
        v.outcomes = state.outcomes
    return v


def _tasks(
    paths: Iterable[str | Path],
    engines: tuple[str, ...],
    items: list[MechanismValidation] | None,
    dataset: str | Path | None,
    keep_results: bool,
) -> list[Task]:
    """One task per file: in memory, the files loaded here (as before); with a dataset, paths only (the worker loads
    its file: nothing per mechanism is held here)."""
    root = None if dataset is None else str(dataset)
    if items is None and root is not None:
        return [Task(k, str(p), engines, root) for k, p in enumerate(paths)]
    items = load_items(paths) if items is None else items
    return [
        Task(k, it.path, engines, root, mechanism=it.mechanism, corpus=it.corpus, keep_results=keep_results)
        if it.mechanism is not None
        else Task(k, it.path, engines, root)
        for k, it in enumerate(items)
    ]


class _Gather:
    """The main process's side of a run: each finished task's validation (in memory) or Outcome (with a dataset)."""

    def __init__(self, tasks: list[Task], engines: tuple[str, ...], progress: Any, shown: int | None, streamed: bool):
        self.tasks, self.engines, self.progress, self.streamed = tasks, engines, progress, streamed
        self.shown = shown
        self.whole: dict[int, MechanismValidation] = {}
        self.outcomes: list[Outcome] = []
        self.generated_shown = 0

    def done(self, task: Task, out: Any) -> None:
        value = out.value if out.ok else None
        out.value = None  # the runner keeps its outcomes: nothing heavy in them
        if value is None:
            value = _lost(task, out.error or "no result", out.seconds, out.worker)
            if self.streamed:
                write_item(Path(task.dataset), task.index, value)  # type: ignore[arg-type]
                value = Outcome(task.index, value.name, value.passed, value.red, value.error, out.seconds, value)
        item = value.item if isinstance(value, Outcome) else value
        if isinstance(value, Outcome):
            self.outcomes.append(dataclasses.replace(value, item=None))
        if item is not None:
            for r in item.runs.values():
                r.worker, r.task_seconds = r.worker or out.worker, r.task_seconds or out.seconds
            if self._keep(item):
                self.whole[task.index] = item
        if self.progress:
            self.progress(_done_line(value if item is None else item, out.seconds))

    def _keep(self, item: MechanismValidation) -> bool:
        if not self.streamed or item.corpus is None:
            return True
        if self.shown is not None and self.generated_shown >= self.shown:
            return False
        self.generated_shown += 1
        return True

    def items(self) -> list[MechanismValidation]:
        return [self.whole[k] for k in sorted(self.whole)]


def _done_line(x: Any, seconds: float) -> str:
    """One progress line per mechanism: its name, pass / red / which engines failed, the task's time."""
    what = "pass" if x.passed else "RED" if x.red else "failed (not red)"
    what = "error: " + x.error[:120] if x.error else what
    if isinstance(x, Outcome):
        return f"{x.name}: {what} in {seconds:.2f} s"
    bad = [f"{e} {r.status}" for e, r in x.runs.items() if r.status in ("error", "stopped")]
    return f"{x.name}: {what} in {seconds:.2f} s" + (f" ({', '.join(bad)})" if bad else "")


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


def mechanism_entry(it: MechanismValidation) -> dict[str, Any]:
    """One mechanism's entry of summary.json: its runs, every comparison with every quantity's errors, the verdict."""
    entry: dict[str, Any] = {"name": it.name, "file": it.path, "passed": it.passed}
    if it.error:
        entry["error"] = it.error
        entry.update(samples=None, loops=None, mobility=None, runs={}, comparisons=[])
        return entry
    m = it.mechanism
    L, J, M = m.gruebler()
    entry.update(samples=len(m.times), loops=J - L + 1, mobility=M, red=it.red)
    entry["runs"] = {
        name: {
            "status": r.status,
            "samples": r.samples,
            "seconds": r.seconds,
            "message": r.message,
            "worker": r.worker,
            "task_seconds": r.task_seconds,
            "cpu_seconds": r.cpu_seconds,
        }
        for name, r in it.runs.items()
    }
    if it.corpus is not None:
        entry["corpus"] = _corpus_entry(it)
    entry["comparisons"] = [_comparison_entry(c) for c in it.checks]
    if it.verdict is not None:
        entry["verdict"] = it.verdict.as_dict()
    return entry


def summary_head(v: Validation) -> dict[str, Any]:
    """summary.json's fields before the mechanisms."""
    return {
        "schema": SCHEMA,
        "created": v.started,
        "seconds": v.seconds,
        "passed": v.passed,
        "red": v.red,
        "engines": list(v.engines),
        "versions": v.versions,
        "tolerances": {f"{a} vs {b}": t.as_dict() for (a, b), t in TOLERANCES.items()},
    }


def to_summary(v: Validation) -> dict[str, Any]:
    """The machine-readable summary (documented by validators/summary.schema.json)."""
    tally = Tally(v.engines)
    mechs = []
    for it in v.items:
        mechs.append(mechanism_entry(it))
        tally.add(mechs[-1])
    out = summary_head(v) | {"mechanisms": mechs} | tally.fields()
    if v.runner:
        out["runner"] = v.runner
    return out


class Tally:
    """The summary's counts, gathered one mechanism entry at a time (memory: the counts and the names of the red
    and the blamed ones), so that a summary can be written while its entries stream past."""

    def __init__(self, engines: Iterable[str]) -> None:
        self.engines = tuple(engines)
        self.per_engine = tally((), self.engines)
        self.status: dict[str, int] = {}
        self.vloop_blamed: list[str] = []
        self.red: list[str] = []
        self.n = self.passed = 0
        self.seeds: set[int] = set()
        self.families: dict[str, int] = {}
        self.generated = self.limit_runs = 0

    def add(self, entry: dict[str, Any]) -> None:
        self.n += 1
        self.passed += bool(entry["passed"])
        v = entry.get("verdict")
        if v is not None:
            for e, st in v["engines"].items():
                self.per_engine.setdefault(e, dict.fromkeys(STATUSES, 0))[st] += 1
            self.status[v["status"]] = self.status.get(v["status"], 0) + 1
            if "vloop" in v["blamed"]:
                self.vloop_blamed.append(entry["name"])
        if entry.get("red"):
            self.red.append(entry["name"])
        c = entry.get("corpus")
        if c is not None:
            self.generated += 1
            self.seeds.add(int(c["seed"]))
            key = f"{c['family']}/{c.get('variant', '')}"
            self.families[key] = self.families.get(key, 0) + 1
            self.limit_runs += (c.get("expect") or {}).get("stop_sample") is not None

    def fields(self) -> dict[str, Any]:
        """The summary's fields after the mechanisms: verdicts, counts, and the corpus's when there is one."""
        out: dict[str, Any] = {
            "verdicts": {
                "engines": self.per_engine,
                "mechanisms": dict(sorted(self.status.items())),
                "vloop_blamed": self.vloop_blamed,
                "red": self.red,
            },
            "counts": {"mechanisms": self.n, "passed": self.passed, "red": len(self.red)},
        }
        if self.generated:
            out["corpus"] = {
                "seeds": sorted(self.seeds),
                "mechanisms": self.generated,
                "families": dict(sorted(self.families.items())),
                "limit_runs": self.limit_runs,
            }
        return out


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


def comparison_table(summary: dict[str, Any], rows: list[dict[str, Any]] | None = None) -> Any:
    """The rows of :func:`comparison_rows` (or ``rows``, made by it) as a pandas DataFrame with fixed columns and
    dtypes."""
    import pandas as pd

    df = pd.DataFrame(comparison_rows(summary) if rows is None else rows, columns=list(TABLE_COLUMNS))
    for col in ("corpus_seed", "corpus_index", "samples"):
        df[col] = df[col].astype("Int64")
    for col in ("engine_seconds", "max_abs", "max_rel", "rms", "t_at_max", "peak", "allowed", "ratio"):
        df[col] = df[col].astype("float64")
    for col in ("mechanism_passed", "comparison_passed", "passed"):
        df[col] = df[col].astype("boolean")
    return df


def write_table(
    summary: dict[str, Any], path: str | Path, fmt: str = "parquet", rows: list[dict[str, Any]] | None = None
) -> Path:
    """Write the comparison table as ``fmt`` ("parquet" or "csv", vloop.files.writers.write_table): errors in the
    quantity's unit (see summary.json), times in s, ratios unitless; a non-finite error is a null."""
    from vloop.files.writers import write_table as write

    units = {"engine_seconds": "s", "t_at_max": "s", "max_rel": "1", "ratio": "1"}
    units.update(dict.fromkeys(("max_abs", "rms", "peak", "allowed"), "the quantity's"))
    return write(comparison_table(summary, rows), path, fmt, units, {"schema": SCHEMA})


def write_parquet(summary: dict[str, Any], path: str | Path) -> Path:
    """Write the comparison table as Parquet (pyarrow; ``pip install 'vloop[parquet]'``)."""
    return write_table(summary, path, "parquet")
