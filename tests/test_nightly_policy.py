"""The nightly's exit policy and the reference engines' own second look.

Red (exit 1) only where vloop may be wrong: vloop blamed by the consensus, or a mechanism undecided. A reference
engine blamed by engines that agree with vloop, or inconclusive by its own evidence, is reported (table, summary,
pages) and exits 0 unless --strict. The engines' fixes are checked against the closed forms (validators.analytic),
never against vloop alone.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from tests.conftest import plant
from validators import corpus
from validators.consensus import decide
from validators.validate import _table, exit_status
from vloop.cli import main

MECHANISMS = Path(__file__).resolve().parents[1] / "mechanisms"


# ---------------------------------------------------------------- the consensus with inconclusive engines


def test_an_inconclusive_engine_does_not_vote_and_keeps_its_reason():
    """exudyn-dynamic disagrees with everyone but said it cannot resolve the mechanism: it is neither blamed nor
    counted, the others agree, and the mechanism passes (not red) with the engine's own reason kept."""
    v = decide(
        ["vloop", "analytic", "pinocchio", "exudyn-dynamic"],
        {("exudyn-dynamic", "vloop"): "P.ay off", ("exudyn-dynamic", "analytic"): "P.ay off"},
        inconclusive={"exudyn-dynamic": "its own error estimate is 3× its allowance"},
    )
    assert v.status == "pass" and v.blamed == () and not v.red
    assert v.engines == {"vloop": "pass", "analytic": "pass", "pinocchio": "pass", "exudyn-dynamic": "inconclusive"}
    assert v.inconclusive == {"exudyn-dynamic": "its own error estimate is 3× its allowance"}


def test_fewer_than_two_engines_left_is_inconclusive_and_a_wrong_vloop_is_still_red():
    two = decide(["vloop", "exudyn-dynamic"], {("exudyn-dynamic", "vloop"): "x"}, inconclusive={"exudyn-dynamic": "h"})
    assert two.status == "inconclusive" and not two.red and two.engines["exudyn-dynamic"] == "inconclusive"
    # an inconclusive reference engine cannot hide a wrong vloop: the two others still outvote it
    odd = decide(
        ["vloop", "analytic", "pinocchio", "exudyn-dynamic"],
        {("analytic", "vloop"): "a", ("pinocchio", "vloop"): "b", ("exudyn-dynamic", "vloop"): "c"},
        inconclusive={"exudyn-dynamic": "h"},
    )
    assert odd.status == "blamed" and odd.blamed == ("vloop",) and odd.red
    assert decide(["vloop", "pinocchio"], {("pinocchio", "vloop"): "x"}).red  # undecided: red


# ---------------------------------------------------------------- exit status


def _summary(status: str, blamed: tuple[str, ...] = (), inconclusive: dict | None = None) -> dict:
    engines = ["vloop", "analytic", "pinocchio", "exudyn-kinematic", "exudyn-dynamic"]
    states = dict.fromkeys(engines, "pass")
    states.update(dict.fromkeys(blamed, "blamed"))
    states.update(dict.fromkeys(inconclusive or {}, "inconclusive"))
    red = status == "undecided" or "vloop" in blamed
    verdict = {"status": status, "blamed": list(blamed), "reason": "r", "engines": states, "reasons": {},
               "inconclusive": inconclusive or {}, "red": red}  # fmt: skip
    worst = {"quantity": "P.ay", "max_abs": 0.0616, "allowed": 0.00852}
    comps = [{"engine": e, "reference": "vloop", "passed": e not in blamed, "worst": worst} for e in engines[1:]]
    runs = {e: {"status": "ok", "message": ""} for e in engines}
    mech = {"name": "c00022-fourbar-change-point-with-a-long-name", "passed": status == "pass" and not inconclusive,
            "runs": runs, "comparisons": comps, "verdict": verdict, "corpus": {"family": "fourbar"}}  # fmt: skip
    ok = {"name": "c00001-fourbar", "passed": True, "runs": runs, "comparisons": [], "corpus": {"family": "fourbar"}}
    mechs = [ok] * 29 + [mech]
    tally = {e: {"pass": 29 + (states[e] == "pass"), "blamed": int(states[e] == "blamed"), "undecided": 0,
                 "inconclusive": int(states[e] == "inconclusive"), "skipped": 0} for e in engines}  # fmt: skip
    return {"passed": mech["passed"], "red": red, "engines": engines, "mechanisms": mechs,
            "verdicts": {"engines": tally, "mechanisms": {"pass": 29, status: 1}, "red": [mech["name"]] * red,
                         "vloop_blamed": [mech["name"]] * ("vloop" in blamed)}}  # fmt: skip


