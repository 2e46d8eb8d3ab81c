"""The teaching quantities as files and text: ``extras.csv`` (``vloop run --extras``), the summary
``vloop info`` prints, and the transmission-angle figure (``vloop run --plot``).

``extras.csv`` columns (one row per sample, the run's samples; angles rad, lengths the file's units):

* ``t``
* ``ic.A.B.x``, ``ic.A.B.y``: instant centre of bodies A and B (body order: ground, links, blocks);
  ``ic.A.B.inf``: 1 when it is at infinity (pure relative translation; then x, y hold its unit
  direction, angle in [0°, 180°)); ``ic.A.B.source``: 1 Kennedy's theorem, 2 the velocity field
  (Kennedy does not reach the pair at that sample), 0 neither (x = y = 0: bodies at rest, out of
  Kennedy's reach).
* ``mu.J.raw``, ``mu.J.folded``: transmission angle of the dyad measured at joint J (raw in [0, π],
  folded to [0, π/2] as textbooks quote it); ``mu.J.pressure`` for slider dyads (RRP, RPR): the
  pressure angle π/2 − folded.
* ``OUT.velocity_ratio``, ``OUT.mechanical_advantage`` for each output (one driver only): signed
  ẋ_out/ẋ_in and ẋ_in/ẋ_out, no losses (:mod:`vloop.teaching.ratios` for units).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import VloopError
from ..model import Mechanism
from ..result import Result
from .centres import instant_centres, kennedy_centres
from .ratios import default_outputs, mechanical_advantage, velocity_ratio
from .transmission import transmission_angles


def extras(
    mech: Mechanism, result: Result, outputs: list[str] | None = None, system: Any = None
) -> dict[str, np.ndarray]:
    """The extras columns (module docstring) over the run, by name, in file order."""
    cols: dict[str, np.ndarray] = {}
    ic = instant_centres(mech, result)
    for p, (a, b) in enumerate(ic.pairs):
        x, y, inf = ic.position(a, b)
        cols[f"ic.{a}.{b}.x"], cols[f"ic.{a}.{b}.y"] = x, y
        cols[f"ic.{a}.{b}.inf"] = inf.astype(float)
        cols[f"ic.{a}.{b}.source"] = ic.source[:, p].astype(float)
    for ta in transmission_angles(mech, result, system):
        j = ta.dyad.label
        cols[f"mu.{j}.raw"], cols[f"mu.{j}.folded"] = ta.raw, ta.folded
        if ta.dyad.kind != "RRR":
            cols[f"mu.{j}.pressure"] = ta.pressure
    if len(mech.drivers) == 1:
        for out in default_outputs(mech) if outputs is None else outputs:
            cols[f"{out}.velocity_ratio"] = velocity_ratio(mech, result, out)
            cols[f"{out}.mechanical_advantage"] = mechanical_advantage(mech, result, out)
    elif outputs:
        velocity_ratio(mech, result, outputs[0])  # raises the one-driver error
    return cols


def _check_finite(mech: Mechanism, result: Result, cols: dict[str, np.ndarray]) -> None:
    for name, v in cols.items():
        bad = ~np.isfinite(v)
        if bad.any():
            k = int(np.argmax(bad))
            why = " (the output is exactly at a dead centre there)" if name.endswith("mechanical_advantage") else ""
            raise VloopError(
                f"{mech.name}: {name} is not finite at t = {result.t[k]:.10g} s (sample {k}){why}", entry=name, sample=k
            )


def write_extras(
    mech: Mechanism, result: Result, folder: str | Path, outputs: list[str] | None = None, system: Any = None
) -> Path:
    """Write ``folder/extras.csv`` atomically (through vloop.files.output); every value must be finite."""
    from ..files.output import atomic_write

    cols = extras(mech, result, outputs, system)
    _check_finite(mech, result, cols)
    path = Path(folder) / "extras.csv"
    names = ["t", *cols]
    data = np.column_stack([result.t, *cols.values()]) if len(result.t) else np.zeros((0, len(names)))
    with atomic_write(path) as fh:
        np.savetxt(fh, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return path


def parse_outputs(mech: Mechanism, text: str) -> list[str]:
    """Outputs named on the command line (``--ma l4,l6``), checked: moving links or sliders, one driver."""
    from ..errors import MechanismError
    from .ratios import output_rate_column

    names = [n.strip() for n in str(text).split(",") if n.strip()]
    if not names:
        raise MechanismError(
            f"{mech.name}: --ma names no output (give links or sliders, comma-separated)", entry="outputs"
        )
    if len(mech.drivers) != 1:
        raise MechanismError(
            f"{mech.name}: --ma: a velocity ratio needs exactly one driver (the file has {len(mech.drivers)})",
            entry="outputs",
        )
    for n in names:
        output_rate_column(mech, n)
    return names


def run_files(
    mech: Mechanism, result: Result, folder: str | Path, *, extras: bool, plot: bool, outputs: list[str] | None = None
) -> list[Path]:
    """What ``vloop run`` adds: extras.csv (``--extras``) and transmission.png (``--plot``, if any dyad)."""
    files = []
    if extras:
        files.append(write_extras(mech, result, folder, outputs))
    if plot:
        fig = plot_transmission_angles(mech, result, Path(folder) / "transmission.png")
        if fig is not None:
            files.append(fig)
    return files


def plot_transmission_angles(mech: Mechanism, result: Result, path: str | Path) -> Path | None:
    """Figure of every dyad's folded transmission angle [deg] over time; None when there is no dyad."""
    from ..files.output import atomic_write

    angles = transmission_angles(mech, result)
    if not angles or not len(result.t):
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    for ta in angles:
        ax.plot(result.t, np.degrees(ta.folded), lw=1.6, label=f"μ at {ta.dyad.label} ({ta.dyad.kind})")
    ax.axhline(40.0, color="0.4", ls="--", lw=1, label="40°: a common lower limit")
    ax.set_ylim(0, 92)
    ax.set_yticks(range(0, 91, 15))
    ax.set_xlabel("t [s]")
    ax.set_ylabel("transmission angle μ [deg] (pressure angle = 90° − μ)")
    ax.set_title(f"{mech.title or mech.name}\ntransmission angle of each dyad (folded to 0–90°)", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc="best")
    fig.tight_layout()
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=110)
    plt.close(fig)
    return Path(path)


