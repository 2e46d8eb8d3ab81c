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
from .errors import VloopError


def _fail(msg: str) -> int:
    print(f"vloop: error: {msg}", file=sys.stderr)
    return 2


def cmd_run(args: argparse.Namespace) -> int:
    from .loops import compile_system
    from .mechanism import load
    from .solver import solve

    mech = load(args.file)
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
            return _fail(f"{exc} (wrote {len(partial)} rows to {out / 'results.csv'})")
        raise
    out.mkdir(parents=True, exist_ok=True)
    result.to_csv(out / "results.csv")
    result.to_csv(out / "health.csv", health=True)
    files = [out / "results.csv", out / "health.csv"]
    if args.plot:
        from .plots import plot_result

        files += plot_result(mech, result, out)
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
    print("wrote " + ", ".join(str(f) for f in files))
    return 0


def cmd_loops(args: argparse.Namespace) -> int:
    from .equations import describe
    from .loops import compile_system
    from .mechanism import load

    print(describe(compile_system(load(args.file)), latex=args.latex))
    return 0


def cmd_info(args: argparse.Namespace) -> int:
    from .equations import grashof
    from .loops import compile_system, loop_jacobian
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
    if system.assembly.get("moved", 0) > 1e-12 * mech.scale:
        print(f"t = 0 assembly: joints moved by up to {system.assembly['moved']:.3g} {mech.units} to close the loops")
    return 0


def _validate_files(args: argparse.Namespace) -> list[Path]:
    """The FILES and DIRs given (a folder: every .toml in it, sorted), plus the catalog with --all."""
    from .pytest_plugin import catalog

    files: list[Path] = []
    for f in map(Path, args.files):
        files += sorted(f.glob("*.toml")) if f.is_dir() else [f]
    if args.all:
        files += catalog()
    return files


def _corpus_options(args: argparse.Namespace) -> str:
    """The generator options that differ from the defaults (a reproduce command must repeat them)."""
    from .corpus import FAMILIES

    opts = ""
    if args.families and [f.strip() for f in args.families.split(",")] != list(FAMILIES):
        opts += f" --families {args.families}"
    if args.limit_fraction != 0.1:
        opts += f" --limit-fraction {args.limit_fraction:g}"
    return opts


def _families(args: argparse.Namespace) -> list[str] | None:
    """--families: family or family/variant names (checked by vloop.corpus)."""
    from .corpus import _catalogue

    if args.families is None:
        return None
    fams = [f.strip() for f in args.families.split(",") if f.strip()]
    try:
        _catalogue(fams or [""])
    except ValueError as exc:
        raise VloopError(str(exc), entry="families") from None
    return fams


def _check_corpus_args(args: argparse.Namespace, n: int) -> None:
    if not 1 <= n <= 1_000_000:
        raise VloopError(f"--n/--corpus must be between 1 and 1000000, got {n}", entry="n")
    if args.seed is not None and not 0 <= args.seed < 2**63:
        raise VloopError(f"--seed must be a non-negative integer below 2**63, got {args.seed}", entry="seed")
    if not 0 <= args.start < 10**8:
        raise VloopError(f"--start must be between 0 and 10**8, got {args.start}", entry="start")
    if not (0.0 <= args.limit_fraction <= 1.0):
        raise VloopError(f"--limit-fraction must be between 0 and 1, got {args.limit_fraction}", entry="limit-fraction")


def cmd_corpus(args: argparse.Namespace) -> int:
    """vloop corpus --n N --seed S --out DIR: generate N mechanism files (and sidecars) of known structure."""
    from . import corpus
    from .output import default_folder

    _check_corpus_args(args, args.n)
    seed = args.seed if args.seed is not None else 0
    out = Path(args.out) if args.out else default_folder(f"corpus-{seed}")
    items, refused = corpus.generate(
        args.n, seed, start=args.start, families=_families(args), limit_fraction=args.limit_fraction
    )
    settings = {"start": args.start, "families": _families(args), "limit_fraction": args.limit_fraction}
    corpus.write(items, out, seed=seed, refused=refused, **settings)
    limits = sum(1 for it in items if it.sidecar["expect"]["stop_sample"] is not None)
    print(
        f"wrote {len(items)} mechanisms (seed {seed}, indices {args.start}..{args.start + len(items) - 1}; "
        f"{limits} run into a limit on purpose) to {out}"
    )
    if refused:
        print(f"note: vloop refused {len(refused)} drawn mechanisms (listed in {out / 'corpus.json'})")
    return 0


