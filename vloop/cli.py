"""Command line: ``vloop run | view | loops | info | validate | study | synth | assemble | export``. One function
per command.

Exit codes: 0 success; 1 a validation that fails its tolerances; 2 bad input, an output that cannot be
written, or a motion that cannot be completed (one line on stderr, no traceback; ``run`` still writes
every row solved before the failure); 130 interrupted (Ctrl-C: nothing half-written is left behind).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .errors import MotionError, VloopError
from .model import angle_text
from .result import Result

RUN_TABLES = ("results.csv", "results.parquet", "results.npz", "health.csv", "health.parquet", "health.npz")
INFO_SOLVE_LIMIT = 200_000  # vloop info solves the file's motion up to this many samples


def _fail(msg: str) -> int:
    print(f"vloop: error: {' '.join(msg.splitlines())}", file=sys.stderr)  # one line, whatever the message holds
    return 2


# ---------------------------------------------------------------- shared option handling


def _load(args: argparse.Namespace) -> Any:
    """The mechanism file named on the command line (profiles outside its folder only if allowed); a file written
    from dimensions assembled at t = 0."""
    from . import load

    return load(args.file, allow_external_profiles=getattr(args, "allow_external_profiles", False))


def _out_folder(args: argparse.Namespace, mech: Any) -> Path:
    """--out, else out/<safe name> (a name can never lead outside out/), checked before any work."""
    from .files.output import check_folder, default_folder

    return check_folder(Path(args.out) if args.out else default_folder(mech.name))


def _add_file(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", type=_type("file"), help="mechanism file (TOML)")
    p.add_argument(
        "--allow-external-profiles",
        action="store_true",
        help="read tabulated profiles outside the mechanism file's folder (refused by default)",
    )


# ---------------------------------------------------------------- run


def cmd_run(args: argparse.Namespace) -> int:
    """Solve the file's motion in chunks, streaming results.FMT and health.FMT to disk; the extras the options
    ask for (plots, extras.csv, forces, the viewer page) need the whole run in memory. One atomic set."""
    from .compiler import compile_system

    mech = _load(args)
    outputs = _teaching_outputs(args, mech)
    if args.sweep:
        mech = _rocking(mech)
    system = compile_system(mech, args.method)
    out = _out_folder(args, mech)
    summary, files, error = _run_streamed(args, mech, system, out, outputs)
    if error is not None:
        return _fail(f"{error} (wrote {summary.rows} rows to {out / f'results.{args.format}'})")
    _print_run_summary(system, summary)
    print("wrote " + ", ".join(str(f) for f in files))
    return 0


def _run_streamed(args: argparse.Namespace, mech: Any, system: Any, out: Path, outputs: Any) -> tuple:
    """Stream the run's chunks into results.FMT / health.FMT (vloop.files.writers) inside one OutputSet, then the
    extras from the whole run when asked. Returns (summary, published files, the MotionError that stopped it)."""
    from .core.solver import CHUNK_ROWS, join, solve_iter
    from .files import budget, writers
    from .files.output import OutputSet
    from .files.progress import Progress
    from .forces import has_forces

    keep = bool(args.plot or args.html or args.extras or outputs is not None or has_forces(mech))
    n = len(mech.times)
    budget.check(system, n, not keep, CHUNK_ROWS, args.memory_budget)
    with OutputSet(out, owns=RUN_TABLES) as files:  # a results.csv never stays beside a new results.parquet
        writers.check_disk(files.folder, n, budget.columns(system), args.format)
        chunks = solve_iter(system, memory_budget=args.memory_budget)
        with Progress(n, mech.name) as progress:
            summary, kept, _, error = writers.stream(
                files, args.format, chunks, _column_names(system), mech.units, mech.name, progress, keep
            )
        if keep and kept:
            _write_extras(files.stage, args, mech, join(kept), outputs, error)
    return summary, files.published, error


def _column_names(system: Any) -> list[str]:
    """The results' columns in output order (as vloop.solve names them)."""
    cols = [f"{name}.{f}" for name, _, _ in system.link_outputs for f in ("theta", "omega", "alpha")]
    cols += [f"{p}.{f}" for p in system.point_names for f in ("x", "y", "vx", "vy", "ax", "ay")]
    cols += [f"{s}.{f}" for s in system.slider_names for f in ("s", "v", "a")]
    return cols


def _print_run_summary(system: Any, summary: Any) -> None:
    mech = system.mechanism
    asm = system.assembly
    moved = ""
    if asm.get("moved", 0) > 1e-12 * mech.scale:  # more than round-off
        moved = f", t = 0 assembly moved joints by up to {asm['moved']:.3g} {mech.units}"
    print(
        f"{mech.name}: {summary.rows} samples, t = {summary.t_first:g}..{summary.t_last:g} s, "
        f"{len(system.loops)} loop{'s' if len(system.loops) != 1 else ''}, "
        f"max closure {summary.closure:.2g}, max condition {summary.cond:.3g}{moved}"
    )
    notes = Result(mech.name, "vloop", np.zeros(0), {}, {"ill_conditioned": np.array([summary.ill])}, summary.meta)
    for line in health_notes(notes):
        print(line)


def _rocking(mech: Any) -> Any:
    from .sweep import rocking

    mech = rocking(mech)
    lo, hi = mech.options.get("sweep", (None, None))
    if lo is not None:
        print(f"{mech.name}: rocks between the limits of {mech.drivers[0].range_text(lo, hi, mech.units)}")
    return mech


