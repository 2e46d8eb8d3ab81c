"""Whether a function y = f(x), given as its parsed expression, is defined and bounded over a whole range.

Found from the expression, not from samples: interval arithmetic over pieces of the range (every node of the
expression tree evaluated to an interval that contains its values over the piece), each node checking its own
domain — a denominator or a negative power's base that may be zero, tan's argument crossing an odd multiple of
π/2, log's argument ≤ 0, sqrt's or a fractional power's base < 0, asin's or acos's argument outside [−1, 1],
an overflow. A piece where every node's interval proves its domain is cleared; a piece where a node's argument
is continuous (its subtree cleared there) and its values at the piece's ends and middle lie on both sides of a
forbidden value (intermediate value theorem), or where a value at those points is undefined, holds a proven
fault; the rest are halved and checked again, down to the resolution of a double. What cannot be cleared is
refused too (a double root of a denominator, 1/(x − 1.5)**2, is a pole that never changes sign).
"""

from __future__ import annotations

import ast
import math
from dataclasses import dataclass

import numpy as np

from ..errors import SynthesisError

PIECES = 64  # the range's first split
MAX_PIECES = 4096  # pieces kept per level: more is an expression no interval will clear (sin(1/x) near 0)
LEVELS = 64  # halvings: a piece 2^-64 of the range is below a double's resolution
HALF_PI = 0.5 * math.pi


@dataclass
class _Iv:
    """A node over m pieces: the interval [lo, hi] of its values, its values at each piece's (start, middle, end)
    ``pts`` (m, 3), whether it is proven defined, finite and continuous on the piece (``ok``), whether it is
    proven undefined or unbounded somewhere in it (``bad``), and why (``why``)."""

    lo: np.ndarray
    hi: np.ndarray
    pts: np.ndarray
    ok: np.ndarray
    bad: np.ndarray
    why: np.ndarray


def check_bounded(tree: ast.AST, x0: float, xf: float, text: str, entry: str = "f") -> None:
    """SynthesisError naming the x where f is undefined or unbounded on [x0, xf] (or cannot be shown bounded)."""
    lo, hi = min(x0, xf), max(x0, xf)
    edges = np.linspace(lo, hi, PIECES + 1)
    a, b = edges[:-1], edges[1:]
    for _ in range(LEVELS):
        with np.errstate(all="ignore"):
            iv = _node(tree, a, b)
        if iv.bad.any():
            k = int(np.argmax(iv.bad))
            x, why = _locate(tree, a[k], b[k])
            raise SynthesisError(
                f"{entry}: f(x) = {text.strip()!r:.60} is not defined or not bounded over x in [{lo:g}, {hi:g}]: "
                f"{why} at x = {x:.7g}",
                entry=entry,
            )
        keep = ~iv.ok & (b > a)
        if not keep.any():
            return
        a, b = a[keep][:MAX_PIECES], b[keep][:MAX_PIECES]
        mid = 0.5 * (a + b)
        a, b = np.concatenate([a, mid]), np.concatenate([mid, b])
    x = 0.5 * (a[0] + b[0])
    raise SynthesisError(
        f"{entry}: f(x) = {text.strip()!r:.60} cannot be shown bounded over x in [{lo:g}, {hi:g}]: near x = {x:.7g} "
        "it may have a pole (a denominator or a log's argument touching zero) — give a range that keeps clear of it",
        entry=entry,
    )


def _locate(tree: ast.AST, a: float, b: float) -> tuple[float, str]:
    """The fault in piece [a, b], narrowed by halving while one half still proves it."""
    with np.errstate(all="ignore"):
        why = str(_node(tree, np.array([a]), np.array([b])).why[0])
        for _ in range(LEVELS):
            m = 0.5 * (a + b)
            iv = _node(tree, np.array([a, m]), np.array([m, b]))
            if iv.bad[0]:
                b, why = m, str(iv.why[0])
            elif iv.bad[1]:
                a, why = m, str(iv.why[1])
            else:
                break
        ends = np.array([a, 0.5 * (a + b), b])
        undefined = ~np.isfinite(_point(tree, ends))
    return (float(ends[undefined][0]) if undefined.any() else 0.5 * (a + b)), why


def _point(tree: ast.AST, x: np.ndarray) -> np.ndarray:
    from .expression import evaluate

    return evaluate(tree, x)


