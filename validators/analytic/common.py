"""Plumbing shared by the hand-derived closed forms (``validators.analytic``).

Nothing here solves a loop equation: this module only reads the mechanism
description (driver input, body frames, who is pinned to whom), anchors the
angles the closed forms produce, carries rigid-body kinematics from a solved
joint to the other points of the same body, and packs a :class:`Result`.

Conventions (as in ``vloop/mechanism.py``): lengths in the file's units,
angles in radians from +x, CCW positive; a point's kinematics is carried as
complex arrays z = x + j·y, ż, z̈ over time. A "vector angle" φ is the
direction of the vector between two members of a body; the body's own θ is
φ − β, with β the direction of that vector in the body frame (``Body.local``),
so every joint order in the file is handled the same way.

Rigid-body transport (K a solved member of the body, ρ local coordinates as
complex numbers): z_P = z_K + e^{jθ}(ρ_P − ρ_K); ż_P = ż_K + jω·e^{jθ}(ρ_P − ρ_K);
z̈_P = z̈_K + (jα − ω²)·e^{jθ}(ρ_P − ρ_K).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from vloop.drivers import evaluate
from vloop.mechanism import Body, Driver, Mechanism, angle_text
from vloop.result import Result

ENGINE = "analytic"
TWO_PI = 2.0 * math.pi
ROUNDOFF = 64 * 2.220446049250313e-16  # a reach computed from lengths of size L is exact to about ROUNDOFF·L
AXIS_TOL = 1e-12  # |component| below which a unit slider axis counts as exactly horizontal/vertical

Kin = tuple[np.ndarray, np.ndarray, np.ndarray]  # z, ż, z̈ (complex) or θ, ω, α (real)


class LimitPositionError(ValueError):
    """The input drove the mechanism to or beyond a position where it cannot be assembled.

    Attributes: ``sample`` (index in the requested times), ``time`` [s],
    ``input_value`` (the driver's θ [rad] there), ``limit`` (the limiting input
    [rad], when known) and ``partial`` (a Result with every sample before it,
    or ``None`` when there is none).
    """

    def __init__(
        self,
        message: str,
        *,
        sample: int,
        time: float,
        input_value: float,
        limit: float | None = None,
        partial: Result | None = None,
    ) -> None:
        super().__init__(message)
        self.sample = sample
        self.time = time
        self.input_value = input_value
        self.limit = limit
        self.partial = partial


# ---------------------------------------------------------------- structure


def crank_driver(mech: Mechanism) -> Driver | None:
    """The mechanism's single crank driver, or None if it is driven otherwise."""
    if len(mech.drivers) != 1 or mech.drivers[0].kind != "crank":
        return None
    return mech.drivers[0]


def pins(mech: Mechanism) -> dict[str, tuple[str, ...]]:
    """Every joint that joins two or more bodies, with the bodies that name it."""
    out = {}
    for j in mech.joints:
        bs = mech.bodies_at(j)
        if len(bs) >= 2:
            out[j] = bs
    return out


def pins_of(mech: Mechanism, body: str) -> set[str]:
    """The pins (joints shared with another body) that ``body`` takes part in."""
    return {j for j, bs in pins(mech).items() if body in bs}


def other_body(bodies: tuple[str, ...], known: str) -> str | None:
    """The body of a two-body pin that is not ``known``."""
    rest = [b for b in bodies if b != known]
    return rest[0] if len(bodies) == 2 and len(rest) == 1 else None


def member_vector(body: Body, j1: str, j2: str) -> tuple[float, float]:
    """(length, β): distance from ``j1`` to ``j2`` on ``body`` and its direction in the body frame."""
    (x1, y1), (x2, y2) = body.local[j1], body.local[j2]
    return math.hypot(x2 - x1, y2 - y1), math.atan2(y2 - y1, x2 - x1)


@dataclass(frozen=True)
class CrankStart:
    """Where every role search starts: the ground, the driven crank, its ground pivot, every pin, the ground's pins."""

    ground: str
    crank: str
    pivot: str
    pins: dict[str, tuple[str, ...]]
    ground_pins: set[str]


