"""The nightly's history: what changed from night to night, on one page.

    write_trend(figures, night_folder)        # night_folder/trend.json: this night's figures (a few KB)
    write_history(root, night_folder)         # night_folder/history.html: every night under root, newest first

A nightly (``vloop validate --nightly --out ROOT``) writes each night into ROOT/DATE/. Each night keeps its figures
in ``trend.json`` — mechanisms, passes, red ones, per engine its passes, blamed failures, undecided and
inconclusive ones, per family its passes (all engines and per engine), the failing mechanisms' keys, the time per
mechanism — so the history reads a few KB per night, not the nights' summaries (an older night without
trend.json is read from its summary.json once, by :func:`figures_from_summary`). The page shows, per night: the
counts, the new failures against the night before (and those fixed since), the reference engines' blamed and
inconclusive counts, the seconds per mechanism; per family its pass rate night by night; and a figure of the pass
rate and the time per mechanism. One self-contained file (a data-URI figure, no script), like report.html.
"""

from __future__ import annotations

import json
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .html import _RC, TEMPLATES, _new_figure, _picture

TREND = "trend.json"
HISTORY = "history.html"
STATUSES = ("pass", "blamed", "undecided", "inconclusive", "skipped")
NIGHTS_SHOWN = 60  # nights on the page (the newest)
NEW_SHOWN = 30  # new failures named per night (all are counted)


def _key(m: dict[str, Any]) -> str:
    c = m.get("corpus")
    return f"{m['name']}@seed{c['seed']}" if c else m["name"]


def figures_from_summary(summary: dict[str, Any], folder: str = "") -> dict[str, Any]:
    """A night's trend figures from its summary.json (its mechanisms all there)."""
    acc = Accumulator(summary.get("engines", []))
    for m in summary.get("mechanisms", []):
        acc.add(m)
    return acc.figures(summary, folder)


class Accumulator:
    """A night's trend figures gathered one summary entry at a time (counts, and the failing mechanisms' keys)."""

    def __init__(self, engines: Iterable[str]) -> None:
        self.engines = list(engines)
        self.per_engine = {
            e: {"pass": 0, "blamed": 0, "undecided": 0, "inconclusive": 0, "skipped": 0} for e in engines
        }
        self.families: dict[str, dict[str, Any]] = {}
        self.failed: list[str] = []
        self.red: list[str] = []
        self.n = self.passed = 0

    def add(self, m: dict[str, Any]) -> None:
        self.n += 1
        self.passed += bool(m["passed"])
        if not m["passed"]:
            self.failed.append(_key(m))
        if m.get("red"):
            self.red.append(_key(m))
        fam = f"{m['corpus']['family']}/{m['corpus'].get('variant', '')}" if m.get("corpus") else "catalog"
        row = self.families.setdefault(fam, {"n": 0, "passed": 0, "engines": {e: 0 for e in self.engines}})
        row["n"] += 1
        row["passed"] += bool(m["passed"])
        for e, status in ((m.get("verdict") or {}).get("engines") or {}).items():
            self.per_engine.setdefault(e, dict.fromkeys(STATUSES, 0))
            self.per_engine[e][status] = self.per_engine[e].get(status, 0) + 1
            if status == "pass":
                row["engines"][e] = row["engines"].get(e, 0) + 1

    def figures(self, summary: dict[str, Any], folder: str = "") -> dict[str, Any]:
        seconds = float(summary.get("seconds") or 0.0)
        return {
            "folder": folder,
            "created": summary.get("created", ""),
            "date": (summary.get("nightly") or {}).get("date") or str(summary.get("created", ""))[:10],
            "mechanisms": self.n,
            "passed": self.passed,
            "red": len(self.red),
            "seconds": seconds,
            "seconds_per_mechanism": seconds / self.n if self.n else None,
            "engines": self.per_engine,
            "families": dict(sorted(self.families.items())),
            "failed": sorted(self.failed),
            "red_mechanisms": sorted(self.red),
        }


