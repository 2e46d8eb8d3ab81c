"""Shrink a failing generated mechanism to a simpler file that still fails, as hypothesis shrinks.

A generated mechanism is a pure function of its Spec (:func:`validators.corpus.build`): a flat dict of
numbers (lengths, pivot positions, axis angles, ω, α, sample counts). Shrinking edits those numbers
toward simpler ones and keeps an edit when the rebuilt file *still fails the same way* (the same
engine-vs-reference comparison, engine error or expectation fails), the way hypothesis shrinks the
choices behind a failing example:

1. fewer samples: ``n`` (and a limit run's ``k_stop``/``n_after``) halved while it still fails;
2. every other number, one at a time: 0 where zero is a legal value (pivot position, offsets, α),
   else the same number with 1, then 2, then 3 significant digits — the first that still fails wins.

Passes repeat until a whole pass changes nothing or the budget is spent (``max_tries`` rebuilt files
that were validated, ``seconds`` of wall time). Structural choices (family, variant, branch signs,
which link a dyad hangs on) are never changed, and a rebuild that does not satisfy its variant
(:class:`validators.corpus.Infeasible`) is skipped without counting as a try. "Simpler" is measured by
:func:`complexity`: significant digits over all numbers, then samples.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterable
from dataclasses import dataclass, replace
from typing import Any

from validators import corpus

from . import harness

ZEROABLE = ("x0", "y0", "alpha", "alpha_b", "px", "py", "cy", "hy1", "hy2", "tip_n")
FIXED = ("sigma", "dir", "n_attach", "kind1", "kind2", "host1", "host2", "host2_1", "host2_2", "perm")
COUNTS = ("n", "k_stop", "n_after")
CHEAP_ENGINES = ("vloop", "analytic", "pinocchio", "exudyn-kinematic")


def digits(x: float) -> int:
    """Significant digits needed to write ``x`` exactly (0 for zero)."""
    if x == 0 or not math.isfinite(x):
        return 0
    for d in range(1, 18):
        if float(f"{x:.{d}g}") == x:
            return d
    return 17


def complexity(params: dict[str, float]) -> tuple[int, int]:
    """(significant digits of every shrinkable number, samples): smaller is simpler."""
    return sum(digits(v) for k, v in params.items() if k not in FIXED + COUNTS), int(params.get("n", 0))


def signature(item: harness.MechanismValidation) -> set[str]:
    """What fails in a validated mechanism: "ENGINE vs REFERENCE", "ENGINE error", "expectation"."""
    out = {f"{c.engine} vs {c.reference}" for c in item.checks if not c.passed}
    out |= {f"{r.engine} error" for r in item.runs.values() if r.status == "error"}
    if item.expectation is not None and not item.expectation["passed"]:
        out.add("expectation")
    return out


def engines_of(sig: Iterable[str], engines: Iterable[str]) -> tuple[str, ...]:
    """The engines needed to see a failure signature again (those it names, plus the references)."""
    named = {w for s in sig for w in s.replace(" vs ", " ").replace(" error", "").split() if w in harness.ENGINES}
    if any(s == "expectation" for s in sig):
        named |= set(engines)
    return tuple(e for e in engines if e in named)


@dataclass
class Shrunk:
    """The smallest still-failing Item found, how it differs from the original, and what it cost."""

    item: corpus.Item
    original: corpus.Spec
    tries: int
    seconds: float
    failure: set[str]
    before: tuple[int, int]
    after: tuple[int, int]

    @property
    def changed(self) -> dict[str, list[float]]:
        new = self.item.spec.params
        return {k: [v, new[k]] for k, v in self.original.params.items() if new.get(k) != v}


def _candidates(key: str, value: float) -> list[float]:
    if key in COUNTS:
        floor = {"n": 20, "k_stop": 10, "n_after": 3}[key]
        half = max(floor, int(value) // 2)
        return [float(half)] if half < value else []
    out = [0.0] if key in ZEROABLE and value != 0 else []
    out += [float(f"{value:.{d}g}") for d in (1, 2, 3) if d < digits(value)]
    return [c for c in dict.fromkeys(out) if c != value]


def still_fails(item: corpus.Item, engines: tuple[str, ...], target: set[str]) -> set[str]:
    """The part of ``target`` that the rebuilt ``item`` still shows (empty: it passes now)."""
    v = harness.validate_mechanism(item.name, engines, mechanism=item.mechanism, corpus=item.sidecar)
    return signature(v) & target


def shrink(
    spec: corpus.Spec,
    failure: set[str],
    engines: Iterable[str],
    *,
    max_tries: int = 40,
    seconds: float = 60.0,
) -> Shrunk | None:
    """Shrink ``spec`` while the rebuilt file still shows part of ``failure``; None if nothing can be run."""
    engines = engines_of(failure, engines)
    if not engines:
        return None
    t0 = time.perf_counter()
    best = corpus.build(spec)
    tries, builds = 0, 0
    improved = True
    while improved and tries < max_tries and time.perf_counter() - t0 < seconds:
        improved = False
        keys = [k for k in COUNTS if k in best.spec.params]
        keys += sorted(k for k in best.spec.params if k not in FIXED + COUNTS)
        for key in keys:
            for cand in _candidates(key, best.spec.params[key]):
                if tries >= max_tries or time.perf_counter() - t0 >= seconds or builds > 20 * max_tries:
                    break
                params = {**best.spec.params, key: cand}
                if complexity(params) >= complexity(best.spec.params):
                    continue
                builds += 1
                try:
                    item = corpus.build(replace(best.spec, params=params))
                except corpus.Infeasible:
                    continue
                tries += 1
                if still_fails(item, engines, failure):
                    best, improved = item, True
                    break
    kept = still_fails(best, engines, failure) if best.spec is not spec else failure
    return Shrunk(
        best,
        spec,
        tries,
        time.perf_counter() - t0,
        kept,
        complexity(spec.params),
        complexity(best.spec.params),
    )


def minimized_sidecar(sh: Shrunk) -> dict[str, Any]:
    """The minimized file's sidecar: as generated, plus where it came from and what was changed."""
    side = dict(sh.item.sidecar)
    side["minimized_from"] = {"seed": sh.original.seed, "index": sh.original.index, "params": sh.original.params}
    side["changed"] = sh.changed
    side["reproduce"] = f"vloop validate {sh.item.name}-min.toml"
    return side
