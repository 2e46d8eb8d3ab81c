"""The compiled mechanism: LoopSystem (immutable) and the numerics every algorithm shares.

A LoopSystem holds the vector terms z = (r + s_i)·e^{j(φ_a + δ)} of the paper's graph (see
:mod:`vloop.method.graph`), the loop equations Σ_k C[l, k]·z_k = 0, the unknowns (rotating links' angles
and slider displacements less the driven ones), the block-triangular structure of the equations
(:mod:`vloop.method.structure`) and the assembled configuration at t = 0 (:mod:`vloop.method.assembly`).
It is built by :func:`vloop.compiler.compile_system`.

This module owns the loop terms: every evaluation of term vectors, loop closures and their Jacobians is here
(:func:`term_values`, :func:`loop_residual`, :func:`loop_jacobian`; index data gathered once for repeated
evaluation: :class:`TermIndex`, :class:`LoopGroup` (one configuration or many rows at once), :class:`DyadTerms`
(one loop in two unknowns, in Python numbers); :func:`turning_with`, a loop's vectors that turn with one angle).
The compile steps (:mod:`~vloop.method.assembly`, :mod:`~vloop.method.structure`,
:mod:`~vloop.method.branches`) consume them.
"""

from __future__ import annotations

import math
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
    "DyadTerms",
    "Loop",
    "LoopGroup",
    "LoopSystem",
    "TermIndex",
    "loop_jacobian",
    "loop_residual",
    "term_values",
    "turning_with",
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
    """The compiled mechanism (immutable). Variables: angles 0..n_angles-1, then sliders n_angles..n_angles+ns-1."""

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
        n_angles = self.n_angles
        return f"θ_{self.angle_links[v]}" if v < n_angles else f"s_{self.slider_names[v - n_angles]}"

    def loops_of(self, block: Block) -> list[Loop]:
        return [self.loops[i] for i in block.loops]


# ------------------------------------------------------------------ numerics shared with the solver


def term_values(system: LoopSystem, q: np.ndarray, terms: np.ndarray | None = None) -> np.ndarray:
    """Complex term vectors z for variables ``q`` (shape (..., n_vars)); only ``terms`` if given."""
    q = np.asarray(q, float)
    n_angles = system.n_angles
    phi = np.concatenate([q[..., :n_angles], np.zeros((*q.shape[:-1], 1))], axis=-1)
    s = np.concatenate([q[..., n_angles:], np.zeros((*q.shape[:-1], 1))], axis=-1)
    k = slice(None) if terms is None else terms
    return (system.t_r[k] + s[..., system.t_sl[k]]) * np.exp(1j * (phi[..., system.t_ang[k]] + system.t_delta[k]))


def loop_terms(system: LoopSystem, loops: list[int]) -> np.ndarray:
    """The terms ``loops`` use (a loop's equations involve only these)."""
    return np.nonzero(np.any(system.C[loops] != 0, axis=0))[0]


