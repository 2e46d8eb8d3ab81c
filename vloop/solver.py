"""Position, velocity and acceleration over time, block by block.

State over the sample grid (rows = samples):

* ``E[:, a] = e^{jθ_a}`` (unit complex) and ``TH[:, a]`` (unwrapped θ) per rotating
  link, ``W``/``AL`` its ω/α; ``S``/``SD``/``SDD`` per slider. A last padding
  column (E = 1, others 0) stands for "fixed" so terms index it with -1.
* Term vectors ``z = (r + s)·cδ·E`` with cδ = e^{jδ}; velocities and
  accelerations follow by differentiation:
  ż = ṡ·e + jω·z,   z̈ = s̈·e + 2jṡω·e + (jα − ω²)·z,   e = cδ·E.

Blocks are solved in the order of the block-triangular decomposition. One-loop
dyads have closed forms evaluated for all samples at once (branch σ from the
t = 0 assembly); other blocks use Newton–Raphson per sample with the analytic
Jacobian, warm-started by the Taylor predictor x + ẋ·h + ẍ·h²/2 from the
previous sample. Velocities and accelerations are the exact linear systems
J·u̇ = −(known part of Σ ż), J·ü = −(known part of Σ z̈), solved for all samples
at once (Cramer's rule for 2×2 blocks, batched ``numpy.linalg.solve`` otherwise).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from . import budget, newton
from .assembly import redundancy_text
from .drivers import evaluate_all
from .errors import MechanismError, MotionError
from .loops import Block, LoopSystem
from .model import Mechanism
from .result import Result

EPS = float(np.finfo(float).eps)
DEFAULT_RTOL = (
    1e-9  # accuracy asked of every output, relative: a sample whose error bound cond²·ε exceeds it is refused
)
ILL_FRACTION = 1e-3  # a kept sample whose error bound exceeds this fraction of rtol is flagged ill-conditioned
CHANGE_GAP = 1e-6  # two assembly branches closer than this fraction of the mechanism size meet: a change point
DEFAULT_TOL = 1e-12  # Newton stops when the step is below tol·(1 + |x|)
DEFAULT_MAX_ITER = 30
TWO_PI = 2.0 * math.pi


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Im(conj(a)·b): the 2-D cross product of complex numbers seen as vectors."""
    return a.real * b.imag - a.imag * b.real


def _add_real_product(out: np.ndarray, A: np.ndarray, H: np.ndarray) -> None:
    """out += A @ H for real A and complex H, as two real BLAS products (numpy's mixed
    real-complex matmul takes a slow generic loop)."""
    out.real += A @ H.real
    out.imag += A @ H.imag


@dataclass
class _Sum:
    """Σ_t M[t, :]·z_t over a set of terms, regrouped so it costs a few small matrix products:
    rigid vectors by the angle that turns them (G, constant), vectors fixed to the ground (c0),
    slider vectors on the ground (Hf: only s varies) and slider vectors on moving guides.
    Evaluated for positions, velocities or accelerations from the state arrays."""

    c0: np.ndarray  # (K,): the rigid vectors fixed to the ground
    avars: np.ndarray  # angle columns turning rigid vectors
    G: np.ndarray  # (len(avars), K): Σ M·r·e^{jδ} of the rigid vectors turning with each angle
    f_sl: np.ndarray  # sliders along ground lines ...
    f_r: np.ndarray
    Hf: np.ndarray  # (n, K): M·e^{jδ}
    s_ang: np.ndarray  # slider vectors on moving guides: angle, slider, r, e^{jδ}, M
    s_sl: np.ndarray
    s_r: np.ndarray
    s_cd: np.ndarray
    Ms: np.ndarray

    @classmethod
    def build(cls, sys: LoopSystem, terms: np.ndarray, M: np.ndarray) -> _Sum:
        ang, sl, r = sys.t_ang[terms], sys.t_sl[terms], sys.t_r[terms]
        cd = np.exp(1j * sys.t_delta[terms])
        M = M.astype(complex).reshape(len(terms), -1)
        rigid = sl < 0
        fixed = rigid & (ang < 0)
        c0 = ((r * cd)[fixed][:, None] * M[fixed]).sum(0)
        avars = np.unique(ang[rigid & (ang >= 0)])
        G = np.array([((r * cd)[rigid & (ang == a)][:, None] * M[rigid & (ang == a)]).sum(0) for a in avars])
        G = G.reshape(len(avars), M.shape[1])
        f = ~rigid & (ang < 0)
        mv = ~rigid & (ang >= 0)
        return cls(c0, avars, G, sl[f], r[f], cd[f][:, None] * M[f], ang[mv], sl[mv], r[mv], cd[mv], M[mv])

    def pos(self, st: _State, k: slice) -> np.ndarray:
        out = st.E[k][:, self.avars] @ self.G + self.c0
        if len(self.f_sl):
            _add_real_product(out, self.f_r + st.S[k][:, self.f_sl], self.Hf)
        if len(self.s_sl):
            es = self.s_cd * st.E[k][:, self.s_ang]
            out += ((self.s_r + st.S[k][:, self.s_sl]) * es) @ self.Ms
        return out

    def vel(self, st: _State, k: slice) -> np.ndarray:
        out = 1j * ((st.W[k][:, self.avars] * st.E[k][:, self.avars]) @ self.G)
        if len(self.f_sl):
            _add_real_product(out, st.SD[k][:, self.f_sl], self.Hf)
        if len(self.s_sl):
            es = self.s_cd * st.E[k][:, self.s_ang]
            ms = self.s_r + st.S[k][:, self.s_sl]
            out += ((st.SD[k][:, self.s_sl] + 1j * st.W[k][:, self.s_ang] * ms) * es) @ self.Ms
        return out

    def acc(self, st: _State, k: slice) -> np.ndarray:
        w = st.W[k][:, self.avars]
        out = ((1j * st.AL[k][:, self.avars] - w * w) * st.E[k][:, self.avars]) @ self.G
        if len(self.f_sl):
            _add_real_product(out, st.SDD[k][:, self.f_sl], self.Hf)
        if len(self.s_sl):
            es = self.s_cd * st.E[k][:, self.s_ang]
            ms = self.s_r + st.S[k][:, self.s_sl]
            ws = st.W[k][:, self.s_ang]
            sd = st.SD[k][:, self.s_sl]
            coriolis = 2j * sd * ws  # a slider on a rotating guide
            out += ((st.SDD[k][:, self.s_sl] + coriolis + (1j * st.AL[k][:, self.s_ang] - ws * ws) * ms) * es) @ self.Ms
        return out


@dataclass
class _Plan:
    """Index data of one block (precomputed once per LoopSystem)."""

    block: Block
    C: np.ndarray  # (m, n_terms_block) signs of the block's terms in its loops
    Ct: np.ndarray  # C.T as complex: complex @ complex matmuls are far faster than complex @ float
    ang: np.ndarray  # per term: angle variable, slider, r, e^{jδ}
    sl: np.ndarray
    r: np.ndarray
    cd: np.ndarray
    unk_ang: list[int]  # angle variables among the unknowns
    unk_sl: list[int]  # slider indices among the unknowns
    masks: list[np.ndarray]  # per unknown: the block terms it enters
    total: _Sum  # Σ over the block's loops (K = m)
    known_sum: _Sum  # Σ over the vectors independent of the unknowns
    # per unknown angle a: W_a(t) = const + Σ coef·s (the block's vectors turning with a, unrotated)
    w_const: dict[int, complex]
    w_sl: dict[int, list[tuple[int, complex]]]
    # per unknown slider i: its vector's direction U = coef·E[:, ang]
    u_dir: dict[int, tuple[int, complex]]


def _plans(sys: LoopSystem) -> list[_Plan]:
    plans = sys.cache.get("plans")
    if plans is not None:
        return plans
    na = sys.n_angles
    cd_all = np.exp(1j * sys.t_delta)
    plans = []
    for b in sys.blocks:
        Cb = sys.C[list(b.loops)]
        terms = np.nonzero(np.any(Cb != 0, axis=0))[0]
        Cb = Cb[:, terms]
        ang, sl = sys.t_ang[terms], sys.t_sl[terms]
        unk_ang = [v for v in b.unknowns if v < na]
        unk_sl = [v - na for v in b.unknowns if v >= na]
        known = ~(np.isin(ang, unk_ang) | np.isin(sl, unk_sl))
        masks = [(ang == v) if v < na else (sl == v - na) for v in b.unknowns]
        g = Cb[0]
        w_const, w_sl, u_dir = {}, {}, {}
        for a in unk_ang:
            on = np.nonzero(ang == a)[0]
            w_const[a] = complex(sum(g[t] * sys.t_r[terms[t]] * cd_all[terms[t]] for t in on))
            w_sl[a] = [(int(sl[t]), complex(g[t] * cd_all[terms[t]])) for t in on if sl[t] >= 0]
        for i in unk_sl:
            t = int(np.nonzero(sl == i)[0][0])
            u_dir[i] = (int(ang[t]), complex(g[t] * cd_all[terms[t]]))
        plan = _Plan(
            b, Cb, Cb.T.astype(complex), ang, sl, sys.t_r[terms], cd_all[terms], unk_ang, unk_sl, masks,
            _Sum.build(sys, terms, Cb.T), _Sum.build(sys, terms[known], Cb.T[known]), w_const, w_sl, u_dir,
        )  # fmt: skip
        plans.append(plan)
    sys.cache["plans"] = plans
    return plans


