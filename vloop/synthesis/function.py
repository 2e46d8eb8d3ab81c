"""Function generation: a linkage whose output follows y = f(x) as its input follows x.

**Four-bar (Freudenstein).** Ground pivots O2 = (0, 0) and O4 = (d, 0); crank a = O2A at θ2, coupler b = AB,
rocker c = O4B at θ4 (angles from the ground line, CCW). The loop a·e^{jθ2} + b·e^{jθ3} − c·e^{jθ4} − d = 0,
with θ3 eliminated (|b·e^{jθ3}|² = |c·e^{jθ4} + d − a·e^{jθ2}|²), gives Freudenstein's equation

    K1·cos θ4 − K2·cos θ2 + K3 = cos(θ2 − θ4),   K1 = d/a,  K2 = d/c,  K3 = (a² − b² + c² + d²)/(2ac),

linear in K1, K2, K3: three precision pairs (θ2k, θ4k) solve it exactly, more by least squares. Then
a = d/K1, c = d/K2, b² = a² + c² + d² − 2ac·K3. A negative a (or c) is a crank (rocker) pointing the other
way: the linkage is built with A = a·e^{jθ2} (B = O4 + c·e^{jθ4}) as the signs say.

**Slider-crank.** Crank a = O2A at θ, rod b = AB, slider pin B = (s, e) on a line parallel to x at offset e:
(s − a·cos θ)² + (a·sin θ − e)² = b², i.e. K1·s·cos θ + K2·sin θ − K3 = s² with K1 = 2a, K2 = 2ae,
K3 = a² + e² − b² (linear again): a = K1/2, e = K2/K1, b² = a² + e² − K3.

**Mapping.** x in [x0, xf] ↦ θ2 = θs + (x − x0)/(xf − x0)·(θf − θs); y ↦ output = os + (y − y0)/(yf − y0)·(of − os)
with y0 = f(x0), yf = f(xf) unless given. Precision x by Chebyshev spacing x_j = (x0 + xf)/2 −
(xf − x0)/2·cos((2j − 1)π/(2n)), j = 1..n, evenly spaced, or given. The input turns at 1 rad/s: the instant of
a precision point is its input angle from θs. The structural error y(x) − f(x) is measured over the range by
re-solving the linkage with vloop.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence

import numpy as np

from ..errors import MotionError, SynthesisError
from . import arguments as args
from .candidates import Candidates, Task
from .circuits import arcs, classify, swept
from .defects import Draft, Requirements, assess
from .domain import check_bounded
from .expression import Expression, parse
from .linkages import FOURBAR, SLIDER_CRANK, Topology, reanchored

SPACINGS = ("chebyshev", "even")
MAX_RATIO = 1e6  # a crank or rocker longer than this many grounds is a linkage at infinity, not a design
LINKAGES = ("fourbar", "slider-crank")


def chebyshev(x0: float, xf: float, n: int) -> np.ndarray:
    """Chebyshev spacing of n precision points over [x0, xf] (ascending when x0 < xf)."""
    j = np.arange(1, n + 1)
    return 0.5 * (x0 + xf) - 0.5 * (xf - x0) * np.cos((2 * j - 1) * math.pi / (2 * n))


def freudenstein(theta2: np.ndarray, theta4: np.ndarray) -> np.ndarray:
    """K1, K2, K3 of Freudenstein's equation through the pairs (θ2, θ4) [rad]: exact for three, least squares for
    more (SynthesisError when the pairs do not determine them)."""
    M = np.stack([np.cos(theta4), -np.cos(theta2), np.ones_like(theta2)], 1)
    return _solve(M, np.cos(theta2 - theta4), "Freudenstein's equation")


def fourbar_lengths(K: np.ndarray, d: float) -> tuple[float, float, float]:
    """(a, b, c) from Freudenstein's coefficients and the ground length d (a, c signed; b > 0)."""
    K1, K2, K3 = (float(k) for k in K)
    if K1 == 0 or K2 == 0:
        raise SynthesisError("no four-bar: a Freudenstein coefficient is zero (a crank or rocker of infinite length)")
    a, c = d / K1, d / K2
    if max(abs(a), abs(c)) > MAX_RATIO * d:
        raise SynthesisError(
            f"no four-bar: the precision pairs ask for a {'crank' if abs(a) >= abs(c) else 'rocker'} "
            f"{max(abs(a), abs(c)) / d:.3g} times the ground (an output that follows the input in step: a linkage at "
            "infinity); choose other pairs or ranges"
        )
    b2 = a * a + c * c + d * d - 2 * a * c * K3
    if not b2 > 0:
        raise SynthesisError(f"no four-bar through these precision points: the coupler's length² is {b2:.4g} ≤ 0")
    return a, math.sqrt(b2), c