def crank_start(
    mech: Mechanism, *, links: int, sliders: int, pin_count: int, ground_pivots: int, binary: bool = True
) -> CrankStart | None:
    """The crank of a mechanism with one crank driver and these counts, or None.

    ``links`` bodies that are links (the ground included), ``sliders`` blocks, ``pin_count`` pins (each joining
    exactly two bodies when ``binary``), ``ground_pivots`` pins on the ground, one of them the crank's pivot,
    which joins only the ground and the crank.
    """
    drv = crank_driver(mech)
    if drv is None or len(mech.links) != links or len(mech.sliders) != sliders:
        return None
    g, crank, pivot = mech.ground, drv.target, drv.pivot
    pm = pins(mech)
    if len(pm) != pin_count or (binary and any(len(bs) != 2 for bs in pm.values())):
        return None
    gp = pins_of(mech, g)
    if len(gp) != ground_pivots or pivot not in gp or set(pm[pivot]) != {g, crank}:
        return None
    return CrankStart(g, crank, pivot, pm, gp)


def sole_pin(mech: Mechanism, body: str, *known: str) -> str | None:
    """The one pin of ``body`` other than ``known``, or None if it has none or several."""
    rest = pins_of(mech, body) - set(known)
    return rest.pop() if len(rest) == 1 else None


def next_link(start: CrankStart, pin: str, known: str) -> str | None:
    """The body across the two-body ``pin`` from ``known``, unless it is the ground (then None)."""
    b = other_body(start.pins[pin], known)
    return None if b == start.ground else b


def cross(u: complex | np.ndarray, v: complex | np.ndarray) -> Any:
    """z-component of u × v for complex-encoded plane vectors."""
    return (np.conj(u) * v).imag


def branch_sign(value: float, what: str) -> float:
    """±1 from a t = 0 orientation test; refuses a configuration sitting exactly on a toggle."""
    if not math.isfinite(value) or value == 0.0:
        raise ValueError(f"{what}: the t = 0 coordinates sit on a toggle (collinear), so the branch is undefined")
    return 1.0 if value > 0 else -1.0


# ---------------------------------------------------------------- time and input


def evaluation_times(mech: Mechanism, times: np.ndarray | None) -> tuple[np.ndarray, int | None, int]:
    """(t, inserted, anchor): the requested times, with t = 0 inserted if absent.

    The closed forms give angles modulo 2π; the continuous branch is the one
    through the body's coordinate angle at t = 0 (the instant the coordinates
    describe), so t = 0 is evaluated even when not requested (``inserted`` is
    its index, removed again from the output). ``anchor`` is the index of t = 0
    (or, for a profile that does not cover t = 0, of the first sample). Unwrapping
    assumes consecutive samples less than half a turn apart.
    """
    t = np.asarray(mech.times if times is None else times, float).ravel()
    if t.size == 0:
        raise ValueError("no sample times given")
    if np.any(np.diff(t) <= 0):
        raise ValueError("sample times must be strictly increasing")
    drv = mech.drivers[0] if mech.drivers else None
    covers_zero = drv is None or drv.profile is None or drv.profile.t[0] <= 0.0 <= drv.profile.t[-1]
    hit = np.flatnonzero(t == 0.0)
    if hit.size:
        return t, None, int(hit[0])
    if not covers_zero:
        return t, None, 0
    k = int(np.searchsorted(t, 0.0))
    return np.insert(t, k, 0.0), k, k


def driver_input(drv: Driver, t: np.ndarray) -> Kin:
    """θ [rad], ω [rad/s], α [rad/s²] of the driven link at times ``t`` (vloop.drivers.evaluate)."""
    th, om, al = evaluate(drv, t)
    return np.asarray(th, float), np.asarray(om, float), np.asarray(al, float)


def requested_index(k: int, inserted: int | None) -> int:
    """Map an index of the evaluation grid back to the requested times."""
    return k if inserted is None or k < inserted else k - 1


