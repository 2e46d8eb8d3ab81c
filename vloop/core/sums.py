"""Sums of vector terms Σ_t M[t, :]·z_t over the state's rows: loop closures, a block's known part, every point.

A sum is regrouped once per LoopSystem by what moves its terms: rigid vectors by the angle that turns them
(coefficients G), vectors fixed to the ground (constants), slider vectors along ground lines (H: only s varies)
and slider vectors on moving guides. It is evaluated for positions, velocities or accelerations
(:meth:`Sum.by_column`) entry by entry, or, for the largest sums, by dense real matrix products.
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from ..method.loops import LoopSystem
from .data import State


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


def term_constants(system: LoopSystem) -> tuple[list[int], list[int], list, list, np.ndarray]:
    """Every term's angle variable, slider, magnitude and e^{jδ} as Python numbers, and e^{jδ} as an array
    (cached); for a system of :func:`per_row`, each magnitude and e^{jδ} an array over the rows."""
    if "term_lists" not in system.cache:
        cd = np.exp(1j * system.t_delta)
        system.cache["term_lists"] = (system.t_ang.tolist(), system.t_sl.tolist(), system.t_r.tolist(), cd.tolist(), cd)
    return system.cache["term_lists"]


def per_row(system: LoopSystem, r: np.ndarray, cd: np.ndarray, samples: int) -> LoopSystem:
    """The system with every term's magnitude and e^{jδ} given per variant (r, cd: (n_terms, variants)), each
    variant's on its ``samples`` rows (variants of one structure solved together, their samples stacked). Its
    plans and sums are built from these in the same order of operations as from Python numbers, each constant
    one per variant, then one per row (:func:`rows_of`); they take each coefficient at the rows they evaluate."""
    out = dataclasses.replace(system, cache={"per_row": samples})
    out.cache["term_lists"] = (system.t_ang.tolist(), system.t_sl.tolist(), list(r), list(cd), cd)
    return out


def is_per_row(system: LoopSystem) -> bool:
    """Whether the system's term constants are per row (:func:`per_row`)."""
    return bool(system.cache.get("per_row"))


def rows_of(system: LoopSystem, x: complex | np.ndarray) -> complex | np.ndarray:
    """A constant built from per-variant values (last axis: variants) spread over each variant's rows; a number
    (no term gave it) as it is."""
    return _spread(system.cache["per_row"], x)


def _spread(samples: int, x: complex | np.ndarray) -> complex | np.ndarray:
    return np.repeat(x, samples, axis=-1) if isinstance(x, np.ndarray) else x


def at_rows(x: complex | np.ndarray, k: slice | np.ndarray) -> complex | np.ndarray:
    """A coefficient at rows ``k``: itself where it is one number for every row, else its rows k."""
    return x[k] if isinstance(x, np.ndarray) else x


def nonzero(x: complex | np.ndarray) -> bool:
    """Whether a coefficient adds anything (one per row: unless it is zero on every row)."""
    return bool(np.any(x)) if isinstance(x, np.ndarray) else bool(x)


FEW_ENTRIES = 128  # a sum of more entries and columns than this is evaluated by the dense product (Sum.by_column)


