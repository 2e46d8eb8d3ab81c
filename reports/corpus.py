"""The corpus page: how a generated corpus fared, family by family and engine by engine.

    write_corpus_page(summary, Path("validation"))      # -> validation/corpus.html

Built from summary.json alone (so it can be redrawn from an old run): the pass rate per family,
variant and engine, the worst errors with the files they come from, histograms of the error
ratios (worst error / allowed, per comparison, log scale), the runs into a limit and whether every
engine stopped at the recorded sample, and every failure with the one command that reproduces it
and, when it was minimized, the smallest failing file. One self-contained HTML file (figures as
data URIs, no script), like report.html.
"""

from __future__ import annotations

import math
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from .html import _RC, TEMPLATES, _new_figure, _png

WORST_SHOWN = 25
HIST_BINS = np.arange(-17.0, 4.01, 0.5)  # log10(error / allowed): round-off far left, failures right of 0


def _ratio(q: dict[str, Any] | None) -> float | None:
    """Worst error as a fraction of what is allowed (inf for a non-finite error)."""
    if not q:
        return None
    err = float("inf") if isinstance(q["max_abs"], str) else float(q["max_abs"])
    return err / q["allowed"] if q["allowed"] > 0 else (0.0 if err == 0 else float("inf"))


def _engine_ok(m: dict[str, Any], engine: str) -> bool | None:
    """Did ``engine`` pass on mechanism ``m`` (its run, its comparisons, its expected sample count)?"""
    run = m["runs"].get(engine)
    if run is None or run["status"] == "skipped":
        return None
    if run["status"] == "error":
        return False
    comps = [c for c in m["comparisons"] if c["engine"] == engine or c["reference"] == engine]
    exp = (m.get("corpus") or {}).get("expect") or {}
    seen = (exp.get("observed") or {}).get(engine)
    expected = exp.get("samples")
    return all(c["passed"] for c in comps) and (seen is None or expected is None or seen == expected)


def family_rows(mechs: list[dict[str, Any]], engines: list[str]) -> list[dict[str, Any]]:
    """Per family/variant: mechanisms passed, and per engine passed/ran (None where the engine never ran)."""
    groups: dict[str, list[dict[str, Any]]] = defaultdict(list)
    for m in mechs:
        c = m["corpus"]
        groups[f"{c['family']}/{c.get('variant', '')}"].append(m)
    rows = []
    for key in sorted(groups):
        ms = groups[key]
        cells = []
        for e in engines:
            verdicts = [v for v in (_engine_ok(m, e) for m in ms) if v is not None]
            cells.append(_rate_cell(sum(verdicts), len(verdicts)))
        rows.append({"family": key, "total": _rate_cell(sum(m["passed"] for m in ms), len(ms)), "cells": cells})
    return rows


def _rate_cell(ok: int, n: int) -> dict[str, Any]:
    if n == 0:
        return {"text": "—", "css": "na", "title": "not run"}
    return {"text": f"{ok}/{n}", "css": "pass" if ok == n else "fail", "title": f"{100.0 * ok / n:.1f} % pass"}


def worst_rows(mechs: list[dict[str, Any]], limit: int = WORST_SHOWN) -> list[dict[str, Any]]:
    """The comparisons with the largest error ratio, worst first, with their files."""
    rows = []
    for m in mechs:
        for c in m["comparisons"]:
            r = _ratio(c["worst"])
            if r is None:
                continue
            q = c["worst"]
            rows.append(
                {
                    "ratio": r,
                    "ratio_text": "inf" if math.isinf(r) else f"{r:.2e}",
                    "mechanism": m["name"],
                    "file": m["file"],
                    "family": f"{m['corpus']['family']}/{m['corpus'].get('variant', '')}",
                    "pair": f"{c['engine']} vs {c['reference']}",
                    "quantity": q["quantity"],
                    "max_abs": q["max_abs"] if isinstance(q["max_abs"], str) else f"{q['max_abs']:.3g}",
                    "t": f"{q['t_at_max']:.6g}",
                    "passed": c["passed"],
                }
            )
    rows.sort(key=lambda r: -r["ratio"])
    return rows[:limit]


def histogram(mechs: list[dict[str, Any]]) -> Any:
    """Histograms of log10(worst error / allowed) per engine-vs-reference pair (one panel each)."""
    import matplotlib

    by_pair: dict[str, list[float]] = defaultdict(list)
    for m in mechs:
        for c in m["comparisons"]:
            r = _ratio(c["worst"])
            if r is not None:
                by_pair[f"{c['engine']} vs {c['reference']}"].append(r)
    if not by_pair:
        return None
    pairs = sorted(by_pair)
    cols = min(2, len(pairs))
    rows = math.ceil(len(pairs) / cols)
    with matplotlib.rc_context(_RC):
        fig = _new_figure(5.6 * cols, 2.9 * rows)
        axes = fig.subplots(rows, cols, squeeze=False)
        for ax, pair in zip(axes.flat, pairs, strict=False):
            r = np.asarray(by_pair[pair], float)
            lg = np.log10(np.clip(np.where(np.isfinite(r), r, 1e4), 1e-17, 1e4))
            ax.hist(lg, bins=HIST_BINS, color="#2b4c8c", alpha=0.85)
            ax.axvline(0.0, color="#b00020", lw=1.4, ls="--")
            n_fail = int(np.count_nonzero(r > 1))
            ax.set_title(f"{pair}: {len(r)} comparisons, {n_fail} over", fontsize=11)
            ax.set_xlabel("log₁₀(worst error / allowed)")
            ax.set_ylabel("mechanisms")
        for ax in list(axes.flat)[len(pairs) :]:
            ax.set_visible(False)
        fig.tight_layout()
        return _png(fig, "Histograms of the worst error over its allowance, per engine and reference")


def limit_rows(mechs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Runs driven into a limit on purpose: the recorded stop sample and each engine's sample count."""
    rows = []
    for m in mechs:
        exp = m["corpus"].get("expect") or {}
        if exp.get("stop_sample") is None:
            continue
        rows.append(
            {
                "mechanism": m["name"],
                "file": m["file"],
                "stop": exp["stop_sample"],
                "observed": ", ".join(f"{e} {n if n is not None else '—'}" for e, n in exp.get("observed", {}).items()),
                "passed": bool(exp.get("passed")),
            }
        )
    return rows


def render_corpus(summary: dict[str, Any]) -> str:
    """The corpus page's HTML text (from summary.json's mechanisms that carry a "corpus" entry)."""
    import jinja2

    mechs = [m for m in summary.get("mechanisms", []) if m.get("corpus")]
    engines = list(summary.get("engines", []))
    info = summary.get("corpus", {})
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(TEMPLATES),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    limits = limit_rows(mechs)
    return env.get_template("corpus.html.j2").render(
        created=summary.get("created", ""),
        n=len(mechs),
        n_passed=sum(1 for m in mechs if m["passed"]),
        seeds=", ".join(str(s) for s in info.get("seeds", [])),
        command=info.get("command", ""),
        engines=engines,
        families=family_rows(mechs, engines),
        worst=worst_rows(mechs),
        histogram=histogram(mechs),
        limits=limits,
        limits_passed=sum(1 for r in limits if r["passed"]),
        failures=info.get("failures", []),
        minimized=[m for m in info.get("minimized", []) if m.get("file") or m.get("skipped")],
    )


def write_corpus_page(summary: dict[str, Any], out_dir: str | Path) -> Path:
    """Write ``out_dir/corpus.html`` through vloop.files.output and return its path."""
    from vloop.files.output import write_text

    return write_text(Path(out_dir) / "corpus.html", render_corpus(summary))
