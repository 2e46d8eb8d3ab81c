"""Command line: ``vloop run|loops|info FILE``.

Exit codes: 0 success; 2 bad input or a motion that cannot be completed (one line
on stderr, no traceback; ``run`` still writes every row solved before the failure).
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


def cmd_run(args: argparse.Namespace) -> int:
    from .compiler import compile_system
    from .forces import has_forces, write_forces
    from .mechanism import load
    from .solver import solve

    mech = load(args.file)
    outputs = _teaching_outputs(args, mech)
    out = Path(args.out) if args.out else Path("out") / mech.name
    if args.sweep:
        from .sweep import rocking

        mech = rocking(mech)
        lo, hi = mech.options.get("sweep", (None, None))
        if lo is not None:
            d = mech.drivers[0]
            print(f"{mech.name}: {d.symbol} rocks between its limits {lo:.10g} and {hi:.10g}")
    system = compile_system(mech, args.method)
    try:
        result = solve(system)
    except VloopError as exc:
        partial = exc.partial
        if partial is not None:
            out.mkdir(parents=True, exist_ok=True)
            partial.to_csv(out / "results.csv")
            partial.to_csv(out / "health.csv", health=True)
            if args.plot:
                from .plots import plot_result

                plot_result(mech, partial, out)
            try:
                _teaching_files(args, mech, partial, out, outputs)
            except VloopError as extra:
                print(f"vloop: no extras for the partial run: {extra}", file=sys.stderr)
            page = ""
            if args.html and len(partial):
                page = f" and the viewer page {_view_page(mech, partial, out, str(exc))}"
            if has_forces(mech):
                write_forces(mech, partial, out, plot=args.plot)
            return _fail(f"{exc} (wrote {len(partial)} rows to {out / 'results.csv'}{page})")
        raise
    out.mkdir(parents=True, exist_ok=True)
    result.to_csv(out / "results.csv")
    result.to_csv(out / "health.csv", health=True)
    files = [out / "results.csv", out / "health.csv"]
    if args.plot:
        from .plots import plot_result

        files += plot_result(mech, result, out)
    files += _teaching_files(args, mech, result, out, outputs)
    if has_forces(mech):  # masses or loads: the kinetostatics too
        files += write_forces(mech, result, out, plot=args.plot)
    if args.html:
        files.append(_view_page(mech, result, out))
    asm = system.assembly
    moved = ""
    if asm.get("moved", 0) > 1e-12 * mech.scale:  # more than round-off
        moved = f", t = 0 assembly moved joints by up to {asm['moved']:.3g} {mech.units}"
    print(
        f"{mech.name}: {len(result)} samples, t = {result.t[0]:g}..{result.t[-1]:g} s, "
        f"{len(system.loops)} loop{'s' if len(system.loops) != 1 else ''}, "
        f"max closure {np.max(result.health['residual'], initial=0):.2g}, "
        f"max condition {np.max(result.health['cond'], initial=1):.3g}{moved}"
    )
    for line in health_notes(result):
        print(line)
    print("wrote " + ", ".join(str(f) for f in files))
    return 0


def health_notes(result: Result, redundancy: bool = True) -> list[str]:
    """Lines that say what health.csv flags: change points passed, ill-conditioned samples kept."""
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


def _view_page(mech: Any, result: Any, out: Path, error: str | None = None) -> Path:
    """The viewer page of a run, ``out/<safe name>.html`` (``vloop view``, ``vloop run --html``)."""
    from .output import safe_folder_name
    from .view import write_view

    return write_view(mech, result, out / f"{safe_folder_name(mech.name)}.html", error=error)


def cmd_view(args: argparse.Namespace) -> int:
    """Solve the file's motion and write one offline HTML page that animates it (exit 2 if it stopped)."""
    from .mechanism import load
    from .output import default_folder
    from .view import solve_for_view

    mech = load(args.file)
    result, error = solve_for_view(mech)
    out = Path(args.out) if args.out else default_folder(mech.name)
    page = _view_page(mech, result, out, error)
    print(f"{mech.name}: {len(result)} samples, t = {result.t[0]:g}..{result.t[-1]:g} s; wrote {page}")
    if args.open:
        import webbrowser

        webbrowser.open(page.resolve().as_uri())
    if error:
        return _fail(f"{error} (the page shows the motion up to its last assembled instant: {page})")
    return 0


