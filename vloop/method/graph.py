"""The paper's graph of a mechanism, its vector terms, its loops and the paths to every point.

One node per (body, joint) incidence plus the world origin on the ground; an edge inside each
body from its reference node to each other node (a star: a body adds no cycle of its own); an
edge between the nodes of the bodies that share a pin (a star per pin); an edge from a guide's
reference node to the block it carries (the slider vector, plus the constant offset of the
sliding line). Every edge carries *terms*, complex vectors z = (r + s)·e^{j(φ_a + δ)} with φ_a the
angle of rotating link a (φ ≡ 0 for the ground) and s a slider displacement (absent for rigid
vectors). A cycle basis gives J − L + 1 independent loops. Each loop is written with one vector per
body it crosses (the body's star vectors and slider-line offsets along the way summed into a chord,
a term of its own), so a four-bar's ground vector is O2→O4 wherever the world origin lies.
"""

from __future__ import annotations

import itertools
import math
from collections import deque
from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from ..model import Body, Mechanism

if TYPE_CHECKING:
    import networkx as nx

ORIGIN = "@O"  # the world origin node on the ground
SMALL_RANK = 64  # up to this many loops every candidate cycle is shortened by a search
SHORT_CYCLE = 16  # beyond, a fundamental cycle this short is kept as it is


@dataclass
class Terms:
    """The vector terms, as growing lists while the graph is built (arrays via :meth:`arrays`)."""

    ang: list[int] = field(default_factory=list)  # angle variable turning the term, -1 = fixed (ground)
    sl: list[int] = field(default_factory=list)  # slider index whose s the term carries, -1 = none
    r: list[float] = field(default_factory=list)  # constant magnitude
    delta: list[float] = field(default_factory=list)  # constant angle offset [rad]
    label: list[str] = field(default_factory=list)
    body: list[str] = field(default_factory=list)  # the body the term is fixed in (a slider's: its guide)
    ends: list[tuple[str, str]] = field(default_factory=list)  # the points it runs from and to (names)
    parts: dict[int, tuple[tuple[int, float], ...]] = field(default_factory=dict)  # chord → Σ c·z of these terms

    def add(self, ang: int, sl: int, r: float, delta: float, label: str, body: str = "", ends: tuple = ("", "")) -> int:
        if r < 0:
            r, delta = -r, delta + math.pi
        self.ang.append(ang)
        self.sl.append(sl)
        self.r.append(r)
        self.delta.append(delta % (2 * math.pi))
        self.label.append(label)
        self.body.append(body)
        self.ends.append(ends)
        return len(self.r) - 1

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        return (
            np.array(self.ang, int),
            np.array(self.sl, int),
            np.array(self.r, float),
            np.array(self.delta, float),
        )


@dataclass
class MechanismGraph:
    """The graph with its terms, the angle variable of each rotating link and the sliders' t = 0 s.

    The graph is its nodes and edges (u, v, data) in the order they were added, and its adjacency in networkx's
    layout; ``G`` builds the networkx graph from them on first use (the compiler walks the adjacency)."""

    parts: tuple[list, list[tuple]]  # nodes, edges
    terms: Terms
    angle_links: tuple[str, ...]
    slider_names: tuple[str, ...]
    coords_s: list[float]
    owner: dict[str, tuple[int, float]]  # body → (angle variable turning it or -1, constant frame offset)

    @cached_property
    def adj(self) -> dict:
        return adjacency(*self.parts)

    @cached_property
    def forest(self) -> list[list[tuple]]:
        """A breadth-first tree per component (:func:`_forest`), shared by the cycle basis and the point paths."""
        return _forest(self.adj)

    @cached_property
    def G(self) -> nx.Graph:
        return networkx_graph(*self.parts)


def adjacency(nodes: list, edges: list[tuple]) -> dict:
    """node → {neighbour: edge data}, as ``nx.Graph`` holds it after ``add_nodes_from(nodes)`` and
    ``add_edges_from(edges)``: the same orders, one data dict per edge (a repeated edge's data merged)."""
    adj: dict = {n: {} for n in nodes}
    for u, v, data in edges:
        nu, nv = adj.setdefault(u, {}), adj.setdefault(v, {})
        merged = nu.get(v, {})
        merged.update(data)
        nu[v] = nv[u] = merged
    return adj