def passes_between(
    theta: np.ndarray, extremes: Sequence[float], closes: Callable[[np.ndarray], np.ndarray]
) -> np.ndarray:
    """Whether the input reaches each sample from the one before without passing a limit (True at sample 0).

    A dyad driven by a crank closes while the distance it must bridge stays within its reach; that distance is
    extreme where the input angle is one of ``extremes`` (mod 2π), and a limit gap narrower than the samples'
    spacing lies around one of them, where the samples on either side still close. So ``closes(θ)`` (the
    closed form's own test, at input angles θ) is asked at every such angle the input passes between two
    samples. The input is taken to move monotonically from one sample to the next.
    """
    ok = np.ones(len(theta), bool)
    lo, hi = np.minimum(theta[:-1], theta[1:]), np.maximum(theta[:-1], theta[1:])
    for c in extremes:
        x = c + TWO_PI * np.ceil((lo - c) / TWO_PI)  # the first angle ≡ c at or above lo
        k = np.flatnonzero((lo < x) & (x < hi))
        if len(k):
            ok[k + 1] &= closes(x[k])
    return ok


def gap_text(between: np.ndarray, k: int) -> str:
    """What to add to the message of a failure at sample k that :func:`passes_between` found."""
    return "" if between[k] else " between the sample before and this one (the input passes a limit position there)"


def check_dyads(
    fails: Sequence[tuple[np.ndarray, str]],
    *,
    mech: Mechanism,
    t: np.ndarray,
    inserted: int | None,
    theta_in: np.ndarray,
    resolve: Callable[[np.ndarray], Result],
) -> None:
    """:func:`check_assembly` over several dyads: ``fails`` pairs each one's closable-mask with its message."""
    check_assembly(
        np.logical_and.reduce([ok for ok, _ in fails]),
        mech=mech,
        t=t,
        inserted=inserted,
        theta_in=theta_in,
        what=lambda k: "; ".join(msg for ok, msg in fails if not ok[k]),
        limit=None,
        resolve=resolve,
    )


def check_assembly(
    ok: np.ndarray,
    *,
    mech: Mechanism,
    t: np.ndarray,
    inserted: int | None,
    theta_in: np.ndarray,
    what: Callable[[int], str],
    limit: float | None,
    resolve: Callable[[np.ndarray], Result],
) -> None:
    """Raise :class:`LimitPositionError` at the first sample where ``ok`` is False.

    ``what(k)`` describes the failure at evaluation sample k; ``resolve(times)``
    recomputes the samples before it for ``partial``.
    """
    bad = np.flatnonzero(~ok)
    if bad.size == 0:
        return
    k = int(bad[0])
    user_t = t if inserted is None else np.delete(t, inserted)
    if inserted is not None and k == inserted:
        raise LimitPositionError(
            f"{mech.name}: cannot be assembled at t = 0 (driver θ = {angle_text(theta_in[k])}): {what(k)}",
            sample=-1,
            time=0.0,
            input_value=float(theta_in[k]),
            limit=limit,
        )
    i = requested_index(k, inserted)
    partial = resolve(user_t[:i]) if i > 0 else None
    raise LimitPositionError(
        f"{mech.name}: no assembly at sample {i} (t = {user_t[i]:.10g} s, driver θ = {angle_text(theta_in[k])}): "
        f"{what(k)}; the {i} samples before it are in .partial",
        sample=i,
        time=float(user_t[i]),
        input_value=float(theta_in[k]),
        limit=limit,
        partial=partial,
    )


# ---------------------------------------------------------------- output