def _generate_for_validate(args: argparse.Namespace, out: Path) -> tuple[list[Path], dict]:
    """--corpus N: a fresh corpus inside the output folder; its seed (drawn if not given) goes to the summary."""
    import secrets

    from . import corpus

    _check_corpus_args(args, args.corpus)
    seed = args.seed if args.seed is not None else secrets.randbelow(2**31)
    folder = out / f"corpus-{seed}"
    items, refused = corpus.generate(
        args.corpus, seed, start=args.start, families=_families(args), limit_fraction=args.limit_fraction
    )
    corpus.write(items, folder, seed=seed, refused=refused, start=args.start, limit_fraction=args.limit_fraction)
    from validators.nightly import corpus_command

    info = {
        "seed": seed,
        "n": len(items),
        "start": args.start,
        "folder": str(folder),
        "command": corpus_command(seed, len(items), args.start, _corpus_options(args)),
    }
    return [folder / f"{it.name}.toml" for it in items], info


def cmd_validate(args: argparse.Namespace) -> int:
    import datetime as dt
    import json

    from validators import harness, nightly

    from .output import ensure_folder, write_text

    engines = tuple(e.strip() for e in args.engines.split(",") if e.strip())
    unknown = [e for e in engines if e not in harness.ENGINES]
    if unknown:
        return _fail(f"validate: unknown engine {', '.join(unknown)} (known: {', '.join(harness.ENGINES)})")
    if args.scheduler and args.workers:
        return _fail("validate: give --scheduler ADDRESS or --workers N, not both")
    root = Path(args.out)
    out = ensure_folder(nightly.dated_folder(root) if args.nightly else root)
    files = _validate_files(args)
    corpus_info = None
    if args.corpus is not None:
        generated, corpus_info = _generate_for_validate(args, out)
        files += generated
    if not files:
        return _fail("validate: name mechanism files or folders, use --all, or --corpus N")
    bar = sys.stderr.isatty()

    def progress(msg: str) -> None:
        if not bar:
            print(msg, file=sys.stderr, flush=True)

    validation = harness.run(
        files,
        engines,
        progress=progress,
        scheduler=args.scheduler,
        workers=args.workers,
        timeout=args.timeout,
        bar=bar,
    )
    summary = harness.to_summary(validation)
    if "corpus" in summary:
        _corpus_failures(summary, validation, engines, args, corpus_info, out)
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
    written = [write_text(out / "summary.json", json.dumps(summary, indent=1, allow_nan=False))]
    written += _write_tables_and_pages(validation, summary, out, args)
    print(_table(summary))
    for f in flags:
        print(f"FLAG {f['message']}")
    _print_corpus_failures(summary)
    print("wrote " + ", ".join(str(w) for w in written))
    if validation.bad_input:
        return 2
    return 0 if validation.passed and not flags else 1


def _corpus_failures(
    summary: dict, validation: Any, engines: tuple[str, ...], args: argparse.Namespace, info: dict | None, out: Path
) -> None:
    """summary["corpus"]: how to regenerate it, each failure's reproduce command, the minimized failures."""
    from validators import nightly

    failures = nightly.corpus_failures(summary, engines, _corpus_options(args))
    summary["corpus"].update(info or {}, failures=failures)
    if failures and args.minimize_tries > 0:
        summary["corpus"]["minimized"] = nightly.minimize_failures(
            validation.items, engines, out, max_tries=args.minimize_tries
        )


def _print_corpus_failures(summary: dict) -> None:
    for f in summary.get("corpus", {}).get("failures", []):
        print(f"FAIL {f['mechanism']}: reproduce with: {f['reproduce']}")
    for m in summary.get("corpus", {}).get("minimized", []):
        if m.get("file"):
            print(f"minimized {m['mechanism']} in {m['tries']} tries: {m['file']} (still fails: {m['still_failing']})")


def _write_tables_and_pages(validation: Any, summary: dict, out: Path, args: argparse.Namespace) -> list[Path]:
    """comparisons.parquet (when pyarrow is there), report.html (catalog + failing generated files), corpus.html."""
    from validators import harness

    written: list[Path] = []
    try:
        written.append(harness.write_parquet(summary, out / "comparisons.parquet"))
    except VloopError as exc:
        if "pyarrow" not in str(exc):
            raise
        print(f"vloop: no comparisons.parquet ({exc})", file=sys.stderr)
    if args.no_report:
        return written
    try:
        from reports.html import write_report
    except ImportError as exc:  # the report needs Jinja2; the summary does not
        print(f"vloop: no report ({exc})", file=sys.stderr)
        return written
    shown = [it for it in validation.items if it.corpus is None or not it.passed]
    generated_failures = [it for it in shown if it.corpus is not None]
    if len(generated_failures) > MAX_CORPUS_SECTIONS:  # a broken night must not make a 1,000-section report
        drop = {id(it) for it in generated_failures[MAX_CORPUS_SECTIONS:]}
        shown = [it for it in shown if id(it) not in drop]
    if shown:
        import dataclasses

        written.append(write_report(dataclasses.replace(validation, items=shown), summary, out, animate=args.animate))
    if "corpus" in summary:
        from reports.corpus import write_corpus_page

        written.append(write_corpus_page(summary, out))
    return written


