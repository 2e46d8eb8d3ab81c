"""A generated corpus of random mechanisms with known structure, for validation at scale.

    items = generate(200, seed=7)              # Item: name, spec, TOML text, sidecar dict
    write(items, Path("corpus"))               # corpus/NAME.toml + NAME.json + corpus.json

Every mechanism is drawn from a family whose structure is known (four-bars of every Grashof
class and the change points, offset and inverted slider-cranks, Watt II and Stephenson III
six-bars driven at the crank, the rocker or the output, five-bars with two cranks, eight-bars
with three sliders like the paper's, four-bars and slider-cranks with random dyads hung on
ternary links), with random dimensions, pivots, slider axes, assembly branches and drivers
(constant angular acceleration, or a tabulated rocking input).

How a file is made (none of it calls vloop's loop equations or solver):

1. **Draw** (:func:`draw`): every random choice is made here, from
   ``numpy.random.default_rng([seed, index])``, into a :class:`Spec` — family, variant, drive
   kind and a flat dict of numbers. Mechanism ``index`` depends on (seed, index) only, so one
   mechanism of a large corpus is reproduced alone (``vloop corpus --start I --n 1``).
2. **Build** (:func:`build`): a pure function of the Spec. Joint coordinates at t = 0 come from
   closed-form dyad assembly (law of cosines for an RRR dyad, projection on the line for an RRP
   dyad, the slot's offset for an RPR dyad), on the branch the Spec names. The motion is checked
   with the same dyad formulas over a grid six times finer than the samples: every dyad keeps
   its "margin" (the sine of the angle between its two links, |cos| of the rod against the
   line's normal, |s|/ρ in a slot) above the Spec's minimum, so the time span stays clear of
   limit positions. A build that cannot satisfy its Spec raises :class:`Infeasible` and
   :func:`draw_item` draws again from the same random stream.
3. **Limit runs.** For a known fraction of the single-loop families with a limited input, the
   input runs into its limit position on purpose; the limit angle is the closed form (law of
   cosines for the four-bar and the inverted slider-crank, an arcsine for the slider-crank),
   its time the root of θ0 + ω·t + α·t²/2 = θ_lim, and the grid is laid so the limit falls
   between 25 % and 75 % of a step after the last sample that can be assembled: the expected
   stop sample K (the number of samples solved) is unambiguous. It is written in the file's
   comments and in the sidecar JSON (``expect.stop_sample``).
4. **Check and write**: the TOML text is read back by :func:`vloop.loads` and compiled by
   :func:`vloop.compile` (a file vloop refuses is not written: it is drawn again, and counted
   in ``corpus.json`` as ``refused``); files are written through :mod:`vloop.files.output`.

Lengths are in the file's units (scale drawn from 0.03 to 30), angles in radians, CCW positive.
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

GENERATOR = "vloop-corpus/1"
TWO_PI = 2.0 * math.pi
DENSE = 6  # margin-check points per sample interval
MAX_DRAWS = 400  # attempts per mechanism before giving up (a family whose draws all fail is a bug here)
CHANGE_POINT_CLEARANCE = 1e-2  # rad: no sample this close to a change-point input angle (branches meet)

Forward = Callable[[list[np.ndarray]], tuple[dict[str, np.ndarray], np.ndarray]]


class Infeasible(Exception):
    """The Spec cannot be built as asked (no assembly, a limit inside the span, ...): draw again."""


# ---------------------------------------------------------------- dyads (positions only)


def cis(angle: float | np.ndarray) -> Any:
    """e^{j·angle}."""
    return np.exp(1j * np.asarray(angle, float))


def cross(u: Any, v: Any) -> Any:
    """z-component of u × v for complex-encoded plane vectors."""
    return (np.conj(u) * v).imag


def rrr_position(p1: Any, p2: Any, l1: float, l2: float, sigma: float, slack: float = 0.0) -> tuple[Any, Any]:
    """Middle pin X of the RRR dyad P1–X–P2 (|X − P1| = l1, |X − P2| = l2), law of cosines.

    σ = +1 puts X left of P1→P2. Returns (X, margin): margin = sin of the angle between the two
    links at X (0 at a toggle), −1 where the dyad cannot close (q² < −slack·l1²).
    """
    delta = np.asarray(p2, complex) - np.asarray(p1, complex)
    f = np.abs(delta)
    f_safe = np.where(f > 0, f, 1.0)
    p = (l1 * l1 - l2 * l2 + f * f) / (2.0 * f_safe)
    q2 = (l1 - p) * (l1 + p)
    ok = (q2 > -slack * l1 * l1) & (f > 0)
    x = p1 + l1 * cis(np.angle(delta) + sigma * np.arctan2(np.sqrt(np.maximum(q2, 0.0)), p))
    margin = np.where(ok, np.abs(cross(x - p1, x - p2)) / (l1 * l2), -1.0)
    return x, margin


def rrp_position(p1: Any, length: float, l0: complex, u: complex, sigma: float) -> tuple[Any, Any]:
    """End X of a rod P1–X (length ``length``) whose X slides on the line l0 + λ·u (|u| = 1).

    σ = sign((X − P1)·u). Returns (X, margin): margin = |cos ψ| (ψ the rod's angle to the line),
    −1 where the line is out of reach.
    """
    eta = (np.conj(1j * u) * (np.asarray(p1, complex) - l0)).real
    sin_psi = -eta / length
    c2 = 1.0 - sin_psi * sin_psi
    ok = c2 > 0
    cos_psi = sigma * np.sqrt(np.maximum(c2, 0.0))
    x = p1 + length * cis(np.angle(u) + np.arctan2(sin_psi, cos_psi))
    return x, np.where(ok, np.abs(cos_psi), -1.0)


def rpr_direction(p: Any, o: Any, e: float, sigma: float) -> tuple[Any, Any]:
    """Direction φ of a slot turning about O, passing at signed offset e from O, through the block pin P.

    P − O = (s + j·e)·e^{jφ}, σ = sign(s). Returns (φ, margin): margin = |s|/|P − O|, −1 where
    |P − O| ≤ |e| (the pin comes closer to O than the slot's offset).
    """
    delta = np.asarray(p, complex) - np.asarray(o, complex)
    rho = np.abs(delta)
    s2 = (rho - abs(e)) * (rho + abs(e))
    ok = s2 > 0
    s = sigma * np.sqrt(np.maximum(s2, 0.0))
    phi = np.angle(delta) - np.arctan2(e, s)
    return phi, np.where(ok, np.abs(s) / np.where(rho > 0, rho, 1.0), -1.0)


def on_body(j1: Any, j2: Any, rho: complex) -> Any:
    """A point fixed to the body through J1 and J2, at ``rho`` in the frame with x along J1→J2."""
    d = np.asarray(j2, complex) - np.asarray(j1, complex)
    return j1 + d / np.abs(d) * rho


def local(j1: complex, j2: complex, x: complex) -> complex:
    """``rho`` of :func:`on_body` for the t = 0 position ``x``."""
    d = j2 - j1
    return (x - j1) * np.conj(d) / abs(d)


def side(p1: complex, p2: complex, x: complex) -> float:
    """σ of :func:`rrr_position` that puts the t = 0 point x where it is (refuses a toggle)."""
    c = float(cross(p2 - p1, x - p1))
    if not math.isfinite(c) or abs(c) < 1e-9 * abs(p2 - p1) * abs(x - p1):
        raise Infeasible("a dyad is at its toggle at t = 0")
    return 1.0 if c > 0 else -1.0


def sign_of(x: float) -> float:
    if not math.isfinite(x) or abs(x) < 1e-12:
        raise Infeasible("branch undefined at t = 0")
    return 1.0 if x > 0 else -1.0


def limit_angles_cosine(a: float, d: float, ground_angle: float, reach: Iterable[float]) -> list[float]:
    """Input angles φ where |O2 + a·e^{jφ} − O4| equals one of ``reach`` (law of cosines).

    |A − O4|² = a² + d² − 2·a·d·cos(φ − θ1) = f²  ⇒  φ = θ1 ± arccos((a² + d² − f²)/(2·a·d)).
    """
    out = []
    for f in reach:
        x = (a * a + d * d - f * f) / (2.0 * a * d)
        if abs(x) <= 1.0:
            g = math.acos(x)
            out += [ground_angle + g, ground_angle - g]
    return out


def interval_around(theta0: float, angles: Sequence[float]) -> tuple[float, float] | None:
    """The nearest limit angle below and above θ0 (unwrapped around θ0); None if there is none."""
    if not angles:
        return None
    rel = [math.remainder(a - theta0, TWO_PI) for a in angles]
    ups = [r if r > 0 else r + TWO_PI for r in rel]
    downs = [r if r < 0 else r - TWO_PI for r in rel]
    return theta0 + max(downs), theta0 + min(ups)


# ---------------------------------------------------------------- what a family builder returns


@dataclass
class Draft:
    """A mechanism at t = 0 and how it moves, before its drive and time span are chosen.

    ``forward(inputs)`` gives the moving joints (complex arrays) and the smallest dyad margin for
    arrays of the driven inputs (each driver's θ, the link's absolute angle). ``input_range`` is
    the closed-form interval of input 0 around its t = 0 value (None: it turns fully);
    ``limit_formula`` says how it was computed (for the file's comments).
    """

    variant: str
    joints: dict[str, complex]
    links: dict[str, dict[str, Any]]
    drivers: list[tuple[str, str]]  # (link, pivot)
    forward: Forward
    input_range: tuple[float, float] | None = None
    limit_formula: str = ""
    sliders: dict[str, dict[str, Any]] = field(default_factory=dict)
    points: dict[str, tuple[str, complex]] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    closed_form: bool = True  # a hand-derived closed form exists (validators.analytic)
    limit_capable: bool = False  # input_range is a closed form, so a run into the limit has a known stop
    slack: float = 0.0  # margin threshold override (change points: the branches meet, margin reaches 0)
    change_angles: tuple[float, ...] = ()  # input angles of change points (mod 2π)

    def theta0(self, k: int = 0) -> float:
        link, pivot = self.drivers[k]
        j2 = self.links[link]["joints"][1]
        return float(np.angle(self.joints[j2] - self.joints[pivot]))


def _stated_lengths(draft: Draft) -> None:
    """State the length of every binary moving link (so change points are exact, not rounded)."""
    for lk in draft.links.values():
        if not lk.get("ground") and len(lk["joints"]) == 2:
            j1, j2 = lk["joints"]
            lk.setdefault("length", abs(draft.joints[j2] - draft.joints[j1]))
        elif len(lk["joints"]) != 2:
            lk.pop("length", None)


# ---------------------------------------------------------------- families: four-bar


def _fourbar_class(a: float, b: float, c: float, d: float) -> str:
    ls = sorted([a, b, c, d])
    lhs, rhs = ls[0] + ls[3], ls[1] + ls[2]
    if math.isclose(lhs, rhs, rel_tol=1e-9):
        return "change-point"
    if lhs > rhs:
        return "triple-rocker"
    return {a: "crank-rocker", d: "double-crank", c: "rocker-crank", b: "double-rocker"}[ls[0]]


def fourbar_lengths(p: dict[str, float], variant: str) -> tuple[float, float, float, float]:
    """(a, b, c, d) relative to the scale; the change points' equal or summed lengths are derived, not drawn,
    so that a shrunk Spec stays a change point."""
    a, b, c, d = (p[k] for k in ("a", "b", "c", "d"))
    if variant in ("parallelogram", "antiparallelogram"):
        c, d = a, b
    elif variant == "kite":
        b, d = a, c
    elif variant == "change-point":
        x, y = p["b"], p["c"]
        rest = [x, y, x + y - a]
        k = int(p["perm"]) % 6
        order = [(0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)][k]
        b, c, d = (rest[i] for i in order)
    return a, b, c, d


def fourbar_draft(p: dict[str, float], variant: str) -> Draft:
    """Crank O2A (a), coupler AB (b, carries P), rocker O4B (c), ground O2O4 (d at angle γ)."""
    s = p["scale"]
    a, b, c, d = (s * x for x in fourbar_lengths(p, variant))
    if min(a, b, c, d) <= 0:
        raise Infeasible("a link of zero length")
    cls = _fourbar_class(a, b, c, d)
    if (variant in CHANGE_POINTS) != (cls == "change-point") or (variant not in CHANGE_POINTS and cls != variant):
        raise Infeasible(f"lengths give a {cls}, not a {variant}")
    o2 = s * complex(p["x0"], p["y0"])
    o4 = o2 + d * cis(p["ground_angle"])
    sigma = p["sigma"]
    change = variant in CHANGE_POINTS

    def forward(inputs: list[np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        pa = o2 + a * cis(inputs[0])
        pb, m = rrr_position(pa, o4, b, c, sigma, slack=1e-12 if change else 0.0)
        return {"A": pa, "B": pb}, m

    pos, m = forward([np.array([p["theta0"]])])
    if m[0] <= 0:
        raise Infeasible("four-bar does not close at t = 0")
    ja, jb = complex(pos["A"][0]), complex(pos["B"][0])
    joints = {"O2": o2, "A": ja, "B": jb, "O4": o4}
    links = {
        "ground": {"joints": ["O2", "O4"], "ground": True},
        "crank": {"joints": ["O2", "A"], "length": a},
        "coupler": {"joints": ["A", "B"], "length": b},
        "rocker": {"joints": ["O4", "B"], "length": c},
    }
    toggles = limit_angles_cosine(a, d, p["ground_angle"], (b + c, abs(b - c)))
    draft = Draft(variant, joints, links, [("crank", "O2")], forward, closed_form=True)
    draft.points["P"] = ("coupler", ja + (jb - ja) / b * s * complex(p["px"], p["py"]))
    draft.notes.append(
        f"four-bar, {cls}: crank a = {a:.6g}, coupler b = {b:.6g}, rocker c = {c:.6g}, ground d = {d:.6g}"
    )
    if change:
        # the branches meet where |A − O4| has an extremum equal to a fold length: d + a = b + c (crank
        # pointing away from O4) or |d − a| = |b − c| (crank pointing at O4)
        tol = 1e-9 * max(a, b, c, d)
        g = p["ground_angle"]
        angles = [g + math.pi] if abs(d + a - b - c) <= tol else []
        angles += [g] if abs(abs(d - a) - abs(b - c)) <= tol else []
        draft.slack, draft.change_angles = 1.0, tuple(t % TWO_PI for t in angles)
        draft.notes.append(
            "change point (s + l = p + q): at the input angles "
            + ", ".join(f"{t:.10g}" for t in sorted(draft.change_angles))
            + " rad all four pins are collinear and the open and crossed branches meet; the motion continues "
            "on the branch that keeps the velocities continuous (the branch sign flips there)"
        )
    elif cls in ("crank-rocker", "double-crank"):
        if toggles:
            raise Infeasible("numerically Grashof crank with a reachable toggle")
    else:
        draft.input_range = interval_around(p["theta0"], toggles)
        draft.limit_capable = True
        draft.limit_formula = (
            "the crank stops where coupler and rocker are collinear, |A − O4| = b + c or |b − c|: "
            "cos(θ − γ) = (a² + d² − f²)/(2·a·d) (law of cosines)"
        )
    return draft


CHANGE_POINTS = ("parallelogram", "antiparallelogram", "kite", "change-point")


def draw_fourbar(rng: np.random.Generator, variant: str) -> dict[str, float]:
    """Lengths of the requested Grashof class (or change point), pivots, branch, coupler point."""
    p = _placement(rng)
    for _ in range(1000):
        a, b, c, d = (float(x) for x in rng.uniform(0.2, 1.6, 4))
        if variant == "parallelogram" or variant == "antiparallelogram":
            c, d = a, b
            if abs(a - b) < 0.1:
                continue
        elif variant == "kite":
            a = min(a, c) * 0.8
            b, d = a, c
        elif variant == "change-point":
            x, y, z = sorted(rng.uniform(0.3, 1.6, 3))
            if z - y < 0.05 or y - x < 0.05:
                continue
            a = float(x) * 0.7  # the crank is the shortest, so it turns fully
            b, c, d = float(y), float(z), 0.0  # d is derived: fourbar_lengths
            got = "change-point"
            break
        got = _fourbar_class(a, b, c, d)
        if variant in CHANGE_POINTS:
            if got == "change-point":
                break
            continue
        ls = sorted([a, b, c, d])
        if got == variant and abs(ls[0] + ls[3] - ls[1] - ls[2]) > 0.05 * ls[3]:
            break
    else:  # pragma: no cover - the classes are all reachable with these bounds
        raise Infeasible(f"no {variant} four-bar drawn")
    sigma = 1.0 if variant == "parallelogram" else -1.0 if variant == "antiparallelogram" else _sign(rng)
    if variant in ("parallelogram", "antiparallelogram"):
        # on a parallelogram the branch sign alone does not say which one: σ is set after the draw
        # so that the t = 0 configuration is the one named (checked in build)
        sigma = 0.0
    p.update(a=a, b=b, c=c, d=d, sigma=sigma, theta0=float(rng.uniform(0, TWO_PI)), perm=float(rng.integers(6)))
    p.update(px=float(rng.uniform(-0.3, 1.3)), py=float(rng.uniform(-0.6, 0.6)))
    return p


def _parallelogram_sigma(p: dict[str, float], crossed: bool) -> float:
    """σ for which the t = 0 four-bar is the parallelogram (B − A ∥ O4 − O2) or the crossed one."""
    s = p["scale"]
    o2 = s * complex(p["x0"], p["y0"])
    o4 = o2 + s * p["d"] * cis(p["ground_angle"])
    pa = o2 + s * p["a"] * cis(p["theta0"])
    want = pa + (o4 - o2)  # the parallelogram's B
    sig = side(pa, o4, want)
    return -sig if crossed else sig


# ---------------------------------------------------------------- slider-cranks


def slider_crank_draft(p: dict[str, float], variant: str) -> Draft:
    """Crank O2A (a), rod AB (b, carries P), block at B on a ground line at offset e, axis angle φ."""
    s = p["scale"]
    a, b, e = s * p["a"], s * p["b"], s * p["e"]
    o2 = s * complex(p["x0"], p["y0"])
    u = complex(cis(p["axis_angle"]))
    l0 = o2 + 1j * u * e  # a point of the line: the foot of O2's normal, at signed offset e
    sigma = p["sigma"]

    def forward(inputs: list[np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        pa = o2 + a * cis(inputs[0])
        pb, m = rrp_position(pa, b, l0, u, sigma)
        return {"A": pa, "B": pb}, m

    if a <= 0 or b <= 0 or (variant == "offset") != (a + abs(e) < b):
        raise Infeasible(f"crank a, rod b and offset e do not make the {variant} variant")
    pos, m = forward([np.array([p["theta0"]])])
    if m[0] <= 0:
        raise Infeasible("slider-crank does not close at t = 0")
    ja, jb = complex(pos["A"][0]), complex(pos["B"][0])
    joints = {"O2": o2, "A": ja, "B": jb}
    links = {
        "ground": {"joints": ["O2"], "ground": True},
        "crank": {"joints": ["O2", "A"], "length": a},
        "rod": {"joints": ["A", "B"], "length": b},
    }
    draft = Draft(variant, joints, links, [("crank", "O2")], forward)
    draft.sliders["block"] = {"joint": "B", "guide": "ground", "axis": u}
    draft.points["P"] = ("rod", ja + (jb - ja) / b * s * complex(p["px"], p["py"]))
    draft.notes.append(
        f"offset slider-crank: crank a = {a:.6g}, rod b = {b:.6g}, offset e = {e:.6g}, "
        f"line at {p['axis_angle']:.6g} rad"
    )
    # η(φ) = e_n + a·sin(φ − φu) is the crank pin's distance from the line; the rod reaches it while |η| < b
    eta_o2 = -e
    lims = []
    for target in (b, -b):
        x = (target - eta_o2) / a
        if abs(x) <= 1.0:
            g = math.asin(x)
            lims += [p["axis_angle"] + g, p["axis_angle"] + math.pi - g]
    if lims:
        draft.input_range = interval_around(p["theta0"], lims)
        draft.limit_capable = True
        draft.limit_formula = (
            "the rod is perpendicular to the line where the crank pin's distance from it equals b: "
            "−e + a·sin(θ − φ) = ±b, θ = φ + asin((±b + e)/a) or φ + π − asin(...)"
        )
    return draft


def draw_slider_crank(rng: np.random.Generator, variant: str) -> dict[str, float]:
    p = _placement(rng)
    for _ in range(1000):
        a, b = float(rng.uniform(0.2, 1.0)), float(rng.uniform(0.5, 2.0))
        e = float(rng.uniform(-1.0, 1.0)) * (b if variant == "rocking" else (b - a))
        full = a + abs(e) < b * 0.97
        if (variant == "offset") == full and (full or abs(e) - a < 0.9 * b):
            break
    p.update(a=a, b=b, e=e, axis_angle=_axis_angle(rng), sigma=_sign(rng), theta0=float(rng.uniform(0, TWO_PI)))
    p.update(px=float(rng.uniform(-0.2, 1.2)), py=float(rng.uniform(-0.5, 0.5)))
    return p


def inverted_draft(p: dict[str, float], variant: str) -> Draft:
    """Crank O2A (a); block at A sliding in a slot of the rocker about O4, slot offset e from O4."""
    s = p["scale"]
    a, d, e = s * p["a"], s * p["d"], s * p["e"]
    o2 = s * complex(p["x0"], p["y0"])
    o4 = o2 + d * cis(p["ground_angle"])
    sigma = p["sigma"]
    arm = s * complex(p["tip_s"], p["tip_n"])  # the rocker's tip in the slot frame (along, across)

    def forward(inputs: list[np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        pa = o2 + a * cis(inputs[0])
        phi, m = rpr_direction(pa, o4, e, sigma)
        return {"A": pa, "C": o4 + cis(phi) * arm}, m

    if a <= 0 or d <= 0 or (variant == "crank") != (abs(e) < abs(d - a)):
        raise Infeasible(f"crank a, ground d and offset e do not make the {variant} variant")
    pos, m = forward([np.array([p["theta0"]])])
    if m[0] <= 0:
        raise Infeasible("inverted slider-crank does not close at t = 0")
    ja, jc = complex(pos["A"][0]), complex(pos["C"][0])
    if abs(jc - o4) < 0.05 * s:
        raise Infeasible("rocker tip on the pivot")
    phi0, _ = rpr_direction(ja, o4, e, sigma)
    u = complex(cis(float(phi0)))
    joints = {"O2": o2, "A": ja, "O4": o4, "C": jc}
    links = {
        "ground": {"joints": ["O2", "O4"], "ground": True},
        "crank": {"joints": ["O2", "A"], "length": a},
        "rocker": {"joints": ["O4", "C"]},
    }
    draft = Draft(variant, joints, links, [("crank", "O2")], forward)
    draft.sliders["block"] = {"joint": "A", "guide": "rocker", "axis": u}
    draft.notes.append(f"inverted slider-crank: crank a = {a:.6g}, ground d = {d:.6g}, slot offset e = {e:.6g} from O4")
    lims = limit_angles_cosine(a, d, p["ground_angle"], (abs(e),))
    if lims:
        draft.input_range = interval_around(p["theta0"], lims)
        draft.limit_capable = True
        draft.limit_formula = (
            "the slot is tangent to the crank-pin circle where |A − O4| = |e|: "
            "cos(θ − γ) = (a² + d² − e²)/(2·a·d) (law of cosines)"
        )
    return draft


def draw_inverted(rng: np.random.Generator, variant: str) -> dict[str, float]:
    p = _placement(rng)
    for _ in range(1000):
        a, d = float(rng.uniform(0.2, 1.5)), float(rng.uniform(0.2, 1.5))
        if abs(a - d) < 0.1:
            continue
        e = float(rng.uniform(-1, 1)) * (abs(d - a) * 0.9 if variant == "crank" else (a + d))
        full = abs(e) < abs(d - a) * 0.95
        if (variant == "crank") == full and (full or abs(e) > abs(d - a) * 1.05):
            break
    p.update(a=a, d=d, e=e, ground_angle=_axis_angle(rng), sigma=_sign(rng), theta0=float(rng.uniform(0, TWO_PI)))
    p.update(tip_s=float(rng.uniform(-2.0, 2.0)), tip_n=float(rng.uniform(-0.3, 0.3)))
    return p


# ---------------------------------------------------------------- six-bars and five-bars


def watt2_draft(p: dict[str, float], variant: str) -> Draft:
    """Four-bar O2–A–B–O4 (ternary rocker O4, B, C) in series with four-bar C–D–O6."""
    base = fourbar_draft(p, "crank-rocker")
    s = p["scale"]
    j = dict(base.joints)
    o4, jb = j["O4"], j["B"]
    jc = o4 + (jb - o4) / abs(jb - o4) * s * complex(p["cx"], p["cy"])
    jd = jc + s * complex(p["dx"], p["dy"])
    o6 = jd + s * complex(p["gx"], p["gy"])
    l5, l6 = abs(jd - jc), abs(jd - o6)
    sig2 = side(jc, o6, jd)
    rho_c = local(o4, jb, jc)
    base_fwd = base.forward

    def forward(inputs: list[np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        pos, m = base_fwd(inputs)
        pc = on_body(o4, pos["B"], rho_c)
        pd, m2 = rrr_position(pc, o6, l5, l6, sig2)
        return {**pos, "C": pc, "D": pd}, np.minimum(m, m2)

    j.update(C=jc, D=jd, O6=o6)
    links = dict(base.links)
    links["ground"] = {"joints": ["O2", "O4", "O6"], "ground": True}
    links["rocker"] = {"joints": ["O4", "B", "C"]}
    links["link5"] = {"joints": ["C", "D"], "length": l5}
    links["output"] = {"joints": ["O6", "D"], "length": l6}
    draft = Draft(variant, j, links, [("crank", "O2")], forward, points={"P": base.points["P"]})
    draft.notes = [*base.notes, f"Watt II: second four-bar C–D–O6, link5 = {l5:.6g}, output = {l6:.6g}"]
    if variant == "output":
        return _driven_at(draft, "output", "O6", forward_index=("O6", "D"))
    return draft


def stephenson3_draft(p: dict[str, float], variant: str) -> Draft:
    """Four-bar O2–A–B–O4 with a ternary coupler (A, B, C) carrying the dyad C–D–O6."""
    base = fourbar_draft(p, "crank-rocker")
    s = p["scale"]
    j = dict(base.joints)
    ja, jb = j["A"], j["B"]
    jc = ja + (jb - ja) / abs(jb - ja) * s * complex(p["cx"], p["cy"])
    jd = jc + s * complex(p["dx"], p["dy"])
    o6 = jd + s * complex(p["gx"], p["gy"])
    l5, l6 = abs(jd - jc), abs(jd - o6)
    sig2 = side(jc, o6, jd)
    rho_c = local(ja, jb, jc)
    base_fwd = base.forward

    def forward(inputs: list[np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        pos, m = base_fwd(inputs)
        pc = on_body(pos["A"], pos["B"], rho_c)
        pd, m2 = rrr_position(pc, o6, l5, l6, sig2)
        return {**pos, "C": pc, "D": pd}, np.minimum(m, m2)

    j.update(C=jc, D=jd, O6=o6)
    links = dict(base.links)
    links["ground"] = {"joints": ["O2", "O4", "O6"], "ground": True}
    links["coupler"] = {"joints": ["A", "B", "C"]}
    links["link5"] = {"joints": ["C", "D"], "length": l5}
    links["output"] = {"joints": ["O6", "D"], "length": l6}
    draft = Draft(variant, j, links, [("crank", "O2")], forward, points={"P": base.points["P"]})
    draft.notes = [*base.notes, f"Stephenson III: dyad C–D–O6 on the coupler, link5 = {l5:.6g}, output = {l6:.6g}"]
    if variant == "rocker":
        return _driven_at(draft, "rocker", "O4", forward_index=("O4", "B"))
    if variant == "output":
        draft = _driven_at(draft, "output", "O6", forward_index=("O6", "D"))
        draft.closed_form = False  # driven at the output the two loops are coupled: Newton, no closed form
        draft.notes.append("driven at the output: loops 1 and 2 are solved together (Newton); no closed form")
    return draft


def _monotone_segment(draft: Draft, j1: str, j2: str) -> tuple[np.ndarray, np.ndarray]:
    """(θ2, ψ) along the crank angle θ2 where ψ = arg(j2 − j1) is monotone, through t = 0, ψ increasing."""
    th2_0 = draft.theta0(0)
    grid = th2_0 + np.linspace(-math.pi, math.pi, 20001)
    pos, m = draft.forward([grid])
    psi = np.unwrap(np.angle(pos[j2] - draft.joints[j1]))  # j1 is a ground pivot
    k0 = 10000
    psi = psi - psi[k0] + float(np.angle(draft.joints[j2] - draft.joints[j1]))
    dpsi = np.gradient(psi, grid)
    good = (m > 0) & (np.sign(dpsi) == np.sign(dpsi[k0])) & (np.abs(dpsi) > 1e-3)
    if not good[k0]:
        raise Infeasible("driven link at a limit at t = 0")
    lo, hi = k0, k0
    while lo > 0 and good[lo - 1]:
        lo -= 1
    while hi < len(grid) - 1 and good[hi + 1]:
        hi += 1
    g_seg, psi_seg = grid[lo : hi + 1], psi[lo : hi + 1]
    if psi_seg[-1] < psi_seg[0]:
        g_seg, psi_seg = g_seg[::-1], psi_seg[::-1]
    if psi_seg[-1] - psi_seg[0] < 0.1:
        raise Infeasible("driven link barely moves")
    return g_seg, psi_seg


def _driven_at(draft: Draft, link: str, pivot: str, forward_index: tuple[str, str]) -> Draft:
    """Drive ``link`` instead of the crank; the motion is the crank-parametrized curve, re-read.

    Along the crank angle θ2 the forward chain gives the driven link's angle ψ(θ2); driven at
    that link, the mechanism follows the same curve as long as ψ is monotone in θ2 (where
    dψ/dθ2 = 0 the new input reaches a limit). The feasible input range is the monotone segment
    through the t = 0 configuration, computed on a grid of θ2 (2·10⁴ points a turn) and kept 3 %
    of its width clear of both ends; inverting ψ(θ2) there by interpolation gives θ2 for any
    input, and the margins of every dyad along it.
    """
    g_seg, psi_seg = _monotone_segment(draft, *forward_index)
    width = psi_seg[-1] - psi_seg[0]
    fwd_crank = draft.forward

    def forward(inputs: list[np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        psi_t = np.asarray(inputs[0], float)
        th2 = np.interp(psi_t, psi_seg, g_seg)
        pos, m = fwd_crank([th2])
        outside = (psi_t < psi_seg[0]) | (psi_t > psi_seg[-1])
        return pos, np.where(outside, -1.0, m)

    if draft.links[link]["joints"][0] != pivot:
        raise Infeasible("driven link's pivot is not its first joint")
    clear = 0.03 * width
    return replace(
        draft,
        drivers=[(link, pivot)],
        forward=forward,
        input_range=(float(psi_seg[0] + clear), float(psi_seg[-1] - clear)),
        limit_capable=False,
        limit_formula="",
        notes=[
            *draft.notes,
            f"driven at {link} (pivot {pivot}): its feasible range [{psi_seg[0]:.6g}, {psi_seg[-1]:.6g}] rad "
            "is the monotone segment of its angle along the crank's, on a 2·10⁴-point grid (kept 3 % clear)",
        ],
    )


def fivebar_draft(p: dict[str, float], variant: str) -> Draft:
    """Two cranks O2A (a) and O5D (e), links AC (l3) and DC (l4) pinned at C."""
    s = p["scale"]
    o2 = s * complex(p["x0"], p["y0"])
    o5 = o2 + s * p["d"] * cis(p["ground_angle"])
    a, e = s * p["a"], s * p["e"]
    ja, jd = o2 + a * cis(p["theta0"]), o5 + e * cis(p["theta0b"])
    jc = ja + s * complex(p["cx"], p["cy"])
    l3, l4 = abs(jc - ja), abs(jc - jd)
    sig = side(ja, jd, jc)

    def forward(inputs: list[np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        pa, pd = o2 + a * cis(inputs[0]), o5 + e * cis(inputs[1])
        pc, m = rrr_position(pa, pd, l3, l4, sig)
        return {"A": pa, "D": pd, "C": pc}, m

    joints = {"O2": o2, "A": ja, "C": jc, "D": jd, "O5": o5}
    links = {
        "ground": {"joints": ["O2", "O5"], "ground": True},
        "crank": {"joints": ["O2", "A"], "length": a},
        "link3": {"joints": ["A", "C"], "length": l3},
        "link4": {"joints": ["D", "C"], "length": l4},
        "crank2": {"joints": ["O5", "D"], "length": e},
    }
    draft = Draft(variant, joints, links, [("crank", "O2"), ("crank2", "O5")], forward)
    draft.notes.append(f"five-bar, two cranks a = {a:.6g}, e = {e:.6g}; links l3 = {l3:.6g}, l4 = {l4:.6g}")
    return draft


def eightbar_draft(p: dict[str, float], variant: str) -> Draft:
    """The paper's eight-bar: crank O2A, coupler AB, block at B on line 1, rods BC, BD to blocks on lines 2, 3.

    ``paper``: line 1 horizontal, lines 2 and 3 vertical (the paper's Fig. 1); ``tilted``: any angles.
    """
    s = p["scale"]
    o2 = s * complex(p["x0"], p["y0"])
    a = s * p["a"]
    ja = o2 + a * cis(p["theta0"])
    jb = ja + s * complex(p["bx"], p["by"])
    if variant == "paper":
        angles = (0.0, math.pi / 2, -math.pi / 2)
    else:
        angles = (p["axis1"], p["axis2"], p["axis3"])
    u1, u2, u3 = (complex(cis(t)) for t in angles)
    jc = jb + s * complex(p["cx"], p["cy"])
    jd = jb + s * complex(p["dx"], p["dy"])
    b, l5, l7 = abs(jb - ja), abs(jc - jb), abs(jd - jb)
    s1 = sign_of(float((np.conj(u1) * (jb - ja)).real))
    s2 = sign_of(float((np.conj(u2) * (jc - jb)).real))
    s3 = sign_of(float((np.conj(u3) * (jd - jb)).real))

    def forward(inputs: list[np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        pa = o2 + a * cis(inputs[0])
        pb, m1 = rrp_position(pa, b, jb, u1, s1)
        pc, m2 = rrp_position(pb, l5, jc, u2, s2)
        pd, m3 = rrp_position(pb, l7, jd, u3, s3)
        return {"A": pa, "B": pb, "C": pc, "D": pd}, np.minimum(np.minimum(m1, m2), m3)

    joints = {"O2": o2, "A": ja, "B": jb, "C": jc, "D": jd}
    links = {
        "ground": {"joints": ["O2"], "ground": True},
        "crank": {"joints": ["O2", "A"], "length": a},
        "coupler": {"joints": ["A", "B"], "length": b},
        "rod5": {"joints": ["B", "C"], "length": l5},
        "rod7": {"joints": ["B", "D"], "length": l7},
    }
    draft = Draft(variant, joints, links, [("crank", "O2")], forward)
    draft.sliders = {
        "block4": {"joint": "B", "guide": "ground", "axis": u1},
        "block6": {"joint": "C", "guide": "ground", "axis": u2},
        "block8": {"joint": "D", "guide": "ground", "axis": u3},
    }
    draft.notes.append(
        f"eight-bar with three sliders: crank a = {a:.6g}, coupler b = {b:.6g}, rods {l5:.6g}, {l7:.6g}; "
        f"lines at {angles[0]:.6g}, {angles[1]:.6g}, {angles[2]:.6g} rad"
    )
    return draft


# ---------------------------------------------------------------- random dyads hung on ternary links


ATTACH_KINDS = ("rrr-ground", "rrr-link", "rrp-ground")


Step = Callable[[dict[str, np.ndarray]], tuple[dict[str, np.ndarray], np.ndarray]]


@dataclass
class _Chain:
    """A mechanism under construction: its t = 0 joints, links, sliders, and each moving link's frame."""

    joints: dict[str, complex]
    links: dict[str, dict[str, Any]]
    sliders: dict[str, dict[str, Any]]
    frames: dict[str, tuple[str, str]]

    def pin_on(self, host: str, name: str, rel: complex) -> complex:
        """A new pin on ``host`` at ``rel`` in its frame (along, across its first member); its t = 0 position."""
        j1, j2 = self.frames[host]
        z1, z2 = self.joints[j1], self.joints[j2]
        self.joints[name] = z1 + (z2 - z1) / abs(z2 - z1) * rel
        self.links[host]["joints"] = [*self.links[host]["joints"], name]
        return self.joints[name]

    def add_link(self, name: str, j1: str, j2: str) -> None:
        self.links[name] = {"joints": [j1, j2]}
        self.frames[name] = (j1, j2)


def attach_draft(p: dict[str, float], variant: str) -> Draft:
    """A base (crank-rocker four-bar or offset slider-crank) with one or two random dyads attached.

    Each dyad hangs on a new pin H of a moving link (which becomes ternary) and ends at a new
    ground pivot (RRR), a new pin on another moving link (RRR) or a block on a new ground line (RRP).
    """
    base = fourbar_draft(p, "crank-rocker") if variant.startswith("fourbar") else slider_crank_draft(p, "offset")
    frames = {n: (v["joints"][0], v["joints"][1]) for n, v in base.links.items() if not v.get("ground")}
    chain = _Chain(dict(base.joints), {k: dict(v) for k, v in base.links.items()}, dict(base.sliders), frames)
    steps, notes = [], list(base.notes)
    for k in range(1, int(p["n_attach"]) + 1):
        step, note = _attach_one(chain, p, k)
        steps.append(step)
        notes.append(note)
    base_fwd = base.forward

    def forward(inputs: list[np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        pos, m = base_fwd(inputs)
        pos = {**{n: np.full(np.shape(inputs[0]), z) for n, z in base.joints.items()}, **pos}
        for step in steps:
            new, m2 = step(pos)
            pos.update(new)
            m = np.minimum(m, m2)
        return pos, m

    draft = Draft(variant, chain.joints, chain.links, base.drivers, forward, points=dict(base.points), notes=notes)
    draft.sliders = chain.sliders
    return draft


def _attach_one(chain: _Chain, p: dict[str, float], k: int) -> tuple[Step, str]:
    """Dyad k: pin H on a host link, middle pin X, then a ground pivot G, a pin K on a second link, or a block."""
    s = p["scale"]
    hosts = sorted(chain.frames)
    host = hosts[int(p[f"host{k}"] * len(hosts)) % len(hosts)]
    j1, j2 = chain.frames[host]
    hn, xn = f"H{k}", f"X{k}"
    h0 = chain.pin_on(host, hn, s * complex(p[f"hx{k}"], p[f"hy{k}"]))
    x0 = chain.joints[xn] = h0 + s * complex(p[f"mx{k}"], p[f"my{k}"])
    rho_h = local(chain.joints[j1], chain.joints[j2], h0)
    chain.add_link(f"bar{k}a", hn, xn)
    kind = ATTACH_KINDS[int(p[f"kind{k}"]) % 3]
    if kind == "rrp-ground":
        u = complex(cis(p[f"axis{k}"]))
        sig = sign_of(float((np.conj(u) * (x0 - h0)).real))
        chain.sliders[f"block{k}"] = {"joint": xn, "guide": "ground", "axis": u}
        note = f"dyad {k}: rod {hn}–{xn} on {host}, block on a ground line at {p[f'axis{k}']:.6g} rad"
        return _rrp_step(j1, j2, rho_h, hn, xn, abs(x0 - h0), x0, u, sig), note
    g0 = x0 + s * complex(p[f"gx{k}"], p[f"gy{k}"])
    if kind == "rrr-ground":
        gn = f"G{k}"
        chain.joints[gn] = g0
        chain.links["ground"]["joints"] = [*chain.links["ground"]["joints"], gn]
        end: tuple[str, complex, tuple[str, str] | None, complex | None] = (gn, g0, None, None)
        note = f"dyad {k}: {hn}–{xn}–{gn}, {hn} on {host}, {gn} a new ground pivot"
    else:
        other = [n for n in hosts if n != host]
        host2 = other[int(p[f"host2_{k}"] * len(other)) % len(other)]
        gn = f"K{k}"
        k1, k2 = chain.frames[host2]
        chain.joints[gn] = g0
        chain.links[host2]["joints"] = [*chain.links[host2]["joints"], gn]
        end = (gn, g0, (k1, k2), local(chain.joints[k1], chain.joints[k2], g0))
        note = f"dyad {k}: {hn}–{xn}–{gn}, {hn} on {host}, {gn} on {host2}"
    chain.add_link(f"bar{k}b", gn, xn)
    return _rrr_step(j1, j2, rho_h, hn, xn, end, x0, chain.joints), note


def _rrp_step(
    j1: str, j2: str, rho_h: complex, hn: str, xn: str, length: float, x0: complex, u: complex, sig: float
) -> Step:
    def step(pos: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        h = on_body(pos[j1], pos[j2], rho_h)
        x, m = rrp_position(h, length, x0, u, sig)
        return {hn: h, xn: x}, m

    return step


def _rrr_step(
    j1: str,
    j2: str,
    rho_h: complex,
    hn: str,
    xn: str,
    end: tuple[str, complex, tuple[str, str] | None, complex | None],
    x0: complex,
    joints: dict[str, complex],
) -> Step:
    gn, g0, frame, rho_g = end
    h0 = joints[hn]
    l1, l2 = abs(x0 - h0), abs(x0 - g0)
    sig = side(h0, g0, x0)

    def step(pos: dict[str, np.ndarray]) -> tuple[dict[str, np.ndarray], np.ndarray]:
        h = on_body(pos[j1], pos[j2], rho_h)
        g = np.full(np.shape(h), g0) if frame is None else on_body(pos[frame[0]], pos[frame[1]], rho_g)
        x, m = rrr_position(h, g, l1, l2, sig)
        return {hn: h, xn: x, gn: g}, m

    return step


# ---------------------------------------------------------------- drawing the numbers


def _sign(rng: np.random.Generator) -> float:
    return 1.0 if rng.random() < 0.5 else -1.0


def _axis_angle(rng: np.random.Generator) -> float:
    """A slider axis or ground-line angle: a textbook one (0, ±π/2, π) a third of the time, else any."""
    if rng.random() < 1 / 3:
        return float(rng.choice([0.0, math.pi / 2, math.pi, -math.pi / 2]))
    return float(rng.uniform(-math.pi, math.pi))


def _placement(rng: np.random.Generator) -> dict[str, float]:
    """Scale (0.03 … 30 file units), the first pivot's position and the ground line's angle."""
    return {
        "scale": float(10 ** rng.uniform(-1.5, 1.5)),
        "x0": float(rng.uniform(-2, 2)),
        "y0": float(rng.uniform(-2, 2)),
        "ground_angle": _axis_angle(rng),
    }


def _polar(rng: np.random.Generator, lo: float, hi: float) -> tuple[float, float]:
    r, t = rng.uniform(lo, hi), rng.uniform(-math.pi, math.pi)
    return float(r * math.cos(t)), float(r * math.sin(t))


def _dyad_numbers(rng: np.random.Generator, p: dict[str, float]) -> None:
    """C on a ternary link (along, across its first member), D from C, the new pivot from D."""
    p["cx"], p["cy"] = float(rng.uniform(-0.5, 1.5)), float(rng.uniform(-0.8, 0.8))
    p["dx"], p["dy"] = _polar(rng, 0.6, 1.8)
    p["gx"], p["gy"] = _polar(rng, 0.5, 1.6)


def draw_sixbar(rng: np.random.Generator, variant: str) -> dict[str, float]:
    p = draw_fourbar(rng, "crank-rocker")
    _dyad_numbers(rng, p)
    return p


def draw_fivebar(rng: np.random.Generator, variant: str) -> dict[str, float]:
    p = _placement(rng)
    p.update(d=float(rng.uniform(0.8, 2.0)), a=float(rng.uniform(0.2, 0.6)), e=float(rng.uniform(0.2, 0.6)))
    p.update(theta0=float(rng.uniform(0, TWO_PI)), theta0b=float(rng.uniform(0, TWO_PI)))
    p["cx"], p["cy"] = _polar(rng, 0.8, 2.0)
    return p


def draw_eightbar(rng: np.random.Generator, variant: str) -> dict[str, float]:
    p = _placement(rng)
    p.update(a=float(rng.uniform(0.2, 0.8)), theta0=float(rng.uniform(0, TWO_PI)))
    p["bx"], p["by"] = _polar(rng, 1.0, 2.0)
    p["cx"], p["cy"] = _polar(rng, 0.8, 2.0)
    p["dx"], p["dy"] = _polar(rng, 0.8, 2.0)
    p.update(axis1=_axis_angle(rng), axis2=_axis_angle(rng), axis3=_axis_angle(rng))
    return p


def draw_attach(rng: np.random.Generator, variant: str) -> dict[str, float]:
    p = draw_fourbar(rng, "crank-rocker") if variant.startswith("fourbar") else draw_slider_crank(rng, "offset")
    p["n_attach"] = float(variant[-1])
    for k in (1, 2):
        p[f"host{k}"], p[f"host2_{k}"] = float(rng.random()), float(rng.random())
        p[f"kind{k}"] = float(rng.integers(0, 3))
        p[f"hx{k}"], p[f"hy{k}"] = float(rng.uniform(-0.3, 1.3)), float(rng.uniform(-0.6, 0.6))
        p[f"mx{k}"], p[f"my{k}"] = _polar(rng, 0.5, 1.6)
        p[f"gx{k}"], p[f"gy{k}"] = _polar(rng, 0.5, 1.6)
        p[f"axis{k}"] = _axis_angle(rng)
    return p


@dataclass(frozen=True)
class Family:
    """A family: its variants, how to draw a variant's numbers, how to build its Draft."""

    name: str
    variants: tuple[str, ...]
    draw: Callable[[np.random.Generator, str], dict[str, float]]
    draft: Callable[[dict[str, float], str], Draft]
    limited: tuple[str, ...] = ()  # variants whose input has a limited range (rocking, ramp or limit drives)
    limit_capable: tuple[str, ...] = ()  # of those, the ones whose limit is a closed form


FAMILIES: dict[str, Family] = {
    f.name: f
    for f in (
        Family(
            "fourbar",
            ("crank-rocker", "double-crank", "rocker-crank", "double-rocker", "triple-rocker", *CHANGE_POINTS),
            draw_fourbar,
            fourbar_draft,
            limited=("rocker-crank", "double-rocker", "triple-rocker"),
            limit_capable=("rocker-crank", "double-rocker", "triple-rocker"),
        ),
        Family(
            "slider_crank",
            ("offset", "rocking"),
            draw_slider_crank,
            slider_crank_draft,
            limited=("rocking",),
            limit_capable=("rocking",),
        ),
        Family(
            "inverted_slider_crank",
            ("crank", "limited"),
            draw_inverted,
            inverted_draft,
            limited=("limited",),
            limit_capable=("limited",),
        ),
        Family("watt2", ("crank", "output"), draw_sixbar, watt2_draft, limited=("output",)),
        Family(
            "stephenson3", ("crank", "rocker", "output"), draw_sixbar, stephenson3_draft, limited=("rocker", "output")
        ),
        Family("fivebar", ("two-cranks",), draw_fivebar, fivebar_draft),
        Family("eightbar", ("paper", "tilted"), draw_eightbar, eightbar_draft),
        Family("attach", ("fourbar-1", "fourbar-2", "slider-1", "slider-2"), draw_attach, attach_draft),
    )
}


# ---------------------------------------------------------------- specs, drives, time spans


@dataclass(frozen=True)
class Spec:
    """Everything random about one mechanism: a pure function of (seed, index) via :func:`draw`."""

    family: str
    variant: str
    drive: str  # "constant" | "rocking" | "ramp" | "limit"
    seed: int
    index: int
    params: dict[str, float]

    @property
    def name(self) -> str:
        return f"c{self.index:05d}-{self.family}-{self.variant}"

    def to_dict(self) -> dict[str, Any]:
        return {
            "family": self.family,
            "variant": self.variant,
            "drive": self.drive,
            "seed": self.seed,
            "index": self.index,
            "params": dict(self.params),
        }

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> Spec:
        return cls(d["family"], d["variant"], d["drive"], int(d["seed"]), int(d["index"]), dict(d["params"]))


def _draw_drive(rng: np.random.Generator, fam: Family, variant: str, limit: bool, p: dict[str, float]) -> str:
    """The drive kind and its numbers (ω, α, samples, margins, ...) into ``p``."""
    p["omega"] = float(rng.uniform(0.5, 8.0)) * _sign(rng)
    p["alpha"] = 0.0 if rng.random() < 0.5 else float(rng.uniform(-0.3, 0.3)) * abs(p["omega"]) ** 2
    p["n"] = float(rng.integers(40, 241))
    p["margin"] = float(10 ** rng.uniform(-2.3, -1.0))  # the smallest dyad margin allowed along the run
    if fam.name == "fivebar":
        p["omega_b"] = float(rng.uniform(0.5, 8.0)) * _sign(rng)
        p["alpha_b"] = 0.0 if rng.random() < 0.5 else float(rng.uniform(-1, 1)) * abs(p["omega_b"]) ** 2
    if variant not in fam.limited:
        p["turns"] = float(rng.uniform(0.4, 2.0))
        return "constant"
    p["dir"] = _sign(rng)
    if limit:
        p["alpha"] = abs(p["alpha"]) * p["dir"] * 0.2
        p["omega"] = abs(p["omega"]) * p["dir"]
        p["k_stop"] = float(rng.integers(20, 160))
        p["u_stop"] = float(rng.uniform(0.25, 0.75))
        p["n_after"] = float(rng.integers(5, 60))
        return "limit"
    if rng.random() < 0.5:
        p["reach"] = float(rng.uniform(0.3, 0.95))
        return "ramp"
    p["rock_lo"], p["rock_hi"] = (float(x) for x in rng.uniform(0.02, 0.25, 2))
    p["period"] = float(rng.uniform(0.5, 4.0))
    p["cycles"] = float(rng.uniform(0.6, 2.5))
    return "rocking"


def _catalogue(families: Sequence[str] | None) -> dict[str, tuple[str, ...]]:
    """family -> allowed variants, from names like "fourbar" or "fourbar/kite" (None: everything)."""
    if not families:
        return {f: fam.variants for f, fam in FAMILIES.items()}
    out: dict[str, tuple[str, ...]] = {}
    for name in families:
        fam, _, variant = name.partition("/")
        if fam not in FAMILIES or (variant and variant not in FAMILIES[fam].variants):
            known = ", ".join(f"{f} ({'|'.join(x.variants)})" for f, x in FAMILIES.items())
            raise ValueError(f"unknown corpus family '{name}' (known: {known})")
        keep = (variant,) if variant else FAMILIES[fam].variants
        out[fam] = tuple(v for v in FAMILIES[fam].variants if v in (*out.get(fam, ()), *keep))
    return out


def choose(
    rng: np.random.Generator, families: Sequence[str] | None = None, limit_fraction: float = 0.1
) -> tuple[str, str, bool]:
    """(family, variant, limit run?): a family with probability ∝ √(its variants), then a variant; a limit run with
    probability ``limit_fraction``, among the variants whose limit is a closed form. ``families``
    names families or family/variant pairs (e.g. "fourbar/kite")."""
    allowed = _catalogue(families)
    if rng.random() < limit_fraction:
        choices = [(f, v) for f, vs in allowed.items() for v in vs if v in FAMILIES[f].limit_capable]
        if choices:
            fam, variant = choices[int(rng.integers(len(choices)))]
            return fam, variant, True
    names = list(allowed)
    weights = np.sqrt([len(allowed[f]) for f in names])  # a family with more variants gets more draws
    fam = names[int(rng.choice(len(names), p=weights / weights.sum()))]
    variants = allowed[fam]
    return fam, variants[int(rng.integers(len(variants)))], False


def draw(seed: int, index: int, family: str, variant: str, limit: bool, rng: np.random.Generator) -> Spec:
    """One draw of the numbers of a (family, variant) mechanism and its drive."""
    fam = FAMILIES[family]
    p = fam.draw(rng, variant)
    drive = _draw_drive(rng, fam, variant, limit, p)
    return Spec(family, variant, drive, int(seed), int(index), p)


def _nice(x: float, digits: int = 3) -> float:
    """x rounded to ``digits`` significant digits (a readable time step)."""
    if x <= 0 or not math.isfinite(x):
        raise Infeasible("time step not positive")
    e = math.floor(math.log10(x)) - digits + 1
    return round(x, -e) if e < 0 else float(round(x / 10**e) * 10**e)


@dataclass
class Motion:
    """The drive (driver table entries), the time grid and the expected stop of one mechanism."""

    drivers: list[dict[str, Any]]
    time: dict[str, float]
    samples: int
    stop_sample: int | None = None
    limit: dict[str, Any] | None = None
    notes: list[str] = field(default_factory=list)


def _constant(theta0: float, omega: float, alpha: float) -> Callable[[np.ndarray], np.ndarray]:
    return lambda t: theta0 + omega * t + 0.5 * alpha * t * t


def _first_bad(draft: Draft, inputs: list[Callable[[np.ndarray], np.ndarray]], t_end: float, n: int, m_min: float):
    """The first time on a grid DENSE× finer than the samples where a dyad margin drops below m_min."""
    t = np.linspace(0.0, t_end, DENSE * (n - 1) + 1)
    _, m = draft.forward([f(t) for f in inputs])
    bad = np.flatnonzero(m < m_min)
    return float(t[bad[0]]) if bad.size else None


def _crank_entry(draft: Draft, k: int, omega: float, alpha: float) -> dict[str, Any]:
    link, pivot = draft.drivers[k]
    return {"link": link, "pivot": pivot, "omega": omega, "alpha": alpha}


def _grid(h: float, n: int) -> dict[str, float]:
    return {"start": 0.0, "stop": float(repr_round(h * (n - 1))), "step": h}


def repr_round(x: float) -> float:
    """x with 12 significant digits: a stop time that reads well and still gives the intended sample count."""
    return float(f"{x:.12g}")


def plan_constant(draft: Draft, p: dict[str, float]) -> Motion:
    """Constant angular acceleration of every crank for ``turns`` turns, shortened to stay clear of limits."""
    n = int(p["n"])
    th = [_constant(draft.theta0(0), p["omega"], p["alpha"])]
    drivers = [_crank_entry(draft, 0, p["omega"], p["alpha"])]
    if len(draft.drivers) == 2:
        th.append(_constant(draft.theta0(1), p["omega_b"], p["alpha_b"]))
        drivers.append(_crank_entry(draft, 1, p["omega_b"], p["alpha_b"]))
    span = p["turns"] * TWO_PI / abs(p["omega"])
    h = _nice(span / (n - 1))
    m_min = 0.0 if draft.slack else p["margin"]
    bad = _first_bad(draft, th, h * (n - 1), n, m_min)
    notes = []
    if bad is not None:
        if bad < 0.3 * h * (n - 1):
            raise Infeasible("a dyad reaches its limit early in the run")
        n = int(0.85 * bad / h) + 1
        if n < 20 or _first_bad(draft, th, h * (n - 1), n, m_min) is not None:
            raise Infeasible("no clear span")
        notes.append("span shortened to 85 % of the time at which a dyad would come within its margin of a limit")
    motion = Motion(drivers, _grid(h, n), n, notes=notes)
    if draft.change_angles:
        _clear_of_change_points(draft, th[0], h, n)
    return motion


def _clear_of_change_points(draft: Draft, theta: Callable[[np.ndarray], np.ndarray], h: float, n: int) -> None:
    """No sample within CHANGE_POINT_CLEARANCE of a change point, where the two branches meet."""
    th = theta(h * np.arange(n))
    for c in draft.change_angles:
        if np.min(np.abs(np.remainder(th - c + math.pi, TWO_PI) - math.pi)) < CHANGE_POINT_CLEARANCE:
            raise Infeasible("a sample sits on a change point")


def _range(draft: Draft) -> tuple[float, float]:
    if draft.input_range is None:
        raise Infeasible("the input turns fully: no range to rock in or run into")
    lo, hi = draft.input_range
    return lo, hi


def plan_ramp(draft: Draft, p: dict[str, float]) -> Motion:
    """Constant speed from θ0 toward one end of the input's range, stopping short of it."""
    lo, hi = _range(draft)
    th0, n = draft.theta0(0), int(p["n"])
    if not lo < th0 < hi:  # the range is already kept clear of the limits: t = 0 must be inside it too
        raise Infeasible("t = 0 too close to a limit of the input")
    end = hi - 0.05 * (hi - lo) if p["dir"] > 0 else lo + 0.05 * (hi - lo)
    dist = (end - th0) * p["reach"]
    if dist * p["dir"] <= 1e-3 * (hi - lo):
        raise Infeasible("no room to move")
    omega = math.copysign(abs(p["omega"]), dist)
    h = _nice(dist / omega / (n - 1))
    th = [_constant(th0, omega, 0.0)]
    if _first_bad(draft, th, h * (n - 1), n, p["margin"]) is not None:
        raise Infeasible("ramp comes within the margin of a limit")
    return Motion([_crank_entry(draft, 0, omega, 0.0)], _grid(h, n), n)


def plan_rocking(draft: Draft, p: dict[str, float]) -> Motion:
    """A tabulated input θ(t) = c + A·sin(Ω·t + ψ) (columns t, theta, omega, alpha) inside the range."""
    lo, hi = _range(draft)
    th0, n, w = draft.theta0(0), int(p["n"]), hi - lo
    r_lo, r_hi = min(lo + p["rock_lo"] * w, th0 - 0.02 * w), max(hi - p["rock_hi"] * w, th0 + 0.02 * w)
    if r_lo <= lo + 0.01 * w or r_hi >= hi - 0.01 * w:
        raise Infeasible("θ0 too close to a limit to rock around it")
    c, amp = 0.5 * (r_lo + r_hi), 0.5 * (r_hi - r_lo)
    big = 2.0 * math.pi / p["period"]
    psi = math.asin(max(-1.0, min(1.0, (th0 - c) / amp)))
    if p["dir"] < 0:
        psi = math.pi - psi
    span = p["cycles"] * p["period"]
    rows = max(int(80 * p["cycles"]), 40)
    tp = np.linspace(0.0, span, rows + 1)
    prof = {
        "t": tp.tolist(),
        "theta": (c + amp * np.sin(big * tp + psi)).tolist(),
        "omega": (amp * big * np.cos(big * tp + psi)).tolist(),
        "alpha": (-amp * big * big * np.sin(big * tp + psi)).tolist(),
    }
    # the file's angles continue the link's t = 0 angle in [0, 2π) (docs/file-format.md); asin's t = 0 round-off removed
    shift = th0 % TWO_PI - th0
    prof["theta"] = [x + shift for x in prof["theta"]]
    prof["theta"][0] = th0 % TWO_PI
    h = _nice(span / (n - 1))
    n = math.floor(span / h + 1e-9) + 1
    th = [lambda t: c + amp * np.sin(big * t + psi)]
    if _first_bad(draft, th, h * (n - 1), n, p["margin"]) is not None:
        raise Infeasible("rocking comes within the margin of a limit")
    link, pivot = draft.drivers[0]
    motion = Motion([{"link": link, "pivot": pivot, "profile": prof}], _grid(h, n), n)
    motion.notes.append(
        f"tabulated rocking input θ(t) = {c:.6g} + {amp:.6g}·sin({big:.6g}·t + {psi:.6g}) rad, {rows + 1} rows "
        "with exact ω and α columns (quintic Hermite between rows)"
    )
    return motion


def plan_limit(draft: Draft, p: dict[str, float]) -> Motion:
    """Constant ω (and α, same sign) from θ0 past the closed-form limit angle; the stop sample is known.

    θ(t) = θ0 + ω·t + α·t²/2 reaches θ_lim at t_lim = Δ/|ω| (α = 0) or (√(ω² + 2|α|Δ) − |ω|)/|α|.
    The step h = t_lim/(K − 1 + u) puts the limit u of a step after sample K − 1: samples 0 … K − 1
    assemble, sample K does not, so every engine must return K samples.
    """
    if not draft.limit_capable:
        raise Infeasible("no closed-form limit")
    lo, hi = _range(draft)
    th0 = lo + (draft.theta0(0) - lo) % TWO_PI  # the t = 0 angle within the range: the limit one turn away or less
    lim = hi if p["dir"] > 0 else lo
    delta = abs(lim - th0)
    w, a = abs(p["omega"]), abs(p["alpha"])
    t_lim = delta / w if a == 0 else (math.sqrt(w * w + 2 * a * delta) - w) / a
    k, u = int(p["k_stop"]), p["u_stop"]
    h = t_lim / (k - 1 + u)
    n = k + int(p["n_after"])
    omega, alpha = math.copysign(w, p["dir"]), math.copysign(a, p["dir"])
    times = h * np.arange(n)
    theta = _constant(th0, omega, alpha)(times)
    past = np.flatnonzero(p["dir"] * (theta - lim) > 0)
    if not past.size or int(past[0]) != k:
        raise Infeasible("the limit does not fall where planned")
    _, m = draft.forward([theta[:k]])
    if np.any(m <= 0):
        raise Infeasible("a sample before the limit does not assemble")
    motion = Motion([_crank_entry(draft, 0, omega, alpha)], {"start": 0.0, "stop": float(times[-1]), "step": h}, n)
    motion.stop_sample = k
    motion.limit = {"angle": lim, "time": t_lim, "formula": draft.limit_formula}
    motion.notes.append(
        f"runs INTO its limit on purpose: θ_lim = {lim:.12g} rad ({draft.limit_formula}), reached at "
        f"t = {t_lim:.12g} s, {u:.2f} of a step after sample {k - 1}: expected stop at sample {k} of {n} "
        f"({k} samples solved)"
    )
    return motion


PLANS = {"constant": plan_constant, "ramp": plan_ramp, "rocking": plan_rocking, "limit": plan_limit}


# ---------------------------------------------------------------- build: Spec -> file


@dataclass
class Item:
    """One generated mechanism: its Spec, the TOML text, the sidecar and the loaded Mechanism."""

    spec: Spec
    text: str
    sidecar: dict[str, Any]
    mechanism: Any

    @property
    def name(self) -> str:
        return self.spec.name


def _xy(z: complex) -> list[float]:
    return [float(z.real), float(z.imag)]


def _file_dict(name: str, draft: Draft, motion: Motion) -> dict[str, Any]:
    out: dict[str, Any] = {"name": name, "title": f"corpus: {draft.notes[0].split(':')[0]} ({draft.variant})"}
    out["units"] = "m"
    out["joints"] = {j: _xy(z) for j, z in draft.joints.items()}
    links = {}
    for n, lk in draft.links.items():
        entry: dict[str, Any] = {"joints": list(lk["joints"])}
        if lk.get("ground"):
            entry["ground"] = True
        elif "length" in lk:
            entry["length"] = float(lk["length"])
        links[n] = entry
    out["links"] = links
    if draft.sliders:
        out["sliders"] = {
            n: {"joint": s["joint"], "guide": s["guide"], "axis": _xy(s["axis"])} for n, s in draft.sliders.items()
        }
    if draft.points:
        out["points"] = {n: {"link": lk, "at": _xy(z)} for n, (lk, z) in draft.points.items()}
    out["drivers"] = motion.drivers
    out["time"] = motion.time
    return out


def _comments(spec: Spec, draft: Draft, motion: Motion, closed_form: bool) -> str:
    lines = [
        f"Generated by vloop corpus ({GENERATOR}): seed {spec.seed}, index {spec.index}.",
        f"Reproduce: vloop corpus --seed {spec.seed} --start {spec.index} --n 1 --out DIR",
        f"Family {spec.family}, variant {spec.variant}, drive {spec.drive}.",
        *draft.notes,
        *motion.notes,
        f"Expected: {motion.samples} samples"
        + (f", STOP at sample {motion.stop_sample} (limit position)" if motion.stop_sample is not None else "")
        + f"; closed form: {'yes (validators.analytic)' if closed_form else 'none (coupled loops)'}.",
    ]
    return "".join(f"# {ln}\n" for ln in lines)


def build(spec: Spec) -> Item:
    """The mechanism file of ``spec`` (pure function of it); raises Infeasible when it cannot be made."""
    import tomli_w

    import vloop

    fam = FAMILIES[spec.family]
    p = dict(spec.params)
    if spec.variant in ("parallelogram", "antiparallelogram"):
        p["sigma"] = _parallelogram_sigma(p, spec.variant == "antiparallelogram")
    with np.errstate(all="ignore"):
        draft = fam.draft(p, spec.variant)
        _stated_lengths(draft)
        motion = PLANS[spec.drive](draft, p)
    name = spec.name
    closed_form = draft.closed_form
    text = _comments(spec, draft, motion, closed_form) + "\n" + tomli_w.dumps(_file_dict(name, draft, motion))
    try:
        mech = vloop.loads(text, source=f"{name}.toml")
        vloop.compile(mech)
    except vloop.VloopError as exc:
        raise Infeasible(f"vloop refused it: {exc}") from None
    if len(mech.times) != motion.samples:
        raise Infeasible(f"time grid gives {len(mech.times)} samples, planned {motion.samples}")
    expect_samples = motion.stop_sample if motion.stop_sample is not None else motion.samples
    sidecar = {
        "generator": GENERATOR,
        "name": name,
        **spec.to_dict(),
        "closed_form": closed_form,
        "change_point": bool(draft.change_angles),
        "samples": motion.samples,
        "expect": {"samples": expect_samples, "stop_sample": motion.stop_sample, "limit": motion.limit},
        "notes": [*draft.notes, *motion.notes],
        "reproduce": f"vloop corpus --seed {spec.seed} --start {spec.index} --n 1 --out DIR",
    }
    return Item(spec, text, sidecar, mech)


@dataclass
class Draw:
    """The outcome of drawing one mechanism: the Item, and the specs vloop refused on the way."""

    item: Item
    refused: list[dict[str, Any]]
    attempts: int


def draw_item(seed: int, index: int, families: Sequence[str] | None = None, limit_fraction: float = 0.1) -> Draw:
    """Mechanism ``index`` of corpus ``seed``: its family, variant and drive kind are chosen once
    (:func:`choose`), then its numbers are drawn from the same random stream until they build."""
    rng = np.random.default_rng([seed, index])
    family, variant, limit = choose(rng, families, limit_fraction)
    refused: list[dict[str, Any]] = []
    for attempt in range(1, MAX_DRAWS + 1):
        spec = draw(seed, index, family, variant, limit, rng)
        try:
            return Draw(build(spec), refused, attempt)
        except Infeasible as exc:
            if str(exc).startswith("vloop refused"):
                refused.append({"spec": spec.to_dict(), "message": str(exc)})
    raise RuntimeError(f"corpus: no buildable mechanism in {MAX_DRAWS} draws for seed {seed}, index {index}")


def generate(
    n: int,
    seed: int,
    *,
    start: int = 0,
    families: Sequence[str] | None = None,
    limit_fraction: float = 0.1,
) -> tuple[list[Item], list[dict[str, Any]]]:
    """Mechanisms ``start`` … ``start + n − 1`` of corpus ``seed`` and every spec vloop refused."""
    _catalogue(families)  # unknown names fail here, before any drawing
    items, refused = [], []
    for i in range(start, start + n):
        d = draw_item(seed, i, families, limit_fraction)
        items.append(d.item)
        refused += d.refused
    return items, refused


def write(
    items: Sequence[Item], out: str | Path, *, seed: int, refused: Sequence[dict[str, Any]] = (), **settings: Any
) -> list[Path]:
    """NAME.toml and NAME.json for every item and a corpus.json manifest, atomically, inside ``out``."""
    from vloop.files.output import ensure_folder

    out = ensure_folder(out)
    written = [_write_item(out, it) for it in items]
    _write_manifest(out, seed, settings, [f"{it.name}.toml" for it in items], _family_counts(items), refused,
                    sum(1 for it in items if it.sidecar["expect"]["stop_sample"] is not None))  # fmt: skip
    return written


def generate_into(
    out: str | Path,
    n: int,
    seed: int,
    *,
    start: int = 0,
    families: Sequence[str] | None = None,
    limit_fraction: float = 0.1,
) -> list[Path]:
    """:func:`generate` and :func:`write` one mechanism at a time (memory: the file names and the counts, not the
    mechanisms: a 10,000-mechanism corpus costs what a 1,000 one does); the files written, in index order."""
    from vloop.files.output import ensure_folder

    _catalogue(families)
    out = ensure_folder(out)
    written, refused, counts, limits = [], [], {}, 0
    for i in range(start, start + n):
        d = draw_item(seed, i, families, limit_fraction)
        written.append(_write_item(out, d.item))
        refused += d.refused
        key = f"{d.item.spec.family}/{d.item.spec.variant}"
        counts[key] = counts.get(key, 0) + 1
        limits += d.item.sidecar["expect"]["stop_sample"] is not None
    settings = {"start": start, "families": families, "limit_fraction": limit_fraction}
    _write_manifest(out, seed, settings, [p.name for p in written], dict(sorted(counts.items())), refused, limits)
    return written


def _write_item(out: Path, it: Item) -> Path:
    from vloop.files.output import write_text

    path = write_text(out / f"{it.name}.toml", it.text)
    write_text(out / f"{it.name}.json", json.dumps(it.sidecar, indent=1, allow_nan=False))
    return path


def _write_manifest(
    out: Path,
    seed: int,
    settings: dict,
    files: list[str],
    families: dict[str, int],
    refused: Sequence[dict],
    limits: int,
) -> None:
    """corpus.json: the generator, seed and settings, the families' counts, what vloop refused, the files."""
    from vloop.files.output import write_text

    manifest = {
        "generator": GENERATOR,
        "seed": seed,
        "n": len(files),
        "settings": settings,
        "families": families,
        "limit_runs": limits,
        "refused": list(refused),
        "files": files,
    }
    write_text(out / "corpus.json", json.dumps(manifest, indent=1, allow_nan=False))


def _family_counts(items: Iterable[Item]) -> dict[str, int]:
    out: dict[str, int] = {}
    for it in items:
        key = f"{it.spec.family}/{it.spec.variant}"
        out[key] = out.get(key, 0) + 1
    return dict(sorted(out.items()))


def read_sidecar(path: str | Path) -> dict[str, Any] | None:
    """The sidecar JSON next to a corpus file (NAME.json for NAME.toml), or None if there is none.

    A JSON file that is not a corpus sidecar (no ``generator`` key of ours) is ignored; one that claims to
    be but has a missing or malformed field raises MechanismError naming the file and the field.
    """
    from vloop.errors import MechanismError

    side = Path(path).with_suffix(".json")
    if not side.is_file():
        return None
    try:
        data = json.loads(side.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    if not isinstance(data, dict) or data.get("generator") != GENERATOR:
        return None
    problem = _sidecar_problem(data)
    if problem:
        raise MechanismError(f"{side}: corpus sidecar {problem}", entry="sidecar")
    return data


def _is_int(x: Any, lo: int = 0) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and lo <= x < 2**63


def _sidecar_problem(d: dict[str, Any]) -> str:
    """What is wrong with a sidecar's fields ("" if nothing): the harness and the shrinker trust them."""
    fam, variant = d.get("family"), d.get("variant")
    if not isinstance(fam, str) or fam not in FAMILIES or variant not in FAMILIES[fam].variants:
        return "field 'family'/'variant': not a known family and variant"
    if not isinstance(d.get("drive"), str) or d["drive"] not in PLANS:
        return f"field 'drive': must be one of {', '.join(PLANS)}"
    if not _is_int(d.get("seed")) or not _is_int(d.get("index")):
        return "fields 'seed' and 'index' must be non-negative integers"
    params = d.get("params")
    if not isinstance(params, dict) or not all(
        isinstance(k, str) and isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        for k, v in params.items()
    ):
        return "field 'params' must map names to finite numbers"
    exp = d.get("expect")
    if not isinstance(exp, dict) or not _is_int(exp.get("samples")):
        return "field 'expect.samples' must be a non-negative integer"
    stop = exp.get("stop_sample")
    if stop is not None and not (_is_int(stop) and stop <= exp["samples"]):
        return "field 'expect.stop_sample' must be null or an integer up to expect.samples"
    if not isinstance(d.get("closed_form"), bool):
        return "field 'closed_form' must be true or false"
    return ""
