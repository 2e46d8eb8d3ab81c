"""Nightly runs: a dated output folder and a comparison with the previous run's summary.json.

A quantity is flagged when its error crossed its tolerance (passed before, fails now) or grew
by more than ``GROWTH`` times. Errors far below their tolerance are round-off and jitter
between library versions, so growth is measured on max(error, NOISE × allowed): a quantity at
1e-16 that moves to 1e-15 is not news; one that moves from 1e-12 to 1e-10 of a 1e-9 tolerance is.
An engine that ran before and fails now, and a comparison that disappeared, are flagged too.

A flag is red (it makes the night red) when it may be vloop's: the mechanism's verdict is red now, or the flagged
comparison is between vloop and an engine that passes on the mechanism (not blamed, not inconclusive). A flag
between reference engines, or on an engine blamed or inconclusive now, is reported and is red only with --strict.
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


def _index(summary: dict[str, Any]) -> tuple[dict[tuple[str, str, str, str], dict], dict[tuple[str, str, str], dict]]:
    """The previous night by quantity (where its comparisons list every quantity) and by comparison (where they
    keep only their worst: a summary written from the dataset)."""
    by_q, by_c = {}, {}
    for m in summary.get("mechanisms", []):
        for c in m.get("comparisons", []):
            if c.get("quantities"):
                for q in c["quantities"]:
                    by_q[(_key(m), c["engine"], c["reference"], q["quantity"])] = q
            elif c.get("worst"):
                by_c[(_key(m), c["engine"], c["reference"])] = {**c["worst"], "passed": bool(c.get("passed", True))}
    return by_q, by_c


def _err(q: dict[str, Any]) -> float:
    v = q["max_abs"]
    return float("inf") if isinstance(v, str) else float(v)


def _ratio(q: dict[str, Any]) -> float:
    return _err(q) / max(float(q["allowed"]), 1e-300)


def _flag(
    m: dict[str, Any], c: dict[str, Any], q: dict[str, Any], p: dict[str, Any], by_ratio: bool
) -> dict[str, Any] | None:
    """A flag when ``q`` (now) crossed its tolerance or grew more than GROWTH times against ``p`` (before): errors
    measured above NOISE of the allowance; ``by_ratio``: the comparison's worst, as error over allowance."""
    before, after = (_ratio(p), _ratio(q)) if by_ratio else (_err(p), _err(q))
    floor = NOISE if by_ratio else NOISE * float(q["allowed"])
    passed_now = q.get("passed", _err(q) <= float(q["allowed"])) if not by_ratio else c.get("passed", after <= 1)
    if p["passed"] and not passed_now:
        kind = "crossed tolerance"
    elif max(after, floor) > GROWTH * max(before, floor):
        kind = f"grew more than {GROWTH:g}x"
    else:
        return None
    engine, ref, quantity, mech = c["engine"], c["reference"], q["quantity"], _key(m)
    what = " (of its allowance)" if by_ratio else ""
    return {
        "mechanism": mech,
        "engine": engine,
        "reference": ref,
        "quantity": quantity,
        "kind": kind,
        "before": before,
        "after": after,
        "allowed": 1.0 if by_ratio else q["allowed"],
        "red": _red(m, engine, ref),
        "message": (
            f"{mech}: {engine} vs {ref}: {quantity} {kind} ({before:.3g} -> {after:.3g}{what}, "
            f"allowed {1.0 if by_ratio else q['allowed']:.3g})"
        ),
    }


def _red(m: dict[str, Any] | None, engine: str, reference: str) -> bool:
    """Whether a flag on ``engine`` vs ``reference`` of mechanism ``m`` (its current entry) may be vloop's."""
    verdict = (m or {}).get("verdict") or {}
    if verdict.get("red"):
        return True
    if "vloop" not in (engine, reference):
        return False
    other = reference if engine == "vloop" else engine
    return not other or verdict.get("engines", {}).get(other, "pass") == "pass"