def networkx_graph(nodes: list, edges: list[tuple]) -> nx.Graph:
    """The networkx graph of ``nodes`` and ``edges`` (u, v, data), added in that order."""
    import networkx as nx

    G = nx.Graph()
    G.add_nodes_from(nodes)
    G.add_edges_from(edges)
    return G


def build_graph(mech: Mechanism, bodies: dict[str, Body]) -> MechanismGraph:
    """Step 1: nodes, body stars, pin stars and slider edges, with their vector terms."""
    angle_links = tuple(n for n, lk in mech.links.items() if not lk.ground)
    avar = {n: i for i, n in enumerate(angle_links)}
    owner = {name: _owner(bodies, avar, name) for name in mech.body_names}
    terms = Terms()
    nodes, ref = _reference_nodes(mech, bodies)
    edges = _body_stars(mech, bodies, terms, ref, owner)
    for j in mech.joints:
        at = mech.bodies_at(j)
        edges += [((at[0], j), (other, j), {"terms": (), "start": (at[0], j), "kind": "pin"}) for other in at[1:]]
    coords_s = _add_slider_edges(mech, bodies, edges, terms, ref, owner)
    return MechanismGraph((nodes, edges), terms, angle_links, tuple(mech.sliders), coords_s, owner)


def _owner(bodies: dict[str, Body], avar: dict[str, int], body: str) -> tuple[int, float]:
    """Angle variable that turns ``body`` and the constant offset of its frame (a block rides its guide)."""
    b = bodies[body]
    if b.kind == "ground":
        return -1, 0.0
    if b.kind == "link":
        return avar[body], 0.0
    g = bodies[b.guide]
    return (-1 if g.kind == "ground" else avar[g.name]), b.theta0 - g.theta0


def _reference_nodes(mech: Mechanism, bodies: dict[str, Body]) -> tuple[list, dict[str, tuple[str, str]]]:
    """Every node (the world origin first, then each body's joints and points) and each body's reference node."""
    ground = mech.ground
    ref: dict[str, tuple[str, str]] = {}
    nodes = [(ground, ORIGIN)]
    for bname in mech.body_names:
        b = bodies[bname]
        ref[bname] = (bname, ORIGIN) if b.kind == "ground" else (bname, next(iter(b.local)))
        nodes += [(bname, m) for m in b.local]
    return nodes, ref


def _body_stars(
    mech: Mechanism,
    bodies: dict[str, Body],
    terms: Terms,
    ref: dict[str, tuple[str, str]],
    owner: dict[str, tuple[int, float]],
) -> list[tuple]:
    """Each body's edges from its reference node to its other nodes, with their terms."""
    origin = origin_name(mech)
    edges = []
    for bname in mech.body_names:
        ang, off = owner[bname]
        for m, (lx, ly) in bodies[bname].local.items():
            node = (bname, m)
            if node == ref[bname]:
                continue
            start = origin if ref[bname][1] == ORIGIN else ref[bname][1]
            r, delta = math.hypot(lx, ly), math.atan2(ly, lx) + off
            tid = terms.add(ang, -1, r, delta, f"{start}→{m} ({bname})", bname, (start, m))
            edges.append((ref[bname], node, {"terms": ((tid, 1.0),), "start": ref[bname], "kind": "link"}))
    return edges