def _write_extras(stage: Path, args: argparse.Namespace, mech: Any, result: Result, outputs: Any, error: Any) -> None:
    """The files of one run besides results and health, into the staging folder (published together)."""
    if args.plot and len(result):
        from .views.plots import plot_result

        plot_result(mech, result, stage)
    if len(result):
        try:
            _teaching_files(args, mech, result, stage, outputs)
        except VloopError as extra:
            if error is None:
                raise
            print(f"vloop: no extras for the partial run: {extra}", file=sys.stderr)
    forces = _forces(mech, result, stage, args.plot)
    if args.html:
        _view_page(mech, result, stage, str(error) if error else None, forces)


def _forces(mech: Any, result: Result, stage: Path, plot: bool) -> Any:
    """forces.csv (and forces.png) when the file has masses or loads; returns the ForceResult (or None).
    Reactions a redundant linkage leaves undetermined get no column, and a line on stderr says which."""
    forces = _solve_forces(mech, result)
    if forces is None:
        return None
    forces.to_csv(stage / "forces.csv")
    if plot:
        from .views.forces_plot import plot_forces

        plot_forces(mech, forces, stage)
    if forces.message:
        print(f"vloop: {forces.message}: {', '.join(forces.indeterminate)} (no number in forces.csv)", file=sys.stderr)
    return forces


def health_notes(result: Result, redundancy: bool = True) -> list[str]:
    """Lines that say what health.csv flags: redundancy, change points passed, ill-conditioned samples kept."""
    lines = []
    if redundancy and "redundancy" in result.meta:
        lines.append("  " + result.meta["redundancy"])
    for cp in result.meta.get("change_points", []):
        inputs = ", ".join(
            f"{k} = {angle_text(v) if k.startswith('θ_') else f'{v:.10g}'}" for k, v in cp["inputs"].items()
        )
        if cp.get("kind") == "singular":
            lines.append(
                f"  singular configuration passed: loop {cp['loop']} ({cp['label']}) at t = {cp['time']:.10g} s, "
                f"{inputs}: the redundant linkage's only branch goes on; rates there interpolated across it"
            )
            continue
        lines.append(
            f"  change point: loop {cp['loop']} ({cp['label']}) at t = {cp['time']:.10g} s, {inputs}: "
            f"continued on the {'smooth' if cp['continued'] == 'smooth' else 'other (as [solver] change_points asks)'}"
            " branch"
        )
    ill = int(np.sum(result.health.get("ill_conditioned", 0)))
    if ill:
        lines.append(
            f"  {ill} ill-conditioned sample{'s' if ill != 1 else ''} kept (error bound cond³·ε above "
            f"1e-3 of rtol = {result.meta.get('rtol', 1e-9):g}): flagged in health.csv"
        )
    return lines


def _teaching_outputs(args: argparse.Namespace, mech) -> list[str] | None:
    """The --ma outputs, checked before anything is solved (vloop.teaching)."""
    from .teaching.report import parse_outputs

    return parse_outputs(mech, args.ma) if args.ma is not None else None


def _teaching_files(args: argparse.Namespace, mech, result, out: Path, outputs: list[str] | None) -> list[Path]:
    """extras.csv (--extras) and transmission.png (--plot): vloop.teaching."""
    if not (args.extras or args.plot or outputs is not None):
        return []
    from .teaching.report import run_files

    return run_files(mech, result, out, extras=args.extras or outputs is not None, plot=args.plot, outputs=outputs)


def _view_page(mech: Any, result: Any, folder: Path, error: str | None = None, forces: Any = None) -> Path:
    """The viewer page of a run, ``folder/<safe name>.html`` (``vloop view``, ``vloop run --html``)."""
    from .files.output import safe_folder_name
    from .views.view import write_view

    return write_view(mech, result, folder / f"{safe_folder_name(mech.name)}.html", error=error, forces=forces)


# ---------------------------------------------------------------- simulate


def cmd_simulate(args: argparse.Namespace) -> int:
    """Forward dynamics (vloop.dynamics): integrate the file's [dynamics] over its [time] rows, write results,
    health and energy (and plots, the viewer page) as one atomic set; the cycle quantities of a crank, and the
    flywheel for a stated Cs. A motion that reaches a limit stops there: its rows are written, exit 2."""
    from .dynamics import report
    from .dynamics.integrate import simulate
    from .files.output import OutputSet

    mech = _load(args)
    if mech.dynamics is None:
        return _fail(f"{mech.source}: [dynamics] missing: vloop simulate needs the input's loads (docs/dynamics.md)")
    out = _out_folder(args, mech)  # before the integration: a bad --out is one line, no work lost
    error = None
    try:
        sim = simulate(mech)
    except MotionError as exc:
        if exc.partial is None:
            raise
        sim, error = exc.partial, exc
    with OutputSet(out) as files:
        report.write(sim, files.stage, args.format, plot=args.plot, html=args.html, error=str(error) if error else None)
    for line in report.summary_lines(sim):
        print(line)
    print("wrote " + ", ".join(str(f) for f in files.published))
    if error is not None:
        return _fail(f"{error} (wrote {len(sim.result)} rows)")
    return _simulate_cycle(args, mech, sim)


def _simulate_cycle(args: argparse.Namespace, mech: Any, sim: Any) -> int:
    """The cycle quantities of an input that turned fully at least twice; the flywheel when asked."""
    from .dynamics.cycle import cycle, flywheel_for

    if args.flywheel_for is None and len(sim.turns) < 2:
        return 0
    for line in cycle(sim).lines():
        print(line)
    if args.flywheel_for is not None:
        for line in flywheel_for(mech, args.flywheel_for).lines():
            print(line)
    return 0


