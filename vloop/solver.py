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

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .drivers import evaluate_all
from .errors import MotionError
from .loops import Block, LoopSystem, compile_system
from .mechanism import Mechanism
from .result import Result

TOGGLE_COND = 1e12  # a block Jacobian this ill-conditioned is a toggle (singular)
DEFAULT_TOL = 1e-12  # Newton stops when the step is below tol·(1 + |x|)
DEFAULT_MAX_ITER = 30
MAX_LEAD_IN = 100_000


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
    def __init__(self, sample: int, loop: int, why: str) -> None:
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


def _closed_form(p: _Plan, st: _State, k: slice, na: int) -> np.ndarray:
    """Closed-form positions of a one-loop dyad for rows ``k``; returns the mask of assemblable rows."""
    b = p.block
    X = -p.known_sum.pos(st, k)[:, 0]
    sig = b.sigma
    if b.kind == "RRR":
        # W1·E1 + W2·E2 = X: |W1|, |W2|, |X| form a triangle (law of cosines)
        W1, W2 = _w(p, st, k, p.unk_ang[0]), _w(p, st, k, p.unk_ang[1])
        A2, B2 = np.abs(W1) ** 2, np.abs(W2) ** 2
        D2 = X.real**2 + X.imag**2
        k1 = 0.5 * (A2 + D2 - B2)
        h2 = A2 * D2 - k1 * k1
        ok = (h2 >= 0) & (D2 > 0)
        P = X * (k1 + 1j * sig * np.sqrt(np.where(ok, h2, 0.0))) / np.where(D2 > 0, D2, 1.0)
        _set_angle(st, k, p.unk_ang[0], P / W1)
        _set_angle(st, k, p.unk_ang[1], (X - P) / W2)
        return ok
    if b.kind == "RRP":
        # W1·E1 + s·U = X with U a known unit direction: project on U's normal
        i = p.unk_sl[0]
        Uc = np.conj(_u(p, st, k, i))
        W1 = _w(p, st, k, p.unk_ang[0])
        XU, WU = X * Uc, W1 * Uc
        y = XU.imag
        h = np.abs(W1) ** 2 - y * y
        ok = h >= 0
        c = sig * np.sqrt(np.where(ok, h, 0.0))
        _set_angle(st, k, p.unk_ang[0], (c + 1j * y) / WU)
        st.S[k, i] = XU.real - c
        return ok
    if b.kind == "RPR":
        # (W + s·c)·E = X with c a unit direction fixed to the same link: |W + s·c| = |X|
        i, a = p.unk_sl[0], p.unk_ang[0]
        cdir = p.u_dir[i][1]
        W = _w(p, st, k, a, skip=i)
        bb = (W * np.conj(cdir)).real
        disc = bb * bb - np.abs(W) ** 2 + (X.real**2 + X.imag**2)
        s = -bb + sig * np.sqrt(np.where(disc >= 0, disc, 0.0))
        den = W + s * cdir
        ok = (disc >= 0) & (np.abs(den) > 0)
        st.S[k, i] = s
        _set_angle(st, k, a, X / np.where(ok, den, 1.0))
        return ok
    # PP: s1·U1 + s2·U2 = X
    U1, U2 = _u(p, st, k, p.unk_sl[0]), _u(p, st, k, p.unk_sl[1])
    det = cross(U1, U2)
    ok = np.abs(det) > 1e-12
    dd = np.where(ok, det, 1.0)
    st.S[k, p.unk_sl[0]] = cross(X, U2) / dd
    st.S[k, p.unk_sl[1]] = cross(U1, X) / dd
    return ok


def _set_angle(st: _State, k: slice, a: int, E: np.ndarray) -> None:
    E = E / np.abs(E)
    st.E[k, a] = E
    # unwrap by accumulating the increments from the t = 0 assembly (row 0)
    Ek = st.E[k, a]
    inc = np.angle(Ek[1:] * np.conj(Ek[:-1]))
    st.TH[k, a] = st.TH[0, a] + np.concatenate(([np.angle(Ek[0] * np.exp(-1j * st.TH[0, a]))], np.cumsum(inc)))


