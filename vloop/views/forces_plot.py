"""The forces figure of ``vloop run --plot`` (PNG, matplotlib ``Figure``, no pyplot), as textbooks draw
them: the driver torque over time, the pin reactions' magnitudes over time, and a polar plot of the
driven crank's bearing force (the force on the crank at its ground pivot, the vector's tip traced over
the run).

Every pin reaction is drawn when there are at most ``MAX_PINS``; beyond that the largest ones are, and
the figure names the others (every reaction is in forces.csv). Reactions whose magnitudes coincide
are told apart by line style (:mod:`.curves`). The polar plot's radial labels never overlap: fewer
rings are labelled until they fit, on the side the force points to least.
"""

from __future__ import annotations

import textwrap
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..files.output import atomic_write
from ..model import Mechanism
from .curves import distinguish

if TYPE_CHECKING:  # the plot reads a ForceResult; vloop.forces imports this module lazily
    from ..forces import ForceResult

MAX_PINS = 10  # reaction magnitudes drawn (the largest): one colour each in matplotlib's cycle
MAX_NAMED = 40  # omitted reactions named on the figure; the rest are counted
RADIAL_LABELS = 4  # labelled rings of the polar plot at most


def polar_pin(mech: Mechanism, forces: ForceResult) -> str | None:
    """The reaction drawn in the polar plot: the first driver's ground bearing, else the largest one."""
    names = [c[:-4] for c in forces.columns if c.endswith(".mag")]
    for d in mech.drivers:
        if d.kind == "crank":
            hit = [n for n in names if n.startswith(f"{d.pivot}:") and n.endswith(f">{d.target}")]
            if hit:
                return hit[0]
    return max(names, key=lambda n: float(np.max(forces[f"{n}.mag"], initial=0.0)), default=None)


def drawn_pins(forces: ForceResult) -> tuple[list[str], list[str]]:
    """(drawn, omitted) reaction magnitude columns: all when at most MAX_PINS, else the largest peaks."""
    mags = sorted((c for c in forces.columns if c.endswith(".mag")), key=lambda c: -float(np.max(forces[c])))
    return mags[:MAX_PINS], mags[MAX_PINS:]


def _omitted_note(forces: ForceResult, omitted: list[str]) -> str:
    names = [c[:-4] for c in omitted]
    listed = ", ".join(names[:MAX_NAMED]) + (f" and {len(names) - MAX_NAMED} more" if len(names) > MAX_NAMED else "")
    peak = max(float(np.max(forces[c])) for c in omitted)
    return (
        f"pin forces not drawn ({len(names)} of {len(names) + MAX_PINS}, the smallest: peaks ≤ {peak:.3g} N; "
        f"every reaction is in forces.csv): {listed}"
    )


def _torque_panel(ax: Any, mech: Mechanism, forces: ForceResult) -> None:
    for d in mech.drivers:
        col = f"{d.target}.torque" if d.kind == "crank" else f"{d.target}.force"
        if col in forces:
            unit = "N·m" if d.kind == "crank" else "N"
            ax.plot(forces.t, forces[col], lw=1.8, label=f"{col} [{unit}]")
    ax.axhline(0.0, color="k", lw=0.6)
    ax.set_ylabel("driver torque / force")
    ax.set_xlabel("t [s]")
    distinguish(ax)
    ax.legend(fontsize=9, loc="best")
    ax.grid(True, alpha=0.3)
    ax.set_title(f"{mech.title or mech.name}\nforces (kinetostatics)", fontsize=10)


def _pin_panel(ax: Any, forces: ForceResult, drawn: list[str]) -> None:
    for c in drawn:
        ax.plot(forces.t, forces[c], lw=1.4, label=c[:-4])
    ax.set_ylabel("pin force |F| [N]")
    ax.set_xlabel("t [s]")
    ax.grid(True, alpha=0.3)
    if drawn:
        distinguish(ax)
        ax.legend(fontsize=8, loc="best", ncol=2 if len(drawn) > 5 else 1)


def _quiet_side(theta: np.ndarray, r: np.ndarray) -> float:
    """The direction [deg] (an odd multiple of 22.5°) the force points to least, weighted by magnitude."""
    centres = np.arange(22.5, 360.0, 45.0)
    gap = np.abs((np.degrees(theta)[:, None] - centres[None, :] + 180.0) % 360.0 - 180.0)
    weight = (gap < 22.5) * r[:, None]
    return float(centres[int(np.argmin(weight.sum(axis=0)))])


def _overlaps(texts: list[Any], renderer: Any) -> bool:
    boxes = [t.get_window_extent(renderer) for t in texts if t.get_visible() and t.get_text()]
    return any(a.overlaps(b) for i, a in enumerate(boxes) for b in boxes[i + 1 :])


def _polar_panel(fig: Any, where: Any, pin: str, forces: ForceResult) -> Any:
    from matplotlib.ticker import EngFormatter

    ax = fig.add_subplot(where, projection="polar")
    fx, fy = forces[f"{pin}.fx"], forces[f"{pin}.fy"]
    theta, r = np.arctan2(fy, fx), np.hypot(fx, fy)
    ax.plot(np.unwrap(theta), r, lw=1.4)  # unwrapped: across ±180° the curve takes the short way round
    ax.set_title(f"{pin} [N], polar", fontsize=9, pad=14)
    ax.set_rlabel_position(_quiet_side(theta, r))
    ax.yaxis.set_major_formatter(EngFormatter(sep=""))
    ax.tick_params(axis="y", labelsize=8)
    return ax


def _fit_radial_labels(fig: Any, ax: Any) -> None:
    """Fewer labelled rings until the radial labels, the angle labels and the title do not overlap."""
    from matplotlib.ticker import MaxNLocator

    for n in range(RADIAL_LABELS, 0, -1):
        ax.yaxis.set_major_locator(MaxNLocator(nbins=n, prune="lower"))
        renderer = fig.canvas.get_renderer()
        fig.canvas.draw()
        texts = [*ax.yaxis.get_ticklabels(), *ax.xaxis.get_ticklabels(), ax.title]
        if not _overlaps(texts, renderer):
            return


def forces_figure(mech: Mechanism, forces: ForceResult) -> Any:
    """The forces figure (module docstring); None for a run without samples."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    if len(forces.t) == 0:
        return None
    fig = Figure(figsize=(11, 8.5))
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 2, width_ratios=(1.5, 1))
    _torque_panel(fig.add_subplot(grid[0, :]), mech, forces)
    drawn, omitted = drawn_pins(forces)
    _pin_panel(fig.add_subplot(grid[1, 0]), forces, drawn)
    pin = polar_pin(mech, forces)
    polar = _polar_panel(fig, grid[1, 1], pin, forces) if pin is not None else None
    notes = [_omitted_note(forces, omitted)] if omitted else []
    if forces.indeterminate:
        notes.append("statically indeterminate: " + ", ".join(forces.indeterminate))
    lines = [line for note in notes for line in textwrap.wrap(note, 170)]
    if lines:
        fig.text(0.01, 0.005, "\n".join(lines), fontsize=8, va="bottom")
    fig.tight_layout(rect=(0, 0.018 * len(lines), 1, 1))
    if polar is not None:
        _fit_radial_labels(fig, polar)
    return fig


def plot_forces(mech: Mechanism, forces: ForceResult, out_dir: str | Path) -> list[Path]:
    """Write forces.png (driver torque, reaction magnitudes, polar plot of one bearing force)."""
    fig = forces_figure(mech, forces)
    if fig is None:
        return []
    path = Path(out_dir) / "forces.png"
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    return [path]