def write_trend(figures: dict[str, Any], folder: Path) -> Path:
    """``folder``/trend.json (atomically)."""
    from vloop.files.output import write_text

    return write_text(Path(folder) / TREND, json.dumps(figures, indent=1, allow_nan=False))


def nights(root: Path, tonight: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """Every night's figures under ``root`` (trend.json, else its summary.json), oldest first; ``tonight``: the
    figures of the night being written (its folder, ``tonight["folder"]``, is not read)."""
    out = []
    skip = (tonight or {}).get("folder")
    for folder in sorted(p for p in Path(root).iterdir() if p.is_dir() and not p.name.startswith(".")):
        figs = None if folder.name == skip else _read(folder)
        if figs is not None:
            out.append({**figs, "folder": folder.name})
    if tonight is not None:
        out.append(tonight)
    out.sort(key=lambda f: (str(f.get("created") or ""), f["folder"]))
    return out


def _read(folder: Path) -> dict[str, Any] | None:
    try:
        if (folder / TREND).is_file():
            return json.loads((folder / TREND).read_text(encoding="utf-8"))
        if (folder / "summary.json").is_file():
            return figures_from_summary(json.loads((folder / "summary.json").read_text(encoding="utf-8")), folder.name)
    except (OSError, ValueError, KeyError, TypeError):
        return None  # a night that cannot be read is left out of the history, not a reason to fail tonight
    return None


def changes(history: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per night (newest first): its figures, the failures new since the night before and those fixed since."""
    rows = []
    for k, night in enumerate(history):
        before = set(history[k - 1]["failed"]) if k else set()
        now = set(night["failed"])
        new, fixed = sorted(now - before), sorted(before - now)
        rows.append({**night, "new": new, "new_shown": new[:NEW_SHOWN], "fixed": fixed, "first": k == 0})
    return rows[::-1]


def render(history: list[dict[str, Any]]) -> str:
    """history.html's text."""
    import jinja2
    import matplotlib

    shown = history[-NIGHTS_SHOWN:]
    rows = changes(shown)
    engines = sorted({e for n in shown for e in n["engines"]}, key=lambda e: (e != "vloop", e))
    families = sorted({f for n in shown for f in n["families"]})
    with matplotlib.rc_context(_RC):
        figure = _figure(shown)
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(TEMPLATES), autoescape=True, undefined=jinja2.StrictUndefined
    )
    return env.get_template("history.html.j2").render(
        rows=rows, engines=engines, families=families, nights=shown[::-1], figure=figure
    )


def _figure(history: list[dict[str, Any]]) -> Any:
    """Pass rate and seconds per mechanism, night by night."""
    if not history:
        return None
    fig = _new_figure(9.0, 3.2)
    ax1, ax2 = fig.subplots(1, 2)
    x = list(range(len(history)))
    labels = [n["folder"] for n in history]
    ax1.plot(x, [100.0 * n["passed"] / max(n["mechanisms"], 1) for n in history], "o-", color="#2b4c8c")
    ax1.set_title("mechanisms passing every comparison [%]")
    ax2.plot(x, [n.get("seconds_per_mechanism") or 0.0 for n in history], "o-", color="#8c2b4c")
    ax2.set_title("seconds per mechanism (wall, whole run)")
    for ax in (ax1, ax2):
        ax.set_xticks(x, labels, rotation=45, ha="right", fontsize=8)
    fig.tight_layout()
    return _picture(fig, "Pass rate and seconds per mechanism, night by night")


def write_history(root: Path, folder: Path, tonight: dict[str, Any] | None = None) -> Path:
    """``folder``/history.html: every night under ``root``, and ``tonight``'s figures (a night not published yet)."""
    from vloop.files.output import write_text

    return write_text(Path(folder) / HISTORY, render(nights(root, tonight)))