def slider_crank(theta: np.ndarray, s: np.ndarray) -> tuple[float, float, float]:
    """(a, b, e) of the offset slider-crank through the pairs (θ [rad], s [length]): crank, rod, offset."""
    M = np.stack([s * np.cos(theta), np.sin(theta), -np.ones_like(theta)], 1)
    K1, K2, K3 = (float(k) for k in _solve(M, s * s, "the slider-crank's equation"))
    if K1 == 0:
        raise SynthesisError("no slider-crank through these precision points: the crank's length comes out zero")
    a, e = K1 / 2, K2 / K1
    b2 = a * a + e * e - K3
    if not b2 > 0:
        raise SynthesisError(f"no slider-crank through these precision points: the rod's length² is {b2:.4g} ≤ 0")
    return a, math.sqrt(b2), e


def _solve(M: np.ndarray, rhs: np.ndarray, what: str) -> np.ndarray:
    if np.linalg.matrix_rank(M, tol=1e-12 * max(1.0, float(np.max(np.abs(M))))) < 3:
        raise SynthesisError(f"the precision points do not determine {what}'s three coefficients (dependent rows)")
    if len(M) == 3:
        return np.linalg.solve(M, rhs)
    return np.linalg.lstsq(M, rhs, rcond=None)[0]


def function(
    f: Callable[[np.ndarray], np.ndarray] | str | None = None,
    *,
    x_range: tuple[float, float] | None = None,
    input_range: tuple[float, float] | None = None,
    output_range: tuple[float, float] | None = None,
    y_range: tuple[float, float] | None = None,
    points: int = 3,
    spacing: str = "chebyshev",
    precision: Sequence[float] | None = None,
    pairs: Sequence[tuple[float, float]] | None = None,
    linkage: str = "fourbar",
    ground: float = 1.0,
    samples: int = 201,
    requirements: Requirements | None = None,
    name: str = "function",
    units: str = "m",
) -> Candidates:
    """A function generator: y = f(x) on ``x_range`` by the input over ``input_range`` [rad] and the output over
    ``output_range`` (a four-bar's rocker angle [rad]; a slider-crank's slider position [length]); or directly
    through precision ``pairs`` (input [rad], output). ``ground``: O2O4 [length] of a four-bar. Returns the
    candidate, re-solved: errors at the precision points, structural error over the range (``samples``)."""
    started = time.perf_counter()
    _arguments(f, x_range, input_range, output_range, y_range, points, spacing, precision, pairs, linkage)
    args.common(name, units, requirements)
    args.limited(ground, "ground", "function.ground")
    args.count(samples, "samples", "function.samples")
    setup = _setup(f, x_range, input_range, output_range, y_range, points, spacing, precision, pairs, linkage)
    th, out = setup["theta"], setup["output"]
    top, coords, output = _linkage(linkage, th[0], out[0], th, out, ground)
    ts, tf = setup["input_range"]
    direction = 1.0 if tf >= ts else -1.0
    verdict = classify(top, _configs(top, coords, th, out), direction)
    t = direction * (th - ts)
    span = direction * (tf - ts)
    mech0 = top.mechanism(coords, name=name, omega=direction, times=np.array([0.0]), units=units)
    notes = _sweep_note(top, coords, th[0], ts, tf) if not verdict.kind else ()
    try:
        mech = reanchored(mech0, top, -float(t[0]), np.array([0.0]))
    except MotionError as exc:  # the range's start is beyond a limit of the motion from the first point
        mech = mech0
        notes = notes or (f"branch defect: the input range's start cannot be reached from the first point ({exc})",)
        t, span = t - t[0], span - float(t[0])
    task = Task("function", setup["scale"], len(th) == 3, outputs=_physical(out, coords, top), output=output,
                units=units, scale="the output's range")  # fmt: skip
    draft = Draft(f"{name}_1", "function", top, mech, t, span, notes=notes, verdict=verdict)
    cand = assess(draft, task, requirements or Requirements())
    if notes and "branch" not in cand.defects:
        cand.defects = (*cand.defects, "branch")
    cand.guided = "rocker" if top.name == "fourbar" else "slider"
    cand.notes = (*cand.notes, *_flipped(coords, th[0], out[0], top))
    if setup["f"] is not None:
        _structural(cand, setup, samples, direction)
    return Candidates(task, [cand], time.perf_counter() - started).keep(name)


