"""Distributed validation of a generated corpus: Dask LocalCluster vs in-process, Parquet, nightly, corpus page.

* A 40-mechanism corpus validated on a LocalCluster (2 worker processes) with vloop, the closed forms,
  Pinocchio and Exudyn (kinematic) gives the same summary (every number) as the in-process run, with each
  task's worker and time recorded, and summary.json valid against its (extended) schema.
* comparisons.parquet holds one row per mechanism × engine × reference × quantity.
* A nightly run with --corpus prints the one command that reproduces a failure, shrinks the failing file
  to a simpler one that still fails and writes it next to summary.json; corpus.html shows the families,
  the worst errors, the histograms, the limit runs and the failures.
"""

from __future__ import annotations

import copy
import dataclasses
import json
import re
from pathlib import Path

import jsonschema
import numpy as np
import pytest

import vloop
from tests.conftest import plant
from validators import corpus, harness, shrink
from vloop.cli import main

SCHEMA = json.loads((Path(harness.__file__).parent / "summary.schema.json").read_text())
ENGINES = ("vloop", "analytic", "pinocchio", "exudyn-kinematic")
SEED = 424242
TIMING = ("seconds", "task_seconds", "cpu_seconds", "worker")


@pytest.fixture(scope="module")
def corpus40(tmp_path_factory) -> list[Path]:
    pytest.importorskip("pinocchio")
    pytest.importorskip("exudyn")
    out = tmp_path_factory.mktemp("corpus40")
    items, _ = corpus.generate(40, SEED)
    corpus.write(items, out, seed=SEED)
    return sorted(out.glob("*.toml"))


@pytest.fixture(scope="module")
def in_process(corpus40):
    v = harness.run(corpus40, ENGINES)
    return v, harness.to_summary(v)


def _numbers(summary: dict) -> dict:
    """The summary without what depends on when and where it ran (times, workers, runner settings)."""
    s = copy.deepcopy(summary)
    for key in ("created", "seconds", "runner", "versions"):
        s.pop(key, None)
    for m in s["mechanisms"]:
        for r in m["runs"].values():
            for k in TIMING:
                r.pop(k, None)
    return s


def test_local_cluster_gives_the_same_summary_as_in_process(corpus40, in_process):
    pytest.importorskip("distributed")
    _, here = in_process
    v = harness.run(corpus40, ENGINES, workers=2, timeout=300)
    there = harness.to_summary(v)
    jsonschema.validate(there, SCHEMA)
    jsonschema.validate(here, SCHEMA)
    # one task per mechanism (its engines, comparisons and verdict where it runs)
    assert there["runner"] == {
        "mode": "local-cluster", "workers": 2, "scheduler": None, "timeout": 300, "tasks": 40, "resumed": 0,
    }  # fmt: skip
    assert here["runner"]["mode"] == "in-process"
    assert _numbers(there) == _numbers(here)
    workers = {r["worker"] for m in there["mechanisms"] for r in m["runs"].values()}
    assert len(workers) == 2 and not any(w.startswith("local:") for w in workers)
    assert {r["worker"] for m in here["mechanisms"] for r in m["runs"].values()} == {
        next(iter(here["mechanisms"]))["runs"]["vloop"]["worker"]
    }
    assert all(r["task_seconds"] >= r["seconds"] >= 0 for m in there["mechanisms"] for r in m["runs"].values())
    # what the 40 show: only change points may fail (the lead's fix), and Exudyn's own findings (see report)
    for m in here["mechanisms"]:
        assert m["corpus"]["seed"] == SEED
        if not m["passed"]:
            assert m["corpus"]["change_point"], m["name"]
    assert here["corpus"]["seeds"] == [SEED] and here["corpus"]["mechanisms"] == 40


def test_passing_generated_runs_keep_their_numbers_but_not_their_histories(in_process):
    v, summary = in_process
    for it, m in zip(v.items, summary["mechanisms"], strict=True):
        for name, r in it.runs.items():
            assert m["runs"][name]["samples"] == r.samples
            if it.passed:
                assert r.result is None
            elif r.status in ("ok", "stopped"):
                assert r.result is not None  # a failure keeps its histories for the report


