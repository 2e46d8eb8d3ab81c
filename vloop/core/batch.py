"""Many variants of one mechanism solved together: a leading batch axis over variants.

Every variant shares the nominal LoopSystem's structure; its own numbers are per-variant term constants
(r, e^{jδ}), driver numbers and frame offsets (:class:`vloop.core.variants.Designs`). The state holds arrays of
shape (variants, internal samples, columns) — the single-run solver's state with a leading axis — and every
operation is elementwise over variants (no BLAS product mixes rows, so a variant's numbers do not depend on
which other variants it is solved with: chunking never changes a number).

Blocks are solved in the structure's order, over every sample at once:

* **closed-form dyads** (RRR, RRP, RPR, PP) exactly as :mod:`vloop.core.solver` writes them, elementwise, on
  the nominal branch σ;
* **Newton blocks** by continuation along the samples, batched over variants: Taylor predictor from the
  sample before, Newton–Raphson with the analytic Jacobian (``numpy.linalg.solve`` on stacks of small
  matrices), exact linear rates. The t = 0 assembly of a Newton block is continued from the nominal design
  (term vectors and driver numbers blended in ASSEMBLY_STEPS steps), on the nominal branch (the sign of its
  Jacobian's determinant).

A variant the batch is not sure of — its motion passes a limit (the loop stops closing), a dip of a dyad's
discriminant that the single run's first zoom pass would not dismiss (a possible change point, or a limit
between samples), a sample whose velocity error bound cond²·ε exceeds a tenth of rtol (the single run
refuses at rtol), a branch sign change, a Newton step that does not converge, close, or stay near its
prediction, inputs too large to resolve or moving too far per sample, a non-finite number — is solved
again on its own by the single-run solver (:func:`vloop.core.solver.solve` on the variant's LoopSystem: same
structure, its own constants), which locates limits, passes change points and says why a motion stops,
exactly as ``vloop.solve`` of that variant's file would (or, with ``solve(..., doubtful="fail")``, reported as
not completed without that second solve). A variant that does not assemble at t = 0 on the nominal branch is
reported, not solved.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Self

import numpy as np

from ..drivers import evaluate
from ..errors import MotionError, VloopError
from ..method.loops import Block, LoopSystem
from .changepoints import CHANGE_GAP, DIP, ETA_INPUT, ZOOM_POINTS
from .kernels import DEFAULT_RTOL, EPS, block_terms, cross, det_sign, newton_rows, pinv_rows, solve_rows
from .solver import DEFAULT_MAX_ITER, DEFAULT_TOL, MAX_INPUT_STEP
from .variants import Designs, VariantModel

TWO_PI = 2.0 * math.pi
# Variants × internal samples solved together. NumPy computes ``a * tmp`` in place as ``tmp * a`` when the
# temporary is 256 KiB or more, and a complex product (fused multiply-add) is not bitwise symmetric: keeping
# every complex (variants × samples) array below that size makes a variant's numbers independent of how many
# variants it is solved with — the chunking never changes a number. (The state stays in cache, too.)
ROWS = 16_000
ASSEMBLY_STEPS = 16  # continuation steps from the nominal design to a variant (t = 0, Newton blocks)
JUMP = 0.5  # a Newton correction beyond this fraction of the predicted move is not trusted
SURE = 0.1  # a sample whose velocity error bound cond²·ε exceeds this fraction of rtol is left to the single run
CLOSURE = 1e-9  # a Newton row closes every equation to this fraction of the mechanism size
MAX_GRID_FACTOR = 64  # internal samples allowed per requested one (plus a lead-in allowance)
MAX_LEAD = 100_000


# ---------------------------------------------------------------- the shared internal grid


@dataclass(frozen=True)
class Grid:
    """Internal times shared by every variant: t[0] = 0 (the assembly), then rows up to every requested
    time with rows inserted where any variant's input moves more than MAX_INPUT_STEP; ``out`` the internal
    row of each requested time."""

    t: np.ndarray
    out: np.ndarray
    times: np.ndarray


def make_grid(model: VariantModel, designs: Designs, times: np.ndarray) -> Grid:
    """The internal grid for ``times`` [s] (strictly increasing) that serves every one of ``designs``."""
    times = np.asarray(times, float)
    lead = times[0] != 0.0
    seq = np.concatenate([[0.0], times]) if lead else times
    steps = np.ones(max(len(seq) - 1, 0), np.int64)
    mech = model.mechanism
    if mech.drivers and len(seq) > 1:
        steps = np.maximum(_steps_needed(model, designs, seq, lead), 1).astype(np.int64)
    starts = np.concatenate([[0], np.cumsum(steps)])
    k = np.arange(starts[-1])
    seg = np.repeat(np.arange(len(steps)), steps)
    frac = (k - starts[seg]) / steps[seg]
    t = np.append(seq[seg] + frac * (seq[seg + 1] - seq[seg]), seq[-1]) if len(seq) > 1 else seq.copy()
    t[starts] = seq
    out = starts[1:] if lead else starts
    return Grid(t, out, times)


def _steps_needed(model: VariantModel, designs: Designs, seq: np.ndarray, lead: bool) -> np.ndarray:
    """Internal rows each interval of ``seq`` needs so that no variant's input moves more than MAX_INPUT_STEP per
    row, capped at MAX_GRID_FACTOR (MAX_LEAD for a lead-in from t = 0): a variant whose inputs move farther is
    left to the single-run solver (see _impose), which inserts its own rows. Evaluated in blocks of variants."""
    mech = model.mechanism
    units = np.array([1.0 if d.kind == "crank" else mech.scale / TWO_PI for d in mech.drivers])
    h = np.abs(np.diff(seq))[None, :, None]
    need = np.ones(len(seq) - 1)
    per = max(1, ROWS // len(seq))
    for lo in range(0, len(designs), per):
        X, XD, _ = _inputs(model, designs.take(slice(lo, lo + per)), seq)
        travel = _travel(X, XD, h) / units
        with np.errstate(invalid="ignore"):
            most = np.ceil(np.nanmax(travel, axis=(0, 2)) / MAX_INPUT_STEP)
        need = np.maximum(need, np.where(np.isfinite(most), most, 1.0))  # absurd inputs: those variants go single
    cap = np.full(len(need), float(MAX_GRID_FACTOR))
    if lead:
        cap[0] = MAX_LEAD
    return np.minimum(need, cap)


def _travel(X: np.ndarray, XD: np.ndarray, h: np.ndarray) -> np.ndarray:
    """How far each input moves over each interval, at most: |Δx|, or the interval times the larger rate at its
    ends (the largest over it for a constant acceleration, so evenly inserted rows each move at most their share)."""
    with np.errstate(invalid="ignore"):
        return np.maximum(np.abs(np.diff(X, axis=1)), h * np.maximum(np.abs(XD[:, 1:]), np.abs(XD[:, :-1])))


def _inputs(model: VariantModel, d: Designs, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Drivers' x, ẋ, ẍ per variant at times ``t`` (n,) or, per variant, (V, n): arrays (V, n, n_drivers), as
    vloop.drivers evaluates them."""
    mech = model.mechanism
    V, m = len(d), len(mech.drivers)
    X, XD, XDD = (np.zeros((V, np.shape(t)[-1], m)) for _ in range(3))
    for j, drv in enumerate(mech.drivers):
        if drv.profile is not None:
            x, xd, xdd = evaluate(drv, t)
            X[:, :, j], XD[:, :, j], XDD[:, :, j] = x, xd, xdd
            continue
        x0, v0, a0 = d.x0[:, j : j + 1], d.v0[:, j : j + 1], d.a0[:, j : j + 1]
        X[:, :, j] = x0 + v0 * t + 0.5 * a0 * t * t
        XD[:, :, j] = v0 + a0 * t
        XDD[:, :, j] = a0
    return X, XD, XDD