def _add_slider_edges(
    mech: Mechanism,
    bodies: dict[str, Body],
    edges: list[tuple],
    terms: Terms,
    ref: dict[str, tuple[str, str]],
    owner: dict[str, tuple[int, float]],
) -> list[float]:
    """Guide → block edges (added to ``edges``): s along the axis plus the sliding line's constant offset.
    Returns each s at t = 0."""
    coords_s = []
    for i, sl in enumerate(mech.sliders.values()):
        g = bodies[sl.guide]
        ang, _ = owner[sl.guide]
        px, py = mech.joints[sl.joint]
        dx, dy = px - g.origin[0], py - g.origin[1]
        cg, sg = math.cos(g.theta0), math.sin(g.theta0)
        lx, ly = cg * dx + sg * dy, -sg * dx + cg * dy
        alpha = math.atan2(sl.axis[1], sl.axis[0]) - g.theta0 if sl.angle is None else sl.angle
        s0 = lx * math.cos(alpha) + ly * math.sin(alpha)
        e = -lx * math.sin(alpha) + ly * math.cos(alpha) if sl.offset is None else sl.offset  # stated: dimensions
        coords_s.append(s0)
        start = origin_name(mech) if ref[sl.guide][1] == ORIGIN else ref[sl.guide][1]
        line = f"line of {sl.name}"  # its point s = 0
        edge = [(terms.add(ang, i, 0.0, alpha, f"s_{sl.name}", sl.guide, (line, sl.joint)), 1.0)]
        if abs(e) > 1e-15 * mech.scale:
            offset = terms.add(ang, -1, e, alpha + math.pi / 2, f"offset of {sl.name}", sl.guide, (start, line))
            edge.insert(0, (offset, 1.0))  # along the edge: from the guide's reference to the line, then along it
        data = {"terms": tuple(edge), "start": ref[sl.guide], "kind": "slider"}
        edges.append((ref[sl.guide], (sl.name, sl.joint), data))
    return coords_s


def origin_name(mech: Mechanism) -> str:
    """The world origin's display name: a ground joint placed there, else "O"."""
    at_origin = [j for j in mech.links[mech.ground].joints if mech.joints[j] == (0.0, 0.0)]
    return at_origin[0] if at_origin else "O"


# ------------------------------------------------------------------ cycles


def cycle_basis(G: nx.Graph | dict, forest: list[list[tuple]] | None = None) -> list[list]:
    """Step 2: independent cycles (J − L + 1 of them), each as nodes in traversal order, in a canonical order.

    The shortest cycle through each non-tree edge of a breadth-first spanning forest (a breadth-first
    search that stops at the first cycle: near-linear for a linkage, whose loops are short), kept
    greedily by length while independent (GF(2) elimination on edge bitsets), completed by fundamental
    cycles if needed. Short loops are what the block structure needs; on every catalog mechanism this is
    the minimum cycle basis networkx computes (de Pina's algorithm, whose cost grows like the cube of
    the size: tests/test_graph.py compares them). The searches run on plain dicts in networkx's order of
    nodes, neighbours and edges (its traversals cost more than the small graphs they walk). ``G``: a
    networkx graph or its adjacency (:func:`adjacency`); ``forest``: its breadth-first trees, where known.
    """
    adj = G if isinstance(G, dict) else dict(G.adjacency())
    edges = _edges(adj)
    forest = _forest(adj) if forest is None else forest
    rank = len(edges) - len(adj) + len(forest)
    order = {n: i for i, n in enumerate(adj)}
    cycles = [_canonical(c, order) for c in _short_cycle_basis(adj, edges, forest, rank)]
    cycles.sort(key=lambda c: sorted(order[n] for n in c))
    return cycles


def _edges(adj: dict) -> list[tuple]:
    """The edges in networkx's order (``G.edges``): by first node, then neighbour, each once."""
    seen: set = set()
    out = []
    for n, nbrs in adj.items():
        out += [(n, m) for m in nbrs if m not in seen]
        seen.add(n)
    return out


def _bfs_edges(adj: dict, root) -> list[tuple]:
    """Tree edges (parent, child) of a breadth-first search from ``root``, as ``nx.bfs_edges`` gives them."""
    seen = {root}
    queue = deque([root])
    out = []
    while queue:
        x = queue.popleft()
        for y in adj[x]:
            if y not in seen:
                seen.add(y)
                queue.append(y)
                out.append((x, y))
    return out


def _forest(adj: dict) -> list[list[tuple]]:
    """A breadth-first tree of each connected component, from its first node in node order (as networkx's
    components and ``bfs_edges`` give them): each as its edges (parent, child), the root first."""
    trees, seen = [], set()
    for n in adj:
        if n not in seen:
            tree = [(None, n), *_bfs_edges(adj, n)]
            seen.update(y for _, y in tree)
            trees.append(tree)
    return trees


