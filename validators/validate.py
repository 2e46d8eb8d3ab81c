"""The harness's commands, ``vloop validate`` and ``vloop corpus`` (the CLI parses their options and calls these).

Every input is checked before any engine runs: the engines (a list that can compare something), the runner (a
scheduler that answers), the previous summary a nightly run compares with (UTF-8 JSON of the summary's shape,
finite numbers), the corpus options and the output folder (writable). Then the corpus is generated, the files
loaded by the workers (a bad file is reported in the summary, the others validated), one task per mechanism run,
each writing its comparisons to the dataset ``comparisons/`` (validators.dataset), and ``summary.json``,
``comparisons.FMT`` (streamed from the dataset: validators.streamed), ``report.html`` (with its ``viewer/`` pages),
``corpus.html``, the nightly's ``trend.json`` and ``history.html`` and the minimized failures written and published
together (:class:`vloop.files.output.OutputSet`): Ctrl-C leaves the previous set or the new one, and no file of the
previous set stays beside the new one. The run in progress (its identity and the dataset) is kept in
``OUT/.vloop-run`` until it is published: ``--resume`` continues it after Ctrl-C, a SIGKILL or a restart.

Exit codes (docs/validation.md, "Exit status"): 1 when vloop may be wrong — vloop blamed by the consensus, a
mechanism undecided, or a nightly flag that may be vloop's; 0 otherwise, also when a reference engine is blamed by
engines that agree with vloop or is inconclusive (reported in the table, the summary and the pages), unless
``--strict`` (then any failed comparison or flag is 1); 2 bad input (a file, an option, the previous summary) or
nothing to compare.
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

OWNS = ("summary.json", "comparisons.csv", "comparisons.parquet", "comparisons", "report.html", "corpus.html", "viewer")
OWNS += ("*-min.*", "trend.json", "history.html")
MAX_CORPUS_SECTIONS = 20  # generated failures shown in report.html (a broken night must not make 1,000 sections)


def validate(args: argparse.Namespace, started: float | None = None) -> int:
    """``vloop validate``: check every input, run, write and publish one set, print the table; the exit code."""
    import shutil

    from vloop.files.output import OutputSet, ensure_folder

    started = time.perf_counter() if started is None else started
    engines = tuple(args.engines)
    _check_runner(args)
    root = Path(args.out)
    out = _out_folder(args, root)
    previous = _previous(args, root, out)
    families = parse_families(args.families)
    files = _validate_files(args)
    if not files and args.corpus is None:
        raise VloopError("validate: name mechanism files or folders, use --all, or --corpus N", entry="files")
    ensure_folder(out)
    work = _work(out, args, engines, files)
    with OutputSet(out, owns=OWNS) as outset:
        corpus_info = None
        if args.corpus is not None:
            generated, corpus_info = _generate(args, families, outset)
            files += generated
        _check_something_to_compare(files, engines)
        validation = _run(files, engines, args, work)
        dynamics_ok, dynamics_lines, dynamics = _dynamics(files, engines)
        ran = time.perf_counter()
        summary = _summary(validation, args, corpus_info, previous, outset, work, dynamics)
        written = _write(validation, summary, outset, args, work)
    shutil.rmtree(work, ignore_errors=True)
    for line in _report_lines(summary, written, ran - started, time.perf_counter() - started):
        print(line)
    for line in dynamics_lines:
        print(line)
    if validation.bad_input or any(m.get("error") for m in summary["mechanisms"]):
        return 2
    return max(exit_status(summary, getattr(args, "strict", False)), 0 if dynamics_ok else 1)


def exit_status(summary: dict, strict: bool = False) -> int:
    """1 when vloop may be wrong (a red mechanism, a red nightly flag); with ``strict`` also any failed comparison
    or flag; else 0."""
    flags = summary.get("nightly", {}).get("flags") or []
    if summary.get("red") or any(f.get("red", True) for f in flags):
        return 1
    return 1 if strict and (not summary["passed"] or flags) else 0


def _dynamics(files: list[Path], engines: tuple[str, ...]) -> tuple[bool, list[str], dict[str, list[dict]]]:
    """The files with a [dynamics] section: vloop.simulate against Exudyn and Pinocchio (validators.dynamics_check),
    those of the two the engines name: whether every comparison passed, the lines to print (one per engine) and
    summary.json's "dynamics" entries by file (as given). Each such file is read here on its own, so the run's
    memory stays that of one mechanism."""
    from . import dynamics_check

    chosen = tuple(
        name
        for name, wanted in (("exudyn-simulate", "exudyn"), ("pinocchio-simulate", "pinocchio"))
        if any(e.startswith(wanted) for e in engines)
    )
    ok, lines, entries = True, [], {}
    for path in files if chosen else []:
        mech = _with_dynamics(path)
        if mech is None:
            continue
        try:
            rows = dynamics_check.compare(mech, engines=chosen)
        except VloopError as exc:
            lines.append(f"  {mech.name}: dynamics not compared: {exc}")
            entries[str(path)] = [{"engine": e, "verdict": "not compared", "message": str(exc)} for e in chosen]
            continue
        ok &= all(r.passed for r in rows)
        lines += dynamics_check.lines(mech.name, rows)
        entries[str(path)] = dynamics_check.summary_entries(rows)
    return ok, lines, entries


def _with_dynamics(path: Path) -> Any:
    """The file's Mechanism where it has a one-input [dynamics] section (a cheap look at its text first), else None."""
    import vloop

    try:
        if "dynamics" not in Path(path).read_text(encoding="utf-8"):
            return None
        mech = vloop.load(path)
    except (OSError, UnicodeDecodeError, VloopError):
        return None  # the kinematic comparison reports an unreadable file
    return mech if mech.dynamics is not None and len(mech.drivers) == 1 else None


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
    """--corpus N: a fresh corpus inside the output set, written as it is drawn; its seed goes to the summary."""
    from . import corpus

    seed = args.seed
    folder = outset.path(f"corpus-{seed}")
    files = corpus.generate_into(
        folder, args.corpus, seed, start=args.start, families=families, limit_fraction=args.limit_fraction
    )
    info = {
        "seed": seed,
        "n": len(files),
        "start": args.start,
        "folder": str(outset.final(folder)),
        "command": nightly.corpus_command(seed, len(files), args.start, corpus_options(args)),
    }
    return files, info


