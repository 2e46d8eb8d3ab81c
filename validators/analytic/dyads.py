"""The validators' own dyad formulas, shared by every closed form built from dyads.

Not a closed form of its own (it is not in ``analytic.CLOSED_FORMS``): the
six-bars, the five-bar, Jansen's legs, the inverted slider-crank, the Whitworth
mechanism, the slider-crank's rod and any chain of dyads (:mod:`.chain`) are each
solved as a sequence of the dyads below, in the order a student would draw them.
Nothing here touches vloop's loop equations or solver.

Conventions as in :mod:`validators.analytic.common`: a point is carried as
complex arrays (z, ż, z̈) = (x + j·y, ...), an angle as (φ, ω, α) [rad, rad/s,
rad/s²], CCW positive from +x; lengths in the file's units. u × v is
Im(conj(u)·v).

RRR dyad (:func:`rrr`): two links of lengths l1, l2, hinged to known moving or
fixed points P1, P2 and to each other at X.

  Position (law of cosines in triangle P1–X–P2): δ = P2 − P1, f = |δ|; the foot
  of X on the line P1P2, measured from P1, is p = (l1² − l2² + f²)/(2f), its
  height q = √(l1² − p²), so φ1 = arg δ + σ·atan2(q, p), X = P1 + l1·e^{jφ1},
  φ2 = arg(X − P2). σ = sign((P2 − P1) × (X − P1)), fixed by the t = 0
  coordinates. No assembly where l1² − p² ≤ 0 (f ≥ l1 + l2 or f ≤ |l1 − l2|).

  Velocity: differentiate P1 + l1·e^{jφ1} = P2 + l2·e^{jφ2} (e_k = e^{jφk}):
      j·l1·ω1·e1 − j·l2·ω2·e2 = D,   D = Ṗ2 − Ṗ1.
  Multiply by conj(e2) and take the real part (the ω2 term drops out):
      ω1 = −Re(D·conj(e2)) / (l1·sin(φ1 − φ2));
  by conj(e1):  ω2 = Re(D·conj(e1)) / (l2·sin(φ2 − φ1)).

  Acceleration: differentiate again; the same two projections with
      R = P̈2 − P̈1 + l1·ω1²·e1 − l2·ω2²·e2   in place of D give α1 and α2.

RPR dyad (:func:`rpr`, the inverted slider): a block pinned at a known point P
slides along a line fixed to a link that turns about a known pivot O; the line
is at signed distance e from O (e = u × (P − O) at t = 0, u the line's unit
direction) and the block sits at s along it, so with u = e^{jφ}

      P − O = δ = (s + j·e)·e^{jφ}.

  Position: δ = ρ·e^{jψ}; then sin(ψ − φ) = e/ρ, s = ρ·cos(ψ − φ) = σ·√(ρ² − e²)
  with σ = sign(s) at t = 0, φ = ψ − atan2(e, s). No assembly where ρ ≤ |e|.

  Velocity: conj(u)·δ̇ = ṡ − ω·e + j·ω·s, so
      ω = Im(conj(u)·δ̇)/s,   ṡ = Re(conj(u)·δ̇) + ω·e.
  Acceleration: conj(u)·δ̈ = s̈ − α·e − ω²·s + j·(2·ω·ṡ + α·s − ω²·e), so
      α = (Im(conj(u)·δ̈) − 2·ω·ṡ + ω²·e)/s,   s̈ = Re(conj(u)·δ̈) + α·e + ω²·s.
  Singular where s = 0 (the block over the pivot).

RRP dyad (:func:`rrp`, a rod and a block on a ground line): rod P1→X of length
b, X the pin of a block sliding on the line L0 + λ·u (n = j·u its normal).
With η = (P1 − L0)·n the distance of P1 from the line and ψ = θ − arg u:

  Position: η + b·sin ψ = 0, so sin ψ = −η/b, cos ψ = σ·√(1 − sin²ψ)
  (σ = sign((X − P1)·u) at t = 0), θ = arg u + ψ, s = u·X = u·P1 + b·cos ψ.
  No assembly where η² ≥ b².
  Velocity: b·cos ψ·ω = −η̇, ṡ = u·Ṗ1 − b·sin ψ·ω.
  Acceleration: α = (b·sin ψ·ω² − η̈)/(b·cos ψ),
  s̈ = u·P̈1 − b·cos ψ·ω² − b·sin ψ·α.

Slider on a moving guide (:class:`GuidedAssembly`): the file's s is the
projection of the block's joint P on the turning axis u(t) = e^{j(θg + γ)}
from the guide's first joint G (γ = axis angle − guide angle at t = 0). With
Δ = P − G:  s = Re(conj(u)·Δ),  ṡ = Re(conj(u)·Δ̇) + ω·Im(conj(u)·Δ),
s̈ = Re(conj(u)·Δ̈) + 2·ω·Im(conj(u)·Δ̇) + α·Im(conj(u)·Δ) − ω²·Re(conj(u)·Δ),
(ω, α of the guide; d/dt conj(u) = −j·ω·conj(u)). The block turns with its
guide: θ_block = θ_guide + (θ0_block − θ0_guide).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from vloop.mechanism import Mechanism
from vloop.result import LINK_FIELDS, POINT_FIELDS, SLIDER_FIELDS, Result

from .common import TWO_PI, Assembly, Kin, branch_sign, cross, member_vector

__all__ = [
    "GuidedAssembly",
    "carry",
    "close_rrr",
    "crank_pin",
    "fixed_kin",
    "local_vector",
    "rpr",
    "rrp",
    "rrr",
    "rrr_sigma",
]


def fixed_kin(z: complex, n: int) -> Kin:
    """A point that does not move: (z, 0, 0) over ``n`` samples."""
    zero = np.zeros(n, complex)
    return np.full(n, z, complex), zero, zero.copy()


def local_vector(mech: Mechanism, body: str, frm: str, to: str) -> complex:
    """The body-frame vector from member ``frm`` to member ``to`` of ``body`` (complex)."""
    local = mech.bodies()[body].local
    (x1, y1), (x2, y2) = local[frm], local[to]
    return complex(x2 - x1, y2 - y1)


def carry(zK: Kin, th: Kin, rho: complex) -> Kin:
    """Rigid-body transport: a point at body-frame offset ``rho`` from the solved member K.

    z = z_K + e^{jθ}·ρ,  ż = ż_K + j·ω·e^{jθ}·ρ,  z̈ = z̈_K + (j·α − ω²)·e^{jθ}·ρ.
    """
    z, zd, zdd = zK
    t, om, al = th
    r = np.exp(1j * t) * rho
    return z + r, zd + 1j * om * r, zdd + (1j * al - om * om) * r


def rrr(z1: Kin, z2: Kin, l1: float, l2: float, sigma: float) -> tuple[np.ndarray, Kin, Kin, Kin]:
    """The RRR dyad of the module docstring.

    Returns (ok, (φ1, ω1, α1), (φ2, ω2, α2), (X, Ẋ, Ẍ)): φ1 the direction P1→X,
    φ2 the direction P2→X (not unwrapped), X the middle pin; ``ok`` is False
    where the dyad cannot be assembled (the returned values there are finite
    but meaningless).
    """
    p1, p1d, p1dd = z1
    p2, p2d, p2dd = z2
    delta = p2 - p1
    f = np.abs(delta)
    f_safe = np.where(f > 0, f, 1.0)
    p = (l1 * l1 - l2 * l2 + f * f) / (2.0 * f_safe)
    q2 = (l1 - p) * (l1 + p)
    ok = (q2 > 0.0) & (f > 0.0)
    phi1 = np.angle(delta) + sigma * np.arctan2(np.sqrt(np.where(ok, q2, 0.0)), p)
    e1 = np.exp(1j * phi1)
    x = p1 + l1 * e1
    phi2 = np.angle(x - p2)
    e2 = np.exp(1j * phi2)
    s12 = np.sin(phi1 - phi2)
    s12 = np.where(ok & (s12 != 0.0), s12, 1.0)
    dv = p2d - p1d
    w1 = -(dv * np.conj(e2)).real / (l1 * s12)
    w2 = (dv * np.conj(e1)).real / (-l2 * s12)
    r = p2dd - p1dd + l1 * w1 * w1 * e1 - l2 * w2 * w2 * e2
    a1 = -(r * np.conj(e2)).real / (l1 * s12)
    a2 = (r * np.conj(e1)).real / (-l2 * s12)
    xd = p1d + 1j * l1 * w1 * e1
    xdd = p1dd + (1j * a1 - w1 * w1) * l1 * e1
    return ok, (phi1, w1, a1), (phi2, w2, a2), (x, xd, xdd)


def rrr_sigma(z1: complex, z2: complex, x: complex, what: str) -> float:
    """σ of :func:`rrr` from t = 0 positions: +1 if X is left of P1→P2, −1 if right (refuses a toggle)."""
    return branch_sign(float(cross(z2 - z1, x - z1)), what)


def crank_pin(asm: Assembly, crank: str, pivot: str, pin: str, inputs: Kin) -> Kin:
    """The pin of a crank turning about a fixed pivot: carried from the pivot by a·e^{jβ} (the crank frame's O→A)."""
    a, beta = member_vector(asm.bodies[crank], pivot, pin)
    return carry(fixed_kin(asm.fixed(pivot), len(asm.t)), inputs, a * np.exp(1j * beta))


def close_rrr(
    asm: Assembly, links: tuple[str, str], joints: tuple[str, str, str], z1: Kin, z2: Kin
) -> tuple[np.ndarray, Kin, float]:
    """Close the RRR dyad of ``links`` (L1 from P1, L2 from P2) meeting at X, ``joints`` = (P1, P2, X).

    Lengths from the body frames, σ from the t = 0 coordinates (:func:`rrr_sigma`); stores both links' angles
    and X's kinematics in ``asm``. Returns (ok, X's kinematics, σ).
    """
    (l1, l2), (p1, p2, x) = links, joints
    len1, _ = member_vector(asm.bodies[l1], p1, x)
    len2, _ = member_vector(asm.bodies[l2], p2, x)
    z0 = asm.mech.joints
    at = (complex(*z0[p1]), complex(*z0[p2]), complex(*z0[x]))
    sigma = rrr_sigma(*at, f"{asm.mech.name}: pin {x} on the line {p1}{p2}")
    ok, phi1, phi2, zx = rrr(z1, z2, len1, len2, sigma)
    asm.set_from_vector(l1, p1, x, *phi1)
    asm.set_from_vector(l2, p2, x, *phi2)
    asm.set_point(x, *zx)
    return ok, zx, sigma


def rrp(zA: Kin, b: float, L0: complex, u: complex, sigma: float) -> tuple[np.ndarray, Kin, Kin]:
    """The RRP dyad of the module docstring: rod A→B of length b, B on the line L0 + λ·u.

    Returns (ok, (θ, ω, α), (s, ṡ, s̈)) with θ the direction A→B (not unwrapped)
    and s = u·B; ``ok`` is False where the line is out of reach (η² ≥ b²).
    """
    z, zd, zdd = zA
    n = 1j * u
    eta = (np.conj(n) * (z - L0)).real
    etad = (np.conj(n) * zd).real
    etadd = (np.conj(n) * zdd).real
    sin_psi = -eta / b
    disc = 1.0 - sin_psi * sin_psi
    ok = disc > 0.0
    cos_psi = sigma * np.sqrt(np.where(ok, disc, 1.0))
    om3 = -etad / (b * cos_psi)
    al3 = (b * sin_psi * om3 * om3 - etadd) / (b * cos_psi)
    th3 = np.angle(u) + np.arctan2(sin_psi, cos_psi)
    s = (np.conj(u) * z).real + b * cos_psi
    sd = (np.conj(u) * zd).real - b * sin_psi * om3
    sdd = (np.conj(u) * zdd).real - b * cos_psi * om3 * om3 - b * sin_psi * al3
    return ok, (th3, om3, al3), (s, sd, sdd)


def rpr(zP: Kin, zO: Kin, e: float, sigma: float) -> tuple[np.ndarray, Kin, Kin]:
    """The RPR dyad (inverse slider) of the module docstring.

    Returns (ok, (φ, ω, α), (s, ṡ, s̈)): φ the direction of the sliding line
    (not unwrapped), s the block's position along it measured from the foot of
    the pivot O on the line; ``ok`` is False where ρ ≤ |e| or s = 0.
    """
    delta = zP[0] - zO[0]
    dd = zP[1] - zO[1]
    ddd = zP[2] - zO[2]
    rho = np.abs(delta)
    s2 = (rho - abs(e)) * (rho + abs(e))
    ok = s2 > 0.0
    s = sigma * np.sqrt(np.where(ok, s2, 1.0))
    phi = np.angle(delta) - np.arctan2(e, s)
    uc = np.exp(-1j * phi)  # conj(u)
    v, acc = uc * dd, uc * ddd
    w = v.imag / s
    sd = v.real + w * e
    al = (acc.imag - 2.0 * w * sd + w * w * e) / s
    sdd = acc.real + al * e + w * w * s
    return ok, (phi, w, al), (s, sd, sdd)


class GuidedAssembly(Assembly):
    """:class:`Assembly` that also outputs sliders whose guide is a moving link.

    Use :meth:`set_from_axis` for a guide whose angle comes from its sliding
    line; :meth:`result` turns each block with its guide and projects the
    block's joint on the turning axis (module docstring).
    """

    def set_from_axis(self, body: str, slider: str, phi: Kin) -> None:
        """Store a guide's motion from the direction φ of the line of ``slider`` it carries.

        θ = φ − γ (γ = axis angle − θ0 of the guide at t = 0), unwrapped and
        shifted by whole turns to the body's coordinate angle at t = 0.
        """
        if self.mech.sliders[slider].guide != body:
            raise ValueError(f"{self.mech.name}: slider {slider} is not guided by {body}")
        gamma = self.bodies[slider].theta0 - self.bodies[body].theta0
        th = np.unwrap(np.asarray(phi[0], float) - gamma)
        th = th + TWO_PI * np.round((self.bodies[body].theta0 - th[self.anchor]) / TWO_PI)
        self.set_angle(body, th, phi[1], phi[2])

    def result(self, closed_form: str, meta: dict[str, Any] | None = None) -> Result:
        """As :meth:`Assembly.result`, plus blocks on moving guides (θ, ω, α and s, ṡ, s̈), in vloop's column order."""
        m = self.mech
        moving = {n: s for n, s in m.sliders.items() if s.guide != m.ground}
        for name, sl in moving.items():
            th, om, al = self.angles[sl.guide]
            off = self.bodies[name].theta0 - self.bodies[sl.guide].theta0
            self.set_angle(name, th + off, om, al)
        self._complete()
        keep = np.ones(len(self.t), bool)
        if self.inserted is not None:
            keep[self.inserted] = False
        extra: dict[str, np.ndarray] = {}
        for name, sl in moving.items():
            th, om, al = (a[keep] for a in self.angles[sl.guide])
            gamma = self.bodies[name].theta0 - self.bodies[sl.guide].theta0
            origin = self.bodies[sl.guide].joints[0]
            uc = np.exp(-1j * (th + gamma))
            dz = [(a - b)[keep] for a, b in zip(self.points[sl.joint], self.points[origin], strict=True)]
            p, pd, pdd = (uc * d for d in dz)
            extra[f"{name}.s"] = p.real
            extra[f"{name}.v"] = pd.real + om * p.imag
            extra[f"{name}.a"] = pdd.real + 2.0 * om * pd.imag + al * p.imag - om * om * p.real
            for f, arr in zip(LINK_FIELDS, self.angles[name], strict=True):
                extra[f"{name}.{f}"] = arr[keep]
        ground_guided = {n: s for n, s in m.sliders.items() if n not in moving}
        self.mech = dataclasses.replace(m, sliders=ground_guided)
        try:
            base = super().result(closed_form, meta)
        finally:
            self.mech = m
        cols = {**base.columns, **extra}
        order = [f"{n}.{f}" for n in m.moving_links for f in LINK_FIELDS]
        order += [f"{n}.{f}" for n in m.tracked_points for f in POINT_FIELDS]
        order += [f"{n}.{f}" for n in m.sliders for f in SLIDER_FIELDS]
        bad = [c for c in extra if not np.all(np.isfinite(extra[c]))]
        if bad:
            raise ValueError(f"{m.name}: the closed form produced non-finite values in {', '.join(bad[:5])}")
        return Result(base.mechanism, base.engine, base.t, {c: cols[c] for c in order}, meta=base.meta)