MAX_CORPUS_SECTIONS = 20


def _table(summary: dict) -> str:
    """One line per mechanism: each engine's worst error as a fraction of what is allowed."""
    engines = [e for e in summary["engines"] if e != "vloop"]
    head = f"{'mechanism':32s} " + " ".join(f"{e:>17s}" for e in engines) + "  result"
    lines = [head, "-" * len(head)]
    generated = [m for m in summary["mechanisms"] if m.get("corpus")]
    for m in summary["mechanisms"]:
        if m.get("corpus") and m["passed"] and len(generated) > 30:
            continue  # a big corpus: one line per failure here, the rest in corpus.html
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
    if generated:
        ok = sum(1 for m in generated if m["passed"])
        lines.append(f"generated corpus: {ok} of {len(generated)} mechanisms pass (per family: corpus.html)")
    lines.append(f"{'all passed' if summary['passed'] else 'FAILED'} in {summary['seconds']:.1f} s")
    return "\n".join(lines)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="vloop", description="Kinematics of planar linkages by automatic vector loops.")
    p.add_argument("--version", action="version", version=f"vloop {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    r = sub.add_parser("run", help="solve P/V/A over the file's time span and write results.csv (and plots)")
    r.add_argument("file")
    r.add_argument("--out", help="output folder (default: out/NAME)")
    r.add_argument("--plot", action="store_true", help="also write links.png, sliders.png, paths.png")
    r.add_argument(
        "--method", choices=["auto", "newton"], default=None, help="closed-form blocks (auto) or Newton only"
    )
    r.add_argument(
        "--sweep",
        action="store_true",
        help="instead of the file's motion, rock the input between its limit positions (one turn if it has none)",
    )
    r.set_defaults(func=cmd_run)
    lo = sub.add_parser("loops", help="print the vector-loop equations as the paper writes them")
    lo.add_argument("file")
    lo.add_argument("--latex", action="store_true", help="emit LaTeX")
    lo.set_defaults(func=cmd_loops)
    v = sub.add_parser("validate", help="run every engine on mechanisms, compare, write summary.json and a report")
    v.add_argument("files", nargs="*", help="mechanism files or folders of them (or --all)")
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
    _add_runner_options(v)
    v.add_argument("--corpus", type=int, metavar="N", help="also generate and validate N random mechanisms")
    _add_corpus_options(v)
    v.add_argument(
        "--minimize-tries",
        type=int,
        default=40,
        metavar="T",
        help="shrink each failing generated mechanism with up to T rebuilt files (0: off; default 40)",
    )
    v.set_defaults(func=cmd_validate)
    c = sub.add_parser("corpus", help="generate random mechanism files of known structure (validation corpus)")
    c.add_argument("--n", type=int, required=True, help="how many mechanisms")
    c.add_argument("--out", help="output folder (default: out/corpus-SEED)")
    _add_corpus_options(c)
    c.set_defaults(func=cmd_corpus)
    i = sub.add_parser("info", help="links, joints, pin orders, mobility, loops, Grashof class")
    i.add_argument("file")
    i.set_defaults(func=cmd_info)
    return p


def _add_runner_options(p: argparse.ArgumentParser) -> None:
    where = p.add_mutually_exclusive_group()
    where.add_argument("--scheduler", metavar="ADDRESS", help="run the tasks on this Dask scheduler (tcp://host:8786)")
    where.add_argument("--workers", type=int, metavar="N", help="run the tasks on a local Dask cluster of N processes")
    p.add_argument(
        "--timeout", type=float, default=600.0, metavar="S", help="seconds per task before it counts as hung (600)"
    )


def _add_corpus_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=int, help="corpus seed (vloop corpus: 0; validate --corpus: a fresh random one)")
    p.add_argument("--start", "--corpus-start", dest="start", type=int, default=0, help="first mechanism index")
    p.add_argument("--families", help="families or family/variant pairs, e.g. fourbar/kite,watt2 (default: all)")
    p.add_argument(
        "--limit-fraction", type=float, default=0.1, help="fraction of runs driven into a limit on purpose (0.1)"
    )


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