def _configs(top: Topology, coords: dict[str, complex], th: np.ndarray, out: np.ndarray) -> list[dict[str, complex]]:
    """The linkage at each precision pair as the method means it: the crank turned by the input's increment, the
    rocker by the output's (a slider moved along +x by it)."""
    turn = np.exp(1j * (th - th[0]))
    if top.sliders:
        moved = coords["B"] + (out - out[0])
    else:
        moved = coords["O4"] + (coords["B"] - coords["O4"]) * np.exp(1j * (out - out[0]))
    return [{**coords, "A": coords["A"] * turn[k], "B": complex(moved[k])} for k in range(len(th))]


def _sweep_note(top: Topology, coords: dict[str, complex], th1: float, ts: float, tf: float) -> tuple[str, ...]:
    """A branch defect's note when the input range runs into a limit of the crank (a toggle between positions)."""
    rng = arcs(top, coords)
    start = float(np.angle(coords["A"])) + ts - th1
    ends = swept(rng, start, start + tf - ts)
    if ends is None:
        return ()
    at = float(rng.psi(np.array([start]))[0])
    lo, hi = (math.degrees(ts + v - rng.phase - at) for v in ends)
    return (
        f"branch defect: the input range [{math.degrees(ts):.2f}°, {math.degrees(tf):.2f}°] runs into a limit of "
        f"the crank, which rocks between {lo:.2f}° and {hi:.2f}° (in the input's angles)",
    )


def _arguments(f, x_range, input_range, output_range, y_range, points, spacing, precision, pairs, linkage) -> None:
    """Each argument's type and range (vloop.synthesis.arguments), before any work."""
    args.choice(linkage, "linkage", LINKAGES)
    out_bound = args.MAX_ANGLE if linkage == "fourbar" else args.MAX_LENGTH
    if pairs is not None:
        args.rows(pairs, "pairs", 3, 1000, (("input", args.MAX_ANGLE), ("output", out_bound)))
    else:
        if f is not None:
            args.function_of_x(f)
        for value, where, bound in (
            (x_range, "x_range", 1e300), (input_range, "input_range", args.MAX_ANGLE),
            (output_range, "output_range", out_bound), (y_range, "y_range", 1e300),
        ):  # fmt: skip
            if value is not None:
                args.pair(value, where, bound)
    if input_range is not None:
        args.pair(input_range, "input_range", args.MAX_ANGLE)
    args.count(points, "points", "function.points")
    args.choice(spacing, "spacing", SPACINGS)
    if precision is not None:
        args.table(precision, "precision", "a list of x values")