def _parser_simulate(sub: Any) -> None:
    s = sub.add_parser("simulate", help="forward dynamics: the motion under the file's [dynamics] loads")
    _add_file(s)
    s.add_argument("--out", type=_type("out"), help="output folder (default: out/NAME)")
    s.add_argument("--plot", action="store_true", help="also write links.png, sliders.png, paths.png, energy.png")
    s.add_argument("--html", action="store_true", help="also write the interactive viewer page NAME.html")
    s.add_argument("--format", choices=["csv", "parquet"], default="csv", help="csv (default) or parquet tables")
    s.add_argument(
        "--flywheel-for", type=_type("cs"), metavar="CS",
        help="also size the flywheel on the input that brings the coefficient of speed fluctuation to CS",
    )  # fmt: skip
    s.set_defaults(func=cmd_simulate)


# ---------------------------------------------------------------- view, loops, info


def cmd_view(args: argparse.Namespace) -> int:
    """Solve the file's motion and write one offline HTML page that animates it (exit 2 if it stopped). The page
    is bounded by its bytes: a long run's page carries every k-th sample (and says so)."""
    from .files.output import OutputSet
    from .views.view import solve_for_view

    mech = _load(args)
    with OutputSet(_out_folder(args, mech)) as files:
        result, error = solve_for_view(mech)
        forces = _solve_forces(mech, result)
        _view_page(mech, result, files.stage, error, forces)
    (page,) = files.published
    shown = result.meta.get("page")
    samples = f"{shown['of']} samples (the page carries {len(result)})" if shown else f"{len(result)} samples"
    print(f"{mech.name}: {samples}, t = {result.t[0]:g}..{result.t[-1]:g} s; wrote {page}")
    if args.open:
        import webbrowser

        webbrowser.open(page.resolve().as_uri())
    if error:
        return _fail(f"{error} (the page shows the motion up to its last assembled instant: {page})")
    return 0


def _solve_forces(mech: Any, result: Result) -> Any:
    """The ForceResult when the file has masses or loads (and the run has samples), else None."""
    from .forces import has_forces, solve_forces

    return solve_forces(mech, result) if has_forces(mech) and len(result) else None


def cmd_loops(args: argparse.Namespace) -> int:
    """Print the loop equations as the paper writes them (or LaTeX)."""
    from .compiler import compile_system
    from .method.equations import describe

    print(describe(compile_system(_load(args)), latex=args.latex, exact=args.exact))
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    """Links, joints, sliders, points, drivers; mobility and redundancy; loops, blocks, branches; the motion."""
    from .compiler import compile_system
    from .teaching.report import info_lines

    mech = _load(args)
    system = compile_system(mech)
    for part in (_info_parts(mech), _info_mobility(system), _info_loops(system), _info_motion(system)):
        print("\n".join(part))
    print("\n".join(info_lines(mech)))
    return 0


def _info_parts(mech: Any) -> list[str]:
    bodies = mech.bodies()
    kinds = {1: "guide", 2: "binary", 3: "ternary", 4: "quaternary"}
    lines = [
        f"{mech.name}: {mech.title}" if mech.title else mech.name,
        f"  source: {mech.source}   units: {mech.units}"
        + ("   written from dimensions (coordinates: the t = 0 assembly)" if mech.from_dimensions else ""),
    ]
    lines.append(f"\nlinks ({len(mech.links)}, plus {len(mech.sliders)} slider blocks):")
    for name, lk in mech.links.items():
        kind = "ground" if lk.ground else kinds.get(len(lk.joints), f"{len(lk.joints)}-joint")
        extra = f", length {bodies[name].local[lk.joints[1]][0]:.6g}" if len(lk.joints) == 2 and not lk.ground else ""
        if lk.sides is not None:
            angle = f", angle {lk.angle:.6g} rad" if lk.angle is not None else ""
            extra = f", sides {', '.join(f'{x:.6g}' for x in lk.sides)}{angle}"
        lines.append(f"  {name:12s} {kind:10s} joints {', '.join(lk.joints)}{extra}")
    lines.append(f"\njoints ({len(mech.joints)}):")
    for j, (x, y) in mech.joints.items():
        at, order = mech.bodies_at(j), mech.pin_order(j)
        what = f"pin of order {order} ({', '.join(at)})" if order else f"point of {at[0]}"
        lines.append(f"  {j:8s} ({x:.6g}, {y:.6g})  {what}")
    if mech.sliders:
        lines.append(f"\nsliders ({len(mech.sliders)}):")
        for s in mech.sliders.values():
            inv = " (inverse slider)" if not mech.links[s.guide].ground else ""
            stated = "".join(f", {k} {getattr(s, k):.6g}" for k in ("angle", "offset") if getattr(s, k) is not None)
            lines.append(
                f"  {s.name:8s} joint {s.joint} on {s.guide}{inv}, axis ({s.axis[0]:.6g}, {s.axis[1]:.6g}){stated}"
            )
    if mech.points:
        lines.append(f"\npoints ({len(mech.points)}):")
        lines += [f"  {p.name:8s} on {p.link} at ({p.at[0]:.6g}, {p.at[1]:.6g})" for p in mech.points.values()]
    lines.append("\ndrivers:")
    for d in mech.drivers:
        if d.profile is not None:
            lines.append(f"  {d.symbol}: profile {d.profile.source} ({len(d.profile.t)} rows)")
        else:
            x0 = angle_text(d.x0, 6) if d.kind == "crank" else f"{d.x0:.6g} {mech.units}"
            unit = "rad" if d.kind == "crank" else mech.units
            lines.append(f"  {d.symbol}(t) = {x0} + {d.v0:g}·t + {d.a0:g}·t²/2 [{unit}, t in s]")
    return lines


