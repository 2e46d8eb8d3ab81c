"""Path generation: a linkage whose tracer point passes through N target points, with or without prescribed
timing, as its input turns once.

No closed form past a few points: a global search over the linkage's t = 0 coordinates (scipy's differential
evolution; every generation's whole population solved by vloop's batched solver in one evaluation over
``samples`` input angles of a full turn), then a local least-squares polish of the best distinct members on
the exact instants. The score of a member is the rms distance [fraction of the targets' size] from each target
to its nearest sample of the path (without timing: those samples must come in the targets' order within one
turn; with timing: the path at the prescribed input angles), plus a penalty when the order is wrong or the
transmission angle falls below the limit asked; a member whose input cannot turn fully, or that the batch is not
sure of (a toggle, a change point), is infeasible.

The polish works on the coordinates and (without timing) the instants t_2..t_N of targets 2..N, with t_1 = 0:
the mechanism's t = 0 is target 1. Its Jacobian is one batched solve of the member and its forward-difference
neighbours, with ∂P(t_k)/∂t_k the tracer's velocity. Four-bars first; with ``linkage = "auto"`` a Stephenson III
six-bar where no four-bar reaches every target within ``tolerance``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
from scipy.optimize import differential_evolution, least_squares

from ..errors import SynthesisError
from . import arguments as args
from ._evaluate import evaluate
from .candidates import Candidates, Task, shortfall
from .defects import Draft, Requirements, assess, population_transmission
from .fit import match
from .linkages import FOURBAR, STEPHENSON3, Topology

TWO_PI = 2.0 * math.pi
LINKAGES = {"fourbar": (FOURBAR,), "sixbar": (STEPHENSON3,), "auto": (FOURBAR, STEPHENSON3)}
INFEASIBLE = 10.0  # the score of a member that cannot turn fully (the targets' size is 1)
ORDER_PENALTY = 1.0
FD_STEP = 1e-7  # forward-difference step of the polish's Jacobian (the targets' size is 1)
COINCIDENT = 1e-9
# the polish keeps every joint within this many times the search region: a four-bar's within the region (room
# beyond it mostly lets the polish wander off to large linkages), a six-bar's within three (moving off the four-bar
# it was seeded with takes its extra dyad well outside the four-bar's span)
POLISH_REACH = {"fourbar": 1.0, "stephenson3": 3.0}
# the polish's methods, the next from the best point of the last while it misses the tolerance: the dogleg (a few
# Gauss-Newton steps to the manifold of exact linkages), and with prescribed timing (as many residuals as unknowns:
# isolated solutions, where the dogleg stalls more often) then the reflective trust region
POLISH_METHODS = ("dogbox", "trf")
MAX_NFEV = 60  # least-squares evaluations of one polish (each a batched solve of the member and its neighbours)
WALL = 8  # evaluations on members that will not solve after which a polish stops (see _Wall)
SCREEN = 4  # members drawn per member kept in DE's first population (see _initial)
RETRY = 5  # generations after a failed polish before the next best member is polished (unless the score drops)
STAGNANT = 30  # generations without a 5 % gain (and failed polishes) after which an evolution stops for a new one
POLISH_AT = 0.2  # a member whose sampled score is within this (of the size) is worth polishing


@dataclass(frozen=True)
class Targets:
    """Target points normalised (centre 0, size 1) and the map back; ``timing`` the instants [s] of each (input
    at 1 rad/s) when prescribed, with the input's direction ``omega``."""

    z: np.ndarray
    centre: complex
    size: float
    timing: np.ndarray | None
    omega: float


