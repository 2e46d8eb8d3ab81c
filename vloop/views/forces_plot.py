"""The forces figure of ``vloop run --plot`` (PNG, matplotlib's Agg backend), as textbooks draw them:
the driver torque over time, the pin reactions' magnitudes over time, and a polar plot of the
driven crank's bearing force (the force on the crank at its ground pivot, the vector's tip traced
over the run)."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..files.output import atomic_write
from ..model import Mechanism

if TYPE_CHECKING:  # the plot reads a ForceResult; vloop.forces imports this module lazily
    from ..forces import ForceResult

TOP_PINS = 6  # reaction magnitudes drawn (the largest)


def polar_pin(mech: Mechanism, forces: ForceResult) -> str | None:
    """The reaction drawn in the polar plot: the first driver's ground bearing, else the largest one."""
    names = [c[:-4] for c in forces.columns if c.endswith(".mag")]
    for d in mech.drivers:
        if d.kind == "crank":
            hit = [n for n in names if n.startswith(f"{d.pivot}:") and n.endswith(f">{d.target}")]
            if hit:
                return hit[0]
    return max(names, key=lambda n: float(np.max(forces[f"{n}.mag"], initial=0.0)), default=None)


def plot_forces(mech: Mechanism, forces: ForceResult, out_dir: str | Path) -> list[Path]:
    """Write forces.png (driver torque, reaction magnitudes, polar plot of one bearing force)."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    if len(forces.t) == 0:
        return []
    fig = Figure(figsize=(11, 8.5))
    grid = fig.add_gridspec(2, 2, width_ratios=(1.5, 1))
    ax_t = fig.add_subplot(grid[0, :])
    for d in mech.drivers:
        col = f"{d.target}.torque" if d.kind == "crank" else f"{d.target}.force"
        if col in forces:
            unit = "N·m" if d.kind == "crank" else "N"
            ax_t.plot(forces.t, forces[col], lw=1.8, label=f"{col} [{unit}]")
    ax_t.axhline(0.0, color="k", lw=0.6)
    ax_t.set_ylabel("driver torque / force")
    ax_t.set_xlabel("t [s]")
    ax_t.legend(fontsize=9, loc="best")
    ax_t.grid(True, alpha=0.3)
    ax_t.set_title(f"{mech.title or mech.name}\nforces (kinetostatics)", fontsize=10)
    ax_m = fig.add_subplot(grid[1, 0])
    mags = sorted((c for c in forces.columns if c.endswith(".mag")), key=lambda c: -float(np.max(forces[c])))
    for c in mags[:TOP_PINS]:
        ax_m.plot(forces.t, forces[c], lw=1.4, label=c[:-4])
    ax_m.set_ylabel("pin force |F| [N]")
    ax_m.set_xlabel("t [s]")
    ax_m.grid(True, alpha=0.3)
    if mags:
        ax_m.legend(fontsize=8, loc="best")
    pin = polar_pin(mech, forces)
    if pin is not None:
        ax_p = fig.add_subplot(grid[1, 1], projection="polar")
        fx, fy = forces[f"{pin}.fx"], forces[f"{pin}.fy"]
        ax_p.plot(np.arctan2(fy, fx), np.hypot(fx, fy), lw=1.4)
        ax_p.set_title(f"{pin} [N], polar", fontsize=9)
    if forces.indeterminate:
        fig.text(0.01, 0.005, "statically indeterminate: " + ", ".join(forces.indeterminate), fontsize=8)
    fig.tight_layout()
    path = Path(out_dir) / "forces.png"
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    return [path]
