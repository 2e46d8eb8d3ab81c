"""The corpus page: how a generated corpus fared, family by family and engine by engine.

    write_corpus_page(summary, Path("validation"))      # -> validation/corpus.html

Built from summary.json alone (so it can be redrawn from an old run): first, in red, every mechanism where
vloop is the odd engine out; per engine its passes, the failures blamed on it and the undecided ones (the
consensus of validators.consensus); the pass rate per family, variant and engine, the worst errors with
the files they come from, histograms of the error
ratios (worst error / allowed, per comparison, log scale), the runs into a limit and whether every
engine stopped at the recorded sample, and every failure with the one command that reproduces it
and, when it was minimized, the smallest failing file. One self-contained HTML file (figures as
data URIs, no script), like report.html.
"""

from __future__ import annotations

import heapq
import math
from array import array
from collections import defaultdict
from pathlib import Path
from typing import Any

import numpy as np

from .html import _RC, TEMPLATES, _new_figure, _picture

WORST_SHOWN = 25
LIMITS_SHOWN = 200  # limit runs listed, the failing ones first (all are counted)
HIST_BINS = np.arange(-17.0, 4.01, 0.5)  # log10(error / allowed): round-off far left, failures right of 0


def _ratio(q: dict[str, Any] | None) -> float | None:
    """Worst error as a fraction of what is allowed (inf for a non-finite error)."""
    if not q:
        return None
    err = float("inf") if isinstance(q["max_abs"], str) else float(q["max_abs"])
    return err / q["allowed"] if q["allowed"] > 0 else (0.0 if err == 0 else float("inf"))


def engine_status(m: dict[str, Any], engine: str) -> str | None:
    """``engine``'s verdict on mechanism ``m``: "pass", "blamed", "undecided" (validators.consensus), None if it
    had nothing to say. A summary written before verdicts existed: "blamed" for every engine in a failure."""
    verdict = m.get("verdict")
    if verdict is not None:
        status = verdict["engines"].get(engine)
        return None if status in (None, "skipped") else status
    ok = _engine_ok(m, engine)
    return None if ok is None else ("pass" if ok else "blamed")


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


class CorpusFigures:
    """The corpus page's figures gathered one summary entry at a time (memory: counts per family and engine, the
    worst comparisons, one error ratio per comparison, the failing limit runs): a corpus of 100,000 costs what a
    corpus of 1,000 does, but for the ratios (8 bytes per comparison)."""

    def __init__(self, engines: list[str]) -> None:
        self.engines = list(engines)
        self.families: dict[str, dict[str, Any]] = {}
        self.per_engine = {
            e: {"pass": 0, "blamed": 0, "undecided": 0, "inconclusive": 0, "skipped": 0} for e in engines
        }
        self.vloop_odd: list[dict[str, Any]] = []
        self.worst: list[tuple[float, int, dict[str, Any]]] = []  # a heap of the WORST_SHOWN largest ratios
        self.ratios: dict[str, array] = defaultdict(lambda: array("d"))
        self.limits: list[dict[str, Any]] = []  # the limit runs that failed, and some that passed (all are counted)
        self.limits_ok: list[dict[str, Any]] = []
        self.n = self.n_passed = self.n_blamed = self.n_undecided = self.n_inconclusive = 0
        self.n_limits = self.limits_passed = self._seq = 0

    def add(self, m: dict[str, Any]) -> None:
        """One mechanism of summary.json (those without a "corpus" entry are not the corpus's)."""
        if not m.get("corpus"):
            return
        self.n += 1
        self.n_passed += bool(m["passed"])
        status = (m.get("verdict") or {}).get("status")
        self.n_blamed += status == "blamed"
        self.n_undecided += status == "undecided"
        self.n_inconclusive += status == "inconclusive" or bool((m.get("verdict") or {}).get("inconclusive"))
        fam = self.families.setdefault(_family(m), {"total": [], "cells": {e: [] for e in self.engines}})
        fam["total"].append("pass" if m["passed"] else status or "blamed")
        for e in self.engines:
            st = engine_status(m, e)
            self.per_engine[e]["skipped" if st is None else st] += 1
            if st is not None:
                fam["cells"][e].append(st)
        if "vloop" in (m.get("verdict") or {}).get("blamed", []):
            self.vloop_odd.append(
                {"mechanism": m["name"], "file": m["file"], "reason": m["verdict"]["reasons"].get("vloop", "")}
            )
        for c in m["comparisons"]:
            self._comparison(m, c)
        self._limit(m)

    def _comparison(self, m: dict[str, Any], c: dict[str, Any]) -> None:
        r = _ratio(c["worst"])
        if r is None:
            return
        self.ratios[f"{c['engine']} vs {c['reference']}"].append(r)
        self._seq += 1
        key = (r, self._seq)  # the order met breaks ties: rows themselves are never compared
        if len(self.worst) < WORST_SHOWN or key > self.worst[0][:2]:
            q = c["worst"]
            row = {
                "ratio": r,
                "ratio_text": "inf" if math.isinf(r) else f"{r:.2e}",
                "mechanism": m["name"],
                "file": m["file"],
                "family": _family(m),
                "pair": f"{c['engine']} vs {c['reference']}",
                "quantity": q["quantity"],
                "max_abs": q["max_abs"] if isinstance(q["max_abs"], str) else f"{q['max_abs']:.3g}",
                "t": f"{q['t_at_max']:.6g}",
                "passed": c["passed"],
            }
            (heapq.heappush if len(self.worst) < WORST_SHOWN else heapq.heapreplace)(self.worst, (*key, row))

    def _limit(self, m: dict[str, Any]) -> None:
        exp = m["corpus"].get("expect") or {}
        if exp.get("stop_sample") is None:
            return
        self.n_limits += 1
        self.limits_passed += bool(exp.get("passed"))
        rows = self.limits if not exp.get("passed") else self.limits_ok
        if len(self.limits) + len(self.limits_ok) < LIMITS_SHOWN or (rows is self.limits and self.limits_ok):
            if len(self.limits) + len(self.limits_ok) >= LIMITS_SHOWN:
                self.limits_ok.pop()  # a failing run takes the place of a passing one
            observed = ", ".join(f"{e} {n if n is not None else '—'}" for e, n in exp.get("observed", {}).items())
            rows.append({"mechanism": m["name"], "file": m["file"], "stop": exp["stop_sample"],
                         "observed": observed, "passed": bool(exp.get("passed"))})  # fmt: skip

    def limit_rows(self) -> list[dict[str, Any]]:
        """The runs into a limit listed: every failing one (up to LIMITS_SHOWN), then passing ones to fill it."""
        return self.limits + self.limits_ok

    def family_rows(self) -> list[dict[str, Any]]:
        """Per family/variant: mechanisms passed, and per engine passed/ran (None where the engine never ran)."""
        return [
            {"family": k, "total": _rate_cell(f["total"]), "cells": [_rate_cell(f["cells"][e]) for e in self.engines]}
            for k, f in sorted(self.families.items())
        ]

    def engine_rows(self) -> list[dict[str, Any]]:
        return [{"engine": e, **self.per_engine[e]} for e in self.engines]

    def worst_rows(self) -> list[dict[str, Any]]:
        return [row for _, _, row in sorted(self.worst, key=lambda w: (-w[0], w[1]))]