def _newton_block(
    p: _Plan, st: _State, n: int, tg: np.ndarray, na: int, scale: float, tol: float, max_iter: int
) -> None:
    """Per-sample Newton with analytic Jacobian and a Taylor predictor; raises _Failure."""
    b = p.block
    nu = len(b.unknowns)
    is_ang = np.array([v < na for v in b.unknowns])
    col = [v if v < na else v - na for v in b.unknowns]
    x = np.array([st.TH[0, c] if a else st.S[0, c] for a, c in zip(is_ang, col, strict=True)])
    xd = np.zeros(nu)
    xdd = np.zeros(nu)
    sign0 = None
    m = p.C.shape[0]
    colscale = np.where(is_ang, 1.0 / scale, 1.0)  # unit-free condition number, as in _block_health
    cond_first = cond_last = 1.0

    def put(k: int, x: np.ndarray) -> None:
        for i in range(nu):
            if is_ang[i]:
                st.TH[k, col[i]] = x[i]
                st.E[k, col[i]] = complex(math.cos(x[i]), math.sin(x[i]))
            else:
                st.S[k, col[i]] = x[i]

    for k in range(n):
        if k > 0:
            h = tg[k] - tg[k - 1]
            x = x + xd * h + 0.5 * xdd * h * h
        row = slice(k, k + 1)
        converged = False
        for _ in range(max_iter):
            put(k, x)
            z, e = st.z(row, p.ang, p.sl, p.r, p.cd)
            F = p.C @ z[0]
            J = _jacobian(p, z, e)[0]
            try:
                dx = np.linalg.solve(J, -np.concatenate([F.real, F.imag]))
            except np.linalg.LinAlgError:
                raise _Failure(k, b.loops[0], "the loop Jacobian is singular (a toggle)") from None
            x = x + dx
            if np.max(np.abs(dx)) <= tol * (1.0 + np.max(np.abs(x))):
                converged = True
                break
        put(k, x)
        z, e = st.z(row, p.ang, p.sl, p.r, p.cd)
        res = np.max(np.abs(p.C @ z[0])) / scale
        if not converged or not np.isfinite(res) or res > 1e-9:
            worst = b.loops[int(np.argmax(np.abs(p.C @ z[0])))] if np.isfinite(res) else b.loops[0]
            why = f"Newton did not converge (closure {res:.2g} of the mechanism size)"
            if k > 0 and cond_last > 10 * cond_first:
                why += (
                    f"; the Jacobian's condition number grew from {cond_first:.3g} to {cond_last:.3g}: "
                    "a limit position or toggle is reached"
                )
            raise _Failure(k, worst, why)
        J = _jacobian(p, z, e)
        cond_last = float(np.linalg.cond(J[0] * colscale))
        if k == 0:
            cond_first = cond_last
        sgn = np.sign(np.linalg.det(J[0]))
        if sign0 is None:
            sign0 = sgn
        elif sgn != sign0:
            raise _Failure(
                k, b.loops[0], "the assembly branch flipped (the Jacobian changed sign): a toggle was crossed"
            )
        if m and k + 1 < n:
            xd = _rates(p, st, row, J, "v")[0]
            _store(p, st, row, xd[None, :], "v", na)
            xdd = _rates(p, st, row, J, "a")[0]
            _store(p, st, row, np.zeros((1, nu)), "v", na)


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
    return np.linalg.solve(J, rhs[..., None])[..., 0]


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
    return np.linalg.cond(Js), np.sign(np.linalg.det(J))


# ------------------------------------------------------------------ driver