def test_parquet_table_has_one_row_per_compared_quantity(in_process, tmp_path):
    pd = pytest.importorskip("pandas")
    pytest.importorskip("pyarrow")
    _, summary = in_process
    path = harness.write_parquet(summary, tmp_path / "comparisons.parquet")
    df = pd.read_parquet(path)
    assert list(df.columns) == list(harness.TABLE_COLUMNS)
    n = sum(max(len(c["quantities"]), 1) for m in summary["mechanisms"] for c in m["comparisons"])
    assert len(df) == n
    rows = df.dropna(subset=["quantity"])
    assert np.allclose(rows["ratio"], rows["max_abs"] / rows["allowed"])
    assert (rows["passed"] == (rows["max_abs"] <= rows["allowed"])).all()
    assert set(df["engine"]) == {"analytic", "pinocchio", "exudyn-kinematic"}
    assert set(df["family"]) <= set(corpus.FAMILIES) and (df["corpus_seed"] == SEED).all()
    per = df.groupby(["mechanism", "engine", "reference"])["comparison_passed"].first()
    want = {
        (m["name"], c["engine"], c["reference"]): c["passed"] for m in summary["mechanisms"] for c in m["comparisons"]
    }
    assert per.to_dict() == want


def test_corpus_page_shows_families_worst_errors_histograms_and_limits(in_process, tmp_path):
    from reports.corpus import write_corpus_page

    _, summary = in_process
    path = write_corpus_page(summary, tmp_path)
    html = path.read_text()
    for anchor in ('id="family-table"', 'id="worst-table"', 'id="limit-table"', "data:image/webp;base64,"):
        assert anchor in html
    families = {f"{m['corpus']['family']}/{m['corpus']['variant']}" for m in summary["mechanisms"]}
    assert all(f in html for f in families)
    assert "of 40 pass" in html and str(SEED) in html
    assert html.count("<tr>") >= len(families) + 1


@pytest.fixture
def broken_analytic(monkeypatch):
    """Inject a bug: the closed form's rocker angle is off by 1e-6 rad whenever a four-bar's crank is
    longer than 0.1 (file units) — a failure that survives shrinking, as a real one would."""

    def wrong(mech, res):
        if "rocker.theta" in res.columns and mech.links["crank"].length > 0.1:
            res.columns["rocker.theta"] = res.columns["rocker.theta"] + 1e-6
        return res

    plant(monkeypatch, "analytic", wrong)


def test_nightly_corpus_reproduces_and_minimizes_a_failure(tmp_path, broken_analytic, capsys):
    root = tmp_path / "nightly"
    argv = ["validate", "--nightly", "--corpus", "5", "--seed", "8", "--families", "fourbar/crank-rocker"]
    code = main([*argv, "--engines", "vloop,analytic", "--out", str(root), "--minimize-tries", "30"])
    assert code == 1
    out = capsys.readouterr().out
    (day,) = list(root.iterdir())
    summary = json.loads((day / "summary.json").read_text())
    jsonschema.validate(summary, SCHEMA)
    info = summary["corpus"]
    assert info["seed"] == 8 and info["n"] == 5
    assert info["command"] == "vloop corpus --seed 8 --n 5 --families fourbar/crank-rocker --out corpus-8"
    assert info["failures"]
    first = info["failures"][0]
    k = int(first["mechanism"][1:6])
    cmd = (
        f"vloop validate --corpus 1 --corpus-start {k} --seed 8 --families fourbar/crank-rocker "
        f"--engines vloop,analytic --out validation-8-{k}"
    )
    assert first["reproduce"] == cmd and f"reproduce with: {cmd}" in out
    assert "rocker.theta off by" in first["message"]
    # minimized: simpler, still failing, next to summary.json, a valid file with its sidecar
    mins = [m for m in info["minimized"] if m.get("file")]
    assert mins and all(Path(m["file"]).parent == day for m in mins)
    m0 = mins[0]
    before_digits, before_n, after_digits, after_n = m0["complexity"]
    assert after_digits < before_digits and after_n <= before_n and m0["still_failing"] == "analytic vs vloop"
    small = vloop.load(m0["file"])
    side = corpus.read_sidecar(m0["file"])
    assert side["minimized_from"]["seed"] == 8 and side["changed"]
    assert small.links["crank"].length > 0.1  # the failure's condition survived
    v = harness.validate_mechanism(m0["file"], ("vloop", "analytic"), mechanism=small, corpus=side)
    assert shrink.signature(v) == {"analytic vs vloop"}
    assert f"minimized {m0['mechanism']}" in out
    # the report shows the failing generated files, and corpus.html the commands
    assert "corpus.html" in (day / "report.html").read_text()
    page = (day / "corpus.html").read_text()
    assert cmd in page and "Minimized failures" in page
    # the same command regenerates the same mechanism
    assert (
        main(
            [
                "corpus",
                "--n",
                "1",
                "--start",
                str(k),
                "--seed",
                "8",
                "--families",
                "fourbar/crank-rocker",
                "--out",
                str(tmp_path / "r"),
            ]
        )
        == 0
    )
    again = (tmp_path / "r" / f"{first['mechanism']}.toml").read_text()
    assert again == Path(first["file"]).read_text()


