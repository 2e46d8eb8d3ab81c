"""`vloop validate`: summary.json (schema), pass/fail, a perturbed engine input, nightly flags."""

from __future__ import annotations

import json
from pathlib import Path

import jsonschema
import pytest

import vloop
from tests.conftest import MECHANISMS, plant
from validators import harness, nightly
from vloop.cli import main

SCHEMA = json.loads((Path(harness.__file__).parent / "summary.schema.json").read_text())
FAST = "vloop,analytic,pinocchio"


@pytest.fixture(scope="module")
def validated(tmp_path_factory):
    pytest.importorskip("pinocchio")
    out = tmp_path_factory.mktemp("val")
    files = [MECHANISMS / "eightbar.toml", MECHANISMS / "fourbar_nongrashof_past_limit.toml"]
    code = main(["validate", *map(str, files), "--engines", FAST, "--out", str(out), "--no-report"])
    return code, out, json.loads((out / "summary.json").read_text())


def test_validate_passes_and_summary_matches_schema(validated):
    code, _, summary = validated
    assert code == 0
    jsonschema.validate(summary, SCHEMA)
    assert summary["passed"] is True
    assert [m["name"] for m in summary["mechanisms"]] == ["eightbar", "fourbar_nongrashof_past_limit"]
    eb = summary["mechanisms"][0]
    assert eb["loops"] == 3 and eb["mobility"] == 1 and eb["samples"] == 48
    assert {(c["engine"], c["reference"]) for c in eb["comparisons"]} == {
        ("analytic", "vloop"),
        ("pinocchio", "vloop"),
        ("pinocchio", "analytic"),
    }
    for c in eb["comparisons"]:
        assert c["samples"] == 48 and c["passed"] and c["worst"]["max_abs"] <= c["worst"]["allowed"]
    # every quantity's figures: in the comparison table (the summary keeps each comparison's worst)
    import pandas as pd

    table = pd.read_parquet(validated[1] / "comparisons.parquet")
    for _, rows in table[table.mechanism == "eightbar"].groupby(["engine", "reference"]):
        assert len(rows) > 50 and (rows.max_abs <= rows.allowed).all()
    # the past-limit run: every engine stops at sample 173 and they agree before it
    ng = summary["mechanisms"][1]
    assert {r["status"] for r in ng["runs"].values()} == {"stopped"}
    assert {r["samples"] for r in ng["runs"].values()} == {173}
    assert summary["versions"]["pin"] != "not installed"


def test_perturbed_engine_input_fails_naming_mechanism_engine_quantity_time():
    """Rod l5 1 % too long in Pinocchio's input only: the comparison must fail and say where."""
    pytest.importorskip("pinocchio")
    path = MECHANISMS / "eightbar.toml"
    good = vloop.load(path)
    text = path.read_text().replace("length = 6.15 }   # rod d", "length = 6.2115 }  # rod d, +1 %")
    bad = vloop.loads(text.replace("[time]", "[solver]\nassembly_tolerance = 0.02\n\n[time]"), source=str(path))
    a = harness.run_engine("pinocchio", bad)
    b = harness.run_engine("vloop", good)
    c = harness.check(a, b, "eightbar")
    assert not c.passed
    assert "eightbar: pinocchio vs vloop:" in c.message
    assert "l5.theta off by" in c.message or "l6.s off by" in c.message or "C." in c.message
    assert " at t = " in c.message


def test_failing_engine_does_not_stop_the_others(tmp_path, monkeypatch, capsys):
    def boom(mech, res):
        raise RuntimeError("closed form exploded")

    plant(monkeypatch, "analytic", boom)
    code = main(
        [
            "validate",
            str(MECHANISMS / "slider_crank_offset.toml"),
            "--engines",
            "vloop,analytic",
            "--out",
            str(tmp_path),
            "--no-report",
        ]
    )
    assert code == 1
    summary = json.loads((tmp_path / "summary.json").read_text())
    runs = summary["mechanisms"][0]["runs"]
    assert runs["analytic"]["status"] == "error" and "closed form exploded" in runs["analytic"]["message"]
    assert runs["vloop"]["status"] == "ok"
    assert " error " in capsys.readouterr().out