def _run_blocks(
    sys: LoopSystem, st: _State, tg: np.ndarray, n: int, scale: float, tol: float, max_iter: int
) -> tuple[int, _Failure | None, list[np.ndarray], list[np.ndarray]]:
    """Solve every block in order on rows 0..n-1 (row 0 must be an assembled configuration).

    Returns the number of rows solved, the first failure (or None), and each
    block's condition numbers and Jacobian determinant signs.
    """
    na = sys.n_angles
    n_ok = n
    failure: _Failure | None = None
    conds: list[np.ndarray] = []
    signs: list[np.ndarray] = []
    for p in _plans(sys):
        k = slice(0, n_ok)
        if p.block.kind == "newton":
            try:
                _newton_block(p, st, n_ok, tg, na, scale, tol, max_iter)
            except _Failure as f:
                failure, n_ok = f, f.sample
        else:
            ok = _closed_form(p, st, k, na)
            if not ok.all():
                bad = int(np.argmin(ok))
                failure = _Failure(bad, p.block.loops[0], "the loop cannot close: the input is past a limit position")
                n_ok = bad
        k = slice(0, n_ok)
        if n_ok == 0:
            break
        cols = _columns(p, st, k) if len(p.block.unknowns) == 2 else None  # shared by health and rates
        cond, sgn = _block_health(p, st, k, scale, cols)
        bad = np.nonzero((cond > TOGGLE_COND) | (sgn != sgn[0]))[0]
        if len(bad):
            failure = _Failure(int(bad[0]), p.block.loops[0], "the mechanism reaches a toggle (singular Jacobian)")
            n_ok = int(bad[0])
            k = slice(0, n_ok)
            cond, sgn = cond[:n_ok], sgn[:n_ok]
            cols = None if cols is None else (cols[0][:n_ok], cols[1][:n_ok])
        conds.append(cond)
        signs.append(sgn)
        if n_ok == 0:
            break
        J = None if cols is not None else _jacobian(p, *st.z(k, p.ang, p.sl, p.r, p.cd))
        _store(p, st, k, _rates(p, st, k, J, "v", cols), "v", na)
        _store(p, st, k, _rates(p, st, k, J, "a", cols), "a", na)
    return n_ok, failure, conds, signs


LIMIT_RTOL = 1e-12  # the limit is located to this fraction of the drivers' range over the run


def _locate_failure(
    sys: LoopSystem, st: _State, tg: np.ndarray, k: int, X: np.ndarray, scale: float, tol: float, max_iter: int
) -> tuple[float, np.ndarray]:
    """Bisect between the last solved sample k−1 and the failing sample k for the last assemblable
    time (a limit position or toggle). Returns (time, driver values there)."""
    mech = sys.mechanism
    na, ns = sys.n_angles, len(sys.slider_names)
    span = np.ptp(X, axis=0) if X.size else np.zeros(0)
    span = np.where(span > 0, span, 1.0)
    base = _State(1, na, ns)
    for name in ("E", "TH", "S"):
        getattr(base, name)[0] = getattr(st, name)[k - 1]
    lo, hi = float(tg[k - 1]), float(tg[k])
    x_lo = X[k - 1] if X.size else np.zeros(0)
    x_hi = X[k] if X.size else np.zeros(0)
    for _ in range(200):
        if X.size and np.all(np.abs(x_hi - x_lo) <= LIMIT_RTOL * span):
            break
        if hi - lo <= 4 * np.spacing(max(abs(hi), 1.0)):
            break
        mid = 0.5 * (lo + hi)
        trial = _State(2, na, ns)
        for name in ("E", "TH", "S"):
            getattr(trial, name)[0] = getattr(base, name)[0]
        grid = np.array([lo, mid])
        xm = np.zeros(0)
        if mech.drivers:
            Xd, XD, XDD = evaluate_all(mech, grid)
            _impose_drivers(sys, trial, Xd, XD, XDD)
            xm = Xd[1]
        n_ok, *_ = _run_blocks(sys, trial, grid, 2, scale, tol, max_iter)
        if n_ok == 2:
            lo, x_lo = mid, xm
            for name in ("E", "TH", "S"):
                getattr(base, name)[0] = getattr(trial, name)[1]
        else:
            hi, x_hi = mid, xm
    return lo, x_lo


