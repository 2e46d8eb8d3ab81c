"""The instructors' report: one self-contained HTML file of a cross-validation run.

    v = validators.harness.run(paths, engines=("vloop", "analytic", "pinocchio"))
    write_report(v, validators.harness.to_summary(v), Path("out"))      # -> out/report.html

Everything is embedded (figures as base64 WebP (lossless) and GIF data URIs, CSS inline, no script, no
font or URL to fetch), so the file opens offline in any browser and can be mailed as is.
Figures are drawn on matplotlib ``Figure`` objects with the Agg canvas directly, never
through pyplot: no GUI backend is touched and no figure is left registered anywhere.
"""

from __future__ import annotations

import base64
import datetime as _dt
import io
import itertools
import math
import tempfile
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Polygon
from matplotlib.ticker import FuncFormatter, NullFormatter
from matplotlib.transforms import ScaledTranslation

from vloop.compare import QuantityError, error_series
from vloop.mechanism import Driver, Mechanism
from vloop.result import Result

from .model import Check as CheckedComparison
from .model import Item as MechanismValidation
from .model import Run as EngineRun
from .model import Validation

TEMPLATES = Path(__file__).resolve().parent / "templates"
GROUPS = ("angle", "angular velocity", "angular acceleration", "position", "velocity", "acceleration")
GROUPS += ("force", "moment")  # kinetostatics, for mechanisms with masses (validators/engines.py)
MAX_FRAMES = 40  # animated GIF frames per mechanism
LINKS_PER_FIGURE = 6  # more rotating links than this are spread over several history figures
WORST_SHOWN = 4  # quantities per engine in the error-vs-time plots
DPI = 96
VIEWER_FOLDER = "viewer"  # one interactive page per mechanism, next to report.html
GIF_DPI = 72
WEBP_EFFORT = 4  # libwebp's method 0–6: 4 is its default; 6 saves ~2 % more at twice the time

# Each engine keeps one look in every plot, so curves that lie on top of each other stay visible.
ENGINE_STYLE: dict[str, dict[str, Any]] = {
    "vloop": {"ls": "-", "lw": 2.6, "alpha": 0.55},
    "analytic": {"ls": "--", "lw": 1.5},
    "pinocchio": {"ls": "none", "marker": "o", "ms": 5, "mfc": "none", "mew": 1.2},
    "exudyn-kinematic": {"ls": "none", "marker": "x", "ms": 5, "mew": 1.2},
    "exudyn-dynamic": {"ls": ":", "lw": 1.4, "marker": "+", "ms": 7, "mew": 1.2},
}
_SPARE_STYLES = ({"ls": "-.", "lw": 1.3, "marker": "s", "ms": 4, "mfc": "none"}, {"ls": "none", "marker": "^", "ms": 5})
_COLORS = ("#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22")
_STOP_STYLE: dict[str, Any] = {"color": "#b00", "ls": (0, (4, 3)), "lw": 1.2}
_RC = {
    "font.size": 11,
    "axes.titlesize": 12,
    "axes.labelsize": 11,
    "legend.fontsize": 9.5,
    "axes.grid": True,
    "grid.alpha": 0.3,
    "axes.spines.top": False,
    "axes.spines.right": False,
}


# ------------------------------------------------------------------ images


@dataclass(frozen=True)
class Image:
    """An embedded picture: its data URI and pixel size."""

    uri: str
    width: int
    height: int
    alt: str


def _new_figure(w: float, h: float) -> Figure:
    """A Figure on its own Agg canvas (not known to pyplot, so nothing to close)."""
    fig = Figure(figsize=(w, h))
    FigureCanvasAgg(fig)
    return fig


def _picture(fig: Figure, alt: str, dpi: int = DPI) -> Image:
    """Render ``fig`` to 256 palette colours (no visible loss for line art), stored as lossless WebP.

    Lossless WebP holds the very pixels a palette PNG would at about three quarters of its bytes (the
    catalog's report: 2.76 MB of figures → 2.03 MB); every current browser shows it. Fewer colours would
    cost more than they save: at 32 a fifth of the inked pixels move and light greys (grids, guides) vanish."""
    from PIL import Image as PILImage

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, bbox_inches="tight", pad_inches=0.08, facecolor="white")
    fig.clear()
    buf.seek(0)
    im = PILImage.open(buf).convert("RGB")
    q = im.quantize(colors=256, method=PILImage.Quantize.FASTOCTREE, dither=PILImage.Dither.NONE)
    out = io.BytesIO()
    q.convert("RGB").save(out, format="WEBP", lossless=True, quality=100, method=WEBP_EFFORT)
    return Image("data:image/webp;base64," + base64.b64encode(out.getvalue()).decode("ascii"), im.width, im.height, alt)


