"""Curves drawn on top of each other, told apart as textbooks do (matplotlib ``Axes``).

Two curves of an axes *coincide* when, sample by sample over the whole run, they are closer than
``TOLERANCE`` of the axes' width and height (measured in the axes' own box, so a log axis is judged as
drawn). The first curve of a coincident group keeps its look; each later one gets another line style,
an open marker every few samples (staggered, so the markers do not hide each other), and a legend
label that says what it lies on: ``l8 (= l6)``. Curves that meet over part of the run only (two
reactions both near zero for a while) are visible elsewhere and are left as they are.

Lines whose label starts with ``_child`` (matplotlib's unnamed lines: a mechanism's outline, a grid
study's variant curves) are left alone; a line labelled ``_NAME`` takes part as NAME without a legend
entry.
"""

from __future__ import annotations

from typing import Any

import numpy as np

TOLERANCE = 0.005  # of the axes' span: a 1.6 pt line on a 2.3 in panel is 1 % of its height
STYLES = ("--", ":", "-.", "-")  # named line styles, so a reader's legend shows the difference
MARKERS = ("o", "s", "^", "D", "v", "<", ">", "p")
MARKS_PER_CURVE = 12


def _name(line: Any) -> str | None:
    label = str(line.get_label())
    if label.startswith("_child"):
        return None
    return label.removeprefix("_")


def _in_box(ax: Any, line: Any) -> np.ndarray:
    """The line's samples in the axes' unit box (n × 2); non-finite samples stay NaN."""
    ax.get_xlim(), ax.get_ylim()  # settles the view limits the transform reads
    x = np.asarray(line.get_xdata(), float)
    y = np.asarray(line.get_ydata(), float)
    xy = np.column_stack([x, y])
    ok = np.isfinite(xy).all(axis=1)
    out = np.full(xy.shape, np.nan)
    if ok.any():
        out[ok] = (ax.transScale + ax.transLimits).transform(xy[ok])
    return out


def coincide(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two curves (n × 2, in the axes' unit box) are within ``TOLERANCE`` at every sample
    (a sample missing from both counts as shared)."""
    if a.shape != b.shape or not len(a):
        return False
    both_missing = np.isnan(a).any(axis=1) & np.isnan(b).any(axis=1)
    with np.errstate(invalid="ignore"):
        close = np.all(np.abs(a - b) <= TOLERANCE, axis=1)
    return bool(np.all(close | both_missing))


def _groups(pairs: set[tuple[int, int]], n: int) -> list[list[int]]:
    """Curves linked by coincident pairs, each group in drawing order."""
    root = list(range(n))

    def find(i: int) -> int:
        while root[i] != i:
            root[i] = root[root[i]]
            i = root[i]
        return i

    for i, j in pairs:
        root[find(j)] = find(i)
    members: dict[int, list[int]] = {}
    for i in range(n):
        members.setdefault(find(i), []).append(i)
    return [g for g in members.values() if len(g) > 1]


def distinguish(ax: Any, lines: list[Any] | None = None) -> list[Any]:
    """Restyle the axes' coincident curves (see the module docstring); return the lines restyled.

    ``lines``: the curves to consider (default: every named line drawn in data coordinates).
    Call it after the curves are drawn and before the legend is made.
    """
    if lines is None:
        lines = [ln for ln in ax.get_lines() if _name(ln) is not None and ln.get_transform() == ax.transData]
    boxed = [_in_box(ax, ln) for ln in lines]
    names = [_name(ln) for ln in lines]
    n = len(lines)
    pairs = {(i, j) for i in range(n) for j in range(i + 1, n) if coincide(boxed[i], boxed[j])}
    changed = []
    for group in _groups(pairs, n):
        taken = {lines[group[0]].get_linestyle()}
        for k, i in enumerate(group[1:], start=1):
            under = [names[j] for j in group[:k] if (j, i) in pairs]
            if not under:  # in the group through a later curve only: nothing of it is hidden
                continue
            line = lines[i]
            style = next((s for s in STYLES if s not in taken), line.get_linestyle())
            taken.add(style)
            every = max(len(boxed[i]) // MARKS_PER_CURVE, 1)
            line.set_linestyle(style)
            line.set_marker(MARKERS[(k - 1) % len(MARKERS)])
            line.set_markerfacecolor("none")
            line.set_markersize(5.5)
            line.set_markevery((k * every // len(group), every))
            line.set_zorder(line.get_zorder() + 0.01 * k)
            line.set_label(f"{line.get_label()} ({', '.join(f'= {u}' for u in under)})")
            changed.append(line)
    return changed


def note_legend(ax: Any, changed: list[Any], **kwargs: Any) -> None:
    """A legend of the restyled curves for an axes that has none (a panel below the one with the legend)."""
    named = [ln for ln in changed if not str(ln.get_label()).startswith("_")]
    if named and ax.get_legend() is None:
        ax.legend(handles=named, **({"fontsize": 8, "loc": "best"} | kwargs))
