"""Motion generation: a four-bar whose coupler carries a body through given poses (x, y of a point P on it, θ).

Poses k = 1..N: P_k (complex) and θ_k; α_k = θ_k − θ_1, δ_k = P_k − P_1; the displacement from pose 1 to pose k
is D_k(z) = P_k + e^{jα_k}(z − P_1). A dyad is a ground pivot M (centre point, Burmester's Mittelpunkt) and a
moving pivot A (circle point, at pose 1) whose distance from M stays the same in every pose: |D_k(A) − M| =
|A − M|. Two dyads on one coupler make the four-bar (crank O2A, coupler AB carrying P, rocker O4B).

* **Standard dyad form** (Erdman & Sandor): with W = A − M and Z = P_1 − A, W·(e^{jβ_k} − 1) + Z·(e^{jα_k} − 1)
  = δ_k, β_k the link's rotation. Linear in W, Z once the β's are chosen: two positions take Z (the moving
  pivot) or M (then Z·(e^{jα} − e^{jβ}) = δ − (P_1 − M)(e^{jβ} − 1)) with β; three positions take β_2, β_3.
* **Three positions, a pivot chosen**: the circle point of a centre point M is the circumcentre of M and its
  inverted positions D_k⁻¹(M); the centre point of a circle point A is the circumcentre of A, D_2(A), D_3(A).
* **Four and five positions (Burmester)**: written in M and a = A − P_1, each position gives
  g_k = |P_k − M + e^{jα_k}a|² − |P_1 − M + a|² = 0 (k = 2..N), linear in a for a given M. Four positions:
  three equations in a are consistent only where det[p_k(M) | c_k(M)] = 0, a cubic in M — the centre-point
  curve (found along rays from the poses' centre, where it is a cubic in the distance, by its roots); each
  centre point's circle point follows by least squares (the circle-point curve). Five positions: the
  Burmester points are the centre points of positions 1234 where g_5 = 0 too — sign changes of g_5 along the
  1234 curve, refined by Newton on g_2..g_5 in (M, a); at most four are real. Every pair of dyads is a
  candidate four-bar, either dyad driving.

Without free choices (two to four positions) the dyads are searched: centre points on a grid over a region
(two positions: with a few rotations β each; four: samples of the centre-point curve), every pair a four-bar,
the whole population screened by vloop's batched solver (reaches the poses in order on one branch, transmission
angle), the best re-solved exactly (:mod:`vloop.synthesis.defects`).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ..errors import SynthesisError
from . import arguments as args
from ._evaluate import evaluate
from .candidates import Candidates, Task, shortfall
from .circuits import classify, screen
from .defects import Draft, Requirements, assess, population_transmission
from .fit import match
from .linkages import FOURBAR

TWO_PI = 2.0 * math.pi
COINCIDENT = 1e-9  # of the size: two poses closer than this (and at the same angle) are one pose
RAYS = 720  # rays along which the centre-point curve is found
SCREEN_SAMPLES = 180


@dataclass(frozen=True)
class Poses:
    """Poses in normalised units: points ``p`` (N,) complex and angles ``theta`` (N,) [rad], with the centre and
    size [length] that map them back (world = centre + size·normalised)."""

    p: np.ndarray
    theta: np.ndarray
    centre: complex
    size: float

    @property
    def alpha(self) -> np.ndarray:
        return self.theta - self.theta[0]

    @property
    def delta(self) -> np.ndarray:
        return self.p - self.p[0]

    def move(self, k: int, z: np.ndarray) -> np.ndarray:
        """D_k: a point carried by the body from pose 1 to pose k."""
        return self.p[k] + np.exp(1j * self.alpha[k]) * (z - self.p[0])

    def back(self, k: int, z: np.ndarray) -> np.ndarray:
        """D_k⁻¹: the point of pose 1 that the body carries to z in pose k."""
        return self.p[0] + np.exp(-1j * self.alpha[k]) * (z - self.p[k])


def poses_of(raw: object) -> Poses:
    """Poses [[x, y, θ], ...] checked (2 to 5, finite, no two the same) and normalised."""
    arr = np.asarray(raw, float) if _is_table(raw) else None
    if arr is None or arr.ndim != 2 or arr.shape[1] != 3:
        raise SynthesisError("[motion] poses must be a list of [x, y, theta] triples", entry="motion.poses")
    if not np.all(np.isfinite(arr)):
        raise SynthesisError("[motion] poses must be finite numbers", entry="motion.poses")
    n = len(arr)
    if not 2 <= n <= 5:
        more = " (more poses than five: no four-bar in general; use path generation)" if n > 5 else ""
        raise SynthesisError(f"[motion] motion generation takes 2 to 5 poses, got {n}{more}", entry="motion.poses")
    z = arr[:, 0] + 1j * arr[:, 1]
    centre = complex(np.mean(z))
    size = float(np.hypot(np.ptp(arr[:, 0]), np.ptp(arr[:, 1])))
    if not size > 0:
        size = 1.0
    for i in range(n):
        for j in range(i):
            same_angle = abs(math.remainder(arr[i, 2] - arr[j, 2], TWO_PI)) <= COINCIDENT
            if abs(z[i] - z[j]) <= COINCIDENT * size and same_angle:
                raise SynthesisError(f"[motion] poses {j + 1} and {i + 1} coincide", entry="motion.poses")
    _one_pole(z, arr[:, 2], size)
    return Poses((z - centre) / size, arr[:, 2].copy(), centre, size)


def _one_pole(z: np.ndarray, theta: np.ndarray, size: float) -> None:
    """Refuse poses that all turn about one point (the displacement poles P1k, z = D_k(z), coincide): every
    moving pivot's centre point is that pole, so both dyads share one ground pivot: a crank, no four-bar."""
    rot = np.exp(1j * (theta[1:] - theta[0]))
    if len(rot) < 2 or np.any(np.abs(rot - 1) < 1e-9):  # two poses: any pole has dyads about it
        return
    poles = (z[1:] - rot * z[0]) / (1 - rot)
    if np.max(np.abs(poles - poles[0])) <= COINCIDENT * max(size, float(np.max(np.abs(poles)))):
        raise SynthesisError(
            f"[motion] the poses all turn about one point ({poles[0].real + 0.0:.6g}, {poles[0].imag + 0.0:.6g}): the "
            "body is a "
            "crank pinned there (every moving pivot's ground pivot is that point), no four-bar",
            entry="motion.poses",
        )


