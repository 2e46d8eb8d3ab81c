"""The studio's slow work, done away from the message loop: synthesis (vloop.synthesis, in a worker process) and
validation against Pinocchio and Exudyn (``vloop validate`` in a child process: the product never imports the
harness). A job is a picklable callable of plain data; its answer is plain data too."""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import Any

from . import document as docs
from .session import MessageError, Session

# the child lowers its own priority first (no preexec_fn: this runs in a thread), then is `vloop validate`
CHILD = "import os, sys; hasattr(os, 'nice') and os.nice(19); from vloop.cli import main; sys.exit(main(sys.argv[1:]))"
VALIDATE_TIMEOUT = 600.0  # s: the engines' budgets end well before (a four-bar takes ~5 s)
MAX_TARGETS = 8
# the engines' numerical libraries on one thread each: on a small machine a validation leaves the other cores to the
# page and the server (its solves are small; threads would only contend)
ONE_THREAD = {k: "1" for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMEXPR_NUM_THREADS")}


def job(s: Session, msg: dict) -> Callable[[], Any]:
    op = msg.get("op")
    if op == "synthesize":
        return _synthesis_job(s, msg)
    if op == "validate":
        if s.frame.mech is None:
            raise MessageError(f"not yet a mechanism to validate: {s.frame.draft}")
        import vloop

        return functools.partial(validate, vloop.dumps(s.frame.mech), s.frame.mech.name)
    raise MessageError(f"{str(op)[:40]!r} is not slow work")


def finish(s: Session, msg: dict, answer: Any) -> dict[str, Any]:
    if msg["op"] == "validate":
        return {"validation": answer}
    s.candidates = answer["mechanisms"]
    return {"candidates": answer["candidates"], **s.state()}


# ---------------------------------------------------------------- synthesis


def _synthesis_job(s: Session, msg: dict) -> Callable[[], Any]:
    """``kind``: "path" (``points`` [[x, y], ...], 3 to 8), "motion" (``points`` [[x, y, angle], ...], 2 to 5 poses)
    or "function" (``expr`` f(x), ``x_range``, ``input_range`` and ``output_range`` [rad])."""
    kind = msg.get("kind", "path")
    count = msg.get("count", 3)
    if not isinstance(count, int) or isinstance(count, bool) or not 1 <= count <= 8:
        raise MessageError("synthesize: count from 1 to 8")
    units, seed = s.doc.get("units", "m"), int(msg.get("seed", 0)) % 2**31
    if kind == "function":
        expr = msg.get("expr")
        if not isinstance(expr, str) or not 0 < len(expr) <= 200:
            raise MessageError("synthesize: a function f(x) as text, e.g. log10(x)")
        from vloop.synthesis.expression import parse

        parse(expr, entry="synthesize.expr")  # refused here, in one line, before any worker starts (never executed)
        ranges = [_pair(msg.get(k), k) for k in ("x_range", "input_range", "output_range")]
        return functools.partial(synthesize, "function", [expr, *ranges], count, seed, units)
    if kind not in ("path", "motion"):
        raise MessageError("synthesize: kind 'path', 'motion' or 'function'")
    points, width = msg.get("points", s.targets), 3 if kind == "motion" else 2
    if not isinstance(points, list) or not (3 if kind == "path" else 2) <= len(points) <= MAX_TARGETS:
        raise MessageError(f"synthesize: {'3' if kind == 'path' else '2'} to {MAX_TARGETS} targets")
    pts = [[docs.number(v, "target") for v in p] for p in points if isinstance(p, list) and len(p) == width]
    if len(pts) != len(points):
        raise MessageError(f"synthesize: each target is {'[x, y, angle]' if width == 3 else '[x, y]'}")
    s.targets = pts
    return functools.partial(synthesize, kind, pts, count, seed, units)


def _pair(value: Any, what: str) -> list[float]:
    if not isinstance(value, list) or len(value) != 2:
        raise MessageError(f"synthesize: {what} is [from, to]")
    a, b = (docs.number(v, what) for v in value)
    if a == b:
        raise MessageError(f"synthesize: {what} must not be empty")
    return [a, b]


def synthesize(kind: str, points: list, count: int, seed: int, units: str) -> dict[str, Any]:
    """Candidates through ``points`` (path), ``poses`` (motion), or generating f (function: ``points`` is [expr,
    x_range, input_range, output_range]): each as a mechanism file's structure, its error [fraction of the
    targets' size], defects and its tracer's path over the displayed turn."""
    import vloop.synthesis as syn
    from vloop.mechanism import to_dict

    if kind == "path":
        found = syn.path(points, linkage="fourbar", count=count, seed=seed, units=units, name="candidate")
    elif kind == "motion":
        found = syn.motion(points, count=count, units=units, name="candidate")
    else:
        expr, x_range, input_range, output_range = points
        found = syn.function(expr, x_range=tuple(x_range), input_range=tuple(input_range),
                             output_range=tuple(output_range), units=units, name="candidate")  # fmt: skip
    out = []
    for c in list(found)[:count]:
        out.append({
            "name": c.name, "topology": c.topology, "error": float(c.error), "solution": bool(c.solution),
            "grashof": c.grashof, "defects": list(c.defects), "min_transmission": _num(c.min_transmission),
            "tracer": c.tracer, "path": _path(c),
        })  # fmt: skip
    return {"candidates": out, "mechanisms": [to_dict(c.mechanism) for c in list(found)[:count]]}


def _num(x: Any) -> float | None:
    try:
        return float(x)
    except (TypeError, ValueError, OverflowError):
        return None


def _path(c: Any) -> list[list[float]]:
    """The candidate's tracer over its motion (at most 360 points), for the drawing."""
    import numpy as np

    import vloop

    try:
        res = vloop.solve(c.mechanism)
    except vloop.MotionError as exc:
        res = exc.partial
    if res is None or not len(res) or not c.tracer:
        return []
    x, y = res[f"{c.tracer}.x"], res[f"{c.tracer}.y"]
    rows = np.linspace(0, len(x) - 1, min(len(x), 360)).astype(int)
    return [[float(x[k]), float(y[k])] for k in rows]


# ---------------------------------------------------------------- validation


def lower_priority() -> None:
    """Run below the page's own work: a validation or a search yields the processor to dragging (nice 19)."""
    if hasattr(os, "nice"):
        os.nice(19)


def validate(text: str, name: str) -> dict[str, Any]:
    """``vloop validate`` on the drawing in a child process (its own temporary folder): the verdict and each
    engine's status and worst comparison."""
    with tempfile.TemporaryDirectory(prefix="vloop-studio-") as tmp:
        path = Path(tmp) / "studio.toml"
        path.write_text(text, encoding="utf-8")
        out = Path(tmp) / "validation"
        env = {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in sys.path if p), **ONE_THREAD}
        args = ["validate", str(path), "--out", str(out), "--no-report"]
        proc = subprocess.run(
            [sys.executable, "-c", CHILD, *args], capture_output=True, text=True, timeout=VALIDATE_TIMEOUT, env=env,
            cwd=tmp,
        )  # fmt: skip
        summary = out / "summary.json"
        if not summary.is_file():
            tail = (proc.stderr or proc.stdout).strip().splitlines()[-1:] or ["no output"]
            return {"passed": False, "verdict": "not run", "message": tail[0][:500], "engines": []}
        data = json.loads(summary.read_text(encoding="utf-8"))
    return _verdict(data, proc.stdout)


def _verdict(data: dict, stdout: str) -> dict[str, Any]:
    mech = data["mechanisms"][0]
    engines = [{"engine": k, "status": v["status"], "message": v.get("message", "")} for k, v in mech["runs"].items()]
    for c in mech.get("comparisons", []):
        for e in engines:
            if e["engine"] == c["engine"]:
                e.update(passed=bool(c["passed"]), comparison=c.get("message", ""))
    table = [ln for ln in stdout.splitlines() if ln.strip() and not ln.startswith("wrote")][-3:]
    return {"passed": bool(mech["passed"]), "verdict": "pass" if mech["passed"] else "fail", "engines": engines,
            "table": table}  # fmt: skip
