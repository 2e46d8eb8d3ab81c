"""Pictures of a synthesis: the structural error of a function generator, the path through its targets, the
poses a motion generator meets (the linkage drawn at each)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .candidates import Candidate, Candidates

# each candidate's path and linkage in its own colour (Okabe–Ito, as the viewer); the targets in black
CANDIDATE_COLOURS = ("#0072B2", "#D55E00", "#009E73", "#CC79A7", "#E69F00", "#56B4E9")


def plot_result(result: Candidates, chosen: list[Candidate], folder: Path) -> list[Path]:
    """The method's picture for the chosen candidates (or the best few when none is a solution)."""
    shown = chosen or result.items[:3]
    if not shown:
        return []
    if result.task.method == "function":
        return [_structural(shown, folder / "structural_error.png")]
    if result.task.method == "path":
        return [_path(result, shown, folder / "path.png")]
    return [_poses(result, shown[0], folder / "poses.png")]


def _figure(title: str):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5.5))
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    return plt, fig, ax


def _save(plt, fig, path: Path) -> Path:
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def _structural(shown: list[Candidate], path: Path) -> Path:
    plt, fig, ax = _figure("Structural error y(x) − f(x) of the function generator")
    for c in shown:
        s = c.extra.get("structural")
        if s is None:
            continue
        ax.plot(s["x"], s["error"], label=f"{c.name} (max {c.structural_error:.3g} of the y range)")
    ax.axhline(0.0, color="k", lw=0.8)
    ax.set_xlabel("x")
    ax.set_ylabel("error in y")
    if ax.get_legend_handles_labels()[1]:
        ax.legend(loc="best", fontsize=8)
    else:  # precision pairs without f: no structural error to draw
        ax.text(0.5, 0.5, "no function given (precision pairs): no structural error", ha="center",
                transform=ax.transAxes)  # fmt: skip
    return _save(plt, fig, path)


def _path(result: Candidates, shown: list[Candidate], path: Path) -> Path:
    from .. import solve

    plt, fig, ax = _figure("Tracer paths through the target points")
    for k, c in enumerate(shown):
        colour = CANDIDATE_COLOURS[k % len(CANDIDATE_COLOURS)]
        turn = 2 * math.pi / abs(c.mechanism.drivers[0].v0)
        res = solve(c.mechanism, np.linspace(0.0, turn, 361))
        label = f"{c.name}: error {c.error:.2g} of {result.task.scale}" if math.isfinite(c.error) else c.name
        ax.plot(res[f"{c.tracer}.x"], res[f"{c.tracer}.y"], lw=1.6, color=colour, label=label)
        _draw(ax, c, res, 0, alpha=0.6, colour=colour)
    _targets(ax, result.task.points)
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    ax.set_xlabel(f"x [{drawable(result.task.units)}]")
    ax.set_ylabel(f"y [{drawable(result.task.units)}]")
    return _save(plt, fig, path)


def _poses(result: Candidates, c: Candidate, path: Path) -> Path:
    from .. import solve

    plt, fig, ax = _figure(f"{c.name} at each pose")
    res = solve(c.mechanism, np.asarray(c.times))
    for k in range(len(res.t)):
        _draw(ax, c, res, k, alpha=0.35 + 0.65 * k / max(len(res.t) - 1, 1))
    for key, style in (("centre", "C0"), ("circle", "C2")):
        z = result.curves.get(key)
        if z is not None and len(z):
            ax.plot(z.real, z.imag, ".", ms=1.5, color=style, label=f"{key}-point curve (poses 1–4)")
    pts, ang = result.task.points, result.task.angles
    r = 0.15 * result.task.size
    for z, a in zip(pts, ang, strict=True):
        ax.annotate("", xy=(z.real + r * math.cos(a), z.imag + r * math.sin(a)), xytext=(z.real, z.imag),
                    arrowprops={"arrowstyle": "->", "color": "C3"})  # fmt: skip
    _targets(ax, pts)
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(loc="best", fontsize=8)
    ax.set_xlabel(f"x [{drawable(result.task.units)}]")
    ax.set_ylabel(f"y [{drawable(result.task.units)}]")
    return _save(plt, fig, path)


def drawable(text: str) -> str:
    """Text as written (never math: "$" escaped), each character the font lacks shown as "?" (no missing-glyph
    warning)."""
    from matplotlib import font_manager, ft2font

    font = ft2font.FT2Font(font_manager.findfont(font_manager.FontProperties()))
    out = "".join(ch if ch.isprintable() and font.get_char_index(ord(ch)) else "?" for ch in text)
    return out.replace("$", r"\$")


def _targets(ax, pts: np.ndarray) -> None:
    ax.plot(pts.real, pts.imag, "x", color="k", ms=9, mew=2, label="targets", zorder=5)
    for k, z in enumerate(pts):
        ax.annotate(str(k + 1), (z.real, z.imag), textcoords="offset points", xytext=(6, 6), color="k")


def _draw(ax, c: Candidate, res, k: int, alpha: float, colour: str = "0.3") -> None:
    """The linkage at sample k: each link as a polygon of its joints."""
    mech = c.mechanism
    for lk in mech.links.values():
        xs = [res[f"{j}.x"][k] for j in lk.joints]
        ys = [res[f"{j}.y"][k] for j in lk.joints]
        if lk.ground:
            ax.plot(xs, ys, "^", color="k", ms=8, alpha=alpha)
            continue
        ax.plot(
            [*xs, xs[0]] if len(xs) > 2 else xs,
            [*ys, ys[0]] if len(ys) > 2 else ys,
            "-o",
            color=colour,
            ms=3,
            lw=1.5,
            alpha=alpha,
        )
    for p in mech.points.values():
        corners = [mech.links[p.link].joints[0], p.name, mech.links[p.link].joints[1]]
        xs, ys = [res[f"{j}.x"][k] for j in corners], [res[f"{j}.y"][k] for j in corners]
        ax.plot(xs, ys, "-", color=colour, lw=1, alpha=0.6 * alpha)
