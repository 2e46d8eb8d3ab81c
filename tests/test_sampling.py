"""Any sampling gives the same motion: coarse samples over many turns (a chart of the input's range, no rows
inserted, Newton rows predicted from it) and many change points (all searched at once) against independent
references.

* The catalog's mechanisms sampled at 30° of input per sample over many turns against the same motion sampled
  16 times finer and solved without a chart (continuation from row to row, today's path), at the samples they
  share: every column, unwrapped angles to the turn, to 1e-12 of its peak (round-off of the peak: both runs close
  every loop to Newton's tolerance or exactly).
* The closed forms (validators.analytic: the four-bar by the law of cosines, the slider-crank by projection, the
  eight-bar's three RRP dyads and the Jansen pair, derived by hand) at 30°/sample over 100 turns, both methods:
  1e-12 of each column's peak as vloop.compare measures it, and the unwrapped angles to 1e-12 of their peak
  (measured 3e-15: every turn counted).
* Parallelogram and kite four-bars sampled coarsely over many turns: their change points are where the geometry
  says (θ2 = kπ), every one of them found, and the motion is the hand-derived one (test_change_points.py has the
  derivations).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

import vloop
from tests.conftest import MECHANISMS
from tests.test_change_points import PARALLELOGRAM, _kite_B, kite
from validators import analytic
from vloop.core import charts, solver

CATALOG = ["fourbar_crank_rocker_open", "slider_crank_offset", "eightbar", "jansen_pair"]
ROCKER = "sixbar_stephenson3_output_driven"


def rocking(mech: vloop.Mechanism, periods: int, period: float = 2.0) -> vloop.Mechanism:
    """The output-driven six-bar rocked back and forth: θ6 = θ6(0) + A·(1 − cos 2πt/T), 0.05 rad short of the
    upper limit of its range (2.3220 rad, vloop.sweep.feasible_range), a tabulated profile with ω and α."""
    d = mech.drivers[0]
    amp = 0.5 * (2.3220 - 0.05 - d.x0)
    w = 2 * math.pi / period
    t = np.linspace(0.0, periods * period, 64 * periods + 1)
    profile = vloop.model.Profile(
        t, d.x0 + amp * (1 - np.cos(w * t)), amp * w * np.sin(w * t), amp * w * w * np.cos(w * t)
    )
    return dataclasses.replace(mech, drivers=(dataclasses.replace(d, profile=profile),))


def turn_times(mech: vloop.Mechanism, turns: float, n: int) -> np.ndarray:
    """n times at which the input has turned evenly over ``turns`` turns (rocking periods for a profile)."""
    d = mech.drivers[0]
    if d.profile is not None:
        return np.linspace(0.0, turns * 2.0, n)
    angle = np.linspace(0.0, turns * 2 * math.pi, n)
    return angle / d.v0 if d.a0 == 0 else (-d.v0 + np.sqrt(d.v0 * d.v0 + 2 * d.a0 * angle)) / d.a0


def load(name: str) -> vloop.Mechanism:
    mech = vloop.load(MECHANISMS / f"{name}.toml")
    return rocking(mech, 12) if name == ROCKER else mech


KIND = {"x": "x", "y": "x", "s": "x", "vx": "v", "vy": "v", "v": "v", "ax": "a", "ay": "a", "a": "a"}


def worst(a: vloop.Result, b: vloop.Result, every: int = 1, only: str = "") -> tuple[float, str]:
    """Largest |a − b[::every]| over the columns (ending in ``only``; angles unwrapped, not modulo 2π) as a
    fraction of its peak, at least 1e-9 of the peak of its kind (positions, velocities, accelerations, θ, ω, α:
    a column that is zero in theory, as vloop.compare takes it)."""
    peaks = {c: float(np.max(np.abs(b[c]))) for c in b.columns}
    kinds = {c: KIND.get(c.rsplit(".", 1)[-1], c.rsplit(".", 1)[-1]) for c in b.columns}
    kind_peak: dict[str, float] = {}
    for c, p in peaks.items():
        kind_peak[kinds[c]] = max(kind_peak.get(kinds[c], 0.0), p)
    out = (0.0, "")
    for c in b.columns:
        if c.endswith(only):
            floor = max(peaks[c], 1e-9 * kind_peak[kinds[c]])
            out = max(out, (float(np.max(np.abs(a[c] - b[c][::every]))) / floor, c))
    return out


@pytest.mark.parametrize("method", ["auto", "newton"])
@pytest.mark.parametrize("name", [*CATALOG, ROCKER])
def test_a_coarse_run_is_the_fine_run_at_the_samples_they_share(name, method, monkeypatch):
    mech = load(name)
    system = vloop.compile(mech, method=method)
    fine_t = turn_times(mech, 12, 12 * 12 * 16 + 1)  # 1.875° of input per sample
    coarse = vloop.solve(system, fine_t[::16])  # 30° per sample
    assert any(c is not None for c in system.cache["charts"].values())  # (solved on a chart)
    with monkeypatch.context() as m:
        m.setattr(solver, "_chart", lambda run, times: None)  # continued row after row, rows inserted
        fine = vloop.solve(vloop.compile(mech, method=method), fine_t)
    gap, column = worst(coarse, fine, every=16)
    assert gap <= 1e-12, (column, gap)


@pytest.mark.parametrize("method", ["auto", "newton"])
@pytest.mark.parametrize("name", CATALOG)
def test_closed_forms_at_thirty_degrees_a_sample(name, method):
    mech = vloop.load(MECHANISMS / f"{name}.toml")
    t = turn_times(mech, 100, 1201)
    res = vloop.solve(mech, t, method=method)
    ref = analytic.solve(mech, t)
    vloop.compare.assert_histories_close(res, ref, rtol=1e-12, min_columns=10)
    gap, column = worst(res, ref, only=".theta")  # the angles to the turn as well (compare takes them modulo 2π)
    assert gap <= 1e-12, (column, gap)


def parallelogram(turns: int, samples_per_turn: float) -> vloop.Mechanism:
    """The test_change_points parallelogram at ω = 2 rad/s from θ2 = π/2 over ``turns`` turns."""
    stop = turns * math.pi
    return vloop.loads(PARALLELOGRAM.format(alpha=0.0, stop=stop, step=math.pi / samples_per_turn, solver=""))


@pytest.mark.parametrize("per_turn", [12.5, 41.3, 400.0])
def test_a_parallelogram_over_forty_turns_passes_every_folding(per_turn):
    """Foldings at θ2 = kπ (all four pins collinear); on the parallelogram branch θ4 = θ2, θ3 = 0 throughout."""
    mech = parallelogram(40, per_turn)
    res = vloop.solve(mech)
    th2 = math.pi / 2 + 2.0 * res.t
    folds = np.array([c["inputs"]["θ_crank"] for c in res.meta["change_points"]]) / math.pi
    assert np.array_equal(np.round(folds), np.arange(1, 81))  # π, 2π, …, 80π: none missed, none twice
    # t* to ~1e-11 of the run's input whatever the sampling: measured 3.9e-11 rad at 12.5 samples a turn, 2.6e-11
    # at 400 (the zoom stops at 1e-9 of its first bracket, h's round-off near its double zero limits it at ~1e-11)
    assert np.max(np.abs(folds - np.round(folds))) * math.pi <= 1e-10
    assert all(c["continued"] == "smooth" for c in res.meta["change_points"])
    assert np.max(np.abs(res["rocker.theta"] - th2)) < 1e-9 * np.max(th2)
    assert np.max(np.abs(res["rocker.omega"] - 2.0)) < 1e-9
    assert np.max(np.abs(res["coupler.omega"])) < 1e-9 and np.max(np.abs(res["coupler.theta"])) < 1e-9
    B = 2.0 * np.exp(1j * th2) + 4.0
    assert np.max(np.abs(res["B.x"] + 1j * res["B.y"] - B)) < 1e-9 * 4.0


def test_a_kite_over_twenty_turns_sampled_coarsely():
    """Crank = coupler = 1, rocker = ground = 2.5: B is O2 mirrored in the line A–O4, the branches cross at θ2 = kπ."""
    a, d, th0, w = 1.0, 2.5, 0.7, 1.5
    turns, step = 20, 2 * math.pi / 1.5 / 23.0  # 23 samples a turn (15.7°)
    res = vloop.solve(kite(a, d, th0, w, turns * 2 * math.pi / w, step))
    th2 = th0 + w * res.t
    B = _kite_B(a * np.exp(1j * th2), d)
    assert np.max(np.abs(res["B.x"] + 1j * res["B.y"] - B)) < 1e-9 * d
    folds = np.array([c["inputs"]["θ_crank"] for c in res.meta["change_points"]]) / math.pi
    assert np.array_equal(np.round(folds), np.arange(1, 2 * turns + 1))  # π … 40π, within 0.7 + 40π rad
    assert np.max(np.abs(folds - np.round(folds))) * math.pi <= 1e-10  # (as above)


def test_many_change_points_cost_no_python_call_each(monkeypatch):
    """The search over 800 foldings probes in a number of batches set by the zoom's depth, not by the foldings."""
    from vloop.core import changepoints

    calls = []
    real = changepoints.dyads_at
    monkeypatch.setattr(changepoints, "dyads_at", lambda *a, **k: calls.append(len(a[1])) or real(*a, **k))
    res = vloop.solve(parallelogram(400, 12.5))
    assert len(res.meta["change_points"]) == 800
    assert len(calls) <= 2 * changepoints.ZOOM_STEPS + 8 and sum(calls) > 800 * changepoints.ZOOM_POINTS


