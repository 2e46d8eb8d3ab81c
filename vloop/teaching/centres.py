"""Instant centres of every pair of bodies, by two independent constructions.

An instant centre I_ab is the point where bodies a and b have the same velocity: their relative
motion is, for that instant, a rotation about I_ab (or a translation, when I_ab is at infinity).

* :func:`kennedy_centres` — geometry only (positions, never velocities). Primary centres: a pin
  joining a and b is I_ab; a block sliding on its guide has I at infinity, perpendicular to the
  sliding axis. Then Kennedy's theorem (the three centres I_ab, I_bc, I_ac of any three bodies lie
  on one line) is applied until no more centres can be found: I_ac is the intersection of the
  lines I_ab–I_bc and I_ad–I_dc for two different third bodies b, d. Some pairs are out of its
  reach (every pair but the pins in a five-bar with two inputs; a few in some six-bars): those
  stay ``found = False``.
* :func:`velocity_centres` — velocities only: with P any point, the relative velocity of the two
  bodies at P, Δv = v_a(P) − v_b(P), and their relative angular velocity Δω = ω_a − ω_b,
  I = P + j·Δv/Δω (complex numbers, j·z turns z by +90°). Δω = 0 puts I at infinity, in the
  direction perpendicular to Δv (a pure relative translation).

Both work in homogeneous coordinates h = (x/L, y/L, w) with L the mechanism's size (``mech.scale``),
normalised to unit length with w >= 0: a centre at distance r is (x/L, y/L, 1)/√(1 + r²/L²), a
centre at infinity in direction u is (u_x, u_y, 0). Lines and intersections are cross products,
so centres at infinity need no special case, and two constructions are compared by the distance
between their unit vectors (sign-free), which is the distance in mechanism sizes near the
mechanism and the angle seen from the origin far away. A centre farther than ``FAR`` mechanism
sizes is reported at infinity (its direction is then known to about 1/FAR, its distance not at all).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from ..model import Mechanism
from ..result import Result
from . import _motion

FAR = 1e8  # beyond this many mechanism sizes a centre is reported at infinity
LINE_MIN = 1e-9  # two centres closer than this (in mechanism sizes) do not define a line
KENNEDY_MIN = 1e-6  # intersection quality below this: the construction is too ill-conditioned to trust
VELOCITY_MIN = 1e-13  # relative motion below this fraction of the bodies' own motion: no centre
TOP_LINES = 4  # Kennedy: per sample, the intersections of the best-defined lines only


@dataclass(frozen=True)
class CentreSet:
    """Instant centres of body pairs over a run, in unit homogeneous coordinates (module docstring).

    ``pairs[p] = (a, b)`` in the mechanism's body order (ground first); ``h[k, p]`` = (x/L, y/L, w)
    at sample k, unit length, w >= 0; ``found[k, p]`` False where the construction gives no centre.
    """

    pairs: tuple[tuple[str, str], ...]
    h: np.ndarray
    found: np.ndarray
    scale: float
    method: str

    def index(self, a: str, b: str) -> int:
        """Column of the pair (a, b) in either order."""
        for p, pair in enumerate(self.pairs):
            if pair in ((a, b), (b, a)):
                return p
        raise KeyError(f"no pair of bodies ({a}, {b})")

    def position(self, a: str, b: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, y, at_infinity) of I_ab [length]; at infinity (x, y) is the unit direction of the centre,
        its sign chosen so the direction's angle lies in [0°, 180°). Not found: (0, 0, False)."""
        return to_cartesian(self.h[:, self.index(a, b)], self.scale)

    def unreachable(self) -> list[tuple[str, str]]:
        """Pairs this construction finds at no sample."""
        return [pair for p, pair in enumerate(self.pairs) if not self.found[:, p].any()]