def _info_mobility(system: Any) -> list[str]:
    from .method.assembly import redundancy_text
    from .method.loops import loop_jacobian

    mech = system.mechanism
    L, J, M = mech.gruebler()
    unk = list(system.unknowns)
    rows = list(range(len(system.loops)))
    rank = int(np.linalg.matrix_rank(loop_jacobian(system, system.q0, rows, unk))) if unk else 0
    full = "full rank: the drivers fix the motion" if rank == len(unk) else "rank deficient"
    lines = [
        f"\nmobility: Gruebler M = 3(L-1) - 2J = 3({L}-1) - 2*{J} = {M}, drivers: {len(mech.drivers)}; "
        f"loop Jacobian at t = 0: rank {rank} of {len(unk)} unknowns ({full})"
    ]
    if "redundancy" in system.assembly:
        lines.append(redundancy_text(system.assembly["redundancy"], system))
    return lines


def _info_loops(system: Any) -> list[str]:
    from .method.branches import dyad_branch
    from .method.equations import grashof

    mech = system.mechanism
    L, J, _ = mech.gruebler()
    lines = [f"loops: {len(system.loops)} (J - L + 1 = {J - L + 1})"]
    lines += [f"  loop {lp.index + 1}: {lp.label}" for lp in system.loops]
    lines.append("solving order: " + " -> ".join(f"{[i + 1 for i in b.loops]} {b.kind}" for b in system.blocks))
    for b in system.blocks:
        if b.kind in ("RRR", "RRP", "RPR"):
            lp = system.loops[b.loops[0]]
            branch = dyad_branch(system, b, system.q0)
            lines.append(
                f"  loop {lp.index + 1} assembly branch at t = 0: sigma = {b.sigma:+.0f}"
                f"{f': {branch.text()}' if branch else ''}"
            )
    for li, cls, (g, p1, c, p2) in grashof(system):
        lines.append(f"four-bar loop {li + 1}: {cls} (ground {g:.6g}, links {p1:.6g}, {c:.6g}, {p2:.6g})")
    return lines


def _info_motion(system: Any) -> list[str]:
    """The time grid; change points and kept ill-conditioned samples (they show only along the motion)."""
    from .core.solver import solve

    mech = system.mechanism
    n = len(mech.times)
    lines = [f"time: {n} samples, t = {mech.times[0]:g}..{mech.times[-1]:g} s"]
    if n <= INFO_SOLVE_LIMIT:
        try:
            notes = health_notes(solve(system), redundancy=False)
        except MotionError as exc:
            notes = [*health_notes(exc.partial, redundancy=False), f"  the motion stops: {exc}"]
        lines += ["motion:", *notes] if notes else ["motion: no change point, no ill-conditioned sample"]
    if system.assembly.get("moved", 0) > 1e-12 * mech.scale:
        lines.append(
            f"t = 0 assembly: joints moved by up to {system.assembly['moved']:.3g} {mech.units} to close the loops"
        )
    return lines


# ---------------------------------------------------------------- validate, corpus (the harness: validators/)


def cmd_validate(args: argparse.Namespace) -> int:
    """Run every engine on the files, compare, write summary.json, the comparison table and the report
    (validators.validate: every input checked first, the outputs published as one set)."""
    from validators.validate import validate

    return validate(args, getattr(args, "started", None))


def cmd_corpus(args: argparse.Namespace) -> int:
    """vloop corpus --n N --seed S --out DIR: generate N mechanism files (and sidecars) of known structure."""
    from validators.validate import corpus_files

    return corpus_files(args)


# ---------------------------------------------------------------- assemble


def cmd_assemble(args: argparse.Namespace) -> int:
    """A file written from dimensions, assembled at t = 0 and written back with closed coordinates (to --out, else
    to standard output); how each dyad's branch was chosen is printed."""
    from .authoring import assemble_mechanism, closed_text
    from .errors import MechanismError
    from .files.dimensions import missing_dimensions
    from .files.fileformat import load
    from .files.output import write_text

    draft = load(args.file, allow_external_profiles=args.allow_external_profiles)
    if not draft.from_dimensions:
        lacks = "; ".join(missing_dimensions(draft.links, draft.sliders, draft.points, {})[:3])
        raise MechanismError(
            f"{args.file}: not written from dimensions ({lacks or 'its centres of mass are given by com'}): its "
            "coordinates are its assembly (vloop info says how far the t = 0 assembly moves them)",
            entry="file",
        )
    closed, report = assemble_mechanism(draft)
    head = f"# {closed.name}: assembled at t = 0 by vloop assemble from {Path(args.file).name}\n"
    source = Path(args.file).read_text(encoding="utf-8")
    first, _, rest = source.partition("\n")
    own = first.startswith(f"# {closed.name}: assembled at t = 0 by vloop assemble from ")  # from an earlier run
    text = head + closed_text(rest if own else source, closed)
    lines = [f"{closed.name}: {line}" for line in report.lines(closed.units)]
    if args.out is None:
        print(text, end="")
        print("\n".join(lines), file=sys.stderr)
        return 0
    write_text(args.out, text)
    print("\n".join([*lines, f"wrote {args.out}"]))
    return 0


# ---------------------------------------------------------------- export


def cmd_export(args: argparse.Namespace) -> int:
    """The mechanism at time --at: a drawing (SVG, PDF) or its links as parts (DXF); or its model for another
    engine at t = 0 (MJCF, an Exudyn or a Pinocchio script). Published as one set."""
    from .files.output import OutputSet
    from .views.export import export, options, time_at

    mech = _load(args)
    if args.format in MODEL_FORMATS:
        return _export_model(args, mech)
    if args.at is None:
        raise VloopError(f"export: --at T (a time in seconds) is needed for --format {args.format}", entry="at")
    at = time_at(mech, args.at)  # before any work: a bad time is one line, nothing written
    given = {k: getattr(args, k) for k in ("pin", "width", "kerf", "dimensions")}
    opts = options(mech, args.format, **given)
    out = _out_folder(args, mech)
    with OutputSet(out) as files:
        export(mech, files.stage, at, args.format, **opts)
    print(f"{mech.name} at t = {at:g} s: wrote " + ", ".join(str(f) for f in files.published))
    return 0