def _is_table(raw: object) -> bool:
    try:
        np.asarray(raw, float)
    except (TypeError, ValueError, OverflowError):
        return False
    return True


# ---------------------------------------------------------------- dyads


def circumcentre(z1: complex, z2: complex, z3: complex) -> complex | None:
    """The centre of the circle through three points (None when they are collinear)."""
    b, c = z2 - z1, z3 - z1
    den = 2 * (b.conjugate() * c).imag
    if abs(den) <= 1e-14 * max(abs(b), abs(c), 1e-300) ** 2:
        return None
    return z1 - 1j * (abs(b) ** 2 * c - abs(c) ** 2 * b) / den


def circle_point(ps: Poses, centre: complex) -> complex | None:
    """Three poses: the moving pivot (pose 1) whose ground pivot is ``centre``."""
    return circumcentre(centre, ps.back(1, centre), ps.back(2, centre))


def centre_point(ps: Poses, moving: complex) -> complex | None:
    """Three poses: the ground pivot of the moving pivot ``moving`` (pose 1)."""
    return circumcentre(moving, ps.move(1, moving), ps.move(2, moving))


def dyad_from_rotations(ps: Poses, beta: Sequence[float], moving: complex | None = None, fixed: complex | None = None):
    """The standard dyad form: (M, A) from the link's rotations β_k (two positions also need the moving or the
    fixed pivot; three positions take β_2, β_3)."""
    e_b = np.exp(1j * np.asarray(beta, float)) - 1
    e_a = np.exp(1j * ps.alpha[1:]) - 1
    d = ps.delta[1:]
    if len(ps.p) == 3:
        mat = np.array([[e_b[0], e_a[0]], [e_b[1], e_a[1]]])
        if abs(np.linalg.det(mat)) < 1e-12:
            return None
        W, Z = np.linalg.solve(mat, d)
    elif moving is not None:
        Z = ps.p[0] - moving
        if abs(e_b[0]) < 1e-12:
            return None
        W = (d[0] - Z * e_a[0]) / e_b[0]
    else:
        den = np.exp(1j * ps.alpha[1]) - np.exp(1j * beta[0])
        if fixed is None or abs(den) < 1e-12:
            return None
        Z = (d[0] - (ps.p[0] - fixed) * e_b[0]) / den
        W = ps.p[0] - Z - fixed
    A = ps.p[0] - Z
    return A - W, A