def _setup(f, x_range, input_range, output_range, y_range, points, spacing, precision, pairs, linkage) -> dict:
    """The precision pairs (input θ [rad], output) and the mapping, checked."""
    if linkage not in LINKAGES:
        raise SynthesisError(f"[function] linkage must be one of {', '.join(LINKAGES)}, got {linkage!r}")
    if pairs is not None:
        P = np.asarray(pairs, float)
        if P.ndim != 2 or P.shape[1] != 2 or len(P) < 3 or not np.all(np.isfinite(P)):
            raise SynthesisError("[function] pairs must be at least three finite [input, output] pairs")
        if not np.ptp(P[:, 1]) > 0 or not np.ptp(P[:, 0]) > 0:
            raise SynthesisError("[function] pairs: the inputs, and the outputs, must not all be the same")
        rng = input_range or (float(P[0, 0]), float(P[-1, 0]))
        return {"f": None, "theta": P[:, 0], "output": P[:, 1], "input_range": rng, "scale": float(np.ptp(P[:, 1]))}
    if f is None or x_range is None or input_range is None or output_range is None:
        raise SynthesisError("[function] give the function with x_range, input_range and output_range (or pairs)")
    fn = parse(f) if isinstance(f, str) else f
    x0, xf = (float(v) for v in x_range)
    if not (math.isfinite(x0) and math.isfinite(xf)) or x0 == xf:
        raise SynthesisError(f"[function] x_range must be two different finite numbers, got {x_range}")
    if isinstance(fn, Expression):  # found from the expression: its poles and domain over the whole range
        check_bounded(fn.tree, x0, xf, fn.text)
    xs = _precision_x(x0, xf, points, spacing, precision)
    dense = np.linspace(x0, xf, 1001)
    yd = np.asarray(fn(np.concatenate([dense, xs])), float)
    if yd.shape != (len(dense) + len(xs),) or not np.all(np.isfinite(yd)):
        bad = np.concatenate([dense, xs])[~np.isfinite(np.broadcast_to(yd, (len(dense) + len(xs),)))]
        where = f" (at x = {bad[0]:.6g})" if len(bad) else ""
        raise SynthesisError(f"[function] f is not defined (finite) over x in [{x0:g}, {xf:g}]{where}")
    y0, yf = (
        (float(v) for v in y_range)
        if y_range is not None
        else (float(fn(np.array([x0]))[0]), float(fn(np.array([xf]))[0]))
    )
    if not (math.isfinite(y0) and math.isfinite(yf)) or abs(yf - y0) <= 1e-12 * float(np.max(np.abs(yd))):
        raise SynthesisError(
            f"[function] f takes the same value at both ends of the range: give y_range (got {y0:g}, {yf:g})"
        )
    (ts, tf), (os_, of) = _pair(input_range, "input_range"), _pair(output_range, "output_range")
    ys = yd[len(dense) :]
    theta = ts + (xs - x0) / (xf - x0) * (tf - ts)
    output = os_ + (ys - y0) / (yf - y0) * (of - os_)
    return {"f": fn, "theta": theta, "output": output, "input_range": (ts, tf), "x": (x0, xf), "y": (y0, yf),
            "output_range": (os_, of), "scale": abs(of - os_)}  # fmt: skip


def _pair(v: object, what: str) -> tuple[float, float]:
    try:
        a, b = (float(x) for x in v)  # type: ignore[union-attr]
    except (TypeError, ValueError, OverflowError):
        raise SynthesisError(f"[function] {what} must be two numbers [start, stop], got {v!r:.60}") from None
    if not (math.isfinite(a) and math.isfinite(b)) or a == b:
        raise SynthesisError(f"[function] {what} must be two different finite numbers, got [{a:g}, {b:g}]")
    return a, b


def _precision_x(x0: float, xf: float, n: int, spacing: str, precision: Sequence[float] | None) -> np.ndarray:
    if precision is not None:
        xs = np.asarray(precision, float)
        lo, hi = min(x0, xf), max(x0, xf)
        if xs.ndim != 1 or len(xs) < 3 or not np.all(np.isfinite(xs)) or np.any((xs < lo) | (xs > hi)):
            raise SynthesisError(f"[function] precision must be at least three x values inside [{lo:g}, {hi:g}]")
        if len(np.unique(xs)) != len(xs):
            raise SynthesisError("[function] precision x values must be distinct")
        return np.sort(xs) if xf > x0 else np.sort(xs)[::-1]
    if isinstance(n, bool) or not isinstance(n, int) or not 3 <= n <= 1000:
        raise SynthesisError(f"[function] points must be an integer from 3 to 1000, got {n!r:.40}")
    if spacing not in SPACINGS:
        raise SynthesisError(f"[function] spacing must be one of {', '.join(SPACINGS)}, got {spacing!r:.40}")
    if spacing == "even":
        return x0 + (xf - x0) * (np.arange(n) + 0.5) / n
    return chebyshev(x0, xf, n)


