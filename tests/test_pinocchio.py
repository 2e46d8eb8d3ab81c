"""The independent Pinocchio engine (validators/pinocchio.py) against vloop, closed forms,
finite differences of itself, and itself on another kinematic tree.

Every catalog mechanism (mechanisms/*.toml, globbed at collection time) is checked.
Tolerances (scale-relative, see vloop.compare):

* vs vloop and vs closed forms: rtol = 1e-9 (the project's target; both engines
  converge Newton to round-off, measured agreement is ~1e-13).
* another root / cut set: rtol = 1e-10 — the same equations written on another
  tree differ only by round-off (measured ~1e-14).
* finite differences: see FD_RTOL below.
"""

from __future__ import annotations

import functools
import importlib
import importlib.util
import itertools
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import vloop
from tests.conftest import ROOT, mechanism_files
from vloop.compare import assert_histories_close
from vloop.drivers import evaluate_all
from vloop.errors import MotionError
from vloop.mechanism import Mechanism
from vloop.result import Result

pytest.importorskip("pinocchio")

from validators import pinocchio as vpin  # after the importorskip on purpose

MECH_FILES = mechanism_files()  # globbed at collection time
MECH_IDS = [p.stem for p in MECH_FILES]

RTOL_REFERENCE = 1e-9
RTOL_TREE = 1e-10
# Five-point central differences over ±h, ±h/2 with h = 3e-3 of the sampling step.
# Truncation (h/2)⁴·|f⁽⁵⁾|/30 is ~(ω·h)⁴/500 ≈ 1e-15 of the peak for the catalog's ω·dt ≲ 0.3 rad;
# what remains is the engine's round-off (~1e-15 relative in positions, ~cond·ε in velocities)
# amplified by 1/(ω·h) ≈ 1e3: measured ≤ 2e-10 of the peak, and 1e-9 for a five-bar sampled
# 0.05 rad before its limit position, where the derivatives grow like powers of
# 1/(distance to the limit). FD_RTOL = 1e-7 keeps a margin of 100 over that worst case; an
# error in a velocity or acceleration formula (a missing J̇·q̇ term) shows up at ~1e-2.
FD_STEP = 3e-3
FD_RTOL = 1e-7
FD_FLOOR = 1e-10  # of the group's peak: round-off / h on quantities that stay near zero
FD_MAX_CENTERS = 60


@functools.cache
def _mech(path: Path) -> Mechanism:
    return vloop.load(path)


@functools.cache
def _pin(path: Path, **options: object) -> tuple[Result, MotionError | None]:
    """Pinocchio result (or the partial one and the error) with cached solves."""
    try:
        return vpin.solve(_mech(path), **options), None
    except MotionError as exc:
        return exc.partial, exc


def _slice(r: Result, idx: np.ndarray | slice) -> Result:
    return Result(r.mechanism, r.engine, r.t[idx], {k: v[idx] for k, v in r.columns.items()})


def _agree_or_fail_alike(
    a: Result, a_err: MotionError | None, b: Result, b_err: MotionError | None, rtol: float
) -> None:
    """Both complete and agree, or both stop with MotionError and agree where both solved."""
    if (a_err is None) != (b_err is None):
        stopped = a_err or b_err
        raise AssertionError(f"only {'the first' if a_err else 'the second'} engine stopped: {stopped}")
    n = min(len(a), len(b))
    if n:  # (both stopping at the first sample is agreement too)
        assert_histories_close(a.head(n), b.head(n), rtol, min_columns=len(a.columns))


# ---------------------------------------------------------------- (a) vs vloop


@pytest.mark.parametrize("path", MECH_FILES, ids=MECH_IDS)
def test_matches_vloop(path: Path) -> None:
    if importlib.util.find_spec("vloop.core.solver") is None:
        pytest.skip("vloop.core.solver is not written yet: vloop.solve is unavailable")
    mech = _mech(path)
    try:
        ref, ref_err = vloop.solve(mech), None
    except MotionError as exc:
        ref, ref_err = exc.partial, exc
    res, err = _pin(path)
    _agree_or_fail_alike(res, err, ref, ref_err, RTOL_REFERENCE)


# ---------------------------------------------------------------- (b) vs closed forms


