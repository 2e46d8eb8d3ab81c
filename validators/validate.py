"""The harness's commands, ``vloop validate`` and ``vloop corpus`` (the CLI parses their options and calls these).

Every input is checked before any engine runs: the engines (a list that can compare something), the runner (a
scheduler that answers), the previous summary a nightly run compares with (UTF-8 JSON of the summary's shape,
finite numbers), the corpus options and the output folder (writable). Then the corpus is generated, the files
loaded (a bad file is reported in the summary, the others validated), the tasks run, and ``summary.json``,
``comparisons.FMT``, ``report.html`` (with its ``viewer/`` pages), ``corpus.html`` and the minimized failures
written and published together (:class:`vloop.files.output.OutputSet`): Ctrl-C leaves the previous set or the new
one, and no file of the previous set stays beside the new one.

Exit codes: 0 every comparison passed; 1 a comparison failed its tolerance (or a nightly flag was raised);
2 bad input (a file, an option, the previous summary) or nothing to compare.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime as dt
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from vloop.errors import VloopError

from . import harness, nightly
from .tolerances import TOLERANCES

OWNS = ("summary.json", "comparisons.csv", "comparisons.parquet", "report.html", "corpus.html", "viewer", "*-min.*")
MAX_CORPUS_SECTIONS = 20  # generated failures shown in report.html (a broken night must not make 1,000 sections)


def validate(args: argparse.Namespace, started: float | None = None) -> int:
    """``vloop validate``: check every input, run, write and publish one set, print the table; the exit code."""
    from vloop.files.output import OutputSet, ensure_folder

    from . import dynamics_check

    started = time.perf_counter() if started is None else started
    engines = tuple(args.engines)
    _check_runner(args)
    root = Path(args.out)
    out = nightly.dated_folder(root) if args.nightly else root
    previous = _previous(args, root, out)
    families = parse_families(args.families)
    files = _validate_files(args)
    if not files and args.corpus is None:
        raise VloopError("validate: name mechanism files or folders, use --all, or --corpus N", entry="files")
    ensure_folder(root)
    with OutputSet(out, owns=OWNS) as outset:
        corpus_info = None
        if args.corpus is not None:
            generated, corpus_info = _generate(args, families, outset)
            files += generated
        items = harness.load_items(files)
        _check_something_to_compare(items, engines)
        validation = _run(items, engines, args)
        dynamics_ok, dynamics_lines, dynamics = _dynamics(items, engines)
        ran = time.perf_counter()
        summary = _summary(validation, engines, args, corpus_info, previous, outset)
        dynamics_check.add_to_summary(summary, {str(outset.final(p)): e for p, e in dynamics.items()})
        written = _write(validation, summary, outset, args)
    for line in _report_lines(summary, written, ran - started, time.perf_counter() - started):
        print(line)
    for line in dynamics_lines:
        print(line)
    if validation.bad_input:
        return 2
    return 0 if validation.passed and dynamics_ok and not summary.get("nightly", {}).get("flags") else 1


def _dynamics(items: list[Any], engines: tuple[str, ...]) -> tuple[bool, list[str], dict[str, list[dict]]]:
    """The files with a [dynamics] section: vloop.simulate against Exudyn and Pinocchio (validators.dynamics_check),
    those of the two the engines name: whether every comparison passed, the lines to print (one per engine) and
    summary.json's "dynamics" entries by file."""
    from . import dynamics_check

    chosen = tuple(
        name
        for name, wanted in (("exudyn-simulate", "exudyn"), ("pinocchio-simulate", "pinocchio"))
        if any(e.startswith(wanted) for e in engines)
    )
    ok, lines, entries = True, [], {}
    for it in items if chosen else []:
        mech = getattr(it, "mechanism", None)
        if mech is None or mech.dynamics is None or len(mech.drivers) != 1:
            continue
        try:
            rows = dynamics_check.compare(mech, engines=chosen)
        except VloopError as exc:
            lines.append(f"  {mech.name}: dynamics not compared: {exc}")
            entries[it.path] = [{"engine": e, "verdict": "not compared", "message": str(exc)} for e in chosen]
            continue
        ok &= all(r.passed for r in rows)
        lines += dynamics_check.lines(mech.name, rows)
        entries[it.path] = dynamics_check.summary_entries(rows)
    return ok, lines, entries


