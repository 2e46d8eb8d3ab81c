"""Command line: ``vloop run | view | loops | info | validate``. One function per command.

Exit codes: 0 success; 1 a validation that fails its tolerances; 2 bad input, an output that cannot be
written, or a motion that cannot be completed (one line on stderr, no traceback; ``run`` still writes
every row solved before the failure); 130 interrupted (Ctrl-C: nothing half-written is left behind).
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from . import __version__
from .errors import MotionError, VloopError
from .result import Result

INFO_SOLVE_LIMIT = 200_000  # vloop info solves the file's motion up to this many samples


def _fail(msg: str) -> int:
    print(f"vloop: error: {msg}", file=sys.stderr)
    return 2


# ---------------------------------------------------------------- shared option handling


def _load(args: argparse.Namespace) -> Any:
    """The mechanism file named on the command line (profiles outside its folder only if allowed)."""
    from .fileformat import load

    return load(args.file, allow_external_profiles=getattr(args, "allow_external_profiles", False))


def _out_folder(args: argparse.Namespace, mech: Any) -> Path:
    """--out, else out/<safe name> (a name can never lead outside out/)."""
    from .output import default_folder

    return Path(args.out) if args.out else default_folder(mech.name)


def _add_file(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="mechanism file (TOML)")
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
    """Stream the run's chunks into results.FMT / health.FMT (vloop.writers) inside one OutputSet, then the
    extras from the whole run when asked. Returns (summary, published files, the MotionError that stopped it)."""
    from . import budget, writers
    from .forces import has_forces
    from .output import OutputSet
    from .progress import Progress
    from .solver import CHUNK_ROWS, join, solve_iter

    keep = bool(args.plot or args.html or args.extras or outputs is not None or has_forces(mech))
    n = len(mech.times)
    budget.check(system, n, not keep, CHUNK_ROWS, args.memory_budget)
    with OutputSet(out) as files:
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
        print(f"{mech.name}: {mech.drivers[0].symbol} rocks between its limits {lo:.10g} and {hi:.10g}")
    return mech


def _write_extras(stage: Path, args: argparse.Namespace, mech: Any, result: Result, outputs: Any, error: Any) -> None:
    """The files of one run besides results and health, into the staging folder (published together)."""
    if args.plot and len(result):
        from .plots import plot_result

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
    from .forces import has_forces, solve_forces

    if not has_forces(mech) or not len(result):
        return None
    forces = solve_forces(mech, result)
    forces.to_csv(stage / "forces.csv")
    if plot:
        from .forces_plot import plot_forces

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
        inputs = ", ".join(f"{k} = {v:.10g}" for k, v in cp["inputs"].items())
        lines.append(
            f"  change point: loop {cp['loop']} ({cp['label']}) at t = {cp['time']:.10g} s, {inputs}: "
            f"continued on the {'smooth' if cp['continued'] == 'smooth' else 'other (as [solver] change_points asks)'}"
            " branch"
        )
    ill = int(np.sum(result.health.get("ill_conditioned", 0)))
    if ill:
        lines.append(
            f"  {ill} ill-conditioned sample{'s' if ill != 1 else ''} kept (error bound cond²·ε above "
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
    from .output import safe_folder_name
    from .view import write_view

    return write_view(mech, result, folder / f"{safe_folder_name(mech.name)}.html", error=error, forces=forces)


# ---------------------------------------------------------------- view, loops, info


def cmd_view(args: argparse.Namespace) -> int:
    """Solve the file's motion and write one offline HTML page that animates it (exit 2 if it stopped)."""
    from .output import OutputSet
    from .view import solve_for_view

    mech = _load(args)
    result, error = solve_for_view(mech)
    out = _out_folder(args, mech)
    with OutputSet(out) as files:
        forces = _forces_quiet(mech, result)
        _view_page(mech, result, files.stage, error, forces)
    (page,) = files.published
    print(f"{mech.name}: {len(result)} samples, t = {result.t[0]:g}..{result.t[-1]:g} s; wrote {page}")
    if args.open:
        import webbrowser

        webbrowser.open(page.resolve().as_uri())
    if error:
        return _fail(f"{error} (the page shows the motion up to its last assembled instant: {page})")
    return 0


def _forces_quiet(mech: Any, result: Result) -> Any:
    from .forces import has_forces, solve_forces

    return solve_forces(mech, result) if has_forces(mech) and len(result) else None


