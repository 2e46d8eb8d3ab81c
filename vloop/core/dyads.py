"""Closed-form dyads: a one-loop block of two unknowns solved for every row at once, its rates and its health.

Four kinds (:mod:`vloop.method.structure` classifies them): RRR (two links: the law of cosines), RRP (a link
and a slider along a known direction: a projection), RPR (a slider on a link through a pivot) and PP (two
sliders: linear). The branch σ = ±1 of each row picks one of the two assemblies (fixed at t = 0, flipped where
the run passes a change point); the discriminant h says how far apart the two assemblies lie. Rates by
Cramer's rule on the two Jacobian columns; health: the condition number and the sign of det J.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .accuracy import EPS
from .data import State
from .linalg import cross
from .plans import Plan


def _turning_vector(plan: Plan, state: State, k: slice, a: int, skip: int = -2) -> np.ndarray | complex:
    """W_a: the block's vectors turning with unknown angle a, before rotation (slider ``skip`` left out)."""
    rows = plan.per_row  # constants one per row: taken at rows k
    w: np.ndarray | complex = plan.w_const[a][k] if rows else plan.w_const[a]
    for i, coef in plan.w_sl[a]:
        if i != skip:
            w = w + (coef[k] if rows else coef) * state.s[k, i]
    return w


def _slider_direction(plan: Plan, state: State, k: slice, i: int) -> np.ndarray | complex:
    """U: the unit direction of unknown slider i's vector (a constant for a slider along a ground line)."""
    a, coef = plan.u_dir[i]
    coef = plan.at(coef, k)
    return coef if a < 0 else coef * state.e[k, a]


def _rows_of(x: np.ndarray | complex, n: int) -> np.ndarray:
    """x as an array of n rows (a constant repeated)."""
    return np.broadcast_to(x, (n,))


