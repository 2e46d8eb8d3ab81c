"""A block's plan: its terms, the roles of its unknowns and its sums, made once per LoopSystem (cached).

A block (:class:`~vloop.method.loops.Block`) is one step of the block-triangular solving order: a closed-form
dyad or a Newton block. Its plan holds the block's terms with their signs in its loops, the constants of its
closed form in Python numbers, and three sums: over its loops (the rates' right-hand sides), over its known
vectors (what the unknown vectors must add up to) and over the vectors still at zero rate (velocities).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..method.loops import Block, LoopSystem
from .data import State
from .sums import SMALL_SUM, Sum, build_sums, is_per_row, rows_of, term_constants


@dataclass
class Plan:
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
    total: Sum  # Σ over the block's loops (K = m)
    known_sum: Sum  # −Σ over the vectors independent of the unknowns (what the unknown vectors must add up to)
    # per unknown angle a: W_a(t) = const + Σ coef·s (the block's vectors turning with a, unrotated)
    w_const: dict[int, complex]
    w_sl: dict[int, list[tuple[int, complex]]]
    # per unknown slider i: its vector's direction U = coef·E[:, ang]
    u_dir: dict[int, tuple[int, complex]]
    known: np.ndarray = None  # type: ignore[assignment]  # the block terms independent of the unknowns
    # Σ over the block's loops without the rigid vectors turning with an unknown angle: with the unknowns' rates
    # still zero those add nothing to the velocities' known part (a sum for velocities only)
    vel_sum: Sum = None  # type: ignore[assignment]
    per_row: bool = False  # r, cd one per variant and the closed form's constants one per row (sums.per_row)
    samples: int = 0  # ... each variant's rows
    # per term: the magnitude its round-off is relative to (r, or for a chord the magnitudes it was summed from:
    # a ground chord between pivots far from the origin is as exact as their coordinates, not as its length)
    sizes: np.ndarray = None  # type: ignore[assignment]

    def known_magnitude(self, state: State, k: slice | np.ndarray) -> np.ndarray:
        """Σ |r + s| over the known vectors per row (a chord's r counted as the magnitudes it was summed from):
        what the known part X is computed from (its round-off grows with it, not with |X|: a mechanism far from
        the origin sums large vectors to a small X)."""
        if not self.per_row:
            r = self.sizes[self.known]
        else:
            variant = np.arange(k.start or 0, k.stop) if isinstance(k, slice) else np.asarray(k)
            r = self.sizes[:, variant // self.samples].T[:, self.known]
        return np.abs(r + state.s[k][:, self.sl[self.known]]).sum(axis=1)

    def term_values(self, k: slice | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The block terms' r and e^{jδ} for rows ``k``: (terms,) each, or (rows, terms) where given per variant
        (rows of ``samples`` each, variant by variant)."""
        if not self.per_row:
            return self.r, self.cd
        variant = np.arange(k.start or 0, k.stop) if isinstance(k, slice) else np.asarray(k)
        variant = variant // self.samples
        return np.ascontiguousarray(self.r[:, variant].T), np.ascontiguousarray(self.cd[:, variant].T)

    def at(self, x: complex | np.ndarray, k: slice | np.ndarray) -> complex | np.ndarray:
        """One of the closed form's constants at rows ``k`` (itself unless given per row)."""
        return x[k] if self.per_row else x


def block_terms(system: LoopSystem, b: Block) -> tuple:
    """A block's terms (those in its loops, as global term ids), their signs in its loops (m, n_terms),
    their angle variables and sliders, the unknown angles and sliders, and which terms depend on none."""
    Cb = system.C[list(b.loops)]
    terms = (Cb != 0).any(axis=0).nonzero()[0]
    Cb = Cb[:, terms]
    ang, sl = system.t_ang[terms], system.t_sl[terms]
    unk_ang = [v for v in b.unknowns if v < system.n_angles]
    unk_sl = [v - system.n_angles for v in b.unknowns if v >= system.n_angles]
    ua, us = set(unk_ang), set(unk_sl)
    known = np.array([a not in ua and i not in us for a, i in zip(ang.tolist(), sl.tolist(), strict=True)], bool)
    return terms, Cb, ang, sl, unk_ang, unk_sl, known


def block_plans(system: LoopSystem) -> list[Plan]:
    """Every block's plan (cached), and the system's sums (:func:`system_sums`) with them: the small sums of
    equal width are made together."""
    plans = system.cache.get("plans")
    if plans is not None:
        return plans
    rows = is_per_row(system)
    data = [_plan_data(system, b) for b in system.blocks]
    specs: dict[int, list] = {}  # small sums by width K: (owner, terms, M's rows)
    made: dict = {}
    for n, (_, block_specs, m) in enumerate(data):
        if isinstance(block_specs[0][1], np.ndarray):  # a large block
            made[n] = [Sum.build(system, terms, M) for terms, M in block_specs]
        else:
            specs.setdefault(m, []).extend((n, *spec) for spec in block_specs)
    everything = np.arange(len(system.t_r))
    for owner, M in (("points", system.path), ("loops", system.C.T)):
        if M.size <= SMALL_SUM or rows:
            specs.setdefault(M.shape[1], []).append((owner, everything.tolist(), M.tolist()))
        else:
            made[owner] = [Sum.build(system, everything, M)]
    for K, group in specs.items():
        for (owner, _, _), s in zip(group, build_sums(system, [(t, rows) for _, t, rows in group], K), strict=True):
            made.setdefault(owner, []).append(s)
    system.cache["sums"] = (made["points"][0], made["loops"][0])
    system_terms = [block_terms(system, b)[0] for b in system.blocks]
    plans = []
    for n, (args, _, _) in enumerate(data):
        total, known_sum, vel_sum = made[n]
        plans.append(
            Plan(
                *args[:10],
                total,
                known_sum,
                *args[10:],
                vel_sum=vel_sum,
                per_row=rows,
                samples=system.cache.get("per_row", 0),
                sizes=term_sizes(system)[system_terms[n]],
            )
        )  # type: ignore[misc]
    system.cache["plans"] = plans
    return plans


def _plan_data(system: LoopSystem, b: Block) -> tuple[tuple, list, int]:
    """One block's plan but its sums: its terms and the closed forms' constants (in Python numbers: numpy's scalar
    operations, the same bits), and its three sums' terms and rows (all terms, the known ones negated, those
    still at zero rates; as arrays for a large block) with their width."""
    na = system.n_angles
    _, _, t_r, t_cd, cd_all = term_constants(system)
    terms, Cb, ang, sl, unk_ang, unk_sl, known = block_terms(system, b)
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
        w_const[a] = _number(system, sum(g[n] * t_r[tl[n]] * t_cd[tl[n]] for n in on))
        w_sl[a] = [(sll[n], _number(system, g[n] * t_cd[tl[n]])) for n in on if sll[n] >= 0]
    for i in unk_sl:
        n = first_of[i]
        u_dir[i] = (al[n], _number(system, g[n] * t_cd[tl[n]]))
    ua = set(unk_ang)
    still = [not (i < 0 and a in ua) for a, i in zip(al, sll, strict=True)]
    CbT = Cb.T
    if Cb.size <= SMALL_SUM or is_per_row(system):
        rows = CbT.tolist()
        specs = [(tl, rows), _rows_where(kl, tl, [[-x for x in row] for row in rows]), _rows_where(still, tl, rows)]
    else:
        still_a = np.array(still, bool)
        specs = [(terms, CbT), (terms[known], -CbT[known]), (terms[still_a], CbT[still_a])]
    r = np.array([t_r[t] for t in tl], float)  # one per variant: (terms, variants)
    cd = cd_all[terms]
    args = (b, Cb, CbT.astype(complex), ang, sl, r, cd, unk_ang, unk_sl, masks, w_const, w_sl, u_dir, known)
    return args, specs, len(Cb)


def term_sizes(system: LoopSystem) -> np.ndarray:
    """Per term (and per variant where given so): the magnitude its round-off is relative to — its own r, or for a
    chord (a body's vectors a loop crosses, summed once) the larger of r and its parts' sizes summed."""
    r = np.array(term_constants(system)[2], float)  # (terms,) or (terms, variants)
    sizes = np.abs(r)
    for tid, parts in sorted(system.chords):  # (a chord's parts are terms made before it)
        sizes[tid] = np.maximum(sizes[tid], sum(abs(c) * sizes[p] for p, c in parts))
    return sizes


def _number(system: LoopSystem, x: complex | np.ndarray) -> complex | np.ndarray:
    """A constant as a Python complex number (one per variant: spread over the rows, :func:`sums.rows_of`)."""
    return rows_of(system, x) if isinstance(x, np.ndarray) else complex(x)


def _rows_where(keep: list[bool], terms: list[int], rows: list[list[float]]) -> tuple[list[int], list[list[float]]]:
    """The terms and rows where ``keep`` holds."""
    return [t for t, k in zip(terms, keep, strict=True) if k], [r for r, k in zip(rows, keep, strict=True) if k]


def system_sums(system: LoopSystem) -> tuple[Sum, Sum]:
    """Sums giving every point's position (and rates) and every loop's closure residual (made with the plans)."""
    block_plans(system)
    return system.cache["sums"]


def store_rates(plan: Plan, state: State, k: slice, vals: np.ndarray, what: str, na: int) -> None:
    for i, v in enumerate(plan.block.unknowns):
        if v < na:
            (state.omega if what == "v" else state.alpha)[k, v] = vals[:, i]
        else:
            (state.s_dot if what == "v" else state.s_ddot)[k, v - na] = vals[:, i]
