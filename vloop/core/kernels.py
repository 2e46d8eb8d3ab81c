"""The solver's building blocks: state arrays over the sample grid and the numerics of one block.

Shared by :mod:`vloop.core.solver` (the run: blocks in order, limits, late starts, chunks, the Result),
:mod:`vloop.core.newton` (Newton blocks vectorized over samples) and :mod:`vloop.core.changepoints` (where two
assembly branches meet). See :mod:`vloop.core.solver` for the state's layout and the formulas.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any

import numpy as np

from ..drivers import evaluate_all
from ..method.loops import Block, LoopSystem
from ..model import Mechanism

EPS = float(np.finfo(float).eps)


DEFAULT_RTOL = 1e-9  # accuracy asked of every output, relative (refusals and flags follow it: see _velocity_bound)


ILL_FRACTION = 1e-3  # a kept sample whose error bound exceeds this fraction of rtol is flagged ill-conditioned


TWO_PI = 2.0 * math.pi


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


def _real_reps(G: list[list[complex]] | np.ndarray, K: int) -> tuple[np.ndarray, np.ndarray]:
    """The real (2a, 2K) matrices R of G and of j·G (a rows of K) with ``Z.view(float) @ R == (Z @ G).view(float)``
    for complex Z (n, a): one real BLAS product on the interleaved [Re, Im] view instead of a complex one (half the
    work, no temporaries)."""
    a = len(G)
    B = np.empty((2, a, K), complex)
    B[0] = np.array(G, complex).reshape(a, K)
    np.multiply(1j, B[0], out=B[1])
    F = B.view(float).reshape(2, a, K, 2)  # [Re, Im] of each entry
    R = np.empty((2, a, 2, K, 2))
    R[:, :, 0] = F  # rows 2i: Re, Im of row i interleaved
    np.negative(F[..., 1], out=R[:, :, 1, :, 0])  # rows 2i + 1: −Im, Re
    R[:, :, 1, :, 1] = F[..., 0]
    R = R.reshape(2, 2 * a, 2 * K)
    return R[0], R[1]


SMALL_SUM = 400  # a sum of up to this many terms × columns is built from Python numbers (fewer numpy calls)
_NO_INT, _NO_FLOAT, _NO_COMPLEX = np.zeros(0, int), np.zeros(0), np.zeros(0, complex)


def _columns_of(A: np.ndarray, cols: np.ndarray | None) -> np.ndarray:
    """The state columns ``cols`` of A (all of them, as a view, for None), C-contiguous."""
    return A if cols is None else A.take(cols, axis=1)


def _used(cols: set[int], width: int) -> np.ndarray | None:
    """The state columns a sum reads (None: most of them, read whole rows rather than gather)."""
    return None if 2 * len(cols) > width else np.array(sorted(cols), int)


def _term_lists(sys: LoopSystem) -> tuple[list[int], list[int], list[float], list[complex], np.ndarray]:
    """Every term's angle variable, slider, magnitude and e^{jδ} as Python numbers, and e^{jδ} as an array
    (cached)."""
    if "term_lists" not in sys.cache:
        cd = np.exp(1j * sys.t_delta)
        sys.cache["term_lists"] = (sys.t_ang.tolist(), sys.t_sl.tolist(), sys.t_r.tolist(), cd.tolist(), cd)
    return sys.cache["term_lists"]


FEW_ENTRIES = 128  # a sum of more entries and columns than this is evaluated by the dense product (_Sum.by_column)


@dataclass(frozen=True)
class _Entries:
    """A sum Σ_t M[t, :]·z_t entry by entry: output column i gets g·(the turning vectors of angle column a) for
    each (i, a, g) in ``rigid``, the constant ``const[i]`` (ground vectors, positions only) and h·(slider column
    s's value or rate) for each (i, s, h) in ``lines``. The same coefficients as the sum's matrices."""

    angles: list[int]  # the angle columns read
    rigid: list[tuple[int, int, complex]]
    const: list[complex]
    lines: list[tuple[int, int, complex]]

    @classmethod
    def of(cls, acols: Iterable[int], G: list, scols: Iterable[int], H: list, na: int, c0: list[complex]) -> _Entries:
        """From G's rows (for angle columns ``acols``; the padding column na: the ground) and H's rows (for slider
        columns ``scols``); ``c0``: ground vectors given apart."""
        const = list(c0)
        rigid = []
        for a, row in zip(acols, G, strict=True):
            for i, g in enumerate(row):
                if g and a == na:
                    const[i] += g
                elif g:
                    rigid.append((i, a, g))
        lines = [(i, c, h) for c, row in zip(scols, H, strict=True) for i, h in enumerate(row) if h]
        return cls(sorted({a for _, a, _ in rigid}), rigid, const, lines)

    def pay(self) -> _Entries | None:
        """Itself where entry by entry is the cheaper way to evaluate the sum, else None: for every sum of at most
        FEW_ENTRIES entries and columns. Each entry is a pass over a state column, contiguous in the column-major
        state; the dense product reads whole rows, transposed (measured on every sum of the catalog at 4,800 and
        48,000 samples: entry by entry the faster for each, the dense product 1.5–8.6× their time in total per
        mechanism). A larger sum's Python loop would cost more than its dense product saves."""
        return self if len(self.rigid) + len(self.lines) + len(self.const) <= FEW_ENTRIES else None


@dataclass
class _Sum:
    """Σ_t M[t, :]·z_t over a set of terms, regrouped: rigid vectors by the angle that turns them (G), vectors
    fixed to the ground (c0), slider vectors on the ground (H: only s varies) and slider vectors on moving guides.
    Evaluated for positions, velocities or accelerations from the state arrays by :meth:`by_column` ((K, rows)):
    entry by entry (``entries``: every sum but the largest; a point or loop sees one or two of the mechanism's
    vectors per link), else by a few dense real matrix products (pos/vel/acc, (rows, K)) on the interleaved
    [Re, Im] view (_real_reps: half the work of complex ones), whose arrays R, Rj, c0 and H are made on first use.
    A dense sum that reads most angle columns reads whole state rows, the ground vectors on the padding column
    (E = 1, ω = α = 0); one that reads a few gathers them."""

    acols: np.ndarray | None  # state angle columns read (None: whole rows, padding included, c0 in R)
    scols: np.ndarray | None  # state slider columns read
    s_ang: np.ndarray  # slider vectors on moving guides: angle, slider, r, e^{jδ}, M
    s_sl: np.ndarray
    s_r: np.ndarray
    s_cd: np.ndarray
    Ms: np.ndarray
    entries: _Entries | None  # the same sum entry by entry (None: evaluated by the dense products)
    coef: tuple  # G's rows (for acols), H's rows (for scols), the ground vectors (None: in G) and K

    @cached_property
    def _reps(self) -> tuple[np.ndarray, np.ndarray]:
        return _real_reps(self.coef[0], self.coef[3])

    @property
    def R(self) -> np.ndarray:
        """(2·len(acols), 2K): the real representation of G = Σ M·r·e^{jδ} per turning angle."""
        return self._reps[0]

    @property
    def Rj(self) -> np.ndarray:
        """... of j·G (velocities)."""
        return self._reps[1]

    @cached_property
    def c0(self) -> np.ndarray:
        """(2K,): the ground vectors, interleaved (zero where R has them: acols None)."""
        c0, K = self.coef[2], self.coef[3]
        return np.array([0j] * K if c0 is None else c0, complex).view(float)

    @cached_property
    def H(self) -> np.ndarray:
        """(len(scols), 2K) real: Σ M·e^{jδ} of each slider's vectors on ground lines, interleaved."""
        H, K = self.coef[1], self.coef[3]
        return np.array(H, complex).view(float).reshape(len(H), 2 * K)

    @classmethod
    def build(cls, sys: LoopSystem, terms: np.ndarray, M: np.ndarray) -> _Sum:
        """Σ_t M[t, :]·z_t over ``terms`` (M: one row per term, K columns). A small sum from Python numbers
        (:func:`_sums`), a large one by numpy's vector operations (the same values)."""
        M = M.reshape(len(terms), -1)
        if M.size <= SMALL_SUM:
            return _sums(sys, [(terms.tolist(), M.tolist())], M.shape[1])[0]
        na, ns = sys.n_angles, len(sys.slider_names)
        ang, sl, r = sys.t_ang[terms], sys.t_sl[terms], sys.t_r[terms]
        cd = _term_lists(sys)[4][terms]
        M = M.astype(complex)
        K = M.shape[1]
        col = np.where(ang < 0, na, ang)  # the padding column stands for the ground
        ground = (sl < 0) | (ang < 0)  # rigid, or a slider along a ground line: r (and s) times a constant
        G = np.zeros((na + 1, K), complex)
        np.add.at(G, col[ground], (r * cd)[ground][:, None] * M[ground])
        on_line = (sl >= 0) & (ang < 0)
        H = np.zeros((ns + 1, K), complex)
        np.add.at(H, sl[on_line], cd[on_line][:, None] * M[on_line])
        acols = _used(set(ang[ground & (ang >= 0)].tolist()), na + 1)
        scols = _used(set(sl[on_line].tolist()), ns + 1)
        c0 = None if acols is None else G[na]  # gathered: the ground vectors are a constant, the padding not read
        coef = (G if acols is None else G[acols], H if scols is None else H[scols], c0, K)
        mv = (sl >= 0) & (ang >= 0)
        entries = None
        if np.count_nonzero(G) + np.count_nonzero(H) + K <= FEW_ENTRIES:
            entries = _Entries.of(range(na + 1), G.tolist(), range(ns + 1), H.tolist(), na, [0j] * K).pay()
        return cls(acols, scols, ang[mv], sl[mv], r[mv], cd[mv], M[mv], entries, coef)

    def _rigid(self, E: np.ndarray, R: np.ndarray, factor: np.ndarray | None = None) -> np.ndarray:
        """Σ over the rigid vectors as a real (rows, 2K) array: (E·factor) @ G by its representation R."""
        if self.acols is not None and not len(self.acols):
            return np.zeros((len(E), R.shape[1]))
        E = _columns_of(E, self.acols)
        if factor is not None:
            E = E * _columns_of(factor, self.acols)
        return np.ascontiguousarray(E).view(float) @ R

    def _on_lines(self, out: np.ndarray, S: np.ndarray) -> np.ndarray:
        """out (real, interleaved) += the slider vectors along ground lines for slider values (or rates) S."""
        if self.H.size:
            out += _columns_of(S, self.scols) @ self.H
        return out.view(complex)

    def pos(self, st: _State, k: slice | np.ndarray) -> np.ndarray:
        rigid = self._rigid(st.E[k], self.R)
        if self.acols is not None:
            rigid += self.c0
        out = self._on_lines(rigid, st.S[k])
        if len(self.s_sl):
            out += self._moving(st, k, "p")
        return out

    def vel(self, st: _State, k: slice | np.ndarray) -> np.ndarray:
        E = st.E[k]
        out = self._on_lines(self._rigid(E, self.Rj, st.W[k]), st.SD[k])
        if len(self.s_sl):
            out += self._moving(st, k, "v")
        return out

    def acc(self, st: _State, k: slice | np.ndarray) -> np.ndarray:
        E, w = st.E[k], st.W[k]
        wc = _columns_of(w, self.acols)
        f = np.empty(wc.shape, complex)  # (jα − ω²)·e^{jθ}: tangential and normal accelerations in one product
        np.multiply(wc, wc, out=f.real)
        np.negative(f.real, out=f.real)
        f.imag = _columns_of(st.AL[k], self.acols)
        f *= _columns_of(E, self.acols)
        out = self._on_lines(f.view(float) @ self.R if f.shape[1] else np.zeros((len(f), self.R.shape[1])), st.SDD[k])
        if len(self.s_sl):
            out += self._moving(st, k, "a")
        return out

    def _moving(self, st: _State, k: slice | np.ndarray, what: str) -> np.ndarray:
        """(rows, K) complex: Σ over the slider vectors on moving guides, (r + s)·e^{j(θ + δ)} and its rates."""
        es = self.s_cd * st.E[k][:, self.s_ang]
        ms = self.s_r + st.S[k][:, self.s_sl]
        if what == "p":
            return (ms * es) @ self.Ms
        ws = st.W[k][:, self.s_ang]
        sd = st.SD[k][:, self.s_sl]
        if what == "v":
            return ((sd + 1j * ws * ms) * es) @ self.Ms
        coriolis = 2j * sd * ws  # a slider on a rotating guide
        return ((st.SDD[k][:, self.s_sl] + coriolis + (1j * st.AL[k][:, self.s_ang] - ws * ws) * ms) * es) @ self.Ms

    def by_column(self, st: _State, k: slice | np.ndarray, what: str) -> np.ndarray:
        """(K, rows) complex: the sum over rows ``k`` — of positions (what="p"), velocities ("v") or accelerations
        ("a") — column by column, each contiguous. Entry by entry for a sum of few entries: a product per entry
        on the state columns it reads beats a dense product that is mostly zeros and writes strided rows (the
        eight-bar's points at 48,000 samples: 5.6 → 1.8 ms); the dense product, transposed, otherwise."""
        e = self.entries
        if e is None:
            return np.ascontiguousarray((self.pos if what == "p" else self.vel if what == "v" else self.acc)(st, k).T)
        n = len(st.E[k]) if isinstance(k, slice) else len(k)
        turning = {a: _turning(st, k, a, what) for a in e.angles}
        out = np.empty((len(e.const), n), complex)
        started = [False] * len(out)
        for i, a, g in e.rigid:
            coef = 1j * g if what == "v" else g  # velocities: j·ω·e^{jθ}·g
            if started[i]:
                out[i] += turning[a] * coef
            else:
                np.multiply(turning[a], coef, out=out[i])
                started[i] = True
        for i, c in enumerate(e.const if what == "p" else [0j] * len(out)):
            if not started[i]:
                out[i] = c
            elif c:
                out[i] += c
        S = (st.S if what == "p" else st.SD if what == "v" else st.SDD)[k]
        for i, c, h in e.lines:  # sliders along ground lines
            _add_line(out[i], S[:, c], h)
        if len(self.s_sl):
            out += self._moving(st, k, what).T
        return out


def _turning(st: _State, k: slice | np.ndarray, a: int, what: str) -> np.ndarray:
    """e^{jθ}, ω·e^{jθ} (times j by the caller) or (jα − ω²)·e^{jθ} of angle column a over rows ``k``."""
    E = st.E[k, a]
    if what == "p":
        return E
    if what == "v":
        return E * st.W[k, a]
    w = st.W[k, a]
    f = np.empty(len(w), complex)
    np.multiply(w, w, out=f.real)
    np.negative(f.real, out=f.real)
    f.imag = st.AL[k, a]
    f *= E
    return f


def _add_line(col: np.ndarray, s: np.ndarray, h: complex) -> None:
    """col += h·s for real s: on the real or imaginary part alone for a line along an axis (without the product
    for a unit coefficient, the usual one: x or y)."""
    part, c = (col.real, h.real) if h.imag == 0 else (col.imag, h.imag) if h.real == 0 else (col, h)
    if c == 1:
        np.add(part, s, out=part)
    elif c == -1:
        np.subtract(part, s, out=part)
    else:
        part += s * c


def _sum_parts(sys: LoopSystem, terms: list[int], rows: list[list[float]], K: int) -> tuple:
    """A sum's constants in Python numbers, term by term in order (np.add.at's operations on complex M: the same
    bits): the angle and slider columns read, the ground vectors, G's and H's rows, the sliders on moving guides."""
    na, ns = sys.n_angles, len(sys.slider_names)
    t_ang, t_sl, t_r, t_cd, _ = _term_lists(sys)
    G: dict[int, list[complex]] = {}  # angle column → its row of G (the padding column na: the ground)
    H: dict[int, list[complex]] = {}  # slider → its row of H
    acols, scols, mv = set(), set(), []
    zero = [0j] * K  # a row no term adds to
    for n, (t, row) in enumerate(zip(terms, rows, strict=True)):
        a, i = t_ang[t], t_sl[t]
        if i >= 0 and a >= 0:  # a slider vector on a moving guide
            mv.append(n)
            continue
        rc, key = t_r[t] * t_cd[t], na if a < 0 else a  # rigid, or along a ground line
        G[key] = [x + rc * m for x, m in zip(G.get(key, zero), row, strict=True)]
        if i < 0:
            acols.add(a)
            continue
        cd = t_cd[t]
        H[i] = [x + cd * m for x, m in zip(H.get(i, zero), row, strict=True)]
        scols.add(i)
    acols.discard(-1)
    acol, scol = _used(acols, na + 1), _used(scols, ns + 1)
    c0 = None
    if acol is not None:  # gathered: the ground vectors are a constant, the padding column is not read
        c0 = G.get(na, zero)
    G_rows = [G.get(a, zero) for a in (range(na + 1) if acol is None else acol.tolist())]
    H_rows = [H.get(i, zero) for i in (range(ns + 1) if scol is None else scol.tolist())]
    moving = [(terms[n], rows[n]) for n in mv]
    return acol, scol, c0, G_rows, H_rows, moving


def _sums(sys: LoopSystem, specs: list[tuple[list[int], list[list[float]]]], K: int) -> list[_Sum]:
    """The sums Σ_t M[t, :]·z_t of several (terms, M's rows) with K columns each."""
    t_ang, t_sl, t_r, t_cd, _ = _term_lists(sys)
    no_Ms = np.zeros((0, K), complex)
    out = []
    for acol, scol, c0, G, Hp, moving in (_sum_parts(sys, terms, rows, K) for terms, rows in specs):
        s_ang, s_sl, s_r, s_cd, Ms = _NO_INT, _NO_INT, _NO_FLOAT, _NO_COMPLEX, no_Ms
        if moving:
            s_ang, s_sl = np.array([t_ang[t] for t, _ in moving], int), np.array([t_sl[t] for t, _ in moving], int)
            s_r, s_cd = np.array([t_r[t] for t, _ in moving], float), np.array([t_cd[t] for t, _ in moving], complex)
            Ms = np.array([row for _, row in moving], complex).reshape(len(moving), K)
        acols = range(sys.n_angles + 1) if acol is None else acol.tolist()
        scols = range(len(sys.slider_names) + 1) if scol is None else scol.tolist()
        entries = _Entries.of(acols, G, scols, Hp, sys.n_angles, c0 or [0j] * K).pay()
        out.append(_Sum(acol, scol, s_ang, s_sl, s_r, s_cd, Ms, entries, (G, Hp, c0, K)))
    return out


@dataclass
class _Plan:
    """Index data of one block (precomputed once per LoopSystem)."""

    block: Block
    C: np.ndarray  # (m, n_terms_block) signs of the block's terms in its loops
    Ct: np.ndarray  # C.T as complex: complex @ complex matmuls are far faster than complex @ float
    ang: np.ndarray  # per term: angle variable, slider, r, e^{jδ}
    sl: np.ndarray
    r: np.ndarray
    cd: np.ndarray
    unk_ang: list[int]  # angle variables among the unknowns
    unk_sl: list[int]  # slider indices among the unknowns
    masks: list[np.ndarray]  # per unknown: the block terms it enters
    total: _Sum  # Σ over the block's loops (K = m)
    known_sum: _Sum  # −Σ over the vectors independent of the unknowns (what the unknown vectors must add up to)
    # per unknown angle a: W_a(t) = const + Σ coef·s (the block's vectors turning with a, unrotated)
    w_const: dict[int, complex]
    w_sl: dict[int, list[tuple[int, complex]]]
    # per unknown slider i: its vector's direction U = coef·E[:, ang]
    u_dir: dict[int, tuple[int, complex]]
    known: np.ndarray = None  # type: ignore[assignment]  # the block terms independent of the unknowns
    # Σ over the block's loops without the rigid vectors turning with an unknown angle: with the unknowns' rates
    # still zero those add nothing to the velocities' known part (a sum for velocities only)
    vel_sum: _Sum = None  # type: ignore[assignment]

    def known_magnitude(self, st: _State, k: slice | np.ndarray) -> np.ndarray:
        """Σ |r + s| over the known vectors per row: what the known part X is summed from (its round-off
        grows with it, not with |X|: a mechanism far from the origin sums large vectors to a small X)."""
        return np.abs(self.r[self.known] + st.S[k][:, self.sl[self.known]]).sum(axis=1)


def block_terms(sys: LoopSystem, b: Block) -> tuple:
    """A block's terms (those in its loops, as global term ids), their signs in its loops (m, n_terms),
    their angle variables and sliders, the unknown angles and sliders, and which terms depend on none."""
    Cb = sys.C[list(b.loops)]
    terms = (Cb != 0).any(axis=0).nonzero()[0]
    Cb = Cb[:, terms]
    ang, sl = sys.t_ang[terms], sys.t_sl[terms]
    unk_ang = [v for v in b.unknowns if v < sys.n_angles]
    unk_sl = [v - sys.n_angles for v in b.unknowns if v >= sys.n_angles]
    ua, us = set(unk_ang), set(unk_sl)
    known = np.array([a not in ua and i not in us for a, i in zip(ang.tolist(), sl.tolist(), strict=True)], bool)
    return terms, Cb, ang, sl, unk_ang, unk_sl, known


def _plans(sys: LoopSystem) -> list[_Plan]:
    """Every block's plan (cached), and the system's sums (:func:`_system_sums`) with them: the small sums of
    equal width are made together."""
    plans = sys.cache.get("plans")
    if plans is not None:
        return plans
    data = [_plan_data(sys, b) for b in sys.blocks]
    specs: dict[int, list] = {}  # small sums by width K: (owner, terms, M's rows)
    made: dict = {}
    for n, (_, block_specs, m) in enumerate(data):
        if isinstance(block_specs[0][1], np.ndarray):  # a large block
            made[n] = [_Sum.build(sys, terms, M) for terms, M in block_specs]
        else:
            specs.setdefault(m, []).extend((n, *spec) for spec in block_specs)
    everything = np.arange(len(sys.t_r))
    for owner, M in (("points", sys.path), ("loops", sys.C.T)):
        if M.size <= SMALL_SUM:
            specs.setdefault(M.shape[1], []).append((owner, everything.tolist(), M.tolist()))
        else:
            made[owner] = [_Sum.build(sys, everything, M)]
    for K, group in specs.items():
        for (owner, _, _), s in zip(group, _sums(sys, [(t, rows) for _, t, rows in group], K), strict=True):
            made.setdefault(owner, []).append(s)
    sys.cache["sums"] = (made["points"][0], made["loops"][0])
    plans = []
    for n, (args, _, _) in enumerate(data):
        total, known_sum, vel_sum = made[n]
        plans.append(_Plan(*args[:10], total, known_sum, *args[10:], vel_sum=vel_sum))  # type: ignore[misc]
    sys.cache["plans"] = plans
    return plans


def _plan_data(sys: LoopSystem, b: Block) -> tuple[tuple, list, int]:
    """One block's plan but its sums: its terms and the closed forms' constants (in Python numbers: numpy's scalar
    operations, the same bits), and its three sums' terms and rows (all terms, the known ones negated, those
    still at zero rates; as arrays for a large block) with their width."""
    na = sys.n_angles
    _, _, t_r, t_cd, cd_all = _term_lists(sys)
    terms, Cb, ang, sl, unk_ang, unk_sl, known = block_terms(sys, b)
    tl, al, sll, kl = terms.tolist(), ang.tolist(), sl.tolist(), known.tolist()
    masks = [(ang == v) if v < na else (sl == v - na) for v in b.unknowns]
    g = Cb[0].tolist()
    turned_by: dict[int, list[int]] = {}  # angle → the block terms it turns
    first_of: dict[int, int] = {}  # slider → its first block term
    for n, (a, i) in enumerate(zip(al, sll, strict=True)):
        turned_by.setdefault(a, []).append(n)
        first_of.setdefault(i, n)
    w_const, w_sl, u_dir = {}, {}, {}
    for a in unk_ang:
        on = turned_by.get(a, [])
        w_const[a] = complex(sum(g[n] * t_r[tl[n]] * t_cd[tl[n]] for n in on))
        w_sl[a] = [(sll[n], complex(g[n] * t_cd[tl[n]])) for n in on if sll[n] >= 0]
    for i in unk_sl:
        n = first_of[i]
        u_dir[i] = (al[n], complex(g[n] * t_cd[tl[n]]))
    ua = set(unk_ang)
    still = [not (i < 0 and a in ua) for a, i in zip(al, sll, strict=True)]
    CbT = Cb.T
    if Cb.size <= SMALL_SUM:
        rows = CbT.tolist()
        specs = [(tl, rows), _rows_where(kl, tl, [[-x for x in row] for row in rows]), _rows_where(still, tl, rows)]
    else:
        still_a = np.array(still, bool)
        specs = [(terms, CbT), (terms[known], -CbT[known]), (terms[still_a], CbT[still_a])]
    r = np.array([t_r[t] for t in tl], float)
    cd = cd_all[terms]
    args = (b, Cb, CbT.astype(complex), ang, sl, r, cd, unk_ang, unk_sl, masks, w_const, w_sl, u_dir, known)
    return args, specs, len(Cb)


def _rows_where(keep: list[bool], terms: list[int], rows: list[list[float]]) -> tuple[list[int], list[list[float]]]:
    """The terms and rows where ``keep`` holds."""
    return [t for t, k in zip(terms, keep, strict=True) if k], [r for r, k in zip(rows, keep, strict=True) if k]


def _system_sums(sys: LoopSystem) -> tuple[_Sum, _Sum]:
    """Sums giving every point's position (and rates) and every loop's closure residual (made with the plans)."""
    _plans(sys)
    return sys.cache["sums"]


class _State:
    """Arrays over the sample grid (rows × columns); the last column of each is the 'fixed' padding. Column-major:
    every column (an angle's e^{jθ}, a slider's s, ...) is contiguous, as the kernels and the sums (entry by
    entry) read and write them one at a time; row-major, each pass over a column read every row's cache line
    (with it, the eight-bar took 1.1× the time at 4,800 samples and 1.3× at 48,000, the Jansen pair 1.2× and 1.7×
    with its 13 columns split into chunks of 12,000 to stay in cache)."""

    def __init__(self, n: int, na: int, ns: int) -> None:
        self.E = np.ones((na + 1, n), complex).T
        self.TH = np.zeros((na, n)).T
        self.W = np.zeros((na + 1, n)).T
        self.AL = np.zeros((na + 1, n)).T
        self.S = np.zeros((ns + 1, n)).T
        self.SD = np.zeros((ns + 1, n)).T
        self.SDD = np.zeros((ns + 1, n)).T

    def z(
        self, k: slice, ang: np.ndarray, sl: np.ndarray, r: np.ndarray, cd: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Term vectors z = (r + s)·e^{j(θ + δ)} and their unit directions over rows ``k``."""
        e = cd * self.E[k][:, ang]
        return (r + self.S[k][:, sl]) * e, e


class _Failure(Exception):
    """Why sample ``sample`` cannot be solved; ``loop`` (index) where a loop is to blame."""

    def __init__(self, sample: int, loop: int | None, why: str) -> None:
        self.sample, self.loop, self.why = sample, loop, why


def _w(p: _Plan, st: _State, k: slice, a: int, skip: int = -2) -> np.ndarray | complex:
    """W_a: the block's vectors turning with unknown angle a, before rotation (slider ``skip`` left out)."""
    w: np.ndarray | complex = p.w_const[a]
    for i, coef in p.w_sl[a]:
        if i != skip:
            w = w + coef * st.S[k, i]
    return w


def _u(p: _Plan, st: _State, k: slice, i: int) -> np.ndarray | complex:
    """U: the unit direction of unknown slider i's vector (a constant for a slider along a ground line)."""
    a, coef = p.u_dir[i]
    return coef if a < 0 else coef * st.E[k, a]


def _rows_of(x: np.ndarray | complex, n: int) -> np.ndarray:
    """x as an array of n rows (a constant repeated)."""
    return np.broadcast_to(x, (n,))


def _closed_form(p: _Plan, st: _State, k: slice, na: int, sig: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form positions of a one-loop dyad for rows ``k`` on branches ``sig`` (±1 per row).

    Returns the mask of assemblable rows and the discriminant h [length²]: the dyad's two
    assembly solutions lie 2·√h apart (h < 0: no solution, the input is past a limit position;
    h = 0: the two branches meet — a toggle, or a change point where they cross).
    """
    b = p.block
    X = p.known_sum.by_column(st, k, "p")[0]
    if b.kind == "RRR":
        # W1·E1 + W2·E2 = X: |W1|, |W2|, |X| form a triangle (law of cosines)
        W1, W2 = _w(p, st, k, p.unk_ang[0]), _w(p, st, k, p.unk_ang[1])
        A2, B2 = np.abs(W1) ** 2, np.abs(W2) ** 2
        D2 = X.real**2 + X.imag**2
        k1 = 0.5 * (A2 + D2 - B2)
        h2 = _round_off_zero(
            A2 * D2 - k1 * k1,
            A2 * D2 + k1 * k1,
            lambda m: (
                (np.broadcast_to(A2, k1.shape)[m] + np.abs(k1[m]))
                * np.sqrt(D2[m])
                * p.known_magnitude(st, _sub_rows(k, m))
            ),
        )
        ok = (h2 >= 0) & (D2 > 0)
        Dd = np.where(D2 > 0, D2, 1.0)
        P = X * (k1 + 1j * sig * np.sqrt(np.where(ok, h2, 0.0))) / Dd
        _set_angle(st, k, p.unk_ang[0], P / W1)
        _set_angle(st, k, p.unk_ang[1], (X - P) / W2)
        return ok, h2 / Dd
    if b.kind == "RRP":
        # W1·E1 + s·U = X with U a known unit direction: project on U's normal
        i = p.unk_sl[0]
        Uc = np.conj(_u(p, st, k, i))
        W1 = _w(p, st, k, p.unk_ang[0])
        XU, WU = X * Uc, W1 * Uc
        y = XU.imag
        A2 = np.abs(W1) ** 2  # |W1|², per row or one for all
        h = _round_off_zero(A2 - y * y, A2, lambda m: np.abs(y[m]) * p.known_magnitude(st, _sub_rows(k, m)))
        ok = h >= 0
        c = sig * np.sqrt(np.where(ok, h, 0.0))
        E = np.empty(len(y), complex)
        E.real, E.imag = c, y
        _set_angle(st, k, p.unk_ang[0], E * (1.0 / WU) if np.ndim(WU) == 0 else E / WU)
        st.S[k, i] = XU.real - c
        return ok, h
    if b.kind == "RPR":
        # (W + s·c)·E = X with c a unit direction fixed to the same link: |W + s·c| = |X|
        i, a = p.unk_sl[0], p.unk_ang[0]
        cdir = p.u_dir[i][1]
        W = _w(p, st, k, a, skip=i)
        bb = (W * np.conj(cdir)).real
        D2 = X.real**2 + X.imag**2
        disc = _round_off_zero(
            bb * bb - np.abs(W) ** 2 + D2,
            bb * bb + np.abs(W) ** 2 + D2,
            lambda m: np.sqrt(D2[m]) * p.known_magnitude(st, _sub_rows(k, m)),
        )
        s = -bb + sig * np.sqrt(np.where(disc >= 0, disc, 0.0))
        den = W + s * cdir
        ok = (disc >= 0) & (np.abs(den) > 0)
        st.S[k, i] = s
        _set_angle(st, k, a, X / np.where(ok, den, 1.0))
        return ok, disc
    # PP: s1·U1 + s2·U2 = X (linear: one solution, no branches)
    U1, U2 = (_rows_of(_u(p, st, k, i), len(X)) for i in p.unk_sl[:2])
    det = cross(U1, U2)
    ok = np.abs(det) > 1e-12
    dd = np.where(ok, det, 1.0)
    st.S[k, p.unk_sl[0]] = cross(X, U2) / dd
    st.S[k, p.unk_sl[1]] = cross(U1, X) / dd
    return ok, np.full(len(ok), np.inf)


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


def _set_angle(st: _State, k: slice, a: int, E: np.ndarray) -> None:
    """Store e^{jθ} and the unwrapped θ = φ + 2π·n for rows ``k`` (row k.start keeps its turn count).

    φ is the principal angle of E, n the whole turns counted by continuity from the first row:
    the stored θ is then exactly φ + 2πn whatever the sampling before it, so a run that starts
    late gives the same numbers as one from t = 0.
    """
    E = E / np.abs(E)
    st.E[k, a] = E
    phi = np.arctan2(E.imag, E.real)
    start = st.TH[k.start or 0, a]
    turns = np.empty(len(phi))  # whole turns between each row's principal angle and the one before
    turns[:1] = phi[:1] - start
    np.subtract(phi[1:], phi[:-1], out=turns[1:])
    turns *= 1.0 / TWO_PI
    np.rint(turns, out=turns)
    jumps = np.flatnonzero(turns != 0)  # few: where φ wraps past ±π
    th = phi
    if len(jumps):  # θ = φ + 2π·n, n the turns counted so far (piecewise constant between jumps)
        n = np.zeros(len(phi))
        if len(jumps) <= 8:
            for j in jumps.tolist():
                n[j:] -= turns[j]
        else:
            n[jumps[0] :] = np.repeat(-np.cumsum(turns[jumps]), np.diff(np.append(jumps, len(phi))))
        th = phi + TWO_PI * n
    st.TH[k, a] = th


def _rates(p: _Plan, st: _State, k: slice, what: str, cols: _Cols2 | None = None) -> np.ndarray:
    """Unknown rates (what="v") or accelerations ("a") of a one-loop block for rows ``k``, by Cramer's rule.

    The unknowns' own rate columns must still be zero: the sum is then the known part.
    """
    R = (p.vel_sum if what == "v" else p.total).by_column(st, k, what)[0]  # the known part
    c = cols if cols is not None else _columns(p, st, k)
    Rr, Ri = R.real, R.imag  # c1·x1 + c2·x2 = −R
    out = np.empty((len(Rr), 2))
    np.multiply(Ri * c.c2r - Rr * c.c2i, c.inv_det, out=out[:, 0])
    np.multiply(Rr * c.c1i - Ri * c.c1r, c.inv_det, out=out[:, 1])
    return out


def det_sign(J: np.ndarray) -> np.ndarray:
    """Sign of det J (the assembly branch); a rectangular (redundant) block has no branch sign: +1."""
    if J.shape[-1] == J.shape[-2]:
        return np.sign(np.linalg.det(J))
    return np.ones(J.shape[:-2])


@dataclass
class _Cols2:
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

    def head(self, n: int) -> _Cols2:
        """The first n rows (a constant column stays a constant)."""
        return _Cols2(*(x[:n] if np.ndim(x) else x for x in (getattr(self, f.name) for f in dataclasses.fields(self))))


def _columns(p: _Plan, st: _State, k: slice) -> _Cols2:
    """The Jacobian columns of a one-loop (two-unknown) block on rows ``k``."""
    cols, norms = [], []
    for v in p.block.unknowns:
        if v in p.unk_ang:
            W = _w(p, st, k, v)
            cols.append(1j * W * st.E[k, v])
            norms.append(abs(W) ** 2 if np.ndim(W) == 0 else None)  # |E| = 1: a rigid link's length, squared
        else:  # a slider's direction: a constant along a ground line, a constant times E on a moving one
            i = p.unk_sl[p.block.unknowns.index(v) - len(p.unk_ang)]
            cols.append(_u(p, st, k, i))
            norms.append(abs(p.u_dir[i][1]) ** 2)
    n = len(st.E[k])
    if all(np.ndim(c) == 0 for c in cols):  # both constant (two sliders along ground lines): one per row all the same
        cols = [np.full(n, c) for c in cols]
    c1r, c1i, c2r, c2i = (np.ascontiguousarray(x) if np.ndim(x) else float(x) for c in cols for x in (c.real, c.imag))
    det = c1r * c2i - c1i * c2r
    n1 = c1r * c1r + c1i * c1i if norms[0] is None else norms[0]
    n2 = c2r * c2r + c2i * c2i if norms[1] is None else norms[1]
    with np.errstate(divide="ignore"):
        return _Cols2(c1r, c1i, c2r, c2i, det, 1.0 / det, n1, n2)


def _store(p: _Plan, st: _State, k: slice, vals: np.ndarray, what: str, na: int) -> None:
    for i, v in enumerate(p.block.unknowns):
        if v < na:
            (st.W if what == "v" else st.AL)[k, v] = vals[:, i]
        else:
            (st.SD if what == "v" else st.SDD)[k, v - na] = vals[:, i]


def _block_health(
    p: _Plan, st: _State, k: slice, scale: float, cols: _Cols2 | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Condition number (angle columns divided by the mechanism size) and det sign per row of a one-loop block."""
    c = cols if cols is not None else _columns(p, st, k)
    s1 = 1.0 / scale if p.block.unknowns[0] in p.unk_ang else 1.0  # angle columns in lengths: per size
    s2 = 1.0 / scale if p.block.unknowns[1] in p.unk_ang else 1.0
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


@dataclass
class _Inputs:
    """The drivers' values, rates and accelerations at internal grid times.

    From ``t_first`` on: the file's drivers. Before it, a path in input space x0 + u·R with
    u = (t − lead_from)/span: the lead-in of a run that starts late (from the inputs at t = 0
    to those at ``t_first`` less their whole crank turns, see :func:`_lead_in`), or the one-turn
    probe that measures winding numbers (``t_first`` = ∞).
    """

    mech: Mechanism
    t_first: float = -math.inf
    lead_from: float = 0.0
    span: float = 1.0
    x0: np.ndarray | None = None
    R: np.ndarray | None = None

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, float)
        m = len(self.mech.drivers)
        if m and len(t) and t[0] >= self.t_first:  # (ascending) every time is the file's own: no lead-in path
            return evaluate_all(self.mech, t)
        X, XD, XDD = np.zeros((len(t), m)), np.zeros((len(t), m)), np.zeros((len(t), m))
        if m == 0:
            return X, XD, XDD
        real = t >= self.t_first
        if real.any():
            X[real], XD[real], XDD[real] = evaluate_all(self.mech, t[real])
        if not real.all():
            u = (t[~real] - self.lead_from) / self.span
            X[~real] = self.x0 + u[:, None] * self.R
            XD[~real] = self.R / self.span
        return X, XD, XDD


@dataclass(frozen=True)
class _ChangePoint:
    """Where block ``block``'s assembly branches meet (a change point), or where a redundant block's
    Jacobian loses rank on its one smooth branch (kind "singular"), at internal time ``time``."""

    block: int
    time: float
    flip: bool  # whether σ changes there (True on the smooth continuation of a crossing)
    smooth: bool  # whether this continuation is the one whose velocities stay continuous
    kind: str = "change point"


@dataclass
class _Run:
    """What one solve needs besides the state arrays; probes share ``events`` with their run."""

    sys: LoopSystem
    inputs: _Inputs
    scale: float
    tol: float
    max_iter: int
    rtol: float
    events: dict[int, list[_ChangePoint]] = field(default_factory=dict)
    detect: bool = True  # look for change points (the main run only)
    check: bool = True  # refuse ill-conditioned samples and branch flips
    rates: bool = True
    newton_sign: dict[int, float] = field(default_factory=dict)  # det sign of each Newton block's t = 0 branch
    tail: bool = True  # the rows end the run (not a chunk followed by another)
    t_start: float = 0.0  # the run's first requested time
    memory_budget: Any = None  # as given to solve() (bytes or text), else from the environment or the file
    sink: Any = None  # solve()'s whole-run output columns, filled chunk by chunk (vloop.core.solver._Sink)
    blocks: Callable[..., Any] | None = None  # the solver's block runner, for probes (set by vloop.core.solver)

    def sigma(self, i: int, t: np.ndarray) -> np.ndarray:
        """Assembly branch (±1) of closed-form block ``i`` at times ``t``: σ at t = 0, flipped after each event."""
        sig = np.full(len(t), _plans(self.sys)[i].block.sigma)
        for ev in self.events.get(i, ()):
            if ev.flip:
                sig[t > ev.time] *= -1.0
        return sig


@dataclass
class _Solved:
    n_ok: int
    failure: _Failure | None
    conds: list[np.ndarray]
    signs: list[np.ndarray]
    discs: list[np.ndarray]  # closed-form blocks' discriminants h (None for Newton blocks)
    at_change: np.ndarray  # rows whose rates were taken across a change point


def _rates_by(p: _Plan, st: _State, k: slice, inv: np.ndarray, what: str) -> np.ndarray:
    """Rates of a Newton block from its factored Jacobians (J⁻¹, or the least-squares (JᵀJ)⁻¹Jᵀ)."""
    return (inv @ known_rhs(p.vel_sum if what == "v" else p.total, st, k, what)[..., None])[..., 0]


def known_rhs(s: _Sum, st: _State, k: slice | np.ndarray, what: str) -> np.ndarray:
    """(rows, 2K) real: minus a sum's velocities (what="v") or accelerations ("a"), [Re of each column, then Im]:
    the right-hand side of a block's rate equations J·ẋ = −(known part)."""
    R = s.by_column(st, k, what)
    return np.negative(np.concatenate([R.real, R.imag])).T


def _fail(out: _Solved, failure: _Failure) -> None:
    """Keep the earliest failure; rows from it on are not solved."""
    if failure.sample < out.n_ok:
        out.n_ok, out.failure = failure.sample, failure


def _error_bound(cond: np.ndarray) -> np.ndarray:
    """Relative error bound of a sample's accelerations: cond³·ε. Next to a fold the positions themselves are
    only known to cond·ε (the inputs' round-off, amplified), the velocities to cond²·ε, the accelerations to
    cond³·ε (measured on a parallelogram at its folding: the bound holds, with a margin of ~10)."""
    return cond * cond * cond * EPS


def _velocity_bound(cond: np.ndarray) -> np.ndarray:
    """Relative error bound of a sample's velocities: cond²·ε (a sample beyond rtol here is refused)."""
    return cond * cond * EPS


def _impose_drivers(sys: LoopSystem, st: _State, X: np.ndarray, XD: np.ndarray, XDD: np.ndarray) -> None:
    na = sys.n_angles
    for j, v in enumerate(sys.drivers):
        if v < na:
            st.TH[:, v] = X[:, j]
            np.cos(X[:, j], out=st.E[:, v].real)
            np.sin(X[:, j], out=st.E[:, v].imag)
            st.W[:, v], st.AL[:, v] = XD[:, j], XDD[:, j]
        else:
            st.S[:, v - na], st.SD[:, v - na], st.SDD[:, v - na] = X[:, j], XD[:, j], XDD[:, j]


def _initial_state(sys: LoopSystem, n: int) -> _State:
    """A state of n rows whose row 0 is the t = 0 assembly."""
    na, ns = sys.n_angles, len(sys.slider_names)
    st = _State(n, na, ns)
    st.TH[0, :] = sys.q0[:na]
    st.E[0, :na] = np.exp(1j * sys.q0[:na])
    st.S[0, :ns] = sys.q0[na:]
    return st


def _change_point_choices(sys: LoopSystem, loop_number: int) -> list[str]:
    """``[solver] change_points`` for a loop: "smooth" (default) or "other", or a list for successive ones."""
    spec = sys.mechanism.options.get("change_points", {}).get(loop_number, "smooth")
    return [spec] if isinstance(spec, str) else list(spec)


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


def newton_rows(
    residual: Callable[[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]],
    x: np.ndarray,
    tol: float,
    max_iter: int,
) -> tuple[np.ndarray, np.ndarray]:
    """Batched Newton–Raphson from ``x`` (rows, nu): ``residual(act, x_act)`` stores x_act on the rows ``act`` and
    gives their residuals and Jacobians (F, J); a row stops as its step falls below tol·(1 + |x|) (least squares
    where J has more rows than columns). Returns (solution, converged mask); the caller stores the finite rows."""
    x = x.copy()
    conv = np.zeros(len(x), bool)
    act = np.arange(len(x))
    for _ in range(max_iter):
        F, J = residual(act, x[act])
        dx = least_squares_rows(J, -F)
        xa = x[act] + dx
        x[act] = xa
        finite = np.all(np.isfinite(xa), axis=1)
        with np.errstate(invalid="ignore"):
            done = finite & (np.max(np.abs(dx), axis=1) <= tol * (1.0 + np.max(np.abs(xa), axis=1)))
        conv[act[done]] = True
        act = act[finite & ~done]
        if not len(act):
            break
    return x, conv


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
            p = _pivot_rows(A, k)
            pivots.append(p)
            _swap_pattern(nz, k, *_swap_rows(A, k, p))
            piv = A[k, k].copy()
            neg ^= (p != k) ^ (piv < 0)
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
    p = np.full(A.shape[-1], A.shape[0] - 1)
    for i in range(len(a) - 2, -1, -1):
        np.copyto(p, k + i, where=a[i] == top)
    return p


def _swap_rows(A: np.ndarray, k: int, p: np.ndarray) -> tuple[list[int], bool]:
    """Swap row k with row p[m] of each matrix m (p ≥ k): one plain swap when all pivot alike (along a path
    they mostly do), masked swaps row by row otherwise. Returns the rows swapped with k (k left out) and
    whether every matrix swapped alike."""
    first = int(p[0])
    if np.all(p == first):
        if first != k:
            t = A[k].copy()
            A[k] = A[first]
            A[first] = t
            return [first], True
        return [], True
    swapped = []
    for i in range(k + 1, A.shape[0]):
        m = p == i
        if m.any():
            t = A[k].copy()
            np.copyto(A[k], A[i], where=m)
            np.copyto(A[i], t, where=m)
            swapped.append(i)
    return swapped, False