def test_a_chart_that_a_row_misses_gives_the_run_without_it(monkeypatch):
    """A row that fails a check on the chart sends the chunk back to the continuation: the same numbers, bit for
    bit, as a run that never drew a chart."""
    mech = load("sixbar_stephenson3_output_driven")
    t = turn_times(mech, 12, 145)
    with monkeypatch.context() as m:
        m.setattr(solver, "_chart", lambda run, times: None)
        plain = vloop.solve(vloop.compile(mech), t)
    real = charts.Chart.predict

    def off(self, x, cols):  # a prediction a whole radian off: Newton lands far from it, or elsewhere
        pred, move = real(self, x, cols)
        return pred + 1.0, move

    monkeypatch.setattr(charts.Chart, "predict", off)
    missed = vloop.solve(vloop.compile(mech), t)
    for c in plain.columns:
        assert np.array_equal(plain[c], missed[c]), c


def test_a_chart_is_not_drawn_across_a_limit():
    """A non-Grashof crank pushed past its limit over many coarse turns stops where it stops without a chart."""
    mech = vloop.load(MECHANISMS / "fourbar_nongrashof_past_limit.toml")
    t = mech.times[0] + np.linspace(0.0, 40 * (mech.times[-1] - mech.times[0]), 300)
    with pytest.raises(vloop.MotionError) as charted:
        vloop.solve(mech, t)
    assert all(c is None for c in vloop.compile(mech).cache.get("charts", {}).values())
    assert "limit" in str(charted.value) or "toggle" in str(charted.value)