@pytest.mark.parametrize(
    "case, code, strict_code",
    [
        (("blamed", ("exudyn-dynamic",)), 0, 1),
        (("blamed", ("pinocchio",)), 0, 1),
        (("pass", (), {"exudyn-dynamic": "own estimate 3× its allowance"}), 0, 1),
        (("blamed", ("vloop",)), 1, 1),
        (("undecided", ()), 1, 1),
        (("pass", ()), 0, 0),
    ],
)
def test_exit_status_is_red_only_when_vloop_may_be_wrong(case, code, strict_code):
    s = _summary(*case)
    assert exit_status(s) == code and exit_status(s, strict=True) == strict_code
    # a nightly flag: red when it may be vloop's, reported otherwise
    flagged = s | {"nightly": {"flags": [{"red": False, "message": "exudyn-dynamic vs vloop grew"}]}}
    assert exit_status(flagged) == code and exit_status(flagged, strict=True) == 1
    assert exit_status(s | {"nightly": {"flags": [{"red": True, "message": "vloop vs analytic grew"}]}}) == 1


def test_the_printed_table_fits_its_columns_and_says_the_verdict_once():
    """A 30-mechanism corpus with one failure: the failing row is as wide as the header, the verdict is said once
    (in the verdict column), and the count is over the whole corpus (29 of 30), not over the rows shown."""
    text = _table(_summary("blamed", ("exudyn-dynamic",)), corpus_page=True)
    lines = text.splitlines()
    head = next(line for line in lines if line.startswith("mechanism"))
    row = next(line for line in lines if line.startswith("c00022"))
    assert len(row.split("  blamed on")[0]) <= len(head.split("  verdict")[0])
    assert row.count("blamed") == 2 and row.endswith("blamed on exudyn-dynamic")  # the cell's mark and the verdict
    assert "FAIL" not in row and "7.2e+00 blamed" in row
    assert "29 of 30 mechanisms pass every comparison" in text
    assert "exudyn-dynamic: blamed on 1, undecided on 0, inconclusive on 0" in text


# ---------------------------------------------------------------- end to end: a planted wrong reference engine


def _off(mech, res):
    """The engine's own result with every link angle off by 1e-6 rad (1000× the 1e-9 tolerance)."""
    res = dataclasses.replace(res, columns=dict(res.columns))
    for c in [c for c in res.columns if c.endswith(".theta")]:
        res.columns[c] = res.columns[c] + 1e-6
    return res


@pytest.mark.parametrize("wrong, code", [("pinocchio", 0), pytest.param("vloop", 1, marks=pytest.mark.slow)])
def test_validate_exits_0_on_a_reference_engine_blamed_and_1_on_vloop(wrong, code, tmp_path, monkeypatch, capsys):
    pytest.importorskip("pinocchio")
    plant(monkeypatch, wrong, _off)
    args = [
        "validate",
        str(MECHANISMS / "fourbar_crank_rocker_open.toml"),
        "--engines",
        "vloop,analytic,pinocchio",
        "--no-report",
    ]
    assert main([*args, "--out", str(tmp_path / "a")]) == code
    summary = json.loads((tmp_path / "a" / "summary.json").read_text())
    assert summary["mechanisms"][0]["verdict"]["blamed"] == [wrong] and summary["red"] == (wrong == "vloop")
    out = capsys.readouterr().out
    assert ("RED: vloop blamed on 1" in out) == (wrong == "vloop")
    assert ("vloop passed; reference engines: blamed 1 (not red; --strict makes it red)" in out) == (wrong != "vloop")
    assert exit_status(summary, strict=True) == 1


# ---------------------------------------------------------------- the engines' own fixes


def test_pinocchio_follows_an_antiparallelogram_through_its_change_point():
    """Seed 9191's antiparallelogram (index 55 of the kite/antiparallelogram families): a sample 0.014 rad before
    the change point, the next 0.21 rad after it. Pinocchio's continuation used to land on the other branch there
    (the branches cross, so det J keeps its sign); with every step held to its predicted path it stays on the
    branch whose velocities are continuous — the closed form's, to round-off."""
    pytest.importorskip("pinocchio")
    import vloop
    from validators import analytic
    from validators import pinocchio as vpin

    item = corpus.generate(1, 9191, start=55, families=["fourbar/kite", "fourbar/antiparallelogram"])[0][0]
    assert item.name == "c00055-fourbar-antiparallelogram"
    mech = vloop.loads(item.text)
    p, a = vpin.solve(mech), analytic.solve(mech)
    for col in ("B.x", "B.y", "B.vx", "B.vy", "B.ax", "B.ay", "rocker.theta"):
        peak = float(np.max(np.abs(a[col])))
        assert float(np.max(np.abs(p[col] - a[col]))) <= 1e-9 * max(peak, 1e-3), col