def cmd_loops(args: argparse.Namespace) -> int:
    """Print the loop equations as the paper writes them (or LaTeX)."""
    from .compiler import compile_system
    from .equations import describe

    print(describe(compile_system(_load(args)), latex=args.latex))
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
        f"  source: {mech.source}   units: {mech.units}",
    ]
    lines.append(f"\nlinks ({len(mech.links)}, plus {len(mech.sliders)} slider blocks):")
    for name, lk in mech.links.items():
        kind = "ground" if lk.ground else kinds.get(len(lk.joints), f"{len(lk.joints)}-joint")
        extra = f", length {bodies[name].local[lk.joints[1]][0]:.6g}" if len(lk.joints) == 2 and not lk.ground else ""
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
            lines.append(f"  {s.name:8s} joint {s.joint} on {s.guide}{inv}, axis ({s.axis[0]:.6g}, {s.axis[1]:.6g})")
    if mech.points:
        lines.append(f"\npoints ({len(mech.points)}):")
        lines += [f"  {p.name:8s} on {p.link} at ({p.at[0]:.6g}, {p.at[1]:.6g})" for p in mech.points.values()]
    lines.append("\ndrivers:")
    for d in mech.drivers:
        if d.profile is not None:
            lines.append(f"  {d.symbol}: profile {d.profile.source} ({len(d.profile.t)} rows)")
        else:
            unit = "rad" if d.kind == "crank" else mech.units
            lines.append(f"  {d.symbol}(t) = {d.x0:.6g} + {d.v0:g}·t + {d.a0:g}·t²/2 [{unit}]")
    return lines


def _info_mobility(system: Any) -> list[str]:
    from .assembly import redundancy_text
    from .loops import loop_jacobian

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
    from .equations import grashof
    from .loops import branch_name

    mech = system.mechanism
    L, J, _ = mech.gruebler()
    lines = [f"loops: {len(system.loops)} (J - L + 1 = {J - L + 1})"]
    lines += [f"  loop {lp.index + 1}: {lp.label}" for lp in system.loops]
    lines.append("solving order: " + " -> ".join(f"{[i + 1 for i in b.loops]} {b.kind}" for b in system.blocks))
    for b in system.blocks:
        if b.kind in ("RRR", "RRP", "RPR"):
            lp = system.loops[b.loops[0]]
            name = branch_name(system, system.q0, lp)
            lines.append(
                f"  loop {lp.index + 1} assembly branch at t = 0: sigma = {b.sigma:+.0f}{f' ({name})' if name else ''}"
            )
    for li, cls, (g, p1, c, p2) in grashof(system):
        lines.append(f"four-bar loop {li + 1}: {cls} (ground {g:.6g}, links {p1:.6g}, {c:.6g}, {p2:.6g})")
    return lines


def _info_motion(system: Any) -> list[str]:
    """The time grid; change points and kept ill-conditioned samples (they show only along the motion)."""
    from .solver import solve

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


# ---------------------------------------------------------------- validate