def _walk_cycle(G: nx.Graph, nodes: list) -> list:
    """The cycle's nodes in traversal order (networkx returns them as a set-like list)."""
    nodes = list(nodes)
    if all(G.has_edge(u, v) for u, v in zip(nodes, nodes[1:] + nodes[:1], strict=True)):
        return nodes
    H = G.subgraph(nodes)
    walk, prev = [nodes[0]], None
    while len(walk) < len(nodes):
        nxt = next(n for n in H.neighbors(walk[-1]) if n != prev and n not in walk)
        prev = walk[-1]
        walk.append(nxt)
    return walk


def _canonical(nodes: list, order: dict) -> list:
    """Start from the cycle's lowest node and go the canonical way round."""
    k = min(range(len(nodes)), key=lambda i: order[nodes[i]])
    nodes = nodes[k:] + nodes[:k]
    if len(nodes) > 2 and order[nodes[1]] > order[nodes[-1]]:
        nodes = [nodes[0], *reversed(nodes[1:])]
    return nodes


def _short_cycle_basis(adj: dict, edges: list[tuple], forest: list[list[tuple]], rank: int) -> list[list]:
    """The shortest cycle through each non-tree edge of a breadth-first forest, kept greedily by length while
    independent; fundamental cycles complete the basis if some of them coincide."""
    edge_id = {frozenset(e): i for i, e in enumerate(edges)}
    fundamental = _fundamental_cycles(edges, forest)
    candidates = []
    for cyc in fundamental:  # each closes on one non-tree edge (its last and first nodes)
        if rank > SMALL_RANK and len(cyc) <= SHORT_CYCLE:
            candidates.append(cyc)  # already short: a search would cross the ground's hub (O(size) each)
            continue
        path = _shortest_path_avoiding(adj, cyc[-1], cyc[0])
        candidates.append(path if path is not None else cyc)
    candidates.sort(key=len)
    basis: dict[int, int] = {}  # pivot bit → reduced bitset, for independence tests
    chosen: list[list] = []
    for cyc in candidates + fundamental:
        if _insert(basis, _bits(cyc, edge_id)):
            chosen.append(cyc)
            if len(chosen) == rank:
                break
    return chosen


def _shortest_path_avoiding(adjacency: dict, u, v) -> list | None:
    """The shortest path v → ... → u not using the edge (u, v) (with that edge: the shortest cycle through it)."""
    prev = {v: None}
    queue = deque([v])
    while queue:
        x = queue.popleft()
        for y in adjacency[x]:
            if y in prev or (x == v and y == u):
                continue
            prev[y] = x
            if y == u:
                path = [u]
                while prev[path[-1]] is not None:
                    path.append(prev[path[-1]])
                return path
            queue.append(y)
    return None


def _fundamental_cycles(edges: list[tuple], forest: list[list[tuple]]) -> list[list]:
    """Cycles of the non-tree edges of a breadth-first spanning forest (they always span the cycle space),
    component by component, each edge in networkx's order."""
    out = []
    for tree in forest:
        parent = dict((b, a) for a, b in tree)
        depth = {tree[0][1]: 0}
        for a, b in tree[1:]:
            depth[b] = depth[a] + 1
        in_tree = {frozenset((b, a)) for b, a in parent.items() if a is not None}
        for a, b in edges:
            if a not in parent or frozenset((a, b)) in in_tree:
                continue
            left, right = [a], [b]
            while left[-1] != right[-1]:
                if depth[left[-1]] >= depth[right[-1]]:
                    left.append(parent[left[-1]])
                else:
                    right.append(parent[right[-1]])
            out.append(left + list(reversed(right[:-1])))
    return out


def _bits(cycle: list, edge_id: dict) -> int:
    b = 0
    for x, y in zip(cycle, cycle[1:] + cycle[:1], strict=True):
        b ^= 1 << edge_id[frozenset((x, y))]
    return b


def _insert(basis: dict[int, int], bits: int) -> bool:
    """Reduce ``bits`` by the basis (GF(2)); keep it if independent. Returns whether it was kept."""
    while bits:
        top = bits.bit_length() - 1
        if top not in basis:
            basis[top] = bits
            return True
        bits ^= basis[top]
    return False


# ------------------------------------------------------------------ paths