@pytest.mark.slow
def test_exudyn_dynamic_integrates_a_change_point_window_again_before_it_is_blamed():
    """Seed 7, index 22 (a change-point four-bar): at its default step Exudyn's accelerations are 7× their allowance
    next to the change point (P.ay at t = 0.204 s). Its second look integrates the window again at finer steps and
    keeps the first run whose own Richardson estimate is within its allowance; that run agrees with the closed form
    within the stated tolerance."""
    pytest.importorskip("exudyn")
    import vloop
    from validators import analytic, engines
    from validators.tolerances import tolerance
    from vloop.compare import compare

    item = corpus.generate(1, 7, start=22)[0][0]
    mech = vloop.loads(item.text)
    first = engines.ENGINES["exudyn-dynamic"].run(mech)
    ref = analytic.solve(mech).head(len(first))
    tol = tolerance("exudyn-dynamic", "analytic")

    def check(res):
        return compare(res, ref.head(len(res)), tol.rtol, floor=tol.floor, atol_t=res.meta["allowance"])

    assert not check(first).passed
    look = engines.ENGINES["exudyn-dynamic"].second_look(mech, first, stopped=False)
    assert look.result is not None and not look.inconclusive and look.result.meta["step"] < first.meta["step"]
    assert len(look.result) == len(first) and check(look.result).passed


def test_exudyn_dynamic_reuses_the_kinematic_pass_bit_for_bit():
    """A task runs exudyn-kinematic then exudyn-dynamic on one mechanism: the dynamic mode's kinematic pass (its
    step's rate and its conditioning) is the same Exudyn computation, done once; the result is identical."""
    pytest.importorskip("exudyn")
    import vloop
    from validators import engines
    from validators import exudyn as vexu

    mech = vloop.loads(corpus.generate(1, 2026, start=101)[0][0].text)
    vexu._LAST.__init__()
    alone = engines.ENGINES["exudyn-dynamic"].run(mech)
    engines.ENGINES["exudyn-kinematic"].run(mech)
    assert vexu._LAST.recall(mech, mech.times) is not None
    after = engines.ENGINES["exudyn-dynamic"].run(mech)
    assert set(alone.columns) == set(after.columns)
    assert all(np.array_equal(alone[c], after[c]) for c in alone.columns)
    assert all(np.array_equal(alone.meta["allowance"][g], after.meta["allowance"][g]) for g in alone.meta["allowance"])


# ---------------------------------------------------------------- the history across nights


def test_history_shows_new_failures_against_the_night_before(tmp_path):
    """Three nights: the first read from its summary.json (a night before trend.json existed), the others from
    trend.json. Per night the page gives the counts, the red ones, per engine blamed/undecided/inconclusive, the
    failures new since the night before and those fixed, and per family the passes."""
    from reports.history import figures_from_summary, write_history, write_trend

    def night(failing: dict[str, str], created: str) -> dict:
        mechs = []
        for name in ["c00001-fourbar-kite", "c00002-watt2-crank", "c00003-fourbar-kite"]:
            blamed = failing.get(name)
            engines = {"vloop": "pass", "exudyn-dynamic": "pass"}
            if blamed:
                engines[blamed] = "blamed"
            verdict = {"status": "blamed" if blamed else "pass", "blamed": [blamed] if blamed else [],
                       "engines": engines, "red": blamed == "vloop"}  # fmt: skip
            fam, var = name.split("-")[1:3]
            mechs.append({"name": name, "passed": not blamed, "red": blamed == "vloop", "verdict": verdict,
                          "corpus": {"seed": 9, "family": fam, "variant": var}})  # fmt: skip
        return {"created": created, "seconds": 30.0, "engines": ["vloop", "exudyn-dynamic"], "mechanisms": mechs}

    first = tmp_path / "2026-11-26"
    first.mkdir()
    (first / "summary.json").write_text(json.dumps(night({"c00001-fourbar-kite": "exudyn-dynamic"}, "2026-11-26T02")))
    second = tmp_path / "2026-11-27"
    second.mkdir()
    two = night({"c00002-watt2-crank": "vloop"}, "2026-11-27T02")
    write_trend(figures_from_summary(two, second.name), second)
    tonight = figures_from_summary(night({}, "2026-11-28T02"), "2026-11-28")
    (tmp_path / "out").mkdir()
    html = write_history(tmp_path, tmp_path / "out", tonight).read_text()
    rows = html[html.index('id="nights-table"') :].split("<tbody>")[1].split("</tbody>")[0].split("</tr>")[:-1]
    assert [r.split('summary.json">')[1].split("<")[0] for r in rows] == ["2026-11-28", "2026-11-27", "2026-11-26"]
    assert "none" in rows[0] and ">1</td>" in rows[0].split("none")[1]  # tonight: nothing new, one fixed
    assert "c00002-watt2-crank@seed9" in rows[1] and 'class="cell fail">1</td>' in rows[1]  # new, and red
    assert "first night" in rows[2] and "1 / 0 / 0" in rows[2]  # exudyn-dynamic blamed once
    family = html[html.index('id="family-history"') :]
    assert ">2/2</td>" in family.split("fourbar/kite")[1].split("</tr>")[0]