def targets_of(points: object, timing: object = None) -> Targets:
    """The targets [[x, y], ...] (at least three, finite, distinct) and the timing [rad] (input angles at which
    each is reached: strictly monotonic, less than a turn from first to last)."""
    try:
        arr = np.asarray(points, float)
    except (TypeError, ValueError, OverflowError):
        arr = None
    if arr is None or arr.ndim != 2 or arr.shape[1] != 2:
        raise SynthesisError("[path] points must be a list of [x, y] pairs", entry="path.points")
    if not np.all(np.isfinite(arr)):
        raise SynthesisError("[path] points must be finite numbers", entry="path.points")
    if not 3 <= len(arr) <= 100:
        raise SynthesisError(f"[path] path generation takes 3 to 100 points, got {len(arr)}", entry="path.points")
    z = arr[:, 0] + 1j * arr[:, 1]
    centre = complex(np.mean(z))
    size = float(np.hypot(np.ptp(arr[:, 0]), np.ptp(arr[:, 1])))
    for i in range(len(z)):
        for j in range(i):
            if not abs(z[i] - z[j]) > COINCIDENT * size:
                raise SynthesisError(f"[path] points {j + 1} and {i + 1} coincide", entry="path.points")
    t, omega = None, 1.0
    if timing is not None:
        t, omega = _timing(timing, len(z))
    return Targets((z - centre) / size, centre, size, t, omega)


def _timing(timing: object, n: int) -> tuple[np.ndarray, float]:
    try:
        phi = np.asarray(timing, float)
    except (TypeError, ValueError, OverflowError):
        phi = None
    if phi is None or phi.shape != (n,) or not np.all(np.isfinite(phi)):
        raise SynthesisError(f"[path] timing must be {n} finite input angles [rad], one per point", entry="path.timing")
    step = np.diff(phi)
    if not (np.all(step > 0) or np.all(step < 0)):
        raise SynthesisError("[path] timing must be strictly increasing or decreasing", entry="path.timing")
    span = abs(phi[-1] - phi[0])
    if not span < TWO_PI:
        raise SynthesisError("[path] timing must span less than one turn (2π rad)", entry="path.timing")
    omega = 1.0 if step[0] > 0 else -1.0
    return np.abs(phi - phi[0]), omega


