"""Solver checks against independent references: finite differences, geometry, exact inputs."""

from __future__ import annotations

import math

import numpy as np
import pytest

import vloop
from tests.conftest import MECHANISMS, mechanism_files
from vloop.result import LINK_FIELDS, POINT_FIELDS, SLIDER_FIELDS

FD_POINTS = 20001  # central differences over the run: h = span / 20000


def fine_run(path):
    """Solve on a fine grid over the file's span; for a run that stops at a limit, keep 80 % of what was solved."""
    mech = vloop.load(path)
    t = np.linspace(mech.times[0], mech.times[-1], FD_POINTS)
    try:
        return vloop.solve(mech, t)
    except vloop.MotionError as exc:
        n = int(0.8 * len(exc.partial))
        assert n > 100, f"{path.name}: too few samples before the failure to difference"
        return exc.partial.head(n)


def derivative_pairs(res):
    pairs = []
    for n in res.names("link"):
        pairs += [(f"{n}.theta", f"{n}.omega"), (f"{n}.omega", f"{n}.alpha")]
    for n in res.names("point"):
        pairs += [(f"{n}.x", f"{n}.vx"), (f"{n}.y", f"{n}.vy"), (f"{n}.vx", f"{n}.ax"), (f"{n}.vy", f"{n}.ay")]
    for n in res.names("slider"):
        pairs += [(f"{n}.s", f"{n}.v"), (f"{n}.v", f"{n}.a")]
    return pairs


def five_point(x: np.ndarray, h: float) -> np.ndarray:
    """Central difference x'(t) ≈ (x(t−2h) − 8x(t−h) + 8x(t+h) − x(t+2h))/12h at the interior samples:
    truncation h⁴/30·x⁽⁵⁾, round-off ~1.5·ε·|x|/h."""
    return (x[:-4] - 8 * x[1:-3] + 8 * x[3:-1] - x[4:]) / (12 * h)


@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_rates_match_central_differences(path):
    """Velocities against differences of positions, accelerations against differences of velocities.

    h = span/20000 keeps the h⁴ truncation below 1e-9 of each peak for these runs (their fastest
    harmonics turn ≲ 0.01 rad per step) and the round-off ε·|x|/h below 1e-9 too; a tabulated input
    (a cubic spline) adds an O(h²) error at its knots, < 1e-7 here. Asserted: 1e-6 of the peak of the
    derivative (or 1e-3 of its group's peak, for quantities that stay near zero)."""
    res = fine_run(path)
    h = res.t[1] - res.t[0]
    errs = {dq: np.max(np.abs(five_point(res[q], h) - res[dq][2:-2])) for q, dq in derivative_pairs(res)}
    group_peak: dict[str, float] = {}
    for dq in errs:
        g = dq.rsplit(".", 1)[1]
        group_peak[g] = max(group_peak.get(g, 0.0), np.max(np.abs(res[dq])))
    for dq, err in errs.items():
        g = dq.rsplit(".", 1)[1]
        scale = max(np.max(np.abs(res[dq])), 1e-3 * group_peak[g])
        assert err <= 1e-6 * scale, (
            f"{path.stem}: {dq} differs from the central difference by {err:.3g} ({err / scale:.2g} of scale)"
        )


@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_link_lengths_stay_rigid(path):
    """Geometry, independent of the loop equations: every binary link keeps its t = 0 length."""
    mech = vloop.load(path)
    try:
        res = vloop.solve(mech)
    except vloop.MotionError as exc:
        res = exc.partial
    bodies = mech.bodies()
    for name, lk in mech.links.items():
        if lk.ground or len(lk.joints) < 2:
            continue
        a, b = lk.joints[:2]
        d = np.hypot(res[f"{b}.x"] - res[f"{a}.x"], res[f"{b}.y"] - res[f"{a}.y"])
        assert np.max(np.abs(d - bodies[name].local[b][0])) < 1e-12 * mech.scale, name


@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_newton_agrees_with_closed_form_blocks(path):
    """The Newton path and the closed-form path are different algorithms on the same equations."""
    mech = vloop.load(path)
    try:
        a = vloop.solve(mech, method="auto")
    except vloop.MotionError as exc:
        a = exc.partial
    try:
        b = vloop.solve(mech, method="newton")
    except vloop.MotionError as exc:
        b = exc.partial
    n = min(len(a), len(b))
    # near a limit position the two may stop one sample apart; compare what both solved, away from it
    n = n if n == len(vloop.load(path).times) else max(n - 3, 0)
    from vloop.compare import assert_histories_close

    assert_histories_close(a.head(n), b.head(n), rtol=1e-9)