def test_exudyn_refine_says_inconclusive_from_its_own_estimate_or_its_own_failures():
    """The second look decides from Exudyn's runs alone: finer runs that keep changing by more than the allowance
    (Richardson: the finer run's error is the change over (h₁/h₂)² − 1) make it inconclusive with the estimate and
    where; a run that fails at the same sample at every step makes it inconclusive with that failure."""
    import vloop
    from validators import exudyn as vexu
    from vloop.errors import MotionError

    mech = vloop.load(MECHANISMS / "fourbar_crank_rocker_open.toml")
    first = vloop.solve(mech)
    first.meta.update(step=1e-3, accuracy=1e-5)

    def drifting(times, accuracy):  # each finer run 1 % off the one before in P's acceleration
        res = dataclasses.replace(first, columns=dict(first.columns), meta={"step": 1e-3 * (accuracy / 1e-5) ** 0.5})
        res.columns["B.ax"] = first["B.ax"] * (1 + 0.01 / accuracy * 1e-6)
        return res

    res, why, note = vexu.refine(mech, first, False, drifting)
    assert res is None and why.startswith("its own error estimate (Richardson, runs at h = 0.001, 0.0005, ")
    assert "× its allowance at t = " in why and "(B.ax)" in why and note.startswith("integrated again at h = ")

    def failing(times, accuracy):
        raise MotionError("x: exudyn-dynamic: Newton failed", time=0.5, sample=7, partial=first.head(7))

    res, why, _ = vexu.refine(mech, first, True, failing)
    assert res is None and why.startswith("its time integration fails at sample 7 at every step tried")

    def converged(times, accuracy):
        return dataclasses.replace(first, meta={"step": 1e-3 * (accuracy / 1e-5) ** 0.5})

    res, why, note = vexu.refine(mech, first, False, converged)
    assert res is not None and why == "" and "own error estimate within its allowance" in note


def test_a_second_look_at_an_extrapolated_run_estimates_from_single_runs():
    """An extrapolated first run's error is not of the order Richardson's estimate assumes (next to a change point:
    seed 2026's c07439): the second look makes its single twin at the same accuracy first and estimates each finer
    single run from the one before; a twin that fails where the pair went on leaves the engine without a verdict."""
    import vloop
    from validators import exudyn as vexu
    from vloop.errors import MotionError

    mech = vloop.load(MECHANISMS / "fourbar_crank_rocker_open.toml")
    first = vloop.solve(mech)
    first.meta.update(step=4e-3, accuracy=1e-5, richardson={"steps": [4e-3, 8e-3]})
    asked = []

    def single(times, accuracy):
        asked.append(accuracy)
        return dataclasses.replace(first, meta={"step": 1e-3 * (accuracy / 1e-5) ** 0.5, "accuracy": accuracy})

    res, why, note = vexu.refine(mech, first, False, single)
    assert asked == [1e-5, vexu.REFINE_ACCURACIES[0]] and res is not None and why == ""
    assert note == "integrated again at h = 0.0005 s (own error estimate within its allowance)"

    def failing(times, accuracy):
        raise MotionError("x: exudyn-dynamic: Newton failed", time=0.5, sample=7, partial=first.head(7))

    res, why, _ = vexu.refine(mech, first, False, failing)
    assert (
        res is None
        and why == "its single run fails before sample 7, where its extrapolated pair went on: Newton failed"
    )


def test_pinocchio_path_check_never_refuses_a_step_it_cannot_shorten():
    """Seed 60606, index 891 (a Stephenson III): the path check refused its first step at every bisection level;
    the last level takes the step as Newton lands it, and the run agrees with the closed form to 1e-9 of peak."""
    pytest.importorskip("pinocchio")
    import vloop
    from validators import analytic
    from validators import pinocchio as vpin

    mech = vloop.loads(corpus.generate(1, 60606, start=891)[0][0].text)
    p, a = vpin.solve(mech), analytic.solve(mech)
    assert len(p) == len(mech.times) == 184
    for col in (c for c in a.columns if c in p.columns and c.endswith((".x", ".y", ".vx", ".vy"))):
        assert float(np.max(np.abs(p[col] - a[col]))) <= 1e-9 * max(float(np.max(np.abs(a[col]))), 1e-3), col
