"""Figures in the style of the paper's Figs. 5–7 (PNG, matplotlib ``Figure`` objects, no pyplot).

Curves that lie on top of each other (the eight-bar's mirror-image sliders l6 and l8) are drawn
with different line styles and markers and named in the legend (:mod:`.curves`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from ..model import Mechanism
from ..result import Result
from .curves import distinguish, note_legend


def _history(
    result: Result, names: list[str], fields: tuple[str, str, str], ylabels: tuple[str, str, str], title: str
) -> Any:
    """Three stacked panels over time (θ, ω, α or s, v, a), one curve per name."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7.5, 8.5))
    axes = fig.subplots(3, 1, sharex=True)
    for ax, f, yl in zip(axes, fields, ylabels, strict=True):
        for n in names:
            ax.plot(result.t, result[f"{n}.{f}"], label=n, lw=1.6)
        ax.set_ylabel(yl)
        ax.grid(True, alpha=0.3)
    changed = [distinguish(ax) for ax in axes]
    axes[0].legend(loc="best", fontsize=9)
    for ax, lines in zip(axes[1:], changed[1:], strict=True):
        note_legend(ax, lines)
    axes[0].set_title(title, fontsize=10)
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    return fig


def _paths(mech: Mechanism, result: Result) -> Any:
    """The joints' and points' paths, with the mechanism drawn at the first sample."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 6))
    ax = fig.add_subplot()
    for n in mech.tracked_points:
        ax.plot(result[f"{n}.x"], result[f"{n}.y"], lw=1.2, label=n)
    for lk in mech.links.values():  # the mechanism at the first sample
        xs = [result[f"{j}.x"][0] for j in lk.joints]
        ys = [result[f"{j}.y"][0] for j in lk.joints]
        if len(lk.joints) > 2:
            xs.append(xs[0])
            ys.append(ys[0])
        ax.plot(xs, ys, "k-o" if not lk.ground else "k^", lw=2.5, ms=4)
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    distinguish(ax)
    ax.legend(fontsize=8, loc="best")
    ax.set_title(
        f"{mech.title or mech.name}\npaths of joints and points (mechanism at t = {result.t[0]:g} s)", fontsize=10
    )
    ax.set_xlabel(f"x [{mech.units}]")
    ax.set_ylabel(f"y [{mech.units}]")
    fig.tight_layout()
    return fig


def figures(mech: Mechanism, result: Result) -> dict[str, Any]:
    """The figures ``plot_result`` writes, by file name: links.png (θ, ω, α of the rotating links),
    sliders.png (s, v, a) and paths.png; none for a result without samples."""
    if len(result.t) == 0:
        return {}
    out = {}
    title = mech.title or mech.name
    driven = {d.target for d in mech.drivers if d.kind == "crank"}
    rotating = [n for n in mech.links if not mech.links[n].ground and n not in driven] or [
        n for n in mech.links if not mech.links[n].ground
    ]
    if rotating:
        out["links.png"] = _history(
            result, rotating, ("theta", "omega", "alpha"), ("θ [rad]", "ω [rad/s]", "α [rad/s²]"),
            f"{title}\nangular position, velocity, acceleration of the links",
        )  # fmt: skip
    if mech.sliders:
        u = mech.units
        out["sliders.png"] = _history(
            result, list(mech.sliders), ("s", "v", "a"), (f"s [{u}]", f"v [{u}/s]", f"a [{u}/s²]"),
            f"{title}\nposition, velocity, acceleration of the sliders",
        )  # fmt: skip
    out["paths.png"] = _paths(mech, result)
    return out


def plot_result(mech: Mechanism, result: Result, out_dir: str | Path) -> list[Path]:
    """Write links.png (θ, ω, α of the rotating links), sliders.png (s, v, a) and paths.png."""
    import matplotlib

    matplotlib.use("Agg")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files: list[Path] = []
    for name, fig in figures(mech, result).items():
        fig.savefig(out / name, dpi=110)
        files.append(out / name)
    return files