def cmd_validate(args: argparse.Namespace) -> int:
    import datetime as dt
    import json

    from validators import harness, nightly

    from .pytest_plugin import catalog

    files = [Path(f) for f in args.files]
    if args.all:
        files += catalog()
    if not files:
        return _fail("validate: name mechanism files or use --all")
    engines = tuple(e.strip() for e in args.engines.split(",") if e.strip())
    unknown = [e for e in engines if e not in harness.ENGINES]
    if unknown:
        return _fail(f"validate: unknown engine {', '.join(unknown)} (known: {', '.join(harness.ENGINES)})")
    root = Path(args.out)
    out = nightly.dated_folder(root) if args.nightly else root

    def progress(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    validation = harness.run(files, engines, progress=progress)
    summary = harness.to_summary(validation)
    flags: list[dict] = []
    if args.nightly:
        prev = Path(args.previous) if args.previous else nightly.previous_summary(root, out)
        if prev is not None:
            flags = nightly.compare_summaries(summary, nightly.load_summary(prev))
        summary["nightly"] = {
            "date": dt.date.today().isoformat(),
            "previous": str(prev) if prev else None,
            "flags": flags,
        }
    out.mkdir(parents=True, exist_ok=True)
    (out / "summary.json").write_text(json.dumps(summary, indent=1, allow_nan=False), encoding="utf-8")
    written = [out / "summary.json"]
    if not args.no_report:
        try:
            from reports.html import write_report
        except ImportError as exc:  # the report needs Jinja2; the summary does not
            print(f"vloop: no report ({exc})", file=sys.stderr)
        else:
            written.append(write_report(validation, summary, out, animate=args.animate))
    print(_table(summary))
    for f in flags:
        print(f"FLAG {f['message']}")
    print("wrote " + ", ".join(str(w) for w in written))
    if validation.bad_input:
        return 2
    return 0 if validation.passed and not flags else 1


def _table(summary: dict) -> str:
    """One line per mechanism: each engine's worst error as a fraction of what is allowed."""
    engines = [e for e in summary["engines"] if e != "vloop"]
    head = f"{'mechanism':32s} " + " ".join(f"{e:>17s}" for e in engines) + "  result"
    lines = [head, "-" * len(head)]
    for m in summary["mechanisms"]:
        cells = []
        for e in engines:
            run = m.get("runs", {}).get(e)
            comps = [c for c in m.get("comparisons", []) if c["engine"] == e]
            if run is None or run["status"] == "skipped":
                cells.append("-")
            elif run["status"] == "error":
                cells.append("ERROR")
            else:
                worst = max(
                    (
                        (c["worst"]["max_abs"] if isinstance(c["worst"]["max_abs"], float) else float("inf"))
                        / max(c["worst"]["allowed"], 1e-300)
                        for c in comps
                        if c["worst"]
                    ),
                    default=0.0,
                )
                mark = "" if all(c["passed"] for c in comps) else " FAIL"
                cells.append(f"{worst:.1e} of tol{mark}")
        verdict = "error: " + m["error"][:60] if m.get("error") else ("pass" if m["passed"] else "FAIL")
        lines.append(f"{m['name'][:32]:32s} " + " ".join(f"{c:>17s}" for c in cells) + f"  {verdict}")
    lines.append(f"{'all passed' if summary['passed'] else 'FAILED'} in {summary['seconds']:.1f} s")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vloop", description="Kinematics of planar linkages by automatic vector loops.")
    p.add_argument("--version", action="version", version=f"vloop {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="solve P/V/A over the file's time span and write results.csv (and plots)")
    _add_file(r)
    r.add_argument("--out", help="output folder (default: out/NAME)")
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
    r.add_argument(
        "--memory-budget",
        default=None,
        help="refuse a run estimated to need more memory than this (e.g. 2G, 500M; default: env "
        "VLOOP_MEMORY_BUDGET, the file's [solver] memory_budget, else half the available memory)",
    )
    r.set_defaults(func=cmd_run)
    vw = sub.add_parser("view", help="write one offline HTML page that animates the mechanism (loops, arrows, plots)")
    _add_file(vw)
    vw.add_argument("--out", help="output folder (default: out/NAME); the page is NAME.html")
    vw.add_argument("--open", action="store_true", help="open the page in the default web browser")
    vw.set_defaults(func=cmd_view)
    lo = sub.add_parser("loops", help="print the vector-loop equations as the paper writes them")
    _add_file(lo)
    lo.add_argument("--latex", action="store_true", help="emit LaTeX")
    lo.set_defaults(func=cmd_loops)
    v = sub.add_parser("validate", help="run every engine on mechanisms, compare, write summary.json and a report")
    v.add_argument("files", nargs="*", help="mechanism files (or --all)")
    v.add_argument("--all", action="store_true", help="every file in mechanisms/")
    v.add_argument(
        "--engines",
        default="vloop,analytic,pinocchio,exudyn-kinematic,exudyn-dynamic",
        help="comma-separated: vloop, analytic, pinocchio, exudyn-kinematic, exudyn-dynamic",
    )
    v.add_argument("--out", default="validation", help="output folder (default: validation)")
    v.add_argument("--nightly", action="store_true", help="dated subfolder; compare with the previous run")
    v.add_argument("--previous", help="summary.json to compare with (default: the newest under --out)")
    v.add_argument("--no-report", action="store_true", help="summary.json only")
    v.add_argument("--animate", action="store_true", help="add an animated GIF per mechanism to the report")
    v.set_defaults(func=cmd_validate)
    i = sub.add_parser("info", help="links, joints, pin orders, mobility, loops, Grashof class")
    _add_file(i)
    i.set_defaults(func=cmd_info)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; every failure a user can cause ends in one line on stderr and its exit code."""
    args = build_parser().parse_args(argv)
    try:
        with np.errstate(all="ignore"):
            return int(args.func(args))
    except VloopError as exc:
        return _fail(str(exc))
    except KeyboardInterrupt:
        print("vloop: interrupted (nothing half-written was left behind)", file=sys.stderr)
        return 130
    except BrokenPipeError:  # the reader went away (vloop ... | head): nothing left to say
        sys.stderr.close()
        return 0
    except MemoryError:
        from .budget import out_of_memory

        return _fail(out_of_memory())
    except OSError as exc:  # an output or input the operating system refused, outside vloop's own checks
        from .output import describe_os_error

        where = exc.filename if exc.filename is not None else "a file"
        return _fail(f"{where}: {describe_os_error(exc)}")


if __name__ == "__main__":
    sys.exit(main())
