"""The compiled mechanism: LoopSystem (immutable) and the numerics every algorithm shares.

A LoopSystem holds the vector terms z = (r + s_i)·e^{j(φ_a + δ)} of the paper's graph (see
:mod:`vloop.method.graph`), the loop equations Σ_k C[l, k]·z_k = 0, the unknowns (rotating links' angles
and slider displacements less the driven ones), the block-triangular structure of the equations
(:mod:`vloop.method.structure`) and the assembled configuration at t = 0 (:mod:`vloop.method.assembly`).
It is built by :func:`vloop.compiler.compile_system`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property
from typing import TYPE_CHECKING

import numpy as np

from ..model import Mechanism
from .graph import ORIGIN, Loop, networkx_graph

if TYPE_CHECKING:
    import networkx as nx

__all__ = [
    "ORIGIN",
    "Block",
    "Loop",
    "LoopGroup",
    "LoopSystem",
    "TermIndex",
    "loop_jacobian",
    "loop_polygon",
    "loop_residual",
    "term_values",
]


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
    graph_parts: tuple = field(repr=False)  # the graph's nodes and edges (u, v, data): see the ``graph`` property
    assembly: dict = field(default_factory=dict)
    method: str = "auto"
    cache: dict = field(default_factory=dict, repr=False, compare=False)  # solver plans
    chords: tuple = ()  # (term, ((part, coefficient), ...)): a body's vectors a loop crosses, summed (graph.crossings)

    @cached_property
    def graph(self) -> nx.Graph:
        """The paper's graph (:mod:`vloop.method.graph`) as a networkx graph, built on first use."""
        return networkx_graph(*self.graph_parts)

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


def term_values(sys: LoopSystem, q: np.ndarray, terms: np.ndarray | None = None) -> np.ndarray:
    """Complex term vectors z for variables ``q`` (shape (..., n_vars)); only ``terms`` if given."""
    q = np.asarray(q, float)
    na = sys.n_angles
    phi = np.concatenate([q[..., :na], np.zeros((*q.shape[:-1], 1))], axis=-1)
    s = np.concatenate([q[..., na:], np.zeros((*q.shape[:-1], 1))], axis=-1)
    k = slice(None) if terms is None else terms
    return (sys.t_r[k] + s[..., sys.t_sl[k]]) * np.exp(1j * (phi[..., sys.t_ang[k]] + sys.t_delta[k]))


def loop_terms(sys: LoopSystem, loops: list[int]) -> np.ndarray:
    """The terms ``loops`` use (a loop's equations involve only these)."""
    return np.nonzero(np.any(sys.C[loops] != 0, axis=0))[0]


class TermIndex:
    """Term vectors at one configuration, for the terms ``k`` (all by default), the index data gathered once:
    :func:`term_values`' arithmetic, bit for bit (the variables extended by a zero stand for "none")."""

    def __init__(self, sys: LoopSystem, k: np.ndarray | None = None) -> None:
        k = np.arange(len(sys.t_r)) if k is None else k
        n, na = sys.n_vars, sys.n_angles
        self.r, self.delta = sys.t_r[k], sys.t_delta[k]
        ang, sl = sys.t_ang[k], sys.t_sl[k]
        self.ang_list, self.sl_list = ang.tolist(), sl.tolist()
        self.at_ang = np.where(ang < 0, n, ang)
        self.at_sl = np.where(sl < 0, n, na + sl)

    def at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The term vectors z and their directions e = e^{j(φ + δ)} at ``q`` (one configuration)."""
        qx = np.concatenate((q, _ZERO))
        e = np.exp(1j * (qx[self.at_ang] + self.delta))
        return (self.r + qx[self.at_sl]) * e, e


_ZERO = np.zeros(1)


class LoopGroup(TermIndex):
    """The equations of ``loops`` in the variables ``cols``, index data gathered once for repeated evaluation
    (Newton at t = 0): the same arithmetic as :func:`loop_residual` and :func:`loop_jacobian`, bit for bit. Its
    term vectors are those of the terms ``k`` the loops use (:meth:`at`, or the whole system's at ``k``)."""

    def __init__(self, sys: LoopSystem, loops: list[int], cols: list[int]) -> None:
        self.k = loop_terms(sys, loops)
        super().__init__(sys, self.k)
        self.Cg = sys.C[np.ix_(loops, self.k)]
        na, ang, sl = sys.n_angles, self.ang_list, self.sl_list
        shape = (len(ang), len(cols))  # d z_t / d col: j·z_t where col turns t, e_t where col is t's slider
        self.on_angle = np.array([[a == c for c in cols] for a in ang], complex).reshape(shape)
        self.on_slider = np.array([[c >= na and i == c - na for c in cols] for i in sl], complex).reshape(shape)

    def residual(self, zk: np.ndarray) -> np.ndarray:
        """The group's loops' closure at its term vectors ``zk``."""
        return zk @ self.Cg.T

    def jacobian(self, zk: np.ndarray, ek: np.ndarray) -> np.ndarray:
        """[Re; Im] of the loops' Jacobian in ``cols`` at its term vectors and directions."""
        J = self.Cg @ ((1j * zk)[:, None] * self.on_angle + ek[:, None] * self.on_slider)
        return np.concatenate((J.real, J.imag))


def loop_jacobian(sys: LoopSystem, q: np.ndarray, loops: list[int], cols: list[int]) -> np.ndarray:
    """Real Jacobian of [Re; Im] of ``loops`` w.r.t. variables ``cols`` at one configuration ``q``.

    d/dθ_a of r·e^{j(θ_a + δ)} is j·z; d/ds of (r + s)·e^{jφ} is e^{jφ}. Only the loops' own terms are
    evaluated, so a small group of a large mechanism costs little.
    """
    k = loop_terms(sys, loops)
    z = term_values(sys, q, k)
    na = sys.n_angles
    phi = np.append(q[:na], 0.0)
    ang, sl = sys.t_ang[k], sys.t_sl[k]
    e = np.exp(1j * (phi[ang] + sys.t_delta[k]))
    cols_a = np.asarray(cols, int)
    D = (1j * z)[:, None] * (ang[:, None] == cols_a[None, :]) + e[:, None] * (
        (sl[:, None] == cols_a[None, :] - na) & (cols_a[None, :] >= na)
    )
    J = sys.C[np.ix_(loops, k)] @ D
    return np.vstack([J.real, J.imag])


def loop_residual(sys: LoopSystem, q: np.ndarray, loops: list[int] | None = None) -> np.ndarray:
    """Complex closure residual of each loop (or of ``loops``) at ``q``."""
    if loops is None:
        return term_values(sys, q) @ sys.C.T
    k = loop_terms(sys, loops)
    return term_values(sys, q, k) @ sys.C[np.ix_(loops, k)].T


def loop_polygon(sys: LoopSystem, q: np.ndarray, loop: Loop) -> list[complex]:
    """The distinct joints at a loop's corners at configuration ``q`` (the world origin where the loop uses it)."""
    z = term_values(sys, q)
    tol = 1e-12 * sys.mechanism.scale
    pts: list[complex] = []
    for _, joint in loop.corners:
        p = 0j if joint == ORIGIN else complex(z @ sys.path[:, sys.point_names.index(joint)])
        if not pts or abs(p - pts[-1]) > tol:
            pts.append(p)
    if len(pts) > 1 and abs(pts[0] - pts[-1]) <= tol:
        pts.pop()
    return pts