def point_paths(
    G: nx.Graph | dict, mech: Mechanism, n_terms: int, forest: list[list[tuple]] | None = None
) -> np.ndarray:
    """Step 4: every joint/point's position as a sum of terms along a breadth-first tree from the origin.

    Returns (n_terms, n_points) coefficients (±1, 0): position = z @ path. ``forest``: the graph's
    breadth-first trees (:func:`_forest`), whose first starts at the origin, where known.
    """
    points = mech.tracked_points
    root = (mech.ground, ORIGIN)
    coeff: dict[tuple[str, str], dict[int, float]] = {root: {}}
    adj = G if isinstance(G, dict) else dict(G.adjacency())
    tree = forest[0][1:] if forest and forest[0][0][1] == root else _bfs_edges(adj, root)
    for u, v in tree:
        data = adj[u][v]
        sign = 1.0 if data["start"] == u else -1.0
        c = dict(coeff[u])
        for tid, s in data["terms"]:
            c[tid] = c.get(tid, 0.0) + sign * s
        coeff[v] = c
    path = np.zeros((n_terms, len(points)))
    for k, p in enumerate(points):
        for tid, s in coeff[(mech.body_of_point(p), p)].items():
            path[tid, k] = s
    return path


# ------------------------------------------------------------------ loops


@dataclass(frozen=True)
class Loop:
    """One vector loop: its traversal, terms with signs, and the variables it involves.

    Each body the loop crosses adds one vector, from the joint where the loop enters it to the joint where it
    leaves (a chord of the body: the sum of the body's star vectors and its slider lines' offsets along the
    way), as textbooks write a loop: one ground vector O2→O4 for a four-bar, wherever the world origin is.
    ``corners`` are the nodes where the loop's vectors meet (``nodes`` less those a chord passes over)."""

    index: int
    label: str  # joints along the loop, e.g. "O2–A–B–O4"
    nodes: tuple[tuple[str, str], ...]  # (body, joint) along the traversal, from a corner
    terms: tuple[int, ...]
    signs: tuple[float, ...]
    variables: tuple[int, ...]  # variable ids involved (angles and sliders)
    corners: tuple[tuple[str, str], ...] = ()


def build_loops(mg: MechanismGraph, mech: Mechanism, cycles: list[list]) -> tuple[tuple[Loop, ...], np.ndarray]:
    """Step 3: each cycle as a loop equation Σ_k C[l, k]·z_k = 0 (C = ±1 along the traversal), one vector per
    body crossed (:func:`crossings`; chords are added to ``mg.terms``)."""
    ang, sl, r = mg.terms.ang, mg.terms.sl, mg.terms.r
    n_angles = len(mg.angle_links)
    loops = []
    at_l, at_t, coef = [], [], []  # the nonzero coefficients C[l, t]
    origin = origin_name(mech)
    chords: dict[tuple, int] = {}
    order = {n: i for i, n in enumerate(mg.adj)}
    for li, cyc in enumerate(cycles):
        cyc, row, corners = crossings(mg, cyc, chords, order, origin)
        used = list(row)
        variables: set[int] = set()
        for tid in used:
            if ang[tid] >= 0 and (r[tid] > 0 or sl[tid] >= 0 or tid in mg.terms.parts):
                variables.add(ang[tid])
            if sl[tid] >= 0:
                variables.add(n_angles + sl[tid])
        label = loop_label(corners, mech, origin)
        at_l += [li] * len(used)
        at_t += used
        coef += [row[t] for t in used]
        loops.append(
            Loop(li, label, tuple(cyc), tuple(used), tuple(row.values()), tuple(sorted(variables)), tuple(corners))
        )
    C = np.zeros((len(cycles), len(r)))
    C[at_l, at_t] = coef
    return tuple(loops), C


def loop_row(adj: dict, cyc: list) -> list[tuple[int, float, int]]:
    """The terms along a cycle: (term, coefficient, k) for edge k from cyc[k] to cyc[k + 1], in the order they
    lie along the traversal (a slider edge: its line's offset, then the slider along it)."""
    out = []
    for k, (u, v) in enumerate(zip(cyc, cyc[1:] + cyc[:1], strict=True)):
        data = adj[u][v]
        sign = 1.0 if data["start"] == u else -1.0
        out += [(tid, sign * c, k) for tid, c in (data["terms"] if sign > 0 else data["terms"][::-1])]
    return out