MODEL_FORMATS = ("mjcf", "exudyn", "pinocchio")


def _export_model(args: argparse.Namespace, mech: Any) -> int:
    """--format mjcf|exudyn|pinocchio: the model at t = 0 (validators.models; its engine's package needed)."""
    from validators.models import NEEDS, export

    from .files.output import OutputSet

    module, package = NEEDS[args.format]
    try:
        __import__(module)
    except ImportError:
        message = f"export: --format {args.format} needs {package}: pip install {package}"
        raise VloopError(message, entry="format") from None
    drawing = ("pin", "width", "kerf", "dimensions")
    if args.at is not None or any(getattr(args, k) not in (None, False) for k in drawing):
        raise VloopError(
            f"export: --format {args.format} writes the model at t = 0: --at, --pin, --width, --kerf and "
            "--dimensions are for drawings and parts",
            entry="format",
        )
    with OutputSet(_out_folder(args, mech)) as files:
        export(mech, files.stage, args.format, source=str(args.file))
    print(f"{mech.name}: wrote " + ", ".join(str(f) for f in files.published))
    return 0


# ---------------------------------------------------------------- study


def cmd_study(args: argparse.Namespace) -> int:
    """Run a design study file: every variant solved (in this process, or on Dask), its tables (Parquet or CSV) and
    pictures published as one set in --out. Exit 2 (after writing the tables) when no variant completed."""
    from .files.output import OutputSet, check_folder, default_folder
    from .studies.study import OWNS, run
    from .studies.studyfile import load

    if args.scheduler:
        from .runner import check_scheduler

        check_scheduler(args.scheduler)
    spec = load(args.file)
    out = Path(args.out) if args.out else default_folder(Path(args.file).stem)
    with OutputSet(check_folder(out), owns=OWNS) as outset:
        res = run(spec, scheduler=args.scheduler, workers=args.workers, memory_budget=args.memory_budget)
        res.stage(outset, plot=args.plot, fmt=args.format)
    for line in _study_lines(res):
        print(line)
    print("wrote " + ", ".join(str(f) for f in outset.published))
    if not res.counts["completed"]:
        return _fail(f"{spec.source}: {_none_completed(res)}")
    return 0


def _none_completed(res: Any) -> str:
    """Why a study has no result: no variant completed its motion (the tables give each variant's reason)."""
    c = res.counts
    reasons = [r for r in res.table["reason"] if r]
    first = f"; the first: {reasons[0]}" if reasons else ""
    return (
        f"no variant completed its motion ({c['stopped']:,} stopped, {c['not_assembled']:,} not assembled of "
        f"{c['variants']:,}), so there is no statistic to give{first}"
    )


def _study_lines(res: Any) -> list[str]:
    """The study in a few lines: counts, then per scalar output its nominal, linearized and Monte-Carlo spread,
    in the plots' units (angles in degrees; the tables keep radians). A value that does not exist is said so."""
    from .studies.studyfile import display_unit

    c = res.counts
    lines = [
        f"{res.spec.mechanism.name}: {c['variants']:,} variants ({c['completed']:,} completed, {c['stopped']:,} "
        f"stopped, {c['not_assembled']:,} not assembled; {c['single_runs']:,} solved one by one) in {res.seconds:.2f} s"
    ]
    if not c["completed"]:
        return lines
    outs = {o.name: o for o in res.spec.outputs}
    if any(display_unit(res.spec.mechanism, o)[1].startswith("deg") for o in res.spec.outputs):
        lines.append("  (angles in degrees, as in the plots; the tables keep radians)")
    s = res.summary
    if len(s):
        for _, row in s[s["grid"] == 0].iterrows():
            k, unit = display_unit(res.spec.mechanism, outs[row["output"]])
            lines.append(
                f"  {row['output']} [{unit}]: nominal {_num(row['nominal'], k, '.6g')}, linearized σ "
                f"{_num(row['linearized_sigma'], k, '.4g')}, Monte-Carlo σ {_num(row['mc_sigma'], k, '.4g')} ± "
                f"{_num(row['mc_sigma_error'], k, '.2g')} ({row['completed']:,} of {row['draws']:,} draws completed)"
            )
        return lines
    return lines + _grid_lines(res, outs)


def _num(x: Any, factor: float, spec: str) -> str:
    """A number for the summary in display units; "n/a" where there is none (a missing or non-finite value)."""
    try:
        v = float(x) * factor
    except (TypeError, ValueError, OverflowError):
        return "n/a"
    return format(v, spec) if np.isfinite(v) else "n/a"


def _grid_lines(res: Any, outs: dict) -> list[str]:
    """A grid study's outputs over the completed variants, and the sensitivities at the nominal design."""
    from .studies.studyfile import display_unit

    lines = []
    t = res.table
    for o in res.spec.outputs:
        if o.stat == "class":
            counts = t[o.name].value_counts()
            lines.append(f"  {o.name}: " + ", ".join(f"{n:,} {c}" for c, n in counts.items()))
        elif o.stat not in ("series", "path") and t[o.name].notna().any():
            k, unit = display_unit(res.spec.mechanism, o)
            lo, hi = _num(t[o.name].min(), k, ".6g"), _num(t[o.name].max(), k, ".6g")
            lines.append(f"  {o.name} [{unit}]: {lo} to {hi} over the completed variants")
    sens = res.sensitivity
    for _, row in sens.iterrows() if len(sens) else ():
        d = f"d({row['output']})/d({row['parameter']})"
        lines.append(f"  {d} = {_num(row['derivative'], 1.0, '.4g')} {row['unit']} at the nominal design")
    return lines