def _family(m: dict[str, Any]) -> str:
    return f"{m['corpus']['family']}/{m['corpus'].get('variant', '')}"


def _rate_cell(statuses: list[str]) -> dict[str, Any]:
    """passes/ran, with the blamed failures, the undecided and the inconclusive ones under it."""
    n = len(statuses)
    if n == 0:
        return {"text": "—", "css": "na", "title": "not run", "extra": ""}
    ok, blamed, undecided, unsure = (statuses.count(s) for s in ("pass", "blamed", "undecided", "inconclusive"))
    parts = ((blamed, "blamed"), (undecided, "undecided"), (unsure, "inconclusive"))
    extra = ", ".join(f"{k} {w}" for k, w in parts if k)
    css = "fail" if blamed else ("undecided" if undecided or unsure else "pass")
    return {"text": f"{ok}/{n}", "css": css, "title": f"{100.0 * ok / n:.1f} % pass", "extra": extra}


def histogram(by_pair: dict[str, Any]) -> Any:
    """Histograms of log10(worst error / allowed) per engine-vs-reference pair (one panel each)."""
    import matplotlib

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
        return _picture(fig, "Histograms of the worst error over its allowance, per engine and reference")


def render_corpus(summary: dict[str, Any], figures: CorpusFigures | None = None) -> str:
    """The corpus page's HTML text: from ``figures`` gathered while the entries streamed past, else from
    summary.json's mechanisms that carry a "corpus" entry."""
    import jinja2

    engines = list(summary.get("engines", []))
    if figures is None:
        figures = CorpusFigures(engines)
        for m in summary.get("mechanisms", []):
            figures.add(m)
    info = summary.get("corpus", {})
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(TEMPLATES),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    f = figures
    return env.get_template("corpus.html.j2").render(
        created=summary.get("created", ""),
        n=f.n,
        n_passed=f.n_passed,
        seeds=", ".join(str(s) for s in info.get("seeds", [])),
        command=info.get("command", ""),
        engines=engines,
        families=f.family_rows(),
        engine_rows=f.engine_rows(),
        vloop_odd=f.vloop_odd,
        n_blamed=f.n_blamed,
        n_undecided=f.n_undecided,
        n_inconclusive=f.n_inconclusive,
        worst=f.worst_rows(),
        histogram=histogram(f.ratios),
        limits=f.limit_rows(),
        n_limits=f.n_limits,
        limits_passed=f.limits_passed,
        failures=info.get("failures", []),
        minimized=[m for m in info.get("minimized", []) if m.get("file") or m.get("skipped")],
    )


def write_corpus_page(summary: dict[str, Any], out_dir: str | Path, figures: CorpusFigures | None = None) -> Path:
    """Write ``out_dir/corpus.html`` through vloop.files.output and return its path."""
    from vloop.files.output import write_text

    return write_text(Path(out_dir) / "corpus.html", render_corpus(summary, figures))