def _check_runner(args: argparse.Namespace) -> None:
    from vloop.runner import RunnerError, check_scheduler

    if args.scheduler and args.workers:
        raise RunnerError("validate: give --scheduler ADDRESS or --workers N, not both", entry="runner")
    if args.scheduler:
        check_scheduler(args.scheduler)


def _previous(args: argparse.Namespace, root: Path, out: Path) -> tuple[Path | None, dict | None]:
    """The summary to compare with (--previous, or with --nightly the newest under --out), read and checked."""
    if args.previous:
        path = Path(args.previous)
    elif args.nightly:
        path = nightly.previous_summary(root, out)
    else:
        return None, None
    return (path, nightly.load_summary(path)) if path is not None else (None, None)


def _validate_files(args: argparse.Namespace) -> list[Path]:
    """The FILES and DIRs given (a folder: every .toml in it, sorted), plus the catalog with --all."""
    from vloop.pytest_plugin import catalog

    files: list[Path] = []
    for f in map(Path, args.files):
        files += sorted(f.glob("*.toml")) if f.is_dir() else [f]
    if args.all:
        files += catalog()
    return files


def parse_families(text: str | None) -> list[str] | None:
    """--families: family or family/variant names, comma-separated (checked against validators.corpus)."""
    from .corpus import _catalogue

    if text is None:
        return None
    fams = [f.strip() for f in text.split(",") if f.strip()]
    try:
        _catalogue(fams or [""])
    except ValueError as exc:
        raise VloopError(f"--families: {exc}", entry="families") from None
    return fams


def corpus_options(args: argparse.Namespace) -> str:
    """The generator options that differ from the defaults (a reproduce command must repeat them)."""
    from .corpus import FAMILIES

    opts = ""
    if args.families and [f.strip() for f in args.families.split(",")] != list(FAMILIES):
        opts += f" --families {args.families}"
    if args.limit_fraction != 0.1:
        opts += f" --limit-fraction {args.limit_fraction:g}"
    return opts


def _generate(args: argparse.Namespace, families: list[str] | None, outset: Any) -> tuple[list[Path], dict]:
    """--corpus N: a fresh corpus inside the output set; its seed (drawn if not given) goes to the summary."""
    import secrets

    from . import corpus

    seed = args.seed if args.seed is not None else secrets.randbelow(2**31)
    folder = outset.path(f"corpus-{seed}")
    items, refused = corpus.generate(
        args.corpus, seed, start=args.start, families=families, limit_fraction=args.limit_fraction
    )
    corpus.write(items, folder, seed=seed, refused=refused, start=args.start, limit_fraction=args.limit_fraction)
    info = {
        "seed": seed,
        "n": len(items),
        "start": args.start,
        "folder": str(outset.final(folder)),
        "command": nightly.corpus_command(seed, len(items), args.start, corpus_options(args)),
    }
    return [folder / f"{it.name}.toml" for it in items], info


def _check_something_to_compare(items: list[Any], engines: tuple[str, ...]) -> None:
    """Refuse a validation that would validate nothing: no pair of the engines has a tolerance on any file (and no
    file is a generated one, whose sidecar's expectations every engine is checked against)."""
    for it in items:
        if it.error or (it.corpus and "expect" in it.corpus):
            return
        applies = [e for e in engines if harness.engine_applies(e, it.mechanism)]
        if any((a, b) in TOLERANCES for a in applies for b in applies if b in harness.REFERENCES):
            return
    raise VloopError(
        f"validate: nothing to compare: --engines {','.join(engines)} makes no comparison on "
        f"{'this file' if len(items) == 1 else f'these {len(items)} files'} (every comparison is of an engine against "
        "vloop or analytic, and analytic needs a closed form: e.g. --engines vloop,pinocchio)",
        entry="engines",
    )


def _run(items: list[Any], engines: tuple[str, ...], args: argparse.Namespace) -> Any:
    bar = sys.stderr.isatty()

    def progress(msg: str) -> None:
        if not bar:
            print(msg, file=sys.stderr, flush=True)

    return harness.run(
        [it.path for it in items],
        engines,
        progress=progress,
        scheduler=args.scheduler,
        workers=args.workers,
        timeout=args.timeout,
        bar=bar,
        items=items,
    )


