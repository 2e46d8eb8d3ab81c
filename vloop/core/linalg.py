"""Batched small linear algebra: stacks of small matrices solved, inverted and judged at once.

Row-first stacks (rows, n, n) go to LAPACK one matrix at a time (numpy.linalg: a singular matrix gives NaN
without spoiling the others); batch-last stacks A[i, j, row] are inverted by Gauss–Jordan applied to the whole
stack at once (:func:`invert_last`). Condition numbers: an upper bound on every row, the exact 2-norm one where
the bound reaches the level that decides a flag or a refusal.
"""

from __future__ import annotations

import numpy as np

from .accuracy import EPS, ILL_FRACTION


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Im(conj(a)·b): the 2-D cross product of complex numbers seen as vectors."""
    return a.real * b.imag - a.imag * b.real


def row_max(A: np.ndarray) -> np.ndarray:
    """max over the columns of A (rows, K) for the few columns of a mechanism: an element-wise maximum
    column by column (numpy's reduction along a short last axis costs a loop per row)."""
    if A.shape[1] > 16 or A.shape[1] == 0:
        return np.max(A, axis=1, initial=-np.inf)
    out = A[:, 0].copy()
    for c in range(1, A.shape[1]):
        np.maximum(out, A[:, c], out=out)
    return out


def det_sign(J: np.ndarray) -> np.ndarray:
    """Sign of det J (the assembly branch); a rectangular (redundant) block has no branch sign: +1."""
    if J.shape[-1] == J.shape[-2]:
        return np.sign(np.linalg.det(J))
    return np.ones(J.shape[:-2])


def invert_rows(A: np.ndarray) -> np.ndarray:
    """Inverses of a stack of square matrices; a singular one gives NaN (the others are kept)."""
    try:
        return np.linalg.inv(A)
    except np.linalg.LinAlgError:
        out = np.full(A.shape, np.nan)
        for k in range(len(A)):
            try:
                out[k] = np.linalg.inv(A[k])
            except np.linalg.LinAlgError:
                pass
        return out


def solve_rows(A: np.ndarray, B: np.ndarray) -> np.ndarray:
    """A⁻¹·B for a stack of small systems (B of shape (rows, n)); a row whose A is singular gives NaN."""
    if not len(A):
        return np.zeros(B.shape)
    try:
        return np.linalg.solve(A, B[..., None])[..., 0]
    except np.linalg.LinAlgError:
        X = np.full(B.shape, np.nan)
        for k in range(len(A)):
            try:
                X[k] = np.linalg.solve(A[k], B[k])
            except np.linalg.LinAlgError:
                pass
        return X


def least_squares_rows(J: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """x with J·x = rhs per row: the solve for a square J, the normal equations JᵀJ·x = Jᵀ·rhs for a block
    with more equations than unknowns (redundant constraints; exact when they are consistent); NaN where
    singular. Newton's step is ``least_squares_rows(J, −F)``."""
    if J.shape[-1] != J.shape[-2]:
        Jt = J.transpose(0, 2, 1)
        J, rhs = Jt @ J, (Jt @ rhs[..., None])[..., 0]
    return solve_rows(J, rhs)


def pinv_rows(A: np.ndarray) -> np.ndarray:
    """Inverses (square) or pseudo-inverses (rectangular, by SVD) of a stack; NaN where not finite."""
    out = np.full(A.transpose(0, 2, 1).shape, np.nan)
    finite = np.all(np.isfinite(A), axis=(1, 2))
    if finite.any():
        out[finite] = np.linalg.pinv(A[finite]) if A.shape[1] != A.shape[2] else invert_rows(A[finite])
    return out


def invert_last(A: np.ndarray, out: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Inverses and determinant signs of a stack of square matrices laid out batch-last, A[i, j, row].

    Gauss–Jordan with partial pivoting (the row of largest magnitude, the first of equals: LAPACK's choice),
    each operation applied to the whole stack at once: this beats LAPACK's per-matrix call, whose overhead
    dominates for small matrices (3× on 4,800 6×6; the Jansen pair's 12×12: 8.1 vs 12.6 ms). A singular matrix
    gives non-finite values and sign 0. ``out``: where to write the inverses (may be A itself). Work arrays are
    rows of the stack, never whole stacks: fresh large arrays cost page faults."""
    if out is None:
        out = np.array(A, float)
    elif out is not A:
        np.copyto(out, A)
    return out, _gauss_jordan(out)


def _gauss_jordan(A: np.ndarray) -> np.ndarray:
    """Invert the batch-last stack A in place; returns the determinant signs. Entries zero in every matrix of the
    stack (a block Jacobian's structure: a loop does not see most unknowns) are tracked, and operations on them
    skipped: they would subtract exact zeros (the eight-bar's 6×6 block has 14 nonzeros of 36)."""
    n, N = A.shape[0], A.shape[-1]
    nz = [set(np.nonzero(row)[0].tolist()) for row in np.any(A != 0, axis=-1)]  # NaN ≠ 0: kept
    pivots = []
    neg = np.zeros(N, bool)
    zero = np.zeros(N, bool)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        for k in range(n):
            pivot = _pivot_rows(A, k)
            pivots.append(pivot)
            _swap_pattern(nz, k, *_swap_rows(A, k, pivot))
            piv = A[k, k].copy()
            neg ^= (pivot != k) ^ (piv < 0)
            zero |= piv == 0
            rp = 1.0 / piv
            A[k, k] = 1.0
            nz[k].add(k)
            cols = sorted(nz[k])
            _scale_row(A, k, cols, rp)
            for i in range(n):
                if i != k and k in nz[i]:
                    f = A[i, k].copy()
                    A[i, k] = 0.0
                    _subtract_row(A, i, k, cols, f)
                    nz[i] |= nz[k]
            A[k, k] = rp
    for k in range(n - 1, -1, -1):  # the row swaps undone as column swaps, in reverse
        _swap_rows(A.swapaxes(0, 1), k, pivots[k])
    return np.where(zero, 0.0, np.where(neg, -1.0, 1.0))


def _scale_row(A: np.ndarray, k: int, cols: list[int], r: np.ndarray) -> None:
    if len(cols) == A.shape[1]:
        A[k] *= r
    else:
        for c in cols:
            A[k, c] *= r


def _subtract_row(A: np.ndarray, i: int, k: int, cols: list[int], f: np.ndarray) -> None:
    """A[i] −= f·A[k] on the columns where row k is not structurally zero (one operation on the whole row where
    it is full: a column at a time costs a call each)."""
    if len(cols) > A.shape[1] // 2:
        A[i] -= f * A[k]
    else:
        for c in cols:
            A[i, c] -= f * A[k, c]


def _swap_pattern(nz: list[set[int]], k: int, swapped: list[int], alike: bool) -> None:
    """Row k's structure swapped with that of the rows it was swapped with; where only some matrices swapped,
    every row involved gets the union."""
    if alike:
        for i in swapped:
            nz[k], nz[i] = nz[i], nz[k]
    elif swapped:
        union = set().union(nz[k], *(nz[i] for i in swapped))
        for i in (k, *swapped):
            nz[i] = set(union)


def _pivot_rows(A: np.ndarray, k: int) -> np.ndarray:
    """Per matrix, the row ≥ k of largest |A[i, k]|, the first of equals."""
    a = np.abs(A[k:, k])
    top = a.max(axis=0)
    pivot = np.full(A.shape[-1], A.shape[0] - 1)
    for i in range(len(a) - 2, -1, -1):
        np.copyto(pivot, k + i, where=a[i] == top)
    return pivot


def _swap_rows(A: np.ndarray, k: int, pivot: np.ndarray) -> tuple[list[int], bool]:
    """Swap row k with row pivot[m] of each matrix m (pivot ≥ k): one plain swap when all pivot alike (along a path
    they mostly do), masked swaps row by row otherwise. Returns the rows swapped with k (k left out) and
    whether every matrix swapped alike."""
    first = int(pivot[0])
    if np.all(pivot == first):
        if first != k:
            t = A[k].copy()
            A[k] = A[first]
            A[first] = t
            return [first], True
        return [], True
    swapped = []
    for i in range(k + 1, A.shape[0]):
        m = pivot == i
        if m.any():
            t = A[k].copy()
            np.copyto(A[k], A[i], where=m)
            np.copyto(A[i], t, where=m)
            swapped.append(i)
    return swapped, False


def apply_last(X: np.ndarray, F: np.ndarray) -> np.ndarray:
    """X·F per row of batch-last stacks: X (n, k, rows), F (k, rows)."""
    return np.einsum("ukn,kn->un", X, F)


def condition_last(J: np.ndarray, X: np.ndarray, colscale: np.ndarray, rtol: float) -> np.ndarray:
    """:func:`condition_rows` on batch-last stacks (J and its inverse X, unscaled): an upper bound of the 2-norm
    condition number on every row, the exact one (:func:`_condition_near`) where the bound reaches the flag level,
    so flags and refusals follow the 2-norm rule exactly. The bound: ‖J‖_F·‖J⁻¹‖_F (≤ n× the exact one),
    tightened where it reaches the level to (Σσ⁸)^⅛ of each (≤ n^¼×) by two Gram products."""
    c2 = colscale * colscale
    with np.errstate(invalid="ignore", over="ignore"):
        fj, fx = c2 @ np.einsum("lun,lun->un", J, J), (1.0 / c2) @ np.einsum("uln,uln->un", X, X)
        cond = np.sqrt(fj * fx)
    cond = np.where(np.isfinite(cond), cond, np.inf)
    level = (ILL_FRACTION * rtol / EPS) ** (1 / 3)
    near = np.nonzero(cond > level)[0]
    for lo in range(0, len(near), NEAR_CHUNK):  # in chunks: a few small stacks alive at a time
        rows = near[lo : lo + NEAR_CHUNK]
        cond[rows] = _condition_near(J[:, :, rows], X[:, :, rows], colscale, fj[rows], fx[rows], cond[rows], level)
    return cond


NEAR_CHUNK = 4096  # rows whose condition bound reaches the flag level, refined together


def _condition_near(
    J: np.ndarray, X: np.ndarray, colscale: np.ndarray, fj: np.ndarray, fx: np.ndarray, cond: np.ndarray, level: float
) -> np.ndarray:
    """The Frobenius bound ``cond`` (of J scaled by colscale, ‖·‖_F² = fj, and its inverse X, fx) tightened to
    (Σσ⁸)^⅛ of each; the exact 2-norm condition number where that still reaches the level: σ_max of J and of
    J⁻¹ by :func:`sigma_max` (the Gram matrices' largest eigenvalues, bracketed to 1e-12), :func:`cond_2norm`
    on the rows it cannot bracket or where J is within ~POWER_COND of singular."""
    r = len(fj)
    with np.errstate(invalid="ignore", over="ignore", divide="ignore"):
        # scaled to unit Frobenius norm: the Gram matrices have trace 1, their powers neither overflow nor
        # (the largest eigenvalue) underflow; row-major (rows, ·, ·): numpy's stacked matmul is ~4× faster on those
        Js = np.multiply(J.transpose(2, 0, 1), colscale / np.sqrt(fj)[:, None, None], order="C")
        Xs = np.multiply(X.transpose(2, 0, 1), 1.0 / (colscale[:, None] * np.sqrt(fx)[:, None, None]), order="C")
        G = np.empty((2 * r, *Js.shape[1:]))
        np.matmul(np.ascontiguousarray(Js.transpose(0, 2, 1)), Js, out=G[:r])
        np.matmul(Xs, np.ascontiguousarray(Xs.transpose(0, 2, 1)), out=G[r:])  # X·Xᵀ: the singular values of X
        G2 = G @ G
        u2 = np.sqrt(np.sqrt(sum_squares(G2)))  # (tr G⁴)^¼ ≥ λ_max: (Σσ⁸)^⅛ of J, of J⁻¹
        tight = cond * np.sqrt(u2[:r] * u2[r:])
    frobenius = cond
    cond = np.where(tight < cond, tight, cond)
    exact = np.nonzero(~(cond <= level))[0]
    if not len(exact):
        return cond
    both = np.concatenate([exact, exact + r])
    lam, ok = sigma_max(G[both], G2[both])
    m = len(exact)
    c = frobenius[exact] * np.sqrt(lam[:m] * lam[m:])
    ok = ok[:m] & ok[m:] & (c <= POWER_COND)
    cond[exact[ok]] = c[ok]
    rest = exact[~ok]
    if len(rest):
        cond[rest] = cond_2norm(Js[rest], G[rest])
    return cond


POWER_COND = 1e6  # past this condition number the exact one is taken by SVD, as numpy.linalg.cond would
SQUARINGS = 4  # G¹⁶ ∝ v₁v₁ᵀ + (λ₂/λ₁)¹⁶…: bracketed where λ₂/λ₁ ≲ 0.44 (σ₂/σ₁ ≲ 0.66); others go to cond_2norm
BRACKET = 1e-12  # the largest eigenvalue's upper and lower bounds agree to this (relative)


def sigma_max(G: np.ndarray, G2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The largest eigenvalue λ₁ of each symmetric positive semidefinite G (rows, n, n; trace 1) given G², and
    whether it is bracketed to BRACKET: from below by the Rayleigh quotient of G's dominant column of G¹⁶
    (G¹⁶ ∝ v₁v₁ᵀ + (λ₂/λ₁)¹⁶…: the quotient's error ∝ (λ₂/λ₁)³²), from above by (tr G³²)^(1/32) = ‖G¹⁶‖_F^(1/16)
    (every other term of the trace is ≥ 0). G's powers by repeated squaring: λ₁ ≥ 1/n keeps λ₁¹⁶ far from
    underflow."""
    with np.errstate(invalid="ignore", over="ignore", divide="ignore", under="ignore"):
        P = G2
        for _ in range(SQUARINGS - 1):
            P = P @ P
        upper = sum_squares(P) ** (1 / 2 ** (SQUARINGS + 1))
        d = np.argmax(np.diagonal(P, axis1=1, axis2=2), axis=1)
        v = P[np.arange(len(P)), :, d]  # the dominant column
        lower = np.einsum("ri,ri->r", v, np.einsum("rij,rj->ri", G, v)) / np.einsum("ri,ri->r", v, v)
        ok = (upper - lower <= BRACKET * lower) & (lower > 0)
    return lower, ok


def sum_squares(A: np.ndarray) -> np.ndarray:
    """Σ A² over each matrix of a stack (rows, n, n): ‖A‖_F² (numpy's sum over two short axes is ~3× slower)."""
    return np.einsum("rij,rij->r", A, A)


def svd_cond(A: np.ndarray) -> np.ndarray:
    """2-norm condition numbers of a stack of rectangular matrices by SVD (infinite where not finite)."""
    cond = np.full(len(A), np.inf)
    ok = np.all(np.isfinite(A), axis=(1, 2))
    if ok.any():
        sv = np.linalg.svd(A[ok], compute_uv=False)
        with np.errstate(divide="ignore", invalid="ignore"):
            cond[ok] = sv[:, 0] / sv[:, -1]
    return cond


EIG_COND = 100.0  # up to this condition number the Gram matrix's eigenvalues give it to ~1e-11 (relative)


def cond_2norm(A: np.ndarray, G: np.ndarray | None = None) -> np.ndarray:
    """2-norm condition numbers of a stack of square matrices (rows, n, n), as numpy.linalg.cond's SVD gives
    them: from the eigenvalues of the Gram matrix G = AᵀA (half an SVD's cost; given or computed) where
    λ_min's round-off, ~n·ε·λ_max, stays below ~1e-11 of it (cond ≤ EIG_COND); by SVD where larger;
    infinite where A is not finite."""
    out = np.full(len(A), np.inf)
    ok = np.nonzero(np.all(np.isfinite(A), axis=(1, 2)))[0]
    if not len(ok):
        return out
    A = A[ok]
    lam = np.linalg.eigvalsh(A.transpose(0, 2, 1) @ A if G is None else G[ok])
    with np.errstate(divide="ignore", invalid="ignore"):
        c = np.sqrt(lam[:, -1] / lam[:, 0])
    svd = np.nonzero(~(c <= EIG_COND))[0]
    if len(svd):
        sv = np.linalg.svd(A[svd], compute_uv=False)
        with np.errstate(divide="ignore"):
            c[svd] = np.where(sv[:, -1] > 0, sv[:, 0] / np.where(sv[:, -1] > 0, sv[:, -1], 1.0), np.inf)
    out[ok] = c
    return out


def condition_rows(Js: np.ndarray, Jinv_s: np.ndarray, rtol: float) -> np.ndarray:
    """Condition number of the scaled Jacobians: the Frobenius-norm one ‖J‖_F·‖J⁺‖_F (an upper bound
    of the 2-norm one, at most nu times it) on every row, replaced by the exact 2-norm one (singular
    values) where the bound reaches the level at which a sample is flagged (cond³·ε > ILL_FRACTION·rtol),
    so flags and refusals follow the 2-norm rule exactly while most rows skip the SVD."""
    with np.errstate(invalid="ignore", over="ignore"):
        cond = np.sqrt(np.sum(Js * Js, axis=(1, 2)) * np.sum(Jinv_s * Jinv_s, axis=(1, 2)))
    cond = np.where(np.isfinite(cond), cond, np.inf)
    level = (ILL_FRACTION * rtol / EPS) ** (1 / 3)
    near = np.nonzero(cond > level)[0]
    if len(near):
        sv = np.linalg.svd(Js[near], compute_uv=False)
        with np.errstate(divide="ignore"):
            cond[near] = np.where(sv[:, -1] > 0, sv[:, 0] / np.where(sv[:, -1] > 0, sv[:, -1], 1.0), np.inf)
    return cond