class _Parser(argparse.ArgumentParser):
    """argparse with one line on stderr for a bad option (no usage block): ``vloop: error: COMMAND: ...``."""

    def error(self, message: str) -> None:  # type: ignore[override]
        text = " ".join(message.split())
        self.exit(2, f"vloop: error: {self.prog.removeprefix('vloop').strip() or 'vloop'}: {text} (see --help)\n")


def _type(name: str) -> Any:
    """argparse's ``type=`` for an option: its parser in vloop.files.options (the one files and environment use)."""
    from .files.options import OPTIONS

    parse = OPTIONS[name].parse

    def convert(text: str) -> Any:
        try:
            return parse(text)
        except VloopError as exc:
            raise argparse.ArgumentTypeError(str(exc).removeprefix(f"--{name}: ")) from None

    convert.__name__ = name  # argparse names the option's kind by it
    return convert


def _engines(text: str) -> tuple[str, ...]:
    """--engines: a non-empty comma-separated list of the harness's engines."""
    from validators.harness import ENGINES

    from .files.options import choice_list

    try:
        return choice_list(text, "--engines", ENGINES)
    except VloopError as exc:
        raise argparse.ArgumentTypeError(str(exc).removeprefix("--engines: ")) from None


# ---------------------------------------------------------------- synth


def cmd_synth(args: argparse.Namespace) -> int:
    """Synthesize what a synthesis file asks; write the ranked candidates, the best solutions' mechanism files
    and (with --plot, --html) their pictures and viewer pages into --out."""
    from .files.output import check_folder, default_folder
    from .synthesis import load, run, write

    spec = load(args.file)
    out = check_folder(Path(args.out) if args.out else default_folder(spec.name))  # before the search
    res = run(spec, progress=lambda msg: print(f"vloop: {msg}", file=sys.stderr))
    files = write(res, out, files=spec.files, plot=args.plot, html=args.html)
    for line in _synth_lines(res):
        print(line)
    print("wrote " + ", ".join(str(f) for f in files))
    return 0


def _synth_lines(res: Any) -> list[str]:
    """The result in a few lines: how many solutions, then one line per candidate."""
    sols = res.solutions
    lines = [
        f"{res.task.method} generation: {len(res)} candidate{'s' if len(res) != 1 else ''}, {len(sols)} "
        f"solution{'s' if len(sols) != 1 else ''} (no defect), in {res.seconds:.2f} s"
    ]
    if res.note:
        lines.append(f"  ({res.note})")
    for c in res:
        what = "solution" if c.solution else "defective: " + ", ".join(c.defects)
        missed = [k + 1 for k, e in enumerate(c.errors) if not np.isfinite(e)]
        error = f"largest error {c.error:.3g} of {res.task.scale}" if np.isfinite(c.error) else (
            f"position{'s' if len(missed) > 1 else ''} {', '.join(map(str, missed))} not reached"
            if missed else "no error figure"
        )  # fmt: skip
        mu = np.degrees(c.min_transmission)
        lines.append(
            f"  {c.name}: {c.topology}, {error}, Grashof: {c.grashof or '-'}, "
            + (f"min transmission {mu:.1f}°, " if np.isfinite(mu) else "")
            + what
        )
    return lines


