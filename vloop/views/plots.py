"""Figures in the style of the paper's Figs. 5–7 (PNG, matplotlib's Agg backend)."""

from __future__ import annotations

from pathlib import Path

from ..model import Mechanism
from ..result import Result


def _figure(
    result: Result,
    names: list[str],
    fields: tuple[str, str, str],
    ylabels: tuple[str, str, str],
    title: str,
    path: Path,
) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(7.5, 8.5), sharex=True)
    for ax, f, yl in zip(axes, fields, ylabels, strict=True):
        for n in names:
            ax.plot(result.t, result[f"{n}.{f}"], label=n, lw=1.6)
        ax.set_ylabel(yl)
        ax.grid(True, alpha=0.3)
    axes[0].legend(loc="best", fontsize=9)
    axes[0].set_title(title, fontsize=10)
    axes[-1].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def plot_result(mech: Mechanism, result: Result, out_dir: str | Path) -> list[Path]:
    """Write links.png (θ, ω, α of the rotating links), sliders.png (s, v, a) and paths.png."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files: list[Path] = []
    if len(result.t) == 0:
        return files
    driven = {d.target for d in mech.drivers if d.kind == "crank"}
    rotating = [n for n in mech.links if not mech.links[n].ground and n not in driven] or [
        n for n in mech.links if not mech.links[n].ground
    ]
    if rotating:
        files.append(
            _figure(
                result, rotating, ("theta", "omega", "alpha"),
                ("θ [rad]", "ω [rad/s]", "α [rad/s²]"),
                f"{mech.title or mech.name}\nangular position, velocity, acceleration of the links", out / "links.png",
            )
        )  # fmt: skip
    if mech.sliders:
        u = mech.units
        files.append(
            _figure(
                result, list(mech.sliders), ("s", "v", "a"),
                (f"s [{u}]", f"v [{u}/s]", f"a [{u}/s²]"),
                f"{mech.title or mech.name}\nposition, velocity, acceleration of the sliders", out / "sliders.png",
            )
        )  # fmt: skip
    fig, ax = plt.subplots(figsize=(7, 6))
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
    ax.legend(fontsize=8, loc="best")
    ax.set_title(
        f"{mech.title or mech.name}\npaths of joints and points (mechanism at t = {result.t[0]:g} s)", fontsize=10
    )
    ax.set_xlabel(f"x [{mech.units}]")
    ax.set_ylabel(f"y [{mech.units}]")
    fig.tight_layout()
    fig.savefig(out / "paths.png", dpi=110)
    plt.close(fig)
    files.append(out / "paths.png")
    return files
