"""A synthesis's output set: the ranked table, the best solutions as mechanism files, pictures, viewer pages.

    candidates.csv        one row per candidate (solutions ranked first; defects named), empty cells for
                          quantities a candidate has not (a position it never reached)
    candidates.parquet    the same table, where pyarrow is installed
    NAME_k.toml           each of the best solutions (files=3 of them): closed t = 0 coordinates, its [time]
                          covering the working motion and every precision instant (listed in the header comment)
    structural_error.png | path.png | poses.png   with plot=True
    NAME_k.html           with html=True: the viewer page of each file, the targets drawn on it

Everything is written through one :class:`~vloop.output.OutputSet` (published together or not at all).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import SynthesisError
from ..files.fileformat import dumps
from ..files.output import OutputSet
from .candidates import Candidate, Candidates

# the set's fixed names (the candidates' files are listed in its record)
OWNS = ("candidates.csv", "candidates.parquet", "structural_error.png", "path.png", "poses.png")
RECORD = ".vloop-synth-outputs"


def write(
    result: Candidates, folder: str | Path, *, files: int = 3, plot: bool = False, html: bool = False
) -> list[Path]:
    """Write the output set into ``folder`` (see the module docstring); returns the published paths. A folder used
    by an earlier synthesis keeps none of its files that this one does not write (a record lists them)."""
    _arguments(result, folder, files, plot, html)
    chosen = result.solutions[:files]
    with OutputSet(folder, owns=OWNS, record=RECORD) as out:
        table = result.table().replace([np.inf, -np.inf], np.nan)
        table["file"] = [f"{c.name}.toml" if c in chosen else "" for c in result.items]
        table.to_csv(out.path("candidates.csv"), index=False, na_rep="")
        _parquet(table, out.path("candidates.parquet"))
        for c in chosen:
            out.write_text(f"{c.name}.toml", toml_text(c))
        if plot:
            from .plot import plot_result

            plot_result(result, chosen, out.stage)
        if html:
            for c in chosen:
                _page(result, c, out.path(f"{c.name}.html"))
    return out.published


def _arguments(result: Any, folder: Any, files: Any, plot: Any, html: Any) -> None:
    """Each argument checked before anything is written (the names become file names inside ``folder``)."""
    from ..files.options import folder as folder_path
    from . import arguments as args

    if not isinstance(result, Candidates):
        raise SynthesisError(f"result: must be what a synthesis returns (Candidates), got {type(result).__name__}")
    folder_path(str(folder) if isinstance(folder, Path) else folder, "folder")
    args.count(files, "files", "files")
    for key, v in (("plot", plot), ("html", html)):
        if not isinstance(v, bool):
            raise SynthesisError(f"{key}: must be True or False, got {v!r:.40}", entry=key)
    for c in result.items:
        args.name(c.name, "candidate name")


def _parquet(table: Any, path: Path) -> None:
    try:
        import pyarrow  # noqa: F401
    except ImportError:
        return
    table.to_parquet(path, index=False)


def toml_text(c: Candidate) -> str:
    """The candidate's mechanism file with a header saying what it is and when it meets each position."""
    fmt = ", ".join
    lines = [
        f"# {c.name}: synthesized by vloop ({c.method} generation, {c.topology}); re-solved by vloop: no defect",
        f"# input: {c.input} (1 rad/s); guided body: {c.guided}" + (f"; tracer point: {c.tracer}" if c.tracer else ""),
        f"# precision positions reached at t = [{fmt(f'{t:.12g}' for t in c.times)}] s",
        f"#   input angle {c.input}.theta = [{fmt(f'{x:.12g}' for x in c.inputs)}] rad",
        f"#   error there = [{fmt(f'{e:.3g}' for e in c.errors)}]"
        + (" rad" if c.method == "function" else f" {c.mechanism.units}"),
    ]
    if c.angle_errors is not None:
        lines.append(f"#   angle error there = [{fmt(f'{e:.3g}' for e in c.angle_errors)}] rad")
    if c.structural_error is not None and math.isfinite(c.structural_error):
        lines.append(f"# largest structural error over the range: {c.structural_error:.4g} of the y range")
    mu = math.degrees(c.min_transmission)
    lines.append(f"# Grashof: {c.grashof or 'no four-bar loop'}; minimum transmission angle {mu:.1f}°")
    return "\n".join(lines) + "\n" + dumps(c.mechanism)


def _page(result: Candidates, c: Candidate, path: Path) -> None:
    """The viewer page of a written candidate with its targets: points, poses (with their angle), or a
    function generator's output pin at each precision instant."""
    from .. import solve
    from ..views.view import write_view

    res = solve(c.mechanism)
    task = result.task
    if task.points is not None:
        angles = task.angles if task.angles is not None else [None] * len(task.points)
        targets = [
            (z.real, z.imag) if a is None else (z.real, z.imag, a) for z, a in zip(task.points, angles, strict=True)
        ]
    else:
        at = solve(c.mechanism, np.asarray(c.times))
        pin = "B"
        targets = [(float(x), float(y)) for x, y in zip(at[f"{pin}.x"], at[f"{pin}.y"], strict=True)]
    write_view(c.mechanism, res, path, targets=targets)