def build_parser() -> argparse.ArgumentParser:
    """The command line: one sub-parser per command, each built by its own function."""
    p = _Parser(prog="vloop", description="Kinematics of planar linkages by automatic vector loops.")
    p.add_argument("--version", action="version", version=f"vloop {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    _parser_run(sub)
    _parser_view(sub)
    _parser_studio(sub)
    _parser_loops(sub)
    _parser_validate(sub)
    _parser_corpus(sub)
    _parser_info(sub)
    _parser_study(sub)
    _parser_assemble(sub)
    _parser_export(sub)
    _parser_synth(sub)
    _parser_simulate(sub)
    return p


def _parser_export(sub: Any) -> None:
    e = sub.add_parser(
        "export",
        help="a drawing at time T (SVG, PDF), the links as parts (DXF), or the model for "
        "MuJoCo (MJCF), Exudyn or Pinocchio (a script)",
    )
    _add_file(e)
    e.add_argument("--at", metavar="T", help="the instant [s], within the file's run (drawings and parts)")
    e.add_argument(
        "--format",
        choices=["svg", "pdf", "dxf", *MODEL_FORMATS],
        default="svg",
        help="svg or pdf (drawing), dxf (parts), mjcf (MuJoCo), exudyn or pinocchio (a Python script)",
    )
    e.add_argument("--out", type=_type("out"), help="output folder (default: out/NAME)")
    e.add_argument("--pin", metavar="D", help="dxf: pin (hole) diameter [file units] (default 2 %% of the size)")
    e.add_argument("--width", metavar="W", help="dxf: link width [file units] (default three pin diameters)")
    e.add_argument("--kerf", metavar="K", help="dxf: the cutter's beam width [file units] (default 0)")
    e.add_argument("--dimensions", action="store_true", help="svg, pdf: dimension every link's length")
    e.set_defaults(func=cmd_export)


def _parser_assemble(sub: Any) -> None:
    a = sub.add_parser("assemble", help="assemble a file written from dimensions at t = 0, write it with coordinates")
    _add_file(a)
    a.add_argument(
        "--out", type=_type("out-file"), metavar="FIXED.toml", help="the file to write (default: standard output)"
    )
    a.set_defaults(func=cmd_assemble)


def _parser_run(sub: Any) -> None:
    r = sub.add_parser("run", help="solve P/V/A over the file's time span and write results.csv (and plots)")
    _add_file(r)
    r.add_argument("--out", type=_type("out"), help="output folder (default: out/NAME)")
    r.add_argument("--plot", action="store_true", help="also write links.png, sliders.png, paths.png (and forces.png)")
    r.add_argument(
        "--method", choices=["auto", "newton"], default=None, help="closed-form blocks (auto) or Newton only"
    )
    r.add_argument(
        "--sweep",
        action="store_true",
        help="instead of the file's motion, rock the input between its limit positions (one turn if it has none)",
    )
    r.add_argument(
        "--extras",
        action="store_true",
        help="also write extras.csv: instant centres, transmission angles, velocity ratios, mechanical advantages",
    )
    r.add_argument(
        "--ma",
        metavar="NAMES",
        help="outputs for the velocity ratio and mechanical advantage in extras.csv, comma-separated "
        "(default: every slider and every undriven link pivoted on the ground)",
    )
    r.add_argument("--html", action="store_true", help="also write the interactive viewer page NAME.html")
    r.add_argument(
        "--format",
        choices=["csv", "parquet", "npz"],
        default="csv",
        help="results and health files: csv (default), parquet (needs pyarrow; units in the schema) or npz",
    )
    _add_memory_budget(r, "run")
    r.set_defaults(func=cmd_run)


def _add_memory_budget(p: argparse.ArgumentParser, what: str) -> None:
    p.add_argument(
        "--memory-budget",
        type=_type("memory-budget"),
        default=None,
        help=f"refuse a {what} estimated to need more memory than this (e.g. 2G, 500M; default: env "
        "VLOOP_MEMORY_BUDGET, the mechanism file's [solver] memory_budget, else half the available memory)",
    )


def _parser_view(sub: Any) -> None:
    vw = sub.add_parser("view", help="write one offline HTML page that animates the mechanism (loops, arrows, plots)")
    _add_file(vw)
    vw.add_argument("--out", type=_type("out"), help="output folder (default: out/NAME); the page is NAME.html")
    vw.add_argument("--open", action="store_true", help="open the page in the default web browser")
    vw.set_defaults(func=cmd_view)


def _parser_studio(sub: Any) -> None:
    st = sub.add_parser("studio", help="draw, drag and design a linkage in the browser (a local web app)")
    st.add_argument("target", nargs="?", help="a mechanism file to open, or the folder to work in (default: here)")
    st.add_argument("--port", type=_studio_port, default=0, help="port on 127.0.0.1 (default: a free one)")
    st.add_argument("--no-browser", action="store_true", help="print the address; do not open a browser")
    st.set_defaults(func=cmd_studio)


def _studio_port(text: str) -> int:
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"a port number from 0 to 65535, got {text!r}")
    return port


def cmd_studio(args: argparse.Namespace) -> int:
    """Serve the studio on 127.0.0.1 until Ctrl-C (files only inside the folder it starts on)."""
    from pathlib import Path

    target = Path(args.target) if args.target else Path.cwd()
    if not target.exists():
        return _fail(f"{args.target}: no such file or folder")
    try:
        from .studio.server import serve
    except ImportError as exc:
        return _fail(f"vloop studio needs its extra: pip install 'vloop[studio]' ({exc.name} is missing)")
    try:
        return serve(target, port=args.port, browser=not args.no_browser)
    except ValueError as exc:
        return _fail(str(exc))
    except KeyboardInterrupt:  # Ctrl-C: the server has closed its socket and workers
        print("vloop studio: stopped", file=sys.stderr)
        return 0


def _parser_loops(sub: Any) -> None:
    lo = sub.add_parser("loops", help="print the vector-loop equations as the paper writes them")
    _add_file(lo)
    lo.add_argument("--latex", action="store_true", help="emit LaTeX")
    lo.add_argument(
        "--exact",
        action="store_true",
        help="every number to full precision (the shortest text that reads back to the same double)",
    )
    lo.set_defaults(func=cmd_loops)


def _parser_validate(sub: Any) -> None:
    v = sub.add_parser("validate", help="run every engine on mechanisms, compare, write summary.json and a report")
    v.add_argument("files", nargs="*", type=_type("file"), help="mechanism files or folders of them (or --all)")
    v.add_argument("--all", action="store_true", help="every file in mechanisms/")
    v.add_argument(
        "--engines",
        type=_engines,
        default=("vloop", "analytic", "pinocchio", "exudyn-kinematic", "exudyn-dynamic"),
        help="comma-separated: vloop, analytic, pinocchio, exudyn-kinematic, exudyn-dynamic, mujoco (at least two that "
        "compare: a validation that compares nothing is refused)",
    )
    v.add_argument("--out", type=_type("out"), default="validation", help="output folder (default: validation)")
    v.add_argument("--nightly", action="store_true", help="dated subfolder; compare with the previous run")
    v.add_argument(
        "--previous",
        type=_type("previous"),
        help="summary.json to compare with (default with --nightly: the newest "
        "under --out); checked before anything runs",
    )
    v.add_argument("--no-report", action="store_true", help="summary.json and the comparison table only")
    v.add_argument("--animate", action="store_true", help="add an animated GIF per mechanism to the report")
    v.add_argument(
        "--format", choices=["parquet", "csv"], default="parquet",
        help="the comparison table: comparisons.parquet (default; needs pyarrow) or comparisons.csv (a units row)",
    )  # fmt: skip
    _add_runner_options(v)
    v.add_argument("--corpus", type=_type("corpus"), metavar="N", help="also generate and validate N random mechanisms")
    _add_corpus_options(v)
    v.add_argument(
        "--minimize-tries",
        type=_type("minimize-tries"),
        default=40,
        metavar="T",
        help="shrink each failing generated mechanism with up to T rebuilt files (0: off; default 40)",
    )
    _add_validate_policy(v)
    v.set_defaults(func=cmd_validate)