# ---------------------------------------------------------------- state and block plans


class _State:
    """The single-run solver's state with a leading variant axis: (V, rows, columns); the last column of each
    is the 'fixed' padding (E = 1, the others 0) that terms index with -1."""

    def __init__(self, V: int, n: int, na: int, ns: int) -> None:
        self.E = np.ones((V, n, na + 1), complex)
        self.TH = np.zeros((V, n, na))
        self.W = np.zeros((V, n, na + 1))
        self.AL = np.zeros((V, n, na + 1))
        self.S = np.zeros((V, n, ns + 1))
        self.SD = np.zeros((V, n, ns + 1))
        self.SDD = np.zeros((V, n, ns + 1))


@dataclass
class _Plan:
    """One block's terms (those in its loops) and the roles of its unknowns."""

    block: Block
    terms: np.ndarray  # global term ids
    C: np.ndarray  # (m, n_block_terms) loop coefficients
    ang: np.ndarray  # per block term
    sl: np.ndarray
    unk_ang: list[int]
    unk_sl: list[int]
    known: np.ndarray  # block terms that depend on no unknown
    on_angle: dict[int, list[int]]  # unknown angle → block terms of the first loop turning with it
    own: dict[int, int]  # unknown slider → its own block term in the first loop

    @classmethod
    def build(cls, sys: LoopSystem, b: Block) -> _Plan:
        terms, Cb, ang, sl, unk_ang, unk_sl, known = block_terms(sys, b)
        g = Cb[0]
        on_angle = {a: [int(t) for t in np.nonzero((ang == a) & (g != 0))[0]] for a in unk_ang}
        own = {i: int(np.nonzero((sl == i) & (g != 0))[0][0]) for i in unk_sl if np.any((sl == i) & (g != 0))}
        return cls(b, terms, Cb, ang, sl, unk_ang, unk_sl, known, on_angle, own)


@dataclass
class _Flags:
    """Per variant: assembled at t = 0, taken by the batch, why not (first reason), worst condition number."""

    assembled: np.ndarray
    regular: np.ndarray
    why: list[str]
    cond: np.ndarray

    @classmethod
    def new(cls, V: int) -> _Flags:
        return cls(np.ones(V, bool), np.ones(V, bool), [""] * V, np.ones(V))

    def refuse(self, mask: np.ndarray, why: str) -> None:
        """These variants do not assemble at t = 0 (the first reason is kept)."""
        for v in np.nonzero(mask & self.assembled)[0]:
            self.why[v] = why
        self.assembled &= ~mask
        self.regular &= ~mask

    def doubt(self, mask: np.ndarray) -> None:
        """These variants are left to the single-run solver."""
        self.regular &= ~mask


# ---------------------------------------------------------------- terms of many variants


def _z(st: _State, k: slice | int, d: Designs, t: int, ang: int, sl: int) -> tuple[np.ndarray, np.ndarray]:
    """Term t's vector z = (r + s)·cd·E and unit direction e over rows ``k`` of every variant."""
    e = d.cd[:, t, None] * st.E[:, k, ang] if isinstance(k, slice) else d.cd[:, t] * st.E[:, k, ang]
    r = d.r[:, t, None] if isinstance(k, slice) else d.r[:, t]
    return (r + st.S[:, k, sl]) * e, e


def _zdot(st: _State, k: slice | int, d: Designs, t: int, ang: int, sl: int, what: str) -> np.ndarray:
    """ż = ṡ·e + jω·z, or z̈ = s̈·e + 2jṡω·e + (jα − ω²)·z, of term t over rows ``k``."""
    z, e = _z(st, k, d, t, ang, sl)
    w = st.W[:, k, ang]
    if what == "v":
        return st.SD[:, k, sl] * e + 1j * w * z
    sd = st.SD[:, k, sl]
    return (st.SDD[:, k, sl] + 2j * sd * w) * e + (1j * st.AL[:, k, ang] - w * w) * z


def _loop_sum(
    st: _State, k: slice | int, d: Designs, p: _Plan, coef: np.ndarray, which: np.ndarray, what: str = "p"
) -> np.ndarray | complex:
    """Σ coef_t·(z_t | ż_t | z̈_t) over the block terms ``which`` (in order: a fixed summation order per variant)."""
    out: np.ndarray | complex = 0j
    for t in which:
        c = coef[t]
        if c == 0:
            continue
        gt, a, s = int(p.terms[t]), int(p.ang[t]), int(p.sl[t])
        if what == "p":
            val = _z(st, k, d, gt, a, s)[0]
        elif a < 0 and s < 0:
            continue  # a vector fixed to the ground does not move
        else:
            val = _zdot(st, k, d, gt, a, s, what)
        out = out + c * val
    return out


def _w(st: _State, k: slice, d: Designs, p: _Plan, a: int, skip: int = -2) -> np.ndarray:
    """W_a: the first loop's vectors turning with unknown angle a, before rotation (slider ``skip`` left out)."""
    g = p.C[0]
    w: np.ndarray | complex = 0j
    for t in p.on_angle[a]:
        gt, s = int(p.terms[t]), int(p.sl[t])
        if s == skip:
            continue
        rs = d.r[:, gt, None] + st.S[:, k, s] if s >= 0 else d.r[:, gt, None]
        w = w + g[t] * rs * d.cd[:, gt, None]
    return np.broadcast_to(w, (st.E.shape[0], 1)) if np.ndim(w) == 0 else w


