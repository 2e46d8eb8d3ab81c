"""``vloop simulate``'s files, written into a folder it is given (an OutputSet's staging folder):

* results.FMT — ``t``, θ ω α of every link, x y vx vy ax ay of every joint and point, s v a of every slider
  (as ``vloop run`` writes them), and the input's torque ``INPUT.torque`` [N·m] (``INPUT.force`` [N]);
* health.FMT — the loop solve's health at every row (as ``vloop run``);
* energy.FMT — kinetic energy, potentials of gravity and springs, works of the input, the loads and the
  dampers, and the balance's residual [J];
* with ``plot``: links.png, sliders.png, paths.png (as ``vloop run --plot``) and energy.png;
* with ``html``: the viewer page NAME.html.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..files.output import atomic_write
from ..files.writers import health_columns, write_table
from ..result import column_units, write_csv
from .integrate import ENERGY_COLUMNS, Simulation


def write(
    sim: Simulation, folder: Path, fmt: str = "csv", *, plot: bool = False, html: bool = False, error: str | None = None
) -> list[Path]:
    """Write the simulation's files into ``folder`` (see the module notes); returns their paths."""
    mech, res = sim.mechanism, sim.result
    units = column_units(["t", *res.columns], mech.units)
    units.update({c: "N·m" for c in res.columns if c.endswith(".torque")})
    units.update({c: "N" for c in res.columns if c.endswith(".force")})
    files = [
        _table(folder / f"results.{fmt}", {"t": res.t, **res.columns}, units),
        _table(folder / f"health.{fmt}", health_columns(res), {}),
        _table(folder / f"energy.{fmt}", {"t": res.t, **sim.energy}, {"t": "s", **dict.fromkeys(ENERGY_COLUMNS, "J")}),
    ]
    if plot and len(res):
        from ..views.plots import plot_result

        files += plot_result(mech, res, folder)
        files.append(energy_figure(sim, folder / "energy.png"))
    if html:
        from ..files.output import safe_folder_name
        from ..views.view import write_view

        files.append(write_view(mech, res, folder / f"{safe_folder_name(mech.name)}.html", error=error))
    return files


def _table(path: Path, cols: dict[str, np.ndarray], units: dict[str, str]) -> Path:
    """A table as ``vloop run`` writes its own: CSV with a header and each number the shortest text that reads
    back to the same double, or Parquet with every column's unit in its schema."""
    if path.suffix == ".csv":
        with atomic_write(path, "wb") as fh:
            write_csv(fh, list(cols), [np.asarray(c) for c in cols.values()])
        return path
    import pandas as pd

    return write_table(pd.DataFrame(cols), path, "parquet", units)


def energy_figure(sim: Simulation, path: Path) -> Path:
    """energy.png: the energies and works over time [J], and the balance's residual below."""
    import matplotlib

    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(8, 6))
    top, bottom = fig.subplots(2, 1, sharex=True, height_ratios=(3, 1))
    t = sim.t
    for name in ENERGY_COLUMNS[:-1]:
        if any(sim.energy[name]):
            top.plot(t, sim.energy[name], label=name.replace("_", " "))
    top.set_ylabel("energy [J]")
    top.legend(loc="best", fontsize=8)
    top.set_title(f"{sim.mechanism.name}: energy balance")
    bottom.plot(t, sim.energy["residual"], color="k")
    bottom.set_ylabel("residual [J]")
    bottom.set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return path


def summary_lines(sim: Simulation) -> list[str]:
    """What the run did: rows, the input's final state, the energy balance's largest residual."""
    mech, res = sim.mechanism, sim.result
    e = sim.energy
    span = max(float(abs(e["kinetic"]).max(initial=0.0)), 1e-300)
    tables = sim.model.tables.error if hasattr(sim.model, "tables") else None  # (two inputs: the solve at each call)
    how = f"tables within {tables:.1e}" if tables is not None else "the loop solve at every step"
    lines = [
        f"{mech.name}: simulated {len(res)} rows, t = {res.t[0]:g}..{res.t[-1]:g} s ({sim.model.dynamics.method}, "
        f"rtol {sim.model.dynamics.rtol:g}, {how})" if len(res) else f"{mech.name}: no row simulated",
    ]  # fmt: skip
    for d in mech.drivers if len(res) else ():
        x = res[f"{d.target}.theta"] if d.kind == "crank" else res[f"{d.target}.s"]
        v = res[f"{d.target}.omega"] if d.kind == "crank" else res[f"{d.target}.v"]
        lines.append(f"  at the end: {d.value_text(float(x[-1]), mech.units)}, rate {float(v[-1]):.10g} per s")
    if len(res):
        lines.append(
            f"  energy balance: largest residual {abs(e['residual']).max():.3g} J (largest kinetic energy {span:.6g} J)"
        )
    return lines