def _add_validate_policy(v: argparse.ArgumentParser) -> None:
    """validate's exit policy and its resumption (validators/validate.py)."""
    v.add_argument(
        "--strict", action="store_true",
        help="exit 1 on any failed comparison, also one blamed on a reference engine or inconclusive "
        "(default: only when vloop is blamed or a mechanism is undecided)",
    )  # fmt: skip
    v.add_argument(
        "--resume", action="store_true",
        help="continue an interrupted run into the same --out from the comparisons already on disk",
    )  # fmt: skip


def _parser_corpus(sub: Any) -> None:
    c = sub.add_parser("corpus", help="generate random mechanism files of known structure (validation corpus)")
    c.add_argument("--n", type=_type("n"), required=True, help="how many mechanisms")
    c.add_argument("--out", type=_type("out"), help="output folder (default: out/corpus-SEED)")
    _add_corpus_options(c)
    c.set_defaults(func=cmd_corpus)


def _parser_info(sub: Any) -> None:
    i = sub.add_parser("info", help="links, joints, pin orders, mobility, loops, Grashof class")
    _add_file(i)
    i.set_defaults(func=cmd_info)


def _parser_study(sub: Any) -> None:
    st = sub.add_parser("study", help="a design study: grids and tolerances over many variants, with sensitivities")
    st.add_argument("file", type=_type("file"), help="study file (TOML; docs/studies.md)")
    st.add_argument("--out", type=_type("out"), help="output folder (default: out/STUDY)")
    st.add_argument("--plot", action="store_true", help="also write the pictures (bands, histograms, maps)")
    st.add_argument(
        "--format", choices=["parquet", "csv"], default="parquet",
        help="the tables: parquet (default; needs pyarrow) or csv (a units row under the header)",
    )  # fmt: skip
    _add_memory_budget(st, "study")
    _add_where(st, "chunks")
    st.set_defaults(func=cmd_study)


def _parser_synth(sub: Any) -> None:
    sy = sub.add_parser("synth", help="design from motion: function, motion or path generation (a synthesis file)")
    sy.add_argument("file", type=_type("file"), help="synthesis file (TOML; docs/synthesis.md)")
    sy.add_argument("--out", type=_type("out"), help="output folder (default: out/NAME)")
    sy.add_argument("--plot", action="store_true", help="also write the picture (structural error, path or poses)")
    sy.add_argument("--html", action="store_true", help="also write a viewer page per written candidate, targets drawn")
    sy.set_defaults(func=cmd_synth)


def _add_where(p: argparse.ArgumentParser, what: str) -> None:
    """--scheduler ADDRESS | --workers N: where the tasks (validate) or chunks (study) run (vloop.runner)."""
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--scheduler", type=_type("scheduler"), metavar="ADDRESS",
        help=f"run the {what} on this Dask scheduler (tcp://host:8786)",
    )  # fmt: skip
    where.add_argument(
        "--workers", type=_type("workers"), metavar="N", help=f"run the {what} on a local Dask cluster of N processes"
    )


def _add_runner_options(p: argparse.ArgumentParser) -> None:
    _add_where(p, "tasks")
    p.add_argument(
        "--timeout", type=_type("timeout"), default=600.0, metavar="S",
        help="seconds per task before it counts as hung (600)",
    )  # fmt: skip


def _add_corpus_options(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--seed", type=_type("seed"), help="corpus seed (vloop corpus: 0; validate --corpus: a fresh random one)"
    )
    p.add_argument(
        "--start", "--corpus-start", dest="start", type=_type("start"), default=0, help="first mechanism index"
    )
    p.add_argument("--families", help="families or family/variant pairs, e.g. fourbar/kite,watt2 (default: all)")
    p.add_argument(
        "--limit-fraction", type=_type("limit-fraction"), default=0.1,
        help="fraction of runs driven into a limit on purpose (0.1)",
    )  # fmt: skip


def _interrupted() -> int:
    print("vloop: interrupted (nothing half-written was left behind)", file=sys.stderr)
    return 130


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; every failure a user can cause ends in one line on stderr and its exit code."""
    started = time.perf_counter()
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as exc:  # --help, --version, or a bad option (one line already printed)
        return int(exc.code or 0) if not isinstance(exc.code, str) else 2
    except KeyboardInterrupt:  # while an option's parser imported what it checks against
        return _interrupted()
    args.started = started
    try:
        from .files.options import check_environment

        check_environment()
        with np.errstate(all="ignore"):
            return int(args.func(args))
    except VloopError as exc:
        return _fail(str(exc))
    except KeyboardInterrupt:
        return _interrupted()
    except BrokenPipeError:  # the reader went away (vloop ... | head): nothing left to say
        sys.stderr.close()
        return 0
    except MemoryError:
        from .files.budget import out_of_memory

        return _fail(out_of_memory())
    except OSError as exc:  # an output or input the operating system refused, outside vloop's own checks
        from .files.output import describe_os_error

        where = exc.filename if exc.filename is not None else "a file"
        return _fail(f"{where}: {describe_os_error(exc)}")


if __name__ == "__main__":
    sys.exit(main())