class Previous:
    """The previous night, indexed once (by quantity, by comparison, by run), to flag tonight's entries one by one."""

    def __init__(self, previous: dict[str, Any]) -> None:
        self.by_q, self.by_c = _index(previous)
        self.runs = {(_key(m), e): r for m in previous.get("mechanisms", []) for e, r in m.get("runs", {}).items()}

    def flags(self, m: dict[str, Any]) -> list[dict[str, Any]]:
        """Tonight's entry ``m`` against the previous night: its flags."""
        flags: list[dict[str, Any] | None] = []
        for c in m.get("comparisons", []):
            pc = self.by_c.get((_key(m), c["engine"], c["reference"]))
            if pc is not None and c.get("worst"):
                flags.append(_flag(m, c, c["worst"], pc, by_ratio=True))
                continue
            for q in c.get("quantities") or ():
                p = self.by_q.get((_key(m), c["engine"], c["reference"], q["quantity"]))
                if p is not None:
                    flags.append(_flag(m, c, q, p, by_ratio=False))
        flags += _engine_flags(m, self.runs)
        return [f for f in flags if f is not None]


def compare_summaries(current: dict[str, Any], previous: dict[str, Any]) -> list[dict[str, Any]]:
    """Flags (one dict each: mechanism, engine, reference, quantity, kind, before, after, red, message), in one pass
    over ``current["mechanisms"]`` (any iterable of entries)."""
    prev = Previous(previous)
    return [f for m in current.get("mechanisms", []) for f in prev.flags(m)]


def _engine_flags(m: dict[str, Any], prev_runs: dict[tuple[str, str], dict]) -> list[dict[str, Any]]:
    """An engine that ran before (ok or stopped) and fails now."""
    out = []
    for e, r in m.get("runs", {}).items():
        before = prev_runs.get((_key(m), e))
        if before is not None and before["status"] in ("ok", "stopped") and r["status"] == "error":
            out.append(
                {
                    "mechanism": m["name"],
                    "engine": e,
                    "reference": "",
                    "quantity": "",
                    "kind": "engine failed",
                    "before": before["status"],
                    "after": r["status"],
                    "allowed": 0.0,
                    "red": e == "vloop" or bool((m.get("verdict") or {}).get("red")),
                    "message": f"{m['name']}: {e} ran before and fails now: {r['message'][:200]}",
                }
            )
    return out


MAX_SUMMARY_BYTES = 1 << 30


def load_summary(path: str | Path) -> dict[str, Any]:
    """A previous run's summary.json, checked before it is used: a readable file, UTF-8 JSON with finite numbers
    (no NaN, Infinity or 1e400; integers below 2**63), and the shape :func:`compare_summaries` reads. Anything
    else is a VloopError naming the file and the first field that is wrong."""
    from vloop.errors import VloopError

    where = f"previous summary {path}"
    try:
        data = _read_json(Path(path))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
        raise VloopError(f"{where}: {_why(exc)}", entry="previous") from None
    problem = _summary_problem(data)
    if problem:
        raise VloopError(f"{where}: {problem}", entry="previous")
    return data


def _read_json(path: Path) -> Any:
    if not path.is_file():
        raise OSError(f"{'is a folder' if path.is_dir() else 'does not exist'}; give a summary.json file")
    if path.stat().st_size > MAX_SUMMARY_BYTES:
        raise OSError(f"is larger than {MAX_SUMMARY_BYTES >> 20} MB")
    text = path.read_bytes().decode("utf-8")
    if not text.strip():
        raise ValueError("is empty")
    return json.loads(text, parse_constant=_refuse_constant, parse_float=_finite_float, parse_int=_bounded_int)


class _NotFinite(ValueError):
    pass


def _refuse_constant(name: str) -> float:
    raise _NotFinite(f"holds {name}: numbers must be finite")


def _finite_float(text: str) -> float:
    x = float(text)
    if x != x or x in (float("inf"), float("-inf")):
        raise _NotFinite(f"holds {text[:30]}, too large for a floating-point number")
    return x


