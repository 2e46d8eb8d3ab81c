"""Remake docs/branches.png, the picture of the branch names (docs/dimensions.md#branch-names).

    python docs/make_branches_png.py [OUT.png]

The catalog's Grashof crank-rocker (O2 = (0, 0), O4 = (7, 0); crank 2, coupler 6, rocker 5) on each branch,
as vloop assembles it from ``[solver] branches``: "open" (B to the left of the diagonal A→O4) and "crossed" (B to
the right), at the crank angle of the file (60°) and at 250°, where the open circuit's quadrilateral crosses
itself and the name stays "open". Every name drawn is the one vloop.method.branches gives (checked here).
"""

from __future__ import annotations

import math
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import vloop  # noqa: E402
from vloop.method.branches import branch_name, dyad_branch  # noqa: E402

FILE = """
name = "crank_rocker"
[joints]
O2 = [0.0, 0.0]
O4 = [7.0, 0.0]
[links]
ground = {{ joints = ["O2", "O4"], ground = true }}
l2 = {{ joints = ["O2", "A"], length = 2.0 }}
l3 = {{ joints = ["A", "B"], length = 6.0 }}
l4 = {{ joints = ["O4", "B"], length = 5.0 }}
[[drivers]]
link = "l2"
theta0 = {theta}
omega = 1.0
[time]
start = 0.0
stop = 1.0
step = 1.0
[solver]
branches = {{ 1 = "{name}" }}
"""


def _joints(name: str, theta_deg: float) -> dict[str, complex]:
    mech = vloop.loads(FILE.format(theta=math.radians(theta_deg), name=name))
    system = vloop.compile(mech)
    assert branch_name(system, system.blocks[0], system.q0) == name
    b = dyad_branch(system, system.blocks[0], system.q0)
    assert (b.start, b.middle, b.end) == ("A", "B", "O4")
    return {j: complex(*xy) for j, xy in mech.joints.items()}


def _draw(ax, p: dict[str, complex], name: str, theta_deg: float) -> None:
    colour = "#1f77b4" if name == "open" else "#d62728"
    for u, v, lw in (("O2", "A", 3), ("A", "B", 3), ("O4", "B", 3)):
        ax.plot([p[u].real, p[v].real], [p[u].imag, p[v].imag], color=colour, lw=lw, solid_capstyle="round", zorder=2)
    ax.plot([p["O2"].real, p["O4"].real], [0, 0], color="0.4", lw=1, zorder=1)
    ax.annotate(
        "", xy=(p["O4"].real, p["O4"].imag), xytext=(p["A"].real, p["A"].imag),
        arrowprops={"arrowstyle": "->", "ls": "--", "color": "0.25", "lw": 1.2}, zorder=3,
    )  # fmt: skip
    for j, z in p.items():
        ax.plot(z.real, z.imag, "o", color="white", mec="black", ms=6, zorder=4)
        dx = -0.35 if j == "O2" else 0.2
        ax.text(z.real + dx, z.imag + 0.25, j, fontsize=10, zorder=5)
    side = "left" if name == "open" else "right"
    ax.set_title(f'"{name}": B {side} of A→O4\nθ₂ = {theta_deg:g}°', fontsize=10)
    ax.set_aspect("equal")
    ax.set_xlim(-3, 9.5)
    ax.set_ylim(-5.5, 6)
    ax.axis("off")


def main(out: Path = ROOT / "docs" / "branches.png") -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(12, 3.6))
    for ax, (name, theta) in zip(axes, (("open", 60), ("crossed", 60), ("open", 250), ("crossed", 250)), strict=True):
        _draw(ax, _joints(name, theta), name, theta)
    fig.suptitle(
        "Branch names: the side of the diagonal A→O4 (input end → frame end) that B lies on, the same over a "
        "whole circuit",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.9))
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out


if __name__ == "__main__":
    print(main(Path(sys.argv[1])) if len(sys.argv) > 1 else main())