@pytest.mark.parametrize("path", MECH_FILES, ids=MECH_IDS)
def test_matches_closed_form(path: Path) -> None:
    try:
        analytic = importlib.import_module("validators.analytic")
    except ModuleNotFoundError:
        pytest.skip("validators.analytic (closed-form dispatch) is not written yet")
    mech = _mech(path)
    if not analytic.available(mech):
        pytest.skip(f"no closed form applies to {mech.name}")
    try:
        ref, ref_err = analytic.solve(mech), None
    except analytic.LimitPositionError as exc:  # the closed form's own "cannot assemble"
        ref, ref_err = exc.partial, exc
    res, err = _pin(path)
    if (err is None) != (ref_err is None):
        raise AssertionError(f"only {'pinocchio' if err else 'the closed form'} stopped: {err or ref_err}")
    if err is not None:
        assert err.sample == ref_err.sample, f"pinocchio: {err}\nclosed form: {ref_err}"
    n = min(len(res), len(ref)) if ref is not None else 0
    if n:
        assert_histories_close(res.head(n), ref.head(n), RTOL_REFERENCE, min_columns=len(ref.columns))


# ---------------------------------------------------------------- finite differences of itself


STENCIL = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])  # times c + STENCIL·h around each centre c


def _fd(values: np.ndarray, h: float) -> np.ndarray:
    """Five-point central difference (rows: centres, columns: STENCIL), error (h/2)⁴·f⁽⁵⁾/30."""
    return (values[:, 0] - 8 * values[:, 1] + 8 * values[:, 3] - values[:, 4]) / (6 * h)