class TermIndex:
    """Term vectors at one configuration, for the terms ``k`` (all by default), the index data gathered once:
    :func:`term_values`' arithmetic, bit for bit (the variables extended by a zero stand for "none")."""

    def __init__(self, system: LoopSystem, k: np.ndarray | None = None) -> None:
        k = np.arange(len(system.t_r)) if k is None else k
        n, n_angles = system.n_vars, system.n_angles
        self.r, self.delta = system.t_r[k], system.t_delta[k]
        ang, sl = system.t_ang[k], system.t_sl[k]
        self.term_angle, self.term_slider = ang.tolist(), sl.tolist()
        self.angle_column = np.where(ang < 0, n, ang)
        self.slide_column = np.where(sl < 0, n, n_angles + sl)

    def at(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The term vectors z and their directions e = e^{j(φ + δ)} at ``q`` (one configuration)."""
        qx = np.concatenate((q, _ZERO))
        e = np.exp(1j * (qx[self.angle_column] + self.delta))
        return (self.r + qx[self.slide_column]) * e, e


_ZERO = np.zeros(1)


class LoopGroup(TermIndex):
    """The equations of ``loops`` in the variables ``cols``, index data gathered once for repeated evaluation
    (Newton at t = 0): the same arithmetic as :func:`loop_residual` and :func:`loop_jacobian`, bit for bit. Its
    term vectors are those of the terms ``k`` the loops use (:meth:`at`, or the whole system's at ``k``)."""

    def __init__(self, system: LoopSystem, loops: list[int], cols: list[int]) -> None:
        self.k = loop_terms(system, loops)
        super().__init__(system, self.k)
        self.coefficients = system.C[np.ix_(loops, self.k)]
        n_angles, ang, sl = system.n_angles, self.term_angle, self.term_slider
        shape = (len(ang), len(cols))  # d z_t / d col: j·z_t where col turns t, e_t where col is t's slider
        self.on_angle = np.array([[a == c for c in cols] for a in ang], complex).reshape(shape)
        on_slider = [[c >= n_angles and i == c - n_angles for c in cols] for i in sl]
        self.on_slider = np.array(on_slider, complex).reshape(shape)

    def residual(self, zk: np.ndarray) -> np.ndarray:
        """The group's loops' closure at its term vectors ``zk``."""
        return zk @ self.coefficients.T

    def jacobian(self, zk: np.ndarray, ek: np.ndarray) -> np.ndarray:
        """[Re; Im] of the loops' Jacobian in ``cols`` at its term vectors and directions."""
        J = self.coefficients @ ((1j * zk)[:, None] * self.on_angle + ek[:, None] * self.on_slider)
        return np.concatenate((J.real, J.imag))

    def many(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The loops' closure (rows × loops, complex) and [Re; Im] Jacobian (rows × 2·loops × cols) at every row of
        ``q`` (rows × variables) at once."""
        qx = np.concatenate((q, np.zeros((len(q), 1))), axis=1)
        e = np.exp(1j * (qx[:, self.angle_column] + self.delta))
        z = (self.r + qx[:, self.slide_column]) * e
        J = np.einsum(
            "lt,ntc->nlc", self.coefficients, (1j * z)[:, :, None] * self.on_angle + e[:, :, None] * self.on_slider
        )
        return z @ self.coefficients.T, np.concatenate((J.real, J.imag), axis=1)


def turning_with(system: LoopSystem, loop: Loop, z: np.ndarray | list[complex], angle: int) -> complex:
    """Σ of the loop's signed vectors that turn with the angle variable ``angle`` (``z``: every term's vector)."""
    return complex(sum(sg * z[t] for t, sg in zip(loop.terms, loop.signs, strict=True) if system.t_ang[t] == angle))


class DyadTerms:
    """One loop in two unknowns, in Python numbers (numpy's calls cost more than the arithmetic of a few terms): its
    term vectors z = (r + s)·e^{j(φ + δ)} and their derivatives j·z (an angle) and e^{j(φ + δ)} (a slider), as
    :class:`LoopGroup`'s arithmetic; ``k`` and :meth:`jacobian` as LoopGroup's. ``terms``: (sign, angle or −1,
    slider variable or −1, r, δ, the unknown turning it, sliding it or −1) per term of the loop."""

    def __init__(self, system: LoopSystem, loop: int, unknowns: list[int]) -> None:
        n_angles = system.n_angles
        row = system.C[loop]
        self.unknowns = unknowns
        self.k = np.flatnonzero(row)
        k = self.k
        self.terms = []  # (sign, angle or -1, slider variable or -1, r, δ, the unknown turning it, sliding it or -1)
        columns = (x.tolist() for x in (row[k], system.t_ang[k], system.t_sl[k], system.t_r[k], system.t_delta[k]))
        for c, a, i, r, d in zip(*columns, strict=True):
            v = n_angles + i if i >= 0 else -1
            turn, slide = (unknowns.index(x) if x in unknowns else -1 for x in (a, v))
            self.terms.append((float(c), a, v, r, d, turn, slide))

    def at(self, q: list[float]) -> tuple[list[complex], list[complex]]:
        """The loop's term vectors z and directions e at the variables q."""
        z, e = [], []
        for _, a, i, r, d, _, _ in self.terms:
            phi = (q[a] if a >= 0 else 0.0) + d
            e.append(complex(math.cos(phi), math.sin(phi)))
            z.append((r + (q[i] if i >= 0 else 0.0)) * e[-1])
        return z, e

    def columns(self, z: list[complex], e: list[complex]) -> list[complex]:
        """The loop's two complex Jacobian columns at its term vectors and directions."""
        J = [0j, 0j]
        for (c, _, _, _, _, ua, ui), zt, et in zip(self.terms, z, e, strict=True):
            if ua >= 0:
                J[ua] += c * 1j * zt
            if ui >= 0:
                J[ui] += c * et
        return J

    def jacobian(self, zk: np.ndarray, ek: np.ndarray) -> np.ndarray:
        """[Re; Im] of the Jacobian (2×2) at its term vectors and directions, as LoopGroup.jacobian."""
        j0, j1 = self.columns(zk.tolist(), ek.tolist())
        return np.array([[j0.real, j1.real], [j0.imag, j1.imag]])


def loop_jacobian(system: LoopSystem, q: np.ndarray, loops: list[int], cols: list[int]) -> np.ndarray:
    """Real Jacobian of [Re; Im] of ``loops`` w.r.t. variables ``cols`` at one configuration ``q``.

    d/dθ_a of r·e^{j(θ_a + δ)} is j·z; d/ds of (r + s)·e^{jφ} is e^{jφ}. Only the loops' own terms are
    evaluated, so a small group of a large mechanism costs little.
    """
    k = loop_terms(system, loops)
    z = term_values(system, q, k)
    n_angles = system.n_angles
    phi = np.append(q[:n_angles], 0.0)
    ang, sl = system.t_ang[k], system.t_sl[k]
    e = np.exp(1j * (phi[ang] + system.t_delta[k]))
    cols_a = np.asarray(cols, int)
    D = (1j * z)[:, None] * (ang[:, None] == cols_a[None, :]) + e[:, None] * (
        (sl[:, None] == cols_a[None, :] - n_angles) & (cols_a[None, :] >= n_angles)
    )
    J = system.C[np.ix_(loops, k)] @ D
    return np.vstack([J.real, J.imag])


def loop_residual(system: LoopSystem, q: np.ndarray, loops: list[int] | None = None) -> np.ndarray:
    """Complex closure residual of each loop (or of ``loops``) at ``q``."""
    if loops is None:
        return term_values(system, q) @ system.C.T
    k = loop_terms(system, loops)
    return term_values(system, q, k) @ system.C[np.ix_(loops, k)].T