def _node(node: ast.AST, a: np.ndarray, b: np.ndarray) -> _Iv:
    m = len(a)
    if isinstance(node, ast.Constant) or (isinstance(node, ast.Name) and node.id != "x"):
        from .expression import CONSTANTS

        v = float(node.value) if isinstance(node, ast.Constant) else CONSTANTS[node.id]
        c = np.full(m, v)
        return _Iv(c, c.copy(), np.full((m, 3), v), np.ones(m, bool), np.zeros(m, bool), np.full(m, "", object))
    if isinstance(node, ast.Name):
        pts = np.stack([a, 0.5 * (a + b), b], 1)
        return _Iv(a.copy(), b.copy(), pts, np.ones(m, bool), np.zeros(m, bool), np.full(m, "", object))
    if isinstance(node, ast.UnaryOp):
        v = _node(node.operand, a, b)
        if isinstance(node.op, ast.USub):
            return _Iv(-v.hi, -v.lo, -v.pts, v.ok, v.bad, v.why)
        return v
    if isinstance(node, ast.BinOp):
        return _binary(node, _node(node.left, a, b), _node(node.right, a, b))
    assert isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
    return _call(node.func.id, _node(node.args[0], a, b))


def _finish(lo, hi, pts, ok, bad, why, cond_ok, cond_bad, reason: str) -> _Iv:
    """A node's result: proven where its children and its own condition are, with a finite interval; a fault
    where a child's is, its own condition is broken, or a value at a point is not finite."""
    new = cond_bad | ~np.all(np.isfinite(pts), axis=1)
    why = np.where(bad | ~new, why, np.where(cond_bad, reason, "the value overflows or is undefined"))
    ok = ok & cond_ok & np.isfinite(lo) & np.isfinite(hi) & ~new
    return _Iv(lo, hi, pts, ok, bad | new, why)


def _both(*ivs: _Iv) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    ok = np.logical_and.reduce([v.ok for v in ivs])
    bad = np.logical_or.reduce([v.bad for v in ivs])
    why = ivs[0].why
    for v in ivs[1:]:
        why = np.where(ivs[0].bad, why, v.why)
    return ok, bad, why


def _product(lo1, hi1, lo2, hi2) -> tuple[np.ndarray, np.ndarray]:
    c = np.stack([lo1 * lo2, lo1 * hi2, hi1 * lo2, hi1 * hi2])
    return np.min(c, axis=0), np.max(c, axis=0)


def _nonzero(v: _Iv) -> tuple[np.ndarray, np.ndarray]:
    """(proven nonzero on the piece, proven zero somewhere in it) of a denominator or a negative power's base."""
    cond_ok = (v.lo > 0) | (v.hi < 0)
    crosses = v.ok & (np.min(v.pts, axis=1) < 0) & (np.max(v.pts, axis=1) > 0)
    return cond_ok, np.any(v.pts == 0, axis=1) | crosses


def _binary(node: ast.BinOp, L: _Iv, R: _Iv) -> _Iv:
    ok, bad, why = _both(L, R)
    true, false = np.ones(len(ok), bool), np.zeros(len(ok), bool)
    if isinstance(node.op, ast.Add):
        return _finish(L.lo + R.lo, L.hi + R.hi, L.pts + R.pts, ok, bad, why, true, false, "")
    if isinstance(node.op, ast.Sub):
        return _finish(L.lo - R.hi, L.hi - R.lo, L.pts - R.pts, ok, bad, why, true, false, "")
    if isinstance(node.op, ast.Mult):
        lo, hi = _product(L.lo, L.hi, R.lo, R.hi)
        return _finish(lo, hi, L.pts * R.pts, ok, bad, why, true, false, "")
    if isinstance(node.op, ast.Div):
        cond_ok, cond_bad = _nonzero(R)
        lo, hi = _product(L.lo, L.hi, 1.0 / R.hi, 1.0 / R.lo)
        return _finish(lo, hi, L.pts / R.pts, ok, bad, why, cond_ok, cond_bad, "a denominator is zero (a pole)")
    return _power(L, R, ok, bad, why)