def _bounded_int(text: str) -> int:
    if len(text.lstrip("-")) > 19 or abs(int(text)) >= 2**63:
        raise _NotFinite(f"holds the integer {text[:30]}{'...' if len(text) > 30 else ''}, too large")
    return int(text)


def _why(exc: BaseException) -> str:
    if isinstance(exc, UnicodeDecodeError):
        return f"is not UTF-8 text (byte {exc.start})"
    if isinstance(exc, RecursionError):
        return "is nested too deeply to be a summary"
    if isinstance(exc, json.JSONDecodeError):
        return f"is not JSON ({exc.msg}, line {exc.lineno} column {exc.colno})"
    if isinstance(exc, OSError) and exc.errno is None:
        return str(exc)
    if isinstance(exc, OSError):
        return f"cannot be read: {(exc.strerror or str(exc)).lower()}"
    return str(exc)


def _summary_problem(data: Any) -> str:
    """The first field of a summary that is not as written by vloop validate ("" when it is)."""
    if not isinstance(data, dict) or not isinstance(data.get("mechanisms"), list):
        return "is not a vloop validation summary (a JSON object with a 'mechanisms' list)"
    for i, m in enumerate(data["mechanisms"]):
        at = f"mechanisms[{i}]"
        if not isinstance(m, dict) or not isinstance(m.get("name"), str):
            return f"{at}: must be an object with a 'name'"
        c = m.get("corpus")
        if c and not (isinstance(c, dict) and isinstance(c.get("seed"), int) and not isinstance(c["seed"], bool)):
            return f"{at}.corpus: must be an object with an integer 'seed'"
        if not isinstance(m.get("runs", {}), dict) or not isinstance(m.get("comparisons", []), list):
            return f"{at}: 'runs' must be an object and 'comparisons' a list"
        for e, r in m.get("runs", {}).items():
            if not (isinstance(r, dict) and isinstance(r.get("status"), str) and isinstance(r.get("message", ""), str)):
                return f"{at}.runs.{e}: must be an object with a 'status' and a 'message'"
        for k, comp in enumerate(m.get("comparisons", [])):
            problem = _comparison_problem(comp, f"{at}.comparisons[{k}]")
            if problem:
                return problem
    return ""


def _comparison_problem(comp: Any, at: str) -> str:
    if not (isinstance(comp, dict) and isinstance(comp.get("engine"), str) and isinstance(comp.get("reference"), str)):
        return f"{at}: must be an object with an 'engine' and a 'reference'"
    if not isinstance(comp.get("quantities", []), list):
        return f"{at}.quantities: must be a list"
    for j, q in enumerate(comp.get("quantities", [])):
        here = f"{at}.quantities[{j}]"
        if not (isinstance(q, dict) and isinstance(q.get("quantity"), str) and isinstance(q.get("passed"), bool)):
            return f"{here}: must be an object with a 'quantity' and 'passed'"
        err, allowed = q.get("max_abs"), q.get("allowed")
        if err != "inf" and not _number(err, 0.0):
            return f'{here}.max_abs: must be a number ≥ 0 or "inf", got {str(err)[:30]}'
        if not _number(allowed, 0.0):
            return f"{here}.allowed: must be a number ≥ 0, got {str(allowed)[:30]}"
    return ""


def _number(x: Any, lo: float) -> bool:
    return isinstance(x, int | float) and not isinstance(x, bool) and x >= lo


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
        entry = {
            "mechanism": m["name"],
            "file": m["file"],
            "family": f"{c['family']}/{c.get('variant', '')}",
            "reproduce": reproduce_command(int(c["seed"]), int(c["index"]), engines, options),
            "message": "; ".join(msgs)[:2000],
        }
        if "verdict" in m:
            v = m["verdict"]
            entry.update(verdict=v["status"], blamed=v["blamed"], reason=v["reason"][:2000])
        out.append(entry)
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
