"""The interactive viewer: one self-contained, offline HTML page per run.

The page is a pure function of the Mechanism, its Result and, optionally, its forces and an error
message. The geometry is serialized once — bodies in their local frames (plates, bars, slots), pins, ground pivots,
slider blocks and guides, the vector loops as (link, slider, r, δ) terms with their equations —
and per sample only the Result's own columns (body poses are read from them: a link's frame is
its first joint and its θ), so the numbers panel shows every sample's exact values. The columns
travel as little-endian float64, byte-shuffled, deflated and base64-encoded (the browser inflates
them with its built-in ``DecompressionStream``): an eight-bar run of 5,000 samples is ~1.3 MB.

A page is bounded by its bytes, not by a sample count: the sample data of a page is at most
``MAX_PAGE_BYTES`` (each float64 counted at its deflated-and-base64 worst case, 8 × 4/3 bytes, so the bound
holds whatever the numbers). A run with more samples than fit is solved at every requested sample (limits,
stops and change points found at the file's resolution) but the page carries every k-th of them and the last
— drawing is thinned, each number shown is a solved sample's exact value — and says so on the page.

The page's script and style live in ``vloop/views/viewer/`` and are inlined at render time; a
Content-Security-Policy (``default-src 'none'``, the script allowed by its hash) forbids any
network request from the page.

``forces`` (optional, duck-typed): ``.t`` (the same samples), ``.columns`` (name → array; driver
columns ``LINK.torque`` [N·m] / ``SLIDER.force`` [N], pin reactions ``JOINT:FROM>ON.fx|fy|mag`` [N],
``SLIDER.normal``, ``SLIDER.moment``, ``shaking.fx|fy|moment``) and ``.arrows`` (list of
``(point, fx_column, fy_column, label)``): reaction arrows at the joints and a driver plot.
"""

from __future__ import annotations

import base64
import hashlib
import html
import json
import math
import re
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import MotionError, VloopError
from ..model import Mechanism
from ..result import Result
from .geometry import BLOCK_SIZE, equation_legend, loop_chains

ASSETS = Path(__file__).resolve().parent / "viewer"
_PLACEHOLDER = re.compile(r"__CSP__|__TITLE__|__HEADING__|__NAME__|/\*__CSS__\*/|__DATA__|/\*__JS__\*/")
FORMAT = 1
MAX_PAGE_BYTES = 32 << 20  # the sample data of one page, at most: a browser opens it in a few seconds
VALUE_BYTES = 8 * 4 / 3 * 1.001  # a float64 in the page, worst case: incompressible, deflate's 0.1 % framing, base64
HEALTH = ("residual", "cond")


class ViewError(VloopError):
    """The page cannot be built from this data (the message names the quantity and sample)."""


# ------------------------------------------------------------------ solving for a page


def solve_for_view(mech: Mechanism) -> tuple[Result, str | None]:
    """Solve the file's motion for a page: (Result, None), or (the samples before a stop, its message).

    The page's size is checked before solving (:func:`page_every`): a run too long for one page is solved chunk
    by chunk at every requested sample and only the samples the page carries are kept (``meta["page"]`` says
    which). Where a motion stops before its first sample, the page shows the t = 0 assembly instead.
    """
    from ..compiler import compile_system
    from ..core.solver import solve
    from ..files.budget import columns

    system = compile_system(mech)
    every = page_every(len(mech.times), columns(system) + len(HEALTH))
    try:
        return (solve(system), None) if every == 1 else (_thinned_run(system, every), None)
    except MotionError as exc:
        partial = exc.partial
        if partial is None or not len(partial):
            partial = solve(system, times=np.zeros(1))
            return partial, f"{exc} (no requested sample could be solved: shown at the t = 0 assembly)"
        return partial, str(exc)


