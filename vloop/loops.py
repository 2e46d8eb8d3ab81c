"""Graph, vector loops and unknowns: compile a Mechanism into an immutable LoopSystem.

The paper's graph: one node per (body, joint) incidence (plus the world origin on
the ground, where ground sliders measure from), an edge inside each body from its
reference node to each other node (a star, so a body adds no cycle of its own),
an edge between the nodes of the bodies that share a pin (a star per pin), and an
edge from a guide's reference node to the block it carries (the slider vector).
A minimum cycle basis (networkx) gives J − L + 1 independent loops.

Every edge carries *terms*; a term is the complex vector

    z = (r + s_i) · e^{j(φ_a + δ)}

with φ_a the angle of rotating link ``a`` (φ ≡ 0 for the ground) and s_i a slider
displacement (absent for rigid vectors). A slider block has no angle of its own:
its vectors ride on its guide's angle with a constant offset. Loop l closes when
Σ_k C[l, k] z_k = 0 (C = ±1 along the traversal).

Unknowns are the angles of rotating links and the slider displacements, less the
driven ones. The structure of the loop equations is decomposed block-triangularly
(maximum matching + strongly connected components, i.e. Dulmage–Mendelsohn at
the level of loops): each block is a set of m loops with 2m unknowns, solved after
the blocks it depends on. One-loop blocks of the classic dyad kinds are solved in
closed form by the solver; larger blocks by Newton–Raphson.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import networkx as nx
import numpy as np

from .drivers import evaluate_all
from .errors import MechanismError
from .mechanism import Mechanism

ORIGIN = "@O"  # the world origin node on the ground
DEFAULT_ASSEMBLY_TOL = 1e-3  # t = 0 closure accepted up to this fraction of the mechanism size
SINGULAR_RCOND = 1e-10  # smallest/largest singular value below this: singular Jacobian


@dataclass(frozen=True)
class Loop:
    """One vector loop: its traversal, terms with signs, and the variables it involves."""

    index: int
    label: str  # joints along the loop, e.g. "O–A–B"
    nodes: tuple[tuple[str, str], ...]  # (body, joint) along the traversal
    terms: tuple[int, ...]
    signs: tuple[float, ...]
    variables: tuple[int, ...]  # variable ids involved (angles and sliders)


@dataclass(frozen=True)
class Block:
    """Loops solved together and their unknowns (variable ids), in solving order.

    ``kind``: "RRR" (two angles), "RRP" (an angle and a slider on a known
    direction), "RPR" (a slider and its own guide's angle), "PP" (two sliders),
    or "newton" (anything else). ``sigma`` is the assembly branch (±1) of a
    closed-form dyad, taken from the t = 0 assembly.
    """

    loops: tuple[int, ...]
    unknowns: tuple[int, ...]
    kind: str
    sigma: float = 1.0


@dataclass(frozen=True)
class LoopSystem:
    """The compiled mechanism (immutable). Variables: angles 0..na-1, then sliders na..na+ns-1."""

    mechanism: Mechanism
    angle_links: tuple[str, ...]
    slider_names: tuple[str, ...]
    # terms
    t_ang: np.ndarray  # angle variable of each term, -1 = fixed (ground)
    t_sl: np.ndarray  # slider index of each term, -1 = none
    t_r: np.ndarray  # constant magnitude
    t_delta: np.ndarray  # constant angle offset [rad]
    t_label: tuple[str, ...]
    loops: tuple[Loop, ...]
    C: np.ndarray  # (n_loops, n_terms) loop coefficients
    point_names: tuple[str, ...]
    path: np.ndarray  # (n_terms, n_points): position of each point as a sum of terms
    link_outputs: tuple[tuple[str, int, float], ...]  # (name, angle var or -1, offset)
    drivers: tuple[int, ...]  # variable id driven by each driver (mechanism.drivers order)
    unknowns: tuple[int, ...]
    blocks: tuple[Block, ...]
    q0: np.ndarray  # assembled variables at t = 0
    coords_q: np.ndarray  # variables read from the file's coordinates
    graph: nx.Graph = field(repr=False)
    assembly: dict = field(default_factory=dict)
    method: str = "auto"
    cache: dict = field(default_factory=dict, repr=False, compare=False)  # solver plans

    @property
    def n_angles(self) -> int:
        return len(self.angle_links)

    @property
    def n_vars(self) -> int:
        return len(self.angle_links) + len(self.slider_names)

    def var_name(self, v: int) -> str:
        na = self.n_angles
        return f"θ_{self.angle_links[v]}" if v < na else f"s_{self.slider_names[v - na]}"

    def loops_of(self, block: Block) -> list[Loop]:
        return [self.loops[i] for i in block.loops]


# ------------------------------------------------------------------ numerics shared with the solver


def term_values(sys: LoopSystem, q: np.ndarray) -> np.ndarray:
    """Complex term vectors z for variables ``q`` (shape (..., n_vars))."""
    q = np.asarray(q, float)
    na = sys.n_angles
    phi = np.concatenate([q[..., :na], np.zeros((*q.shape[:-1], 1))], axis=-1)
    s = np.concatenate([q[..., na:], np.zeros((*q.shape[:-1], 1))], axis=-1)
    return (sys.t_r + s[..., sys.t_sl]) * np.exp(1j * (phi[..., sys.t_ang] + sys.t_delta))


def loop_jacobian(sys: LoopSystem, q: np.ndarray, loops: list[int], cols: list[int]) -> np.ndarray:
    """Real Jacobian of [Re; Im] of ``loops`` w.r.t. variables ``cols`` at one configuration ``q``."""
    z = term_values(sys, q)
    na = sys.n_angles
    phi = np.append(q[:na], 0.0)
    e = np.exp(1j * (phi[sys.t_ang] + sys.t_delta))
    Cl = sys.C[loops]
    J = np.empty((len(loops), len(cols)), complex)
    for c, v in enumerate(cols):
        d = 1j * z * (sys.t_ang == v) if v < na else e * (sys.t_sl == v - na)
        J[:, c] = Cl @ d
    return np.vstack([J.real, J.imag])


def loop_residual(sys: LoopSystem, q: np.ndarray, loops: list[int] | None = None) -> np.ndarray:
    """Complex closure residual of each loop (or of ``loops``) at ``q``."""
    C = sys.C if loops is None else sys.C[loops]
    return term_values(sys, q) @ C.T


# ------------------------------------------------------------------ compile


def compile_system(mech: Mechanism, method: str | None = None) -> LoopSystem:
    """Graph → loops → unknowns → assembly at t = 0 → block structure. Raises MechanismError.

    ``method``: "auto" (closed-form dyads where the structure allows, Newton
    elsewhere) or "newton" (one Newton block for the whole system); default from
    the file's [solver] table, else "auto".
    """
    method = method or mech.options.get("method", "auto")
    bodies = mech.bodies()
    ground = mech.ground
    angle_links = tuple(n for n, lk in mech.links.items() if not lk.ground)
    avar = {n: i for i, n in enumerate(angle_links)}
    na = len(angle_links)
    slider_names = tuple(mech.sliders)

    def owner(body: str) -> tuple[int, float]:
        """Angle variable that turns ``body`` and the constant offset of its frame."""
        b = bodies[body]
        if b.kind == "ground":
            return -1, 0.0
        if b.kind == "link":
            return avar[body], 0.0
        g = bodies[b.guide]
        return (-1 if g.kind == "ground" else avar[g.name]), b.theta0 - g.theta0

    # --- terms and graph
    t_ang: list[int] = []
    t_sl: list[int] = []
    t_r: list[float] = []
    t_delta: list[float] = []
    t_label: list[str] = []

    def add_term(ang: int, sl: int, r: float, delta: float, label: str) -> int:
        if r < 0:
            r, delta = -r, delta + math.pi
        t_ang.append(ang)
        t_sl.append(sl)
        t_r.append(r)
        t_delta.append(delta % (2 * math.pi))
        t_label.append(label)
        return len(t_r) - 1

    G = nx.Graph()
    ref: dict[str, tuple[str, str]] = {}
    G.add_node((ground, ORIGIN))
    for bname in mech.body_names:
        b = bodies[bname]
        ref[bname] = (bname, ORIGIN) if b.kind == "ground" else (bname, next(iter(b.local)))
        for m in b.local:
            G.add_node((bname, m))
    for bname in mech.body_names:
        b = bodies[bname]
        ang, off = owner(bname)
        for m, (lx, ly) in b.local.items():
            node = (bname, m)
            if node == ref[bname]:
                continue
            r = math.hypot(lx, ly)
            start = _origin_name(mech) if ref[bname][1] == ORIGIN else ref[bname][1]
            tid = add_term(ang, -1, r, math.atan2(ly, lx) + off, f"{start}→{m} ({bname})")
            G.add_edge(ref[bname], node, terms=((tid, 1.0),), start=ref[bname], kind="link")
    for j in mech.joints:
        at = mech.bodies_at(j)
        for other in at[1:]:
            G.add_edge((at[0], j), (other, j), terms=(), start=(at[0], j), kind="pin")
    coords_s = []
    for i, sl in enumerate(mech.sliders.values()):
        g = bodies[sl.guide]
        ang, _ = owner(sl.guide)
        px, py = mech.joints[sl.joint]
        dx, dy = px - g.origin[0], py - g.origin[1]
        cg, sg = math.cos(g.theta0), math.sin(g.theta0)
        lx, ly = cg * dx + sg * dy, -sg * dx + cg * dy
        alpha = math.atan2(sl.axis[1], sl.axis[0]) - g.theta0
        s0 = lx * math.cos(alpha) + ly * math.sin(alpha)
        e = -lx * math.sin(alpha) + ly * math.cos(alpha)
        coords_s.append(s0)
        terms = [(add_term(ang, i, 0.0, alpha, f"s_{sl.name}"), 1.0)]
        if abs(e) > 1e-15 * mech.scale:
            terms.append((add_term(ang, -1, e, alpha + math.pi / 2, f"offset of {sl.name}"), 1.0))
        G.add_edge(ref[sl.guide], (sl.name, sl.joint), terms=tuple(terms), start=ref[sl.guide], kind="slider")

    n_terms = len(t_r)
    arr_ang = np.array(t_ang, int)
    arr_sl = np.array(t_sl, int)
    arr_r = np.array(t_r, float)
    arr_delta = np.array(t_delta, float)

    # --- loops from a minimum cycle basis
    order = {n: i for i, n in enumerate(G.nodes)}
    cycles = [_ordered_cycle(G, c, order) for c in nx.minimum_cycle_basis(G)]
    cycles.sort(key=lambda c: sorted(order[n] for n in c))
    loops: list[Loop] = []
    C = np.zeros((len(cycles), n_terms))
    for li, cyc in enumerate(cycles):
        walk: list[int] = []  # terms in traversal order, as the paper writes a loop
        for u, v in zip(cyc, cyc[1:] + cyc[:1], strict=True):
            data = G.edges[u, v]
            sign = 1.0 if data["start"] == u else -1.0
            for tid, s in data["terms"]:
                C[li, tid] += sign * s
                walk.append(tid)
        C[li, (arr_r == 0) & (arr_sl < 0)] = 0.0  # zero-length vectors (coincident pins) add nothing
        used = np.array([t for t in dict.fromkeys(walk) if C[li, t] != 0], int)
        variables: set[int] = set()
        for tid in used:
            if arr_ang[tid] >= 0 and (arr_r[tid] > 0 or arr_sl[tid] >= 0):
                variables.add(int(arr_ang[tid]))
            if arr_sl[tid] >= 0:
                variables.add(na + int(arr_sl[tid]))
        loops.append(
            Loop(
                li,
                _loop_label(cyc, mech),
                tuple(cyc),
                tuple(int(t) for t in used),
                tuple(C[li, used]),
                tuple(sorted(variables)),
            )
        )

    # --- point positions as sums of terms along a BFS tree from the world origin
    points = mech.tracked_points
    path = np.zeros((n_terms, len(points)))
    coeff: dict[tuple[str, str], np.ndarray] = {(ground, ORIGIN): np.zeros(n_terms)}
    for u, v in nx.bfs_edges(G, (ground, ORIGIN)):
        data = G.edges[u, v]
        sign = 1.0 if data["start"] == u else -1.0
        c = coeff[u].copy()
        for tid, s in data["terms"]:
            c[tid] += sign * s
        coeff[v] = c
    for k, p in enumerate(points):
        path[:, k] = coeff[(mech.body_of_point(p), p)]

    link_outputs = tuple((name, *owner(name)) for name in mech.moving_links)

    # --- drivers and unknowns
    driven = []
    for d in mech.drivers:
        driven.append(avar[d.target] if d.kind == "crank" else na + slider_names.index(d.target))
    coords_q = np.array([bodies[n].theta0 for n in angle_links] + coords_s, float)
    unknowns = tuple(v for v in range(na + len(slider_names)) if v not in driven)

    sys = LoopSystem(
        mech, angle_links, slider_names, arr_ang, arr_sl, arr_r, arr_delta, tuple(t_label), tuple(loops), C,
        points, path, link_outputs, tuple(driven), unknowns, (), coords_q, coords_q, G,
    )  # fmt: skip
    q0, report = _assemble(sys)
    blocks = _blocks(sys, q0, method)
    if mech.options.get("branches"):
        blocks, q0, report = _choose_branches(sys, blocks, q0, report)
    return dataclasses.replace(sys, blocks=blocks, q0=q0, assembly=report, method=method, cache={})


def _ordered_cycle(G: nx.Graph, nodes: list, order: dict) -> list:
    """The cycle's nodes in traversal order, from its lowest node, in a canonical direction."""
    nodes = list(nodes)
    ok = all(G.has_edge(u, v) for u, v in zip(nodes, nodes[1:] + nodes[:1], strict=True))
    if not ok:  # walk the cycle's own subgraph
        H = G.subgraph(nodes)
        start = nodes[0]
        walk, prev = [start], None
        while len(walk) < len(nodes):
            nxt = next(n for n in H.neighbors(walk[-1]) if n != prev and n not in walk)
            prev = walk[-1]
            walk.append(nxt)
        nodes = walk
    k = min(range(len(nodes)), key=lambda i: order[nodes[i]])
    nodes = nodes[k:] + nodes[:k]
    if len(nodes) > 2 and order[nodes[1]] > order[nodes[-1]]:
        nodes = [nodes[0], *reversed(nodes[1:])]
    return nodes


def _origin_name(mech: Mechanism) -> str:
    """The world origin's display name: a ground joint placed there, else "O"."""
    at_origin = [j for j in mech.links[mech.ground].joints if mech.joints[j] == (0.0, 0.0)]
    return at_origin[0] if at_origin else "O"


def _loop_label(cyc: list, mech: Mechanism) -> str:
    """Joint names along the loop; the world origin takes the name of a ground joint placed there."""
    origin = _origin_name(mech)
    names: list[str] = []
    for _, j in cyc:
        n = origin if j == ORIGIN else j
        if not names or names[-1] != n:
            names.append(n)
    if len(names) > 1 and names[0] == names[-1]:
        names.pop()
    return "–".join(names)


def _assemble(sys: LoopSystem) -> tuple[np.ndarray, dict]:
    """Close the loops at t = 0 from the file's coordinates (drivers at their t = 0 values)."""
    mech = sys.mechanism
    tol = mech.options.get("assembly_tolerance", DEFAULT_ASSEMBLY_TOL)
    q = sys.coords_q.copy()
    if mech.drivers:
        x0 = evaluate_all(mech, np.zeros(1))[0][0]
        q[list(sys.drivers)] = x0
    scale = mech.scale
    if not sys.loops:
        return q, {"iterations": 0, "closure": 0.0, "moved": 0.0}
    res0 = np.abs(loop_residual(sys, q))
    worst = int(np.argmax(res0))
    if res0[worst] > tol * scale:
        lp = sys.loops[worst]
        why = ""
        if any(abs(q[v] - sys.coords_q[v]) > 1e-12 for v in sys.drivers):
            why = " with the drivers' t = 0 values (theta0/s0 differ from the coordinates)"
        raise MechanismError(
            f"{mech.source}: [joints] the t = 0 coordinates do not close loop {lp.index + 1} ({lp.label}){why}: "
            f"off by {res0[worst]:.4g} {mech.units} ({res0[worst] / scale:.2g} of the mechanism size; "
            f"accepted up to {tol:g})",
            entry="joints",
        )
    unk = list(sys.unknowns)
    rows = list(range(len(sys.loops)))
    it = 0
    for it in range(1, 51):  # noqa: B007 - iteration count is reported
        F = loop_residual(sys, q)
        Fr = np.concatenate([F.real, F.imag])
        J = loop_jacobian(sys, q, rows, unk)
        step = np.linalg.lstsq(J, -Fr, rcond=None)[0]
        q[unk] += step
        if np.max(np.abs(step), initial=0.0) <= 1e-14 * (1 + np.max(np.abs(q[unk]), initial=0.0)):
            break
    closure = float(np.max(np.abs(loop_residual(sys, q)))) / scale
    if closure > 1e-11:
        raise MechanismError(
            f"{mech.source}: [joints] cannot assemble the mechanism at t = 0 from the given coordinates "
            f"(closure {closure:.2g} of its size after {it} Newton steps)",
            entry="joints",
        )
    J = loop_jacobian(sys, q, rows, unk)
    if unk:
        sv = np.linalg.svd(J, compute_uv=False)
        if sv[-1] < SINGULAR_RCOND * sv[0]:
            raise MechanismError(
                f"{mech.source}: [joints] the loop Jacobian is singular at t = 0 "
                f"(rank {int(np.sum(sv >= SINGULAR_RCOND * sv[0]))} "
                f"of {len(unk)}): the mechanism is at a dead point or toggle at t = 0, or some of its constraints are "
                f"redundant; Gruebler's count M = {mech.gruebler()[2]} does not see this",
                entry="joints",
            )
    # how far the assembly moved each point from the typed coordinates
    z0 = term_values(sys, sys.coords_q)
    z1 = term_values(sys, q)
    moved = np.abs((z1 - z0) @ sys.path) if len(sys.point_names) else np.zeros(0)
    return q, {
        "iterations": it,
        "closure": closure,
        "initial_closure": float(res0.max()) / scale,
        "moved": float(moved.max(initial=0.0)),
        "moved_by_point": dict(zip(sys.point_names, moved.tolist(), strict=True)),
    }


def loop_polygon(sys: LoopSystem, q: np.ndarray, loop: Loop) -> list[complex]:
    """The distinct joints along a loop at configuration ``q`` (the world origin where the loop uses it)."""
    z = term_values(sys, q)
    tol = 1e-12 * sys.mechanism.scale
    pts: list[complex] = []
    for _, joint in loop.nodes:
        p = 0j if joint == ORIGIN else complex(z @ sys.path[:, sys.point_names.index(joint)])
        if not pts or abs(p - pts[-1]) > tol:
            pts.append(p)
    if len(pts) > 1 and abs(pts[0] - pts[-1]) <= tol:
        pts.pop()
    return pts


def _segments_cross(a: complex, b: complex, c: complex, d: complex) -> bool:
    def orient(p: complex, q: complex, r: complex) -> float:
        return ((q - p).conjugate() * (r - p)).imag

    return orient(a, b, c) * orient(a, b, d) < 0 and orient(c, d, a) * orient(c, d, b) < 0


def branch_name(sys: LoopSystem, q: np.ndarray, loop: Loop) -> str | None:
    """ "open" or "crossed" for a loop of four joints (a four-bar's quadrilateral), else None."""
    pts = loop_polygon(sys, q, loop)
    if len(pts) != 4:
        return None
    crossed = _segments_cross(pts[0], pts[1], pts[2], pts[3]) or _segments_cross(pts[1], pts[2], pts[3], pts[0])
    return "crossed" if crossed else "open"


def _choose_branches(
    sys: LoopSystem, blocks: tuple[Block, ...], q0: np.ndarray, report: dict
) -> tuple[tuple[Block, ...], np.ndarray, dict]:
    """Put the dyads the file names in [solver] branches on the requested branch, then re-assemble t = 0."""
    from .solver import assemble_blocks

    mech = sys.mechanism
    wanted: dict[int, str] = mech.options["branches"]
    by_loop = {b.loops[0]: i for i, b in enumerate(blocks) if len(b.loops) == 1}
    new = list(blocks)
    for number, choice in sorted(wanted.items()):
        li = number - 1
        if li >= len(sys.loops):
            raise MechanismError(f"{mech.source}: [solver] branches: there is no loop {number}", entry="solver")
        i = by_loop.get(li)
        if i is None or blocks[i].kind not in ("RRR", "RRP", "RPR"):
            raise MechanismError(
                f"{mech.source}: [solver] branches: loop {number} ({sys.loops[li].label}) is not a dyad with two "
                "assembly branches",
                entry="solver",
            )
        flip = choice == "flip"
        if choice in ("open", "crossed"):
            now = branch_name(sys, q0, sys.loops[li])
            if now is None:
                raise MechanismError(
                    f"{mech.source}: [solver] branches: loop {number} ({sys.loops[li].label}) is not a four-joint "
                    "loop; 'open'/'crossed' name a four-bar's branches — use 'flip' or 'keep'",
                    entry="solver",
                )
            flip = now != choice
        if flip:
            new[i] = dataclasses.replace(blocks[i], sigma=-blocks[i].sigma)
    if new == list(blocks):
        return blocks, q0, report
    q1 = assemble_blocks(sys, tuple(new), q0)
    z0, z1 = term_values(sys, sys.coords_q), term_values(sys, q1)
    moved = np.abs((z1 - z0) @ sys.path)
    report = dict(report, moved=float(moved.max(initial=0.0)), branches_flipped=True)
    report["moved_by_point"] = dict(zip(sys.point_names, moved.tolist(), strict=True))
    return tuple(new), q1, report


def _blocks(sys: LoopSystem, q0: np.ndarray, method: str) -> tuple[Block, ...]:
    """Block-triangular decomposition of the loop equations and closed-form classification."""
    mech = sys.mechanism
    unk = list(sys.unknowns)
    if not unk:
        return ()
    if method == "newton":
        return (Block(tuple(range(len(sys.loops))), tuple(unk), "newton"),)
    B = nx.Graph()
    rows = [("row", lp.index, part) for lp in sys.loops for part in (0, 1)]
    B.add_nodes_from(rows, bipartite=0)
    B.add_nodes_from((("var", v) for v in unk), bipartite=1)
    for lp in sys.loops:
        for v in lp.variables:
            if v in unk:
                B.add_edge(("row", lp.index, 0), ("var", v))
                B.add_edge(("row", lp.index, 1), ("var", v))
    match = nx.bipartite.hopcroft_karp_matching(B, top_nodes=rows)
    unmatched_rows = [r for r in rows if r not in match]
    unmatched_vars = [v for v in unk if ("var", v) not in match]
    if unmatched_rows or unmatched_vars:
        over = sorted({sys.loops[r[1]].label for r in unmatched_rows})
        free = [sys.var_name(v) for v in unmatched_vars]
        raise MechanismError(
            f"{mech.source}: [links] the loop equations cannot be solved: "
            + (f"loops {', '.join(over)} over-constrain their part of the mechanism" if over else "")
            + ("; " if over and free else "")
            + (f"{', '.join(free)} are not fixed by any loop (that part can move freely)" if free else ""),
            entry="links",
        )
    D = nx.DiGraph()
    D.add_nodes_from(unk)
    for v in unk:
        r = match[("var", v)]
        for w in sys.loops[r[1]].variables:
            if w in unk and w != v:
                D.add_edge(v, w)  # v's equation needs w
    cond = nx.condensation(D)
    blocks = []
    # dependencies first; among blocks ready together, the lower loop number first
    first_loop = {c: min(match[("var", v)][1] for v in cond.nodes[c]["members"]) for c in cond.nodes}
    for c in nx.lexicographical_topological_sort(cond.reverse(copy=False), key=first_loop.get):
        vars_ = sorted(cond.nodes[c]["members"])
        loops = sorted({match[("var", v)][1] for v in vars_})
        blocks.append(_classify(sys, q0, tuple(loops), tuple(vars_)))
    return tuple(blocks)


def _classify(sys: LoopSystem, q0: np.ndarray, loops: tuple[int, ...], unknowns: tuple[int, ...]) -> Block:
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