@dataclass
class Entries:
    """A sum Σ_t M[t, :]·z_t entry by entry: output column i gets g·(the turning vectors of angle column a) for
    each (i, a, g) in ``rigid``, the constant ``const[i]`` (ground vectors, positions only) and h·(slider column
    s's value or rate) for each (i, s, h) in ``lines``. The same coefficients as the sum's matrices."""

    angles: list[int]  # the angle columns read
    rigid: list[tuple[int, int, complex]]
    const: list[complex]
    lines: list[tuple[int, int, complex]]
    spread: Callable | None = None  # coefficients one per variant: how they spread over the rows (rows_of)

    @classmethod
    def of(
        cls,
        acols: Iterable[int],
        G: list,
        scols: Iterable[int],
        H: list,
        na: int,
        c0: list,
        rows: Callable | None = None,
    ) -> Entries:
        """From G's rows (for angle columns ``acols``; the padding column na: the ground) and H's rows (for slider
        columns ``scols``); ``c0``: ground vectors given apart. ``rows``: how per-variant coefficients spread
        over the rows (:func:`rows_of`; None: one number each)."""
        const = list(c0)
        rigid = []
        for a, row in zip(acols, G, strict=True):
            for i, g in enumerate(row):
                if not (g if rows is None else nonzero(g)):
                    continue
                if a == na:
                    const[i] += g
                else:
                    rigid.append((i, a, g))
        lines = [
            (i, c, h)
            for c, row in zip(scols, H, strict=True)
            for i, h in enumerate(row)
            if (h if rows is None else nonzero(h))
        ]
        return cls(sorted({a for _, a, _ in rigid}), rigid, const, lines, rows)

    @cached_property
    def _rows(self) -> Entries:
        """The entries with their per-variant coefficients spread over the rows (made on first use)."""
        spread = self.spread
        return Entries(
            self.angles,
            [(i, a, spread(g)) for i, a, g in self.rigid],
            [spread(c) for c in self.const],
            [(i, c, spread(h)) for i, c, h in self.lines],
        )

    def at(self, k: slice | np.ndarray) -> Entries:
        """The entries with their coefficients at rows ``k`` (themselves unless one per variant)."""
        if self.spread is None:
            return self
        e = self._rows
        return Entries(
            e.angles,
            [(i, a, g[k]) for i, a, g in e.rigid],
            [at_rows(c, k) for c in e.const],
            [(i, c, h[k]) for i, c, h in e.lines],
        )

    def pay(self) -> Entries | None:
        """Itself where entry by entry is the cheaper way to evaluate the sum, else None: for every sum of at most
        FEW_ENTRIES entries and columns. Each entry is a pass over a state column, contiguous in the column-major
        state; the dense product reads whole rows, transposed (measured on every sum of the catalog at 4,800 and
        48,000 samples: entry by entry the faster for each, the dense product 1.5–8.6× their time in total per
        mechanism). A larger sum's Python loop would cost more than its dense product saves. Coefficients one
        per row have no dense product: entry by entry always."""
        return (
            self
            if self.spread is not None or len(self.rigid) + len(self.lines) + len(self.const) <= FEW_ENTRIES
            else None
        )