def to_cartesian(h: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(x, y, at_infinity) from unit homogeneous centres h (..., 3); see :meth:`CentreSet.position`."""
    xy = h[..., 0] + 1j * h[..., 1]
    w = h[..., 2]
    inf = np.abs(w) * FAR <= np.abs(xy)
    with np.errstate(divide="ignore", invalid="ignore"):
        finite = np.where(inf, 0.0, xy * scale / np.where(inf, 1.0, w))
        u = np.where(np.abs(xy) > 0, xy / np.abs(xy), 0.0)
    u = np.where((np.angle(u) < 0) | (np.angle(u) >= np.pi), -u, u)
    z = np.where(inf, u, finite)
    return z.real, z.imag, inf & (np.abs(xy) > 0)


def distance(h1: np.ndarray, h2: np.ndarray) -> np.ndarray:
    """Distance between unit homogeneous centres, sign-free: in mechanism sizes near the mechanism."""
    return np.minimum(np.linalg.norm(h1 - h2, axis=-1), np.linalg.norm(h1 + h2, axis=-1))


def body_pairs(mech: Mechanism) -> tuple[tuple[str, str], ...]:
    """Every pair of bodies, in the mechanism's body order (ground, links, slider blocks)."""
    return tuple(combinations(mech.body_names, 2))


def _unit(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors along the last axis (w >= 0) and the original norms."""
    n = np.linalg.norm(h, axis=-1)
    with np.errstate(divide="ignore", invalid="ignore"):
        u = np.where(n[..., None] > 0, h / np.where(n > 0, n, 1.0)[..., None], 0.0)
    flip = (u[..., 2] < 0) | ((u[..., 2] == 0) & ((u[..., 1] < 0) | ((u[..., 1] == 0) & (u[..., 0] < 0))))
    return np.where(flip[..., None], -u, u), n


def _homogeneous(z: np.ndarray, scale: float) -> np.ndarray:
    """Unit homogeneous coordinates of finite points z [complex, length]."""
    return _unit(np.stack([z.real / scale, z.imag / scale, np.ones(z.shape)], axis=-1))[0]


# ------------------------------------------------------------------ Kennedy's theorem


def primary_centres(mech: Mechanism, result: Result) -> tuple[np.ndarray, np.ndarray]:
    """(h, found) with the primary centres only: pins (the joint) and sliders (at infinity, ⟂ axis)."""
    pairs = body_pairs(mech)
    n = len(result.t)
    h = np.zeros((n, len(pairs), 3))
    found = np.zeros((n, len(pairs)), bool)
    col = {pair: p for p, pair in enumerate(pairs)} | {(b, a): p for p, (a, b) in enumerate(pairs)}
    for joint in mech.joints:
        at = mech.bodies_at(joint)
        if len(at) < 2:
            continue
        hj = _homogeneous(_motion.point(result, joint), mech.scale)
        for a, b in combinations(at, 2):
            h[:, col[a, b]] = hj
            found[:, col[a, b]] = True
    for name, sl in mech.sliders.items():
        normal = 1j * np.exp(1j * result[f"{name}.theta"])  # the block's θ is its axis direction
        h[:, col[name, sl.guide]] = _unit(np.stack([normal.real, normal.imag, np.zeros(n)], axis=-1))[0]
        found[:, col[name, sl.guide]] = True
    return h, found


def kennedy_centres(mech: Mechanism, result: Result) -> CentreSet:
    """Instant centres [unit homogeneous, mechanism sizes] by Kennedy's theorem from positions alone.

    At each sample, among the pairs of Kennedy lines for a pair of bodies, the best-conditioned
    intersection is kept (quality: the sine between the lines times the shorter line's defining
    span, both in unit homogeneous terms); below ``KENNEDY_MIN`` the centre is left not found there.
    """
    h, found = primary_centres(mech, result)
    pairs = body_pairs(mech)
    bodies = mech.body_names
    col = {pair: p for p, pair in enumerate(pairs)} | {(b, a): p for p, (a, b) in enumerate(pairs)}
    H = np.ascontiguousarray(h.transpose(1, 2, 0))  # (pair, component, sample): contiguous rows
    F = np.ascontiguousarray(found.T)
    progress = True
    while progress:
        progress = False
        for p, (a, b) in enumerate(pairs):
            if F[p].all():
                continue
            lines = _kennedy_lines(H, F, [(col[a, m], col[m, b]) for m in bodies if m not in (a, b)])
            if len(lines) < 2:
                continue
            x, quality = _best_intersection(lines)
            new = (quality > KENNEDY_MIN) & ~F[p]
            if new.any():
                H[p][:, new] = _unit3(x[:, new])[0]
                F[p] |= new
                progress = True
    return CentreSet(pairs, H.transpose(2, 0, 1).copy(), F.T.copy(), mech.scale, "kennedy")


def _cross3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of component-major (3, n) arrays (numpy's cross copies strided input)."""
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _unit3(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`_unit` for component-major (3, n) arrays."""
    u, n = _unit(a.T)
    return u.T, n


def _kennedy_lines(H: np.ndarray, F: np.ndarray, via: list[tuple[int, int]]) -> list[tuple[np.ndarray, np.ndarray]]:
    """Lines through I_am and I_mb for each third body m: (unit line (3, n), quality; 0 where undefined)."""
    out = []
    for p1, p2 in via:
        ok = F[p1] & F[p2]
        if not ok.any():
            continue
        line = _cross3(H[p1], H[p2])
        span = np.sqrt(line[0] ** 2 + line[1] ** 2 + line[2] ** 2)
        good = ok & (span > LINE_MIN)
        out.append((line / np.where(good, span, 1.0), np.where(good, span, 0.0)))
    return out


def _best_intersection(lines: list[tuple[np.ndarray, np.ndarray]]) -> tuple[np.ndarray, np.ndarray]:
    """Per sample, the best-conditioned intersection (3, n) of two of the lines, and its quality.

    With many third bodies only the ``TOP_LINES`` best-defined lines of each sample are paired
    (their pairs cost O(TOP_LINES²) instead of O(lines²): the Jansen pair has 12 per pair of bodies).
    """
    n = len(lines[0][1])
    if len(lines) > TOP_LINES:
        L = np.stack([line for line, _ in lines])  # (m, 3, n)
        Q = np.stack([q for _, q in lines])  # (m, n)
        pick = np.argsort(-Q, axis=0, kind="stable")[:TOP_LINES]
        cols = np.arange(n)
        lines = [(L[pick[i], :, cols].T, Q[pick[i], cols]) for i in range(TOP_LINES)]
    best = np.zeros((3, n))
    quality = np.zeros(n)
    for (l1, q1), (l2, q2) in combinations(lines, 2):
        x = _cross3(l1, l2)
        q = np.sqrt(x[0] ** 2 + x[1] ** 2 + x[2] ** 2) * np.minimum(q1, q2)
        better = q > quality
        best[:, better] = x[:, better]
        quality = np.where(better, q, quality)
    return best, quality


# ------------------------------------------------------------------ velocity field


def velocity_centres(mech: Mechanism, result: Result) -> CentreSet:
    """Instant centres [unit homogeneous, mechanism sizes] from the velocity field: I = P + j·Δv/Δω.

    P is body a's first joint; Δv = v_a(P) − v_b(P) from the Result's point velocities and ω.
    Where the relative motion is below ``VELOCITY_MIN`` of the bodies' own motion (both at rest) the
    centre is not found; for one driver, samples where the input is at rest use the velocity
    coefficients of the same configurations instead (:func:`vloop.teaching._motion.unit_rate_result`).
    """
    pairs = body_pairs(mech)
    n = len(result.t)
    source = result
    rest = np.zeros(n, bool)
    if len(mech.drivers) == 1 and n:
        rest = _motion.at_rest(_motion.input_rate(mech, result))
        if rest.any():
            source = _motion.unit_rate_result(mech, result)
    h = np.zeros((n, len(pairs), 3))
    found = np.zeros((n, len(pairs)), bool)
    for res, rows in ((result, ~rest), (source, rest)):
        if rows.any():
            hp, ok = _relative_centres(mech, res, pairs)
            h[rows], found[rows] = hp[rows], ok[rows]
    return CentreSet(pairs, h, found, mech.scale, "velocity")


def _relative_centres(
    mech: Mechanism, result: Result, pairs: tuple[tuple[str, str], ...]
) -> tuple[np.ndarray, np.ndarray]:
    """Every pair at once: bodies stacked (body, sample), pairs gathered by index."""
    bodies = mech.body_names
    at = {b: i for i, b in enumerate(bodies)}
    refs = [_motion.reference_joint(mech, b) for b in bodies]
    P = np.stack([_motion.point(result, r) for r in refs])
    V = np.stack([_motion.point_velocity(result, r) * (b != mech.ground) for b, r in zip(bodies, refs, strict=True)])
    W = np.stack([_motion.omega(mech, result, b) for b in bodies])
    ia = np.array([at[a] for a, _ in pairs], int)
    ib = np.array([at[b] for _, b in pairs], int)
    L = mech.scale
    Pa = P[ia]  # P = body a's first joint; body b's point there moves with v_b + j·ω_b·(P − P_b)
    dv = V[ia] - V[ib] - 1j * W[ib] * (Pa - P[ib])
    dw = W[ia] - W[ib]
    num = Pa / L * dw + 1j * dv / L  # (I/L)·Δω, so h ∝ (I/L, 1)·Δω
    h, norm = _unit(np.stack([num.real, num.imag, dw], axis=-1))
    own = np.maximum(np.abs(W), np.abs(V) / L)  # each body's own motion, to judge "no relative motion"
    ok = norm > VELOCITY_MIN * np.maximum(own[ia], own[ib])
    return h.transpose(1, 0, 2), ok.T


# ------------------------------------------------------------------ both, merged


@dataclass(frozen=True)
class InstantCentres:
    """The instant centres a user reads: Kennedy's where it reaches, the velocity field's elsewhere.

    ``source[k, p]``: 1 Kennedy's theorem, 2 the velocity field (Kennedy cannot reach this pair
    here), 0 neither (bodies at rest at an instant Kennedy cannot reach; x = y = 0 there).
    """

    centres: CentreSet
    source: np.ndarray
    kennedy: CentreSet
    velocity: CentreSet

    @property
    def pairs(self) -> tuple[tuple[str, str], ...]:
        return self.centres.pairs

    def position(self, a: str, b: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(x, y, at_infinity) of I_ab [length]; at infinity (x, y) is the centre's unit direction."""
        return self.centres.position(a, b)

    def from_velocity_field(self) -> list[tuple[str, str]]:
        """Pairs filled from the velocity field at one sample or more (Kennedy does not reach them there)."""
        return [pair for p, pair in enumerate(self.pairs) if (self.source[:, p] == 2).any()]


def instant_centres(mech: Mechanism, result: Result) -> InstantCentres:
    """Every pair's instant centre over the run [length]: Kennedy's theorem, filled from the velocity field."""
    k = kennedy_centres(mech, result)
    v = velocity_centres(mech, result)
    use_v = ~k.found & v.found
    h = np.where(use_v[..., None], v.h, k.h)
    source = np.where(k.found, 1, np.where(v.found, 2, 0)).astype(np.int8)
    merged = CentreSet(k.pairs, h, k.found | v.found, mech.scale, "merged")
    return InstantCentres(merged, source, k, v)
