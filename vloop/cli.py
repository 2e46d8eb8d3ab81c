"""Command line: ``vloop run | view | loops | info | validate | study``. One function per command.

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
    from .files.fileformat import load

    return load(args.file, allow_external_profiles=getattr(args, "allow_external_profiles", False))


def _out_folder(args: argparse.Namespace, mech: Any) -> Path:
    """--out, else out/<safe name> (a name can never lead outside out/)."""
    from .files.output import default_folder

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
        inputs = ", ".join(f"{k} = {v:.10g}" for k, v in cp["inputs"].items())
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


# ---------------------------------------------------------------- view, loops, info


def cmd_view(args: argparse.Namespace) -> int:
    """Solve the file's motion and write one offline HTML page that animates it (exit 2 if it stopped)."""
    from .files.output import OutputSet
    from .views.view import solve_for_view

    mech = _load(args)
    result, error = solve_for_view(mech)
    out = _out_folder(args, mech)
    with OutputSet(out) as files:
        forces = _solve_forces(mech, result)
        _view_page(mech, result, files.stage, error, forces)
    (page,) = files.published
    print(f"{mech.name}: {len(result)} samples, t = {result.t[0]:g}..{result.t[-1]:g} s; wrote {page}")
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
    from .method.equations import grashof
    from .method.loops import branch_name

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


# ---------------------------------------------------------------- validate


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
    from validators.corpus import FAMILIES

    opts = ""
    if args.families and [f.strip() for f in args.families.split(",")] != list(FAMILIES):
        opts += f" --families {args.families}"
    if args.limit_fraction != 0.1:
        opts += f" --limit-fraction {args.limit_fraction:g}"
    return opts


def _families(args: argparse.Namespace) -> list[str] | None:
    """--families: family or family/variant names (checked by validators.corpus)."""
    from validators.corpus import _catalogue

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
    from validators import corpus

    from .files.output import default_folder

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

    from validators import corpus

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

    from .files.output import ensure_folder, write_text

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


# ---------------------------------------------------------------- study


def cmd_study(args: argparse.Namespace) -> int:
    """Run a design study file: every variant solved (in this process, or on Dask), tables to Parquet in --out."""
    from .files.output import default_folder
    from .studies.study import run
    from .studies.studyfile import load

    spec = load(args.file)
    out = Path(args.out) if args.out else default_folder(Path(args.file).stem)
    res = run(spec, scheduler=args.scheduler, workers=args.workers)
    files = res.write(out, plot=args.plot)
    for line in _study_lines(res):
        print(line)
    print("wrote " + ", ".join(str(f) for f in files))
    return 0


def _study_lines(res: Any) -> list[str]:
    """The study in a few lines: counts, then per scalar output its nominal, linearized and Monte-Carlo spread."""
    c = res.counts
    lines = [
        f"{res.spec.mechanism.name}: {c['variants']:,} variants ({c['completed']:,} completed, {c['stopped']:,} "
        f"stopped, {c['not_assembled']:,} not assembled; {c['single_runs']:,} solved one by one) in {res.seconds:.2f} s"
    ]
    s = res.summary
    if len(s):
        for _, row in s[s["grid"] == 0].iterrows():
            lines.append(
                f"  {row['output']}: nominal {row['nominal']:.6g}, linearized σ {row['linearized_sigma']:.4g}, "
                f"Monte-Carlo σ {row['mc_sigma']:.4g} ± {row['mc_sigma_error']:.2g}"
            )
        return lines
    t = res.table
    for o in res.spec.outputs:
        if o.stat == "class":
            counts = t[o.name].value_counts()
            lines.append(f"  {o.name}: " + ", ".join(f"{n:,} {c}" for c, n in counts.items()))
        elif o.stat not in ("series", "path") and t[o.name].notna().any():
            lines.append(f"  {o.name}: {t[o.name].min():.6g} to {t[o.name].max():.6g} over the completed variants")
    sens = res.sensitivity
    for _, row in sens.iterrows() if len(sens) else ():
        d = f"d({row['output']})/d({row['parameter']})"
        lines.append(f"  {d} = {row['derivative']:.4g} {row['unit']} at the nominal design")
    return lines


def build_parser() -> argparse.ArgumentParser:
    """The command line: one sub-parser per command, each built by its own function."""
    p = argparse.ArgumentParser(prog="vloop", description="Kinematics of planar linkages by automatic vector loops.")
    p.add_argument("--version", action="version", version=f"vloop {__version__}")
    sub = p.add_subparsers(dest="command", required=True)
    _parser_run(sub)
    _parser_view(sub)
    _parser_loops(sub)
    _parser_validate(sub)
    _parser_corpus(sub)
    _parser_info(sub)
    _parser_study(sub)
    return p


def _parser_run(sub: Any) -> None:
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


def _parser_view(sub: Any) -> None:
    vw = sub.add_parser("view", help="write one offline HTML page that animates the mechanism (loops, arrows, plots)")
    _add_file(vw)
    vw.add_argument("--out", help="output folder (default: out/NAME); the page is NAME.html")
    vw.add_argument("--open", action="store_true", help="open the page in the default web browser")
    vw.set_defaults(func=cmd_view)


def _parser_loops(sub: Any) -> None:
    lo = sub.add_parser("loops", help="print the vector-loop equations as the paper writes them")
    _add_file(lo)
    lo.add_argument("--latex", action="store_true", help="emit LaTeX")
    lo.set_defaults(func=cmd_loops)


def _parser_validate(sub: Any) -> None:
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


def _parser_corpus(sub: Any) -> None:
    c = sub.add_parser("corpus", help="generate random mechanism files of known structure (validation corpus)")
    c.add_argument("--n", type=int, required=True, help="how many mechanisms")
    c.add_argument("--out", help="output folder (default: out/corpus-SEED)")
    _add_corpus_options(c)
    c.set_defaults(func=cmd_corpus)


def _parser_info(sub: Any) -> None:
    i = sub.add_parser("info", help="links, joints, pin orders, mobility, loops, Grashof class")
    _add_file(i)
    i.set_defaults(func=cmd_info)


def _parser_study(sub: Any) -> None:
    st = sub.add_parser("study", help="a design study: grids and tolerances over many variants, with sensitivities")
    st.add_argument("file", help="study file (TOML; docs/studies.md)")
    st.add_argument("--out", help="output folder (default: out/STUDY)")
    st.add_argument("--plot", action="store_true", help="also write the pictures (bands, histograms, maps)")
    st.add_argument("--scheduler", metavar="ADDRESS", help="run the chunks on this Dask scheduler (tcp://host:8786)")
    st.add_argument("--workers", type=int, metavar="N", help="run the chunks on a local Dask cluster of N processes")
    st.set_defaults(func=cmd_study)


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
        from .files.budget import out_of_memory

        return _fail(out_of_memory())
    except OSError as exc:  # an output or input the operating system refused, outside vloop's own checks
        from .files.output import describe_os_error

        where = exc.filename if exc.filename is not None else "a file"
        return _fail(f"{where}: {describe_os_error(exc)}")


if __name__ == "__main__":
    sys.exit(main())