def crossings(mg: MechanismGraph, cyc: list, chords: dict, order: dict, origin: str) -> tuple[list, dict, list]:
    """A cycle as one vector per body crossed: (the cycle from a corner, its row {term: ±1} in traversal
    order, its corners). Vectors of zero length (a ground joint at the world origin) are left out; a body's
    consecutive rigid vectors (sl < 0) become one chord (:func:`_chord`)."""
    t = mg.terms
    items = [(tid, c, k) for tid, c, k in loop_row(mg.adj, cyc) if c != 0 and not (t.r[tid] == 0 and t.sl[tid] < 0)]
    runs = _runs([t.body[tid] if t.sl[tid] < 0 else None for tid, _, _ in items])
    size = len(cyc)
    interior: set[int] = set()  # nodes a chord passes over: between two consecutive vectors of one body
    for run in runs:
        for i, j in itertools.pairwise(run):
            m = items[i][2]
            while m != items[j][2]:
                m = (m + 1) % size
                interior.add(m)
    start = next((m for m in range(size) if m not in interior), 0)
    row: dict[int, float] = {}
    for run in sorted(runs, key=lambda run: ((items[run[0]][2] - start) % size, run[0])):
        if len(run) == 1:
            tid, c = items[run[0]][0], items[run[0]][1]
        else:
            tid, c = _chord(mg, [items[i] for i in run], chords, order)
        row[tid] = row.get(tid, 0.0) + c
    corners = [cyc[m % size] for m in range(start, start + size) if m % size not in interior]
    return cyc[start:] + cyc[:start], {k: v for k, v in row.items() if v != 0}, corners


def _runs(keys: list) -> list[list[int]]:
    """Indices of consecutive equal keys (cyclic; None never joins a run), from the first boundary."""
    n = len(keys)
    first = next((i for i in range(n) if keys[i] is None or keys[i] != keys[i - 1]), 0)
    runs: list[list[int]] = []
    for i in (x % n for x in range(first, first + n)):
        if runs and keys[i] is not None and keys[runs[-1][-1]] == keys[i]:
            runs[-1].append(i)
        else:
            runs.append([i])
    return runs


def _chord(mg: MechanismGraph, run: list, chords: dict, order: dict) -> tuple[int, float]:
    """The term for a body's consecutive rigid vectors ``run`` [(term, coefficient, edge)] — their sum, fixed in
    the body — and its coefficient ±1 in the loop. Added to ``mg.terms`` once (``chords``: its parts → term),
    oriented from the joint earlier in the node ``order`` to the later one (from a joint to a slider's line)."""
    t = mg.terms
    z = sum(c * t.r[tid] * complex(math.cos(t.delta[tid]), math.sin(t.delta[tid])) for tid, c, _ in run)
    (first, c0, _), (last, c1, _) = run[0], run[-1]
    body = t.body[first]
    begin, end = t.ends[first][0 if c0 > 0 else 1], t.ends[last][1 if c1 > 0 else 0]
    rank = [order.get((body, name), math.inf) for name in (begin, end)]
    sign = -1.0 if rank[0] > rank[1] else 1.0
    parts = tuple(sorted((tid, sign * c) for tid, c, _ in run))
    if (body, parts) not in chords:
        a, b = (end, begin) if sign < 0 else (begin, end)
        zc = sign * z
        tid = t.add(t.ang[first], -1, abs(zc), math.atan2(zc.imag, zc.real), f"{a}→{b} ({body})", body, (a, b))
        t.parts[tid] = parts
        chords[(body, parts)] = tid
    return chords[(body, parts)], sign


def loop_label(corners: list, mech: Mechanism, origin: str | None = None) -> str:
    """Joint names at a loop's corners; the world origin takes the name of a ground joint placed there (``origin``,
    where known)."""
    origin = origin_name(mech) if origin is None else origin
    names: list[str] = []
    for _, j in corners:
        n = origin if j == ORIGIN else j
        if not names or names[-1] != n:
            names.append(n)
    if len(names) > 1 and names[0] == names[-1]:
        names.pop()
    return "–".join(names)
