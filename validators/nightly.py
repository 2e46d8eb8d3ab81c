"""Nightly runs: a dated output folder and a comparison with the previous run's summary.json.

A quantity is flagged when its error crossed its tolerance (passed before, fails now) or grew
by more than ``GROWTH`` times. Errors far below their tolerance are round-off and jitter
between library versions, so growth is measured on max(error, NOISE × allowed): a quantity at
1e-16 that moves to 1e-15 is not news; one that moves from 1e-12 to 1e-10 of a 1e-9 tolerance is.
An engine that ran before and fails now, and a comparison that disappeared, are flagged too.
"""

from __future__ import annotations

import datetime as _dt
import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

GROWTH = 10.0
NOISE = 1e-4  # fraction of the allowed error below which changes are not flagged


def dated_folder(root: Path, now: _dt.datetime | None = None) -> Path:
    """root/YYYY-MM-DD, or root/YYYY-MM-DD-HHMMSS if that exists already."""
    now = now or _dt.datetime.now()
    p = root / now.strftime("%Y-%m-%d")
    if p.exists():
        p = root / now.strftime("%Y-%m-%d-%H%M%S")
    return p


def previous_summary(root: Path, current: Path) -> Path | None:
    """The newest summary.json under ``root`` from another run folder than ``current``."""
    cands = (
        [
            p / "summary.json"
            for p in root.iterdir()
            if p.is_dir() and p.resolve() != current.resolve() and (p / "summary.json").exists()
        ]
        if root.exists()
        else []
    )
    return max(cands, key=lambda p: p.parent.name, default=None)


def _key(m: dict[str, Any]) -> str:
    """A mechanism's identity across nights: its name, and for a generated one its seed (names repeat per seed)."""
    c = m.get("corpus")
    return f"{m['name']}@seed{c['seed']}" if c else m["name"]


def _index(summary: dict[str, Any]) -> dict[tuple[str, str, str, str], dict[str, Any]]:
    out = {}
    for m in summary.get("mechanisms", []):
        for c in m.get("comparisons", []):
            for q in c.get("quantities", []):
                out[(_key(m), c["engine"], c["reference"], q["quantity"])] = q
    return out


def _err(q: dict[str, Any]) -> float:
    v = q["max_abs"]
    return float("inf") if isinstance(v, str) else float(v)


def compare_summaries(current: dict[str, Any], previous: dict[str, Any]) -> list[dict[str, Any]]:
    """Flags (one dict each: mechanism, engine, reference, quantity, kind, before, after, message)."""
    flags: list[dict[str, Any]] = []
    cur, prev = _index(current), _index(previous)
    for key, q in cur.items():
        p = prev.get(key)
        if p is None:
            continue
        mech, engine, ref, quantity = key
        before, after = _err(p), _err(q)
        floor = NOISE * float(q["allowed"])
        if p["passed"] and not q["passed"]:
            kind = "crossed tolerance"
        elif max(after, floor) > GROWTH * max(before, floor):
            kind = f"grew more than {GROWTH:g}x"
        else:
            continue
        flags.append(
            {
                "mechanism": mech,
                "engine": engine,
                "reference": ref,
                "quantity": quantity,
                "kind": kind,
                "before": before,
                "after": after,
                "allowed": q["allowed"],
                "message": (
                    f"{mech}: {engine} vs {ref}: {quantity} {kind} "
                    f"({before:.3g} -> {after:.3g}, allowed {q['allowed']:.3g})"
                ),
            }
        )
    prev_runs = {(_key(m), e): r for m in previous.get("mechanisms", []) for e, r in m.get("runs", {}).items()}
    for m in current.get("mechanisms", []):
        for e, r in m.get("runs", {}).items():
            before = prev_runs.get((_key(m), e))
            if before is not None and before["status"] in ("ok", "stopped") and r["status"] == "error":
                flags.append(
                    {
                        "mechanism": m["name"],
                        "engine": e,
                        "reference": "",
                        "quantity": "",
                        "kind": "engine failed",
                        "before": before["status"],
                        "after": r["status"],
                        "allowed": 0.0,
                        "message": f"{m['name']}: {e} ran before and fails now: {r['message'][:200]}",
                    }
                )
    return flags


