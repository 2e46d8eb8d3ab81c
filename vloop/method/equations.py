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


def fmt_angle(x: float, latex: bool = False) -> str:
    """A constant angle as 0, π/2, π, 3π/2 when it is one, else in radians to 4 decimals."""
    x = x % (2 * math.pi)
    pi = r"\pi" if latex else "π"
    for k, s in ((0, "0"), (1, f"{pi}/2"), (2, pi), (3, f"3{pi}/2"), (4, "0")):
        if abs(x - k * math.pi / 2) < 1e-9:
            return s
    return f"{x:.4f}"


def _num(x: float) -> str:
    return f"{x:.6g}"


def describe(sys: LoopSystem, latex: bool = False) -> str:
    """Loop equations, legend and solving order as text (or a LaTeX ``align*`` block)."""
    mech = sys.mechanism
    na = sys.n_angles
    letters: dict[object, str] = {}
    legend: list[str] = []
    slider_letter: dict[int, str] = {}

    def theta(a: int) -> str:
        name = sys.angle_links[a]
        return rf"\theta_{{\mathrm{{{name}}}}}" if latex else f"θ_{name}"

    def var_sym(v: int) -> str:
        if v < na:
            return theta(v)
        return slider_letter.get(v - na, f"s_{sys.slider_names[v - na]}")

    def term_text(t: int, sign: float) -> str:
        ang, sl, r = int(sys.t_ang[t]), int(sys.t_sl[t]), float(sys.t_r[t])
        delta = float(sys.t_delta[t]) + (math.pi if sign < 0 else 0.0)
        key = ("s", sl) if sl >= 0 else ("r", round(r, 12), sys.t_label[t])
        if key not in letters:
            letters[key] = _letter(len(letters))
            sym = letters[key]
            if sl >= 0:
                slider_letter[sl] = sym
                legend.append(f"{sym} = s_{sys.slider_names[sl]} (slider {sys.slider_names[sl]})")
            else:
                legend.append(f"{sym} = |{sys.t_label[t]}| = {_num(r)}")
        sym = letters[key]
        if ang < 0:
            arg = fmt_angle(delta, latex)
        else:
            off = fmt_angle(delta, latex)
            arg = theta(ang) if off == "0" else f"{theta(ang)} + {off}"
            if off != "0":
                arg = f"({arg})" if not latex else arg
        if latex:
            return f"{sym}\\,e^{{j {arg}}}"
        return f"{sym}·e^{{j{arg}}}"

    solved_in: dict[int, int] = {}
    for b in sys.blocks:
        for v in b.unknowns:
            solved_in[v] = b.loops[0]
    lines: list[str] = []
    eqs: list[str] = []
    for b in sys.blocks or ():
        for li in b.loops:
            lp = sys.loops[li]
            body = " + ".join(term_text(t, s) for t, s in zip(lp.terms, lp.signs, strict=True))
            unknown = [var_sym(v) for v in lp.variables if v in b.unknowns]
            inputs = [var_sym(v) for v in lp.variables if v in sys.drivers]
            earlier = [var_sym(v) for v in lp.variables if v not in b.unknowns and v not in sys.drivers]
            if latex:
                eqs.append(f"{body} &= 0 && \\text{{loop {li + 1} ({lp.label})}}")
            else:
                lines.append(f"loop {li + 1} ({lp.label}):  {body} = 0")
                detail = [f"unknown: {', '.join(unknown)}"]
                if inputs:
                    detail.append(f"input: {', '.join(inputs)}")
                if earlier:
                    src = sorted({solved_in[v] + 1 for v in lp.variables if v in solved_in and v not in b.unknowns})
                    detail.append(f"from loop {', '.join(map(str, src))}: {', '.join(earlier)}")
                detail.append(_KIND[b.kind])
                lines.append("    " + "; ".join(detail))
    if not sys.blocks:
        for lp in sys.loops:
            body = " + ".join(term_text(t, s) for t, s in zip(lp.terms, lp.signs, strict=True))
            lines.append(f"loop {lp.index + 1} ({lp.label}):  {body} = 0")
    L, J, M = mech.gruebler()
    head = (
        f"{mech.name}: {len(sys.loops)} vector loop{'s' if len(sys.loops) != 1 else ''} "
        f"(J − L + 1 = {J} − {L} + 1), mobility M = {M}, {len(sys.unknowns)} unknowns"
    )
    if latex:
        out = ["% " + head, r"\begin{align*}"]
        out.append(" \\\\\n".join(eqs))
        out.append(r"\end{align*}")
        out.append("% " + "; ".join(legend))
        return "\n".join(out)
    return "\n".join([head, "", *lines, "", "where", *(f"  {x}" for x in legend)])


def grashof(sys: LoopSystem) -> list[tuple[int, str, tuple[float, float, float, float]]]:
    """Grashof class of every four-bar loop (ground + three pinned links, no slider).

    Returns (loop index, class, (ground, input side, coupler, output side) lengths).
    """
    from .loops import term_values

    z = term_values(sys, sys.q0)
    out = []
    for lp in sys.loops:
        if any(sys.t_sl[t] >= 0 for t in lp.terms):
            continue
        order: list[int] = []  # angle owners in traversal order, -1 for the ground
        vec: dict[int, complex] = {}
        for t, s in zip(lp.terms, lp.signs, strict=True):
            a = int(sys.t_ang[t])
            if a not in vec:
                order.append(a)
                vec[a] = 0j
            vec[a] += s * z[t]
        if len(order) != 4 or -1 not in order:
            continue
        k = order.index(-1)
        order = order[k:] + order[:k]
        g, p1, c, p2 = (abs(vec[a]) for a in order)
        lengths = sorted([g, p1, c, p2])
        s_, l_ = lengths[0], lengths[-1]
        pq = sum(lengths) - s_ - l_
        if abs(s_ + l_ - pq) <= 1e-9 * l_:
            cls = "special Grashof (change point)"
        elif s_ + l_ < pq:
            shortest = int(np.argmin([g, p1, c, p2]))
            cls = {
                0: "Grashof double-crank",
                1: "Grashof crank-rocker",
                2: "Grashof double-rocker",
                3: "Grashof rocker-crank",
            }[shortest]
        else:
            cls = "non-Grashof triple-rocker"
        out.append((lp.index, cls, (g, p1, c, p2)))
    return out