def test_start_time_not_zero_continues_from_the_t0_assembly(eightbar_path):
    mech = vloop.load(eightbar_path)
    full = vloop.solve(mech)
    later = vloop.solve(mech, full.t[20:])
    for c in full.columns:
        assert np.allclose(later[c], full[c][20:], rtol=0, atol=1e-12 * max(1, np.max(np.abs(full[c])))), c


def test_every_output_column_present(eightbar_path):
    mech = vloop.load(eightbar_path)
    res = vloop.solve(mech)
    expected = [f"{n}.{f}" for n in mech.moving_links for f in LINK_FIELDS]
    expected += [f"{n}.{f}" for n in mech.tracked_points for f in POINT_FIELDS]
    expected += [f"{n}.{f}" for n in mech.sliders for f in SLIDER_FIELDS]
    assert list(res.columns) == expected
    assert all(np.all(np.isfinite(v)) for v in res.columns.values())


def test_angles_are_continuous(eightbar_path):
    mech = vloop.load(eightbar_path)
    res = vloop.solve(mech, np.linspace(0, 2 * 2 * math.pi / 3, 401))  # two crank turns
    for n in res.names("link"):
        assert np.max(np.abs(np.diff(res[f"{n}.theta"]))) < 0.2, n
    assert res["l2.theta"][-1] - res["l2.theta"][0] == pytest.approx(4 * math.pi)


def test_tabulated_crank_profile_equals_the_formula(tmp_path):
    """A CSV profile θ = θ0 + ω0·t + α·t²/2 (a cubic spline reproduces a parabola exactly) gives the same motion."""
    text = (MECHANISMS / "eightbar.toml").read_text()
    t = np.linspace(0, 2.35, 48)
    theta = math.pi / 2 + 3.0 * t + 0.5 * 0.7 * t**2
    np.savetxt(tmp_path / "crank.csv", np.column_stack([t, theta]), delimiter=",", header="t,theta", comments="")
    (tmp_path / "eb.toml").write_text(text.replace("omega = 3.0   # rad/s\nalpha = 0.0", 'profile = "crank.csv"'))
    (tmp_path / "ref.toml").write_text(text.replace("alpha = 0.0", "alpha = 0.7"))
    a = vloop.solve(vloop.load(tmp_path / "eb.toml"))
    b = vloop.solve(vloop.load(tmp_path / "ref.toml"))
    from vloop.compare import assert_histories_close

    assert_histories_close(a, b, rtol=1e-10)


def test_driven_slider_runs_the_eightbar_backwards(tmp_path):
    """Drive slider l4 with a linear actuator: the crank follows; check rigidity and finite differences."""
    text = (MECHANISMS / "eightbar.toml").read_text()
    text = text.replace(
        'link = "l2"\npivot = "O2"\nomega = 3.0   # rad/s\nalpha = 0.0   # rad/s^2', 'slider = "l4"\nv = 0.5\na = 0.2'
    )
    text = text.replace("stop = 2.35", "stop = 2.0")
    (tmp_path / "act.toml").write_text(text)
    mech = vloop.load(tmp_path / "act.toml")
    t = np.linspace(0, 2.0, 20001)
    res = vloop.solve(mech, t)
    assert np.allclose(res["l4.s"], 4 + 0.5 * t + 0.1 * t**2, atol=1e-14)
    assert np.allclose(np.hypot(res["A.x"], res["A.y"]), 3.0, atol=1e-12)
    h = t[1] - t[0]
    fd = (res["l2.theta"][2:] - res["l2.theta"][:-2]) / (2 * h)
    assert np.max(np.abs(fd - res["l2.omega"][1:-1])) < 1e-6 * np.max(np.abs(res["l2.omega"]))


def test_a_solved_mechanism_is_compiled_once_and_freed_with_its_system(monkeypatch):
    """vloop.solve keeps a Mechanism's LoopSystem on the object (a second solve compiles nothing) and lets both go
    when the mechanism is dropped: the system refers back to the mechanism, and a registry of its own once kept
    every mechanism ever solved (a validation worker grew by ~45 kB a mechanism). Pickling leaves it out."""
    import gc
    import pickle
    import weakref

    from vloop import compiler

    calls = []
    compile_system = compiler.compile_system
    monkeypatch.setattr(compiler, "compile_system", lambda *a, **k: calls.append(a[0].name) or compile_system(*a, **k))
    mech = vloop.load(MECHANISMS / "slider_crank_offset.toml")  # coordinates as written: compiled by solve
    first, again = vloop.solve(mech), vloop.solve(mech)
    assert len(calls) == 1 and np.array_equal(first["l3.alpha"], again["l3.alpha"])
    copy = pickle.loads(pickle.dumps(mech))
    assert len(vloop.solve(copy)) == len(first) and len(calls) == 2
    gone = weakref.ref(mech)
    del mech, copy, first, again
    gc.collect()
    assert gone() is None
