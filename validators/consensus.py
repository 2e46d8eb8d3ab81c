"""The odd engine out: a disagreement on one mechanism attributed by the consensus of the engines.

    verdict = decide(["vloop", "analytic", "pinocchio"], {("analytic", "vloop"): "…", ("analytic", "pinocchio"): "…"})
    verdict.status, verdict.blamed        # "blamed", ("analytic",)

The voters are the engines that had something to say about the mechanism (a closed form that does
not apply is not a voter; an engine that crashed is one, and disagrees with every other). Two voters
disagree when their comparison fails (validators.harness.check: an error beyond the pair's tolerance, or
a run that stops where the other does not), or when exactly one of them returns the number of samples
the corpus generator recorded.

The engines to blame are the smallest set whose removal leaves engines that all agree with each other
(a minimum vertex cover of the disagreements). It is blamed when it is the only such set of that size,
and the engines left are at least two and more than the blamed ones (a strict majority): then only the
blamed engines failed on this mechanism, each with its reason. Otherwise the mechanism is undecided,
and every engine in a disagreement is undecided on it (two engines that disagree, or three that all
disagree with each other, cannot say who is right). An engine whose tolerance is too loose to tell
(Exudyn's time integration next to a wrong vloop) neither accuses nor excuses: only disagreements count.

An engine that found by its own means (its own error estimate, step rejections, conditioning — never
another engine's answer) that it cannot resolve the mechanism is *inconclusive* on it: it is not a voter,
its disagreements do not count, and the reason is kept. A mechanism whose voters are then fewer than two
is inconclusive as a whole (nothing is left to compare).

Red (:attr:`Verdict.red`) means vloop may be wrong: vloop blamed, or no majority (undecided). A reference
engine blamed by engines that agree with vloop, or inconclusive, is reported but is not red
(docs/validation.md: the exit policy).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

PASS, BLAMED, UNDECIDED, INCONCLUSIVE = "pass", "blamed", "undecided", "inconclusive"
STATUSES = (PASS, BLAMED, UNDECIDED, INCONCLUSIVE, "skipped")


@dataclass
class Verdict:
    """A mechanism's verdict: "pass", "blamed" (only ``blamed`` failed), "undecided" or "inconclusive" (fewer than
    two engines could resolve it); per engine its own, and why each inconclusive engine could not resolve it."""

    status: str
    blamed: tuple[str, ...] = ()
    reason: str = ""
    engines: dict[str, str] = field(default_factory=dict)  # engine -> "pass" | "blamed" | "undecided" | "skipped"
    reasons: dict[str, str] = field(default_factory=dict)  # blamed engine -> why
    inconclusive: dict[str, str] = field(default_factory=dict)  # inconclusive engine -> its own reason

    @property
    def red(self) -> bool:
        """Whether vloop may be wrong here: vloop blamed, or no majority to tell."""
        return self.status == UNDECIDED or "vloop" in self.blamed

    def as_dict(self) -> dict[str, Any]:
        return {
            "status": self.status,
            "blamed": list(self.blamed),
            "reason": self.reason,
            "engines": dict(self.engines),
            "reasons": dict(self.reasons),
            "inconclusive": dict(self.inconclusive),
            "red": self.red,
        }


def _pair(a: str, b: str) -> tuple[str, str]:
    return (a, b) if a < b else (b, a)


def _covers(voters: list[str], edges: set[tuple[str, str]]) -> list[tuple[str, ...]]:
    """Every smallest set of voters that touches every disagreement (brute force: five engines at most)."""
    for k in range(len(voters) + 1):
        found = [s for s in itertools.combinations(voters, k) if all(a in s or b in s for a, b in edges)]
        if found:
            return found
    return []


def decide(
    voters: Iterable[str],
    disagreements: Mapping[tuple[str, str], str],
    skipped: Iterable[str] = (),
    inconclusive: Mapping[str, str] | None = None,
) -> Verdict:
    """The verdict from the voters and their disagreements ((engine, engine) -> what differs); ``inconclusive``:
    the engines that said they cannot resolve the mechanism (engine -> their reason), which do not vote."""
    unsure = {e: why for e, why in (inconclusive or {}).items() if e in voters}
    verdict = _decide([v for v in voters if v not in unsure], disagreements, skipped)
    verdict.engines.update(dict.fromkeys(unsure, INCONCLUSIVE))
    verdict.inconclusive = dict(unsure)
    if unsure and len(voters) - len(unsure) < 2:
        verdict.status, verdict.blamed, verdict.reasons = INCONCLUSIVE, (), {}
        verdict.reason = "fewer than two engines could resolve it: " + "; ".join(f"{e}: {w}" for e, w in unsure.items())
        verdict.engines.update({e: PASS for e in voters if e not in unsure})
    return verdict


def _decide(voters: list[str], disagreements: Mapping[tuple[str, str], str], skipped: Iterable[str]) -> Verdict:
    engines = dict.fromkeys(skipped, "skipped")
    reasons_by_pair: dict[tuple[str, str], str] = {}
    for (a, b), why in disagreements.items():
        if a in voters and b in voters and a != b:
            reasons_by_pair.setdefault(_pair(a, b), why)
    if not reasons_by_pair:
        return Verdict(PASS, engines={**engines, **dict.fromkeys(voters, PASS)})
    edges = set(reasons_by_pair)
    covers = _covers(voters, edges)
    left = len(voters) - len(covers[0])
    if len(covers) == 1 and left >= 2 and left > len(covers[0]):
        blamed = covers[0]
        reasons = {e: _accusation(e, voters, blamed, reasons_by_pair) for e in blamed}
        engines.update({e: BLAMED if e in blamed else PASS for e in voters})
        return Verdict(BLAMED, blamed, "; ".join(reasons.values()), engines, reasons)
    involved = {e for pair in edges for e in pair}
    engines.update({e: UNDECIDED if e in involved else PASS for e in voters})
    pairs = ", ".join(f"{a} vs {b}" for a, b in sorted(edges))
    why = (
        f"no majority: {pairs} disagree"
        + (f" ({len(voters)} engines)" if len(voters) > 2 else " (two engines cannot tell which is right)")
        + f": {reasons_by_pair[min(edges)]}"
    )
    return Verdict(UNDECIDED, (), why, engines)


def _accusation(engine: str, voters: list[str], blamed: tuple[str, ...], reasons: Mapping[tuple[str, str], str]) -> str:
    """Why ``engine`` is blamed: whom it disagrees with (who agree with each other), and the first difference."""
    against = [v for v in voters if v not in blamed and _pair(engine, v) in reasons]
    others = [v for v in voters if v not in blamed]
    agree = "which agree with each other" if len(others) > 1 else "the only other engine"
    first = reasons[_pair(engine, against[0])]
    return f"{engine} disagrees with {', '.join(against)} ({agree}): {first}"


def tally(verdicts: Iterable[Verdict], engines: Iterable[str]) -> dict[str, dict[str, int]]:
    """Per engine: how many mechanisms it passed, was blamed on, was undecided or inconclusive on, was skipped on."""
    out = {e: dict.fromkeys(STATUSES, 0) for e in engines}
    for v in verdicts:
        for e, s in v.engines.items():
            out.setdefault(e, dict.fromkeys(STATUSES, 0))[s] += 1
    return out