def _linkage(linkage: str, th1: float, out1: float, th: np.ndarray, out: np.ndarray, ground: float):
    """The topology, its coordinates at the first precision pair, and its output column."""
    if linkage == "fourbar":
        if not (isinstance(ground, (int, float)) and math.isfinite(ground) and ground > 0):
            raise SynthesisError(f"[function] ground must be a positive length, got {ground!r:.40}")
        a, _, c = fourbar_lengths(freudenstein(th, out), float(ground))
        top = FOURBAR.without_tracer()
        coords = {"O2": 0j, "O4": complex(ground), "A": a * np.exp(1j * th1), "B": ground + c * np.exp(1j * out1)}
        return top, coords, "rocker.theta"
    a, _, e = slider_crank(th, out)
    return SLIDER_CRANK, {"O2": 0j, "A": a * np.exp(1j * th1), "B": complex(out1, e)}, "slider.s"


def _physical(out: np.ndarray, coords: dict[str, complex], top: Topology) -> np.ndarray:
    """The output column's values at the precision pairs (a rocker of negative c points the other way)."""
    if top.name != "fourbar":
        return out
    c_positive = abs(np.exp(1j * out[0]) - (coords["B"] - coords["O4"]) / abs(coords["B"] - coords["O4"])) < 1
    return out if c_positive else out + math.pi


def _flipped(coords: dict[str, complex], th1: float, out1: float, top: Topology) -> tuple[str, ...]:
    """Notes for a crank (rocker) whose length came out negative: it points the other way, its angle is the
    input (output) angle asked + π; the increments, and so the function generated, are the same."""
    notes = []
    if abs(np.exp(1j * th1) - coords["A"] / abs(coords["A"])) > 1:
        notes.append("the crank points opposite to the input angles asked (a < 0): its angle is the input + π")
    if (
        top.name == "fourbar"
        and abs(np.exp(1j * out1) - (coords["B"] - coords["O4"]) / abs(coords["B"] - coords["O4"])) > 1
    ):
        notes.append("the rocker points opposite to the output angles asked (c < 0): its angle is the output + π")
    return tuple(notes)


def _dims(top: Topology, coords: dict[str, complex]) -> dict[str, float]:
    return {n: abs(coords[js[1]] - coords[js[0]]) for n, js in top.links.items() if len(js) == 2}


def _structural(cand, setup: dict, samples: int, direction: float) -> None:
    """y(x) − f(x) over the range by re-solving the candidate at ``samples`` x values (NaN past a stop); its
    largest magnitude as a fraction of the y range. An angle output is read relative to the first precision
    point (the file's θ may differ by turns or by π)."""
    from .. import solve

    x0, xf = setup["x"]
    (y0, yf), (os_, of) = setup["y"], setup["output_range"]
    ts, tf = setup["input_range"]
    x = np.linspace(x0, xf, int(samples))
    t = np.append(direction * ((x - x0) / (xf - x0) * (tf - ts)), cand.times[0])
    tu, back = np.unique(t, return_inverse=True)
    column = "rocker.theta" if cand.topology == "fourbar" else "slider.s"
    solved = np.full(len(tu), np.nan)
    try:
        solved = solve(cand.mechanism, tu)[column]
    except MotionError as exc:
        if exc.partial is not None and len(exc.partial.t):
            solved[: len(exc.partial.t)] = exc.partial[column]
    out = solved[back]
    phys = out[:-1]
    if column.endswith(".theta"):
        phys = phys - out[-1] + setup["output"][0]
    y = y0 + (phys - os_) / (of - os_) * (yf - y0)
    err = y - setup["f"](x)
    # unit-free: a fraction of the y range the output stands for
    worst = float(np.nanmax(np.abs(err))) / abs(yf - y0) if np.any(np.isfinite(err)) else math.nan
    cand.structural_error = worst
    cand.extra["structural"] = {"x": x, "error": err}