def test_bad_input_gives_exit_code_2(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text("name = 'x'\n[joints]\nA = [0.0, 0.0]\n")
    assert main(["validate", str(bad), "--engines", "vloop", "--out", str(tmp_path / "o"), "--no-report"]) == 2
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert "missing or empty" in summary["mechanisms"][0]["error"]
    assert main(["validate", str(bad), "--engines", "vloop,warp-drive", "--out", str(tmp_path / "o")]) == 2


def test_nightly_flags_an_injected_regression(validated, tmp_path, monkeypatch, capsys):
    """Yesterday: the real run. Today: Pinocchio's l3.alpha off by 1e-10 of itself — still within
    its 1e-9 tolerance, but 10^3 times yesterday's error: the nightly run must flag it."""
    _, _, summary = validated
    root = tmp_path / "nightly"
    yesterday = root / "2026-11-20"
    yesterday.mkdir(parents=True)
    (yesterday / "summary.json").write_text(json.dumps(summary))

    def drifting(mech, res):
        res.columns["l3.alpha"] = res.columns["l3.alpha"] * (1 + 1e-10)
        return res

    plant(monkeypatch, "pinocchio", drifting)
    code = main(
        [
            "validate",
            str(MECHANISMS / "eightbar.toml"),
            "--engines",
            FAST,
            "--out",
            str(root),
            "--nightly",
            "--no-report",
        ]
    )
    text = capsys.readouterr().out
    assert code == 1
    assert "FLAG eightbar: pinocchio vs vloop: l3.alpha grew more than 10x" in text
    dated = [p for p in root.iterdir() if p.name != "2026-11-20"]
    assert len(dated) == 1
    new = json.loads((dated[0] / "summary.json").read_text())
    jsonschema.validate(new, SCHEMA)
    assert new["passed"] is True  # within tolerance: only the nightly comparison sees the drift
    assert new["nightly"]["previous"].endswith("2026-11-20/summary.json")
    assert {(f["quantity"], f["kind"]) for f in new["nightly"]["flags"]} >= {("l3.alpha", "grew more than 10x")}
    # a quantity that crosses its tolerance is flagged whatever its growth
    cur = json.loads(json.dumps(summary))
    c = cur["mechanisms"][0]["comparisons"][0]
    q = c["worst"]
    q["max_abs"], q["passed"], c["passed"] = q["allowed"] * 2, False, False
    crossed = nightly.compare_summaries(cur, summary)
    assert [f["kind"] for f in crossed] == ["crossed tolerance"]
    assert f"{q['quantity']} crossed tolerance" in crossed[0]["message"]


def test_plugin_parametrizes_over_the_catalog(vloop_mechanism_file, assert_histories_close):
    """The pytest plugin's fixtures: every catalog file, vloop against the Newton path at 1e-9."""
    mech = vloop.load(vloop_mechanism_file)
    try:
        a = vloop.solve(mech)
    except vloop.MotionError as exc:
        a = exc.partial
    b_sys = vloop.compile(mech)
    try:
        b = vloop.solve(b_sys, a.t[: max(len(a) - 2, 1)], method="newton")
    except vloop.MotionError as exc:
        b = exc.partial
    n = min(len(a), len(b))
    assert_histories_close(a.head(n), b.head(n), rtol=1e-9)


@pytest.mark.slow
def test_validate_all_on_the_catalog_passes(tmp_path, capsys):
    """The whole catalog, every engine (Exudyn's dynamic mode included), summary and report (slow: each engine
    is compared with vloop on every catalog file in its own test, test_pinocchio.py, test_exudyn.py,
    test_vs_closed_forms.py; this is the end-to-end run of them all together)."""
    pytest.importorskip("pinocchio")
    pytest.importorskip("exudyn")
    from tests.conftest import mechanism_files

    code = main(["validate", "--all", "--out", str(tmp_path)])
    out = capsys.readouterr().out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert code == 0, out
    jsonschema.validate(summary, SCHEMA)
    assert summary["passed"] and "all passed" in out
    names = {m["name"] for m in summary["mechanisms"]}
    assert names == {p.stem for p in mechanism_files()}
    assert summary["engines"] == ["vloop", "analytic", "pinocchio", "exudyn-kinematic", "exudyn-dynamic"]
    for m in summary["mechanisms"]:
        engines = {c["engine"] for c in m["comparisons"] if c["reference"] == "vloop"}
        expected = {"pinocchio", "exudyn-kinematic", "exudyn-dynamic"}
        if m["runs"]["analytic"]["status"] != "skipped":  # closed forms exist for most, not all
            expected.add("analytic")
        assert engines == expected, m["name"]
    assert sum(m["runs"]["analytic"]["status"] == "skipped" for m in summary["mechanisms"]) <= 1
    html = (tmp_path / "report.html").read_text()
    assert "loop 1 (" in html and all(name in html for name in names)