def _u(st: _State, k: slice, d: Designs, p: _Plan, i: int) -> np.ndarray:
    """The direction of unknown slider i's own vector in the first loop."""
    t = p.own[i]
    return p.C[0][t] * d.cd[:, int(p.terms[t]), None] * st.E[:, k, int(p.ang[t])]


def _known_magnitude(st: _State, d: Designs, p: _Plan) -> np.ndarray:
    """Σ |r + s| over the block's known vectors per row: the round-off the known part X carries grows with it
    (as the single-run solver's Plan.known_magnitude)."""
    out: np.ndarray | float = 0.0
    for t in np.nonzero(p.known)[0]:
        gt, s = int(p.terms[t]), int(p.sl[t])
        out = out + np.abs(d.r[:, gt, None] + st.S[:, :, s] if s >= 0 else d.r[:, gt, None])
    return np.broadcast_to(out, st.E.shape[:2])


# ---------------------------------------------------------------- closed-form dyads


def _round_off_zero(h: np.ndarray, size: np.ndarray) -> np.ndarray:
    return np.where(np.abs(h) <= 16 * EPS * size, 0.0, h)


def _set_angle(st: _State, a: int, E: np.ndarray, ref: np.ndarray) -> None:
    """Store e^{jθ} and the unwrapped θ = φ + 2π·n along the samples, n counted by continuity from ``ref``
    (V,) before row 0 (as the single run counts turns from its t = 0 assembly)."""
    E = E / np.abs(E)
    st.E[:, :, a] = E
    phi = np.angle(E)
    first = np.angle(np.exp(1j * (phi[:, :1] - ref[:, None])))
    est = ref[:, None] + np.concatenate([first, first + np.cumsum(np.angle(np.exp(1j * np.diff(phi, axis=1))), 1)], 1)
    st.TH[:, :, a] = phi + TWO_PI * np.round((est - phi) / TWO_PI)


