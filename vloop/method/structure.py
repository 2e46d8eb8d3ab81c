"""Block-triangular structure of the loop equations, and the closed-form kind of each block.

A maximum matching of equations (each loop's Re and Im rows) to unknowns, then the strongly
connected components of "this unknown's equation needs that unknown" (Dulmage–Mendelsohn at the
level of loops): each block is a set of m loops with 2m unknowns, solved after the blocks it
depends on. One-loop blocks of the classic dyad kinds have closed forms (RRR: two angles; RRP: an
angle and a slider on a known direction; RPR: a slider and its own guide's angle; PP: two sliders);
the assembly branch σ of each is read from the t = 0 configuration.
"""

from __future__ import annotations

import heapq
import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from ..errors import MechanismError
from .loops import Block, LoopSystem, term_values, turning_with


@dataclass(frozen=True)
class Structure:
    """The loop equations' groups in solving order: (loops, unknowns) each.

    ``over_determined``: some equations are not matched to an unknown (more equations than unknowns
    somewhere: redundant constraints, or a structure that cannot move — the rank at t = 0 decides);
    the whole system is then one group, solved by least squares.
    """

    groups: tuple[tuple[tuple[int, ...], tuple[int, ...]], ...]
    over_determined: bool = False


def analyse(system: LoopSystem) -> Structure:
    """Dulmage–Mendelsohn at the level of loops: a maximum matching of equation rows to unknowns, then the
    strongly connected components of "this unknown's equation needs that unknown", dependencies first.

    Where every unknown is matched, the components, the loops of each and the order are the same whatever
    matching is taken (the fine Dulmage–Mendelsohn decomposition is unique; a loop's two rows need the
    same unknowns, so they fall in one group and the lowest loop numbers of the groups differ): any
    maximum matching serves (plain augmenting paths). Otherwise networkx's finds the free unknowns.
    """
    unk = list(system.unknowns)
    if not unk:
        return Structure(((tuple(range(len(system.loops))), ()),) if system.loops else (), bool(system.loops))
    row_of = _augmenting_matching(system, unk)
    if len(row_of) < len(unk):
        _matching(system, unk)  # raises, naming the unknowns no loop fixes
    if len(row_of) < 2 * len(system.loops):
        return Structure(((tuple(range(len(system.loops))), tuple(unk)),), True)
    unk_set = set(unk)
    needs = {v: [w for w in system.loops[row_of[v]].variables if w in unk_set and w != v] for v in unk}
    comps = _strong_components(unk, needs)
    comp_of = {v: c for c, members in enumerate(comps) for v in members}
    first_loop = [min(row_of[v] for v in members) for members in comps]
    waiting = [0] * len(comps)  # groups each group still waits for
    users: list[set[int]] = [set() for _ in comps]
    for v in unk:
        for w in needs[v]:
            a, b = comp_of[v], comp_of[w]
            if a != b and a not in users[b]:
                users[b].add(a)
                waiting[a] += 1
    ready = [(first_loop[c], c) for c in range(len(comps)) if not waiting[c]]
    heapq.heapify(ready)
    groups = []
    while ready:  # dependencies first; among groups ready together, the lower loop number first
        _, c = heapq.heappop(ready)
        vars_ = sorted(comps[c])
        groups.append((tuple(sorted({row_of[v] for v in vars_})), tuple(vars_)))
        for a in users[c]:
            waiting[a] -= 1
            if not waiting[a]:
                heapq.heappush(ready, (first_loop[a], a))
    return Structure(tuple(groups))


def _augmenting_matching(system: LoopSystem, unk: list[int]) -> dict[int, int]:
    """A maximum matching of unknowns to loop rows (two per loop), by augmenting paths: unknown → its row's loop."""
    loops_of: dict[int, list[int]] = {v: [] for v in unk}
    for loop in system.loops:
        for v in loop.variables:
            if v in loops_of:
                loops_of[v].append(loop.index)
    free_rows = [2] * len(system.loops)  # rows of each loop not matched yet
    row_of: dict[int, int] = {}  # unknown → loop of its matched row
    matched: list[list[int]] = [[] for _ in system.loops]  # loop → the unknowns matched to its rows
    for v in unk:
        prev = {v: None}  # breadth-first search for a loop with a free row, through matched unknowns
        queue, end = deque([v]), None
        while queue and end is None:
            x = queue.popleft()
            for li in loops_of[x]:
                if free_rows[li]:
                    end = (x, li)
                    break
                for y in matched[li]:
                    if y not in prev:
                        prev[y] = x
                        queue.append(y)
        if end is None:
            continue
        x, li = end
        free_rows[li] -= 1
        while x is not None:  # shift the matches along the path: x takes loop li, leaving its own to prev[x]
            old = row_of.get(x)
            if old is not None:
                matched[old].remove(x)
            row_of[x] = li
            matched[li].append(x)
            x, li = prev[x], old
    return row_of


