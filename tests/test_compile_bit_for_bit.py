"""The compiler's fast paths give exactly what the straightforward computations give: networkx's traversals and matching, numpy's loop residuals and Jacobians, np.add.at sums, the SVD rank
test and the drivers' arrays at t = 0 — compared bit for bit on every catalog mechanism and on generated ones.
The t = 0 checks still refuse what they refused, with the same messages."""

from __future__ import annotations

import dataclasses
import importlib.util
import math
from types import SimpleNamespace

import networkx as nx
import numpy as np
import pytest

import vloop
from tests.conftest import ROOT, mechanism_files
from tests.test_bad_input import FOURBAR
from validators import corpus
from vloop.core import plans, sums
from vloop.drivers import evaluate_all
from vloop.errors import MechanismError
from vloop.method import assembly, graph, structure
from vloop.method.loops import DyadTerms, LoopGroup, TermIndex, loop_jacobian, loop_residual, term_values

N_GENERATED = 120


def dyad_chain(n: int) -> vloop.Mechanism:
    """benchmarks/bench_compile.py's chain of ``n`` dyads: sums and blocks past SMALL_SUM (built by numpy)."""
    spec = importlib.util.spec_from_file_location("bench_compile", ROOT / "benchmarks" / "bench_compile.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    return bench.dyad_chain(n)


@pytest.fixture(scope="module")
def systems() -> list:
    """Every catalog mechanism (both methods), generated ones and a long chain (both methods), compiled."""
    mechs = [vloop.load(p) for p in mechanism_files()] + [dyad_chain(40)]
    mechs += [item.mechanism for item in corpus.generate(N_GENERATED, 2026)[0]]
    out = [vloop.compile(m) for m in mechs]
    return out + [vloop.compile(m, "newton") for m in mechs[: len(mechanism_files()) + 1]]


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """Bit for bit: dtype, shape, bytes and memory layout."""
    a, b = np.asarray(a), np.asarray(b)
    layout = a.strides == b.strides if a.size else True
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes() and layout


# ------------------------------------------------------------------ graph traversals


def random_graphs() -> list[nx.Graph]:
    rng = np.random.default_rng(5)
    out = []
    for n in (1, 2, 5, 9, 14, 30):
        for m in (n - 1, n, n + 3, 2 * n):
            G = nx.gnm_random_graph(n, max(m, 0), seed=int(rng.integers(1 << 30)))
            out.append(nx.relabel_nodes(G, {v: (f"b{v % 3}", f"j{v}") for v in G}))  # nodes as the compiler's
    return out


def test_traversals_are_networkx_ones(systems):
    """Edges, breadth-first trees and components in networkx's order: the cycle basis and point paths built on
    them are networkx's."""
    for G in [s.graph for s in systems] + random_graphs():
        adj = dict(G.adjacency())
        assert graph._edges(adj) == list(G.edges)
        for root in list(G)[:6]:
            assert graph._bfs_edges(adj, root) == list(nx.bfs_edges(G, root))
        order = {n: i for i, n in enumerate(G)}
        roots = [min(c, key=order.__getitem__) for c in nx.connected_components(G)]
        forest = graph._forest(adj)
        assert [tree[0][1] for tree in forest] == roots
        assert [tree[1:] for tree in forest] == [list(nx.bfs_edges(G, r)) for r in roots]


# ------------------------------------------------------------------ block structure


def reference_analyse(sys) -> structure.Structure:
    """The block structure by networkx: Hopcroft–Karp, condensation, lexicographic topological order."""
    unk = list(sys.unknowns)
    if not unk:
        return structure.Structure(((tuple(range(len(sys.loops))), ()),) if sys.loops else (), bool(sys.loops))
    match, unmatched_rows = structure._matching(sys, unk)
    if unmatched_rows:
        return structure.Structure(((tuple(range(len(sys.loops))), tuple(unk)),), True)
    D = nx.DiGraph()
    D.add_nodes_from(unk)
    for v in unk:
        for w in sys.loops[match[("var", v)][1]].variables:
            if w in unk and w != v:
                D.add_edge(v, w)
    cond = nx.condensation(D)
    first = {c: min(match[("var", v)][1] for v in cond.nodes[c]["members"]) for c in cond.nodes}
    groups = []
    for c in nx.lexicographical_topological_sort(cond.reverse(copy=False), key=first.get):
        vars_ = sorted(cond.nodes[c]["members"])
        groups.append((tuple(sorted({match[("var", v)][1] for v in vars_})), tuple(vars_)))
    return structure.Structure(tuple(groups))


def random_structures() -> list[SimpleNamespace]:
    """Loops over random variable sets: square, redundant and under-determined, coupled and triangular."""
    rng = np.random.default_rng(11)
    out = []
    for _ in range(400):
        n_loops = int(rng.integers(1, 7))
        n_vars = int(rng.integers(1, 2 * n_loops + 3))
        loops = []
        for li in range(n_loops):
            k = int(rng.integers(1, min(n_vars, 4) + 1))
            loops.append(SimpleNamespace(index=li, variables=tuple(sorted(rng.choice(n_vars, k, replace=False)))))
        driven = set(rng.choice(n_vars, int(rng.integers(0, 2)), replace=False).tolist())
        out.append(
            SimpleNamespace(
                loops=tuple(loops),
                unknowns=tuple(v for v in range(n_vars) if v not in driven),
                var_name=lambda v: f"x{v}",
                mechanism=SimpleNamespace(source="random"),
            )
        )
    return out


def outcome(f, sys):
    try:
        return f(sys)
    except MechanismError as e:
        return str(e)


def test_block_structure_is_networkx_one(systems):
    """Any maximum matching gives networkx's groups and order (the fine decomposition is unique); a structure
    whose unknowns cannot all be matched is refused with networkx's message."""
    cases = list(systems) + random_structures()
    results = [(outcome(structure.analyse, s), outcome(reference_analyse, s)) for s in cases]
    assert all(a == b for a, b in results)
    kinds = {type(a).__name__ for a, _ in results}
    assert kinds == {"Structure", "str"}  # both refusals and structures were compared
    assert any(isinstance(a, structure.Structure) and a.over_determined for a, _ in results)
    assert any(isinstance(a, structure.Structure) and len(a.groups) > 2 for a, _ in results)


# ------------------------------------------------------------------ t = 0 assembly


def reference_assemble_q(sys, struct) -> tuple[np.ndarray, int]:
    """Newton at t = 0 by loop_residual and loop_jacobian at every step, the drivers by evaluate_all."""
    q = sys.coords_q.copy()
    if sys.mechanism.drivers:
        q[list(sys.drivers)] = evaluate_all(sys.mechanism, np.zeros(1))[0][0]
    iterations = 0
    for loops, unknowns in struct.groups:
        loops, unknowns = list(loops), list(unknowns)
        for _ in range(50) if unknowns else ():
            iterations += 1
            F = loop_residual(sys, q, loops)
            J = loop_jacobian(sys, q, loops, unknowns)
            rhs = -np.concatenate([F.real, F.imag])
            try:
                step = np.linalg.solve(J, rhs) if J.shape[0] == J.shape[1] else np.linalg.lstsq(J, rhs, rcond=None)[0]
            except np.linalg.LinAlgError:
                step = np.linalg.lstsq(J, rhs, rcond=None)[0]
            q[unknowns] += step
            if np.max(np.abs(step), initial=0.0) <= 1e-14 * (1 + np.max(np.abs(q[unknowns]), initial=0.0)):
                break
    return q, iterations


def test_assembly_is_the_step_by_step_one(systems):
    """The compiled q0 is that of Newton by loop_residual/loop_jacobian with the same iterations: bit for bit where
    a group is solved by numpy, within a few units in the last place where a one-loop group of two unknowns is
    solved in Python numbers (math.cos/sin, Cramer's rule: 2 of 600 generated mechanisms differ, by ≤ 8.9e-16;
    none of the catalog). The report's closure and distances are those at q0."""
    differ = 0
    for sys in systems:
        if sys.mechanism.options.get("branches"):
            continue  # re-assembled by the closed forms after the branch flip
        struct = structure.analyse(sys)
        q, iterations = reference_assemble_q(sys, struct)
        assert np.all(np.abs(sys.q0 - q) <= 4 * np.spacing(np.maximum(np.abs(q), 1.0))), sys.mechanism.name
        differ += not same(sys.q0, q)
        assert sys.assembly["iterations"] == iterations
        closure = float(np.max(np.abs(loop_residual(sys, sys.q0)))) / sys.mechanism.scale
        assert sys.assembly["closure"] == closure
        assert sys.assembly == {**sys.assembly, **assembly.moved(sys, sys.q0)}
    assert differ <= len(systems) // 50


def test_a_dyad_group_assembles_like_least_squares():
    """loops.DyadTerms' residual and Jacobian are loop_residual's and loop_jacobian's (to round-off) at random
    configurations, and a group it cannot step (a singular Jacobian) is left to numpy's least squares."""
    rng = np.random.default_rng(11)
    mechs = [vloop.load(p) for p in mechanism_files()] + [item.mechanism for item in corpus.generate(40, 5)[0]]
    checked = 0
    for mech in mechs:
        sys = vloop.compile(mech)
        for loops, unknowns in structure.analyse(sys).groups:
            if len(loops) != 1 or len(unknowns) != 2:
                continue
            dyad = DyadTerms(sys, loops[0], list(unknowns))
            for _ in range(3):
                q = sys.q0 + rng.normal(0, 0.3, sys.n_vars)
                z, e = dyad.at(q.tolist())
                F = sum(t[0] * zt for t, zt in zip(dyad.terms, z, strict=True))
                j0, j1 = dyad.columns(z, e)
                ref_F = loop_residual(sys, q, list(loops))[0]
                ref_J = loop_jacobian(sys, q, list(loops), list(unknowns))
                size = sys.mechanism.scale
                assert abs(F - ref_F) <= 1e-14 * size
                np.testing.assert_allclose(dyad.jacobian(np.array(z), np.array(e)), ref_J, rtol=0, atol=1e-14 * size)
                assert np.allclose([[j0.real, j1.real], [j0.imag, j1.imag]], ref_J, rtol=0, atol=1e-14 * size)
                checked += 1
    assert checked > 100
    singular = vloop.compile(vloop.load(mechanism_files()[0]))
    loops, unknowns = next((lp, un) for lp, un in structure.analyse(singular).groups if len(un) == 2)
    dyad = DyadTerms(singular, loops[0], list(unknowns))
    dyad.terms = [(0.0, *t[1:]) for t in dyad.terms]  # every coefficient zero: J = 0
    q = singular.q0.copy()
    assert assembly._close_dyad(dyad, q) is None and same(q, singular.q0)


def test_loop_group_is_loop_residual_and_jacobian(systems):
    """TermIndex and LoopGroup evaluate term_values, loop_residual and loop_jacobian's arithmetic, bit for bit."""
    rng = np.random.default_rng(3)
    for sys in systems[:60]:
        every = TermIndex(sys)
        for _ in range(3):
            q = sys.q0 + rng.normal(0, 0.3, sys.n_vars) * np.where(np.arange(sys.n_vars) < sys.n_angles, 1, 0.1)
            z, e = every.at(q)
            assert same(z, term_values(sys, q))
            for loops, unknowns in structure.analyse(sys).groups:
                if not unknowns:
                    continue
                g = LoopGroup(sys, list(loops), list(unknowns))
                zk, ek = g.at(q)
                assert same(zk, z[g.k]) and same(ek, e[g.k])
                assert same(g.residual(zk), loop_residual(sys, q, list(loops)))
                assert same(g.jacobian(zk, ek), loop_jacobian(sys, q, list(loops), list(unknowns)))


def test_inputs_at_start_are_evaluate_alls():
    mech = vloop.load(mechanism_files()[0])
    for x0, v0, a0 in [(0.0, 0.0, 0.0), (-0.0, 0.0, 0.0), (-0.0, -1.0, 2.0), (1.3, -2.0, -0.0), (5e-324, 1e308, -3.0)]:
        d = dataclasses.replace(mech.drivers[0], x0=x0, v0=v0, a0=a0)
        m = dataclasses.replace(mech, drivers=(d,))
        assert same(np.array(assembly.inputs_at_start(m)), evaluate_all(m, np.zeros(1))[0][0])


def test_clearly_regular_agrees_with_the_svd():
    """The 2×2 shortcut only ever says "regular" where the SVD's rank test passes, and says it for ordinary
    Jacobians (the SVD is skipped)."""
    rng = np.random.default_rng(7)
    skipped = 0
    for _ in range(20000):
        ratio = 10.0 ** rng.uniform(-13, 0)
        scale = 10.0 ** rng.uniform(-70, 70)
        U, _ = np.linalg.qr(rng.normal(size=(2, 2)))
        V, _ = np.linalg.qr(rng.normal(size=(2, 2)))
        J = scale * U @ np.diag([1.0, ratio]) @ V
        sv = np.linalg.svd(J, compute_uv=False)
        if assembly._clearly_regular(J):
            skipped += 1
            assert sv[-1] >= 100 * assembly.SINGULAR_RCOND * sv[0] * (1 - 1e-6)
        elif ratio > 1e-6 and 1e-60 < scale < 1e60:
            raise AssertionError(f"an ordinary Jacobian was sent to the SVD: {J}")
    assert skipped > 10000
    for J in (np.zeros((2, 2)), np.full((2, 2), np.nan), np.array([[1e300, 0], [0, 1e300]]), np.eye(2) * 1e-300):
        assert not assembly._clearly_regular(J)


# ------------------------------------------------------------------ the solver's sums


def reference_sum(sys, terms: np.ndarray, M: np.ndarray) -> dict:
    """_Sum.build by numpy: np.add.at over the terms, the real representations by strided assignment."""
    na, ns = sys.n_angles, len(sys.slider_names)
    ang, sl, r = sys.t_ang[terms], sys.t_sl[terms], sys.t_r[terms]
    cd = np.exp(1j * sys.t_delta[terms])
    M = M.astype(complex).reshape(len(terms), -1)
    K = M.shape[1]
    col = np.where(ang < 0, na, ang)
    ground = (sl < 0) | (ang < 0)
    G = np.zeros((na + 1, K), complex)
    np.add.at(G, col[ground], (r * cd)[ground][:, None] * M[ground])
    on_line = (sl >= 0) & (ang < 0)
    H = np.zeros((ns + 1, K), complex)
    np.add.at(H, sl[on_line], cd[on_line][:, None] * M[on_line])

    def used(idx: np.ndarray, width: int):
        cols = np.unique(idx)
        return None if 2 * len(cols) > width else cols

    def real_rep(G: np.ndarray) -> np.ndarray:
        R = np.empty((2 * G.shape[0], 2 * G.shape[1]))
        R[0::2, 0::2], R[0::2, 1::2] = G.real, G.imag
        R[1::2, 0::2], R[1::2, 1::2] = -G.imag, G.real
        return R

    acols, scols = used(ang[ground & (ang >= 0)], na + 1), used(sl[on_line], ns + 1)
    c0 = np.zeros(2 * K)
    if acols is not None:
        c0 = np.ascontiguousarray(G[na]).view(float).copy()
        G = G[acols]
    H = H if scols is None else H[scols]
    H = np.ascontiguousarray(H).view(float).reshape(len(H), 2 * K)
    mv = (sl >= 0) & (ang >= 0)
    return dict(
        acols=acols, R=real_rep(G), Rj=real_rep(1j * G), c0=c0, scols=scols, H=H, s_ang=ang[mv], s_sl=sl[mv],
        s_r=r[mv], s_cd=cd[mv], Ms=M[mv],
    )  # fmt: skip


@pytest.mark.parametrize("plans_first", [False, True])
def test_sums_are_np_add_at_ones(systems, plans_first):
    """Every plan's and every system's sums equal numpy's construction, bit for bit: small ones made from Python
    numbers (alone or together), large ones by numpy."""
    large = 0
    for sys in systems:
        sys = dataclasses.replace(sys, cache={})
        if plans_first:
            plans.block_plans(sys)
        everything = np.arange(len(sys.t_r))
        built = list(zip(plans.system_sums(sys), ((everything, sys.path), (everything, sys.C.T)), strict=True))
        for p in plans.block_plans(sys):
            terms, Cb, ang, sl, unk_ang, _, known = plans.block_terms(sys, p.block)
            still = ~((sl < 0) & np.isin(ang, unk_ang))
            built += [(p.total, (terms, Cb.T)), (p.known_sum, (terms[known], -Cb.T[known]))]
            built += [(p.vel_sum, (terms[still], Cb.T[still]))]
        for s, args in built:
            large += args[1].size > sums.SMALL_SUM
            ref = reference_sum(sys, *args)
            for name, value in ref.items():
                mine = getattr(s, name)
                assert (mine is None) == (value is None), name
                assert value is None or same(mine, value), name
    assert large >= 4  # the chain's point paths and loops, and its Newton block's sums


def reference_block_terms(sys, b) -> tuple:
    """block_terms by numpy indexing."""
    Cb = sys.C[list(b.loops)]
    terms = np.nonzero(np.any(Cb != 0, axis=0))[0]
    Cb = Cb[:, terms]
    ang, sl = sys.t_ang[terms], sys.t_sl[terms]
    unk_ang = [v for v in b.unknowns if v < sys.n_angles]
    unk_sl = [v - sys.n_angles for v in b.unknowns if v >= sys.n_angles]
    return terms, Cb, ang, sl, unk_ang, unk_sl, ~(np.isin(ang, unk_ang) | np.isin(sl, unk_sl))


def test_plan_constants_are_numpy_scalar_ones(systems):
    for sys in systems:
        cd = np.exp(1j * sys.t_delta)
        for p in plans.block_plans(sys):
            ref = reference_block_terms(sys, p.block)
            for mine, theirs in zip(plans.block_terms(sys, p.block), ref, strict=True):
                assert mine == theirs if isinstance(mine, list) else same(mine, theirs)
            terms, Cb, ang, sl, unk_ang, unk_sl, known = ref
            assert same(p.C, Cb) and same(p.Ct, Cb.T.astype(complex)) and same(p.known, known)
            assert same(p.r, sys.t_r[terms]) and same(p.cd, cd[terms])
            masks = [(ang == v) if v < sys.n_angles else (sl == v - sys.n_angles) for v in p.block.unknowns]
            assert all(same(a, b) for a, b in zip(p.masks, masks, strict=True))
            g = Cb[0]
            for a in unk_ang:
                on = np.nonzero(ang == a)[0]
                w = complex(sum(g[t] * sys.t_r[terms[t]] * cd[terms[t]] for t in on))
                assert same(np.array(p.w_const[a]), np.array(w))
                ref = [(int(sl[t]), complex(g[t] * cd[terms[t]])) for t in on if sl[t] >= 0]
                assert [(i, np.array(c).tobytes()) for i, c in p.w_sl[a]] == [
                    (i, np.array(c).tobytes()) for i, c in ref
                ]
            for i in unk_sl:
                t = int(np.nonzero(sl == i)[0][0])
                assert p.u_dir[i][0] == int(ang[t])
                assert same(np.array(p.u_dir[i][1]), np.array(complex(g[t] * cd[terms[t]])))


# ------------------------------------------------------------------ the t = 0 refusals


# the four-bar of tests/test_bad_input.py with the coupler and the rocker in line at t = 0 (a toggle)
TOGGLE = (
    FOURBAR.replace("A = [0.0, 2.0]", "A = [0.0, 1.0]")
    .replace("B = [5.0, 4.0]", "B = [2.0, 1.0]")
    .replace("O4 = [7.0, 0.0]", "O4 = [4.0, 1.0]")
)


def refusal(text: str) -> str:
    with pytest.raises(MechanismError) as err:
        vloop.compile(vloop.loads(text))
    return str(err.value)


def test_t0_refusals_keep_their_messages():
    """Coordinates that do not close, a driver's theta0 off its coordinates, a toggle at t = 0: the messages
    vloop gave before the fast paths, word for word."""
    root = mechanism_files()[0].parent
    eightbar = (root / "eightbar.toml").read_text()
    assert refusal(eightbar.replace("C  = [8.0, 4.6715]", "C  = [8.0, 4.9]")) == (
        "<string>: [joints] the t = 0 coordinates do not close loop 2 (O2–B–C): off by 0.1753 m (0.014 of the "
        "mechanism size; accepted up to 0.001)"
    )
    fourbar = (root / "fourbar_textbook_example.toml").read_text()
    fourbar = fourbar.replace(", length = 120.0 }", " }")  # the coupler drawn, not stated: coordinates, not hints
    assert refusal(fourbar.replace("omega = ", "theta0 = 0.3\nomega = ")) == (
        "<string>: [joints] the t = 0 coordinates do not close loop 1 (O2–A–B–O4) with the drivers' t = 0 values "
        "(theta0/s0 differ from the coordinates): off by 15.82 mm (0.1 of the mechanism size; accepted up to 0.001)"
    )
    assert refusal(TOGGLE) == (
        "<string>: [joints] the loop Jacobian is singular at t = 0 (rank 1 of 2): the mechanism is at a dead "
        "point or toggle at t = 0, or some of its constraints are redundant; Gruebler's count M = 1 does not see this"
    )


def test_nearly_closing_coordinates_are_still_assembled():
    """Within the tolerance the typed coordinates are moved onto the loops (Newton runs): the eight-bar's rounded
    k = g = 4.6715 become √(6.15² − 4²)."""
    sys = vloop.compile(vloop.load(mechanism_files()[0].parent / "eightbar.toml"))
    k = math.sqrt(6.15**2 - 4.0**2)
    assert sys.assembly["iterations"] > len(sys.blocks)
    assert sys.assembly["closure"] <= 1e-11
    na = sys.n_angles
    assert abs(sys.q0[na + 1] - k) < 1e-13 and abs(sys.q0[na + 2] - k) < 1e-13