@dataclass
class Sum:
    """Σ_t M[t, :]·z_t over a set of terms, regrouped: rigid vectors by the angle that turns them (G), vectors
    fixed to the ground (c0), slider vectors on the ground (H: only s varies) and slider vectors on moving guides.
    Evaluated for positions, velocities or accelerations from the state arrays by :meth:`by_column` ((K, rows)):
    entry by entry (``entries``: every sum but the largest; a point or loop sees one or two of the mechanism's
    vectors per link), else by a few dense real matrix products (pos/vel/acc, (rows, K)) on the interleaved
    [Re, Im] view (_real_reps: half the work of complex ones), whose arrays R, Rj, c0 and H are made on first use.
    A dense sum that reads most angle columns reads whole state rows, the ground vectors on the padding column
    (e^{jθ} = 1, ω = α = 0); one that reads a few gathers them."""

    acols: np.ndarray | None  # state angle columns read (None: whole rows, padding included, c0 in R)
    scols: np.ndarray | None  # state slider columns read
    s_ang: np.ndarray  # slider vectors on moving guides: angle, slider, r, e^{jδ}, M
    s_sl: np.ndarray
    s_r: np.ndarray
    s_cd: np.ndarray
    Ms: np.ndarray
    entries: Entries | None  # the same sum entry by entry (None: evaluated by the dense products)
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
    def build(cls, system: LoopSystem, terms: np.ndarray, M: np.ndarray) -> Sum:
        """Σ_t M[t, :]·z_t over ``terms`` (M: one row per term, K columns). A small sum from Python numbers
        (:func:`build_sums`), a large one by numpy's vector operations (the same values)."""
        M = M.reshape(len(terms), -1)
        if M.size <= SMALL_SUM or is_per_row(system):
            return build_sums(system, [(terms.tolist(), M.tolist())], M.shape[1])[0]
        na, ns = system.n_angles, len(system.slider_names)
        ang, sl, r = system.t_ang[terms], system.t_sl[terms], system.t_r[terms]
        cd = term_constants(system)[4][terms]
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
            entries = Entries.of(range(na + 1), G.tolist(), range(ns + 1), H.tolist(), na, [0j] * K).pay()
        return cls(acols, scols, ang[mv], sl[mv], r[mv], cd[mv], M[mv], entries, coef)

    def _rigid(self, cis: np.ndarray, R: np.ndarray, factor: np.ndarray | None = None) -> np.ndarray:
        """Σ over the rigid vectors as a real (rows, 2K) array: (e^{jθ}·factor) @ G by its representation R."""
        if self.acols is not None and not len(self.acols):
            return np.zeros((len(cis), R.shape[1]))
        cis = _columns_of(cis, self.acols)
        if factor is not None:
            cis = cis * _columns_of(factor, self.acols)
        return np.ascontiguousarray(cis).view(float) @ R

    def _on_lines(self, out: np.ndarray, S: np.ndarray) -> np.ndarray:
        """out (real, interleaved) += the slider vectors along ground lines for slider values (or rates) S."""
        if self.H.size:
            out += _columns_of(S, self.scols) @ self.H
        return out.view(complex)

    def pos(self, state: State, k: slice | np.ndarray) -> np.ndarray:
        rigid = self._rigid(state.e[k], self.R)
        if self.acols is not None:
            rigid += self.c0
        out = self._on_lines(rigid, state.s[k])
        if len(self.s_sl):
            out += self._moving(state, k, "p")
        return out

    def vel(self, state: State, k: slice | np.ndarray) -> np.ndarray:
        out = self._on_lines(self._rigid(state.e[k], self.Rj, state.omega[k]), state.s_dot[k])
        if len(self.s_sl):
            out += self._moving(state, k, "v")
        return out

    def acc(self, state: State, k: slice | np.ndarray) -> np.ndarray:
        cis, w = state.e[k], state.omega[k]
        wc = _columns_of(w, self.acols)
        f = np.empty(wc.shape, complex)  # (jα − ω²)·e^{jθ}: tangential and normal accelerations in one product
        np.multiply(wc, wc, out=f.real)
        np.negative(f.real, out=f.real)
        f.imag = _columns_of(state.alpha[k], self.acols)
        f *= _columns_of(cis, self.acols)
        out = self._on_lines(
            f.view(float) @ self.R if f.shape[1] else np.zeros((len(f), self.R.shape[1])), state.s_ddot[k]
        )
        if len(self.s_sl):
            out += self._moving(state, k, "a")
        return out

    def _moving(self, state: State, k: slice | np.ndarray, what: str) -> np.ndarray:
        """(rows, K) complex: Σ over the slider vectors on moving guides, (r + s)·e^{j(θ + δ)} and its rates."""
        if self.s_r.ndim == 1:
            return _moving_terms(state, k, what, self.s_ang, self.s_sl, self.s_r, self.s_cd) @ self.Ms
        values = _moving_terms(state, k, what, self.s_ang, self.s_sl, self.s_r[:, k].T, self.s_cd[:, k].T)
        out = np.zeros((len(values), self.Ms.shape[1]), complex)  # term by term: each row's sum its own
        for j, row in enumerate(self.Ms):
            for i in np.nonzero(row)[0]:
                out[:, i] += row[i] * values[:, j]
        return out

    def by_column(self, state: State, k: slice | np.ndarray, what: str) -> np.ndarray:
        """(K, rows) complex: the sum over rows ``k`` — of positions (what="p"), velocities ("v") or accelerations
        ("a") — column by column, each contiguous. Entry by entry for a sum of few entries: a product per entry
        on the state columns it reads beats a dense product that is mostly zeros and writes strided rows (the
        eight-bar's points at 48,000 samples: 5.6 → 1.8 ms); the dense product, transposed, otherwise."""
        e = self.entries
        if e is None:
            return np.ascontiguousarray(
                (self.pos if what == "p" else self.vel if what == "v" else self.acc)(state, k).T
            )
        n = len(state.e[k]) if isinstance(k, slice) else len(k)
        adds = nonzero if e.spread is not None else bool  # whether a constant adds anything
        e = e.at(k)
        turning = {a: _turning(state, k, a, what) for a in e.angles}
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
            elif adds(c):
                out[i] += c
        slides = (state.s if what == "p" else state.s_dot if what == "v" else state.s_ddot)[k]
        for i, c, h in e.lines:  # sliders along ground lines
            _add_line(out[i], slides[:, c], h)
        if len(self.s_sl):
            out += self._moving(state, k, what).T
        return out


def _moving_terms(
    state: State, k: slice | np.ndarray, what: str, ang: np.ndarray, sl: np.ndarray, r: np.ndarray, cd: np.ndarray
) -> np.ndarray:
    """(rows, terms): slider vectors on moving guides z = (r + s)·e^{jδ}·e^{jθ}, or ż = (ṡ + jω(r + s))·e^{j(θ+δ)},
    or z̈ = (s̈ + 2jṡω + (jα − ω²)(r + s))·e^{j(θ+δ)} (a slider on a rotating guide: the Coriolis term 2jṡω)."""
    es = cd * state.e[k][:, ang]
    ms = r + state.s[k][:, sl]
    if what == "p":
        return ms * es
    ws = state.omega[k][:, ang]
    sd = state.s_dot[k][:, sl]
    if what == "v":
        return (sd + 1j * ws * ms) * es
    coriolis = 2j * sd * ws
    return (state.s_ddot[k][:, sl] + coriolis + (1j * state.alpha[k][:, ang] - ws * ws) * ms) * es