def closed_form(plan: Plan, state: State, k: slice, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form positions of a one-loop dyad for rows ``k`` on branches ``sigma`` (±1 per row), stored in the
    state (the kind's function in CLOSED_FORMS).

    Returns the mask of assemblable rows and the discriminant h [length²]: the dyad's two
    assembly solutions lie 2·√h apart (h < 0: no solution, the input is past a limit position;
    h = 0: the two branches meet — a toggle, or a change point where they cross).
    """
    X = plan.known_sum.by_column(state, k, "p")[0]  # what the two unknown vectors add up to
    return CLOSED_FORMS[plan.block.kind](plan, state, k, X, sigma)


def _rrr(plan: Plan, state: State, k: slice, X: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two links: W1·E1 + W2·E2 = X, so |W1|, |W2|, |X| form a triangle (the law of cosines)."""
    W1, W2 = _turning_vector(plan, state, k, plan.unk_ang[0]), _turning_vector(plan, state, k, plan.unk_ang[1])
    A2, B2 = np.abs(W1) ** 2, np.abs(W2) ** 2
    D2 = X.real**2 + X.imag**2
    k1 = 0.5 * (A2 + D2 - B2)
    h2 = _round_off_zero(
        A2 * D2 - k1 * k1,
        A2 * D2 + k1 * k1,
        lambda m: (
            (np.broadcast_to(A2, k1.shape)[m] + np.abs(k1[m]))
            * np.sqrt(D2[m])
            * plan.known_magnitude(state, _sub_rows(k, m))
        ),
    )
    ok = (h2 >= 0) & (D2 > 0)
    Dd = np.where(D2 > 0, D2, 1.0)
    P = X * (k1 + 1j * sigma * np.sqrt(np.where(ok, h2, 0.0))) / Dd
    state.set_angle(k, plan.unk_ang[0], P / W1)
    state.set_angle(k, plan.unk_ang[1], (X - P) / W2)
    return ok, h2 / Dd


def _rrp(plan: Plan, state: State, k: slice, X: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A link and a slider: W1·E1 + s·U = X with U a known unit direction, projected on U's normal."""
    i = plan.unk_sl[0]
    Uc = np.conj(_slider_direction(plan, state, k, i))
    W1 = _turning_vector(plan, state, k, plan.unk_ang[0])
    XU, WU = X * Uc, W1 * Uc
    y = XU.imag
    A2 = np.abs(W1) ** 2  # |W1|², per row or one for all
    h = _round_off_zero(A2 - y * y, A2, lambda m: np.abs(y[m]) * plan.known_magnitude(state, _sub_rows(k, m)))
    ok = h >= 0
    c = sigma * np.sqrt(np.where(ok, h, 0.0))
    turned = np.empty(len(y), complex)  # W1·E1·Ū
    turned.real, turned.imag = c, y
    rigid = not plan.w_sl[plan.unk_ang[0]] and plan.u_dir[i][0] < 0  # W1·Ū one number (per variant)
    state.set_angle(k, plan.unk_ang[0], turned * (1.0 / WU) if rigid else turned / WU)
    state.s[k, i] = XU.real - c
    return ok, h


def _rpr(plan: Plan, state: State, k: slice, X: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """A slider on a link through a pivot: (W + s·c)·E = X with c a unit direction fixed to the same link, so
    |W + s·c| = |X|."""
    i, a = plan.unk_sl[0], plan.unk_ang[0]
    cdir = plan.at(plan.u_dir[i][1], k)
    W = _turning_vector(plan, state, k, a, skip=i)
    bb = (W * np.conj(cdir)).real
    D2 = X.real**2 + X.imag**2
    disc = _round_off_zero(
        bb * bb - np.abs(W) ** 2 + D2,
        bb * bb + np.abs(W) ** 2 + D2,
        lambda m: np.sqrt(D2[m]) * plan.known_magnitude(state, _sub_rows(k, m)),
    )
    s = -bb + sigma * np.sqrt(np.where(disc >= 0, disc, 0.0))
    den = W + s * cdir
    ok = (disc >= 0) & (np.abs(den) > 0)
    state.s[k, i] = s
    state.set_angle(k, a, X / np.where(ok, den, 1.0))
    return ok, disc


def _pp(plan: Plan, state: State, k: slice, X: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two sliders: s1·U1 + s2·U2 = X (linear: one solution, no branches, h = ∞)."""
    U1, U2 = (_rows_of(_slider_direction(plan, state, k, i), len(X)) for i in plan.unk_sl[:2])
    det = cross(U1, U2)
    ok = np.abs(det) > 1e-12
    dd = np.where(ok, det, 1.0)
    state.s[k, plan.unk_sl[0]] = cross(X, U2) / dd
    state.s[k, plan.unk_sl[1]] = cross(U1, X) / dd
    return ok, np.full(len(ok), np.inf)


# Each closed-form block kind (vloop.method.structure.classify names it) and its positions. A new kind: its
# function here (positions and discriminant from the known part X); its Jacobian columns follow from its
# unknowns (jacobian_columns: an angle's j·W·e^{jθ}, a slider's direction), so its rates and health too.
CLOSED_FORMS = {"RRR": _rrr, "RRP": _rrp, "RPR": _rpr, "PP": _pp}


def _round_off_zero(h: np.ndarray, size: np.ndarray | float, carried: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """A discriminant whose magnitude is within round-off of the terms it was computed from is zero: the
    two branches meet (an input exactly at a limit or change point, up to round-off). ``size`` bounds the
    terms; ``carried(mask)`` adds, on the rows of ``mask``, the round-off the known part X brings in (large
    for a mechanism far from the origin) — evaluated only on rows whose h is small at all."""
    small = np.abs(h) <= 1e-4 * size
    if not small.any():
        return h
    bound = 16 * EPS * (size[small] if np.ndim(size) else size)  # (size: per row, or one for all rows)
    bound = bound + 16 * EPS * carried(small)
    out = h.copy()
    out[np.nonzero(small)[0][np.abs(h[small]) <= bound]] = 0.0
    return out


def _sub_rows(k: slice | np.ndarray, mask: np.ndarray) -> np.ndarray:
    """The state rows of ``k`` that ``mask`` selects."""
    rows = np.arange(k.start or 0, k.stop)[: len(mask)] if isinstance(k, slice) else np.asarray(k)
    return rows[mask]


def dyad_rates(plan: Plan, state: State, k: slice, what: str, cols: JacobianColumns | None = None) -> np.ndarray:
    """Unknown rates (what="v") or accelerations ("a") of a one-loop block for rows ``k``, by Cramer's rule.

    The unknowns' own rate columns must still be zero: the sum is then the known part.
    """
    R = (plan.vel_sum if what == "v" else plan.total).by_column(state, k, what)[0]  # the known part
    c = cols if cols is not None else jacobian_columns(plan, state, k)
    Rr, Ri = R.real, R.imag  # c1·x1 + c2·x2 = −R
    out = np.empty((len(Rr), 2))
    np.multiply(Ri * c.c2r - Rr * c.c2i, c.inv_det, out=out[:, 0])
    np.multiply(Rr * c.c1i - Ri * c.c1r, c.inv_det, out=out[:, 1])
    return out


@dataclass
class JacobianColumns:
    """The two Jacobian columns of a one-loop block (j·W_a·E_a for an angle, U for a slider) as contiguous real
    and imaginary parts, their cross product det and 1/det, and their squared lengths (one number where the column
    is a constant times a unit e^{jθ}): shared by the health columns and both rates."""

    c1r: np.ndarray
    c1i: np.ndarray
    c2r: np.ndarray
    c2i: np.ndarray
    det: np.ndarray
    inv_det: np.ndarray
    n1: np.ndarray | float
    n2: np.ndarray | float

    def head(self, n: int) -> JacobianColumns:
        """The first n rows (a constant column stays a constant)."""
        return JacobianColumns(
            *(x[:n] if np.ndim(x) else x for x in (getattr(self, f.name) for f in dataclasses.fields(self)))
        )


def jacobian_columns(plan: Plan, state: State, k: slice) -> JacobianColumns:
    """The Jacobian columns of a one-loop (two-unknown) block on rows ``k``."""
    cols, norms = [], []
    for v in plan.block.unknowns:
        if v in plan.unk_ang:
            W = _turning_vector(plan, state, k, v)
            cols.append(1j * W * state.e[k, v])
            norms.append(abs(W) ** 2 if np.ndim(W) == 0 else None)  # |E| = 1: a rigid link's length, squared
        else:  # a slider's direction: a constant along a ground line, a constant times E on a moving one
            i = plan.unk_sl[plan.block.unknowns.index(v) - len(plan.unk_ang)]
            cols.append(_slider_direction(plan, state, k, i))
            norms.append(np.abs(plan.at(plan.u_dir[i][1], k)) ** 2 if plan.per_row else abs(plan.u_dir[i][1]) ** 2)
    n = len(state.e[k])
    if all(np.ndim(c) == 0 for c in cols):  # both constant (two sliders along ground lines): one per row all the same
        cols = [np.full(n, c) for c in cols]
    c1r, c1i, c2r, c2i = (np.ascontiguousarray(x) if np.ndim(x) else float(x) for c in cols for x in (c.real, c.imag))
    det = c1r * c2i - c1i * c2r
    n1 = c1r * c1r + c1i * c1i if norms[0] is None else norms[0]
    n2 = c2r * c2r + c2i * c2i if norms[1] is None else norms[1]
    with np.errstate(divide="ignore"):
        return JacobianColumns(c1r, c1i, c2r, c2i, det, 1.0 / det, n1, n2)


def dyad_health(
    plan: Plan, state: State, k: slice, scale: float, cols: JacobianColumns | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Condition number (angle columns divided by the mechanism size) and det sign per row of a one-loop block."""
    c = cols if cols is not None else jacobian_columns(plan, state, k)
    s1 = 1.0 / scale if plan.block.unknowns[0] in plan.unk_ang else 1.0  # angle columns in lengths: per size
    s2 = 1.0 / scale if plan.block.unknowns[1] in plan.unk_ang else 1.0
    f2 = c.n1 * (s1 * s1) + c.n2 * (s2 * s2)  # σ_max² + σ_min² of the scaled block (one number for most dyads)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        q = f2 / (np.abs(c.det) * (s1 * s2))  # ... over σ_max·σ_min = |det|: κ + 1/κ (∞ where det = 0)
        cond = q * q
        cond -= 4.0
        np.maximum(cond, 0.0, out=cond)
        np.sqrt(cond, out=cond)
        cond += q
        cond *= 0.5  # κ = (q + √(q² − 4))/2
    if not (np.ndim(f2) == 0 and f2 > 0):  # 0/0 where both columns vanish with det: singular too
        cond[c.det == 0] = np.inf
    return cond, np.sign(c.det)
