"""The batched linear algebra behind the fast Newton path, against numpy's LAPACK references, and the Newton
path itself against the hand closed forms and against the SVD rule for flags and refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest

import vloop
from tests.conftest import MECHANISMS
from tests.test_change_points import parallelogram
from validators import analytic
from vloop.compare import assert_histories_close
from vloop.core import accuracy, linalg, newton

RNG = np.random.default_rng(15)
EPS = np.finfo(float).eps
LEVEL = (accuracy.ILL_FRACTION * accuracy.DEFAULT_RTOL / EPS) ** (1 / 3)  # cond³·ε > 1e-3·rtol: flagged


def _stack(rows: int, n: int, cond: float | np.ndarray) -> np.ndarray:
    """Random (rows, n, n) matrices with singular values spread from 1 down to 1/cond (per row)."""
    U = np.linalg.qr(RNG.standard_normal((rows, n, n)))[0]
    V = np.linalg.qr(RNG.standard_normal((rows, n, n)))[0]
    s = np.exp(-np.linspace(0, 1, n)[None, :] * np.log(np.broadcast_to(cond, (rows,)))[:, None])
    return (U * s[:, None, :]) @ V.transpose(0, 2, 1) * np.exp(RNG.uniform(-20, 20, rows))[:, None, None]


def _last(A: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(A.transpose(1, 2, 0))


@pytest.mark.parametrize("n", [1, 2, 3, 4, 6, 8])
def test_invert_last_matches_lapack(n):
    A = np.concatenate([RNG.standard_normal((500, n, n)), _stack(500, n, RNG.uniform(1, 1e8, 500))])
    if n > 1:
        A[:50, 0, 0] = 0.0  # a structural zero on the diagonal: pivoting needed
    X, sign = linalg.invert_last(_last(A))
    X = X.transpose(2, 0, 1)
    ref = np.linalg.inv(A)
    err = np.abs(X - ref).max(axis=(1, 2)) / np.abs(ref).max(axis=(1, 2))
    assert np.all(err <= 10 * n * EPS * np.linalg.cond(A))  # LAPACK's own accuracy, ~cond·ε
    assert np.array_equal(sign, np.sign(np.linalg.det(A)))
    # a Newton step by the inverses (batch-last) against numpy.linalg.solve
    b = RNG.standard_normal((len(A), n))
    step = linalg.apply_last(X.transpose(1, 2, 0), b.T).T
    ref_step = np.linalg.solve(A, b[..., None])[..., 0]
    scale = np.abs(ref_step).max(axis=1)
    assert np.all(np.abs(step - ref_step).max(axis=1) <= 10 * n * EPS * np.linalg.cond(A) * scale)


def test_invert_last_on_structurally_sparse_stacks():
    """Entries zero in every matrix (a loop Jacobian's structure) are skipped: the inverses and signs still match
    LAPACK's, where every matrix pivots alike and where they pivot differently (the structures merged)."""
    for n in (4, 6, 8):
        mask = RNG.random((n, n)) < 0.35
        mask[np.arange(n), RNG.permutation(n)] = True  # structurally nonsingular
        A = RNG.standard_normal((600, n, n)) * mask
        A[:300] *= 10.0 ** RNG.uniform(-3, 3, (300, n, 1))  # rows of very different sizes: the pivots differ
        X, sign = linalg.invert_last(_last(A))
        X = X.transpose(2, 0, 1)
        ref = np.linalg.inv(A)
        err = np.abs(X - ref).max(axis=(1, 2)) / np.abs(ref).max(axis=(1, 2))
        assert np.all(err <= 10 * n * EPS * np.linalg.cond(A))
        assert np.array_equal(sign, np.sign(np.linalg.det(A)))


def test_invert_last_pivots_per_matrix_and_flags_singular_ones():
    A = RNG.standard_normal((7, 5, 5))
    A[0] = np.eye(5)[[3, 0, 4, 1, 2]]  # a permutation: odd, det −1
    A[1, 2] = 2.0 * A[1, 4]  # singular: exactly dependent rows
    A[2] = 0.0
    X, sign = linalg.invert_last(_last(A))
    X = X.transpose(2, 0, 1)
    assert np.array_equal(X[0], A[0].T) and sign[0] == -1.0
    assert sign[2] == 0.0 and not np.all(np.isfinite(X[2]))
    assert sign[1] == 0.0 or np.abs(X[1]).max() > 1e14  # rank-deficient: zero pivot, or one at round-off
    np.testing.assert_allclose(X[3:], np.linalg.inv(A[3:]), rtol=1e-10, atol=1e-12)
    assert np.array_equal(sign[3:], np.sign(np.linalg.det(A[3:])))


def test_cond_2norm_matches_svd():
    conds = np.concatenate([RNG.uniform(1, 100, 300), 10 ** RNG.uniform(2, 15, 300), [1.0, 99.99, 100.01]])
    for n in (2, 4, 6, 8):
        A = _stack(len(conds), n, conds)
        ref = np.linalg.cond(A)
        got = linalg.cond_2norm(A)
        ok = ref < 1e12  # beyond, SVD itself is not accurate: compare only the order of magnitude
        assert np.all(np.abs(got[ok] / ref[ok] - 1) <= 1e-10)
        assert np.all(np.abs(np.log10(got[~ok] / ref[~ok])) < 1)
    A = RNG.standard_normal((4, 3, 3))
    A[0, 1] = A[0, 0]  # singular
    A[1, 0, 0] = np.nan
    got = linalg.cond_2norm(A)
    assert got[0] > 1e15 and got[1] == np.inf
    np.testing.assert_allclose(got[2:], np.linalg.cond(A[2:]), rtol=1e-12)


@pytest.mark.parametrize("n", [2, 3, 6, 8])
def test_sigma_max_brackets_the_largest_eigenvalue(n):
    """The largest eigenvalue of Gram matrices by repeated squaring: where it claims a bracket, within 1e-12 of
    LAPACK's eigvalsh; it claims none where the two largest are too close to separate in 32 powers."""
    gaps = np.concatenate([RNG.uniform(0.0, 1.0, 1500), 1 - 10.0 ** RNG.uniform(-12, -1, 500), [1.0, 0.999]])
    s = np.sort(RNG.uniform(0.0, 1.0, (len(gaps), n)), axis=1)[:, ::-1]
    s[:, 1:] *= (gaps / np.where(s[:, 1] > 0, s[:, 1], 1.0))[:, None] * s[:, :1]  # λ₂/λ₁ = gaps
    U = np.linalg.qr(RNG.standard_normal((len(gaps), n, n)))[0]
    G = (U * s[:, None, :]) @ U.transpose(0, 2, 1)
    G /= np.trace(G, axis1=1, axis2=2)[:, None, None]
    lam, ok = linalg.sigma_max(G, G @ G)
    ref = np.linalg.eigvalsh(G)[:, -1]
    assert np.all(np.abs(lam[ok] / ref[ok] - 1) <= 1e-12)
    assert np.all(lam <= ref * (1 + 1e-14))  # a Rayleigh quotient: never above λ₁
    assert ok[gaps < 0.4].all() and not ok[gaps > 1 - 1e-3].any()


@pytest.mark.parametrize("n", [3, 6])
def test_condition_follows_the_svd_rule(n):
    """Upper bound everywhere, exact (to 1e-10) wherever the exact value reaches the flag level,
    so flags and refusals agree with SVD's: on random stacks from well-conditioned to singular."""
    conds = np.concatenate(
        [RNG.uniform(1, 2 * LEVEL, 2000), 10 ** RNG.uniform(1, 16, 500), [LEVEL * 0.999, LEVEL * 1.001]]
    )
    A = _stack(len(conds), n, conds)
    colscale = np.where(np.arange(n) % 2, 1.0, 0.25)  # angle columns divided by the mechanism size
    J = A / colscale  # so that J·colscale is A
    X = linalg.invert_last(_last(J))[0]
    got = linalg.condition_last(_last(J), X, colscale, accuracy.DEFAULT_RTOL)
    ref = np.linalg.cond(A)
    ok = ref < 1e12
    assert np.array_equal(got[ok] > LEVEL, ref[ok] > LEVEL)
    assert np.array_equal(got**2 * EPS > accuracy.DEFAULT_RTOL, ref**2 * EPS > accuracy.DEFAULT_RTOL)
    flagged = ok & (ref > LEVEL)
    tol = np.maximum(1e-10, 100 * ref * EPS)  # an SVD is itself reproducible to ~cond·ε (of J scaled, or not)
    assert np.all(np.abs(got[flagged] / ref[flagged] - 1) <= tol[flagged])
    assert np.all(got[ok] >= ref[ok] * (1 - tol[ok])) and np.all(got[ok] <= n * ref[ok])


def test_cis_series_matches_exp():
    for top in (1e-6, 1e-4, 1e-2, newton.SERIES):
        d = RNG.uniform(-top, top, (3, 1000))
        assert np.abs(newton._cis_series(d) - np.exp(1j * d)).max() <= 2 * EPS


# ---------------------------------------------------------------- the Newton path on mechanisms


@pytest.mark.parametrize(
    "name",
    [
        "eightbar",
        "fourbar_crank_rocker_crossed",
        "inverted_slider_crank",
        "sixbar_watt2",
        "jansen_pair",
        "whitworth_quick_return",
    ],
)
@pytest.mark.parametrize("steps", [7, 4800])
def test_newton_path_matches_the_closed_form(name, steps):
    mech = vloop.load(MECHANISMS / f"{name}.toml")
    if not analytic.available(mech):
        pytest.skip(f"no closed form for {name}")
    t = np.linspace(mech.times[0], mech.times[-1], steps)
    res = vloop.solve(mech, t, method="newton")
    assert_histories_close(res, analytic.solve(mech, t), rtol=1e-12, floor=1e-12, min_columns=10)
    auto = vloop.solve(mech, t)
    assert_histories_close(res, auto, rtol=1e-12, floor=1e-12, min_columns=10)


def _svd_condition(J: np.ndarray, X: np.ndarray, colscale: np.ndarray, rtol: float) -> np.ndarray:
    """The SVD rule: the Frobenius bound, replaced by numpy's SVD where it reaches the level."""
    Js = (J * colscale[:, None]).transpose(2, 0, 1)
    Xs = (X / colscale[:, None, None]).transpose(2, 0, 1)
    with np.errstate(invalid="ignore", over="ignore"):
        cond = np.sqrt(np.sum(Js * Js, axis=(1, 2)) * np.sum(Xs * Xs, axis=(1, 2)))
    cond = np.where(np.isfinite(cond), cond, np.inf)
    near = np.nonzero(cond > (accuracy.ILL_FRACTION * rtol / EPS) ** (1 / 3))[0]
    ok = near[np.all(np.isfinite(Js[near]), axis=(1, 2))]
    cond[ok] = np.linalg.cond(Js[ok])
    return cond


def _run(monkeypatch, reference: bool, mech: vloop.Mechanism, **kw) -> tuple[vloop.Result, str]:
    with monkeypatch.context() as m:
        if reference:
            m.setattr(newton, "condition_last", _svd_condition)
        try:
            return vloop.solve(mech, method="newton", **kw), ""
        except vloop.MotionError as exc:
            return exc.partial, str(exc)


@pytest.mark.parametrize("case", ["parallelogram", "eightbar", "past_limit"])
def test_flags_and_refusals_agree_with_svd(monkeypatch, case):
    """Health flags, condition numbers where flagged, refusals: the same as with numpy's SVD on every row
    whose Frobenius bound reaches the flag level — including samples next to a folding and a toggle."""
    kw = {}
    if case == "parallelogram":
        mech = parallelogram(alpha=0.0, step=0.001)  # three foldings: cond → ∞ around each
    elif case == "eightbar":
        mech = vloop.load(MECHANISMS / "eightbar.toml")
    else:
        mech = vloop.load(MECHANISMS / "fourbar_nongrashof_past_limit.toml")
        lim = math.acos((3.0**2 + 6.0**2 - 8.5**2) / (2 * 3.0 * 6.0))
        d = mech.drivers[0]
        kw["times"] = (lim - d.x0) / d.v0 - np.geomspace(1e-1, 1e-12, 400)
    res, err = _run(monkeypatch, False, mech, **kw)
    ref, ref_err = _run(monkeypatch, True, mech, **kw)
    assert err == ref_err and len(res) == len(ref)
    flags = res.health["ill_conditioned"].astype(bool)
    assert np.array_equal(flags, ref.health["ill_conditioned"].astype(bool))
    assert np.array_equal(res.health["change_point"], ref.health["change_point"])
    cond, ref_cond = res.health["cond"], ref.health["cond"]
    np.testing.assert_allclose(cond[flags], ref_cond[flags], rtol=1e-10)
    assert np.all(cond >= ref_cond * (1 - 1e-10) - (ref_cond > LEVEL))  # below the level: an upper bound
    if case == "eightbar":
        assert flags.sum() > 10  # the whole-system Newton block is flagged on part of the cycle
    if case == "past_limit":
        assert "toggle" in err and flags.sum() >= 1