def _system_sums(sys: LoopSystem) -> tuple[_Sum, _Sum]:
    """Sums giving every point's position (and rates) and every loop's closure residual (cached)."""
    if "sums" not in sys.cache:
        terms = np.arange(len(sys.t_r))
        sys.cache["sums"] = (_Sum.build(sys, terms, sys.path), _Sum.build(sys, terms, sys.C.T))
    return sys.cache["sums"]


class _State:
    """Arrays over the sample grid; the last column of each is the 'fixed' padding."""

    def __init__(self, n: int, na: int, ns: int) -> None:
        self.E = np.ones((n, na + 1), complex)
        self.TH = np.zeros((n, na))
        self.W = np.zeros((n, na + 1))
        self.AL = np.zeros((n, na + 1))
        self.S = np.zeros((n, ns + 1))
        self.SD = np.zeros((n, ns + 1))
        self.SDD = np.zeros((n, ns + 1))

    def z(
        self, k: slice, ang: np.ndarray, sl: np.ndarray, r: np.ndarray, cd: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Term vectors z = (r + s)·e^{j(θ + δ)} and their unit directions over rows ``k``."""
        e = cd * self.E[k][:, ang]
        return (r + self.S[k][:, sl]) * e, e


class _Failure(Exception):
    """Why sample ``sample`` cannot be solved; ``loop`` (index) where a loop is to blame."""

    def __init__(self, sample: int, loop: int | None, why: str) -> None:
        self.sample, self.loop, self.why = sample, loop, why


# ------------------------------------------------------------------ positions


def _w(p: _Plan, st: _State, k: slice, a: int, skip: int = -2) -> np.ndarray | complex:
    """W_a: the block's vectors turning with unknown angle a, before rotation (slider ``skip`` left out)."""
    w: np.ndarray | complex = p.w_const[a]
    for i, coef in p.w_sl[a]:
        if i != skip:
            w = w + coef * st.S[k, i]
    return w


def _u(p: _Plan, st: _State, k: slice, i: int) -> np.ndarray:
    a, coef = p.u_dir[i]
    return coef * st.E[k, a]


def _closed_form(p: _Plan, st: _State, k: slice, na: int, sig: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Closed-form positions of a one-loop dyad for rows ``k`` on branches ``sig`` (±1 per row).

    Returns the mask of assemblable rows and the discriminant h [length²]: the dyad's two
    assembly solutions lie 2·√h apart (h < 0: no solution, the input is past a limit position;
    h = 0: the two branches meet — a toggle, or a change point where they cross).
    """
    b = p.block
    X = -p.known_sum.pos(st, k)[:, 0]
    if b.kind == "RRR":
        # W1·E1 + W2·E2 = X: |W1|, |W2|, |X| form a triangle (law of cosines)
        W1, W2 = _w(p, st, k, p.unk_ang[0]), _w(p, st, k, p.unk_ang[1])
        A2, B2 = np.abs(W1) ** 2, np.abs(W2) ** 2
        D2 = X.real**2 + X.imag**2
        k1 = 0.5 * (A2 + D2 - B2)
        h2 = _round_off_zero(A2 * D2 - k1 * k1, A2 * D2)
        ok = (h2 >= 0) & (D2 > 0)
        Dd = np.where(D2 > 0, D2, 1.0)
        P = X * (k1 + 1j * sig * np.sqrt(np.where(ok, h2, 0.0))) / Dd
        _set_angle(st, k, p.unk_ang[0], P / W1)
        _set_angle(st, k, p.unk_ang[1], (X - P) / W2)
        return ok, h2 / Dd
    if b.kind == "RRP":
        # W1·E1 + s·U = X with U a known unit direction: project on U's normal
        i = p.unk_sl[0]
        Uc = np.conj(_u(p, st, k, i))
        W1 = _w(p, st, k, p.unk_ang[0])
        XU, WU = X * Uc, W1 * Uc
        y = XU.imag
        h = _round_off_zero(np.abs(W1) ** 2 - y * y, np.abs(W1) ** 2)
        ok = h >= 0
        c = sig * np.sqrt(np.where(ok, h, 0.0))
        _set_angle(st, k, p.unk_ang[0], (c + 1j * y) / WU)
        st.S[k, i] = XU.real - c
        return ok, h
    if b.kind == "RPR":
        # (W + s·c)·E = X with c a unit direction fixed to the same link: |W + s·c| = |X|
        i, a = p.unk_sl[0], p.unk_ang[0]
        cdir = p.u_dir[i][1]
        W = _w(p, st, k, a, skip=i)
        bb = (W * np.conj(cdir)).real
        D2 = X.real**2 + X.imag**2
        disc = _round_off_zero(bb * bb - np.abs(W) ** 2 + D2, bb * bb + np.abs(W) ** 2 + D2)
        s = -bb + sig * np.sqrt(np.where(disc >= 0, disc, 0.0))
        den = W + s * cdir
        ok = (disc >= 0) & (np.abs(den) > 0)
        st.S[k, i] = s
        _set_angle(st, k, a, X / np.where(ok, den, 1.0))
        return ok, disc
    # PP: s1·U1 + s2·U2 = X (linear: one solution, no branches)
    U1, U2 = _u(p, st, k, p.unk_sl[0]), _u(p, st, k, p.unk_sl[1])
    det = cross(U1, U2)
    ok = np.abs(det) > 1e-12
    dd = np.where(ok, det, 1.0)
    st.S[k, p.unk_sl[0]] = cross(X, U2) / dd
    st.S[k, p.unk_sl[1]] = cross(U1, X) / dd
    return ok, np.full(len(ok), np.inf)


def _round_off_zero(h: np.ndarray, size: np.ndarray) -> np.ndarray:
    """A discriminant whose magnitude is within round-off of the terms it was computed from (``size``)
    is zero: the two branches meet (an input exactly at a limit or change point, up to round-off)."""
    return np.where(np.abs(h) <= 16 * EPS * size, 0.0, h)


def _set_angle(st: _State, k: slice, a: int, E: np.ndarray) -> None:
    """Store e^{jθ} and the unwrapped θ = φ + 2π·n for rows ``k`` (row k.start keeps its turn count).

    φ is the principal angle of E, n the whole turns counted by continuity from the first row:
    the stored θ is then exactly φ + 2πn whatever the sampling before it, so a run that starts
    late gives the same numbers as one from t = 0.
    """
    E = E / np.abs(E)
    st.E[k, a] = E
    phi = np.angle(st.E[k, a])
    start = st.TH[k.start or 0, a]
    est = start + np.concatenate(
        ([np.angle(np.exp(1j * (phi[0] - start)))], np.cumsum(np.angle(np.exp(1j * np.diff(phi)))))
    )
    st.TH[k, a] = phi + TWO_PI * np.round((est - phi) / TWO_PI)


def _jacobian(p: _Plan, z: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Real block Jacobians (rows, 2m, 2m) of [Re; Im] of the block's loops."""
    cols = []
    for v, mask in zip(p.block.unknowns, p.masks, strict=True):
        d = (1j * z if v in p.unk_ang else e) * mask
        cols.append(d @ p.Ct)  # (rows, m)
    Jc = np.stack(cols, axis=-1)  # (rows, m, nu)
    return np.concatenate([Jc.real, Jc.imag], axis=1)


# ------------------------------------------------------------------ velocities / accelerations


def _rates(p: _Plan, st: _State, k: slice, J: np.ndarray | None, what: str, cols: tuple | None = None) -> np.ndarray:
    """Unknown rates (what="v") or accelerations ("a") of a block for rows ``k``.

    The unknowns' own rate columns must still be zero: the sum is then the known part.
    ``J``: the block Jacobians for blocks larger than 2×2 (Cramer's rule otherwise).
    """
    R = -(p.total.vel(st, k) if what == "v" else p.total.acc(st, k))  # (rows, m) complex
    if J is None:
        c1, c2 = cols if cols is not None else _columns(p, st, k)
        det = cross(c1, c2)
        R0 = R[:, 0]
        out = np.empty((len(R0), 2))
        out[:, 0] = cross(R0, c2) / det
        out[:, 1] = cross(c1, R0) / det
        return out
    rhs = np.concatenate([R.real, R.imag], axis=1)
    return _solve_block(J, rhs)


def _solve_block(J: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """Solve J·x = rhs (batched over leading axes); a block with more equations than unknowns (redundant
    constraints) by least squares with the pseudo-inverse (exact when the equations are consistent)."""
    if J.shape[-1] == J.shape[-2]:
        return np.linalg.solve(J, rhs[..., None])[..., 0]
    return (np.linalg.pinv(J) @ rhs[..., None])[..., 0]


def _det_sign(J: np.ndarray) -> np.ndarray:
    """Sign of det J (the assembly branch); a rectangular (redundant) block has no branch sign: +1."""
    if J.shape[-1] == J.shape[-2]:
        return np.sign(np.linalg.det(J))
    return np.ones(J.shape[:-2])


def _columns(p: _Plan, st: _State, k: slice) -> tuple[np.ndarray, np.ndarray]:
    """The two complex Jacobian columns of a one-loop block: j·W_a·E_a for an angle, U for a slider."""
    cols = []
    for v in p.block.unknowns:
        if v in p.unk_ang:
            cols.append(1j * _w(p, st, k, v) * st.E[k, v])
        else:
            cols.append(_u(p, st, k, p.unk_sl[p.block.unknowns.index(v) - len(p.unk_ang)]))
    return cols[0], cols[1]


def _store(p: _Plan, st: _State, k: slice, vals: np.ndarray, what: str, na: int) -> None:
    for i, v in enumerate(p.block.unknowns):
        if v < na:
            (st.W if what == "v" else st.AL)[k, v] = vals[:, i]
        else:
            (st.SD if what == "v" else st.SDD)[k, v - na] = vals[:, i]


def _block_health(
    p: _Plan, st: _State, k: slice, scale: float, cols: tuple | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Condition number (angle columns divided by the mechanism size) and det sign per row."""
    if len(p.block.unknowns) == 2:
        c1, c2 = cols if cols is not None else _columns(p, st, k)
        if p.block.unknowns[0] in p.unk_ang:
            c1 = c1 / scale
        if p.block.unknowns[1] in p.unk_ang:
            c2 = c2 / scale
        det = cross(c1, c2)
        f2 = (c1.real**2 + c1.imag**2) + (c2.real**2 + c2.imag**2)
        ad = np.abs(det)
        root = np.sqrt(np.maximum(f2 * f2 - 4 * det * det, 0.0))
        with np.errstate(divide="ignore"):
            cond = np.where(ad > 0, (f2 + root) / (2 * np.where(ad > 0, ad, 1.0)), np.inf)
        return cond, np.sign(det)
    J = _jacobian(p, *st.z(k, p.ang, p.sl, p.r, p.cd))
    colscale = np.array([1 / scale if v in p.unk_ang else 1.0 for v in p.block.unknowns])
    Js = J * colscale
    return np.linalg.cond(Js), _det_sign(J)


# ------------------------------------------------------------------ run context


@dataclass
class _Inputs:
    """The drivers' values, rates and accelerations at internal grid times.

    From ``t_first`` on: the file's drivers. Before it, a path in input space x0 + u·R with
    u = (t − lead_from)/span: the lead-in of a run that starts late (from the inputs at t = 0
    to those at ``t_first`` less their whole crank turns, see :func:`_lead_in`), or the one-turn
    probe that measures winding numbers (``t_first`` = ∞).
    """

    mech: Mechanism
    t_first: float = -math.inf
    lead_from: float = 0.0
    span: float = 1.0
    x0: np.ndarray | None = None
    R: np.ndarray | None = None

    def __call__(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        t = np.asarray(t, float)
        m = len(self.mech.drivers)
        X, XD, XDD = np.zeros((len(t), m)), np.zeros((len(t), m)), np.zeros((len(t), m))
        if m == 0:
            return X, XD, XDD
        real = t >= self.t_first
        if real.any():
            X[real], XD[real], XDD[real] = evaluate_all(self.mech, t[real])
        if not real.all():
            u = (t[~real] - self.lead_from) / self.span
            X[~real] = self.x0 + u[:, None] * self.R
            XD[~real] = self.R / self.span
        return X, XD, XDD


@dataclass(frozen=True)
class _ChangePoint:
    """Where the two assembly branches of closed-form block ``block`` meet, at internal time ``time``."""

    block: int
    time: float
    flip: bool  # whether σ changes there (True on the smooth continuation of a crossing)
    smooth: bool  # whether this continuation is the one whose velocities stay continuous


@dataclass
class _Run:
    """What one solve needs besides the state arrays; probes share ``events`` with their run."""

    sys: LoopSystem
    inputs: _Inputs
    scale: float
    tol: float
    max_iter: int
    rtol: float
    events: dict[int, list[_ChangePoint]] = field(default_factory=dict)
    detect: bool = True  # look for change points (the main run only)
    check: bool = True  # refuse ill-conditioned samples and branch flips
    rates: bool = True
    newton_sign: dict[int, float] = field(default_factory=dict)  # det sign of each Newton block's t = 0 branch
    tail: bool = True  # the rows end the run (not a chunk followed by another)
    t_start: float = 0.0  # the run's first requested time
    memory_budget: Any = None  # as given to solve() (bytes or text), else from the environment or the file

    def sigma(self, i: int, t: np.ndarray) -> np.ndarray:
        """Assembly branch (±1) of closed-form block ``i`` at times ``t``: σ at t = 0, flipped after each event."""
        sig = np.full(len(t), _plans(self.sys)[i].block.sigma)
        for ev in self.events.get(i, ()):
            if ev.flip:
                sig[t > ev.time] *= -1.0
        return sig


@dataclass
class _Solved:
    n_ok: int
    failure: _Failure | None
    conds: list[np.ndarray]
    signs: list[np.ndarray]
    discs: list[np.ndarray]  # closed-form blocks' discriminants h (None for Newton blocks)
    at_change: np.ndarray  # rows whose rates were taken across a change point


# ------------------------------------------------------------------ blocks in order


def _run_blocks(run: _Run, st: _State, tg: np.ndarray, n: int, upto: int | None = None) -> _Solved:
    """Solve blocks 0..upto (default: all) in order on rows 0..n-1 (row 0 must be assembled)."""
    sys = run.sys
    na = sys.n_angles
    out = _Solved(n, None, [], [], [], np.zeros(n, bool))
    for i, p in enumerate(_plans(sys)):
        if upto is not None and i > upto:
            break
        fac = None
        if p.block.kind == "newton":
            failure, fac = newton.solve_block(run, st, tg, i, p, out.n_ok)
            if failure is not None:
                _fail(out, failure)
            out.discs.append(None)
            sig = run.sigma(i, tg[: out.n_ok])
        else:
            sig = _positions(run, st, tg, i, p, out)
        if out.n_ok == 0:
            break
        k = slice(0, out.n_ok)
        cols = None
        if fac is None:
            cols = _columns(p, st, k)  # shared by health and rates
            cond, sgn = _block_health(p, st, k, run.scale, cols)
        else:
            cond, sgn = fac.cond[k], fac.sign[k]
        near = _near_change_point(run, i, tg[k], cond)
        if run.check:
            signed = sgn * sig[: out.n_ok]
            bad = np.nonzero(((_error_bound(cond) > run.rtol) | (signed != signed[0])) & ~near)[0]
            if len(bad):
                _fail(out, _Failure(int(bad[0]), p.block.loops[0], _toggle_reason(cond[bad[0]], run.rtol)))
                k = slice(0, out.n_ok)
                cond, sgn, near = cond[k], sgn[k], near[k]
                cols = None if cols is None else (cols[0][k], cols[1][k])
        out.conds.append(cond)
        out.signs.append(sgn)
        if out.n_ok == 0 or not run.rates:
            continue
        if fac is None:
            _store(p, st, k, _rates(p, st, k, None, "v", cols), "v", na)
            _store(p, st, k, _rates(p, st, k, None, "a", cols), "a", na)
        else:
            _store(p, st, k, _rates_by(p, st, k, fac.inv[k], "v"), "v", na)
            _store(p, st, k, _rates_by(p, st, k, fac.inv[k], "a"), "a", na)
        if near.any():
            _rates_across(run, st, tg, i, p, np.nonzero(near)[0], out)
    out.at_change = out.at_change[: out.n_ok]
    return out


def _rates_by(p: _Plan, st: _State, k: slice, inv: np.ndarray, what: str) -> np.ndarray:
    """Rates of a Newton block from its factored Jacobians (J⁻¹, or the least-squares (JᵀJ)⁻¹Jᵀ)."""
    R = -(p.total.vel(st, k) if what == "v" else p.total.acc(st, k))
    rhs = np.concatenate([R.real, R.imag], axis=1)
    return (inv @ rhs[..., None])[..., 0]


def _fail(out: _Solved, failure: _Failure) -> None:
    """Keep the earliest failure; rows from it on are not solved."""
    if failure.sample < out.n_ok:
        out.n_ok, out.failure = failure.sample, failure


def _toggle_reason(cond: float, rtol: float) -> str:
    return (
        f"the mechanism reaches a toggle (singular Jacobian: condition number {cond:.3g}, so the accelerations "
        f"could be wrong by cond²·ε = {min(float(_error_bound(cond)), 1.0):.2g} of their size, "
        f"more than rtol = {rtol:g})"
    )


def _positions(run: _Run, st: _State, tg: np.ndarray, i: int, p: _Plan, out: _Solved) -> np.ndarray:
    """Solve block ``i``'s positions on rows 0..out.n_ok-1 (finding change points on the main run)."""
    na = run.sys.n_angles
    k = slice(0, out.n_ok)
    sig = run.sigma(i, tg[k])
    ok, h = _closed_form(p, st, k, na, sig)
    if run.detect and p.block.kind != "PP":
        n_lim = int(np.argmin(ok)) if not ok.all() else out.n_ok
        try:
            found = _find_change_points(run, st, tg, i, h[:n_lim])
        except _Failure as f:
            found = []
            _fail(out, f)
        if found:
            sig = run.sigma(i, tg[k])
            ok, h = _closed_form(p, st, k, na, sig)
    if not ok[: out.n_ok].all():
        bad = int(np.argmin(ok))
        _fail(out, _Failure(bad, p.block.loops[0], "the loop cannot close: the input is past a limit position"))
    out.discs.append(h)
    return sig


# ------------------------------------------------------------------ change points

ZOOM_POINTS = 17  # probes per zoom step when locating where two branches meet
ZOOM_STEPS = 12  # each step narrows the bracket 16-fold
ETA_INPUT = 1e-5  # the rates across a change point are compared this far from it (input units: rad, or size)


def _candidate_minima(t: np.ndarray, h: np.ndarray, tail: bool = True) -> list[tuple[int, int]]:
    """Brackets (row lo, row hi) around sampled minima of h deep enough to hide a zero between samples.

    Near a double zero h ≈ c·(t − t*)², so a parabola through three samples has its minimum
    near 0 whatever the phase of the sampling; a broad minimum keeps it near the samples.
    ``tail``: also look between the last two samples (the end of the run, not of a chunk: the
    next chunk sees that minimum with both its neighbours).
    """
    n = len(h)
    if n < 2:
        return []
    out = []
    m = np.nonzero((h[1:-1] <= h[:-2]) & (h[1:-1] <= h[2:]))[0] + 1
    for c in m:
        if _parabola_low(t, h, c, c - 1, c + 1) <= 0.25 * min(h[c - 1], h[c + 1]):
            out.append((c - 1, c + 1))
    if tail and h[-1] < h[-2]:  # still falling at the end: a zero may lie before the last sample
        if n < 3 or _parabola_low(t, h, n - 2, n - 2, n - 1) <= 0.25 * h[-1]:
            out.append((n - 2, n - 1))
    return out


def _parabola_low(t: np.ndarray, h: np.ndarray, c: int, lo: int, hi: int) -> float:
    """The least value over [t[lo], t[hi]] of the parabola through samples c − 1, c, c + 1 of h."""
    u0, u2 = t[c - 1] - t[c], t[c + 1] - t[c]
    g0, g2 = (h[c - 1] - h[c]) / u0, (h[c + 1] - h[c]) / u2
    a = (g0 - g2) / (u0 - u2)  # h ≈ h[c] + b·u + a·u² through the three samples
    b = g0 - a * u0
    if not a > 0:
        return float(min(h[lo], h[hi]))
    u = min(max(-b / (2 * a), t[lo] - t[c]), t[hi] - t[c])
    return float(h[c] + b * u + a * u * u)


def _probe(run: _Run, st: _State, tg: np.ndarray, base: int, times: np.ndarray, upto: int, **mode: bool) -> tuple:
    """Solve blocks 0..upto at ``times`` (ascending, after sample ``base``), continuing from sample ``base``.

    Returns (the _Solved record, the probe's state); row 0 of the probe is sample ``base``.
    """
    sys = run.sys
    grid = np.concatenate([[tg[base]], times])
    trial = _State(len(grid), sys.n_angles, len(sys.slider_names))
    for name in ("E", "TH", "S"):
        getattr(trial, name)[0] = getattr(st, name)[base]
    try:
        _impose_drivers(sys, trial, *run.inputs(grid))
    except MechanismError:  # a probe past the end of a tabulated input: nothing to learn there
        return _Solved(0, None, [], [], [], np.zeros(0, bool)), trial
    sub = dataclasses.replace(run, detect=False, **mode)  # shares the events found so far
    return _run_blocks(sub, trial, grid, len(grid), upto=upto), trial


def _find_change_points(run: _Run, st: _State, tg: np.ndarray, i: int, h: np.ndarray) -> list[_ChangePoint]:
    """Locate where block ``i``'s two assembly branches meet between samples, and pick the continuation.

    A sampled minimum of the discriminant h is refined by zooming probes; where the branches come
    within CHANGE_GAP of the mechanism size of each other it is a change point. The continuation
    is the one whose rates stay continuous across it (or the other one where the file asks so in
    ``[solver] change_points``). h < 0 between samples means the motion passes a limit there.
    """
    found = []
    loop = run.sys.loops[_plans(run.sys)[i].block.loops[0]]
    choices = _change_point_choices(run.sys, loop.index + 1)
    for lo, hi in _candidate_minima(tg[: len(h)], h, run.tail):
        if any(tg[lo] <= ev.time <= tg[hi] for ev in run.events.get(i, ())):
            continue  # found already (by the chunk before, whose last rows this chunk starts from)
        t_star, h_min = _zoom(run, st, tg, i, lo, hi)
        if h_min < 0:
            raise _Failure(hi, loop.index, "the loop cannot close between samples: the input passes a limit position")
        if 2.0 * math.sqrt(h_min) > CHANGE_GAP * run.scale:
            continue
        smooth_flip = _smooth_continuation(run, st, tg, i, lo, t_star)
        choice = choices[min(len(found), len(choices) - 1)]
        flip = smooth_flip if choice == "smooth" else not smooth_flip
        ev = _ChangePoint(i, t_star, flip, choice == "smooth")
        run.events.setdefault(i, []).append(ev)
        found.append(ev)
    return found


def _zoom(run: _Run, st: _State, tg: np.ndarray, i: int, lo: int, hi: int) -> tuple[float, float]:
    """(t*, h(t*)): where block ``i``'s discriminant h is least between samples lo and hi.

    Zooms on the sign change of g(t) = h(t + η) − h(t − η), which crosses zero linearly at the
    minimum (h itself is flat there), so t* is found to ~1e-12 of the bracket, not to √ε.
    """
    a, b = float(tg[lo]), float(tg[hi])
    eta = _eta(run, 0.5 * (a + b), b - a)
    first = True
    for _ in range(ZOOM_STEPS):
        ts = np.linspace(a, b, ZOOM_POINTS)
        h = _discriminant(run, st, tg, lo, i, np.concatenate([ts, ts - eta, ts + eta]))
        if h is None:  # an earlier block cannot be solved in the bracket: leave it to the main run
            return a, math.inf
        mid, g = h[: len(ts)], h[2 * len(ts) :] - h[len(ts) : 2 * len(ts)]
        if np.any(mid < 0):
            j = int(np.argmin(mid))
            return float(ts[j]), float(mid[j])
        if first and not (g[0] < 0 <= g[-1]):  # h least at an end of the bracket: no minimum inside it
            return a, math.inf  # (e.g. a limit approached but not passed: h falls to the last sample)
        first = False
        j = int(np.argmax(g >= 0)) if np.any(g >= 0) else len(ts) - 1
        a, b = float(ts[max(j - 1, 0)]), float(ts[j])
        if b - a <= 1e-9 * (tg[hi] - tg[lo]):
            break
    t_star = 0.5 * (a + b)
    h = _discriminant(run, st, tg, lo, i, np.array([t_star]))
    return t_star, (math.inf if h is None else float(h[0]))


def _discriminant(run: _Run, st: _State, tg: np.ndarray, base: int, i: int, times: np.ndarray) -> np.ndarray | None:
    """Block ``i``'s discriminant h at ``times`` (None if an earlier block fails there)."""
    order = np.argsort(times, kind="stable")
    solved, _ = _probe(run, st, tg, base, times[order], i, check=False, rates=False)
    if solved.n_ok < len(times) + 1 or len(solved.discs) <= i:
        return None
    h = np.empty(len(times))
    h[order] = solved.discs[i][1:]
    return h


def _eta(run: _Run, t_star: float, width: float, move: float = ETA_INPUT) -> float:
    """A time offset over which the inputs move ``move`` (radians, or mechanism sizes for sliders)."""
    _, XD, _ = run.inputs(np.array([t_star]))
    units = np.array([1.0 if d.kind == "crank" else run.scale for d in run.sys.mechanism.drivers])
    rate = float(np.max(np.abs(XD[0]) / units, initial=0.0))
    return min(move / rate if rate > 0 else math.inf, 0.25 * width)


def _block_rates(run: _Run, trial: _State, i: int, rows: slice) -> np.ndarray:
    """Block ``i``'s unknown rates (angles: rad/s; sliders: sizes/s) on ``rows`` of a probe."""
    p = _plans(run.sys)[i]
    na = run.sys.n_angles
    return np.stack([trial.W[rows, v] if v < na else trial.SD[rows, v - na] / run.scale for v in p.block.unknowns], 1)


def _smooth_continuation(run: _Run, st: _State, tg: np.ndarray, i: int, lo: int, t_star: float) -> bool:
    """Whether flipping σ at ``t_star`` keeps block ``i``'s rates continuous (else keeping it does)."""
    eta = _eta(run, t_star, float(tg[lo + 1] - tg[lo]))
    ts = np.array([t_star - eta, t_star + eta])
    jumps = []
    for flip in (True, False):
        run.events.setdefault(i, []).append(_ChangePoint(i, t_star, flip, True))
        try:
            solved, trial = _probe(run, st, tg, lo, ts, i, check=False)
        finally:
            run.events[i].pop()
        if solved.n_ok < 3:
            jumps.append(math.inf)
            continue
        r = _block_rates(run, trial, i, slice(1, 3))
        jumps.append(float(np.max(np.abs(r[1] - r[0]))))
    return jumps[0] <= jumps[1]


STENCIL = np.array([-4, -3, -2, -1, 1, 2, 3, 4], float)  # rates across a change point: interpolated from these
STENCIL_INPUT = 0.05  # ... multiples of the time in which the inputs move this far (rad, or sizes)


def _error_bound(cond: np.ndarray) -> np.ndarray:
    """Relative error bound of a sample's rates: accelerations lose cond²·ε (velocities cond·ε, feeding them)."""
    return cond * cond * EPS


def _near_change_point(run: _Run, i: int, t: np.ndarray, cond: np.ndarray) -> np.ndarray:
    """Rows too ill-conditioned for accurate rates that lie within a change point's stencil."""
    near = np.zeros(len(t), bool)
    events = run.events.get(i, ())
    if not events or not run.check:
        return near
    weak = _error_bound(cond) > run.rtol * ILL_FRACTION
    for ev in events:
        reach = 4.0 * _eta(run, ev.time, math.inf, STENCIL_INPUT)
        near |= weak & (np.abs(t - ev.time) < reach)
    return near


def _rates_across(run: _Run, st: _State, tg: np.ndarray, i: int, p: _Plan, rows: np.ndarray, out: _Solved) -> None:
    """Rates of block ``i`` at rows next to a change point, where its Jacobian is (nearly) singular:
    interpolated (degree 7) from the smooth branch at t* ± k·η, k = 1..4, where it is well conditioned."""
    na = run.sys.n_angles
    for ev in run.events[i]:
        eta = _eta(run, ev.time, math.inf, STENCIL_INPUT)
        mine = rows[np.abs(tg[rows] - ev.time) < 4.0 * eta]
        if not len(mine):
            continue
        base = max(int(np.searchsorted(tg, ev.time - 4.0 * eta)) - 1, 0)
        solved, trial = _probe(run, st, tg, base, ev.time + eta * STENCIL, i, check=False)
        if solved.n_ok < len(STENCIL) + 1:
            continue  # the stencil leaves the feasible range: keep the direct rates (flagged)
        u = (tg[mine] - ev.time) / eta
        for what, ang, sl in (("v", trial.W, trial.SD), ("a", trial.AL, trial.SDD)):
            vals = np.stack([ang[1:, v] if v < na else sl[1:, v - na] for v in p.block.unknowns], 1)
            fit = np.polynomial.polynomial.polyfit(STENCIL, vals, len(STENCIL) - 1)
            _store(p, st, mine, np.polynomial.polynomial.polyval(u, fit).T, what, na)
        out.at_change[mine] = True


def _change_point_choices(sys: LoopSystem, loop_number: int) -> list[str]:
    """``[solver] change_points`` for a loop: "smooth" (default) or "other", or a list for successive ones."""
    spec = sys.mechanism.options.get("change_points", {}).get(loop_number, "smooth")
    return [spec] if isinstance(spec, str) else list(spec)


# ------------------------------------------------------------------ limits


LIMIT_RTOL = 1e-12  # the limit is located to this fraction of the drivers' range over the run


def _locate_failure(run: _Run, st: _State, tg: np.ndarray, k: int, X: np.ndarray) -> tuple[float, np.ndarray]:
    """Bisect between the last solved sample k−1 and the failing sample k for the last assemblable
    time (a limit position or toggle). Returns (time, driver values there)."""
    span = np.ptp(X, axis=0) if X.size else np.zeros(0)
    span = np.where(span > 0, span, 1.0)
    base = _State(1, run.sys.n_angles, len(run.sys.slider_names))
    for name in ("E", "TH", "S"):
        getattr(base, name)[0] = getattr(st, name)[k - 1]
    lo, hi = float(tg[k - 1]), float(tg[k])
    x_lo, x_hi = X[k - 1], X[k]
    for _ in range(200):
        if X.size and np.all(np.abs(x_hi - x_lo) <= LIMIT_RTOL * span):
            break
        if hi - lo <= 4 * np.spacing(max(abs(hi), 1.0)):
            break
        mid = 0.5 * (lo + hi)
        solved, trial = _probe(
            run, base, np.array([lo]), 0, np.array([mid]), len(_plans(run.sys)) - 1, check=False, rates=False
        )
        xm = run.inputs(np.array([mid]))[0][0]
        if solved.n_ok == 2:
            lo, x_lo = mid, xm
            for name in ("E", "TH", "S"):
                getattr(base, name)[0] = getattr(trial, name)[1]
        else:
            hi, x_hi = mid, xm
    return lo, x_lo


def assemble_blocks(sys: LoopSystem, blocks: tuple, q0: np.ndarray) -> np.ndarray:
    """The t = 0 configuration the closed-form blocks give with their (possibly flipped) branches."""
    trial_sys = dataclasses.replace(sys, blocks=blocks, q0=q0, cache={})
    na, ns = sys.n_angles, len(sys.slider_names)
    st = _State(1, na, ns)
    st.TH[0] = q0[:na]
    st.E[0, :na] = np.exp(1j * q0[:na])
    st.S[0, :ns] = q0[na:]
    mech = sys.mechanism
    run = _Run(trial_sys, _Inputs(mech), mech.scale, DEFAULT_TOL, DEFAULT_MAX_ITER, DEFAULT_RTOL, detect=False)
    _impose_drivers(sys, st, *run.inputs(np.zeros(1)))
    solved = _run_blocks(run, st, np.zeros(1), 1)
    if solved.n_ok < 1:
        raise MechanismError(
            f"{mech.source}: [solver] branches: the mechanism cannot be assembled on the requested branch at t = 0 "
            f"({solved.failure.why if solved.failure else 'no solution'})",
            entry="solver",
        )
    th = st.TH[0].copy()
    free = np.array([v not in sys.drivers for v in range(na)], bool)
    th[free] %= TWO_PI  # the file's convention at t = 0: θ in [0, 2π)
    return np.concatenate([th, st.S[0, :ns]])


def _impose_drivers(sys: LoopSystem, st: _State, X: np.ndarray, XD: np.ndarray, XDD: np.ndarray) -> None:
    na = sys.n_angles
    for j, v in enumerate(sys.drivers):
        if v < na:
            st.TH[:, v] = X[:, j]
            st.E[:, v] = np.cos(X[:, j]) + 1j * np.sin(X[:, j])
            st.W[:, v], st.AL[:, v] = XD[:, j], XDD[:, j]
        else:
            st.S[:, v - na], st.SD[:, v - na], st.SDD[:, v - na] = X[:, j], XD[:, j], XDD[:, j]


# ------------------------------------------------------------------ a run that starts late

LEAD_STEP = math.pi / 180  # lead-in path step: 1° of crank (or 1/180 of the size of a slider input)
MAX_LEAD = 100_000
TURN_SAMPLES = 720  # samples of the one-turn probe that measures winding numbers


def _lead_in(sys: LoopSystem, run: _Run, t_first: float) -> tuple[np.ndarray, _Inputs, np.ndarray]:
    """Lead-in grid, inputs and whole-turn offsets of the angles for a run whose first time is not 0.

    The configuration at t_first is reached from the t = 0 assembly along a straight path in
    input space to the inputs at t_first less their whole crank turns K_j; the unwrapped angles
    then get 2π·K_j·w_j(v) for the winding number w_j(v) of angle v over one turn of crank j.
    """
    mech = sys.mechanism
    offsets = np.zeros(sys.n_angles)
    if t_first == 0.0 or not mech.drivers:
        return np.zeros(0), run.inputs, offsets
    x0 = run.inputs(np.zeros(1))[0][0]
    x1 = run.inputs(np.array([t_first]))[0][0]
    crank = np.array([d.kind == "crank" for d in mech.drivers])
    K = np.where(crank, np.trunc((x1 - x0) / TWO_PI), 0.0)
    R = x1 - x0 - TWO_PI * K
    units = np.where(crank, 1.0, mech.scale)
    n_lead = int(np.clip(np.ceil(np.max(np.abs(R) / units) / LEAD_STEP), 8, MAX_LEAD))
    length = max(1.0, 1e-3 * abs(t_first))
    lead = t_first - length + length * np.arange(n_lead) / n_lead
    inputs = _Inputs(mech, t_first, t_first - length, length, x0, R)
    for j in np.nonzero(K)[0]:
        offsets += abs(K[j]) * _turn_winding(sys, run, j, math.copysign(TWO_PI, K[j]), x0)
    return lead, inputs, offsets


def _turn_winding(sys: LoopSystem, run: _Run, j: int, turn: float, x0: np.ndarray) -> np.ndarray:
    """How much every angle grows [rad] while crank ``j`` turns once by ``turn`` from the t = 0 assembly."""
    mech = sys.mechanism
    R = np.zeros(len(x0))
    R[j] = turn
    grid = np.linspace(0.0, 1.0, TURN_SAMPLES + 1)
    inputs = _Inputs(mech, math.inf, 0.0, 1.0, x0, R)
    st = _initial_state(sys, len(grid))
    _impose_drivers(sys, st, *inputs(grid))
    turn_run = dataclasses.replace(run, inputs=inputs, events={})
    solved = _run_blocks(turn_run, st, grid, len(grid))
    name = mech.drivers[j].symbol
    if solved.failure is not None:
        raise MotionError(
            f"{mech.name}: cannot reach the first requested time: {name} cannot turn fully from its t = 0 value "
            f"({solved.failure.why})",
            entry="time",
        )
    if (
        np.max(np.abs(st.E[-1] - st.E[0]), initial=0) > 1e-9
        or np.max(np.abs(st.S[-1] - st.S[0]), initial=0) > 1e-9 * mech.scale
    ):
        raise MotionError(
            f"{mech.name}: cannot start at the first requested time without solving every turn before it: "
            f"one turn of {name} does not bring the mechanism back to its t = 0 branch; start nearer t = 0",
            entry="time",
        )
    return TWO_PI * np.round((st.TH[-1] - st.TH[0]) / TWO_PI)


def _initial_state(sys: LoopSystem, n: int) -> _State:
    """A state of n rows whose row 0 is the t = 0 assembly."""
    na, ns = sys.n_angles, len(sys.slider_names)
    st = _State(n, na, ns)
    st.TH[0, :] = sys.q0[:na]
    st.E[0, :na] = np.exp(1j * sys.q0[:na])
    st.S[0, :ns] = sys.q0[na:]
    return st


# ------------------------------------------------------------------ solve


def solve(
    system: LoopSystem,
    times: np.ndarray | None = None,
    *,
    tol: float | None = None,
    max_iter: int | None = None,
    rtol: float | None = None,
    memory_budget: Any = None,
) -> Result:
    """P/V/A of a compiled system at ``times`` [s] (default: the file's). Raises MotionError with ``partial``.

    ``tol``: Newton step tolerance (relative); ``max_iter``; ``rtol``: accuracy asked of every output
    (samples whose error bound cond²·ε exceeds it are refused). The file's [solver] values win for tol
    and max_iter; an ``rtol`` given here wins over the file's. ``memory_budget`` (bytes or "2G"; see
    vloop.budget): a run whose results would not fit is refused before it starts (MemoryBudgetError).
    """
    run, times = _prepare(system, times, tol, max_iter, rtol, memory_budget)
    budget.check(run.sys, len(times), False, CHUNK_ROWS, run.memory_budget)
    with np.errstate(all="ignore"):  # overflow and singular rows are found and reported below
        return _solve(run, times)


def solve_iter(
    system: LoopSystem,
    times: np.ndarray | None = None,
    *,
    chunk: int | None = None,
    tol: float | None = None,
    max_iter: int | None = None,
    rtol: float | None = None,
    memory_budget: Any = None,
) -> Iterator[Result]:
    """As :func:`solve`, but yield the run in chunks of about ``chunk`` samples: memory is bounded by a chunk
    whatever the run's length. A failure raises MotionError whose ``partial`` holds the failing chunk's rows."""
    run, times = _prepare(system, times, tol, max_iter, rtol, memory_budget)
    budget.check(run.sys, len(times), True, CHUNK_ROWS, run.memory_budget)
    with np.errstate(all="ignore"):
        yield from solve_chunks(run, times, chunk or CHUNK)


def _prepare(
    system: LoopSystem, times: np.ndarray | None, tol: Any, max_iter: Any, rtol: Any, memory_budget: Any
) -> tuple[_Run, np.ndarray]:
    """The run context and checked times of a solve."""
    mech = system.mechanism
    tol = float(mech.options.get("tol", DEFAULT_TOL if tol is None else tol))
    max_iter = int(mech.options.get("max_iter", DEFAULT_MAX_ITER if max_iter is None else max_iter))
    rtol = float(rtol if rtol is not None else mech.options.get("rtol", DEFAULT_RTOL))
    times = np.asarray(mech.times if times is None else times, float)
    if times.ndim != 1 or len(times) == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise MotionError("times must be a non-empty, finite, strictly increasing 1-D array", entry="time")
    run = _Run(system, _Inputs(mech), mech.scale, tol, max_iter, rtol)
    run.memory_budget = memory_budget
    return run, times


@dataclass(frozen=True)
class _Grid:
    """The internal sample grid: the lead-in from t = 0, the requested times, and rows inserted
    between requested samples so the inputs move at most MAX_INPUT_STEP per row (turns of the
    other links are then counted right, change points found, Newton continued from near)."""

    t: np.ndarray
    out: np.ndarray  # internal row of each requested sample (increasing)
    skip: int = 0  # leading requested samples already given by the chunk before (its last one)
    offset: int = 0  # index in the whole run of the requested sample at out[0]
    total: int = 0  # requested samples in the whole run

    @property
    def first(self) -> int:
        return int(self.out[0])

    def requested_before(self, row: int) -> int:
        """How many requested samples come before internal row ``row``."""
        return int(np.searchsorted(self.out, row))


MAX_INPUT_STEP = math.radians(10)  # per internal row: of a crank (or 1/36 of the size for a slider input)
MAX_INSERTED = 10_000_000


def _grid(run: _Run, lead: np.ndarray, times: np.ndarray) -> _Grid:
    """Lead-in + requested times, with rows inserted where an input moves more than MAX_INPUT_STEP."""
    mech = run.sys.mechanism
    n = len(times)
    steps = np.ones(max(n - 1, 0), np.int64)
    if mech.drivers and n > 1:
        X, XD, _ = run.inputs(times)
        units = np.array([1.0 if d.kind == "crank" else mech.scale / (2 * math.pi) for d in mech.drivers])
        h = np.diff(times)[:, None]
        travel = np.maximum(np.abs(np.diff(X, axis=0)), 0.5 * h * (np.abs(XD[1:]) + np.abs(XD[:-1]))) / units
        need = np.ceil(travel.max(axis=1) / MAX_INPUT_STEP)
        need = np.where(np.isfinite(need) & (need <= MAX_INSERTED), need, 1.0)  # absurd inputs: refused later
        if need.sum() - len(need) > MAX_INSERTED:
            raise MotionError(
                f"{mech.name}: the inputs travel {float(travel.sum(axis=0).max()):.4g} rad (or sizes) over the run; "
                f"counting the other links' turns needs at most {math.degrees(MAX_INPUT_STEP):g}° per internal "
                f"sample, which would take {int(need.sum()):,} samples (more than {MAX_INSERTED:,}): shorten the run",
                entry="time",
            )
        steps = np.maximum(need, 1).astype(np.int64)
    starts = np.concatenate([[0], np.cumsum(steps)])  # internal index of each requested sample
    k = np.arange(starts[-1])
    seg = np.repeat(np.arange(len(steps)), steps)
    frac = (k - starts[seg]) / steps[seg]
    inner = np.append(times[seg] + frac * (times[seg + 1] - times[seg]), times[-1]) if n > 1 else times.copy()
    inner[starts] = times  # the requested times exactly
    return _Grid(np.concatenate([lead, inner]), len(lead) + starts)


CHUNK = 16_384  # requested samples solved together: the state stays in cache, memory stays bounded
CHUNK_ROWS = 2 * CHUNK  # internal rows allowed in one chunk (inserted rows included) before it is split


def _solve(run: _Run, times: np.ndarray, chunk: int | None = None) -> Result:
    """The whole run as one Result: the chunks joined (on failure, the MotionError's partial joins them)."""
    parts: list[Result] = []
    try:
        for part in solve_chunks(run, times, chunk or CHUNK):
            parts.append(part)
    except MotionError as exc:
        if exc.partial is not None and parts:
            exc.partial = join([*parts, exc.partial])
        raise
    return join(parts)


def join(parts: list[Result]) -> Result:
    """Results of consecutive chunks as one (meta from the last: it has every change point)."""
    if len(parts) == 1:
        return parts[0]
    first, last = parts[0], parts[-1]
    return Result(
        first.mechanism,
        first.engine,
        np.concatenate([p.t for p in parts]),
        {k: np.concatenate([p.columns[k] for p in parts]) for k in first.columns},
        {k: np.concatenate([p.health[k] for p in parts]) for k in first.health},
        dict(last.meta),
    )


def solve_chunks(run: _Run, times: np.ndarray, chunk: int = CHUNK) -> Iterator[Result]:
    """Solve ``times`` in chunks of about ``chunk`` requested samples, yielding each chunk's Result.

    State carried across a chunk border: two internal rows (positions, unwrapped angles, so turn counts
    continue; change-point detection sees the border row with both neighbours), the change points found
    so far and each Newton block's branch sign (in ``run``). A chunk's last rows that a change point just
    past its end could still reach (ill-conditioned rows within its stencil: see _cut) are not given out
    but solved again by the next chunk, as in a run solved in one piece; a failure there is decided by a
    longer chunk. A failure raises MotionError whose ``partial``
    holds this chunk's rows before it (``sample`` counts from the start of the run)."""
    sys = run.sys
    lead, run.inputs, turns = _lead_in(sys, run, float(times[0]))
    run.t_start = float(times[0])
    carry: tuple[np.ndarray, _State] | None = None
    i0, n_total, size, at_least = 0, len(times), chunk, 1
    while i0 < n_total:
        i1 = min(i0 + size, n_total)
        grid = _chunk_grid(run, lead, carry, times, i0, i1, n_total, at_least)
        run.tail = grid.offset + len(grid.out) == n_total
        st = _initial_state(sys, len(grid.t))
        if carry is not None:
            for name in ("E", "TH", "S"):
                getattr(st, name)[:2] = getattr(carry[1], name)
        events = {i: list(evs) for i, evs in run.events.items()}
        try:
            res = _solve_grid(run, grid, st, turns if carry is None else None)
            failure = None
        except MotionError as exc:
            res, failure = exc.partial, exc
        reach = _border_reach(run, grid)
        cut = len(grid.out) - 1 if run.tail else _cut(run, grid, res, reach)
        if failure is not None and (run.tail or failure.time is None or failure.time <= reach):
            raise failure
        if not run.tail and (cut <= grid.skip or grid.out[cut] < 1):  # nothing safe from the chunk's end yet
            at_least = len(grid.out) - grid.skip + 1  # one more requested sample than this chunk had
            run.events, size = events, max(2 * size, at_least)
            continue
        t_cut = float(grid.t[grid.out[cut]])
        run.events = {i: [ev for ev in evs if ev.time <= t_cut] for i, evs in run.events.items()}
        yield res.head(cut + 1 - grid.skip)
        if run.tail:
            return
        row = int(grid.out[cut])
        carry = (grid.t[row - 1 : row + 1], _rows(st, slice(row - 1, row + 1)))
        i0, size, at_least = grid.offset + cut + 1, chunk, 1


def _chunk_grid(
    run: _Run, lead: np.ndarray, carry: tuple | None, times: np.ndarray, i0: int, i1: int, n_total: int, at_least: int
) -> _Grid:
    """The internal grid of requested samples i0..i1-1 (after the carried rows), halved until it fits CHUNK_ROWS
    or holds ``at_least`` requested samples."""
    while True:
        if carry is None:
            grid = _grid(run, lead, times[i0:i1])
        else:
            grid = _grid(run, carry[0][:1], np.concatenate([carry[0][1:], times[i0:i1]]))
        if len(grid.t) <= CHUNK_ROWS or i1 - i0 <= at_least:
            break
        i1 = max(i0 + (i1 - i0) // 2, i0 + at_least)
    return dataclasses.replace(grid, skip=0 if carry is None else 1, offset=i0 - (carry is not None), total=n_total)


def _border_reach(run: _Run, grid: _Grid) -> float:
    """The earliest time a change point found after this chunk's end could still reach back to (its stencil,
    4·η with η the time the inputs take to move STENCIL_INPUT)."""
    t_end = float(grid.t[-1])
    if not run.sys.mechanism.drivers:
        return t_end
    return t_end - 4.0 * _eta(run, t_end, math.inf, STENCIL_INPUT)


def _cut(run: _Run, grid: _Grid, res: Result, reach: float) -> int:
    """The last requested sample of a chunk (index into grid.out) that nothing after the chunk can change:
    before the first sample that is ill-conditioned (next to a singular row: a change point found by
    the next chunk would take its rates across) and within the reach of the chunk's end."""
    weak = _error_bound(res.health["cond"]) > ILL_FRACTION * run.rtol
    unsafe = np.nonzero(weak & (res.t > reach))[0]
    return grid.skip + len(res) - 1 if not len(unsafe) else grid.skip + int(unsafe[0]) - 1


def _rows(st: _State, k: slice) -> _State:
    """A copy of rows ``k`` of a state's positions (rates are recomputed where carried)."""
    out = _State.__new__(_State)
    for name in ("E", "TH", "S"):
        setattr(out, name, getattr(st, name)[k].copy())
    return out


def _solve_grid(run: _Run, grid: _Grid, st: _State, turns: np.ndarray | None) -> Result:
    """Solve one chunk's grid (row 0 assembled; rows 0–1 carried from the chunk before, if any)."""
    sys = run.sys
    tg, n, first = grid.t, len(grid.t), grid.first
    X, XD, XDD = run.inputs(tg)
    _impose_drivers(sys, st, X, XD, XDD)
    early = _check_inputs(sys, X, XD, XDD, first, run.rtol)
    solved = _run_blocks(run, st, tg, early.sample if early else n)
    failure = solved.failure if early is None or (solved.failure and solved.failure.sample < early.sample) else early
    n_ok = min(solved.n_ok, failure.sample if failure else n)
    free = [v for v in range(sys.n_angles) if v not in sys.drivers and turns[v]] if turns is not None else []
    if free:  # whole turns skipped by the lead-in: θ = φ + 2π·n with n counted in whole turns, as from t = 0
        phi = np.angle(st.E[first:, free])
        st.TH[first:, free] = phi + TWO_PI * np.round((st.TH[first:, free] + turns[free] - phi) / TWO_PI)
    limit = None
    if failure is not None and failure.sample > first and failure.loop is not None and failure is not early:
        limit = _locate_failure(run, st, tg, failure.sample, X)
    result = _result(run, st, grid, n_ok, solved)
    bad = _first_non_finite(result)
    if bad is not None:
        row, column = bad
        failure = _Failure(
            int(grid.out[row + grid.skip]), None, f"{column} is not finite (an overflow: the inputs are too large)"
        )
        result, limit = result.head(row), None
    if failure is not None:
        raise _motion_error(sys, failure, grid, X, result, limit)
    return result


def _check_inputs(
    sys: LoopSystem, X: np.ndarray, XD: np.ndarray, XDD: np.ndarray, off: int, rtol: float
) -> _Failure | None:
    """The first sample whose driver inputs are not finite, or whose crank angle is too large to
    resolve to ``rtol`` (its floating-point spacing exceeds rtol radians)."""
    mech = sys.mechanism
    bad = ~np.isfinite(X) | ~np.isfinite(XD) | ~np.isfinite(XDD)
    for j, d in enumerate(mech.drivers):
        if d.kind == "crank":
            bad[off:, j] |= np.spacing(np.abs(X[off:, j])) > rtol
    rows = np.nonzero(bad.any(axis=1))[0]
    if not len(rows):
        return None
    r = int(rows[0])
    j = int(np.argmax(bad[r]))
    d = mech.drivers[j]
    vals = (X[r, j], XD[r, j], XDD[r, j])
    if np.all(np.isfinite(vals)):
        why = f"the input {d.symbol} = {X[r, j]:.6g} rad is too large to resolve to rtol = {rtol:g} rad"
    else:
        which = ("value", "rate", "acceleration")[int(np.argmin(np.isfinite(vals)))]
        why = f"the input's {which} is not finite (an overflow: the driver's numbers are too large)"
    return _Failure(r, None, why)


def _first_non_finite(result: Result) -> tuple[int, str] | None:
    """(row, column) of the first non-finite output value, if any."""
    first = None
    for name, col in result.columns.items():
        bad = ~np.isfinite(col)
        if bad.any():
            r = int(np.argmax(bad))
            if first is None or r < first[0]:
                first = (r, name)
    return first


def _result(run: _Run, st: _State, grid: _Grid, n_ok: int, solved: _Solved) -> Result:
    sys = run.sys
    mech = sys.mechanism
    rows = grid.out[grid.skip :][grid.out[grid.skip :] < n_ok]  # the requested samples solved
    points, loops = _system_sums(sys)
    k = _as_slice(rows)
    P, V, A = points.pos(st, k), points.vel(st, k), points.acc(st, k)
    cols: dict[str, np.ndarray] = {}
    for name, a, offset in sys.link_outputs:
        if a >= 0:
            cols[f"{name}.theta"] = st.TH[rows, a] + offset
            cols[f"{name}.omega"] = st.W[rows, a]
            cols[f"{name}.alpha"] = st.AL[rows, a]
        else:
            cols[f"{name}.theta"] = np.full(len(rows), offset % TWO_PI)
            cols[f"{name}.omega"] = np.zeros(len(rows))
            cols[f"{name}.alpha"] = np.zeros(len(rows))
    for i, name in enumerate(sys.point_names):
        cols[f"{name}.x"], cols[f"{name}.y"] = P[:, i].real, P[:, i].imag
        cols[f"{name}.vx"], cols[f"{name}.vy"] = V[:, i].real, V[:, i].imag
        cols[f"{name}.ax"], cols[f"{name}.ay"] = A[:, i].real, A[:, i].imag
    for i, name in enumerate(sys.slider_names):
        cols[f"{name}.s"], cols[f"{name}.v"], cols[f"{name}.a"] = st.S[rows, i], st.SD[rows, i], st.SDD[rows, i]
    t = grid.t[rows]
    seen = grid.t[grid.out[: grid.skip + len(rows)]]  # requested times solved in this chunk and the one before
    span = np.array([run.t_start, seen[-1]]) if len(seen) else np.zeros(0)
    return Result(
        mech.name,
        "vloop",
        t,
        cols,
        _health(run, st, grid.t[grid.out[: grid.skip + len(rows)]], rows, solved, loops),
        {
            "blocks": [b.kind for b in sys.blocks],
            "assembly": sys.assembly,
            **_events_meta(run, span),
            **_redundancy(sys),
        },
    )


def _as_slice(rows: np.ndarray) -> slice | np.ndarray:
    """Consecutive rows as a slice (state arrays are then read as views, not copied)."""
    if len(rows) and int(rows[-1]) - int(rows[0]) + 1 == len(rows):
        return slice(int(rows[0]), int(rows[-1]) + 1)
    return rows


def _health(run: _Run, st: _State, t: np.ndarray, rows: np.ndarray, solved: _Solved, loops: _Sum) -> dict:
    """Per requested sample (``rows``): closure residual, worst block condition number, branch signature,
    flags. ``t``: the times of the rows, after the last sample of the chunk before if there is one."""
    sys = run.sys
    residual = (
        np.max(np.abs(loops.pos(st, _as_slice(rows))), axis=1) / run.scale if len(sys.loops) else np.zeros(len(rows))
    )
    cond = np.max(np.stack([c[rows] for c in solved.conds]), axis=0) if solved.conds else np.ones(len(rows))
    branch = np.zeros(len(rows), np.int64)
    for bit, sgn in enumerate(solved.signs):
        branch |= (sgn[rows] > 0).astype(np.int64) << bit
    at_change = solved.at_change[rows] if len(solved.at_change) else np.zeros(len(rows), bool)
    change = at_change.copy()
    skip = len(t) - len(rows)  # t starts with the chunk before's last sample, if any
    for evs in run.events.values():
        for ev in evs:
            j = int(np.searchsorted(t, ev.time))
            if 0 < j < len(t) and j >= skip:
                change[j - skip] = True
    return {
        "residual": residual,
        "cond": cond,
        "branch": branch,
        "ill_conditioned": ((_error_bound(cond) > ILL_FRACTION * run.rtol) & ~at_change).astype(np.int8),
        "change_point": change.astype(np.int8),
    }


def _redundancy(sys: LoopSystem) -> dict[str, str]:
    """For a redundant linkage, the line that says so (its reactions are indeterminate)."""
    info = sys.assembly.get("redundancy")
    return {"redundancy": redundancy_text(info, sys)} if info else {}


def _events_meta(run: _Run, t: np.ndarray) -> dict[str, Any]:
    """The change points passed within the requested times (loop, time, inputs, which continuation)."""
    sys = run.sys
    out = []
    for i, evs in sorted(run.events.items()):
        loop = sys.loops[_plans(sys)[i].block.loops[0]]
        for ev in evs:
            if not len(t) or not t[0] <= ev.time <= t[-1]:
                continue
            x = run.inputs(np.array([ev.time]))[0][0]
            out.append(
                {
                    "loop": loop.index + 1,
                    "label": loop.label,
                    "time": ev.time,
                    "inputs": {d.symbol: float(v) for d, v in zip(sys.mechanism.drivers, x, strict=True)},
                    "continued": "smooth" if ev.smooth else "other",
                }
            )
    return {"change_points": sorted(out, key=lambda e: e["time"]), "rtol": run.rtol}


def _motion_error(
    sys: LoopSystem,
    f: _Failure,
    grid: _Grid,
    X: np.ndarray,
    partial: Result,
    limit: tuple[float, np.ndarray] | None = None,
) -> MotionError:
    """The MotionError for failure ``f`` at internal row f.sample; ``sample`` is the first requested one lost."""
    mech = sys.mechanism
    t = float(grid.t[f.sample])
    n_req = grid.total or len(grid.out)
    j = grid.requested_before(f.sample)
    jg = j + grid.offset  # in the whole run
    drv = ", ".join(
        f"{d.symbol} = {X[f.sample, i]:.6g} {'rad' if d.kind == 'crank' else mech.units}"
        for i, d in enumerate(mech.drivers)
    )
    if f.sample < grid.first:
        where = "before the first requested time (on the way from the t = 0 assembly)"
    elif j < len(grid.out) and grid.out[j] == f.sample:
        where = f"at t = {t:.6g} s (sample {jg} of {n_req})"
    else:
        where = f"at t = {t:.6g} s (between samples {jg - 1} and {jg} of {n_req})"
    kept = f"{jg} earlier sample{'s' if jg != 1 else ''} kept" if jg else "no sample kept"
    lim = ""
    if limit is not None:
        vals = ", ".join(
            f"{d.symbol} = {limit[1][i]:.10g} {'rad' if d.kind == 'crank' else mech.units}"
            for i, d in enumerate(mech.drivers)
        )
        lim = f" (last assembled at t = {limit[0]:.10g} s, {vals})"
    at = f": loop {f.loop + 1} ({sys.loops[f.loop].label})" if f.loop is not None else ""
    err = MotionError(
        f"{mech.name}: cannot assemble {where}, {drv}{at}: {f.why}{lim}; {kept}",
        entry=f"loop {f.loop + 1}" if f.loop is not None else "drivers",
        time=t if f.sample >= grid.first else None,
        sample=jg if f.sample >= grid.first else None,
        driver_value=X[f.sample].tolist() if len(X) else None,
        partial=partial,
    )
    err.limit_time = limit[0] if limit is not None else None
    err.limit_value = limit[1].tolist() if limit is not None else None
    return err