def test_streamed_chunks_on_a_chart_join_to_the_run_in_memory():
    mech = load("eightbar")
    t = turn_times(mech, 400, 4800)
    whole = vloop.solve(mech, t)
    parts = list(vloop.core.solver.solve_iter(vloop.compile(mech), t, chunk=700))
    assert len(parts) > 5
    for c in whole.columns:
        assert np.array_equal(np.concatenate([p[c] for p in parts]), whole[c]), c


def test_the_batch_zooms_every_dip_of_every_variant():
    """Near-parallelograms (rocker 2 + δ): their discriminants dip to ~δ at every folding, too close for a first
    look to dismiss; the batch zooms on all of them at once and finds the branches apart, so it solves them itself
    (before, each went to the single run): bit for bit the single run, and the law of cosines on its fixed branch
    (validators.analytic.fourbar). The parallelogram itself (δ = 0) passes change points: the single run's."""
    from validators.analytic import fourbar as analytic_fourbar
    from vloop.core import batch
    from vloop.core.variants import VariantModel, resolve

    text = PARALLELOGRAM.format(alpha=0.0, stop=1.5 * math.pi, step=0.05, solver="")
    mech = vloop.loads(
        text.replace('rocker = { joints = ["O4", "B"] }', 'rocker = { joints = ["O4", "B"], length = 2.001 }')
    )
    model = VariantModel.build(mech, vloop.compile(mech), (resolve(mech, "links.rocker.length", "rocker"),))
    values = np.array([[2.0 + d] for d in (1e-3, 1e-5, 1e-7, 1e-8, 0.0)])
    d = model.designs(values)
    out = batch.solve(model, values, batch.make_grid(model, d, mech.times), ["B.x", "B.y", "rocker.theta"])
    assert out.solver == ["batch"] * 4 + ["single"] and out.completed.all()
    for v in range(4):
        _, own = batch.variant_system(model, values[v], d.take(slice(v, v + 1)), out.q0[v], out.positions[v])
        single = vloop.solve(own, mech.times)
        assert single.meta["change_points"] == []
        ref = analytic_fourbar.solve(own.mechanism, mech.times)
        for c in ("B.x", "B.y", "rocker.theta"):
            assert np.array_equal(out.columns[c][v], single[c]), (v, c)
            assert np.max(np.abs(out.columns[c][v] - ref[c])) <= 1e-9 * 4.0, (v, c)