class Assembly:
    """Collects the closed-form solution and completes it into a :class:`Result`.

    A closed form sets the angles of the bodies it solves and the kinematics of
    the pins it solves; :meth:`result` adds the blocks (θ constant), fixed ground
    points, every other joint/point by rigid-body transport, and slider s, v, a.
    """

    def __init__(self, mech: Mechanism, t: np.ndarray, inserted: int | None, anchor: int) -> None:
        self.mech = mech
        self.bodies = mech.bodies()
        self.t = t
        self.inserted = inserted
        self.anchor = anchor
        self.angles: dict[str, Kin] = {}
        self.points: dict[str, Kin] = {}

    def set_angle(self, body: str, th: np.ndarray, om: np.ndarray, al: np.ndarray) -> None:
        """Store a body's θ, ω, α as given (used for the driven link)."""
        self.angles[body] = (np.asarray(th, float), np.asarray(om, float), np.asarray(al, float))

    def set_from_vector(self, body: str, j1: str, j2: str, phi: np.ndarray, om: np.ndarray, al: np.ndarray) -> None:
        """Store a body's motion from the angle φ of its member vector j1→j2.

        θ = φ − β, unwrapped and shifted by a whole number of turns so that at
        t = 0 it is the one nearest the body's coordinate angle ``Body.theta0``.
        """
        _, beta = member_vector(self.bodies[body], j1, j2)
        th = np.unwrap(np.asarray(phi, float) - beta)
        th = th + TWO_PI * np.round((self.bodies[body].theta0 - th[self.anchor]) / TWO_PI)
        self.set_angle(body, th, om, al)

    def set_point(self, name: str, z: np.ndarray, zd: np.ndarray, zdd: np.ndarray) -> None:
        self.points[name] = (np.asarray(z, complex), np.asarray(zd, complex), np.asarray(zdd, complex))

    def fixed(self, name: str) -> complex:
        """World position of a joint/point of the ground (constant)."""
        x, y = self.mech.points[name].at if name in self.mech.points else self.mech.joints[name]
        return complex(x, y)

    def _complete(self) -> None:
        m, n = self.mech, len(self.t)
        zero = np.zeros(n)
        for name, b in self.bodies.items():
            if b.kind == "block":
                self.angles.setdefault(name, (np.full(n, b.theta0), zero, zero))
        members = {name: [*b.local] for name, b in self.bodies.items()}
        for j in members[m.ground]:
            if j not in self.points:
                self.points[j] = (np.full(n, self.fixed(j), complex), zero.astype(complex), zero.astype(complex))
        todo = [p for p in m.tracked_points if p not in self.points]
        while todo:
            progress = False
            for p in list(todo):
                body = next(
                    (
                        bn
                        for bn, mem in members.items()
                        if p in mem and bn in self.angles and any(k in self.points for k in mem)
                    ),
                    None,
                )
                if body is None:
                    continue
                k = next(k for k in members[body] if k in self.points)
                th, om, al = self.angles[body]
                (xk, yk), (xp, yp) = self.bodies[body].local[k], self.bodies[body].local[p]
                r = np.exp(1j * th) * complex(xp - xk, yp - yk)
                zk, zkd, zkdd = self.points[k]
                self.points[p] = (zk + r, zkd + 1j * om * r, zkdd + (1j * al - om * om) * r)
                todo.remove(p)
                progress = True
            if not progress:
                raise ValueError(f"{m.name}: the closed form left {', '.join(todo)} undetermined")

    def result(self, closed_form: str, meta: dict[str, Any] | None = None) -> Result:
        """The Result (requested samples only): links, joints and points, sliders."""
        self._complete()
        m = self.mech
        keep = np.ones(len(self.t), bool)
        if self.inserted is not None:
            keep[self.inserted] = False
        links = {b: tuple(a[keep] for a in self.angles[b]) for b in m.moving_links}
        points = {}
        for p in m.tracked_points:
            z, zd, zdd = (a[keep] for a in self.points[p])
            points[p] = (z.real, z.imag, zd.real, zd.imag, zdd.real, zdd.imag)
        sliders = {}
        for sn, sl in m.sliders.items():
            if sl.guide != m.ground:
                raise ValueError(f"{m.name}: slider {sn} on a moving guide is outside the closed forms")
            u = complex(*sl.axis)
            z, zd, zdd = (a[keep] for a in self.points[sl.joint])
            sliders[sn] = ((np.conj(u) * z).real, (np.conj(u) * zd).real, (np.conj(u) * zdd).real)
        res = Result.from_arrays(
            m.name,
            ENGINE,
            self.t[keep],
            links=links,
            points=points,
            sliders=sliders,
            meta={"closed_form": closed_form, **(meta or {})},
        )
        bad = [c for c, v in res.columns.items() if not np.all(np.isfinite(v))]
        if bad:
            raise ValueError(f"{m.name}: the closed form produced non-finite values in {', '.join(bad[:5])}")
        return res