def _summary(
    validation: Any,
    engines: tuple[str, ...],
    args: argparse.Namespace,
    corpus_info: dict | None,
    previous: tuple[Path | None, dict | None],
    outset: Any,
) -> dict:
    """summary.json's structure, with every path as it will be once published (not the staging folder's)."""
    for it in validation.items:
        it.path = str(outset.final(it.path))
    summary = harness.to_summary(validation)
    if "corpus" in summary:
        _corpus_failures(summary, validation, engines, args, corpus_info, outset)
    path, before = previous
    if args.nightly or args.previous:
        flags = nightly.compare_summaries(summary, before) if before is not None else []
        summary["nightly"] = {
            "date": dt.date.today().isoformat(),
            "previous": str(path) if path else None,
            "flags": flags,
        }
    return _published(summary, str(outset.stage), str(outset.folder))


def _published(obj: Any, stage: str, folder: str) -> Any:
    """``obj`` with the staging folder's path replaced by the output folder's in every string."""
    if isinstance(obj, str):
        return obj.replace(stage, folder)
    if isinstance(obj, dict):
        return {k: _published(v, stage, folder) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_published(v, stage, folder) for v in obj]
    return obj


def _corpus_failures(
    summary: dict, validation: Any, engines: tuple[str, ...], args: argparse.Namespace, info: dict | None, outset: Any
) -> None:
    """summary["corpus"]: how to regenerate it, each failure's reproduce command, the minimized failures."""
    failures = nightly.corpus_failures(summary, engines, corpus_options(args))
    summary["corpus"].update(info or {}, failures=failures)
    if failures and args.minimize_tries > 0:
        summary["corpus"]["minimized"] = nightly.minimize_failures(
            validation.items, engines, outset.stage, max_tries=args.minimize_tries
        )


def _write(validation: Any, summary: dict, outset: Any, args: argparse.Namespace) -> list[str]:
    """summary.json, comparisons.FMT, report.html and corpus.html into the output set; the names written."""
    from vloop.files.output import write_text

    write_text(outset.path("summary.json"), json.dumps(summary, indent=1, allow_nan=False))
    names = ["summary.json"]
    try:
        harness.write_table(summary, outset.path(f"comparisons.{args.format}"), args.format)
        names.append(f"comparisons.{args.format}")
    except VloopError as exc:
        if "pyarrow" not in str(exc):
            raise
        print(f"vloop: no comparisons.parquet ({exc})", file=sys.stderr)
    if args.no_report:
        return names
    return names + _write_pages(validation, summary, outset.stage, args.animate)


def _write_pages(validation: Any, summary: dict, stage: Path, animate: bool) -> list[str]:
    """report.html (the catalog and the generated files that fail) and corpus.html."""
    try:
        from reports.html import write_report
    except ImportError as exc:  # the report needs Jinja2; the summary does not
        print(f"vloop: no report ({exc})", file=sys.stderr)
        return []
    names = []
    shown = [it for it in validation.items if it.corpus is None or not it.passed]
    generated_failures = [it for it in shown if it.corpus is not None]
    if len(generated_failures) > MAX_CORPUS_SECTIONS:
        drop = {id(it) for it in generated_failures[MAX_CORPUS_SECTIONS:]}
        shown = [it for it in shown if id(it) not in drop]
    if shown:
        write_report(dataclasses.replace(validation, items=shown), summary, stage, animate=animate)
        names.append("report.html")
    if "corpus" in summary:
        from reports.corpus import write_corpus_page

        write_corpus_page(summary, stage)
        names.append("corpus.html")
    return names


def _report_lines(summary: dict, written: list[str], engines_seconds: float, seconds: float) -> list[str]:
    """The table, the flags and failures, what was written, and the verdict with the whole command's time."""
    lines = [_table(summary, "corpus.html" in written)]
    lines += [f"FLAG {f['message']}" for f in summary.get("nightly", {}).get("flags", [])]
    for f in summary.get("corpus", {}).get("failures", []):
        lines.append(f"FAIL {f['mechanism']}: reproduce with: {f['reproduce']}")
    for m in summary.get("corpus", {}).get("minimized", []):
        if m.get("file"):
            lines.append(
                f"minimized {m['mechanism']} in {m['tries']} tries: {m['file']} (still fails: {m['still_failing']})"
            )
    lines.append("wrote " + ", ".join(written))
    verdict = "all passed" if summary["passed"] else "FAILED"
    lines.append(
        f"{verdict} in {seconds:.1f} s (engines {summary['seconds']:.1f} s; summary, tables and pages "
        f"{max(seconds - engines_seconds, 0.0):.1f} s)"
    )
    return lines