@dataclass
class _Problem:
    """One search: the topology, the targets, the samples, the requirements."""

    top: Topology
    tg: Targets
    times: np.ndarray
    at: np.ndarray | None  # with timing: the sample of each target
    req: Requirements
    box: float
    seeds: list = dataclasses.field(default_factory=list)  # (coordinates, ω, instants) to polish and breed from

    @property
    def n_coords(self) -> int:
        return 2 * len(self.top.coordinates)

    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """Each coordinate's search bounds (normalised): within ``box`` sizes of the points, a ground pivot's
        within the ``pivots`` region asked."""
        lo, hi = np.full(self.n_coords, -self.box), np.full(self.n_coords, self.box)
        if self.req.pivots is not None:
            x0, y0, x1, y1 = self.req.pivots
            a = (complex(x0, y0) - self.tg.centre) / self.tg.size
            b = (complex(x1, y1) - self.tg.centre) / self.tg.size
            for i, name in enumerate(self.top.coordinates):
                if name in self.top.links[self.top.ground]:
                    lo[2 * i : 2 * i + 2], hi[2 * i : 2 * i + 2] = (a.real, a.imag), (b.real, b.imag)
        return lo, hi

    def in_bounds(self, coords: np.ndarray) -> np.ndarray:
        """Which rows of coordinates (V, 2·n) keep their ground pivots in the region and every moving link's
        length (a plate's sides, the tracer's distances) within the range asked."""
        lo, hi = self.limits()
        inside = np.all((coords >= lo - 1e-12) & (coords <= hi + 1e-12), axis=1)
        return inside & (self.link_excess(coords) <= 1e-12)

    def link_excess(self, coords: np.ndarray) -> np.ndarray:
        """How far (V,) the rows' moving links fall outside the ``links`` range: the sum of each length's relative
        shortfall below its minimum and excess over its maximum (0 inside, or without a range)."""
        out = np.zeros(len(coords))
        if self.req.links is None:
            return out
        z = coords[:, 0::2] + 1j * coords[:, 1::2]
        short, long_ = (v / self.tg.size for v in self.req.links)
        for i, j in _link_pairs(self.top):
            d = np.abs(z[:, i] - z[:, j])
            out += np.maximum(0.0, short - d) / short + np.maximum(0.0, d - long_) / long_
        return out

    def split(self, X: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Coordinates (S, 2·n) and input speeds (S,) of members X (S, genes)."""
        if self.tg.timing is not None:
            return X, np.full(len(X), self.tg.omega)
        return X[:, :-1], np.where(X[:, -1] >= 0, 1.0, -1.0)

    def score(self, x: np.ndarray) -> np.ndarray:
        """DE's vectorized objective: x (genes, S) → (S,)."""
        coords, omega = self.split(np.asarray(x, float).T)
        need = self.top.coordinates if self.req.min_transmission > 0 else (self.top.tracer,)
        ev = evaluate(self.top, coords, omega, self.times, points=need)
        P = ev.points[self.top.tracer]
        if self.at is not None:
            d, ok = np.abs(P[:, self.at] - self.tg.z), np.ones(len(P), bool)
        else:
            d, _, ok = match(P, self.tg.z)
        cost = np.sqrt(np.mean(d * d, axis=1)) + ORDER_PENALTY * ~ok
        if self.req.min_transmission > 0:
            mu = population_transmission(self.top, ev.points, self.times)
            cost = cost + np.maximum(0.0, self.req.min_transmission - np.nan_to_num(mu))
        cost = cost + ORDER_PENALTY * self.link_excess(coords)  # graded: the evolution moves into the range
        return np.where(ev.completed & np.isfinite(cost), cost, INFEASIBLE)


def path(
    points: object,
    *,
    timing: Sequence[float] | None = None,
    linkage: str = "auto",
    tolerance: float = 0.01,
    count: int = 5,
    seed: int = 0,
    population: int = 10,
    generations: int = 400,
    samples: int = 120,
    restarts: int = 1,
    region: float = 1.5,
    requirements: Requirements | None = None,
    name: str = "path",
    units: str = "m",
    progress: Callable[[str], None] | None = None,
) -> Candidates:
    """Linkages whose tracer passes through ``points`` [[x, y], ...] (with ``timing``: at those input angles
    [rad]). ``linkage``: "fourbar", "sixbar" or "auto" (a six-bar only where no four-bar comes within
    ``tolerance`` [fraction of the points' size]). The search: ``restarts`` differential evolutions of
    ``population`` × genes members for up to ``generations`` (stopping early once a member is within
    ``tolerance``), joints within ``region`` sizes of the points' centre, ``samples`` input angles per turn;
    ``seed`` makes it repeatable. Returns up to ``count`` distinct candidates, polished, re-solved and checked
    (the input must turn fully)."""
    started = time.perf_counter()
    args.common(name, units, requirements)
    args.count(seed, "seed")
    if progress is not None and not callable(progress):
        raise SynthesisError(f"progress: must be a function of one message, got {progress!r:.40}", entry="progress")
    args.rows(points, "points", 1, 10_000, (("x", args.MAX_LENGTH), ("y", args.MAX_LENGTH)))
    if timing is not None:
        args.angles(timing, "timing")
    tg = targets_of(points, timing)
    _check_options(linkage, tolerance, count, population, generations, samples, restarts, region)
    req = dataclasses.replace(requirements or Requirements(full_rotation=True), tolerance=tolerance)
    task = Task("path", tg.size, False, points=tg.centre + tg.size * tg.z, units=units, timing=tg.timing,
                scale="the points' size")  # fmt: skip
    cands, log, drafts = [], [], []
    for top in LINKAGES[linkage]:
        problem = _problem(top, tg, samples, req, region)
        if top is STEPHENSON3 and drafts:  # the four-bars found, each as a six-bar tracing its coupler point
            problem.seeds = _embedded(problem, drafts)
        drafts = _search(problem, tolerance, count, seed, population, generations, restarts, name, units, log)
        found = [assess(d, task, req) for d in drafts]
        cands += found
        if any(c.solution and c.error <= tolerance for c in found):
            break
        if progress is not None and top is not LINKAGES[linkage][-1]:
            progress(f"no {top.name} within {tolerance:g} of the size: trying a {LINKAGES[linkage][-1].name}")
    out = Candidates(task, cands, log=log).keep(name, count)
    out.seconds = time.perf_counter() - started
    if len(out) < count:
        out.note = shortfall("path", count, len(out))
    return out


def _check_options(linkage, tolerance, count, population, generations, samples, restarts, region) -> None:
    """Each search option's type and range (vloop.synthesis.arguments), before any work."""
    args.choice(linkage, "linkage", tuple(LINKAGES))
    args.limited(tolerance, "tolerance", "path.tolerance", open_low=True)
    args.limited(region, "region", "path.region")
    args.count(count, "count")
    for key, v in (("population", population), ("generations", generations), ("samples", samples),
                   ("restarts", restarts)):  # fmt: skip
        args.count(v, key, f"path.{key}")


def _problem(top: Topology, tg: Targets, samples: int, req: Requirements, region: float) -> _Problem:
    grid = np.arange(samples) * (TWO_PI / samples)
    if tg.timing is None:
        return _Problem(top, tg, grid, None, req, region)
    times = np.union1d(grid, tg.timing)
    return _Problem(top, tg, times, np.searchsorted(times, tg.timing), req, region)


def _search(p: _Problem, tolerance, count, seed, population, generations, restarts, name, units, log) -> list[Draft]:
    """Differential evolutions, each stopping once a polished member is within the tolerance, one after another
    (new seeds) until ``count`` distinct candidates are found — at least ``restarts`` of them, and no more once
    one finds nothing; one that stagnates (its population gathered in a basin whose polish fails) hands its
    remaining generations to a new one; then, if still short, the polish of the best members of the last
    populations."""
    lo, hi = p.limits()
    bounds = list(zip(lo, hi, strict=True)) + ([] if p.tg.timing is not None else [(-1.0, 1.0)])
    members, energies, polished = [], [], []
    for start in p.seeds:
        out = _polish(p, *start)
        if out is not None and out[3] <= tolerance and _acceptable(p, out[0], out[1]):
            polished += [] if any(_same(out[0], q[0]) for q in polished) else [out]
    budget, r = generations * max(restarts, count), 0
    while len(polished) < count and budget > 0:
        t0 = time.perf_counter()
        early = _Early(p, tolerance)
        rng = np.random.default_rng(seed + r)
        res = differential_evolution(
            p.score, bounds, popsize=population, maxiter=min(generations, budget), tol=0.0, mutation=(0.5, 1.0),
            recombination=0.9, rng=rng, vectorized=True, updating="deferred", polish=False,
            init=_initial(p, bounds, population, rng), callback=early,
        )  # fmt: skip
        budget -= max(res.nit, 1)
        members.append(res.population)
        energies.append(res.population_energies)
        polished += [f for f in early.found if not any(_same(f[0], q[0]) for q in polished)]
        log.append(f"{p.top.name} search {r + 1}: {res.nit} generations of {len(res.population)} in "
                   f"{time.perf_counter() - t0:.2f} s, best sampled {res.fun:.3g} of the size"
                   + (" (stagnant: a new search)" if early.stagnant else ""))  # fmt: skip
        r += 1
        if not early.stagnant and (r >= max(restarts, count) or (r >= restarts and not early.found)):
            break
    X = np.concatenate(members) if members else np.zeros((0, len(bounds)))
    E = np.concatenate(energies) if energies else np.zeros(0)
    best = [k for k in np.argsort(E) if E[k] < INFEASIBLE][: 2 * count] if len(polished) < count else []
    drafts: list[Draft] = []
    for out in polished + [_polish(p, *s) for s in (_anchored(p, X[best]) if best else [])]:
        if out is None or any(_same(out[0], d.extra["coords"]) for d in drafts):
            continue
        coords, omega, t, err = out
        world = {
            k: p.tg.centre + p.tg.size * complex(coords[2 * i], coords[2 * i + 1])
            for i, k in enumerate(p.top.coordinates)
        }
        mech = p.top.mechanism(world, name=name, omega=omega, times=np.array([0.0]), units=units)
        drafts.append(Draft(name, "path", p.top, mech, t, TWO_PI, float(err), extra={"coords": coords}))
        if len(drafts) == 2 * count:
            break
    return drafts


def _initial(p: _Problem, bounds: list, population: int, rng: np.random.Generator) -> np.ndarray:
    """DE's first population: the best-scoring of SCREEN × as many members drawn by Latin hypercube over the bounds
    (scored in one batched evaluation: most random linkages cannot turn fully, and a population of those learns
    nothing), with the seeds (clipped to the bounds) first."""
    n, S = len(bounds), population * len(bounds)
    lo, hi = np.array(bounds).T
    M = SCREEN * S
    cut = (np.arange(M)[:, None] + rng.uniform(size=(M, n))) / M
    X = lo + (hi - lo) * np.take_along_axis(cut, np.argsort(rng.uniform(size=(M, n)), axis=0), axis=0)
    X = X[np.argsort(p.score(X.T), kind="stable")[:S]]
    for i, (coords, omega, _) in enumerate(p.seeds[: S // 2]):
        gene = coords if p.tg.timing is not None else np.append(coords, 0.5 * omega)
        X[i] = np.clip(gene, lo, hi)
    return X


def _embedded(p: _Problem, drafts: list[Draft]) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """Each four-bar draft as a Stephenson III tracing the same path: its coupler point becomes the coupler's
    pin C, a dyad C–D–O6 is hung there (O6 at the centre of C's path, both links √2/2 of C's mean distance from
    it, so the dyad closes over the turn where it can) and the tracer sits on link CD a thousandth of the size
    from C — the same path to that much, and room for the polish to move off it."""
    out = []
    for d in drafts:
        c4, omega, t = d.extra["coords"], float(d.mechanism.drivers[0].v0), np.asarray(d.times, float)
        ev = evaluate(FOURBAR, c4[None, :], np.array([omega]), p.times, points=("P",))
        if not ev.completed[0]:
            continue
        path = ev.points["P"][0]
        O6 = complex(np.mean(path))
        dist = np.abs(path - O6)
        L = max(np.mean(dist) / math.sqrt(2.0), 0.51 * np.max(dist))
        z = dict(zip(FOURBAR.coordinates, c4[0::2] + 1j * c4[1::2], strict=True))
        C = z["P"]
        f = abs(O6 - C)
        if not (0 < f < 2 * L):
            continue
        u = (O6 - C) / f
        D = C + u * complex(f / 2, math.sqrt(max(L * L - f * f / 4, 0.0)))
        z6 = {"O2": z["O2"], "A": z["A"], "B": z["B"], "O4": z["O4"], "C": C, "D": D, "O6": O6}
        z6["P"] = C + 1e-3 * (D - C) / abs(D - C)
        coords = np.array([[z6[k].real, z6[k].imag] for k in STEPHENSON3.coordinates]).ravel()
        out.append((coords, omega, t))
    return out


class _Early:
    """DE's callback: once the best sampled score is within POLISH_AT, polish the best member not polished yet —
    again whenever the score has dropped by a fifth since the last try, or RETRY generations after it (a failed
    polish is a basin whose exact linkages cannot move through the targets: another member may sit in another);
    stop the evolution when a polished member is within the tolerance, or when it stagnates: no gain of 5 % in
    STAGNANT generations, with polishes failing since the last gain (not a search seeded with linkages found
    before: its best members are those seeds until it moves off them, and a new search would start there again)."""

    def __init__(self, p: _Problem, tolerance: float) -> None:
        self.p, self.tolerance = p, tolerance
        self.tried = math.inf
        self.generation = self.last = 0
        self.polished: list[np.ndarray] = []  # the genes of the members polished so far
        self.found: list[tuple] = []
        self.record, self.improved = math.inf, 0  # the best score so far and the generation it was reached
        self.stagnant = False

    def __call__(self, intermediate_result) -> bool:  # scipy passes the state by this name
        self.generation += 1
        best = float(intermediate_result.fun)
        if best < 0.95 * self.record:
            self.record, self.improved = best, self.generation
        if not self.p.seeds and self.generation - self.improved >= STAGNANT and self.last > self.improved:
            self.stagnant = True
            return True
        if best > POLISH_AT or (best > 0.8 * self.tried and self.generation - self.last < RETRY):
            return False
        pop, energies = intermediate_result.population, intermediate_result.population_energies
        fresh = [k for k in np.argsort(energies) if not any(_same(pop[k], g) for g in self.polished)]
        if not fresh or energies[fresh[0]] > POLISH_AT:
            return False
        k = fresh[0]
        self.tried, self.last = best, self.generation
        self.polished.append(pop[k].copy())
        starts = _anchored(self.p, pop[k : k + 1])
        out = _polish(self.p, *starts[0]) if starts else None
        if out is not None and out[3] <= self.tolerance and _acceptable(self.p, out[0], out[1]):
            self.found.append(out)
            return True
        return False


def _acceptable(p: _Problem, coords: np.ndarray, omega: float) -> bool:
    """Whether a polished member still turns fully (the batch takes its whole turn) with its transmission angle
    at or above the limit asked (the polish minds only the distances)."""
    ev = evaluate(p.top, coords[None, :], np.array([omega]), p.times, points=p.top.coordinates)
    if not ev.completed[0] or not p.in_bounds(coords[None, :])[0]:
        return False
    if p.req.min_transmission <= 0:
        return True
    return bool(population_transmission(p.top, ev.points, p.times)[0] >= p.req.min_transmission)


def _anchored(p: _Problem, X: np.ndarray) -> list[tuple[np.ndarray, float, np.ndarray]]:
    """Each member as (coordinates at target 1, input speed, instants of the targets from t = 0): without
    timing the member's t = 0 is moved to the sample nearest target 1."""
    coords, omega = p.split(X)
    if p.tg.timing is not None:
        return [(coords[i], float(omega[i]), p.tg.timing.copy()) for i in range(len(X))]
    ev = evaluate(p.top, coords, omega, p.times, points=p.top.coordinates)
    _, idx, _ = match(ev.points[p.top.tracer], p.tg.z)
    n, dt = len(p.times), p.times[1] - p.times[0]
    out = []
    for i in range(len(X)):
        if not ev.completed[i]:
            continue
        k1 = idx[i, 0]
        c = np.array([[ev.points[j][i, k1].real, ev.points[j][i, k1].imag] for j in p.top.coordinates]).ravel()
        out.append((c, float(omega[i]), np.mod(idx[i] - k1, n) * dt))
    return out


class _Wall(Exception):
    """The polish kept stepping onto members that will not solve: it is heading for linkages that cannot move
    through the targets (a limit before the last one), and stops there."""


def _polish(p: _Problem, coords: np.ndarray, omega: float, t: np.ndarray):
    """Least squares on the coordinates (and t_2..t_N without timing), by the dogleg method in a box (Gauss-Newton
    steps: a few iterations near the manifold of exact solutions): (coordinates, ω, instants, max error [size]) of
    the best member it met, or None when the member will not solve."""
    nc = len(coords)
    met = {"error": math.inf, "x": None, "walls": 0, "at": None}

    def solved(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The residual and its Jacobian at x, from one batched solve (least squares asks for the Jacobian at the
        point whose residual it has just had)."""
        if met["at"] is None or not np.array_equal(met["at"][0], x):
            met["at"] = (x.copy(), *_residual_jacobian(p, omega, x, nc))
            r = met["at"][1]
            error = float(np.max(np.hypot(*np.split(r, 2))))
            if r[0] == INFEASIBLE:
                met["walls"] += 1
            elif error < met["error"]:
                met["error"], met["x"] = error, x.copy()
        return met["at"][1], met["at"][2]

    def residual(x: np.ndarray) -> np.ndarray:
        if met["walls"] > WALL:
            raise _Wall
        return solved(x)[0]

    x0, lo, hi = _polish_start(p, coords, t)
    solved(x0)
    if met["x"] is None:
        return None
    for method in POLISH_METHODS if p.tg.timing is not None else POLISH_METHODS[:1]:
        if met["error"] <= (p.req.tolerance or 0.0):
            break
        met["walls"] = 0
        try:
            least_squares(
                residual, met["x"], jac=lambda x: solved(x)[1], bounds=(lo, hi), method=method, x_scale="jac",
                xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=MAX_NFEV,
            )  # fmt: skip
        except _Wall:
            pass
    x = met["x"]
    return x[:nc], omega, _instants(p, x, nc), met["error"]


def _polish_start(p: _Problem, coords: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The polish's unknowns at the start and their bounds: joints within POLISH_REACH search regions (or as far
    out as the member's own, re-anchored, already are); instants within a turn."""
    reach = np.maximum(POLISH_REACH[p.top.name] * p.box, 1.05 * np.abs(coords))
    if p.req.pivots is not None:  # a ground pivot stays in the region asked
        lo_c, hi_c = p.limits()
        ground = np.array([c in p.top.links[p.top.ground] for c in p.top.coordinates]).repeat(2)
        low, high = np.where(ground, lo_c, -reach), np.where(ground, hi_c, reach)
        coords = np.clip(coords, low, high)
        if p.tg.timing is not None:
            return coords, low, high
        return (np.concatenate([coords, np.clip(t[1:], 0, TWO_PI)]), np.concatenate([low, np.zeros(len(t) - 1)]),
                np.concatenate([high, np.full(len(t) - 1, TWO_PI)]))  # fmt: skip
    if p.tg.timing is not None:
        return np.clip(coords, -reach, reach), -reach, reach
    lo = np.concatenate([-reach, np.zeros(len(t) - 1)])
    hi = np.concatenate([reach, np.full(len(t) - 1, TWO_PI)])
    return np.clip(np.concatenate([coords, t[1:]]), lo, hi), lo, hi


def _instants(p: _Problem, x: np.ndarray, nc: int) -> np.ndarray:
    """The instants (N,) [s] of the polish's unknowns x: t_1 = 0 and the rest, or the timing given."""
    return p.tg.timing.copy() if p.tg.timing is not None else np.concatenate([[0.0], x[nc:]])


def _residual_jacobian(p: _Problem, omega: float, x: np.ndarray, nc: int) -> tuple[np.ndarray, np.ndarray]:
    """The polish's residual (tracer minus target at the instants, real parts then imaginary; INFEASIBLE where
    the member will not solve) and its Jacobian, from one batched solve of the member and its forward-difference
    neighbours in the coordinates; without timing ∂P(t_k)/∂t_k is the tracer's velocity."""
    c, t = x[:nc], _instants(p, x, nc)
    N = len(t)
    tu, at = np.unique(np.concatenate([[0.0], t]), return_inverse=True)
    rows = np.vstack([c, c + FD_STEP * np.eye(nc)])
    ev = evaluate(p.top, rows, np.full(nc + 1, omega), tu, points=(p.top.tracer,), rates=True)
    if not ev.completed[0]:
        return np.full(2 * N, INFEASIBLE), np.zeros((2 * N, len(x)))
    P = ev.points[p.top.tracer][:, at[1:]]
    r = P[0] - p.tg.z
    cols = (P[1:] - P[0]).T / FD_STEP  # (N, nc)
    if p.tg.timing is None:
        cols = np.concatenate([cols, ev.velocities[p.top.tracer][0, at[1:], None] * np.eye(N)[:, 1:]], 1)
    return np.concatenate([r.real, r.imag]), np.nan_to_num(np.concatenate([cols.real, cols.imag], 0))


def _link_pairs(top: Topology) -> list[tuple[int, int]]:
    """Index pairs (into the coordinates) of every moving link's joints and of the tracer with its link's joints:
    the lengths a ``links`` range bounds (as :func:`~vloop.synthesis.linkages.lengths` lists them)."""
    at = {c: i for i, c in enumerate(top.coordinates)}
    out = []
    for name, joints in top.links.items():
        if name != top.ground:
            out += [(at[a], at[b]) for k, a in enumerate(joints) for b in joints[k + 1 :]]
    for point, body in top.points.items():
        out += [(at[j], at[point]) for j in top.links[body]]
    return out


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Two polished members are one linkage when every coordinate agrees to a thousandth of the size."""
    return bool(np.max(np.abs(a - b)) < 1e-3)