def _strong_components(nodes: list[int], succ: dict[int, list[int]]) -> list[list[int]]:
    """Strongly connected components (Tarjan's algorithm, iterative)."""
    index: dict[int, int] = {}
    low: dict[int, int] = {}
    stack: list[int] = []
    on_stack: set[int] = set()
    comps: list[list[int]] = []
    for root in nodes:
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            v, i = work.pop()
            if i == 0:
                index[v] = low[v] = len(index)
                stack.append(v)
                on_stack.add(v)
            for k in range(i, len(succ[v])):
                w = succ[v][k]
                if w not in index:
                    work += [(v, k + 1), (w, 0)]
                    break
                if w in on_stack:
                    low[v] = min(low[v], index[w])
            else:
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on_stack.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    comps.append(comp)
                if work:
                    u = work[-1][0]
                    low[u] = min(low[u], low[v])
    return comps


def _matching(system: LoopSystem, unk: list[int]) -> tuple[dict, list]:
    """Hopcroft–Karp matching of loop rows (Re, Im) to unknowns; raises if an unknown is fixed by no loop."""
    import networkx as nx

    unk_set = set(unk)
    B = nx.Graph()
    rows = [("row", loop.index, part) for loop in system.loops for part in (0, 1)]
    B.add_nodes_from(rows, bipartite=0)
    B.add_nodes_from((("var", v) for v in unk), bipartite=1)
    for loop in system.loops:
        for v in loop.variables:
            if v in unk_set:
                B.add_edge(("row", loop.index, 0), ("var", v))
                B.add_edge(("row", loop.index, 1), ("var", v))
    match = nx.bipartite.hopcroft_karp_matching(B, top_nodes=rows)
    free = [system.var_name(v) for v in unk if ("var", v) not in match]
    if free:
        raise MechanismError(
            f"{system.mechanism.source}: [links] the loop equations cannot be solved: "
            f"{', '.join(free)} are not fixed by any loop (that part can move freely)",
            entry="links",
        )
    return match, [r for r in rows if r not in match]


def block_structure(
    system: LoopSystem, structure: Structure, q0: np.ndarray, method: str, z: np.ndarray | None = None
) -> tuple[Block, ...]:
    """The blocks to solve, in order: each group classified (closed-form dyad kind and branch σ at the
    t = 0 assembly) under method "auto"; one Newton block over everything under "newton". ``z``: the term
    vectors at ``q0``, where known."""
    if not system.unknowns:
        return ()
    if method == "newton" or structure.over_determined:
        return (Block(tuple(range(len(system.loops))), tuple(system.unknowns), "newton"),)
    zs = (term_values(system, q0) if z is None else z).tolist()  # Python numbers: numpy's scalar operations
    return tuple(classify(system, q0, loops, unknowns, zs) for loops, unknowns in structure.groups)


def classify(
    system: LoopSystem,
    q0: np.ndarray,
    loops: tuple[int, ...],
    unknowns: tuple[int, ...],
    z: np.ndarray | list[complex] | None = None,
) -> Block:
    """Closed-form kind and assembly branch (at the t = 0 assembly) of a one-loop block; "newton" otherwise.
    ``z``: the term vectors at ``q0``, where known."""
    n_angles = system.n_angles
    if len(loops) != 1 or len(unknowns) != 2:
        return Block(loops, unknowns, "newton")
    loop = system.loops[loops[0]]
    angles = [v for v in unknowns if v < n_angles]
    slides = [v - n_angles for v in unknowns if v >= n_angles]
    z = term_values(system, q0) if z is None else z
    phi = np.append(q0[:n_angles], 0.0)
    terms = list(zip(loop.terms, loop.signs, strict=True))

    def on(a: int) -> complex:  # Σ of the loop's vectors turning with angle a
        return turning_with(system, loop, z, a)

    if len(angles) == 2:
        p1 = on(angles[0])
        X = p1 + on(angles[1])
        return Block(loops, unknowns, "RRR", math.copysign(1.0, (np.conj(X) * p1).imag))
    if len(angles) == 1 and len(slides) == 1:
        a, i = angles[0], slides[0]
        st = [(t, sg) for t, sg in terms if system.t_sl[t] == i]
        if len(st) != 1:
            return Block(loops, unknowns, "newton")
        t, sg = st[0]
        if system.t_ang[t] == a:  # the slider rides on the unknown angle: RPR
            c = sg * np.exp(1j * system.t_delta[t])
            W = (on(a) - sg * z[t]) * np.exp(-1j * phi[a])
            return Block(loops, unknowns, "RPR", math.copysign(1.0, q0[n_angles + i] + (W * np.conj(c)).real))
        U = sg * np.exp(1j * (phi[system.t_ang[t]] + system.t_delta[t]))
        return Block(loops, unknowns, "RRP", math.copysign(1.0, (on(a) * np.conj(U)).real))
    return Block(loops, unknowns, "PP")