@pytest.mark.parametrize("index", [77, 218])
@pytest.mark.parametrize("chart", [True, False])
def test_rocked_stephenson_six_bars_stay_on_their_branch(index, chart, monkeypatch):
    """Seed 2027 of the generated corpus: two Stephenson III six-bars rocked at their rocker, solved as one Newton
    block. Continued row after row, a window of coarse rows predicted from one row's Taylor series reached the
    other assembly near the input's reversal (closure, determinant sign and the jump allowance all passed) and
    kept it: the rows after it were wrong by up to twice the peak. The rows between coarse rows, continued one by
    one, now must lead to the coarse row after them, else the run continues from there; on the chart, every row is
    near the chart's. The reference: the closed form (validators.analytic: the four-bar by the law of cosines, the
    dyad on its coupler point)."""
    from validators import corpus

    mech = corpus.draw_item(2027, index).item.mechanism
    if not chart:
        monkeypatch.setattr(solver, "_chart", lambda run, times: None)
    res = vloop.solve(vloop.compile(mech, method="newton"))
    vloop.compare.assert_histories_close(res, analytic.solve(mech), rtol=1e-9, floor=1e-9, min_columns=15)


def gap_slider_crank(delta: float, turns: int = 40) -> vloop.Mechanism:
    """Offset slider-crank: crank 1 about O2 = (0, 0) at ω = 2 rad/s from θ2 = 0.3 rad, block on the line y = e = 0.2,
    rod b = e + cos δ. The rod reaches the line while the crank pin's distance from it, sin θ2 − e, stays within ±b:
    not where sin θ2 < e − b = −cos δ, the gap 3π/2 ± δ (nothing on the other side: sin θ2 − e ≤ 0.8 < b).
    Samples 30° apart over ``turns`` turns: samples 8 and 9 lie at 257.2° and 287.2°, rows inserted every 10°
    (267.2°, 277.2°) or a chart's every 3.75° (264.7°, 268.4°) land in the gap only for δ ≳ 1.6°."""
    e, th0, w = 0.2, 0.3, 2.0
    b = e + math.cos(delta)
    ax, ay = math.cos(th0), math.sin(th0)
    bx = ax + math.sqrt(b * b - (ay - e) ** 2)
    text = f"""name = "gap"
units = "m"
drivers = [{{ link = "crank", pivot = "O2", omega = {w!r} }}]
[joints]
O2 = [0.0, 0.0]
A = [{ax!r}, {ay!r}]
B = [{bx!r}, {e!r}]
[links.ground]
joints = ["O2"]
ground = true
[links.crank]
joints = ["O2", "A"]
[links.rod]
joints = ["A", "B"]
[sliders.block]
joint = "B"
guide = "ground"
axis = [1.0, 0.0]
[time]
start = 0.0
stop = {turns * 2 * math.pi / w!r}
step = {math.radians(30) / w!r}
"""
    return vloop.loads(text)


@pytest.mark.parametrize("delta_deg", [3.0, 0.25, 1e-3])
@pytest.mark.parametrize("chart", [True, False])
def test_a_limit_gap_between_rows_stops_the_run_at_its_edge(delta_deg, chart, monkeypatch):
    """A limit gap narrower than the rows' spacing (no row lands in it) is found by the dips of the discriminant
    and stops the run, on a chart or without: samples 0–8 kept, the limit located at the gap's edge 3π/2 − δ (to
    LIMIT_RTOL of the input's range over the run, 2.5e-10 rad: the bisection's stop), the failure named at an
    input inside the gap. The closed form (validators.analytic.slider_crank, which asks its own reach at the
    crank angles where the pin's distance from the line is extreme) stops at the same sample.

    The limit is the root of the dyad's discriminant h(θ) = b² − (sin θ − e)², to its round-off: h is known to
    ~16·ε·(b² + b·(|O2A| + e)) (the terms it is computed from) and crosses zero at the edge with slope
    |h′| = 2·b·|cos θ| = 2·b·sin δ, so the edge is located to that over the slope (9.7e-10 rad for δ = 0.001°,
    where the gap is nearly a touch), or to the bisection's stop, whichever is larger."""
    delta = math.radians(delta_deg)
    mech = gap_slider_crank(delta)
    if not chart:
        monkeypatch.setattr(solver, "_chart", lambda run, times: None)
    with pytest.raises(vloop.MotionError) as stop:
        vloop.solve(vloop.compile(mech))
    err, edge = stop.value, 1.5 * math.pi - delta
    assert err.sample == 9 and len(err.partial.t) == 9
    b = 0.2 + math.cos(delta)
    round_off = 64 * np.finfo(float).eps * (b * b + b * (1.0 + 0.2)) / (2 * b * math.sin(delta))
    assert abs(err.limit_value[0] - edge) <= max(solver.LIMIT_RTOL * 40 * 2 * math.pi, round_off) + 1e-12
    assert edge < err.driver_value[0] < 1.5 * math.pi + delta
    assert np.max(np.abs(err.partial["crank.theta"] - (0.3 + 2.0 * err.partial.t))) <= 1e-12 * 2 * math.pi
    with pytest.raises(analytic.LimitPositionError) as ref:
        analytic.solve(mech)
    assert ref.value.sample == 9