def _style(engine: str, index: int, n_samples: int, n_engines: int) -> dict[str, Any]:
    """The engine's line style; markers every few samples, staggered so engines do not hide each other's."""
    st = dict(ENGINE_STYLE.get(engine) or _SPARE_STYLES[index % len(_SPARE_STYLES)])
    if st.get("marker"):
        every = max(n_samples // 22, n_engines, 1)
        st["markevery"] = ((index * every) // max(n_engines, 1), every)
    return st


# ------------------------------------------------------------------ geometry at t = 0


@dataclass
class _Geometry:
    """Positions (complex) of every joint/point, slider block angles and the vector loops at t = 0."""

    pos: dict[str, complex]
    block_theta: dict[str, float]
    s0: dict[str, float]
    loops: list[tuple[str, list[tuple[complex, complex]]]] = field(default_factory=list)
    origin_used: bool = False
    note: str = ""


def _compile(mech: Mechanism) -> tuple[Any, str]:
    import vloop

    try:
        return vloop.compile(mech), ""
    except Exception as exc:  # shown in the report; the drawing falls back to the file's coordinates
        return None, f"{type(exc).__name__}: {exc}"


def _geometry(mech: Mechanism, system: Any) -> _Geometry:
    theta = {n: math.atan2(s.axis[1], s.axis[0]) for n, s in mech.sliders.items()}
    pos = {n: complex(*xy) for n, xy in mech.joints.items()} | {p.name: complex(*p.at) for p in mech.points.values()}
    if system is None:
        return _Geometry(pos, theta, {}, note="loops not available: the mechanism did not compile")
    import vloop
    from vloop.views.geometry import loop_chains

    try:
        at0 = vloop.solve(system, times=np.zeros(1))  # the t = 0 assembly, through the public API
    except vloop.VloopError as exc:
        return _Geometry(pos, theta, {}, note=f"loops not available: {exc}")
    pos = {p: complex(at0[f"{p}.x"][0], at0[f"{p}.y"][0]) for p in mech.tracked_points}
    s0 = {n: float(at0[f"{n}.s"][0]) for n in mech.sliders}
    tiny = 1e-9 * mech.scale
    loops = []
    origin_used = False
    for chain in loop_chains(system, at0):  # each loop's vectors head to tail, as the paper draws them
        z = chain.vertices[0]
        segs = [(complex(a), complex(b)) for a, b in itertools.pairwise(z) if abs(b - a) > tiny]
        origin_used |= chain.start is None
        loops.append((f"loop {chain.number} ({chain.label})", segs))
    return _Geometry(pos, theta, s0, loops, origin_used)


# ------------------------------------------------------------------ drawing


def _hull_order(pts: list[complex]) -> list[complex]:
    c = sum(pts) / len(pts)
    return sorted(pts, key=lambda p: math.atan2((p - c).imag, (p - c).real))


def _draw_ground(ax: Any, mech: Mechanism, pos: dict[str, complex]) -> None:
    """A hatched pivot symbol under every ground joint (one line artist for all the hatching)."""
    h = 0.035 * mech.scale
    xs: list[float] = []
    ys: list[float] = []
    for j in mech.links[mech.ground].joints:
        x, y = pos[j].real, pos[j].imag
        tri = [(x, y), (x - 0.6 * h, y - h), (x + 0.6 * h, y - h)]
        ax.add_patch(Polygon(tri, closed=True, fc="#d0d0d0", ec="#444", lw=1.0, zorder=1.5))
        xs += [x - 0.9 * h, x + 0.9 * h, np.nan]
        ys += [y - h, y - h, np.nan]
        for k in range(5):
            x0 = x - 0.8 * h + k * 0.4 * h
            xs += [x0, x0 - 0.25 * h, np.nan]
            ys += [y - h, y - 1.3 * h, np.nan]
    ax.plot(xs, ys, color="#444", lw=1.0, zorder=1.5)


def _draw_mechanism(
    ax: Any,
    mech: Mechanism,
    pos: dict[str, complex],
    block_theta: dict[str, float],
    slot: dict[str, tuple[float, float]],
    *,
    labels: bool = True,
    with_ground: bool = True,
    lw: float = 3.2,
) -> None:
    """Links, ground pivots, slider blocks on their guide lines, tracer points, joint labels."""
    size = mech.scale
    ground = mech.links[mech.ground]
    link_c, fill_c, block_c = "#3d4a63", "#c3d2e6", "#e0953f"
    # slider guide lines (under everything)
    for name, sl in mech.sliders.items():
        u = complex(math.cos(block_theta[name]), math.sin(block_theta[name]))
        lo, hi = slot.get(name, (-0.15 * size, 0.15 * size))
        a, b = pos[sl.joint] + u * lo, pos[sl.joint] + u * hi
        ax.plot(
            [a.real, b.real],
            [a.imag, b.imag],
            color="#9a9a9a",
            lw=5 if sl.guide == mech.ground else 3,
            solid_capstyle="butt",
            zorder=1,
            alpha=0.6,
        )
    # moving links
    for name, lk in mech.links.items():
        if lk.ground or not lk.joints:
            continue
        pts = [pos[j] for j in lk.joints] + [pos[p.name] for p in mech.points.values() if p.link == name]
        if len(pts) >= 3:
            poly = _hull_order(pts)
            ax.add_patch(
                Polygon(
                    [(p.real, p.imag) for p in poly],
                    closed=True,
                    fc=fill_c,
                    ec=link_c,
                    lw=lw * 0.6,
                    alpha=0.85,
                    zorder=2,
                )
            )
        elif len(pts) == 2:
            ax.plot(
                [p.real for p in pts],
                [p.imag for p in pts],
                color=link_c,
                lw=lw,
                solid_capstyle="round",
                zorder=3,
                alpha=0.8,
            )
    if with_ground:
        _draw_ground(ax, mech, pos)
    # slider blocks
    bw, bh = 0.07 * size, 0.04 * size
    for name, sl in mech.sliders.items():
        u = complex(math.cos(block_theta[name]), math.sin(block_theta[name]))
        c = pos[sl.joint]
        corners = [c + u * (sx * bw / 2 + 1j * sy * bh / 2) for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
        ax.add_patch(
            Polygon(
                [(q.real, q.imag) for q in corners], closed=True, fc=block_c, ec="#7a4a12", lw=1.2, zorder=4, alpha=0.95
            )
        )
    # pins and points
    pins = [j for j in mech.joints if len(mech.bodies_at(j)) >= 2 or j in ground.joints]
    ax.plot(
        [pos[j].real for j in pins],
        [pos[j].imag for j in pins],
        "o",
        ms=6.5,
        mfc="white",
        mec="black",
        mew=1.4,
        zorder=5,
    )
    others = [n for n in mech.tracked_points if n not in pins]
    if others:
        ax.plot([pos[n].real for n in others], [pos[n].imag for n in others], "o", ms=4.5, color="black", zorder=5)
    if labels:
        centre = sum(pos[n] for n in mech.tracked_points) / max(len(mech.tracked_points), 1)
        for n in mech.tracked_points:
            d = pos[n] - centre
            d = d / abs(d) if abs(d) > 1e-12 * size else 1j
            q = pos[n] + d * 0.055 * size
            ax.text(
                q.real,
                q.imag,
                n,
                ha="center",
                va="center",
                fontsize=10.5,
                fontweight="bold",
                zorder=7,
                bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.75},
            )


def _slots(mech: Mechanism, result: Result | None, geo_s0: dict[str, float]) -> dict[str, tuple[float, float]]:
    """Extent of each slider's guide line relative to the joint at t = 0: its travel over the run, with margin."""
    out = {}
    for name in mech.sliders:
        if result is not None and f"{name}.s" in result and len(result) and name in geo_s0:
            s = result[f"{name}.s"]
            s = s[np.isfinite(s)]
            if len(s):
                m = 0.08 * mech.scale
                out[name] = (float(s.min()) - geo_s0[name] - m, float(s.max()) - geo_s0[name] + m)
    return out


def _drawing(mech: Mechanism, geo: _Geometry, result: Result | None) -> Image:
    fig = _new_figure(7.4, 6.0)
    ax = fig.add_subplot()
    _draw_mechanism(ax, mech, geo.pos, geo.block_theta, _slots(mech, result, geo.s0))
    handles = []
    size = mech.scale
    for k, (label, segs) in enumerate(geo.loops):
        color = _COLORS[k % len(_COLORS)]
        pts = [a for a, _ in segs]
        centre = sum(pts) / len(pts) if pts else 0j
        step = size * (0.022 + 0.014 * k)  # loops that share a vector are drawn side by side

        def inset(p: complex, centre: complex = centre, step: float = step) -> complex:
            d = centre - p
            return p + (d / abs(d) * min(step, 0.3 * abs(d)) if abs(d) > 0 else 0)

        for a, b in segs:
            a2, b2 = inset(a), inset(b)
            ax.annotate(
                "",
                xy=(b2.real, b2.imag),
                xytext=(a2.real, a2.imag),
                zorder=6,
                arrowprops={
                    "arrowstyle": "-|>",
                    "color": color,
                    "lw": 2.0,
                    "shrinkA": 0,
                    "shrinkB": 0,
                    "mutation_scale": 14,
                },
            )
        if pts:
            ax.text(
                centre.real,
                centre.imag,
                str(k + 1),
                color="white",
                fontsize=10,
                fontweight="bold",
                ha="center",
                va="center",
                zorder=8,
                bbox={"boxstyle": "circle,pad=0.25", "fc": color, "ec": "none"},
            )
        handles.append(Line2D([], [], color=color, lw=2.2, marker=">", ms=6, label=label))
    if geo.origin_used and not any(abs(p) < 1e-12 * size for p in geo.pos.values()):
        ax.plot([0], [0], "+", color="#555", ms=12, mew=1.5, zorder=5)
        ax.annotate("origin", (0, 0), xytext=(4, -12), textcoords="offset points", fontsize=9, color="#555")
    ax.set_aspect("equal", adjustable="datalim")
    ax.margins(0.08)
    ax.set_xlabel(f"x [{mech.units}]")
    ax.set_ylabel(f"y [{mech.units}]")
    ax.set_title(f"{mech.name} at t = 0 with its vector loops", fontsize=12)
    if handles:
        ax.legend(
            handles=handles,
            loc="upper center",
            bbox_to_anchor=(0.5, -0.11),
            ncol=2 if len(handles) > 3 else len(handles),
            frameon=False,
            fontsize=10,
        )
    return _picture(fig, f"{mech.name}: drawing at t = 0 with its vector loops")


# ------------------------------------------------------------------ histories


def _chunks(names: Sequence[str], n: int) -> list[list[str]]:
    return [list(names[i : i + n]) for i in range(0, len(names), n)] if names else []


def _history(
    runs: list[EngineRun],
    names: list[str],
    fields: tuple[str, str, str],
    ylabels: tuple[str, str, str],
    title: str,
    kind: str,
) -> Image:
    fig = _new_figure(8.8, 8.2)
    axes = fig.subplots(3, 1, sharex=True)
    stops = sorted({float(r.result.t[-1]) for r in runs if r.status == "stopped" and r.samples})
    for ax, f, yl in zip(axes, fields, ylabels, strict=True):
        for ei, r in enumerate(runs):
            res = r.result
            st = _style(r.engine, ei, len(res), len(runs))
            for ni, n in enumerate(names):
                if f"{n}.{f}" in res:
                    ax.plot(res.t, res[f"{n}.{f}"], color=_COLORS[ni % len(_COLORS)], **st)
        for ts in stops:
            ax.axvline(ts, **_STOP_STYLE)
        ax.set_ylabel(yl)
    axes[-1].set_xlabel("t [s]")
    axes[0].set_title(title)
    ent = [Line2D([], [], color=_COLORS[i % len(_COLORS)], lw=2.5, label=n) for i, n in enumerate(names)]
    eng = [
        Line2D(
            [],
            [],
            color="black",
            **{k: v for k, v in _style(r.engine, i, 60, 1).items() if k != "markevery"},
            label=r.engine + (" (stopped)" if r.status == "stopped" else ""),
        )
        for i, r in enumerate(runs)
    ]
    if stops:
        eng.append(Line2D([], [], label="motion stops\n(last sample solved)", **_STOP_STYLE))
    leg = axes[0].legend(handles=ent, title=kind, loc="upper left", bbox_to_anchor=(1.01, 1.02), frameon=False)
    axes[0].add_artist(leg)
    axes[1].legend(handles=eng, title="engine", loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False)
    fig.align_ylabels(axes)
    return _picture(fig, title)


def _histories(mech: Mechanism, runs: list[EngineRun]) -> list[Image]:
    """θ/ω/α of the rotating links and s/v/a of the sliders, every engine overlaid (the paper's Figs. 5–7)."""
    runs = [r for r in runs if r.result is not None and len(r.result)]
    if not runs:
        return []
    driven = {d.target for d in mech.drivers if d.kind == "crank"}
    moving = [n for n, lk in mech.links.items() if not lk.ground]
    rotating = [n for n in moving if n not in driven] or moving
    out = []
    groups = _chunks(rotating, LINKS_PER_FIGURE)
    for k, names in enumerate(groups):
        part = f" ({k + 1}/{len(groups)})" if len(groups) > 1 else ""
        out.append(
            _history(
                runs,
                names,
                ("theta", "omega", "alpha"),
                ("θ [rad]", "ω [rad/s]", "α [rad/s²]"),
                f"Angular position, velocity, acceleration of the links{part}",
                "link",
            )
        )
    u = mech.units
    for names in _chunks(list(mech.sliders), LINKS_PER_FIGURE):
        out.append(
            _history(
                runs,
                names,
                ("s", "v", "a"),
                (f"s [{u}]", f"v [{u}/s]", f"a [{u}/s²]"),
                "Position, velocity, acceleration of the sliders",
                "slider",
            )
        )
    return out


def _force_histories(mech: Mechanism, runs: list[EngineRun]) -> list[Image]:
    """Driver torques/forces and the pin reactions' magnitudes, every engine overlaid (mechanisms with masses)."""
    runs = [r for r in runs if r.result is not None and len(r.result)]
    drivers = [c for c in (runs[0].result.columns if runs else {}) if c.endswith((".torque", ".force"))]
    if not drivers:
        return []
    pins = [c for c in runs[0].result.columns if c.endswith(".mag")]
    pins = sorted(pins, key=lambda c: -float(np.max(np.abs(runs[0].result[c]))))[:LINKS_PER_FIGURE]
    fig = _new_figure(8.8, 6.0)
    axes = fig.subplots(2, 1, sharex=True)
    for ax, names, label in ((axes[0], drivers, "driver [N·m or N]"), (axes[1], pins, "pin force |F| [N]")):
        for ei, r in enumerate(runs):
            st = _style(r.engine, ei, len(r.result), len(runs))
            for ni, n in enumerate(names):
                if n in r.result:
                    ax.plot(r.result.t, r.result[n], color=_COLORS[ni % len(_COLORS)], **st)
        ax.set_ylabel(label)
        ent = [Line2D([], [], color=_COLORS[i % len(_COLORS)], lw=2.5, label=n) for i, n in enumerate(names)]
        ax.legend(handles=ent, loc="upper left", bbox_to_anchor=(1.01, 1.0), frameon=False, fontsize=8)
    axes[-1].set_xlabel("t [s]")
    axes[0].set_title("Forces: driver torque and pin reactions (every engine overlaid)")
    return [_picture(fig, f"{mech.name}: driver torque and pin reaction magnitudes")]


# ------------------------------------------------------------------ errors


def _ratio(e: QuantityError) -> float:
    if e.tol > 0:
        return e.max_abs / e.tol
    return 0.0 if e.max_abs == 0 else math.inf


_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")


def _pow10(y: float, _pos: Any = None) -> str:
    """Log-axis tick label 10⁻¹² in plain Unicode (mathtext would cost a parse per label)."""
    if y <= 0:
        return ""
    k = math.log10(y)
    return "10" + str(round(k)).translate(_SUPERSCRIPT) if abs(k - round(k)) < 1e-9 else ""


def _error_checks(item: MechanismValidation) -> list[CheckedComparison]:
    """One comparison per engine for the error plots: against vloop, else against the closed form."""
    out: dict[str, CheckedComparison] = {}
    for c in item.checks:
        if c.comparison is not None and c.engine not in out:
            out[c.engine] = c
    return list(out.values())


def _error_figure(item: MechanismValidation) -> Image | None:
    checks = _error_checks(item)
    if not checks:
        return None
    ncol = 2 if len(checks) > 1 else 1
    nrow = math.ceil(len(checks) / ncol)
    fig = _new_figure(6.2 * ncol, 3.5 * nrow)
    axes = np.atleast_1d(fig.subplots(nrow, ncol, squeeze=False)).ravel()
    for ax, c in zip(axes, checks, strict=False):
        a, b = item.runs[c.engine].result, item.runs[c.reference].result
        worst = sorted(c.comparison.errors, key=_ratio, reverse=True)[:WORST_SHOWN]
        t = b.t[: c.samples]
        plotted = False
        for k, e in enumerate(worst):
            err = error_series(a, b, e.column, c.samples)
            color = _COLORS[k % len(_COLORS)]
            shown = np.where(err > 0, err, np.nan)
            if np.any(np.isfinite(shown)):
                ax.plot(t, shown, color=color, lw=1.5, label=f"{e.column} (allowed {e.tol:.2g})")
                plotted = True
            if e.tol > 0:
                ax.axhline(e.tol, color=color, ls="--", lw=1.1)
        ax.set_yscale("log")
        ax.yaxis.set_major_formatter(FuncFormatter(_pow10))
        ax.yaxis.set_minor_formatter(NullFormatter())
        worst_r = _ratio(worst[0]) if worst else 0.0
        verdict = "PASS" if c.passed else "FAIL"
        ax.set_title(
            f"{c.engine} vs {c.reference}: {verdict}, worst {worst_r:.2g}× allowed",
            color="#1b6e2a" if c.passed else "#b00020",
        )
        ax.set_xlabel("t [s]")
        ax.set_ylabel("|difference|")
        if plotted:
            below = ax.transAxes + ScaledTranslation(0, -0.5, fig.dpi_scale_trans)  # under the x label, any height
            ax.legend(loc="upper left", bbox_to_anchor=(0, 0), bbox_transform=below, ncol=2, frameon=False, fontsize=9)
        else:
            ax.text(
                0.5,
                0.5,
                "identical: every difference is exactly 0",
                transform=ax.transAxes,
                ha="center",
                va="center",
                fontsize=11,
            )
        if len(t):
            ax.set_xlim(float(t[0]), float(t[-1]) if t[-1] > t[0] else float(t[0]) + 1)
    for ax in axes[len(checks) :]:
        ax.set_visible(False)
    fig.suptitle("Errors against the reference over time (dashed: each quantity's allowed error)", fontsize=12)
    fig.tight_layout()
    return _picture(fig, f"{item.name}: errors against the reference over time")


# ------------------------------------------------------------------ animation


def _animation(mech: Mechanism, geo: _Geometry, runs: list[EngineRun]) -> Image | None:
    """An animated GIF (≤ MAX_FRAMES frames) of the motion from the first engine with every joint's history."""
    from matplotlib.animation import FuncAnimation, PillowWriter
    from PIL import Image as PILImage

    need = [f"{n}.x" for n in mech.tracked_points]
    res = next(
        (r.result for r in runs if r.result is not None and len(r.result) > 1 and all(c in r.result for c in need)),
        None,
    )
    if res is None:
        return None
    frames = np.unique(np.linspace(0, len(res) - 1, min(MAX_FRAMES, len(res))).round().astype(int))
    xy = {n: res[f"{n}.x"] + 1j * res[f"{n}.y"] for n in mech.tracked_points}
    allp = np.concatenate(list(xy.values()))
    size = mech.scale
    lo = complex(allp.real.min(), allp.imag.min()) - 0.12 * size * (1 + 1j)
    hi = complex(allp.real.max(), allp.imag.max()) + 0.12 * size * (1 + 1j)
    slots = _slots(mech, res, {n: float(res[f"{n}.s"][0]) for n in mech.sliders if f"{n}.s" in res})

    def block_theta(k: int) -> dict[str, float]:
        out = dict(geo.block_theta)
        for n in mech.sliders:
            if f"{n}.theta" in res:
                out[n] = float(res[f"{n}.theta"][k])
        return out

    fig = _new_figure(5.0, 5.0 * min(max((hi - lo).imag / max((hi - lo).real, 1e-300), 0.5), 1.4))
    ax = fig.add_axes((0.02, 0.02, 0.96, 0.96))
    for n in mech.tracked_points:  # what does not move is drawn once: paths, ground pivots, frame
        ax.plot(xy[n].real, xy[n].imag, color="#c9d3e3", lw=1, zorder=0)
    _draw_ground(ax, mech, {n: complex(v[0]) for n, v in xy.items()})
    ax.set_xlim(lo.real, hi.real)
    ax.set_ylim(lo.imag, hi.imag)
    ax.set_autoscale_on(False)
    ax.set_aspect("equal", adjustable="box")
    ax.set_axis_off()
    clock = ax.text(0.02, 0.97, "", transform=ax.transAxes, va="top", fontsize=9)
    moving: list[Any] = []

    def draw(i: int) -> list:
        k = int(frames[i])
        for artist in moving:
            artist.remove()
        before = set(ax.get_children())
        pos = {n: complex(v[k]) for n, v in xy.items()}
        s_now = {n: float(res[f"{n}.s"][k]) - float(res[f"{n}.s"][0]) for n in slots}
        rel = {n: (a - s_now[n], b - s_now[n]) for n, (a, b) in slots.items()}
        _draw_mechanism(ax, mech, pos, block_theta(k), rel, labels=False, with_ground=False, lw=2.6)
        moving[:] = [a for a in ax.get_children() if a not in before]
        clock.set_text(f"{mech.name}   t = {res.t[k]:.3f} s")
        return []

    anim = FuncAnimation(fig, draw, frames=len(frames), blit=False, repeat=False)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "motion.gif"
        anim.save(path, writer=PillowWriter(fps=12), dpi=GIF_DPI)
        data = path.read_bytes()
    fig.clear()
    with PILImage.open(io.BytesIO(data)) as gif:
        w, h = gif.size
    return Image(
        "data:image/gif;base64," + base64.b64encode(data).decode("ascii"), w, h, f"{mech.name}: animation of the motion"
    )


# ------------------------------------------------------------------ tables


def _fmt(x: float) -> str:
    """Two significant digits: 0.0031, 45, 1.8e-07, 1e-09."""
    if not np.isfinite(x):
        return "∞"
    if x == 0:
        return "0"
    if 1e-3 <= abs(x) < 1e4:
        return f"{x:.2g}"
    mant, exp = f"{x:.1e}".split("e")
    return f"{mant.removesuffix('.0')}e{exp}"


def _by_group(x: float | dict[str, float] | None) -> str:
    """A per-group number as one number when every group has the same."""
    if x is None:
        return "—"
    if not isinstance(x, dict):
        return _fmt(x)
    by_value: dict[float, list[str]] = {}
    for g, v in x.items():
        by_value.setdefault(v, []).append(g)
    if len(by_value) == 1:
        return _fmt(next(iter(by_value)))
    return "\n".join(f"{_fmt(v)} ({', '.join(gs)})" for v, gs in by_value.items())


def _rtol_of(c: CheckedComparison, group: str) -> float | None:
    return c.rtol.get(group) if isinstance(c.rtol, dict) else c.rtol


def _checks_of(item: MechanismValidation, engine: str) -> list[CheckedComparison]:
    """The comparisons that judge ``engine``; a reference-only engine is judged by the closed form."""
    own = [c for c in item.checks if c.engine == engine]
    return own or [c for c in item.checks if c.reference == engine and c.engine == "analytic"]


def _worst_ratio(checks: Iterable[CheckedComparison]) -> float | None:
    ratios = [_ratio(e) for c in checks if c.comparison is not None for e in c.comparison.errors]
    return max(ratios, default=None)


def _cell(item: MechanismValidation, engine: str) -> dict[str, Any]:
    run = item.runs.get(engine)
    if run is None:
        return {"status": "—", "badge": "—", "css": "na", "ratio": "", "title": "not run"}
    checks = _checks_of(item, engine)
    worst = _worst_ratio(checks)
    failed = run.status == "error" or any(not c.passed for c in checks)
    # where the engines disagree, only the odd one out fails (validators.consensus); the others pass
    verdict = item.verdict.engines.get(engine) if item.verdict is not None else None
    if verdict in ("pass", "blamed", "undecided", "inconclusive"):
        failed = verdict != "pass" or run.status == "error"  # an engine that gave nothing is never shown passing
    css = (
        "na"
        if run.status == "skipped"
        else (verdict if verdict in ("undecided", "inconclusive") else "fail" if failed else "pass")
    )
    badge = {"na": "n/a", "fail": "error" if run.status == "error" else "blamed" if verdict == "blamed" else "fail"}
    via = ", ".join(f"vs {c.reference}" if c.engine == engine else f"closed form vs {engine}" for c in checks)
    why = item.verdict.reasons.get(engine, "") if item.verdict is not None else ""
    why = why or item.inconclusive.get(engine, "")
    return {
        "status": run.status,
        "badge": badge.get(css, css),
        "css": css,
        "ratio": "" if worst is None else _fmt(worst),
        "verdict": verdict or "",
        "title": f"run {run.status}: "
        + (why or (run.message.splitlines()[0][:200] if run.message else run.status))
        + (f" ({via})" if via else ""),
    }


def _group_rows(item: MechanismValidation) -> list[dict[str, Any]]:
    rows = []
    for c in item.checks:
        cells = []
        for g in GROUPS:
            errs = [e for e in c.comparison.errors if e.group == g] if c.comparison is not None else []
            if not errs:
                cells.append({"css": "na", "ratio": "—", "quantity": "", "rtol": _fmt(_rtol_of(c, g) or 0)})
                continue
            w = max(errs, key=_ratio)
            cells.append(
                {
                    "css": "pass" if all(e.passed for e in errs) else "fail",
                    "ratio": _fmt(_ratio(w)),
                    "quantity": w.column,
                    "abs": _fmt(w.max_abs),
                    "rtol": _fmt(_rtol_of(c, g) or 0),
                }
            )
        rows.append(
            {
                "engine": c.engine,
                "reference": c.reference,
                "samples": c.samples,
                "passed": c.passed,
                "message": c.message.replace(f"; {item.name}: ", f"\n{item.name}: "),  # one finding a line
                "cells": cells,
            }
        )
    return rows


# ------------------------------------------------------------------ assembly


def _driver_text(d: Driver) -> str:
    if d.profile is not None:
        return f"{d.symbol} from {d.profile.source}"
    if d.kind == "crank":
        return f"{d.symbol}: ω₀ = {d.v0:g} rad/s, α = {d.a0:g} rad/s²"
    return f"{d.symbol}: v₀ = {d.v0:g}, a = {d.a0:g}"


def _summary_entry(summary: dict[str, Any], item: MechanismValidation, index: int) -> dict[str, Any]:
    mechs = summary.get("mechanisms") or []
    if index < len(mechs) and mechs[index].get("name") == item.name:
        return mechs[index]
    return next((m for m in mechs if m.get("name") == item.name and m.get("file") == item.path), {})


def _anchor(name: str, index: int) -> str:
    safe = "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in name)
    return f"m{index + 1}-{safe}"


def _mechanism_section(
    item: MechanismValidation, index: int, engines: Sequence[str], summary: dict[str, Any], animate: bool
) -> dict[str, Any]:
    entry = _summary_entry(summary, item, index)
    sec: dict[str, Any] = {
        "anchor": _anchor(item.name, index),
        "name": item.name,
        "path": item.path,
        "passed": item.passed,
        "error": item.error,
        "cells": [_cell(item, e) for e in engines],
        "verdict": item.verdict.as_dict() if item.verdict is not None else None,
        "loops": entry.get("loops", "—"),
        "mobility": entry.get("mobility", "—"),
        "samples": entry.get("samples", "—"),
    }
    if item.error or item.mechanism is None:
        return sec | {"loops": "—", "mobility": "—", "samples": "—"}
    mech = item.mechanism
    if "loops" not in entry:
        L, J, M = mech.gruebler()
        sec.update(loops=J - L + 1, mobility=M, samples=len(mech.times))
    system, compile_error = _compile(mech)
    geo = _geometry(mech, system)
    runs = [item.runs[e] for e in engines if e in item.runs]
    ref = next((r.result for r in runs if r.result is not None and len(r.result)), None)
    equations, equations_error = "", compile_error
    if system is not None:
        from vloop.method.equations import describe

        try:
            equations = describe(system)
        except Exception as exc:  # the report must still be written
            equations_error = f"{type(exc).__name__}: {exc}"
    sec.update(
        title=mech.title,
        units=mech.units,
        drivers=[_driver_text(d) for d in mech.drivers],
        time=f"{mech.times[0]:g} … {mech.times[-1]:g} s" if len(mech.times) else "—",
        loop_labels=[label for label, _ in geo.loops],
        drawing=_drawing(mech, geo, ref),
        drawing_note=geo.note,
        equations=equations,
        equations_error=equations_error,
        histories=_histories(mech, runs) + _force_histories(mech, runs),
        errors=_error_figure(item),
        group_rows=_group_rows(item),
        runs=[
            {
                "engine": r.engine,
                "status": r.status,
                "samples": r.samples,
                "total": len(mech.times),
                "seconds": f"{r.seconds:.3f}",
                "message": r.message,
            }
            for r in runs
        ],
        animation=_animation(mech, geo, runs) if animate else None,
        viewer=f"{VIEWER_FOLDER}/{sec['anchor']}.html" if _viewer_source(item) else None,
    )
    return sec


def _viewer_source(item: MechanismValidation) -> tuple[Result, str | None] | None:
    """vloop's run of a mechanism for its viewer page (the samples before a stop, with the message), if any."""
    run = item.runs.get("vloop")
    if item.mechanism is None or run is None or run.result is None or not len(run.result):
        return None
    return run.result, (run.message or "motion stopped") if run.status == "stopped" else None


def write_viewer_pages(validation: Validation, out_dir: Path) -> list[Path]:
    """One interactive viewer page per mechanism vloop solved, ``out_dir/viewer/<anchor>.html``."""
    from vloop.views.view import write_view

    pages = []
    for index, item in enumerate(validation.items):
        source = _viewer_source(item)
        if source is not None:
            path = Path(out_dir) / VIEWER_FOLDER / f"{_anchor(item.name, index)}.html"
            pages.append(write_view(item.mechanism, source[0], path, error=source[1]))
    return pages


def _breakable(name: str) -> Any:
    """A name that may wrap after its underscores (a long mechanism name in a narrow column)."""
    from markupsafe import Markup, escape

    return Markup(str(escape(name)).replace("_", "_<wbr>"))


def render(validation: Validation, summary: dict[str, Any], *, animate: bool = False) -> str:
    """The report's HTML text."""
    import jinja2
    import matplotlib

    engines = list(summary.get("engines") or validation.engines)
    with matplotlib.rc_context(_RC):  # the report's look, without changing the caller's settings
        sections = [_mechanism_section(it, i, engines, summary, animate) for i, it in enumerate(validation.items)]
    created = summary.get("created") or validation.started
    try:
        created_text = _dt.datetime.fromisoformat(created).strftime("%Y-%m-%d %H:%M %Z").strip()
    except (TypeError, ValueError):
        created_text = str(created)
    tolerances = [
        {"pair": pair, "rtol": _by_group(t.get("rtol")), "floor": _by_group(t.get("floor")), "note": t.get("note", "")}
        for pair, t in (summary.get("tolerances") or {}).items()
        if all(e in engines for e in pair.split(" vs "))
    ]
    env = jinja2.Environment(
        loader=jinja2.FileSystemLoader(TEMPLATES),
        autoescape=True,
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
    )
    env.filters["breakable"] = _breakable
    return env.get_template("report.html.j2").render(
        created=created_text,
        passed=bool(summary.get("passed", validation.passed)),
        counts=_counts(summary, sections),
        overall=overall(summary),
        engines=engines,
        versions=summary.get("versions") or validation.versions,
        seconds=f"{summary.get('seconds', validation.seconds):.1f}",
        n_passed=sum(1 for s in sections if s["passed"]),
        sections=sections,
        tolerances=tolerances,
        groups=GROUPS,
        corpus=summary.get("corpus"),  # a generated corpus has its own page, corpus.html (reports/corpus.py)
        engine_rows=_engine_rows(summary, engines),
        vloop_odd=[s for s in sections if s["verdict"] and "vloop" in s["verdict"]["blamed"]],
    )


def _counts(summary: dict[str, Any], sections: list[dict[str, Any]]) -> dict[str, int]:
    """Mechanisms in the whole run and how many pass every comparison (a big corpus shows only its failures)."""
    counts = summary.get("counts")
    if counts:
        return {"total": counts["mechanisms"], "passed": counts["passed"]}
    mechs = summary.get("mechanisms")
    if mechs:
        return {"total": len(mechs), "passed": sum(1 for m in mechs if m.get("passed"))}
    return {"total": len(sections), "passed": sum(1 for s in sections if s["passed"])}


def overall(summary: dict[str, Any]) -> dict[str, str]:
    """The front verdict: FAILED when vloop may be wrong (red), PASSED FOR VLOOP when only reference engines failed
    or were inconclusive (amber, docs/validation.md's exit policy), ALL PASSED."""
    v = summary.get("verdicts") or {}
    counts = v.get("mechanisms") or {}
    bad = sum(1 for m in summary.get("mechanisms") or () if m.get("error"))
    if bad:
        return {"css": "fail", "text": "FAILED", "note": f"{bad} file{'s' if bad > 1 else ''} could not be read"}
    if summary.get("red") or (summary.get("red") is None and not summary.get("passed", True)):
        odd, undecided = len(v.get("vloop_blamed") or []), counts.get("undecided", 0)
        return {"css": "fail", "text": "FAILED", "note": f"vloop blamed on {odd}, undecided on {undecided}"}
    if not summary.get("passed", True):
        tally = v.get("engines") or {}
        parts = [
            f"{e}: {t.get('blamed', 0)} blamed, {t.get('inconclusive', 0)} inconclusive"
            for e, t in tally.items()
            if t.get("blamed") or t.get("inconclusive")
        ]
        return {"css": "warn", "text": "PASSED FOR VLOOP", "note": "reference engines failed — " + "; ".join(parts)}
    return {"css": "pass", "text": "ALL PASSED", "note": ""}


def _engine_rows(summary: dict[str, Any], engines: Sequence[str]) -> list[dict[str, Any]]:
    """Per engine: passes, blamed failures, undecided, not applicable (summary.json's verdicts)."""
    tally = (summary.get("verdicts") or {}).get("engines") or {}
    return [{"engine": e, **tally[e]} for e in engines if e in tally]


def write_report(validation: Validation, summary: dict[str, Any], out_dir: Path, *, animate: bool = False) -> Path:
    """Write ``out_dir/report.html`` (self-contained) and the viewer pages it links; return its path."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    path = out_dir / "report.html"
    path.write_text(render(validation, summary, animate=animate), encoding="utf-8")
    write_viewer_pages(validation, out_dir)  # linked from each mechanism's section
    return path