def _power(L: _Iv, R: _Iv, ok, bad, why) -> _Iv:
    """base ** exponent: an integer exponent over any base (a negative one: the base must not be zero), a
    fractional one over a base ≥ 0 (> 0 when negative), a varying one over a base > 0."""
    p = float(R.lo[0]) if len(R.lo) and np.all(R.lo == R.hi) and np.all(R.lo == R.lo[0]) else None
    pts = np.power(L.pts, R.pts)
    if p is not None and p == int(p) and abs(p) < 2**53:
        n = int(p)
        a, b = np.power(L.lo, abs(n)), np.power(L.hi, abs(n))
        if n % 2 == 0:
            straddle = (L.lo < 0) & (L.hi > 0)
            lo, hi = np.where(straddle, 0.0, np.minimum(a, b)), np.maximum(a, b)
        else:
            lo, hi = a, b
        if n >= 0:
            return _finish(lo, hi, pts, ok, bad, why, np.ones_like(ok), np.zeros_like(ok), "")
        cond_ok, cond_bad = _nonzero(L)
        return _finish(1.0 / hi, 1.0 / lo, pts, ok, bad, why, cond_ok, cond_bad, "a negative power of zero (a pole)")
    if p is not None:
        cond_ok = L.lo > 0 if p < 0 else L.lo >= 0
        cond_bad = np.any(L.pts <= 0 if p < 0 else L.pts < 0, axis=1)
        a, b = np.power(np.maximum(L.lo, 0.0), p), np.power(np.maximum(L.hi, 0.0), p)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        reason = "a negative fractional power of a number ≤ 0" if p < 0 else "a fractional power of a negative number"
        return _finish(lo, hi, pts, ok, bad, why, cond_ok, cond_bad, reason)
    cond_ok, cond_bad = L.lo > 0, np.any(L.pts <= 0, axis=1)
    lnlo, lnhi = np.log(np.maximum(L.lo, 1e-300)), np.log(np.maximum(L.hi, 1e-300))
    lo, hi = _product(lnlo, lnhi, R.lo, R.hi)
    return _finish(np.exp(lo), np.exp(hi), pts, ok, bad, why, cond_ok, cond_bad, "a power of a base ≤ 0")


def _call(name: str, v: _Iv) -> _Iv:
    from .expression import FUNCTIONS

    pts = FUNCTIONS[name](v.pts)
    true, false = np.ones(len(v.lo), bool), np.zeros(len(v.lo), bool)
    if name in ("sin", "cos"):
        lo, hi = _periodic(v.lo, v.hi, 0.0 if name == "cos" else HALF_PI)
        return _finish(lo, hi, pts, v.ok, v.bad, v.why, true, false, "")
    if name == "tan":
        k = np.floor((v.lo - HALF_PI) / math.pi)
        cond_ok = (k == np.floor((v.hi - HALF_PI) / math.pi)) & (v.hi - v.lo < math.pi)
        kp = np.floor((v.pts - HALF_PI) / math.pi)
        cond_bad = v.ok & (np.min(kp, axis=1) != np.max(kp, axis=1))
        return _finish(np.tan(v.lo), np.tan(v.hi), pts, v.ok, v.bad, v.why, cond_ok, cond_bad,
                       "tan's argument is an odd multiple of π/2 (a pole)")  # fmt: skip
    domains = {
        "log": (v.lo > 0, np.any(v.pts <= 0, axis=1), "log of a number ≤ 0"),
        "sqrt": (v.lo >= 0, np.any(v.pts < 0, axis=1), "square root of a negative number"),
        "asin": ((v.lo >= -1) & (v.hi <= 1), np.any(np.abs(v.pts) > 1, axis=1), "asin of a number outside [-1, 1]"),
    }
    domains.update({k: domains["log"] for k in ("ln", "log10", "log2")})
    domains["acos"] = (domains["asin"][0], domains["asin"][1], "acos of a number outside [-1, 1]")
    cond_ok, cond_bad, reason = domains.get(name, (true, false, ""))
    f = FUNCTIONS[name]
    if name in ("cosh", "abs"):
        straddle = (v.lo < 0) & (v.hi > 0)
        a, b = f(v.lo), f(v.hi)
        lo, hi = np.where(straddle, f(np.zeros_like(v.lo)), np.minimum(a, b)), np.maximum(a, b)
    else:  # monotone: increasing, or decreasing (acos)
        a, b = (
            f(np.clip(v.lo, -1, 1) if name in ("asin", "acos") else v.lo),
            f(np.clip(v.hi, -1, 1) if name in ("asin", "acos") else v.hi),
        )
        lo, hi = np.minimum(a, b), np.maximum(a, b)
    return _finish(lo, hi, pts, v.ok, v.bad, v.why, cond_ok, cond_bad, reason)


def _periodic(lo: np.ndarray, hi: np.ndarray, shift: float) -> tuple[np.ndarray, np.ndarray]:
    """The range of cos(u − shift) for u in [lo, hi] (cos: shift 0; sin: shift π/2)."""
    u0, u1 = lo - shift, hi - shift
    has_max = np.floor(u1 / (2 * math.pi)) >= np.ceil(u0 / (2 * math.pi))
    has_min = np.floor((u1 - math.pi) / (2 * math.pi)) >= np.ceil((u0 - math.pi) / (2 * math.pi))
    a, b = np.cos(u0), np.cos(u1)
    out_lo = np.where(has_min, -1.0, np.minimum(a, b))
    out_hi = np.where(has_max, 1.0, np.maximum(a, b))
    wide = ~np.isfinite(u0) | ~np.isfinite(u1)
    return np.where(wide, -1.0, out_lo), np.where(wide, 1.0, out_hi)