def assemble_blocks(sys: LoopSystem, blocks: tuple, q0: np.ndarray) -> np.ndarray:
    """The t = 0 configuration the closed-form blocks give with their (possibly flipped) branches."""
    import dataclasses

    trial_sys = dataclasses.replace(sys, blocks=blocks, q0=q0, cache={})
    na, ns = sys.n_angles, len(sys.slider_names)
    st = _State(1, na, ns)
    st.TH[0] = q0[:na]
    st.E[0, :na] = np.exp(1j * q0[:na])
    st.S[0, :ns] = q0[na:]
    mech = sys.mechanism
    if mech.drivers:
        _impose_drivers(sys, st, *evaluate_all(mech, np.zeros(1)))
    n_ok, failure, *_ = _run_blocks(trial_sys, st, np.zeros(1), 1, mech.scale, DEFAULT_TOL, DEFAULT_MAX_ITER)
    if n_ok < 1:
        from .errors import MechanismError

        raise MechanismError(
            f"{mech.source}: [solver] branches: the mechanism cannot be assembled on the requested branch at t = 0 "
            f"({failure.why if failure else 'no solution'})",
            entry="solver",
        )
    th = st.TH[0].copy()
    free = np.array([v not in sys.drivers for v in range(na)], bool)
    th[free] %= 2 * math.pi  # the file's convention at t = 0: θ in [0, 2π)
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


def solve(mechanism: Mechanism | LoopSystem, times: np.ndarray | None = None, **options: Any) -> Result:
    """Solve P/V/A at ``times`` (default: the mechanism's). Raises MotionError with ``partial``."""
    method = options.pop("method", None)
    tol = float(options.pop("tol", DEFAULT_TOL))
    max_iter = int(options.pop("max_iter", DEFAULT_MAX_ITER))
    if options:
        raise TypeError(f"unknown solver option(s): {', '.join(options)}")
    if isinstance(mechanism, LoopSystem):
        sys = mechanism
        if method is not None and method != sys.method:
            sys = compile_system(sys.mechanism, method)
    else:
        sys = compile_system(mechanism, method)
    mech = sys.mechanism
    tol = float(mech.options.get("tol", tol))
    max_iter = int(mech.options.get("max_iter", max_iter))
    times = np.asarray(mech.times if times is None else times, float)
    if times.ndim != 1 or len(times) == 0 or not np.all(np.isfinite(times)) or np.any(np.diff(times) <= 0):
        raise MotionError("times must be a non-empty, finite, strictly increasing 1-D array", entry="time")

    # internal grid: start at t = 0, the instant of the assembly, so branches and angles carry over
    if times[0] == 0.0:
        lead = np.zeros(0)
    else:
        h = (times[1] - times[0]) if len(times) > 1 else abs(times[0]) / 16
        n_lead = int(min(MAX_LEAD_IN, max(1, math.ceil(abs(times[0]) / h))))
        lead = np.linspace(0.0, times[0], n_lead + 1)[:-1]
    tg = np.concatenate([lead, times])
    off = len(lead)
    n = len(tg)
    na, ns = sys.n_angles, len(sys.slider_names)
    st = _State(n, na, ns)
    st.TH[0, :] = sys.q0[:na]
    st.E[0, :na] = np.exp(1j * sys.q0[:na])
    st.S[0, :ns] = sys.q0[na:]
    scale = mech.scale

    if mech.drivers:
        X, XD, XDD = evaluate_all(mech, tg)
        _impose_drivers(sys, st, X, XD, XDD)
    else:
        X = np.zeros((n, 0))

    n_ok, failure, conds, signs = _run_blocks(sys, st, tg, n, scale, tol, max_iter)
    limit = None
    if failure is not None and failure.sample > 0:
        limit = _locate_failure(sys, st, tg, failure.sample, X, scale, tol, max_iter)
    result = _result(sys, st, tg, n_ok, off, conds, signs)
    if failure is not None:
        raise _motion_error(sys, failure, tg, X, off, result, limit)
    return result