def _worst_text(m: dict, engine: str) -> str:
    """An engine's cell of the table: its worst error as a fraction of what is allowed, or what happened. An engine
    not blamed is shown against the engines not blamed (its disagreement with a blamed one is that one's)."""
    run = m.get("runs", {}).get(engine)
    verdict = m.get("verdict") or {}
    own = verdict.get("engines", {}).get(engine)
    blamed = set() if own == "blamed" else set(verdict.get("blamed") or ())
    comps = [c for c in m.get("comparisons", []) if c["engine"] == engine and c.get("reference") not in blamed]
    if run is None or run["status"] == "skipped":
        return "-"
    if run["status"] == "error":
        return "ERROR"
    ratios = [
        (c["worst"]["max_abs"] if isinstance(c["worst"]["max_abs"], int | float) else float("inf"))
        / max(c["worst"]["allowed"], 1e-300)
        for c in comps
        if c["worst"]
    ]
    worst = max(ratios, default=0.0)
    mark = {"blamed": " FAIL", "undecided": " ?"}.get(own or "", "")
    if own is None and not all(c["passed"] for c in comps):
        mark = " FAIL"
    return (f"{worst:.1e} of tol" if worst < float("inf") else "not finite") + mark


def _table(summary: dict, corpus_page: bool) -> str:
    """One line per mechanism: each engine's worst error as a fraction of what is allowed."""
    engines = [e for e in summary["engines"] if e != "vloop"]
    head = f"{'mechanism':32s} " + " ".join(f"{e:>17s}" for e in engines) + "  result"
    lines = [head, "-" * len(head)]
    generated = [m for m in summary["mechanisms"] if m.get("corpus")]
    for m in summary["mechanisms"]:
        if m.get("corpus") and m["passed"] and len(generated) > 30:
            continue  # a big corpus: one line per failure here, the rest in corpus.html
        cells = [_worst_text(m, e) for e in engines]
        verdict = "error: " + m["error"][:60] if m.get("error") else ("pass" if m["passed"] else _blame(m))
        lines.append(f"{m['name'][:32]:32s} " + " ".join(f"{c:>17s}" for c in cells) + f"  {verdict}")
    if generated:
        ok = sum(1 for m in generated if m["passed"])
        where = " (per family: corpus.html)" if corpus_page else ""
        lines.append(f"generated corpus: {ok} of {len(generated)} mechanisms pass{where}")
    odd = (summary.get("verdicts") or {}).get("vloop_blamed") or []
    if odd:
        lines.append(f"VLOOP IS THE ODD ONE OUT on {len(odd)} mechanisms: {', '.join(odd[:10])}")
    return "\n".join(lines)


def _blame(m: dict) -> str:
    """FAIL, with the engine the consensus blames (or "undecided")."""
    v = m.get("verdict") or {}
    if v.get("status") == "blamed":
        return f"FAIL: blamed on {', '.join(v['blamed'])}"
    return "FAIL: undecided" if v.get("status") == "undecided" else "FAIL"


# ---------------------------------------------------------------- vloop corpus


def corpus_files(args: argparse.Namespace, say: Callable[[str], None] = print) -> int:
    """``vloop corpus --n N --seed S --out DIR``: N mechanism files (and sidecars) of known structure, one set."""
    from vloop.files.output import OutputSet, default_folder

    from . import corpus

    families = parse_families(args.families)
    seed = args.seed if args.seed is not None else 0
    out = Path(args.out) if args.out else default_folder(f"corpus-{seed}")
    with OutputSet(out) as outset:
        items, refused = corpus.generate(
            args.n, seed, start=args.start, families=families, limit_fraction=args.limit_fraction
        )
        settings = {"start": args.start, "families": families, "limit_fraction": args.limit_fraction}
        corpus.write(items, outset.stage, seed=seed, refused=refused, **settings)
    limits = sum(1 for it in items if it.sidecar["expect"]["stop_sample"] is not None)
    say(
        f"wrote {len(items)} mechanisms (seed {seed}, indices {args.start}..{args.start + len(items) - 1}; "
        f"{limits} run into a limit on purpose) to {out}"
    )
    if refused:
        say(f"note: vloop refused {len(refused)} drawn mechanisms (listed in {out / 'corpus.json'})")
    return 0