def page_every(samples: int, n_columns: int) -> int:
    """Carry every k-th sample (and the last) so that ``n_columns`` float64 columns fit in MAX_PAGE_BYTES; k ≥ 1."""
    fit = max(int(MAX_PAGE_BYTES // (max(n_columns, 1) * VALUE_BYTES)), 2)
    return 1 if samples <= fit else math.ceil((samples - 1) / (fit - 1))


def page_rows(samples: int, every: int) -> np.ndarray:
    """The samples a page carries: 0, k, 2k, … and the last."""
    rows = np.arange(0, samples, every)
    return rows if rows[-1] == samples - 1 else np.append(rows, samples - 1)


def _thinned_run(system: Any, every: int) -> Result:
    """Solve every sample in chunks, keeping the page's rows (every k-th, and the last solved); a stop raises
    MotionError whose ``partial`` holds the kept rows up to the last solved sample."""
    from ..core.solver import solve_iter

    kept: list[Result] = []
    done = 0
    last: Result | None = None
    try:
        for part in solve_iter(system):
            kept.append(_rows(part, done, every))
            done, last = done + len(part), part
    except MotionError as exc:
        part = exc.partial
        if part is not None and len(part):
            kept.append(_rows(part, done, every))
            done, last = done + len(part), part
        exc.partial = _with_last(kept, last, done, every) if kept and last is not None else exc.partial
        raise
    return _with_last(kept, last, done, every)


def _rows(part: Result, start: int, every: int) -> Result:
    """The rows of a chunk (its first sample numbered ``start``) that fall on the page's grid."""
    take = np.nonzero((start + np.arange(len(part))) % every == 0)[0]
    return _take(part, take)


def _take(res: Result, rows: np.ndarray) -> Result:
    return Result(
        res.mechanism,
        res.engine,
        res.t[rows],
        {k: v[rows] for k, v in res.columns.items()},
        {k: v[rows] for k, v in res.health.items()},
        dict(res.meta),
    )


def _with_last(kept: list[Result], last: Result, done: int, every: int) -> Result:
    """The kept rows joined, the last solved sample added if the grid missed it, and what was kept said in meta."""
    from ..core.solver import join

    if (done - 1) % every:
        kept = [*kept, _take(last, np.array([len(last) - 1]))]
    out = join([k for k in kept if len(k)])
    out.meta = {**last.meta, "page": {"every": every, "of": done}}
    return out


# ------------------------------------------------------------------ page data


def build_payload(
    mech: Mechanism,
    result: Result,
    *,
    forces: Any = None,
    error: str | None = None,
    system: Any = None,
    targets: Any = None,
) -> dict[str, Any]:
    """Everything the page draws, as plain JSON-ready data (see the module docstring).

    Lengths in the file's units, angles in rad (CCW from +x), time in s, forces in N and N·m. ``targets``: a
    synthesis's precision positions, drawn as numbered crosses: ``(x, y)`` points or ``(x, y, angle)`` poses.
    """
    from ..compiler import compile_system

    if not len(result):
        raise ViewError(f"{mech.name}: the result has no sample to show")
    system = system if system is not None else compile_system(mech)
    names, matrix = _columns(mech, result, forces)
    matrix, thinned = _fit_page(matrix, result.meta.get("page"))
    chains = loop_chains(system, result)
    bodies = mech.bodies()
    slots = _slots(mech, result, bodies)
    return {
        "format": FORMAT,
        "name": mech.name,
        "title": mech.title,
        "units": mech.units,
        "scale": mech.scale,
        "error": error or None,
        "samples": matrix.shape[1],
        "thinned": thinned,
        "data": {"columns": names, "encoding": "f64le-shuffle-deflate-base64", "data": _pack(matrix)},
        "bodies": [_body(mech, b, slots) for b in bodies.values()],
        "joints": _joints(mech),
        "labels": _label_directions(mech, result),
        "sliders": [_slider(mech, name, slots[name]) for name in mech.sliders],
        "block": [BLOCK_SIZE[0] * mech.scale, BLOCK_SIZE[1] * mech.scale],
        "loops": [_loop(c) for c in chains],
        "legend": equation_legend(system),
        "links": [n for n, lk in mech.links.items() if not lk.ground],
        "slider_names": list(mech.sliders),
        "points": list(mech.tracked_points),
        "tracers": list(mech.points),
        "drivers": [{"kind": d.kind, "target": d.target, "symbol": d.symbol} for d in mech.drivers],
        "forces": _forces_meta(mech, forces),
        "targets": _targets(mech, targets),
    }


def _fit_page(matrix: np.ndarray, page: dict | None) -> tuple[np.ndarray, dict | None]:
    """The page's columns thinned to MAX_PAGE_BYTES (every k-th sample and the last), and what a note on the page
    says: ``{"every": k, "shown": samples carried, "of": samples solved}`` (None: every sample is there)."""
    n_cols, n = matrix.shape
    every = page_every(n, n_cols)
    if every > 1:
        matrix = matrix[:, page_rows(n, every)]
    before = page or {"every": 1, "of": n}
    total = before["every"] * every
    if total == 1:
        return matrix, None
    return matrix, {"every": total, "shown": matrix.shape[1], "of": before["of"]}


def _targets(mech: Mechanism, targets: Any) -> list[dict[str, float]]:
    """Target points or poses as {x, y[, angle]} (finite numbers only)."""
    out = []
    for k, t in enumerate(targets if targets is not None else ()):
        vals = [float(v) for v in t]
        if len(vals) not in (2, 3) or not all(math.isfinite(v) for v in vals):
            raise ViewError(f"{mech.name}: target {k + 1} must be 2 or 3 finite numbers (x, y[, angle]), got {t!r:.60}")
        out.append(dict(zip(("x", "y", "angle"), vals, strict=False)))
    return out




def _columns(mech: Mechanism, result: Result, forces: Any) -> tuple[list[str], np.ndarray]:
    """Every column the page shows, checked finite: t, the Result's, health, forces (``force:NAME``)."""
    names = ["t", *result.columns]
    arrays = [result.t, *result.columns.values()]
    for key in HEALTH:
        if key in result.health:
            names.append(f"health.{key}")
            arrays.append(result.health[key])
    if forces is not None:
        _check_forces(mech, result, forces)
        for key, col in forces.columns.items():
            names.append(f"force:{key}")
            arrays.append(col)
    matrix = np.empty((len(names), len(result)))
    for k, (name, arr) in enumerate(zip(names, arrays, strict=True)):
        arr = _floats(mech, name, arr)
        if arr.shape != (len(result),):
            raise ViewError(f"{mech.name}: {name} has shape {arr.shape}, expected ({len(result)},)")
        bad = np.flatnonzero(~np.isfinite(arr))
        if len(bad):
            i = int(bad[0])
            raise ViewError(f"{mech.name}: {name} is not finite at sample {i} (t = {result.t[i]:.6g} s): {arr[i]}")
        matrix[k] = arr
    return names, matrix


def _pack(matrix: np.ndarray) -> str:
    """float64 little-endian, column after column, byte-shuffled (byte k of every value together), deflated."""
    raw = np.ascontiguousarray(matrix, dtype="<f8").view(np.uint8).reshape(-1, 8)
    return base64.b64encode(zlib.compress(np.ascontiguousarray(raw.T).tobytes(), 9)).decode("ascii")


def unpack(data: dict[str, Any]) -> dict[str, np.ndarray]:
    """The inverse of the page's data encoding (for tests and tools): column name → float64 array."""
    raw = np.frombuffer(zlib.decompress(base64.b64decode(data["data"])), np.uint8)
    values = raw.reshape(8, -1).T.copy().view("<f8").ravel()
    n = len(values) // max(len(data["columns"]), 1)
    return {name: values[k * n : (k + 1) * n] for k, name in enumerate(data["columns"])}


def _body(mech: Mechanism, body: Any, slots: dict[str, dict[str, Any]]) -> dict[str, Any]:
    """A body in its own frame: members (joints and points), the outline to draw, slots it carries."""
    local = {k: [float(x), float(y)] for k, (x, y) in body.local.items()}
    carried = [name for name, sl in mech.sliders.items() if sl.guide == body.name]
    outline_pts = [tuple(p) for p in local.values()]
    if body.kind == "link":  # a slotted link reaches over its slot
        outline_pts += [tuple(p) for name in carried for p in slots[name]["ends"]]
    return {
        "name": body.name,
        "kind": body.kind,
        "origin": body.joints[0] if body.kind != "ground" else None,
        "local": local,
        "outline": _outline(outline_pts, mech.scale) if body.kind == "link" else [],
        "slots": carried if body.kind == "link" else [],
        "label": _label_point(local, mech.scale) if body.kind == "link" else None,
    }


def _outline(points: list[tuple[float, float]], scale: float) -> list[list[float]]:
    """Convex hull (counter-clockwise) of a body's points; the two extreme points when they are collinear."""
    pts = sorted(set(points))
    if len(pts) <= 2:
        return [list(p) for p in pts]

    def cross(o: tuple, a: tuple, b: tuple) -> float:
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower: list[tuple] = []
    upper: list[tuple] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    hull = lower[:-1] + upper[:-1]
    area = 0.5 * abs(sum(cross(hull[0], hull[i], hull[i + 1]) for i in range(1, len(hull) - 1)))
    span = max(math.dist(a, b) for a in hull for b in hull)
    if len(hull) < 3 or area < 0.02 * span * span:  # a thin sliver reads better as a bar
        a, b = max(((a, b) for a in pts for b in pts), key=lambda ab: math.dist(*ab))
        return [list(a), list(b)]
    return [list(p) for p in hull]


def _label_point(local: dict[str, list[float]], scale: float) -> list[float]:
    """Where a link's name sits in its frame: beside its middle, off the bar, on its right-hand side
    (the loop letters sit on the left of vectors that run along θ)."""
    xs = [p[0] for p in local.values()]
    ys = [p[1] for p in local.values()]
    return [sum(xs) / len(xs), sum(ys) / len(ys) - 0.035 * scale]


def _joints(mech: Mechanism) -> list[dict[str, Any]]:
    """Every joint and tracer point: a pin (two or more bodies), a ground pivot, or a point of one body."""
    ground = mech.links[mech.ground].joints
    out = []
    for name in mech.tracked_points:
        bodies = list(mech.bodies_at(name)) if name in mech.joints else [mech.points[name].link]
        kind = "pin" if len(bodies) >= 2 else "point"
        out.append({"name": name, "kind": kind, "ground": name in ground and len(bodies) >= 2, "bodies": bodies})
    return out


def _label_directions(mech: Mechanism, result: Result) -> dict[str, list[float]]:
    """A unit direction per point for its label: away from the mechanism's middle at the first sample."""
    pos = {p: complex(result[f"{p}.x"][0], result[f"{p}.y"][0]) for p in mech.tracked_points}
    centre = sum(pos.values()) / max(len(pos), 1)
    out = {}
    for p, z in pos.items():
        d = z - centre
        d = d / abs(d) if abs(d) > 1e-9 * mech.scale else 1j
        out[p] = [d.real, d.imag]
    return out


def _slots(mech: Mechanism, result: Result, bodies: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Each slider's guide line in its guide's frame, over the travel of the run (plus the block and a margin)."""
    from .geometry import body_poses

    poses = body_poses(mech, result)
    out = {}
    for name, sl in mech.sliders.items():
        g = bodies[sl.guide]
        c0, s0 = math.cos(g.theta0), math.sin(g.theta0)
        px, py = mech.joints[sl.joint][0] - g.origin[0], mech.joints[sl.joint][1] - g.origin[1]
        through = (c0 * px + s0 * py, -s0 * px + c0 * py)  # the sliding line's point, guide frame
        alpha = math.atan2(sl.axis[1], sl.axis[0]) - g.theta0
        u = (math.cos(alpha), math.sin(alpha))
        x, y, th = poses[sl.guide].T
        dx, dy = result[f"{sl.joint}.x"] - x, result[f"{sl.joint}.y"] - y
        lx, ly = np.cos(th) * dx + np.sin(th) * dy, -np.sin(th) * dx + np.cos(th) * dy
        tau = (lx - through[0]) * u[0] + (ly - through[1]) * u[1]
        reach = 0.5 * BLOCK_SIZE[0] * mech.scale + 0.04 * mech.scale
        lo, hi = float(tau.min()) - reach, float(tau.max()) + reach
        ends = [[through[0] + t * u[0], through[1] + t * u[1]] for t in (lo, hi)]
        out[name] = {"guide": sl.guide, "ends": ends, "axis": list(u)}
    return out


def _slider(mech: Mechanism, name: str, slot: dict[str, Any]) -> dict[str, Any]:
    sl = mech.sliders[name]
    return {
        "name": name,
        "joint": sl.joint,
        "guide": sl.guide,
        "ground": mech.links[sl.guide].ground,
        "ends": slot["ends"],
        "axis": slot["axis"],
    }


def _loop(chain: Any) -> dict[str, Any]:
    return {
        "number": chain.number,
        "label": chain.label,
        "equation": chain.equation,
        "start": chain.start,
        "joints": [list(j) for j in chain.joints],
        "vectors": [
            {"letter": v.letter, "link": v.link, "slider": v.slider, "r": v.r, "delta": v.delta} for v in chain.vectors
        ],
    }


# ------------------------------------------------------------------ forces


def _check_forces(mech: Mechanism, result: Result, forces: Any) -> None:
    """The forces belong to this run: the same samples, named columns, arrows at known points."""
    t = _floats(mech, "forces.t", forces.t)
    gap = np.max(np.abs(t - result.t), initial=0.0) if t.shape == result.t.shape else np.inf
    if not gap <= 1e-9 * (1 + np.abs(result.t).max()):  # also refuses NaN
        raise ViewError(f"{mech.name}: the forces are not given at the result's {len(result)} samples")
    if not isinstance(forces.columns, dict) or not all(isinstance(k, str) for k in forces.columns):
        raise ViewError(f"{mech.name}: forces.columns must map column names to arrays")
    for k, arrow in enumerate(getattr(forces, "arrows", ())):
        if not isinstance(arrow, (tuple, list)) or len(arrow) != 4 or not all(isinstance(a, str) for a in arrow):
            raise ViewError(
                f"{mech.name}: force arrow {k}: expected (point, fx column, fy column, label), got {arrow!r}"
            )
        point, fx, fy, _label = arrow
        if point not in mech.tracked_points:
            raise ViewError(f"{mech.name}: force arrow at {point!r}: no such joint or point")
        for col in (fx, fy):
            if col not in forces.columns:
                raise ViewError(f"{mech.name}: force arrow at {point}: no column {col!r} in the forces")


def _floats(mech: Mechanism, name: str, values: Any) -> np.ndarray:
    try:
        return np.asarray(values, float)
    except (TypeError, ValueError, OverflowError):
        raise ViewError(f"{mech.name}: {name} is not an array of numbers") from None


def _force_unit(name: str) -> str:
    return "N·m" if name.endswith((".torque", ".moment")) else "N"


def _forces_meta(mech: Mechanism, forces: Any) -> dict[str, Any] | None:
    if forces is None:
        return None
    cols = list(forces.columns)
    drivers = []
    for d in mech.drivers:
        col = f"{d.target}.torque" if d.kind == "crank" else f"{d.target}.force"
        if col in forces.columns:
            what = "torque" if d.kind == "crank" else "force"
            drivers.append({"column": col, "label": f"driver {what} on {d.target}", "unit": _force_unit(col)})
    shaking = [c for c in ("shaking.fx", "shaking.fy") if c in forces.columns]
    return {
        "columns": cols,
        "units": {c: _force_unit(c) for c in cols},
        "arrows": [list(a) for a in getattr(forces, "arrows", ())],
        "drivers": drivers,
        "shaking": shaking,
    }


# ------------------------------------------------------------------ the page


def _asset(name: str) -> str:
    return (ASSETS / name).read_text(encoding="utf-8")


def _json_for_script(data: dict[str, Any]) -> str:
    """JSON that cannot close its <script> element nor start a comment (``<``, ``>``, ``&`` escaped)."""
    text = json.dumps(data, allow_nan=False, ensure_ascii=False, separators=(",", ":"))
    return text.replace("<", "\\u003c").replace(">", "\\u003e").replace("&", "\\u0026")


def render(
    mech: Mechanism,
    result: Result,
    *,
    forces: Any = None,
    error: str | None = None,
    system: Any = None,
    targets: Any = None,
) -> str:
    """The viewer page (one HTML string, no external resource)."""
    payload = build_payload(mech, result, forces=forces, error=error, system=system, targets=targets)
    script = _asset("viewer.js")
    digest = base64.b64encode(hashlib.sha256(script.encode("utf-8")).digest()).decode("ascii")
    csp = f"default-src 'none'; script-src 'sha256-{digest}'; style-src 'unsafe-inline'; img-src data:"
    values = {
        "__CSP__": html.escape(csp, quote=False).replace('"', "&quot;"),  # in a "…" attribute
        "__TITLE__": html.escape(f"{mech.name} — vloop viewer"),
        "__HEADING__": html.escape(mech.title or mech.name),
        "__NAME__": html.escape(mech.name),
        "/*__CSS__*/": _asset("viewer.css"),
        "__DATA__": _json_for_script(payload),
        "/*__JS__*/": script,
    }
    # one pass over the template: text put in is never searched again for placeholders
    return _PLACEHOLDER.sub(lambda m: values[m.group(0)], _asset("page.html"))


class InlineView:
    """A viewer page for a notebook's output cell: Jupyter shows ``_repr_html_``, an iframe that holds the page in
    ``srcdoc`` and is sandboxed to scripts only (an opaque origin: no network, no access to the notebook)."""

    def __init__(self, page: str, height: int = 720) -> None:
        self.page = page
        self.height = height

    def _repr_html_(self) -> str:
        return (
            f'<iframe title="vloop viewer" sandbox="allow-scripts" style="width: 100%; height: {self.height}px; '
            f'border: 0" srcdoc="{html.escape(self.page, quote=True)}"></iframe>'
        )


def inline(
    mech: Mechanism, result: Result | None = None, *, forces: Any = None, error: str | None = None, height: int = 720
) -> InlineView:
    """The interactive viewer of a run, inline in a notebook (``vloop.views.view.inline(mech, res)`` as a cell's last
    line). Without ``result`` the file's motion is solved (a stopped motion shows its last instant and message).
    ``height`` [px] of the cell's frame, 200 to 4000."""
    if isinstance(height, bool) or not isinstance(height, int) or not 200 <= height <= 4000:
        raise ViewError(f"{mech.name}: height must be a whole number of pixels from 200 to 4000, got {height!r}")
    if result is None:
        result, error = solve_for_view(mech)
    return InlineView(render(mech, result, forces=forces, error=error), height)


def write_view(
    mech: Mechanism,
    result: Result,
    path: str | Path,
    *,
    forces: Any = None,
    error: str | None = None,
    system: Any = None,
    targets: Any = None,
) -> Path:
    """Write the viewer page to ``path`` atomically (through :mod:`vloop.files.output`) and return the path."""
    from ..files.output import write_text

    return write_text(path, render(mech, result, forces=forces, error=error, system=system, targets=targets))