def _check_something_to_compare(files: list[Path], engines: tuple[str, ...]) -> None:
    """Refuse a validation that would validate nothing: no pair of the engines has a tolerance on any file (and no
    file is a generated one, whose sidecar's expectations every engine is checked against). Files are read one at a
    time until one answers."""
    for path in files:
        (it,) = harness.load_items([path])
        if it.error or (it.corpus and "expect" in it.corpus):
            return
        applies = [e for e in engines if harness.engine_applies(e, it.mechanism)]
        if any((a, b) in TOLERANCES for a in applies for b in applies if b in harness.REFERENCES):
            return
    raise VloopError(
        f"validate: nothing to compare: --engines {','.join(engines)} makes no comparison on "
        f"{'this file' if len(files) == 1 else f'these {len(files)} files'} (every comparison is of an engine against "
        "vloop or analytic, and analytic needs a closed form: e.g. --engines vloop,pinocchio)",
        entry="engines",
    )


# ---------------------------------------------------------------- the run in progress: resumable from disk

WORK = ".vloop-run"  # in the output folder while a run is in progress; kept when it is interrupted
DATASET = "comparisons"  # the comparison dataset's folder (validators.dataset), published with the set


def _out_folder(args: argparse.Namespace, root: Path) -> Path:
    """--out, or with --nightly a new dated folder under it — with --resume the newest one an interrupted run left."""
    if not args.nightly:
        return root
    if getattr(args, "resume", False) and root.is_dir():
        left = sorted((p for p in root.iterdir() if (p / WORK / "run.json").is_file()), key=lambda p: p.name)
        if left:
            return left[-1]
    return nightly.dated_folder(root)


def _identity(args: argparse.Namespace, engines: tuple[str, ...], files: list[Path]) -> dict[str, Any]:
    """What makes two runs the same run (a resumed one must be): engines, files, the corpus's parameters."""
    corpus = None
    if args.corpus is not None:
        corpus = {
            "n": args.corpus,
            "seed": args.seed,
            "start": args.start,
            "families": args.families,
            "limit_fraction": args.limit_fraction,
        }
    return {"engines": list(engines), "files": [str(Path(f).resolve()) for f in files], "corpus": corpus}