def cmd_loops(args: argparse.Namespace) -> int:
    from .compiler import compile_system
    from .equations import describe
    from .mechanism import load

    print(describe(compile_system(load(args.file)), latex=args.latex))
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    from .compiler import compile_system
    from .equations import grashof
    from .loops import loop_jacobian
    from .mechanism import load

    mech = load(args.file)
    system = compile_system(mech)
    bodies = mech.bodies()
    L, J, M = mech.gruebler()
    print(f"{mech.name}: {mech.title}" if mech.title else mech.name)
    print(f"  source: {mech.source}   units: {mech.units}")
    print(f"\nlinks ({len(mech.links)}, plus {len(mech.sliders)} slider blocks):")
    for name, lk in mech.links.items():
        b = bodies[name]
        kind = (
            "ground"
            if lk.ground
            else {1: "guide", 2: "binary", 3: "ternary", 4: "quaternary"}.get(len(lk.joints), f"{len(lk.joints)}-joint")
        )
        extra = ""
        if len(lk.joints) == 2 and not lk.ground:
            extra = f", length {b.local[lk.joints[1]][0]:.6g}"
        print(f"  {name:12s} {kind:10s} joints {', '.join(lk.joints)}{extra}")
    print(f"\njoints ({len(mech.joints)}):")
    for j, (x, y) in mech.joints.items():
        at = mech.bodies_at(j)
        order = mech.pin_order(j)
        what = f"pin of order {order} ({', '.join(at)})" if order else f"point of {at[0]}"
        print(f"  {j:8s} ({x:.6g}, {y:.6g})  {what}")
    if mech.sliders:
        print(f"\nsliders ({len(mech.sliders)}):")
        for s in mech.sliders.values():
            inv = " (inverse slider)" if not mech.links[s.guide].ground else ""
            print(f"  {s.name:8s} joint {s.joint} on {s.guide}{inv}, axis ({s.axis[0]:.6g}, {s.axis[1]:.6g})")
    if mech.points:
        print(f"\npoints ({len(mech.points)}):")
        for p in mech.points.values():
            print(f"  {p.name:8s} on {p.link} at ({p.at[0]:.6g}, {p.at[1]:.6g})")
    print("\ndrivers:")
    for d in mech.drivers:
        if d.profile is not None:
            print(f"  {d.symbol}: profile {d.profile.source} ({len(d.profile.t)} rows)")
        else:
            unit = "rad" if d.kind == "crank" else mech.units
            print(f"  {d.symbol}(t) = {d.x0:.6g} + {d.v0:g}·t + {d.a0:g}·t²/2 [{unit}]")
    unk = list(system.unknowns)
    rank = (
        int(np.linalg.matrix_rank(loop_jacobian(system, system.q0, list(range(len(system.loops))), unk))) if unk else 0
    )
    full = "full rank: the drivers fix the motion" if rank == len(unk) else "rank deficient"
    print(
        f"\nmobility: Gruebler M = 3(L-1) - 2J = 3({L}-1) - 2*{J} = {M}, drivers: {len(mech.drivers)}; "
        f"loop Jacobian at t = 0: rank {rank} of {len(unk)} unknowns ({full})"
    )
    if "redundancy" in system.assembly:
        from .assembly import redundancy_text

        print(redundancy_text(system.assembly["redundancy"], system))
    print(f"loops: {len(system.loops)} (J - L + 1 = {J - L + 1})")
    for lp in system.loops:
        print(f"  loop {lp.index + 1}: {lp.label}")
    print("solving order: " + " -> ".join(f"{[i + 1 for i in b.loops]} {b.kind}" for b in system.blocks))
    from .loops import branch_name

    for b in system.blocks:
        if b.kind in ("RRR", "RRP", "RPR"):
            lp = system.loops[b.loops[0]]
            name = branch_name(system, system.q0, lp)
            named = f" ({name})" if name else ""
            print(f"  loop {lp.index + 1} assembly branch at t = 0: sigma = {b.sigma:+.0f}{named}")
    for li, cls, (g, p1, c, p2) in grashof(system):
        print(f"four-bar loop {li + 1}: {cls} (ground {g:.6g}, links {p1:.6g}, {c:.6g}, {p2:.6g})")
    n = len(mech.times)
    print(f"time: {n} samples, t = {mech.times[0]:g}..{mech.times[-1]:g} s")
    if n <= INFO_SOLVE_LIMIT:  # change points and kept ill-conditioned samples show only along the motion
        from .solver import solve

        try:
            notes = health_notes(solve(system), redundancy=False)
        except MotionError as exc:
            notes = [*health_notes(exc.partial, redundancy=False), f"  the motion stops: {exc}"]
        print("\n".join(["motion:", *notes]) if notes else "motion: no change point, no ill-conditioned sample")
    if system.assembly.get("moved", 0) > 1e-12 * mech.scale:
        print(f"t = 0 assembly: joints moved by up to {system.assembly['moved']:.3g} {mech.units} to close the loops")
    from .teaching.report import info_lines

    print("\n".join(info_lines(mech)))
    return 0


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
    r.add_argument("file")
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
    r.set_defaults(func=cmd_run)
    vw = sub.add_parser("view", help="write one offline HTML page that animates the mechanism (loops, arrows, plots)")
    vw.add_argument("file")
    vw.add_argument("--out", help="output folder (default: out/NAME); the page is NAME.html")
    vw.add_argument("--open", action="store_true", help="open the page in the default web browser")
    vw.set_defaults(func=cmd_view)
    lo = sub.add_parser("loops", help="print the vector-loop equations as the paper writes them")
    lo.add_argument("file")
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
    i.add_argument("file")
    i.set_defaults(func=cmd_info)
    return p


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        with np.errstate(all="ignore"):
            return int(args.func(args))
    except VloopError as exc:
        return _fail(str(exc))
    except KeyboardInterrupt:
        return _fail("interrupted")
    except BrokenPipeError:  # the reader went away (vloop ... | head): nothing left to say
        sys.stderr.close()
        return 0


if __name__ == "__main__":
    sys.exit(main())