def test_a_limit_run_is_planned_from_the_crank_angle_the_file_writes():
    """The generator's limit runs: a crank drawn at θ0 in (π, 2π) is at θ0 − 2π by the joints' atan2, and the time
    the input reaches the recorded limit must count from the file's θ0 (the file writes angles in [0, 2π)), else
    the run crosses a limit a turn earlier than recorded. The check: θ0 + ω·t_lim = θ_lim."""
    from validators import corpus

    planned = 0
    for seed in range(40):
        p = corpus.draw_slider_crank(np.random.default_rng(seed), "rocking")
        p["theta0"] = 5.0
        try:
            draft = corpus.slider_crank_draft(p, "rocking")
            motion = corpus.plan_limit(
                draft, {"dir": 1.0, "omega": 3.0, "alpha": 0.0, "k_stop": 40, "u_stop": 0.5, "n_after": 10}
            )
        except corpus.Infeasible:
            continue
        planned += 1
        assert abs(5.0 + 3.0 * motion.limit["time"] - motion.limit["angle"]) < 1e-12
        assert 0 < motion.limit["angle"] - 5.0 < 2 * math.pi
    assert planned >= 5


def gap_fourbar(delta: float) -> vloop.Mechanism:
    """Four-bar: crank 1 about O2 = (0, 0) at ω = 2 rad/s from 0.3 rad, ground 3 to O4 = (3, 0), coupler 2, rocker
    2 − κ with κ = 4 − √(10 + 6 cos δ). |A − O4|² = 10 − 6 cos θ2 exceeds (b + c)² only within δ of θ2 = π: a gap
    π ± δ. Samples 30° apart over 40 turns: samples 5 and 6 at 167.2° and 197.2°."""
    a, d, b, w, th0 = 1.0, 3.0, 2.0, 2.0, 0.3
    c = math.sqrt(10.0 + 6.0 * math.cos(delta)) - b
    A = complex(a * math.cos(th0), a * math.sin(th0))
    f = abs(d - A)
    p = (b * b - c * c + f * f) / (2 * f)
    B = A + (d - A) / f * complex(p, math.sqrt(b * b - p * p))
    text = f"""name = "gap4"
units = "m"
drivers = [{{ link = "crank", pivot = "O2", omega = {w!r} }}]
[joints]
O2 = [0.0, 0.0]
O4 = [{d!r}, 0.0]
A = [{A.real!r}, {A.imag!r}]
B = [{B.real!r}, {B.imag!r}]
[links.ground]
joints = ["O2", "O4"]
ground = true
[links.crank]
joints = ["O2", "A"]
[links.coupler]
joints = ["A", "B"]
[links.rocker]
joints = ["O4", "B"]
[time]
start = 0.0
stop = {40 * 2 * math.pi / w!r}
step = {math.radians(30) / w!r}
"""
    return vloop.loads(text)


@pytest.mark.parametrize("delta_deg", [0.25, 0.02])
def test_a_four_bar_limit_gap_between_rows_stops_the_run_and_the_closed_form(delta_deg):
    """The same for a non-Grashof four-bar whose coupler and rocker just fail to reach when the crank points away
    from O4: vloop stops with samples 0–5 kept, the limit at π − δ; analytic_fourbar stops at sample 6. (Narrower
    gaps are found too, but their edge only to round-off of the reach over its slope there, |d|A − O4|/dθ2| = 3δ/4:
    2.6e-9 rad at δ = 0.001°.)"""
    delta = math.radians(delta_deg)
    mech = gap_fourbar(delta)
    with pytest.raises(vloop.MotionError) as stop:
        vloop.solve(mech)
    assert stop.value.sample == 6
    assert abs(stop.value.limit_value[0] - (math.pi - delta)) <= solver.LIMIT_RTOL * 40 * 2 * math.pi + 1e-12
    with pytest.raises(analytic.LimitPositionError) as ref:
        analytic.solve(mech)
    assert ref.value.sample == 6