def _work(out: Path, args: argparse.Namespace, engines: tuple[str, ...], files: list[Path]) -> Path:
    """The run's work folder, out/.vloop-run: its identity (run.json) and the comparisons done so far. --resume
    continues the one there (refused if it is another run: other engines, files or corpus); otherwise a run left
    there is discarded and a fresh one started. A corpus without --seed draws one here (a resumed run reuses it)."""
    import secrets
    import shutil

    work = out / WORK
    stored = _stored(work)
    resume = getattr(args, "resume", False)
    if args.corpus is not None and args.seed is None:
        have = (stored or {}).get("corpus") or {}
        args.seed = have.get("seed") if resume and have.get("seed") is not None else secrets.randbelow(2**31)
    ident = _identity(args, engines, files)
    if stored is not None and resume:
        if stored != ident:
            diff = ", ".join(k for k in ident if ident[k] != stored.get(k))
            raise VloopError(
                f"--resume: the interrupted run in {out} is another run (its {diff} differ); "
                "repeat its options, or leave out --resume to start again",
                entry="resume",
            )
        return work
    if stored is not None or work.exists():
        print(f"vloop: discarding the interrupted run in {work} (--resume continues it)", file=sys.stderr)
        shutil.rmtree(work, ignore_errors=True)
    elif resume:
        print(f"vloop: --resume: no interrupted run in {out}; starting one", file=sys.stderr)
    (work / DATASET).mkdir(parents=True, exist_ok=True)
    from vloop.files.output import write_text

    write_text(work / "run.json", json.dumps(ident, indent=1))
    return work