def _closed_form(st: _State, d: Designs, p: _Plan, sigma: float, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions of a one-loop dyad on every row of every variant on branch σ; returns (assemblable, h):
    the discriminant h [length²] is negative past a limit and zero where the two branches meet."""
    k = slice(None)
    X = -_loop_sum(st, k, d, p, p.C[0], np.nonzero(p.known)[0])
    X = np.broadcast_to(X, st.E.shape[:2]) if np.ndim(X) < 2 or X.shape[1] == 1 else X
    kind = p.block.kind
    if kind == "RRR":
        a1, a2 = p.unk_ang
        W1, W2 = _w(st, k, d, p, a1), _w(st, k, d, p, a2)
        A2, B2 = np.abs(W1) ** 2, np.abs(W2) ** 2
        D2 = X.real**2 + X.imag**2
        k1 = 0.5 * (A2 + D2 - B2)
        xerr = _known_magnitude(st, d, p) * np.sqrt(D2)  # ~ |X|·Σ|known| / ε: round-off carried by X
        h2 = _round_off_zero(A2 * D2 - k1 * k1, A2 * D2 + k1 * k1 + (A2 + np.abs(k1)) * xerr)
        ok = (h2 >= 0) & (D2 > 0)
        Dd = np.where(D2 > 0, D2, 1.0)
        P = X * (k1 + 1j * sigma * np.sqrt(np.where(ok, h2, 0.0))) / Dd
        _set_angle(st, a1, P / W1, ref[:, a1])
        _set_angle(st, a2, (X - P) / W2, ref[:, a2])
        return ok, h2 / Dd
    if kind == "RRP":
        i, a = p.unk_sl[0], p.unk_ang[0]
        Uc = np.conj(_u(st, k, d, p, i))
        W1 = _w(st, k, d, p, a)
        XU, WU = X * Uc, W1 * Uc
        y = XU.imag
        h = _round_off_zero(np.abs(W1) ** 2 - y * y, np.abs(W1) ** 2 + np.abs(y) * _known_magnitude(st, d, p))
        ok = h >= 0
        c = sigma * np.sqrt(np.where(ok, h, 0.0))
        _set_angle(st, a, (c + 1j * y) / WU, ref[:, a])
        st.S[:, :, i] = XU.real - c
        return ok, np.broadcast_to(h, ok.shape)
    if kind == "RPR":
        i, a = p.unk_sl[0], p.unk_ang[0]
        t = p.own[i]
        cdir = p.C[0][t] * d.cd[:, int(p.terms[t]), None]
        W = _w(st, k, d, p, a, skip=i)
        bb = (W * np.conj(cdir)).real
        D2 = X.real**2 + X.imag**2
        size = bb * bb + np.abs(W) ** 2 + D2 + np.sqrt(D2) * _known_magnitude(st, d, p)
        disc = _round_off_zero(bb * bb - np.abs(W) ** 2 + D2, size)
        s = -bb + sigma * np.sqrt(np.where(disc >= 0, disc, 0.0))
        den = W + s * cdir
        ok = (disc >= 0) & (np.abs(den) > 0)
        st.S[:, :, i] = s
        _set_angle(st, a, X / np.where(ok, den, 1.0), ref[:, a])
        return ok, disc
    U1, U2 = _u(st, k, d, p, p.unk_sl[0]), _u(st, k, d, p, p.unk_sl[1])  # PP: linear, one solution
    det = cross(U1, U2)
    ok = np.abs(det) > 1e-12
    dd = np.where(ok, det, 1.0)
    st.S[:, :, p.unk_sl[0]] = cross(X, U2) / dd
    st.S[:, :, p.unk_sl[1]] = cross(U1, X) / dd
    return ok, np.full(ok.shape, np.inf)


def _columns(st: _State, d: Designs, p: _Plan) -> tuple[np.ndarray, np.ndarray]:
    """The two complex Jacobian columns of a one-loop block: j·W_a·E_a for an angle, U for a slider."""
    k = slice(None)
    cols = []
    for v in p.block.unknowns:
        if v < st.TH.shape[2]:
            cols.append(1j * _w(st, k, d, p, v) * st.E[:, :, v])
        else:
            cols.append(_u(st, k, d, p, v - st.TH.shape[2]))
    return cols[0], cols[1]


def _closed_form_rates(st: _State, d: Designs, p: _Plan, cols: tuple[np.ndarray, np.ndarray]) -> None:
    """ω/ṡ then α/s̈ of a dyad by Cramer's rule: J·u̇ = −(the loop's ż with the unknowns' rates zero)."""
    c1, c2 = cols
    det = cross(c1, c2)
    na = st.TH.shape[2]
    everything = np.arange(len(p.terms))
    for what in ("v", "a"):
        R0 = -_loop_sum(st, slice(None), d, p, p.C[0], everything, what)
        R0 = np.broadcast_to(R0, c1.shape)
        vals = (cross(R0, c2) / det, cross(c1, R0) / det)
        for v, x in zip(p.block.unknowns, vals, strict=True):
            if v < na:
                (st.W if what == "v" else st.AL)[:, :, v] = x
            else:
                (st.SD if what == "v" else st.SDD)[:, :, v - na] = x


def _dyad_health(c1: np.ndarray, c2: np.ndarray, angle: tuple[bool, bool], scale: float) -> tuple:
    """(condition number, sign of det) per row, angle columns divided by the mechanism size (as the solver)."""
    if angle[0]:
        c1 = c1 / scale
    if angle[1]:
        c2 = c2 / scale
    det = cross(c1, c2)
    f2 = (c1.real**2 + c1.imag**2) + (c2.real**2 + c2.imag**2)
    ad = np.abs(det)
    root = np.sqrt(np.maximum(f2 * f2 - 4 * det * det, 0.0))
    with np.errstate(divide="ignore", invalid="ignore"):
        cond = np.where(ad > 0, (f2 + root) / (2 * np.where(ad > 0, ad, 1.0)), np.inf)
    return cond, np.sign(det)


def _dips(h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(variant, row c) of every dip of the sampled discriminants: a local minimum below DIP of its larger
    neighbour (bracket c − 1 .. c + 1), or still falling at the end (bracket c = n − 2 .. n − 1): where the
    single run zooms in for a change point or a limit between samples (vloop.core.changepoints._candidate_minima)."""
    n = h.shape[1]
    if n < 2:
        return np.zeros(0, int), np.zeros(0, int)
    vs, cs = [np.zeros(0, int)], [np.zeros(0, int)]
    if n >= 3:
        mid, lo, hi = h[:, 1:-1], h[:, :-2], h[:, 2:]
        v, c = np.nonzero((mid <= lo) & (mid <= hi) & (mid < DIP * np.maximum(lo, hi)))
        vs.append(v)
        cs.append(c + 1)
    v = np.nonzero(h[:, -1] < DIP * h[:, -2])[0]
    vs.append(v)
    cs.append(np.full(len(v), -(n - 2)))  # negative: a tail bracket n − 2 .. n − 1
    return np.concatenate(vs), np.concatenate(cs)


def _harmless(run: _Run, d: Designs, i: int, t: np.ndarray, v: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Whether each dip (variant v, row c) is one the single run's first zoom pass dismisses: h least at an end
    of the bracket, or √h (Lipschitz) kept clear of CHANGE_GAP between 17 probes — then its result is the plain
    closed form's, as the batch's. Otherwise (a possible change point, a limit between samples) it is not."""
    tail = c < 0
    lo = np.where(tail, -c, c - 1)
    hi = np.where(tail, -c + 1, c + 1)
    a, b = t[lo], t[hi]
    ts = a[:, None] + (b - a)[:, None] * np.linspace(0.0, 1.0, ZOOM_POINTS)[None, :]
    dv = d.take(v)
    _, XD, _ = _inputs(run.model, dv, 0.5 * (a + b)[:, None])
    units = np.array([1.0 if dr.kind == "crank" else run.scale for dr in run.model.mechanism.drivers])
    rate = np.max(np.abs(XD[:, 0, :]) / units, axis=1, initial=0.0)
    with np.errstate(divide="ignore"):
        eta = np.minimum(np.where(rate > 0, ETA_INPUT / rate, np.inf), 0.25 * (b - a))
    times = np.concatenate([ts, ts - eta[:, None], ts + eta[:, None]], axis=1)
    sys = run.model.system
    st = _State(len(v), times.shape[1], sys.n_angles, len(sys.slider_names))
    _impose(run, st, dv, times, travel=False)
    ok = np.ones(st.E.shape[:2], bool)
    for p in run.plans[: i + 1]:
        okj, h = _closed_form(st, dv, p, p.block.sigma, np.zeros((len(v), sys.n_vars)))
        ok &= okj
    n = ZOOM_POINTS
    mid, g = h[:, :n], h[:, 2 * n :] - h[:, n : 2 * n]
    with np.errstate(invalid="ignore"):
        root = np.sqrt(mid)
        apart = root.min(axis=1) - np.max(np.abs(np.diff(root, axis=1)), axis=1) > 0.5 * CHANGE_GAP * run.scale
    at_end = ~((g[:, 0] < 0) & (g[:, -1] >= 0))
    return ok.all(axis=1) & np.all(mid >= 0, axis=1) & (at_end | apart)


# ---------------------------------------------------------------- Newton blocks


class _Newton:
    """One Newton block over many variants at one internal row: residual, Jacobian, steps, rates."""

    def __init__(self, p: _Plan, na: int, scale: float) -> None:
        self.p, self.na, self.scale = p, na, scale
        self.nu = len(p.block.unknowns)
        self.m2 = 2 * p.C.shape[0]
        self.square = self.m2 == self.nu
        self.is_angle = np.array([v < na for v in p.block.unknowns])
        self.colscale = np.where(self.is_angle, 1.0 / scale, 1.0)
        self.unit = np.where(self.is_angle, 1.0, TWO_PI / scale)

    def read(self, st: _State, vs: np.ndarray, k: int) -> np.ndarray:
        return np.stack(
            [st.TH[vs, k, v] if v < self.na else st.S[vs, k, v - self.na] for v in self.p.block.unknowns], 1
        )

    def put(self, st: _State, vs: np.ndarray, k: int, x: np.ndarray) -> None:
        for u, v in enumerate(self.p.block.unknowns):
            if v < self.na:
                st.TH[vs, k, v] = x[:, u]
                st.E[vs, k, v] = np.cos(x[:, u]) + 1j * np.sin(x[:, u])
            else:
                st.S[vs, k, v - self.na] = x[:, u]

    def residual_jacobian(self, st: _State, d: Designs, vs: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """[Re; Im] of the block's loop sums (Va, 2m) and their Jacobian (Va, 2m, nu)."""
        p = self.p
        m = p.C.shape[0]
        F = np.zeros((len(vs), m), complex)
        J = np.zeros((len(vs), m, self.nu), complex)
        sub = _Sub(st, vs, k)
        for t in range(len(p.terms)):
            gt, a, s = int(p.terms[t]), int(p.ang[t]), int(p.sl[t])
            z, e = sub.z(d, gt, a, s)
            for li in range(m):
                c = p.C[li, t]
                if c == 0:
                    continue
                F[:, li] += c * z
                for u, v in enumerate(p.block.unknowns):
                    if v < self.na and a == v:
                        J[:, li, u] += c * (1j * z)
                    elif v >= self.na and s == v - self.na:
                        J[:, li, u] += c * e
        return np.concatenate([F.real, F.imag], 1), np.concatenate([J.real, J.imag], 1)

    def newton(self, st: _State, d: Designs, vs: np.ndarray, k: int, x: np.ndarray, tol: float, max_iter: int):
        """Batched Newton at row k of variants ``vs`` from ``x``: (solution, converged)."""

        def residual(act: np.ndarray, xa: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
            self.put(st, vs[act], k, xa)
            return self.residual_jacobian(st, d.take(vs[act]), vs[act], k)

        x, conv = newton_rows(residual, x, tol, max_iter)
        good = np.all(np.isfinite(x), axis=1)
        self.put(st, vs[good], k, x[good])
        return x, conv

    def rates(self, st: _State, d: Designs, vs: np.ndarray, k: int, J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """ẋ then ẍ at row k (exact linear solves, least squares for a rectangular block), stored in the state."""
        out = []
        everything = np.arange(len(self.p.terms))
        dv = d.take(vs)
        for what in ("v", "a"):
            sub = _Sub(st, vs, k)  # after the velocities are stored, for the accelerations' quadratic terms
            R = np.stack(
                [-sub.loop_sum(dv, self.p, self.p.C[li], everything, what) for li in range(self.p.C.shape[0])], 1
            )
            rhs = np.concatenate([R.real, R.imag], axis=1)
            val = solve_rows(J, rhs) if self.square else (pinv_rows(J) @ rhs[..., None])[..., 0]
            for u, v in enumerate(self.p.block.unknowns):
                if v < self.na:
                    (st.W if what == "v" else st.AL)[vs, k, v] = val[:, u]
                else:
                    (st.SD if what == "v" else st.SDD)[vs, k, v - self.na] = val[:, u]
            out.append(val)
        return out[0], out[1]

    def cond(self, J: np.ndarray, rtol: float) -> np.ndarray:
        """Condition number of the scaled Jacobians (2-norm where it matters, as vloop.core.newton)."""
        Js = J * self.colscale
        ok = np.all(np.isfinite(Js), axis=(1, 2))
        cond = np.full(len(J), np.inf)
        if ok.any():
            inv = pinv_rows(Js[ok])
            with np.errstate(invalid="ignore", over="ignore"):
                cond[ok] = np.sqrt(np.sum(Js[ok] ** 2, axis=(1, 2)) * np.sum(inv**2, axis=(1, 2)))
        cond = np.where(np.isfinite(cond), cond, np.inf)
        near = np.nonzero(ok & (cond > math.sqrt(SURE * rtol / EPS)))[0]
        if len(near):
            sv = np.linalg.svd(Js[near], compute_uv=False)
            with np.errstate(divide="ignore"):
                cond[near] = np.where(sv[:, -1] > 0, sv[:, 0] / np.where(sv[:, -1] > 0, sv[:, -1], 1.0), np.inf)
        return cond


class _Sub:
    """Row k of some variants ``vs`` of a state, for term sums (the state's arrays indexed once)."""

    def __init__(self, st: _State, vs: np.ndarray, k: int) -> None:
        self.E, self.S = st.E[vs, k], st.S[vs, k]
        self.W, self.AL, self.SD, self.SDD = st.W[vs, k], st.AL[vs, k], st.SD[vs, k], st.SDD[vs, k]

    def z(self, d: Designs, t: int, a: int, s: int) -> tuple[np.ndarray, np.ndarray]:
        e = d.cd[:, t] * self.E[:, a]
        return (d.r[:, t] + self.S[:, s]) * e, e

    def loop_sum(self, d: Designs, p: _Plan, coef: np.ndarray, which: np.ndarray, what: str) -> np.ndarray:
        out = np.zeros(len(self.E), complex)
        for t in which:
            c = coef[t]
            gt, a, s = int(p.terms[t]), int(p.ang[t]), int(p.sl[t])
            if c == 0 or (a < 0 and s < 0):
                continue
            z, e = self.z(d, gt, a, s)
            w = self.W[:, a]
            if what == "v":
                out = out + c * (self.SD[:, s] * e + 1j * w * z)
            else:
                sd = self.SD[:, s]
                out = out + c * ((self.SDD[:, s] + 2j * sd * w) * e + (1j * self.AL[:, a] - w * w) * z)
        return out


# ---------------------------------------------------------------- the run


@dataclass
class _Run:
    """What one batched run shares: the model, the plans, the solver options and the nominal t = 0 data."""

    model: VariantModel
    plans: list[_Plan]
    scale: float
    tol: float
    max_iter: int
    rtol: float
    newton_sign: dict[int, float] = field(default_factory=dict)  # each Newton block's det sign at the nominal t = 0

    @classmethod
    def build(cls, model: VariantModel) -> _Run:
        sys, mech = model.system, model.mechanism
        opts = mech.options
        run = cls(
            model,
            [_Plan.build(sys, b) for b in sys.blocks],
            mech.scale,
            float(opts.get("tol", DEFAULT_TOL)),
            int(opts.get("max_iter", DEFAULT_MAX_ITER)),
            float(opts.get("rtol", DEFAULT_RTOL)),
        )
        if any(p.block.kind == "newton" for p in run.plans):
            nominal = model.designs(model.nominal_values()[None, :])
            st = _State(1, 1, sys.n_angles, len(sys.slider_names))
            _impose(run, st, nominal, np.zeros(1))
            for v in range(sys.n_vars):
                if v not in sys.drivers:
                    _put_var(st, sys.n_angles, v, sys.q0[v])
            for i, p in enumerate(run.plans):
                if p.block.kind == "newton":
                    nt = _Newton(p, sys.n_angles, run.scale)
                    _, J = nt.residual_jacobian(st, nominal, np.zeros(1, int), 0)
                    run.newton_sign[i] = float(det_sign(J)[0] or 1.0)
        return run


def _put_var(st: _State, na: int, v: int, x: float) -> None:
    if v < na:
        st.TH[:, :, v] = x
        st.E[:, :, v] = np.cos(x) + 1j * np.sin(x)
    else:
        st.S[:, :, v - na] = x


def _impose(run: _Run, st: _State, d: Designs, t: np.ndarray, travel: bool = True) -> np.ndarray:
    """Drivers' inputs into the state; returns the variants whose inputs cannot be resolved (non-finite, or a
    crank angle whose floating-point spacing exceeds rtol: the single run refuses those samples)."""
    sys = run.model.system
    na = sys.n_angles
    X, XD, XDD = _inputs(run.model, d, t)
    bad = ~(np.isfinite(X) & np.isfinite(XD) & np.isfinite(XDD)).all(axis=(1, 2))
    if travel and len(t) > 1 and sys.drivers:  # an input moving more than MAX_INPUT_STEP per row: turns miscounted
        units = np.array([1.0 if dr.kind == "crank" else run.scale / TWO_PI for dr in run.model.mechanism.drivers])
        h = np.abs(np.diff(t))[None, :, None]
        with np.errstate(invalid="ignore"):
            bad |= ~np.all(_travel(X, XD, h) / units <= MAX_INPUT_STEP * (1 + 1e-9), axis=(1, 2))
    for j, v in enumerate(sys.drivers):
        if v < na:
            st.TH[:, :, v] = X[:, :, j]
            st.E[:, :, v] = np.cos(X[:, :, j]) + 1j * np.sin(X[:, :, j])
            st.W[:, :, v], st.AL[:, :, v] = XD[:, :, j], XDD[:, :, j]
            with np.errstate(invalid="ignore"):
                bad |= np.any(np.spacing(np.abs(X[:, :, j])) > run.rtol, axis=1)
        else:
            st.S[:, :, v - na], st.SD[:, :, v - na], st.SDD[:, :, v - na] = X[:, :, j], XD[:, :, j], XDD[:, :, j]
    return bad


def _solve_blocks(
    run: _Run,
    st: _State,
    d: Designs,
    t: np.ndarray,
    out_rows: np.ndarray,
    start: np.ndarray,
    flags: _Flags,
) -> None:
    """Every block in order on every row of every variant. ``start`` (V, n_vars): the references the closed
    forms count turns from and the Newton blocks' t = 0 starting values; ``out_rows``: the requested rows
    (the worst condition number is taken over those, as the single run's health)."""
    sys = run.model.system
    na = sys.n_angles
    for i, p in enumerate(run.plans):
        loop = sys.loops[p.block.loops[0]]
        where = f"loop {loop.index + 1} ({loop.label})"
        if p.block.kind == "newton":
            _newton_block(run, st, d, t, i, p, start, out_rows, flags, where)
            continue
        ok, h = _closed_form(st, d, p, p.block.sigma, start)
        flags.refuse(~ok[:, 0], f"cannot assemble at t = 0: {where} cannot close (its links cannot reach)")
        flags.doubt(~ok.all(axis=1))  # a limit: the single run locates it
        if p.block.kind != "PP":
            v, c = _dips(h)
            keep = flags.regular[v] & ok.all(axis=1)[v]
            v, c = v[keep], c[keep]
            if len(v) and any(q.block.kind == "newton" for q in run.plans[:i]):
                flags.doubt(np.isin(np.arange(len(d)), v))  # probing through a Newton block: the single run decides
            elif len(v):
                flags.doubt(np.isin(np.arange(len(d)), v[~_harmless(run, d, i, t, v, c)]))
        cols = _columns(st, d, p)
        cond, sgn = _dyad_health(*cols, (p.block.unknowns[0] < na, p.block.unknowns[1] < na), run.scale)
        flags.doubt(np.any(cond * cond * EPS > SURE * run.rtol, axis=1) | np.any(sgn != sgn[:, :1], axis=1))
        flags.cond = np.maximum(flags.cond, np.max(cond[:, out_rows], axis=1))
        _closed_form_rates(st, d, p, cols)


def _newton_block(
    run: _Run,
    st: _State,
    d: Designs,
    t: np.ndarray,
    i: int,
    p: _Plan,
    start: np.ndarray,
    out_rows: np.ndarray,
    flags: _Flags,
    where: str,
) -> None:
    """A Newton block on every row: the t = 0 row from ``start`` (every assembled variant), then continuation
    along the rows (the variants the batch still takes)."""
    na = run.model.system.n_angles
    nt = _Newton(p, na, run.scale)
    expected = run.newton_sign[i]
    x = start[:, list(p.block.unknowns)].copy()
    xd, xdd = np.zeros_like(x), np.zeros_like(x)
    wanted = np.zeros(st.E.shape[1], bool)
    wanted[out_rows] = True
    for k in range(st.E.shape[1]):
        vs = np.nonzero(flags.assembled if k == 0 else flags.regular)[0]
        if not len(vs):
            return
        h = t[k] - t[k - 1] if k else 0.0
        pred = x[vs] + xd[vs] * h + 0.5 * xdd[vs] * h * h
        xs, conv = nt.newton(st, d, vs, k, pred, run.tol, run.max_iter)
        F, J = nt.residual_jacobian(st, d.take(vs), vs, k)
        with np.errstate(invalid="ignore"):
            closure = np.max(np.abs(F), axis=1) / run.scale
        bad = ~conv | ~(closure <= CLOSURE) | (det_sign(J) != expected)
        if k == 0:
            mask = np.zeros(len(flags.regular), bool)
            mask[vs[bad]] = True
            flags.refuse(
                mask,
                f"cannot assemble at t = 0 on the nominal branch: Newton on {where} does not converge "
                "there from the nominal design, or lands on another branch",
            )
        else:
            with np.errstate(invalid="ignore"):
                c = np.max(np.abs(xs - pred) * nt.unit, axis=1)
                m = np.max(np.abs(pred - x[vs]) * nt.unit, axis=1) + 1e-9 * (1.0 + np.max(np.abs(xs) * nt.unit, axis=1))
            bad |= ~(c <= JUMP * m)  # the correction is not small against the predicted move: not trusted
            flags.regular[vs[bad]] = False
        vs, xs, J = vs[~bad], xs[~bad], J[~bad]
        x[vs] = xs
        xd[vs], xdd[vs] = nt.rates(st, d, vs, k, J)
        cond = nt.cond(J, run.rtol)
        if wanted[k]:
            flags.cond[vs] = np.maximum(flags.cond[vs], cond)
        flags.doubt(np.isin(np.arange(len(flags.regular)), vs[~(cond * cond * EPS <= SURE * run.rtol)]))


def _assemble_newton(run: _Run, d: Designs, flags: _Flags) -> np.ndarray:
    """The t = 0 starting values of every variable: for the Newton blocks' unknowns, continued from the nominal
    assembly to each variant in ASSEMBLY_STEPS steps (term vectors and driver numbers blended), on the nominal
    branch throughout; closed forms need none (their branch σ defines them)."""
    if not run.newton_sign:
        return d.q_start
    sys = run.model.system
    newton_vars = np.zeros(sys.n_vars, bool)
    for p in run.plans:
        if p.block.kind == "newton":
            newton_vars[list(p.block.unknowns)] = True
    nominal = run.model.designs(run.model.nominal_values()[None, :])
    cur = np.broadcast_to(sys.q0, d.q_start.shape).copy()
    for step in range(1, ASSEMBLY_STEPS + 1):
        dl = nominal.blend(d, step / ASSEMBLY_STEPS)
        st = _State(len(d), 1, sys.n_angles, len(sys.slider_names))
        _impose(run, st, dl, np.zeros(1))
        sub = _Flags(flags.assembled.copy(), flags.assembled.copy(), [""] * len(d), np.ones(len(d)))
        _solve_blocks(run, st, dl, np.zeros(1), np.zeros(1, int), np.where(newton_vars, cur, d.q_start), sub)
        for v in np.nonzero(flags.assembled & ~sub.assembled)[0]:
            flags.refuse(np.arange(len(d)) == v, sub.why[v])
        cur = np.concatenate([st.TH[:, 0], st.S[:, 0, :-1]], axis=1)
    return np.where(newton_vars, cur, d.q_start)


# ---------------------------------------------------------------- outputs


def _point_sum(st: _State, d: Designs, sys: LoopSystem, rows: np.ndarray, pi: int, what: str) -> np.ndarray:
    """A joint's or point's position (what="p"), velocity ("v") or acceleration ("a"), complex, over rows."""
    out: np.ndarray | complex = 0j
    for t in np.nonzero(sys.path[:, pi])[0]:
        c = sys.path[t, pi]
        a, s = int(sys.t_ang[t]), int(sys.t_sl[t])
        e = d.cd[:, t, None] * st.E[:, rows, a]
        z = (d.r[:, t, None] + st.S[:, rows, s]) * e
        if what == "p":
            val = z
        elif a < 0 and s < 0:
            continue
        else:
            w, sd = st.W[:, rows, a], st.SD[:, rows, s]
            if what == "v":
                val = sd * e + 1j * w * z
            else:
                val = (st.SDD[:, rows, s] + 2j * sd * w) * e + (1j * st.AL[:, rows, a] - w * w) * z
        out = out + c * val
    return np.broadcast_to(out, (st.E.shape[0], len(rows))) if np.ndim(out) < 2 else out


def columns(run: _Run, st: _State, d: Designs, rows: np.ndarray, names: list[str]) -> dict[str, np.ndarray]:
    """The Result columns ``names`` (``LINK.theta``, ``POINT.ax``, ``SLIDER.v`` ...) at internal ``rows``, (V, n)."""
    sys = run.model.system
    links = {name: (a, j) for j, (name, a, _) in enumerate(sys.link_outputs)}
    out: dict[str, np.ndarray] = {}
    cache: dict[tuple[int, str], np.ndarray] = {}
    for col in names:
        ent, fld = col.rsplit(".", 1)
        if ent in links and fld in ("theta", "omega", "alpha"):
            a, j = links[ent]
            if a < 0:
                val = (d.out_offset[:, j, None] % TWO_PI) if fld == "theta" else np.zeros((len(d), 1))
                out[col] = np.broadcast_to(val, (len(d), len(rows))).copy()
            else:
                arr = {"theta": st.TH, "omega": st.W, "alpha": st.AL}[fld][:, rows, a]
                out[col] = arr + d.out_offset[:, j, None] if fld == "theta" else arr.copy()
        elif ent in sys.slider_names and fld in ("s", "v", "a"):
            i = sys.slider_names.index(ent)
            out[col] = {"s": st.S, "v": st.SD, "a": st.SDD}[fld][:, rows, i].copy()
        else:
            pi = sys.point_names.index(ent)
            what = {"x": "p", "y": "p", "vx": "v", "vy": "v", "ax": "a", "ay": "a"}[fld]
            if (pi, what) not in cache:
                cache[(pi, what)] = _point_sum(st, d, sys, rows, pi, what)
            z = cache[(pi, what)]
            out[col] = z.imag.copy() if fld.endswith("y") else z.real.copy()
    return out


def column_names(sys: LoopSystem) -> list[str]:
    """Every Result column a solve of this system gives."""
    cols = [f"{name}.{f}" for name, _, _ in sys.link_outputs for f in ("theta", "omega", "alpha")]
    cols += [f"{p}.{f}" for p in sys.point_names for f in ("x", "y", "vx", "vy", "ax", "ay")]
    cols += [f"{s}.{f}" for s in sys.slider_names for f in ("s", "v", "a")]
    return cols


# ---------------------------------------------------------------- the batch, and the single runs it hands on


@dataclass
class Outcomes:
    """Per variant: whether it assembled, whether the motion completed, where it stopped and why, the worst
    condition number, which solver gave it ("batch" or "single"), and its t = 0 joint positions and variables."""

    assembled: np.ndarray
    completed: np.ndarray
    stopped_at: np.ndarray
    stopped_sample: np.ndarray
    reason: list[str]
    max_cond: np.ndarray
    solver: list[str]
    positions: np.ndarray  # (V, n_points) complex, t = 0
    q0: np.ndarray  # (V, n_vars): the assembled variables at t = 0 (NaN where not assembled)

    @classmethod
    def empty(cls, n: int, n_points: int, n_vars: int) -> Self:
        """n variants that did not assemble (a subclass's other fields at their defaults)."""
        return cls(
            np.zeros(n, bool),
            np.zeros(n, bool),
            np.full(n, np.nan),
            np.full(n, -1, np.int64),
            [""] * n,
            np.full(n, np.nan),
            [""] * n,
            np.full((n, n_points), np.nan + 0j),
            np.full((n, n_vars), np.nan),
        )

    def fill(self, rows: np.ndarray, res: Outcomes) -> None:
        """Take ``res``'s variants into the rows where ``rows`` (a mask) is set."""
        idx = np.nonzero(rows)[0]
        for name in ("assembled", "completed", "stopped_at", "stopped_sample", "max_cond", "positions", "q0"):
            getattr(self, name)[idx] = getattr(res, name)
        for k, i in enumerate(idx):
            self.reason[i], self.solver[i] = res.reason[k], res.solver[k]

    @classmethod
    def join(cls, parts: list[Outcomes]) -> Outcomes:
        return cls(
            *(
                [x for p in parts for x in getattr(p, f.name)]
                if f.name in ("reason", "solver")
                else np.concatenate([getattr(p, f.name) for p in parts])
                for f in dataclasses.fields(Outcomes)
            )
        )


@dataclass
class BatchOut(Outcomes):
    """What a batch gives for V variants: the Outcomes and the columns (V, n requested samples), NaN where a
    variant has no motion."""

    columns: dict[str, np.ndarray] = field(default_factory=dict)


DOUBTFUL = 'doubtful: not solved on its own (solve(..., doubtful="fail"))'


def solve(
    model: VariantModel, values: np.ndarray, grid: Grid, names: list[str], *, doubtful: str = "single"
) -> BatchOut:
    """Solve the variants whose parameter values are the rows of ``values`` on ``grid``; columns ``names``.

    ``doubtful``: what happens to a variant the batch is not sure of (module docstring): "single" (default)
    solves it again with the single-run solver, which locates its limits and change points; "fail" reports it
    as not completed (reason :data:`DOUBTFUL`, columns NaN) without solving it again — for a search that only
    wants the variants the batch takes as they are (a synthesis scoring a random population, where many
    variants reach limits and each single run would cost more than the whole batch)."""
    if doubtful not in ("single", "fail"):
        raise ValueError(f"doubtful must be 'single' or 'fail', got {doubtful!r}")
    run = _Run.build(model)
    values = np.atleast_2d(np.asarray(values, float))
    V = len(values)
    N = len(grid.out)
    sys = model.system
    out = BatchOut.empty(V, len(sys.point_names), sys.n_vars)
    out.columns = {c: np.full((V, N), np.nan) for c in names}
    per = max(1, ROWS // max(len(grid.t), 1))
    for lo in range(0, V, per):
        hi = min(lo + per, V)
        with np.errstate(all="ignore"):
            _solve_chunk(run, values[lo:hi], grid, names, out, lo, doubtful == "single")
    return out


def _solve_chunk(
    run: _Run, values: np.ndarray, grid: Grid, names: list[str], out: BatchOut, lo: int, single: bool = True
) -> None:
    model, sys = run.model, run.model.system
    d = model.designs(values)
    V = len(d)
    flags = _Flags.new(V)
    start = _assemble_newton(run, d, flags)
    st = _State(V, len(grid.t), sys.n_angles, len(sys.slider_names))
    flags.doubt(_impose(run, st, d, grid.t))
    _solve_blocks(run, st, d, grid.t, grid.out, start, flags)
    cols = columns(run, st, d, grid.out, names)
    finite = np.ones(V, bool)
    for arr in cols.values():
        finite &= np.all(np.isfinite(arr), axis=1)
    flags.doubt(~finite)
    pos = (
        np.stack([_point_sum(st, d, sys, np.zeros(1, int), pi, "p")[:, 0] for pi in range(len(sys.point_names))], 1)
        if sys.point_names
        else np.zeros((V, 0), complex)
    )
    sl = slice(lo, lo + V)
    ok = flags.regular
    for c in names:
        out.columns[c][sl][ok] = cols[c][ok]
    out.assembled[sl] = flags.assembled
    out.completed[sl] = ok
    out.max_cond[sl] = np.where(ok, flags.cond, np.nan)
    out.positions[sl] = np.where(flags.assembled[:, None], pos, np.nan)
    q0 = np.concatenate([st.TH[:, 0], st.S[:, 0, :-1]], axis=1)
    out.q0[sl] = np.where(flags.assembled[:, None], q0, np.nan)
    for v in range(V):
        if ok[v]:
            out.solver[lo + v] = "batch"
        elif not flags.assembled[v]:
            out.reason[lo + v] = flags.why[v]
        elif not single:
            out.reason[lo + v] = DOUBTFUL
        else:
            _single(run, values[v], d.take(slice(v, v + 1)), q0[v], pos[v], grid, names, out, lo + v)


def variant_system(model: VariantModel, values: np.ndarray, d: Designs, q0: np.ndarray, positions: np.ndarray):
    """The variant's own Mechanism (coordinates at its t = 0 assembly) and LoopSystem (the nominal structure
    with its constants), as ``vloop.compile`` of that variant's file would give them."""
    sys = model.system
    mech = model.variant_mechanism(values, dict(zip(sys.point_names, positions.tolist(), strict=True)), q0)
    outputs = tuple((name, a, float(d.out_offset[0, j])) for j, (name, a, _) in enumerate(sys.link_outputs))
    system = dataclasses.replace(
        sys,
        mechanism=mech,
        t_r=d.r[0].copy(),
        t_delta=d.delta[0].copy(),
        q0=np.asarray(q0, float),
        coords_q=d.coords_q[0].copy(),
        link_outputs=outputs,
        cache={},
    )
    return mech, system


def _single(
    run: _Run,
    values: np.ndarray,
    d: Designs,
    q0: np.ndarray,
    pos: np.ndarray,
    grid: Grid,
    names: list[str],
    out: BatchOut,
    v: int,
) -> None:
    """Solve one variant with the single-run solver; record its columns or where and why it stopped."""
    from .solver import solve as solve_system

    out.solver[v] = "single"
    try:
        _, system = variant_system(run.model, values, d, q0, pos)
        res = solve_system(system, grid.times)
    except MotionError as exc:
        out.reason[v] = str(exc)
        t_stop = getattr(exc, "limit_time", None)
        out.stopped_at[v] = t_stop if t_stop is not None else (exc.time if exc.time is not None else np.nan)
        out.stopped_sample[v] = exc.sample if exc.sample is not None else 0
        return
    except VloopError as exc:
        out.reason[v] = str(exc)
        out.stopped_sample[v] = 0
        return
    except (ArithmeticError, ValueError, np.linalg.LinAlgError) as exc:  # numbers no solver can work with
        out.reason[v] = f"{run.model.mechanism.name}: this variant cannot be solved ({type(exc).__name__}: {exc})"
        out.stopped_sample[v] = 0
        return
    for c in names:
        out.columns[c][v] = res.columns[c]
    out.completed[v] = True
    out.max_cond[v] = float(np.max(res.health["cond"])) if len(res.health.get("cond", ())) else np.nan
