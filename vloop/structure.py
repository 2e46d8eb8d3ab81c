"""Block-triangular structure of the loop equations, and the closed-form kind of each block.

A maximum matching of equations (each loop's Re and Im rows) to unknowns, then the strongly
connected components of "this unknown's equation needs that unknown" (Dulmage–Mendelsohn at the
level of loops): each block is a set of m loops with 2m unknowns, solved after the blocks it
depends on. One-loop blocks of the classic dyad kinds have closed forms (RRR: two angles; RRP: an
angle and a slider on a known direction; RPR: a slider and its own guide's angle; PP: two sliders);
the assembly branch σ of each is read from the t = 0 configuration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import networkx as nx
import numpy as np

from .errors import MechanismError
from .loops import Block, LoopSystem, term_values


@dataclass(frozen=True)
class Structure:
    """The loop equations' groups in solving order: (loops, unknowns) each.

    ``over_determined``: some equations are not matched to an unknown (more equations than unknowns
    somewhere: redundant constraints, or a structure that cannot move — the rank at t = 0 decides);
    the whole system is then one group, solved by least squares.
    """

    groups: tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]
    over_determined: bool = False


def analyse(sys: LoopSystem) -> Structure:
    """Dulmage–Mendelsohn at the level of loops: a maximum matching of equation rows to unknowns, then the
    strongly connected components of "this unknown's equation needs that unknown", dependencies first."""
    unk = list(sys.unknowns)
    if not unk:
        return Structure(((tuple(range(len(sys.loops))), ()),) if sys.loops else (), bool(sys.loops))
    match, unmatched_rows = _matching(sys, unk)
    if unmatched_rows:
        return Structure(((tuple(range(len(sys.loops))), tuple(unk)),), True)
    unk_set = set(unk)
    D = nx.DiGraph()
    D.add_nodes_from(unk)
    for v in unk:
        r = match[("var", v)]
        for w in sys.loops[r[1]].variables:
            if w in unk_set and w != v:
                D.add_edge(v, w)  # v's equation needs w
    cond = nx.condensation(D)
    groups = []
    # dependencies first; among groups ready together, the lower loop number first
    first_loop = {c: min(match[("var", v)][1] for v in cond.nodes[c]["members"]) for c in cond.nodes}
    for c in nx.lexicographical_topological_sort(cond.reverse(copy=False), key=first_loop.get):
        vars_ = sorted(cond.nodes[c]["members"])
        loops = sorted({match[("var", v)][1] for v in vars_})
        groups.append((tuple(loops), tuple(vars_)))
    return Structure(tuple(groups))


def _matching(sys: LoopSystem, unk: list[int]) -> tuple[dict, list]:
    """Hopcroft–Karp matching of loop rows (Re, Im) to unknowns; raises if an unknown is fixed by no loop."""
    unk_set = set(unk)
    B = nx.Graph()
    rows = [("row", lp.index, part) for lp in sys.loops for part in (0, 1)]
    B.add_nodes_from(rows, bipartite=0)
    B.add_nodes_from((("var", v) for v in unk), bipartite=1)
    for lp in sys.loops:
        for v in lp.variables:
            if v in unk_set:
                B.add_edge(("row", lp.index, 0), ("var", v))
                B.add_edge(("row", lp.index, 1), ("var", v))
    match = nx.bipartite.hopcroft_karp_matching(B, top_nodes=rows)
    free = [sys.var_name(v) for v in unk if ("var", v) not in match]
    if free:
        raise MechanismError(
            f"{sys.mechanism.source}: [links] the loop equations cannot be solved: "
            f"{', '.join(free)} are not fixed by any loop (that part can move freely)",
            entry="links",
        )
    return match, [r for r in rows if r not in match]


def block_structure(sys: LoopSystem, structure: Structure, q0: np.ndarray, method: str) -> tuple[Block, ...]:
    """The blocks to solve, in order: each group classified (closed-form dyad kind and branch σ at the
    t = 0 assembly) under method "auto"; one Newton block over everything under "newton"."""
    if not sys.unknowns:
        return ()
    if method == "newton" or structure.over_determined:
        return (Block(tuple(range(len(sys.loops))), tuple(sys.unknowns), "newton"),)
    return tuple(classify(sys, q0, loops, unknowns) for loops, unknowns in structure.groups)


def classify(sys: LoopSystem, q0: np.ndarray, loops: tuple[int, ...], unknowns: tuple[int, ...]) -> Block:
    """Closed-form kind and assembly branch (at the t = 0 assembly) of a one-loop block; "newton" otherwise."""
    na = sys.n_angles
    if len(loops) != 1 or len(unknowns) != 2:
        return Block(loops, unknowns, "newton")
    lp = sys.loops[loops[0]]
    angs = [v for v in unknowns if v < na]
    sls = [v - na for v in unknowns if v >= na]
    z = term_values(sys, q0)
    phi = np.append(q0[:na], 0.0)
    terms = list(zip(lp.terms, lp.signs, strict=True))

    def on(a: int) -> complex:  # Σ of the loop's vectors turning with angle a
        return complex(sum(sg * z[t] for t, sg in terms if sys.t_ang[t] == a))

    if len(angs) == 2:
        p1 = on(angs[0])
        X = p1 + on(angs[1])
        return Block(loops, unknowns, "RRR", math.copysign(1.0, (np.conj(X) * p1).imag))
    if len(angs) == 1 and len(sls) == 1:
        a, i = angs[0], sls[0]
        st = [(t, sg) for t, sg in terms if sys.t_sl[t] == i]
        if len(st) != 1:
            return Block(loops, unknowns, "newton")
        t, sg = st[0]
        if sys.t_ang[t] == a:  # the slider rides on the unknown angle: RPR
            c = sg * np.exp(1j * sys.t_delta[t])
            W = (on(a) - sg * z[t]) * np.exp(-1j * phi[a])
            return Block(loops, unknowns, "RPR", math.copysign(1.0, q0[na + i] + (W * np.conj(c)).real))
        U = sg * np.exp(1j * (phi[sys.t_ang[t]] + sys.t_delta[t]))
        return Block(loops, unknowns, "RRP", math.copysign(1.0, (on(a) * np.conj(U)).real))
    return Block(loops, unknowns, "PP")