def _result(sys: LoopSystem, st: _State, tg: np.ndarray, n_ok: int, off: int, conds: list, signs: list) -> Result:
    mech = sys.mechanism
    k = slice(0, n_ok)
    points, loops = _system_sums(sys)
    P, V, A = points.pos(st, k), points.vel(st, k), points.acc(st, k)
    cols: dict[str, np.ndarray] = {}
    for name, a, offset in sys.link_outputs:
        if a >= 0:
            cols[f"{name}.theta"] = st.TH[k, a] + offset
            cols[f"{name}.omega"] = st.W[k, a]
            cols[f"{name}.alpha"] = st.AL[k, a]
        else:
            cols[f"{name}.theta"] = np.full(n_ok, offset % (2 * math.pi))
            cols[f"{name}.omega"] = np.zeros(n_ok)
            cols[f"{name}.alpha"] = np.zeros(n_ok)
    for i, name in enumerate(sys.point_names):
        cols[f"{name}.x"], cols[f"{name}.y"] = P[:, i].real, P[:, i].imag
        cols[f"{name}.vx"], cols[f"{name}.vy"] = V[:, i].real, V[:, i].imag
        cols[f"{name}.ax"], cols[f"{name}.ay"] = A[:, i].real, A[:, i].imag
    for i, name in enumerate(sys.slider_names):
        cols[f"{name}.s"], cols[f"{name}.v"], cols[f"{name}.a"] = st.S[k, i], st.SD[k, i], st.SDD[k, i]
    residual = np.max(np.abs(loops.pos(st, k)), axis=1) / mech.scale if len(sys.loops) else np.zeros(n_ok)
    cond = np.max(np.stack([c[:n_ok] for c in conds]), axis=0) if conds else np.ones(n_ok)
    branch = np.zeros(n_ok, np.int64)
    for bit, s in enumerate(signs):
        branch |= (s[:n_ok] > 0).astype(np.int64) << bit
    sl = slice(off, None)
    return Result(
        mech.name,
        "vloop",
        tg[off:n_ok],
        {c: v[sl] for c, v in cols.items()},
        {"residual": residual[sl], "cond": cond[sl], "branch": branch[sl]},
        {"blocks": [b.kind for b in sys.blocks], "assembly": sys.assembly},
    )


def _motion_error(
    sys: LoopSystem,
    f: _Failure,
    tg: np.ndarray,
    X: np.ndarray,
    off: int,
    partial: Result,
    limit: tuple[float, np.ndarray] | None = None,
) -> MotionError:
    mech = sys.mechanism
    lp = sys.loops[f.loop]
    t = float(tg[f.sample])
    drv = ", ".join(
        f"{d.symbol} = {X[f.sample, j]:.6g} {'rad' if d.kind == 'crank' else mech.units}"
        for j, d in enumerate(mech.drivers)
    )
    if f.sample >= off:
        where = f"at t = {t:.6g} s (sample {f.sample - off} of {len(tg) - off})"
        kept = f"{f.sample - off} earlier sample{'s' if f.sample - off != 1 else ''} kept"
    else:
        where = f"at t = {t:.6g} s, before the first requested time"
        kept = "no sample kept"
    lim = ""
    if limit is not None:
        vals = ", ".join(
            f"{d.symbol} = {limit[1][j]:.10g} {'rad' if d.kind == 'crank' else mech.units}"
            for j, d in enumerate(mech.drivers)
        )
        lim = f" (last assembled at t = {limit[0]:.10g} s, {vals})"
    err = MotionError(
        f"{mech.name}: cannot assemble {where}, {drv}: loop {lp.index + 1} ({lp.label}): {f.why}{lim}; {kept}",
        entry=f"loop {lp.index + 1}",
        time=t,
        sample=f.sample - off,
        driver_value=X[f.sample].tolist() if len(X) else None,
        partial=partial,
    )
    err.limit_time = limit[0] if limit is not None else None
    err.limit_value = limit[1].tolist() if limit is not None else None
    return err