def _fd_results(r: Result, mech: Mechanism, h: float) -> tuple[Result, Result]:
    """From a solve on the stencil grid: Pinocchio at the centres and the central differences
    of its positions (→ velocities) and of its velocities (→ accelerations)."""
    k = len(STENCIL)
    n = len(r) // k
    st = {c: v[: k * n].reshape(n, k) for c, v in r.columns.items()}
    cols: dict[str, np.ndarray] = {}
    for b in mech.moving_links:
        cols[f"{b}.omega"], cols[f"{b}.alpha"] = _fd(st[f"{b}.theta"], h), _fd(st[f"{b}.omega"], h)
    for p in mech.tracked_points:
        for pos, vel, acc in (("x", "vx", "ax"), ("y", "vy", "ay")):
            cols[f"{p}.{vel}"], cols[f"{p}.{acc}"] = _fd(st[f"{p}.{pos}"], h), _fd(st[f"{p}.{vel}"], h)
    for s in mech.sliders:
        cols[f"{s}.v"], cols[f"{s}.a"] = _fd(st[f"{s}.s"], h), _fd(st[f"{s}.v"], h)
    t = r.t[: k * n].reshape(n, k)[:, k // 2]
    centre = Result(r.mechanism, "pinocchio", t, {c: st[c][:, k // 2] for c in cols})
    return centre, Result(r.mechanism, "central differences", t, cols)


@pytest.mark.parametrize("path", MECH_FILES, ids=MECH_IDS)
def test_finite_differences(path: Path) -> None:
    mech = _mech(path)
    tt = np.asarray(mech.times, float)
    if len(tt) < 3:
        pytest.skip("fewer than three samples")
    centres = tt[1:-1][:: max(1, math.ceil((len(tt) - 2) / FD_MAX_CENTERS))]  # inside any profile's range
    h = FD_STEP * float(np.median(np.diff(tt)))
    # keep the centres where the prescribed inputs are themselves smooth and consistent
    # (a tabulated profile's spline has jumps in its third derivative at the knots)
    ins = [
        a.reshape(len(centres), len(STENCIL), -1) for a in evaluate_all(mech, (centres[:, None] + STENCIL * h).ravel())
    ]
    ok = np.ones(len(centres), bool)
    for lo, hi in itertools.pairwise(ins):  # (x, ẋ) then (ẋ, ẍ)
        ok &= np.all(np.abs(_fd(lo, h) - hi[:, 2]) <= FD_RTOL * max(1.0, float(np.max(np.abs(hi)))), axis=1)
    if not np.any(ok):
        pytest.skip(f"{mech.name}: the prescribed input rates are not derivatives of the input anywhere")
    grid = (centres[ok][:, None] + STENCIL * h).ravel()
    try:
        r = vpin.solve(mech, grid)
    except MotionError as exc:
        r = exc.partial
        assert len(r) >= len(STENCIL), f"stopped before the first finite-difference stencil: {exc}"
    centre, fd = _fd_results(r, mech, h)
    assert_histories_close(centre, fd, FD_RTOL, floor=FD_FLOOR, min_columns=len(fd.columns))


# ---------------------------------------------------------------- another tree, same answer


def _variants(mech: Mechanism) -> dict[str, dict]:
    """A floating root with reversed cut preference, and the ground root with the other pins cut."""
    default = vpin.plan_tree(mech)
    cut = {j for j, _, _ in default.cuts}
    pins = [j for j in mech.joints if len(mech.bodies_at(j)) >= 2]
    return {
        "floating-root": {"root": mech.moving_links[-1], "cut_preference": tuple(reversed(pins))},
        "other-cuts": {"cut_preference": tuple(j for j in pins if j not in cut)},
    }


@pytest.mark.parametrize("variant", ["floating-root", "other-cuts"])
@pytest.mark.parametrize("path", MECH_FILES, ids=MECH_IDS)
def test_other_tree_same_answer(path: Path, variant: str) -> None:
    mech = _mech(path)
    options = _variants(mech)[variant]
    default, other = vpin.plan_tree(mech), vpin.plan_tree(mech, **options)
    if (default.root, default.cuts) == (other.root, other.cuts):
        pytest.skip(f"{mech.name}: no other cut set exists (no loop has a choice)")
    res, err = _pin(path)
    alt, alt_err = _pin(path, **options)
    _agree_or_fail_alike(alt, alt_err, res, err, RTOL_TREE)
    if err is not None:
        assert alt_err is not None and alt_err.sample == err.sample


# ---------------------------------------------------------------- model structure


@pytest.mark.parametrize("path", MECH_FILES, ids=MECH_IDS)
def test_tree_keeps_sliders_and_closes_every_pin(path: Path) -> None:
    mech = _mech(path)
    for options in (dict(), *_variants(mech).values()):
        plan = vpin.plan_tree(mech, **options)
        tree = [e for _, e in plan.parent.values()]
        assert sorted(e.b for e in tree if e.kind == "slider") == sorted(mech.sliders)
        for j in mech.joints:  # a pin of order k: k equalities, in the tree or cut
            n_tree = sum(e.kind == "pin" and e.joint == j for e in tree)
            assert n_tree + sum(c[0] == j for c in plan.cuts) == mech.pin_order(j), j
        L, J, _ = mech.gruebler()
        assert len(plan.cuts) == J - (L - 1)  # one cut per independent loop


def _matrices_of_every_conditioning(count: int = 400) -> list[np.ndarray]:
    """U·diag(σ)·Vᵀ with cond₂ = 10^k, k uniform in [0, 17], sizes 2 to 9, columns then scaled as a mechanism's
    (lengths in mm next to angles), plus matrices that are exactly singular or badly scaled."""
    rng = np.random.default_rng(36)
    out = []
    for k in rng.uniform(0.0, 17.0, count):
        n = int(rng.integers(2, 10))
        U, _ = np.linalg.qr(rng.standard_normal((n, n)))
        V, _ = np.linalg.qr(rng.standard_normal((n, n)))
        out.append((U * np.logspace(0.0, -k, n)) @ V.T * rng.choice([1.0, 250.0], n))
    out += [np.zeros((3, 3)), np.array([[1.0, 2.0], [2.0, 4.0]]), np.diag([1.0, 1e-200, 1e150])]
    return out


def test_condition_check_is_numpys() -> None:
    """The singular-position check gives numpy.linalg.cond's verdict, and its number where it is computed: the
    determinant bound certifies only matrices whose SVD condition number is below CERTAIN_COND of the limit."""
    for J in _matrices_of_every_conditioning():
        cond = np.linalg.cond(J)
        assert vpin._cond2(J) == cond or (np.isinf(cond) and np.isinf(vpin._cond2(J)))
        for max_cond in (1e12, 1e6, 1e3):
            if vpin._well_conditioned(J, float(np.linalg.det(J)), max_cond):
                assert cond <= vpin.CERTAIN_COND * max_cond * (1 + 1e-9), (cond, max_cond)


def test_health_condition_numbers_are_the_single_ones() -> None:
    """The health's cond, computed for every sample at once, is tolerances.condition_number of each sample's
    Jacobian (the function the Exudyn engine calls sample by sample), exactly."""
    from validators.tolerances import condition_number, condition_numbers

    path = next(p for p in MECH_FILES if p.stem == "sixbar_watt2")
    res, _ = _pin(path)
    pm = vpin.build_model(_mech(path))
    solver = vpin._Solver(pm, 1e-10, 50, 8, 1e12)
    x = evaluate_all(pm.mech, res.t)[0]
    for k in range(0, len(res), 7):
        J = solver.w.residual(res.meta["q"][k], x[k], True)[1]
        assert res.health["cond"][k] == condition_number(J, solver.lengths, pm.mech.scale)
        # a regular position is certified without an SVD (the check's shortcut is not vacuous)
        assert vpin._well_conditioned(J, float(np.linalg.det(J)), 1e12)
    assert len(condition_numbers(np.zeros((0, 3, 3)), np.zeros(3, bool), 1.0)) == 0


def test_vloop_imports_without_pinocchio() -> None:
    code = "import sys; sys.modules['pinocchio'] = None; import vloop, validators.pinocchio; print('ok')"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=False)
    assert out.stdout.strip() == "ok", out.stderr


# ---------------------------------------------------------------- motion errors and branches

# Non-Grashof four-bar (a = 4.5, b = 3, c = 4, d = 5): the crank cannot pass
# |O4A| = b + c, i.e. θ_crank = acos(−3.75/45) ≈ 1.6542 rad, reached at t ≈ 0.607 s.
NON_GRASHOF = """
name = "nongrashof_inline"
[joints]
O2 = [0.0, 0.0]
A = [2.2500000000000004, 3.8971143170299736]
B = [1.1553557645292445, 1.103952309957945]
O4 = [5.0, 0.0]
[links]
ground = { joints = ["O2", "O4"], ground = true }
crank = { joints = ["O2", "A"] }
coupler = { joints = ["A", "B"] }
rocker = { joints = ["O4", "B"] }
[[drivers]]
link = "crank"
omega = 1.0
[time]
start = 0.0
stop = 2.0
step = 0.05
"""


def test_motion_error_names_the_sample_and_keeps_the_solved_ones() -> None:
    mech = vloop.loads(NON_GRASHOF)
    t_limit = math.acos(-3.75 / 45.0) - math.pi / 3
    with pytest.raises(MotionError) as info:
        vpin.solve(mech)
    err = info.value
    k = int(np.searchsorted(mech.times, t_limit))  # first sample past the limit
    assert err.sample == k and err.time == pytest.approx(mech.times[k])
    msg = str(err)
    assert "\n" not in msg and f"sample {k}" in msg and f"t = {mech.times[k]:g} s" in msg and "θ_crank = " in msg
    assert len(err.partial) == k and err.partial.engine == "pinocchio"
    head = vpin.solve(mech, mech.times[:k])  # the partial is what a shorter run gives
    assert_histories_close(err.partial, head, 1e-12)
    # and it is a real solution: B stays at the coupler length from A
    p = err.partial
    assert np.allclose(np.hypot(p["B.x"] - p["A.x"], p["B.y"] - p["A.y"]), 3.0, rtol=0, atol=1e-12)


@pytest.mark.parametrize("path", MECH_FILES, ids=MECH_IDS)
def test_late_start_and_coarse_sampling_stay_on_the_branch(path: Path) -> None:
    """Starting at times[0] > 0 continues from the t = 0 assembly, and coarse samples are
    joined by continuation, so both give the samples of the full run (not the other
    assembly branch, e.g. for *_crossed files)."""
    full, _ = _pin(path)
    k = len(full) // 3
    if k == 0:
        pytest.skip("too few solved samples")
    for part in (slice(k, None), slice(k, None, 10)):
        sub = vpin.solve(_mech(path), full.t[part])
        assert_histories_close(sub, _slice(full, part), RTOL_TREE, min_columns=len(full.columns))


def test_angles_start_on_the_turn_of_the_coordinates() -> None:
    for path in MECH_FILES:
        mech = _mech(path)
        res, _ = _pin(path)
        if len(res) == 0 or mech.times[0] != 0:
            continue
        for name, body in mech.bodies().items():
            if name in mech.moving_links:
                assert abs(res[f"{name}.theta"][0] - body.theta0) < 1e-3, (path.stem, name)