def test_validate_a_folder_checks_the_sidecar_expectations(tmp_path, capsys):
    items, _ = corpus.generate(6, 5, limit_fraction=1.0)
    corpus.write(items, tmp_path / "c", seed=5)
    code = main(
        ["validate", str(tmp_path / "c"), "--engines", "vloop,analytic", "--out", str(tmp_path / "o"), "--no-report"]
    )
    assert code == 0, capsys.readouterr()
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    assert len(summary["mechanisms"]) == 6
    for m in summary["mechanisms"]:
        exp = m["corpus"]["expect"]
        assert exp["passed"] and exp["stop_sample"] is not None
        assert set(exp["observed"].values()) == {exp["stop_sample"]}


def test_validate_refuses_bad_runner_options(tmp_path, capsys):
    f = str(Path(__file__).resolve().parents[1] / "mechanisms" / "eightbar.toml")
    for extra, what in [
        (["--workers", "0"], "argument --workers: must be an integer from 1 to 256, got 0"),
        (["--timeout", "-1"], "argument --timeout: must be a number above 0 and at most 604800, got '-1'"),
        (["--timeout", "inf"], "argument --timeout: must be a number above 0 and at most 604800, got 'inf'"),
        (["--corpus", "0"], "argument --corpus: must be an integer from 1 to 1,000,000, got 0"),
    ]:
        assert main(["validate", f, "--engines", "vloop", "--out", str(tmp_path), "--no-report", *extra]) == 2
        err = capsys.readouterr().err
        assert what in err and err.count("\n") == 1, err


@pytest.mark.parametrize(
    "field, value, what",
    [
        ("family", "hexagon", "'family'/'variant'"),
        ("seed", -1, "'seed' and 'index'"),
        ("index", 2.5, "'seed' and 'index'"),
        ("params", {"a": float("nan")}, "'params'"),
        ("params", {"a": "1"}, "'params'"),
        ("expect", {"samples": 10**400}, "'expect.samples'"),
        ("expect", {"samples": 5, "stop_sample": 9}, "'expect.stop_sample'"),
        ("closed_form", "yes", "'closed_form'"),
        ("drive", [1], "'drive'"),
    ],
)
def test_a_malformed_sidecar_is_bad_input_naming_the_field(tmp_path, field, value, what, capsys):
    items, _ = corpus.generate(1, 3)
    corpus.write(items, tmp_path, seed=3)
    side = tmp_path / f"{items[0].name}.json"
    data = json.loads(side.read_text())
    data[field] = value
    side.write_text(json.dumps(data))  # NaN is written as NaN, which Python reads back
    code = main(["validate", str(tmp_path), "--engines", "vloop", "--out", str(tmp_path / "o"), "--no-report"])
    assert code == 2
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    err = summary["mechanisms"][0]["error"]
    assert str(side) in err and what in err
    # a JSON next to a file that is not a corpus sidecar is simply not one
    side.write_text(json.dumps({"hello": 1}))
    assert corpus.read_sidecar(tmp_path / f"{items[0].name}.toml") is None


def test_nightly_does_not_compare_generated_files_of_different_seeds():
    from validators import nightly

    def summary(seed, err):
        q = {"quantity": "l3.theta", "max_abs": err, "allowed": 1e-9, "passed": err <= 1e-9}
        comp = {"engine": "analytic", "reference": "vloop", "quantities": [q]}
        m = {"name": "c00003-fourbar-kite", "corpus": {"seed": seed}, "comparisons": [comp], "runs": {}}
        return {"mechanisms": [m]}

    assert nightly.compare_summaries(summary(2, 1e-8), summary(1, 1e-16)) == []
    (flag,) = nightly.compare_summaries(summary(1, 1e-8), summary(1, 1e-16))
    assert flag["kind"] == "crossed tolerance" and flag["mechanism"] == "c00003-fourbar-kite@seed1"


# ---------------------------------------------------------------- the odd engine out (validators.consensus)

PLANT_SEED = 2026
PLANT_INDICES = (
    2,
    21,
    39,
    50,
    52,
    55,
)  # a limit run, an eight-bar, an attached dyad, a Stephenson III, a ramp, a rocking


@pytest.fixture(scope="module")
def plant_files(tmp_path_factory) -> list[Path]:
    pytest.importorskip("pinocchio")
    pytest.importorskip("exudyn")
    out = tmp_path_factory.mktemp("plant")
    corpus.write([corpus.draw_item(PLANT_SEED, i).item for i in PLANT_INDICES], out, seed=PLANT_SEED)
    return sorted(out.glob("*.toml"))


def _perturbed(mech, res):
    """A copy of the engine's own result with every link angle off by 1e-6 rad (1000× the 1e-9 tolerance)."""
    res = dataclasses.replace(res, columns=dict(res.columns))
    for c in [c for c in res.columns if c.endswith(".theta")]:
        res.columns[c] = res.columns[c] + 1e-6
    return res