def _stored(work: Path) -> dict[str, Any] | None:
    try:
        return json.loads((work / "run.json").read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None


def _run(files: list[Path], engines: tuple[str, ...], args: argparse.Namespace, work: Path) -> Any:
    """Every file one task; the comparisons to work/comparisons; the tasks already there skipped."""
    from . import dataset

    bar = sys.stderr.isatty()

    def progress(msg: str) -> None:
        if not bar:
            print(msg, file=sys.stderr, flush=True)

    done = dataset.done(work / DATASET)
    if done:
        print(f"vloop: resuming: {len(done)} of {len(files)} mechanisms already validated", file=sys.stderr)
    try:
        return harness.run(
            files,
            engines,
            progress=progress,
            scheduler=args.scheduler,
            workers=args.workers,
            timeout=args.timeout,
            bar=bar,
            dataset=work / DATASET,
            skip=done,
            shown=MAX_CORPUS_SECTIONS,
        )
    except KeyboardInterrupt:  # what is on disk stays there: say how to go on from it
        kept = len(dataset.done(work / DATASET))
        print(
            f"vloop: {kept} of {len(files)} mechanisms validated are kept in {work}; the same command with "
            "--resume continues from them",
            file=sys.stderr,
        )
        raise


def _summary(
    validation: Any,
    args: argparse.Namespace,
    corpus_info: dict | None,
    previous: tuple[Path | None, dict | None],
    outset: Any,
    work: Path,
    dynamics: dict[str, list[dict]] | None = None,
) -> dict:
    """summary.json and the comparison table, streamed from the dataset in task order (validators.streamed), with
    every path as it will be once published; the summary as the table and pages read it (the mechanisms shown)."""
    from . import dataset, dynamics_check, streamed

    for it in validation.items:
        it.path = streamed.unstaged(str(outset.final(it.path)), str(outset.folder))
    path, before = previous
    figures = trend = None
    if args.corpus is not None and not args.no_report:
        from reports.corpus import CorpusFigures

        figures = CorpusFigures(list(validation.engines))
    if args.nightly:
        from reports.history import Accumulator

        trend = Accumulator(validation.engines)
    head = harness.summary_head(validation)
    night = streamed.Night(head, str(outset.folder), before, corpus_options(args), (figures, trend))
    done = dataset.done(work / DATASET)
    table = outset.path(f"comparisons.{args.format}")
    for k in sorted(done):
        entry = dataset.read_entry(done[k])
        night.add(dynamics_check.attach(entry, (dynamics or {}).get(entry.get("file"))))
        if len(night.rows) >= streamed.TABLE_BLOCK:
            night.block(outset.stage, args.format)
    extra: dict[str, Any] = {"runner": validation.runner}
    if corpus_info is not None:
        extra["corpus"] = corpus_info
    if args.nightly or args.previous:
        extra["nightly"] = {"date": dt.date.today().isoformat(), "previous": str(path) if path else None}
    if night.failures and args.minimize_tries > 0 and corpus_info is not None:
        done_ = nightly.minimize_failures(
            validation.items, validation.engines, outset.stage, max_tries=args.minimize_tries
        )
        extra["corpus"]["minimized"] = json.loads(streamed.unstaged(json.dumps(done_), str(outset.folder)))
    summary = night.finish(outset.path("summary.json"), table, args.format, extra)
    summary["_figures"] = figures
    if trend is not None:  # the night's figures for the history page (reports.history)
        summary["_trend"] = trend.figures(summary, outset.folder.name)
    return summary


def _write(validation: Any, summary: dict, outset: Any, args: argparse.Namespace, work: Path) -> list[str]:
    """The dataset moved into the set; report.html and corpus.html; the names written (summary.json and the table
    are written already)."""
    import os

    for tmp in (work / DATASET).glob("family=*/.*.tmp"):  # a worker killed while it wrote: its file never appeared
        tmp.unlink()
    os.replace(work / DATASET, outset.path(DATASET))
    names = ["summary.json", f"comparisons.{args.format}", f"{DATASET}/"]
    figures, trend = summary.pop("_figures", None), summary.pop("_trend", None)
    if trend is not None:
        from reports.history import write_history, write_trend

        write_trend(trend, outset.stage)
        names.append("trend.json")
        if not args.no_report:
            write_history(Path(args.out), outset.stage, trend)
            names.append("history.html")
    if args.no_report:
        return names
    return names + _write_pages(validation, summary, outset.stage, args.animate, figures)


def _write_pages(validation: Any, summary: dict, stage: Path, animate: bool, figures: Any) -> list[str]:
    """report.html (the files that are not generated, and the generated ones that fail) and corpus.html."""
    from vloop.files.output import interrupts_held

    try:
        with interrupts_held():  # a Ctrl-C inside a compiled module's import (matplotlib's) leaves it half made
            from reports.html import write_report
    except ImportError as exc:  # the report needs Jinja2; the summary does not
        print(f"vloop: no report ({exc})", file=sys.stderr)
        return []
    names = []
    shown = [it for it in validation.items if it.corpus is None or not it.passed]
    if shown:
        write_report(dataclasses.replace(validation, items=shown), summary, stage, animate=animate)
        names.append("report.html")
    if "corpus" in summary:
        from reports.corpus import write_corpus_page

        write_corpus_page(summary, stage, figures)
        names.append("corpus.html")
    return names


def _report_lines(summary: dict, written: list[str], engines_seconds: float, seconds: float) -> list[str]:
    """The table, the flags and failures, what was written, and the verdict with the whole command's time."""
    lines = [_table(summary, "corpus.html" in written)]
    lines += [
        f"FLAG {f['message']}" + ("" if f.get("red", True) else " (not vloop's)")
        for f in summary.get("nightly", {}).get("flags", [])
    ]
    for f in summary.get("corpus", {}).get("failures", []):
        lines.append(f"FAIL {f['mechanism']}: reproduce with: {f['reproduce']}")
    for m in summary.get("corpus", {}).get("minimized", []):
        if m.get("file"):
            lines.append(
                f"minimized {m['mechanism']} in {m['tries']} tries: {m['file']} (still fails: {m['still_failing']})"
            )
    lines.append("wrote " + ", ".join(written))
    lines.append(
        f"{verdict_text(summary)} in {seconds:.1f} s (engines {summary['seconds']:.1f} s; summary, tables "
        f"and pages {max(seconds - engines_seconds, 0.0):.1f} s)"
    )
    return lines


def verdict_text(summary: dict) -> str:
    """The night in one phrase: RED (vloop may be wrong), passed with reference engines' failures, or all passed."""
    v = summary.get("verdicts") or {}
    red = v.get("red") or []
    counts = v.get("mechanisms") or {}
    if summary.get("red"):
        if not red:
            return "RED: a nightly flag may be vloop's"
        odd = len(v.get("vloop_blamed") or [])
        n = (summary.get("counts") or {}).get("mechanisms", len(summary["mechanisms"]))
        return f"RED: vloop blamed on {odd}, undecided on {counts.get('undecided', 0)} of {n} mechanisms"
    if summary["passed"]:
        return "all passed"
    tally = v.get("engines") or {}
    parts = [f"{k} {sum(t.get(k, 0) for t in tally.values())}" for k in ("blamed", "inconclusive")]
    others = ", ".join(p for p in parts if not p.endswith(" 0")) or "flags raised"
    return f"vloop passed; reference engines: {others} (not red; --strict makes it red)"


CELL = 16  # the engines' columns of the printed table


def _worst_text(m: dict, engine: str) -> str:
    """An engine's cell of the table: its worst error as a fraction of what is allowed, then its verdict when that
    is not a pass (blamed, ? undecided, n/c inconclusive); an engine not blamed is shown against the engines not
    blamed (its disagreement with a blamed one is that one's)."""
    run = m.get("runs", {}).get(engine)
    verdict = m.get("verdict") or {}
    own = verdict.get("engines", {}).get(engine)
    blamed = set() if own == "blamed" else set(verdict.get("blamed") or ())
    blamed |= set(verdict.get("inconclusive") or ()) - {engine}
    comps = [c for c in m.get("comparisons", []) if c["engine"] == engine and c.get("reference") not in blamed]
    if run is None or run["status"] == "skipped":
        return "-"
    if run["status"] == "error":
        return "error"
    ratios = [
        (c["worst"]["max_abs"] if isinstance(c["worst"]["max_abs"], int | float) else float("inf"))
        / max(c["worst"]["allowed"], 1e-300)
        for c in comps
        if c["worst"]
    ]
    worst = max(ratios, default=0.0)
    mark = {"blamed": " blamed", "undecided": " ?", "inconclusive": " n/c"}.get(own or "", "")
    if own is None and not all(c["passed"] for c in comps):
        mark = " fail"
    return (f"{worst:.1e}" if worst < float("inf") else "not finite") + mark


def _table(summary: dict, corpus_page: bool) -> str:
    """One line per mechanism (a big corpus: its failures only): each engine's worst error over its allowance, then
    the mechanism's verdict once; under it the counts over every mechanism and per engine."""
    engines = [e for e in summary["engines"] if e != "vloop"]
    head = f"{'mechanism':32s} " + " ".join(f"{e[:CELL]:>{CELL}s}" for e in engines) + "  verdict"
    lines = ["worst error / allowed per engine (blamed, ? undecided, n/c inconclusive)", head, "-" * len(head)]
    generated = (summary.get("corpus") or {}).get("mechanisms") or sum(
        1 for m in summary["mechanisms"] if m.get("corpus")
    )
    for m in summary["mechanisms"]:
        if m.get("corpus") and m["passed"] and generated > 30:
            continue  # a big corpus: one line per failure here, the rest in corpus.html
        cells = [_worst_text(m, e) for e in engines]
        verdict = "error: " + m["error"][:60] if m.get("error") else _outcome(m)
        lines.append(f"{m['name'][:32]:32s} " + " ".join(f"{c:>{CELL}s}" for c in cells) + f"  {verdict}")
    mechs = summary["mechanisms"]
    counts = summary.get("counts") or {"mechanisms": len(mechs), "passed": sum(1 for m in mechs if m["passed"])}
    where = " (per family: corpus.html)" if corpus_page else ""
    lines.append(f"{counts['passed']} of {counts['mechanisms']} mechanisms pass every comparison{where}")
    tally = (summary.get("verdicts") or {}).get("engines") or {}
    for e in summary["engines"]:
        t = tally.get(e)
        if t and (t.get("blamed") or t.get("undecided") or t.get("inconclusive")):
            lines.append(
                f"  {e}: blamed on {t.get('blamed', 0)}, undecided on {t.get('undecided', 0)}, "
                f"inconclusive on {t.get('inconclusive', 0)}"
            )
    odd = (summary.get("verdicts") or {}).get("vloop_blamed") or []
    if odd:
        lines.append(f"VLOOP IS THE ODD ONE OUT on {len(odd)} mechanisms: {', '.join(odd[:10])}")
    return "\n".join(lines)


def _outcome(m: dict) -> str:
    """The mechanism's verdict, said once: pass, VLOOP BLAMED, blamed on a reference engine, undecided, inconclusive
    (each with the engines that could not resolve it)."""
    v = m.get("verdict") or {}
    unsure = ", ".join(v.get("inconclusive") or ())
    tail = f"; inconclusive: {unsure}" if unsure else ""
    status = v.get("status")
    if m["passed"] or status == "pass":
        return "pass" + tail
    if status == "blamed":
        who = ", ".join(v["blamed"])
        return ("VLOOP BLAMED" if "vloop" in v["blamed"] else f"blamed on {who}") + tail
    if status == "undecided":
        return "UNDECIDED" + tail
    if status == "inconclusive":
        return f"inconclusive ({unsure})"
    return "FAIL" + tail


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