def _turning(state: State, k: slice | np.ndarray, a: int, what: str) -> np.ndarray:
    """e^{jθ}, ω·e^{jθ} (times j by the caller) or (jα − ω²)·e^{jθ} of angle column a over rows ``k``."""
    cis = state.e[k, a]
    if what == "p":
        return cis
    if what == "v":
        return cis * state.omega[k, a]
    w = state.omega[k, a]
    f = np.empty(len(w), complex)
    np.multiply(w, w, out=f.real)
    np.negative(f.real, out=f.real)
    f.imag = state.alpha[k, a]
    f *= cis
    return f


def _add_line(col: np.ndarray, s: np.ndarray, h: complex | np.ndarray) -> None:
    """col += h·s for real s: on the real or imaginary part alone for a line along an axis (without the product
    for a unit coefficient, the usual one: x or y). ``h`` one number, or one per row (the same choice where
    every row allows it)."""
    if isinstance(h, np.ndarray):
        part, c = (col.real, h.real) if np.all(h.imag == 0) else (col.imag, h.imag) if np.all(h.real == 0) else (col, h)
        one, minus_one = np.all(c == 1), np.all(c == -1)
    else:
        part, c = (col.real, h.real) if h.imag == 0 else (col.imag, h.imag) if h.real == 0 else (col, h)
        one, minus_one = c == 1, c == -1
    if one:
        np.add(part, s, out=part)
    elif minus_one:
        np.subtract(part, s, out=part)
    else:
        part += s * c


def _sum_parts(system: LoopSystem, terms: list[int], rows: list[list[float]], K: int) -> tuple:
    """A sum's constants in Python numbers, term by term in order (np.add.at's operations on complex M: the same
    bits): the angle and slider columns read, the ground vectors, G's and H's rows, the sliders on moving guides."""
    na, ns = system.n_angles, len(system.slider_names)
    t_ang, t_sl, t_r, t_cd, _ = term_constants(system)
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


def build_sums(system: LoopSystem, specs: list[tuple[list[int], list[list[float]]]], K: int) -> list[Sum]:
    """The sums Σ_t M[t, :]·z_t of several (terms, M's rows) with K columns each."""
    t_ang, t_sl, t_r, t_cd, _ = term_constants(system)
    no_Ms = np.zeros((0, K), complex)
    out = []
    for acol, scol, c0, G, Hp, moving in (_sum_parts(system, terms, rows, K) for terms, rows in specs):
        s_ang, s_sl, s_r, s_cd, Ms = _NO_INT, _NO_INT, _NO_FLOAT, _NO_COMPLEX, no_Ms
        if moving:
            s_ang, s_sl = np.array([t_ang[t] for t, _ in moving], int), np.array([t_sl[t] for t, _ in moving], int)
            s_r, s_cd = np.array([t_r[t] for t, _ in moving], float), np.array([t_cd[t] for t, _ in moving], complex)
            if is_per_row(system):  # one per row: (terms, rows)
                s_r, s_cd = rows_of(system, s_r), rows_of(system, s_cd)
            Ms = np.array([row for _, row in moving], complex).reshape(len(moving), K)
        acols = range(system.n_angles + 1) if acol is None else acol.tolist()
        scols = range(len(system.slider_names) + 1) if scol is None else scol.tolist()
        spread = functools.partial(_spread, system.cache["per_row"]) if is_per_row(system) else None  # (no cycle)
        entries = Entries.of(acols, G, scols, Hp, system.n_angles, c0 or [0j] * K, spread).pay()
        out.append(Sum(acol, scol, s_ang, s_sl, s_r, s_cd, Ms, entries, (G, Hp, c0, K)))
    return out


def known_rhs(s: Sum, state: State, k: slice | np.ndarray, what: str) -> np.ndarray:
    """(rows, 2K) real: minus a sum's velocities (what="v") or accelerations ("a"), [Re of each column, then Im]:
    the right-hand side of a block's rate equations J·ẋ = −(known part)."""
    R = s.by_column(state, k, what)
    return np.negative(np.concatenate([R.real, R.imag])).T