@pytest.mark.parametrize("wrong", ["pinocchio", "vloop"])
def test_a_planted_wrong_engine_is_the_one_blamed(wrong, plant_files, monkeypatch, tmp_path):
    """Four engines on six generated mechanisms, one of them made wrong on purpose: the consensus of the other
    three blames exactly that engine, on every mechanism, in summary.json and on the corpus page; nothing else
    is marked failing. A wrong vloop is the loudest line of the page."""
    from reports.corpus import write_corpus_page
    from validators.validate import _worst_text

    plant(monkeypatch, wrong, _perturbed)
    summary = harness.to_summary(harness.run(plant_files, ENGINES))
    jsonschema.validate(summary, SCHEMA)
    mechs = summary["mechanisms"]
    assert len(mechs) == len(PLANT_INDICES) and not summary["passed"]
    for m in mechs:
        v = m["verdict"]
        assert v["status"] == "blamed" and v["blamed"] == [wrong], (m["name"], v)
        assert v["reasons"][wrong].startswith(f"{wrong} disagrees with ")
        assert {e for e, s in v["engines"].items() if s != "pass"} <= {wrong, "analytic"}  # analytic: skipped
    tally = summary["verdicts"]["engines"]
    assert tally[wrong]["blamed"] == len(mechs) and tally[wrong]["pass"] == 0
    assert all(t["blamed"] == 0 and t["undecided"] == 0 for e, t in tally.items() if e != wrong)
    assert summary["verdicts"]["vloop_blamed"] == ([m["name"] for m in mechs] if wrong == "vloop" else [])
    for m in mechs:  # the printed table: the others are shown against each other, not at the planted error
        for e in (e for e in ENGINES if e not in ("vloop", wrong)):
            text = _worst_text(m, e)
            assert text == "-" or (float(text.split()[0]) < 1.0 and "blamed" not in text), (m["name"], e, text)
        if wrong != "vloop":
            assert _worst_text(m, wrong).endswith(" blamed") and float(_worst_text(m, wrong).split()[0]) > 100
    html = write_corpus_page(summary, tmp_path).read_text()
    row = html[html.index(f'<td class="mono">{wrong}</td>') :].split("</tr>")[0]
    assert f'<td class="cell fail">{len(mechs)}</td>' in row  # its blamed failures
    table = html[html.index('id="family-table"') :].split("</tbody>")[0].split("<tbody>")[1]
    for tr in table.split("</tr>")[:-1]:  # per family: the mechanisms' cell, then one cell per engine
        css = re.findall(r'<td class="cell (\w+)"', tr)
        assert [c for e, c in zip(ENGINES, css[1:], strict=True) if c == "fail"] == ["fail"], tr
        assert css[1 + ENGINES.index(wrong)] == "fail"
    if wrong == "vloop":
        loud = html.index('id="vloop-odd"')
        assert loud < html.index('id="corpus-verdict"') and "vloop is the odd one out on 6 mechanisms" in html
    else:
        assert 'id="vloop-odd"' not in html


def test_a_disagreement_without_majority_is_undecided():
    """Two engines that disagree cannot say which is right; with three, the odd one is blamed."""
    from validators.consensus import decide

    two = decide(["vloop", "pinocchio"], {("pinocchio", "vloop"): "l3.theta off"})
    assert two.status == "undecided" and two.engines == {"vloop": "undecided", "pinocchio": "undecided"}
    assert "two engines cannot tell" in two.reason
    three = decide(["vloop", "analytic", "pinocchio"], {("pinocchio", "vloop"): "x", ("analytic", "pinocchio"): "y"})
    assert three.status == "blamed" and three.blamed == ("pinocchio",)
    ring = decide(["a", "b", "c"], {("a", "b"): "1", ("b", "c"): "2", ("a", "c"): "3"})
    assert ring.status == "undecided" and set(ring.engines.values()) == {"undecided"}
    # a loose engine that cannot tell a wrong vloop from the others neither accuses nor excuses it
    loose = decide(
        ["vloop", "analytic", "pinocchio", "exudyn-dynamic"], {("analytic", "vloop"): "", ("pinocchio", "vloop"): ""}
    )
    assert loose.blamed == ("vloop",) and loose.engines["exudyn-dynamic"] == "pass"
    # two wrong engines out of five that agree with each other: both blamed by the three others
    pair = {(w, r): "" for w in ("exudyn-kinematic", "exudyn-dynamic") for r in ("vloop", "analytic", "pinocchio")}
    both = decide(["vloop", "analytic", "pinocchio", "exudyn-kinematic", "exudyn-dynamic"], pair)
    assert both.status == "blamed" and set(both.blamed) == {"exudyn-kinematic", "exudyn-dynamic"}