def load_summary(path: Path) -> dict[str, Any]:
    return json.loads(Path(path).read_text(encoding="utf-8"))


# ------------------------------------------------------------------ generated corpus: reproduce and minimize


def corpus_command(seed: int, n: int, start: int = 0, options: str = "") -> str:
    """The command that regenerates a corpus (mechanism i depends on (seed, i) only)."""
    first = f" --start {start}" if start else ""
    return f"vloop corpus --seed {seed} --n {n}{first}{options} --out corpus-{seed}"


def reproduce_command(seed: int, index: int, engines: Iterable[str], options: str = "") -> str:
    """One command that regenerates mechanism ``index`` of corpus ``seed`` and validates it with ``engines``."""
    return (
        f"vloop validate --corpus 1 --corpus-start {index} --seed {seed}{options} "
        f"--engines {','.join(engines)} --out validation-{seed}-{index}"
    )


def corpus_failures(summary: dict[str, Any], engines: Iterable[str], options: str = "") -> list[dict[str, Any]]:
    """Every failing generated mechanism with the one command that reproduces it."""
    engines = list(engines)
    out = []
    for m in summary.get("mechanisms", []):
        c = m.get("corpus")
        if c is None or m["passed"]:
            continue
        msgs = [f"{x['engine']} vs {x['reference']}: {x['message']}" for x in m["comparisons"] if not x["passed"]]
        msgs += [f"{e}: {r['message']}" for e, r in m["runs"].items() if r["status"] == "error"]
        if c["expect"] and not c["expect"].get("passed", True):
            msgs.append(c["expect"]["message"])
        out.append(
            {
                "mechanism": m["name"],
                "file": m["file"],
                "family": f"{c['family']}/{c.get('variant', '')}",
                "reproduce": reproduce_command(int(c["seed"]), int(c["index"]), engines, options),
                "message": "; ".join(msgs)[:2000],
            }
        )
    return out


def minimize_failures(
    items: Iterable[Any],
    engines: Iterable[str],
    out: Path,
    *,
    max_items: int = 5,
    max_tries: int = 40,
    seconds: float = 60.0,
) -> list[dict[str, Any]]:
    """Shrink each failing generated mechanism (cheap engines only) and write NAME-min.toml (+ .json) into ``out``.

    ``items`` are the harness's MechanismValidation objects. A failure that needs Exudyn's dynamic mode
    to show is not minimized (too slow to repeat); at most ``max_items`` failures are shrunk.
    """
    from validators.corpus import Spec
    from vloop.files.output import write_text

    from . import shrink

    engines = tuple(engines)
    done: list[dict[str, Any]] = []
    for it in items:
        if it.corpus is None or it.passed or it.error:
            continue
        if len(done) >= max_items:
            break
        failure = shrink.signature(it)
        needed = shrink.engines_of(failure, engines)
        entry: dict[str, Any] = {"mechanism": it.name, "file": "", "tries": 0, "still_failing": ""}
        if not needed or any(e not in shrink.CHEAP_ENGINES for e in needed):
            done.append({**entry, "skipped": "needs an expensive engine (exudyn-dynamic) to show"})
            continue
        result = shrink.shrink(Spec.from_dict(it.corpus), failure, engines, max_tries=max_tries, seconds=seconds)
        if result is None:
            done.append({**entry, "skipped": "no engine to run"})
            continue
        path = out / f"{it.name}-min.toml"
        write_text(path, result.item.text)
        write_text(path.with_suffix(".json"), json.dumps(shrink.minimized_sidecar(result), indent=1, allow_nan=False))
        done.append(
            {
                **entry,
                "file": str(path),
                "tries": result.tries,
                "seconds": result.seconds,
                "still_failing": ", ".join(sorted(result.failure)),
                "changed": result.changed,
                "complexity": [*result.before, *result.after],
            }
        )
    return done