# ------------------------------------------------------------------ vloop info


def _input(mech: Mechanism, x: float) -> str:
    d = mech.drivers[0]
    if d.kind == "crank":
        return f"{d.symbol} = {x:.10g} rad ({math.degrees(x):.4f}°)"
    return f"{d.symbol} = {x:.10g} {mech.units}"


def _value(mech: Mechanism, name: str, v: float) -> str:
    return f"s = {v:.10g} {mech.units}" if name in mech.sliders else f"θ = {v:.10g} rad ({math.degrees(v):.4f}°)"


def _cycle_lines(mech: Mechanism) -> list[str]:
    from .input_cycle import TOL, cycle

    cyc = cycle(mech)
    what = "one turn of the crank" if cyc.full_turn else f"the feasible range [{cyc.lower:.10g}, {cyc.upper:.10g}]"
    lines = [f"  over {what} of {cyc.driver} (dead centres located to {TOL:g} of the range):"]
    for dc in cyc.dyads:
        lines.append(
            f"  transmission angle at {dc.dyad.label} ({dc.dyad.kind}: {dc.dyad.describe()}): "
            f"min {math.degrees(dc.min):.4f}° at {_input(mech, dc.min_input)}, "
            f"max {math.degrees(dc.max):.4f}° at {_input(mech, dc.max_input)}"
        )
    for tg in cyc.toggles:
        mu = f" (μ at {tg.dyad} = {math.degrees(tg.folded):.2g}°)" if tg.folded is not None else ""
        lines.append(f"  toggle (limit of the input) at {_input(mech, tg.input)}{mu}")
    for oc in cyc.outputs.values():
        unit = mech.units if oc.name in mech.sliders else "rad"
        what = "stroke" if oc.name in mech.sliders else "swing"
        travel = "turns fully" if oc.travel is None else f"{what} {oc.travel:.10g} {unit}"
        if oc.travel is not None and unit == "rad":
            travel += f" ({math.degrees(oc.travel):.4f}°)"
        ratio = ""
        if oc.time_ratio is not None:
            sense = "increasing" if oc.slow_sense > 0 else "decreasing"
            ratio = f", time ratio {oc.time_ratio:.10g} (slow stroke with {oc.name} {sense})"
        lines.append(f"  {oc.name}: {travel}{ratio}")
        for r in oc.rests:
            lines.append(
                f"    dead centre at {_input(mech, r.input)}: {oc.name} at rest, {_value(mech, oc.name, r.value)}"
            )
    lines += [f"  {n}" for n in cyc.notes]
    return lines


def _run_lines(mech: Mechanism) -> list[str]:
    """Transmission angles over the file's own run (several drivers: no single input cycle)."""
    from .. import solve

    try:
        res = solve(mech)
    except VloopError as exc:
        if exc.partial is None or not len(exc.partial):
            raise
        res = exc.partial
    span = f"t = {res.t[0]:g}..{res.t[-1]:g} s"
    lines = [f"  over the file's run ({len(mech.drivers)} drivers: no single input cycle), {span}:"]
    for ta in transmission_angles(mech, res):
        ex = ta.extremes()
        lines.append(
            f"  transmission angle at {ta.dyad.label} ({ta.dyad.kind}: {ta.dyad.describe()}): "
            f"min {math.degrees(ex['min']['value']):.4f}° at t = {ex['min']['t']:.6g} s, "
            f"max {math.degrees(ex['max']['value']):.4f}° at t = {ex['max']['t']:.6g} s"
        )
    return lines


def _kennedy_line(mech: Mechanism) -> str:
    from .. import solve

    ken = kennedy_centres(mech, solve(mech, times=np.zeros(1)))
    missing = ken.unreachable()
    n = len(ken.pairs)
    if not missing:
        return f"  instant centres: Kennedy's theorem reaches all {n} pairs of bodies"
    names = ", ".join(f"({a}, {b})" for a, b in missing)
    return (
        f"  instant centres: Kennedy's theorem reaches {n - len(missing)} of {n} pairs at t = 0; "
        f"from the velocity field only: {names}"
    )


def info_lines(mech: Mechanism) -> list[str]:
    """The teaching summary ``vloop info`` prints: transmission angles (min, where), toggles, dead centres,
    strokes, time ratios, Kennedy's reach. Problems become a line of text, never an exception."""
    lines = ["teaching quantities:"]
    for part in (_cycle_lines if len(mech.drivers) == 1 else _run_lines, _kennedy_line):
        try:
            got = part(mech)
        except VloopError as exc:
            got = [f"  not available: {exc}"]
        lines += [got] if isinstance(got, str) else got
    return lines