# ---------------------------------------------------------------- Burmester


def _g_parts(ps: Poses, M: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For centre points M (m,): the equations g_k = c_k + p_k·a (k = 2..N) as (m, N−1) constants c and
    (m, N−1, 2) coefficients p of a = (a_x, a_y)."""
    P1 = ps.p[0]
    w1 = P1 - M  # (m,)
    c, p = [], []
    for k in range(1, len(ps.p)):
        wk = ps.p[k] - M
        rot = np.exp(1j * ps.alpha[k])
        c.append(np.abs(wk) ** 2 - np.abs(w1) ** 2)
        q = 2 * (np.conj(wk) * rot - np.conj(w1))  # g ∋ Re(q·a)
        p.append(np.stack([q.real, -q.imag], -1))
    return np.stack(c, 1), np.stack(p, 1)


def centre_curve(ps: Poses, rays: int = RAYS, reach: float = 20.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Four poses: points of the centre-point curve (within ``reach`` sizes of the poses' centre) and their circle
    points (pose 1), with the ray index of each. Along a ray M = r·u the consistency determinant is a cubic in
    r (exactly: entries affine in r), found from four values and solved."""
    phi = np.arange(rays) * math.pi / rays
    u = np.exp(1j * phi)
    rs = np.array([-1.0, 0.0, 1.0, 2.0])
    dets = np.stack([np.linalg.det(_consistency(ps, r * u)) for r in rs], 1)  # (rays, 4)
    coef = np.linalg.solve(np.vander(rs, 4), dets.T).T  # cubic coefficients, highest first
    r, i = _real_roots(coef)
    keep = np.abs(r) <= reach
    M = r[keep] * u[i[keep]]
    return M, circle_points(ps, M), i[keep]


def _real_roots(coef: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The real roots of cubics (rows of ``coef``, highest power first) and the row of each: the eigenvalues of
    the companion matrices, all rows at once (a row whose leading coefficient vanishes is solved alone)."""
    big = np.max(np.abs(coef), axis=1)
    cubic = np.abs(coef[:, 0]) > 1e-12 * big
    roots, rows = [], []
    if cubic.any():
        c = coef[cubic] / coef[cubic, :1]
        comp = np.zeros((len(c), 3, 3))
        comp[:, 0, :] = -c[:, 1:]
        comp[:, 1, 0] = comp[:, 2, 1] = 1.0
        ev = np.linalg.eigvals(comp)
        real = np.abs(ev.imag) <= 1e-9 * np.maximum(1.0, np.abs(ev))
        k, j = np.nonzero(real)
        roots.append(ev[k, j].real)
        rows.append(np.nonzero(cubic)[0][k])
    for i in np.nonzero(~cubic & (big > 0))[0]:
        ev = np.roots(np.trim_zeros(np.where(np.abs(coef[i]) > 1e-12 * big[i], coef[i], 0.0), "f"))
        ev = ev[np.abs(ev.imag) <= 1e-9 * np.maximum(1.0, np.abs(ev))].real
        roots.append(ev)
        rows.append(np.full(len(ev), i))
    if not roots:
        return np.zeros(0), np.zeros(0, int)
    r, i = np.concatenate(roots), np.concatenate(rows).astype(int)
    order = np.lexsort((r, i))
    return r[order], i[order]


def _consistency(ps: Poses, M: np.ndarray) -> np.ndarray:
    """(m, 3, 3): rows [p_k | c_k] of the first three equations (k = 2, 3, 4)."""
    c, p = _g_parts(ps, M)
    return np.concatenate([p[:, :3, :], c[:, :3, None]], 2)


def circle_points(ps: Poses, M: np.ndarray) -> np.ndarray:
    """The circle point (pose 1) of each centre point, least squares over the equations g_k (the normal
    equations of every point at once; exact where the equations are consistent)."""
    if not len(M):
        return np.zeros(0, complex)
    c, p = _g_parts(ps, M)
    pt = np.swapaxes(p, 1, 2)
    with np.errstate(all="ignore"):
        a = np.linalg.solve(pt @ p + 1e-300 * np.eye(2), (pt @ -c[:, :, None]))[:, :, 0]
    return ps.p[0] + a[:, 0] + 1j * a[:, 1]


def burmester_points(ps: Poses, rays: int = 2 * RAYS) -> list[tuple[complex, complex]]:
    """Five poses: every real Burmester pair (centre point M, circle point A at pose 1)."""
    first4 = Poses(ps.p[:4], ps.theta[:4], ps.centre, ps.size)
    found: list[tuple[complex, complex]] = []
    for origin in (0j, 0.37 + 0.21j):  # two ray centres: a sign change one misses at a branch swap, the other sees
        shifted = Poses(first4.p - origin, first4.theta, 0j, 1.0)
        M, A, ray = centre_curve(shifted, rays, reach=1e3)
        M, A = M + origin, A + origin
        g5 = _g5(ps, M, A)
        for i in range(len(M)):
            for j in _neighbours(ray, M, i):
                if g5[i] == 0 or np.sign(g5[i]) != np.sign(g5[j]):
                    sol = _newton(ps, 0.5 * (M[i] + M[j]), 0.5 * (A[i] + A[j]))
                    if sol is not None and not any(abs(sol[0] - f[0]) < 1e-7 for f in found):
                        found.append(sol)
    return [(o, a) for o, a in found if not _trivial(ps, o, a)]


def _g5(ps: Poses, M: np.ndarray, A: np.ndarray) -> np.ndarray:
    a = A - ps.p[0]
    return np.abs(ps.p[4] - M + np.exp(1j * ps.alpha[4]) * a) ** 2 - np.abs(ps.p[0] - M + a) ** 2


def _neighbours(ray: np.ndarray, M: np.ndarray, i: int) -> list[int]:
    """Points on the next ray near point i (the same branch of the curve, across one ray step)."""
    nxt = np.nonzero(ray == ray[i] + 1)[0]
    if not len(nxt):
        return []
    j = nxt[np.argmin(np.abs(M[nxt] - M[i]))]
    return [int(j)] if abs(M[j] - M[i]) < 0.5 * max(abs(M[i]), 1.0) else []


def _newton(ps: Poses, M: complex, A: complex, iters: int = 50) -> tuple[complex, complex] | None:
    """Newton on g_2..g_5 in (O_x, O_y, a_x, a_y) from a guess; the pair if it converges to round-off."""
    x = np.array([M.real, M.imag, (A - ps.p[0]).real, (A - ps.p[0]).imag])
    for _ in range(iters):
        F, J = _g_jacobian(ps, x)
        try:
            step = np.linalg.solve(J, -F)
        except np.linalg.LinAlgError:
            return None
        x = x + step
        if np.max(np.abs(step)) <= 1e-14 * (1 + np.max(np.abs(x))):
            break
    F, _ = _g_jacobian(ps, x)
    if not np.all(np.isfinite(x)) or np.max(np.abs(F)) > 1e-10 * (1 + np.max(np.abs(x))) ** 2:
        return None
    return complex(x[0], x[1]), ps.p[0] + complex(x[2], x[3])


def _g_jacobian(ps: Poses, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """g_k (k = 2..5) and its Jacobian in (O_x, O_y, a_x, a_y): dg = 2Re(w̄_k(−dO + e^{jα_k}da)) −
    2Re(w̄_1(−dO + da)), w_k = P_k − M + e^{jα_k}·a."""
    M, a = complex(x[0], x[1]), complex(x[2], x[3])
    w1 = ps.p[0] - M + a
    F, J = [], []
    for k in range(1, 5):
        rot = np.exp(1j * ps.alpha[k])
        wk = ps.p[k] - M + rot * a
        F.append(abs(wk) ** 2 - abs(w1) ** 2)
        wa = wk * np.conj(rot)
        J.append([2 * (w1.real - wk.real), 2 * (w1.imag - wk.imag), 2 * (wa.real - w1.real), 2 * (wa.imag - w1.imag)])
    return np.array(F), np.array(J)


def _trivial(ps: Poses, M: complex, A: complex) -> bool:
    """A dyad of no use: a crank of zero length, or a pivot so far off that the link is a slider."""
    return abs(A - M) < 1e-9 or abs(M) > 1e6


# ---------------------------------------------------------------- four-bars from dyads


def motion(
    poses: object,
    *,
    dyads: Sequence[dict] | None = None,
    region: Sequence[float] | None = None,
    grid: int = 10,
    count: int = 5,
    requirements: Requirements | None = None,
    name: str = "motion",
    units: str = "m",
) -> Candidates:
    """Four-bars that carry a body through ``poses`` [[x, y, θ], ...] (2 to 5; x, y of the guided point P on the
    coupler [length], θ the coupler's angle [rad]). ``dyads``: the free choices of both dyads, each a dict with
    ``fixed`` (ground pivot [x, y]), ``moving`` (moving pivot at pose 1 [x, y]) or ``rotations`` (the link's
    turn to poses 2..N [rad]) — two poses take a pivot and a rotation, three one of them, four and five none.
    Without them the dyads are searched over ``region`` [xmin, ymin, xmax, ymax] (default: the poses' box grown
    by their size) on a ``grid`` × ``grid`` lattice (four poses: along the centre-point curve; five: the
    Burmester points). Returns up to ``count`` candidates, re-solved and checked."""
    started = time.perf_counter()
    _arguments(poses, dyads, region, grid, count, requirements, name, units)
    ps = poses_of(poses)
    req = requirements or Requirements()
    task = Task("motion", ps.size, True, points=ps.centre + ps.size * ps.p, angles=ps.theta, units=units,
                scale="the poses' size (an angle error in rad)")  # fmt: skip
    if dyads:
        pairs = [tuple(_given(ps, d, i) for i, d in enumerate(_two(dyads)))]
    elif len(ps.p) == 5:
        found = burmester_points(ps)
        if len(found) < 2:
            raise SynthesisError(f"[motion] the five poses have {len(found)} real Burmester point(s): no four-bar")
        pairs = [(found[i], found[j]) for i in range(len(found)) for j in range(i + 1, len(found))]
    else:
        box = region if region is not None or req.pivots is None else req.pivots  # pivots asked: search there
        pairs = _search(ps, _region(ps, box), grid, count, req)
    drafts = [d for p in pairs for d in _drafts(ps, p, name, units)]
    if not drafts:
        raise SynthesisError("[motion] no four-bar: every pair of dyads found is degenerate")
    cands = [assess(d, task, req) for d in drafts]
    out = Candidates(task, cands).keep(name, count if not dyads and len(ps.p) < 5 else None)
    if len(ps.p) >= 4:  # the curves of the first four poses, for the picture
        first4 = Poses(ps.p[:4], ps.theta[:4], ps.centre, ps.size)
        M, A, _ = centre_curve(first4, reach=3 * max(np.max(np.abs(ps.p)), 1.0))
        out.curves = {"centre": ps.centre + ps.size * M, "circle": ps.centre + ps.size * A}
    out.seconds = time.perf_counter() - started
    if len(out) < count:
        out.note = shortfall("motion", count, len(out), dyads=bool(dyads), poses=len(ps.p))
    return out


def _arguments(poses, dyads, region, grid, count, requirements, name, units) -> None:
    """Each argument's type and range (vloop.synthesis.arguments), before any work."""
    args.common(name, units, requirements)
    args.rows(poses, "poses", 1, 10_000, (("x", args.MAX_LENGTH), ("y", args.MAX_LENGTH), ("θ", args.MAX_ANGLE)))
    args.count(grid, "grid", "motion.grid")
    args.count(count, "count")
    if region is not None:
        box = args.table(region, "region", "[xmin, ymin, xmax, ymax]")
        if box.shape != (4,) or not np.all(np.abs(box) <= args.MAX_LENGTH):
            raise SynthesisError(
                f"region: must be [xmin, ymin, xmax, ymax] within ±{args.MAX_LENGTH:g}", entry="region"
            )
    if dyads is not None and (not isinstance(dyads, (list, tuple)) or len(dyads) not in (0, 2)):
        raise SynthesisError(f"dyads: must be two dicts of free choices (or none), got {dyads!r:.40}", entry="dyads")
    for i, d in enumerate(dyads or ()):
        if not isinstance(d, dict) or not set(d) <= {"fixed", "moving", "rotations"}:
            raise SynthesisError(f"dyads[{i}]: must be a dict of fixed, moving or rotations", entry="dyads")
        for k in ("fixed", "moving"):
            if k in d:
                args.point(d[k], f"dyads[{i}].{k}")
        if "rotations" in d:
            args.angles(d["rotations"], f"dyads[{i}].rotations", 1, 4)


def _two(dyads: Sequence[dict]) -> Sequence[dict]:
    if len(dyads) != 2 or not all(isinstance(d, dict) for d in dyads):
        raise SynthesisError("[motion] dyads: give the free choices of both dyads (two tables)", entry="motion.dyads")
    return dyads


def _given(ps: Poses, choice: dict, i: int) -> tuple[complex, complex]:
    """One dyad (M, A) (normalised) from its free choices."""
    entry = f"motion.dyads[{i}]"
    norm = {k: (complex(*choice[k]) - ps.centre) / ps.size for k in ("fixed", "moving") if k in choice}
    rot = choice.get("rotations")
    n = len(ps.p)
    if rot is not None and len(rot) != n - 1:
        raise SynthesisError(
            f"[{entry}] rotations: give the link's turn to each of poses 2..{n} ({n - 1})", entry=entry
        )
    sol = None
    if n == 2:
        if rot is None or len(norm) != 1:
            raise SynthesisError(f"[{entry}] two poses: give rotations and one pivot (fixed or moving)", entry=entry)
        sol = dyad_from_rotations(ps, rot, moving=norm.get("moving"), fixed=norm.get("fixed"))
    elif n == 3 and len(norm) + (rot is not None) == 1:
        if rot is not None:
            sol = dyad_from_rotations(ps, rot)
        elif "fixed" in norm:
            A = circle_point(ps, norm["fixed"])
            sol = None if A is None else (norm["fixed"], A)
        else:
            M = centre_point(ps, norm["moving"])
            sol = None if M is None else (M, norm["moving"])
    else:
        raise SynthesisError(f"[{entry}] {n} poses: give exactly one of fixed, moving, rotations", entry=entry)
    if sol is None or _trivial(ps, *sol):
        raise SynthesisError(f"[{entry}] these free choices admit no dyad (a pivot at infinity: a slider)", entry=entry)
    return sol


def _drafts(ps: Poses, pair: tuple, name: str, units: str) -> list[Draft]:
    """The four-bar of two dyads, each dyad driving in turn, its input turning the way that meets the poses in
    order on one branch (its defect named from its configuration at each pose: :mod:`.circuits`)."""
    (O1, A1), (O2, A2) = pair
    if abs(A1 - A2) < 1e-9 or abs(O1 - O2) < 1e-9:
        return []
    out = []
    for (Oi, Ai), (Oj, Aj) in (((O1, A1), (O2, A2)), ((O2, A2), (O1, A1))):
        configs = [{"O2": Oi, "A": ps.move(k, Ai), "B": ps.move(k, Aj), "O4": Oj} for k in range(len(ps.p))]
        verdict = classify(FOURBAR, configs)
        world = {k: ps.centre + ps.size * v for k, v in {"O2": Oi, "A": Ai, "B": Aj, "O4": Oj, "P": ps.p[0]}.items()}
        mech = FOURBAR.mechanism(world, name=name, omega=verdict.omega, times=np.array([0.0]), units=units)
        t = verdict.times
        out.append(Draft(name, "motion", FOURBAR, mech, t, float(np.max(t)), verdict=verdict))
    return out


# ---------------------------------------------------------------- the search


def _region(ps: Poses, region: Sequence[float] | None) -> tuple[float, float, float, float]:
    """The search region in normalised units (default: the poses' box grown by one size each way)."""
    if region is None:
        x, y = ps.p.real, ps.p.imag
        return x.min() - 1, y.min() - 1, x.max() + 1, y.max() + 1
    r = [float(v) for v in region]
    if len(r) != 4 or not all(math.isfinite(v) for v in r) or r[0] >= r[2] or r[1] >= r[3]:
        raise SynthesisError(f"[motion] region must be [xmin, ymin, xmax, ymax] with min < max, got {region}")
    lo = (complex(r[0], r[1]) - ps.centre) / ps.size
    hi = (complex(r[2], r[3]) - ps.centre) / ps.size
    return lo.real, lo.imag, hi.real, hi.imag


def _candidate_dyads(ps: Poses, box: tuple[float, float, float, float], grid: int) -> list[tuple[complex, complex]]:
    """Dyads to pair up: on a grid of centre points (two poses: with rotations ±45°, ±90°; three: their circle
    points), or along the centre-point curve inside the region (four poses)."""
    n = len(ps.p)
    if n == 4:
        M, A, _ = centre_curve(ps, reach=3 * max(abs(v) for v in box))
        inside = (M.real >= box[0]) & (M.real <= box[2]) & (M.imag >= box[1]) & (M.imag <= box[3])
        M, A = M[inside], A[inside]
        keep = np.linspace(0, len(M) - 1, min(len(M), grid * grid)).astype(int) if len(M) else []
        return [(M[k], A[k]) for k in keep]
    xs, ys = np.linspace(box[0], box[2], grid), np.linspace(box[1], box[3], grid)
    centres = [complex(x, y) for x in xs for y in ys]
    out = []
    for M in centres:
        if n == 3:
            A = circle_point(ps, M)
            out += [] if A is None else [(M, A)]
        else:
            for b in (-math.pi / 2, -math.pi / 4, math.pi / 4, math.pi / 2):
                sol = dyad_from_rotations(ps, [b], fixed=M)
                out += [] if sol is None else [sol]
    return [d for d in out if not _trivial(ps, *d)]


def _search(ps: Poses, box: tuple, grid: int, count: int, req: Requirements) -> list[tuple]:
    """Every pair of candidate dyads as a four-bar (either dyad driving), screened together by the batched
    solver: those that reach every pose in order on one branch, best transmission angle first."""
    if isinstance(grid, bool) or not isinstance(grid, int) or not 2 <= grid <= 40:
        raise SynthesisError(f"[motion] grid must be an integer from 2 to 40, got {grid!r:.40}")
    dy = _candidate_dyads(ps, box, grid)
    if len(dy) < 2:
        raise SynthesisError("[motion] no dyad in the search region: widen it")
    M = np.array([d[0] for d in dy])
    A = np.array([d[1] for d in dy])
    i, j = np.nonzero(~np.eye(len(dy), dtype=bool))
    ok = (np.abs(A[i] - A[j]) > 1e-6) & (np.abs(M[i] - M[j]) > 1e-6)
    i, j = i[ok], j[ok]
    rows = {"O2": M[i, None], "O4": M[j, None], "A": np.stack([ps.move(k, A[i]) for k in range(len(ps.p))], 1),
            "B": np.stack([ps.move(k, A[j]) for k in range(len(ps.p))], 1)}  # fmt: skip
    omega, turns, good = screen(FOURBAR, {k: np.broadcast_to(v, rows["A"].shape) for k, v in rows.items()})
    i, j, omega, tN = i[good], j[good], omega[good], turns[good, -1]
    if not len(i):
        raise SynthesisError("[motion] no pair of dyads in the search region meets the poses in order: widen region")
    coords = np.stack([M[i], A[i], A[j], M[j], np.full(len(i), ps.p[0])], 1)
    inside = _in_bounds(ps, req, coords)
    if not inside.any():
        raise SynthesisError("[motion] no pair of dyads in the search region keeps within pivots and links: widen them")
    i, j, omega, tN, coords = i[inside], j[inside], omega[inside], tN[inside], coords[inside]
    values = np.stack([coords.real, coords.imag], 2).reshape(len(i), -1)
    times = np.linspace(0.0, 1.0, SCREEN_SAMPLES)
    ev = evaluate(FOURBAR, values, omega * tN, times, points=FOURBAR.coordinates, links=("coupler",))
    path, th = ev.points["P"], ev.angles["coupler"]
    th = th - th[:, :1] + ps.theta[0]
    dist, _, in_order = match(path, ps.p, th, ps.theta)
    step = np.max(np.nan_to_num(np.abs(np.diff(path, axis=1)) + np.abs(np.diff(th, axis=1)), nan=np.inf), axis=1)
    mu = population_transmission(FOURBAR, ev.points, times)
    feasible = ev.completed & in_order & np.all(dist <= step[:, None] + 1e-9, axis=1) & (mu >= req.min_transmission)
    order = np.argsort(np.where(feasible, -np.nan_to_num(mu), np.inf))
    picked: list[int] = []
    for k in order[feasible[order]]:  # distinct pivots: a quarter of the size apart from every pick
        if all(abs(M[i[k]] - M[i[q]]) + abs(M[j[k]] - M[j[q]]) > 0.25 for q in picked):
            picked.append(int(k))
        if len(picked) == 2 * max(count, 1):
            break
    return [((M[i[k]], A[i[k]]), (M[j[k]], A[j[k]])) for k in picked]


def _in_bounds(ps: Poses, req: Requirements, coords: np.ndarray) -> np.ndarray:
    """Which four-bars (rows of normalised O2, A, B, O4, P) keep their ground pivots in ``pivots`` and their moving
    links (crank, coupler's sides, rocker) within ``links`` [length]."""
    world = ps.centre + ps.size * coords
    ok = np.ones(len(coords), bool)
    if req.pivots is not None:
        x0, y0, x1, y1 = req.pivots
        for k in (0, 3):
            z = world[:, k]
            ok &= (z.real >= x0) & (z.real <= x1) & (z.imag >= y0) & (z.imag <= y1)
    if req.links is not None:
        lo, hi = req.links
        for a, b in ((0, 1), (1, 2), (2, 3), (1, 4), (2, 4)):
            d = np.abs(world[:, a] - world[:, b])
            ok &= (d >= lo) & (d <= hi)
    return ok
