"""The loop equations written the way the paper writes them.

    loop 1 (O2–A–B):  a·e^{jθ_l2} + b·e^{jθ_l3} + c·e^{jπ} = 0

Every vector gets a letter (a, b, c, … in order of first appearance; e, i, j, l
and o are skipped), a legend says what it is, and each loop lists its unknowns, the inputs
it takes from the drivers and what earlier loops supply. Signs are folded into
the angles (−v = v·e^{jπ}) so every loop is a plain sum, as in the paper.
"""

from __future__ import annotations

import math
import string
from dataclasses import dataclass
from typing import Any

import numpy as np

from .loops import LoopSystem

_LETTERS = [c for c in string.ascii_lowercase if c not in "eijlo"]  # no e, j (e^{jθ}) nor look-alikes
_KIND = {
    "RRR": "closed form, two angles (law of cosines)",
    "RRP": "closed form, an angle and a slider",
    "RPR": "closed form, a slider and its guide's angle",
    "PP": "closed form, two sliders (linear)",
    "newton": "Newton–Raphson",
}


def _letter(i: int) -> str:
    n = len(_LETTERS)
    return _LETTERS[i] if i < n else _LETTERS[i % n] + str(i // n)


def fmt_angle(x: float, latex: bool = False, exact: bool = False) -> str:
    """A constant angle in [0, 2π) as 0, π/2, π, 3π/2 when it is one (within 1e-9 rad, ``exact``: 1e-12), else in
    radians to 4 decimals (``exact``: the shortest text that reads back to the same double)."""
    x = x % (2 * math.pi)
    pi = r"\pi" if latex else "π"
    tol = 1e-12 if exact else 1e-9
    for k, s in ((0, "0"), (1, f"{pi}/2"), (2, pi), (3, f"3{pi}/2"), (4, "0")):
        if abs(x - k * math.pi / 2) < tol:
            return s
    return repr(x) if exact else f"{x:.4f}"


def _num(x: float, exact: bool = False) -> str:
    return repr(float(x)) if exact else f"{x:.6g}"


@dataclass(frozen=True)
class Vector:
    """One vector of a loop equation, (r + s)·e^{j(θ_link + δ)}, the loop's sign folded into δ (−v = v·e^{jπ}).

    ``letter``: its magnitude's symbol; ``link``: the link whose θ turns it (None: fixed to the ground);
    ``slider``: the slider whose s is its magnitude (None: a rigid vector of length ``r``); ``delta`` in [0, 2π)."""

    term: int
    letter: str
    link: str | None
    slider: str | None
    r: float
    delta: float


@dataclass(frozen=True)
class LoopEquation:
    """One loop equation Σ vectors = 0 and how it is solved: its unknowns, the inputs it takes from the drivers,
    what earlier loops supply (``earlier``: their numbers and the symbols) and the block's method."""

    number: int
    label: str
    vectors: tuple[Vector, ...]
    unknown: tuple[str, ...] = ()
    inputs: tuple[str, ...] = ()
    earlier: tuple[tuple[int, ...], tuple[str, ...]] = ((), ())
    kind: str = ""


@dataclass(frozen=True)
class Legend:
    """What a letter stands for: a slider's displacement (``slider``) or the length ``r`` of the vector ``what``."""

    letter: str
    what: str
    r: float = 0.0
    slider: str | None = None


def vector_loops(system: LoopSystem) -> tuple[list[LoopEquation], list[Legend]]:
    """The loop equations as one structure that both the text and the LaTeX are written from (in solving order;
    vectors of zero length left out), and the legend of their letters (in order of first appearance)."""
    letters: dict[object, str] = {}
    legend: list[Legend] = []
    scale = system.mechanism.scale

    def vector(t: int, sign: float) -> Vector | None:
        ang, sl, r = int(system.t_ang[t]), int(system.t_sl[t]), float(system.t_r[t])
        if sl < 0 and r <= 1e-14 * scale:  # a chord whose parts cancel (the Whitworth's second ground vector)
            return None
        key = ("s", sl) if sl >= 0 else ("r", round(r, 12), system.t_label[t])
        if key not in letters:
            letters[key] = _letter(len(letters))
            name = system.slider_names[sl] if sl >= 0 else None
            legend.append(Legend(letters[key], f"slider {name}" if name else system.t_label[t], r, name))
        delta = (float(system.t_delta[t]) + (math.pi if sign < 0 else 0.0)) % (2 * math.pi)
        link = system.angle_links[ang] if ang >= 0 else None
        return Vector(t, letters[key], link, system.slider_names[sl] if sl >= 0 else None, r, delta)

    def equation(li: int, block: Any = None) -> LoopEquation:
        loop = system.loops[li]
        vectors = tuple(v for t, sg in zip(loop.terms, loop.signs, strict=True) if (v := vector(t, sg)) is not None)
        if block is None:
            return LoopEquation(li + 1, loop.label, vectors)
        sym = {v: _symbol(system, v, letters) for v in loop.variables}
        earlier = [v for v in loop.variables if v not in block.unknowns and v not in system.drivers]
        sources = tuple(sorted({solved_in[v] + 1 for v in earlier if v in solved_in}))
        return LoopEquation(
            li + 1, loop.label, vectors,
            tuple(sym[v] for v in loop.variables if v in block.unknowns),
            tuple(sym[v] for v in loop.variables if v in system.drivers),
            (sources, tuple(sym[v] for v in earlier)), block.kind,
        )  # fmt: skip

    solved_in = {v: b.loops[0] for b in system.blocks for v in b.unknowns}
    if system.blocks:
        loops = [equation(li, b) for b in system.blocks for li in b.loops]
    else:
        loops = [equation(loop.index) for loop in system.loops]
    return loops, legend


def _symbol(system: LoopSystem, v: int, letters: dict) -> str:
    """A variable's symbol: θ_NAME for an angle, a slider's letter (s_NAME before it has one)."""
    n_angles = system.n_angles
    if v < n_angles:
        return f"θ_{system.angle_links[v]}"
    return letters.get(("s", v - n_angles), f"s_{system.slider_names[v - n_angles]}")


def _theta(name: str, latex: bool) -> str:
    return rf"\theta_{{\mathrm{{{name.replace('_', chr(92) + '_')}}}}}" if latex else f"θ_{name}"


def exponent(v: Vector, latex: bool = False, exact: bool = False) -> str:
    """The exponent of a vector's e^{…}: jθ, j(θ + δ) or jδ — one expression, written as text or LaTeX."""
    off = fmt_angle(v.delta, latex, exact)
    j = "j " if latex else "j"
    if v.link is None:
        return f"{j}{off}"
    th = _theta(v.link, latex)
    return f"{j}{th}" if off == "0" else f"{j}({th} + {off})"


def vector_text(v: Vector, latex: bool = False, exact: bool = False) -> str:
    """``a·e^{jθ_l2}`` (text) or ``a\\,e^{j\\theta_{\\mathrm{l2}}}`` (LaTeX)."""
    return f"{v.letter}{chr(92) + ',' if latex else '·'}e^{{{exponent(v, latex, exact)}}}"


def equation_text(eq: LoopEquation, latex: bool = False, exact: bool = False) -> str:
    """The left side of a loop equation, Σ vectors (= 0)."""
    return " + ".join(vector_text(v, latex, exact) for v in eq.vectors)


def legend_text(item: Legend, exact: bool = False) -> str:
    if item.slider is not None:
        return f"{item.letter} = s_{item.slider} (slider {item.slider})"
    return f"{item.letter} = |{item.what}| = {_num(item.r, exact)}"


def describe(system: LoopSystem, latex: bool = False, exact: bool = False) -> str:
    """Loop equations, legend and solving order as text (or a LaTeX ``align*`` block), both written from
    :func:`vector_loops`. ``exact``: every number to full precision (the shortest text that reads back to the same
    double), angles that are multiples of π/2 within 1e-12 rad as such."""
    mech = system.mechanism
    loops, legend = vector_loops(system)
    L, J, M = mech.gruebler()
    head = (
        f"{mech.name}: {len(system.loops)} vector loop{'s' if len(system.loops) != 1 else ''} "
        f"(J − L + 1 = {J} − {L} + 1), mobility M = {M}, {len(system.unknowns)} unknowns"
    )
    notes = [legend_text(x, exact) for x in legend]
    if latex:
        eqs = [f"{equation_text(eq, True, exact)} &= 0 && \\text{{loop {eq.number} ({eq.label})}}" for eq in loops]
        return "\n".join(
            ["% " + head, r"\begin{align*}", " \\\\\n".join(eqs), r"\end{align*}", "% " + "; ".join(notes)]
        )
    lines: list[str] = []
    for eq in loops:
        lines.append(f"loop {eq.number} ({eq.label}):  {equation_text(eq, False, exact)} = 0")
        if eq.kind:
            detail = [f"unknown: {', '.join(eq.unknown)}"]
            if eq.inputs:
                detail.append(f"input: {', '.join(eq.inputs)}")
            if eq.earlier[1]:
                detail.append(f"from loop {', '.join(map(str, eq.earlier[0]))}: {', '.join(eq.earlier[1])}")
            detail.append(_KIND[eq.kind])
            lines.append("    " + "; ".join(detail))
    return "\n".join([head, "", *lines, "", "where", *(f"  {x}" for x in notes)])


GRASHOF_CLASSES = ("Grashof double-crank", "Grashof crank-rocker", "Grashof double-rocker", "Grashof rocker-crank")
SPECIAL_GRASHOF = "special Grashof (change point)"
NON_GRASHOF = "non-Grashof triple-rocker"


def grashof_class(lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grashof class of four-bars from their lengths ``(..., 4)``: ground, input side, coupler, output side.

    s + l < p + q: Grashof, named by its shortest link (ground: double-crank, input: crank-rocker, coupler:
    double-rocker, output: rocker-crank); s + l = p + q within 1e-9·l: special Grashof (its change points);
    otherwise a non-Grashof triple-rocker. Returns the class names (object array) and whether s + l ≤ p + q.
    """
    lengths = np.asarray(lengths, float)
    srt = np.sort(lengths, axis=-1)
    s, l_ = srt[..., 0], srt[..., -1]
    pq = srt[..., 1] + srt[..., 2]
    special = np.abs(s + l_ - pq) <= 1e-9 * l_
    is_grashof = (s + l_ < pq) | special
    names = np.array(GRASHOF_CLASSES, object)[np.argmin(lengths, axis=-1)]
    cls = np.where(special, SPECIAL_GRASHOF, np.where(is_grashof, names, NON_GRASHOF))
    return np.asarray(cls, object).reshape(np.shape(s)), is_grashof


def grashof(system: LoopSystem) -> list[tuple[int, str, tuple[float, float, float, float]]]:
    """Grashof class of every four-bar loop (ground + three pinned links, no slider).

    Returns (loop index, class, (ground, input side, coupler, output side) lengths).
    """
    from .loops import term_values

    z = term_values(system, system.q0)
    out = []
    for loop in system.loops:
        if any(system.t_sl[t] >= 0 for t in loop.terms):
            continue
        order: list[int] = []  # angle owners in traversal order, -1 for the ground
        vec: dict[int, complex] = {}
        for t, s in zip(loop.terms, loop.signs, strict=True):
            a = int(system.t_ang[t])
            if a not in vec:
                order.append(a)
                vec[a] = 0j
            vec[a] += s * z[t]
        if len(order) != 4 or -1 not in order:
            continue
        k = order.index(-1)
        order = order[k:] + order[:k]
        g, p1, c, p2 = (abs(vec[a]) for a in order)
        cls = str(grashof_class(np.array([g, p1, c, p2]))[0])
        out.append((loop.index, cls, (g, p1, c, p2)))
    return out
