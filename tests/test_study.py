"""Design studies (vloop.study), against independent references.

* Every variant of a grid equals ``vloop.solve`` of that variant written as its own mechanism file, whose
  t = 0 coordinates the test computes itself (the circle intersection below), to 1e-12 of the peak.
* The Grashof map equals the inequality s + l ≤ p + q computed here from the grid's integers, exactly.
* The Monte-Carlo standard deviation converges to the linearized one within its sampling error (computed
  here from the table's values), and the sensitivities equal central differences of single solves
  (another step, other files) to 1e-6, and the hand-derived ∂θ4/∂b = −1/(c·sin(θ4 − θ3)).
* Variants that cannot assemble or stop are reported and change nothing for the others; a study on a
  Dask LocalCluster (2 processes) gives the in-process numbers bit for bit; bad study files are refused.
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import vloop
from vloop.errors import MechanismError, MotionError
from vloop.studies import studyfile

ROOT = Path(__file__).resolve().parents[1]
TEXTBOOK = ROOT / "mechanisms" / "fourbar_textbook_example.toml"
A, B, C, D = 40.0, 120.0, 80.0, 100.0  # the textbook four-bar (mm): crank, coupler, rocker, ground
THETA2, OMEGA, ALPHA = math.radians(40.0), 25.0, 15.0


def fourbar_toml(a=A, b=B, c=C, d=D, omega=OMEGA, alpha=ALPHA, times="start = 0.0\nstop = 0.5\nstep = 0.0025") -> str:
    """The textbook four-bar with other numbers as a file of its own: B at t = 0 is where the circles of radius
    b about A and c about O4 cross, on the textbook's (open) side of the diagonal A–O4."""
    pa = a * complex(math.cos(THETA2), math.sin(THETA2))
    diag = d - pa
    dist = abs(diag)
    x = (b * b - c * c + dist * dist) / (2 * dist)
    h = math.sqrt(b * b - x * x)
    pb = pa + (x + 1j * h) * diag / dist
    return f"""name = "fb"
units = "mm"
[joints]
O2 = [0.0, 0.0]
A = [{pa.real!r}, {pa.imag!r}]
B = [{pb.real!r}, {pb.imag!r}]
O4 = [{d!r}, 0.0]
[links]
ground = {{ joints = ["O2", "O4"], ground = true }}
l2 = {{ joints = ["O2", "A"], length = {a!r} }}
l3 = {{ joints = ["A", "B"], length = {b!r} }}
l4 = {{ joints = ["O4", "B"], length = {c!r} }}
[[drivers]]
link = "l2"
omega = {omega!r}
alpha = {alpha!r}
[time]
{times}
"""


def single(**numbers) -> vloop.Result:
    return vloop.solve(vloop.loads(fourbar_toml(**numbers)))


def close(a, b, scale, rtol):
    a, b = np.asarray(a, float), np.asarray(b, float)
    return np.max(np.abs(a - b)) <= rtol * scale


@pytest.fixture(scope="module")
def textbook():
    return vloop.load(TEXTBOOK)


# ---------------------------------------------------------------- grids


def test_coupler_grid_equals_single_solves_of_each_variant_file(textbook):
    lengths = [100.0, 105.0, 110.0, 115.0, 120.0, 125.0, 130.0, 135.0]
    series = ["l3.theta", "l4.theta", "l4.omega", "l4.alpha", "B.ax", "B.vy"]
    res = vloop.study(
        textbook,
        {"links.l3.length": lengths},
        [f"{q}.series" for q in series] + ["B.path", "l4.theta.range", "l4.alpha.peak"],
        sensitivity="none",
    )
    table = res.table
    assert list(table["links.l3.length"]) == lengths
    assert (table["solver"] == "batch").all() and table["completed"].all()
    for _, row in table.iterrows():
        ref = single(b=row["links.l3.length"])
        for q in series:
            peak = np.max(np.abs(ref[q]))
            assert close(row[f"{q}.series"], ref[q], peak, 1e-12), (row["links.l3.length"], q)
        assert close(row["B.path.x"], ref["B.x"], np.max(np.abs(ref["B.x"])), 1e-12)
        assert abs(row["l4.theta.range"] - np.ptp(ref["l4.theta"])) <= 1e-12 * np.max(np.abs(ref["l4.theta"]))
        assert abs(row["l4.alpha.peak"] - np.max(np.abs(ref["l4.alpha"]))) <= 1e-12 * np.max(np.abs(ref["l4.alpha"]))


def test_grashof_map_is_the_inequality_and_only_cranks_complete(textbook):
    bs, cs = np.arange(20.0, 161.0, 10.0), np.arange(20.0, 141.0, 10.0)
    res = vloop.study(
        textbook,
        [{"name": "links.l3.length", "values": bs.tolist()}, {"name": "links.l4.length", "values": cs.tolist()}],
        ["grashof", "transmission_angle.min"],
        times=np.linspace(0.0, 0.25, 31),
        sensitivity="none",
    )
    t = res.table
    assert len(t) == len(bs) * len(cs)
    names = {
        0: "Grashof double-crank",
        1: "Grashof crank-rocker",
        2: "Grashof double-rocker",
        3: "Grashof rocker-crank",
    }
    for _, row in t.iterrows():
        L = [D, A, row["links.l3.length"], row["links.l4.length"]]  # ground, input (crank), coupler, output
        s, l_ = min(L), max(L)
        pq = sum(L) - s - l_
        assert row["grashof.is_grashof"] == (s + l_ <= pq)
        want = (
            "special Grashof (change point)"
            if s + l_ == pq
            else names[int(np.argmin(L))]
            if s + l_ < pq
            else "non-Grashof triple-rocker"
        )
        assert row["grashof"] == want
    # the crank turns fully (0.25 s at 25 rad/s is more than a turn) exactly where the crank is the shortest
    # link of a Grashof linkage: every crank-rocker completes; no triple-rocker does
    assert t.loc[t["grashof"] == "Grashof crank-rocker", "completed"].all()
    assert not t.loc[t["grashof"] == "non-Grashof triple-rocker", "completed"].any()
    done = t[t["completed"] & (t["grashof"] == "Grashof crank-rocker")]
    assert (done["transmission_angle.min"] > 0).all() and (done["transmission_angle.min"] < math.pi / 2).all()


# ---------------------------------------------------------------- tolerances and sensitivities


TOLERANCES = [
    {"name": "links.l2.length", "tolerance": {"dist": "uniform", "half_width": 0.05}},
    {"name": "links.l3.length", "tolerance": {"dist": "uniform", "half_width": 0.05}},
    {"name": "links.l4.length", "tolerance": {"dist": "uniform", "half_width": 0.05}},
    {"name": "joints.O4.x", "tolerance": {"dist": "normal", "sigma": 0.03}},
]


@pytest.fixture(scope="module")
def tolerance_study(textbook):
    return vloop.study(
        textbook,
        TOLERANCES,
        ["l4.theta.series", "l4.theta.range", "transmission_angle.min"],
        times=np.linspace(0.0, 0.25, 46),
        samples=10_000,
        seed=7,
    )


def _sd_and_error(y: np.ndarray) -> tuple[float, float]:
    """Sample standard deviation and its sampling error √((κ − 1)/(4n))·s (delta method, κ the kurtosis)."""
    m = y.mean()
    m2, m4 = np.mean((y - m) ** 2), np.mean((y - m) ** 4)
    s = y.std(ddof=1)
    return s, s * math.sqrt((m4 / m2**2 - 1.0) / (4 * len(y)))


def test_monte_carlo_sigma_converges_to_the_linearized_one(tolerance_study):
    res = tolerance_study
    assert res.counts["completed"] == 10_000
    hist = np.array(res.table["l4.theta.series"].tolist())  # (draws, samples)
    bands = res.bands[res.bands["output"] == "l4.theta.series"]
    lin = bands["linearized_sigma"].to_numpy()
    for k in range(hist.shape[1]):
        sd, err = _sd_and_error(hist[:, k])
        assert abs(sd - lin[k]) <= 4 * err, (k, sd, lin[k], err)
        assert err < 0.01 * sd  # 10,000 draws: the sampling error is below 1 %
    for name in ("l4.theta.range", "transmission_angle.min"):
        sd, err = _sd_and_error(res.table[name].to_numpy())
        row = res.summary[res.summary["output"] == name].iloc[0]
        assert abs(sd - row["linearized_sigma"]) <= 4 * err
        assert row["mc_sigma"] == pytest.approx(sd, rel=1e-12) and row["mc_sigma_error"] == pytest.approx(err, rel=1e-9)


def test_sensitivity_equals_central_differences_of_single_solves(textbook):
    times = "times = [0.0, 0.03, 0.07, 0.11, 0.16, 0.2, 0.25]"
    res = vloop.study(
        textbook,
        {"links.l3.length": [B], "joints.O4.x": [D], "drivers.l2.omega": [OMEGA], "links.l2.length": [A]},
        ["l4.theta.series", "l4.theta.range", "l4.alpha.peak"],
        times=[0.0, 0.03, 0.07, 0.11, 0.16, 0.2, 0.25],
        sensitivity="each",
    )
    keys = {"links.l3.length": "b", "joints.O4.x": "d", "drivers.l2.omega": "omega", "links.l2.length": "a"}
    base = {"a": A, "b": B, "d": D, "omega": OMEGA}
    row = res.table.iloc[0]
    for param, key in keys.items():
        h = 1e-4 * base[key]  # another step than the study's (6e-6), other files
        up, down = single(**{key: base[key] + h}, times=times), single(**{key: base[key] - h}, times=times)
        fd = (up["l4.theta"] - down["l4.theta"]) / (2 * h)
        band = res.bands[res.bands["output"] == "l4.theta.series"][f"d/d({param})"].to_numpy()
        assert close(band, fd, np.max(np.abs(fd)), 1e-6), param
        for out, ref in (("l4.theta.range", np.ptp), ("l4.alpha.peak", lambda x: np.max(np.abs(x)))):
            col = "l4.theta" if out.startswith("l4.theta") else "l4.alpha"
            fd_out = (ref(up[col]) - ref(down[col])) / (2 * h)
            assert abs(row[f"d({out})/d({param})"] - fd_out) <= 1e-6 * max(abs(fd_out), 1e-3), (out, param)


def test_sensitivity_to_the_coupler_is_the_hand_derived_one(tolerance_study):
    # a·e2 + b·e3 − c·e4 − d = 0 at fixed θ2; ∂/∂b: e3 + j·b·e3·θ3' − j·c·e4·θ4' = 0, times e^{−jθ3}, real part:
    # 1 + c·sin(θ4 − θ3)·θ4' = 0, so ∂θ4/∂b = −1/(c·sin(θ4 − θ3))
    bands = tolerance_study.bands
    nominal = single(times="times = " + str(np.linspace(0.0, 0.25, 46).tolist()))
    hand = -1.0 / (C * np.sin(nominal["l4.theta"] - nominal["l3.theta"]))
    got = bands[bands["output"] == "l4.theta.series"]["d/d(links.l3.length)"].to_numpy()
    assert close(got, hand, np.max(np.abs(hand)), 1e-7)


# ---------------------------------------------------------------- failures are per variant


def test_variants_that_cannot_assemble_or_stop_are_reported_and_the_others_go_on(textbook):
    lengths = [2.0, 120.0, 150.0, 5.0, 110.0]  # 2, 5: cannot reach at t = 0; 150: non-Grashof, stops
    outs = ["l4.theta.series", "l4.theta.range"]
    res = vloop.study(textbook, {"links.l3.length": lengths}, outs, sensitivity="none")
    t = res.table.set_index("links.l3.length")
    for b in (2.0, 5.0):
        assert not t.loc[b, "assembled"] and not t.loc[b, "completed"]
        assert "cannot assemble at t = 0" in t.loc[b, "reason"] and "loop 1" in t.loc[b, "reason"]
        assert (
            pd.isna(t.loc[b, "stopped_at"])
            and pd.isna(t.loc[b, "l4.theta.range"])
            and t.loc[b, "l4.theta.series"] is None
        )
    with pytest.raises(MotionError) as exc:
        single(b=150.0)
    assert t.loc[150.0, "assembled"] and not t.loc[150.0, "completed"]
    assert t.loc[150.0, "stopped_at"] == pytest.approx(exc.value.limit_time, abs=1e-9)
    assert t.loc[150.0, "stopped_sample"] == exc.value.sample
    assert "cannot assemble" in t.loc[150.0, "reason"] and pd.isna(t.loc[150.0, "l4.theta.range"])
    alone = vloop.study(textbook, {"links.l3.length": [120.0, 110.0]}, outs, sensitivity="none").table
    for b in (120.0, 110.0):
        mine = alone[alone["links.l3.length"] == b].iloc[0]
        assert t.loc[b, "completed"] and t.loc[b, "l4.theta.range"] == mine["l4.theta.range"]
        assert t.loc[b, "l4.theta.series"] == mine["l4.theta.series"]
    assert res.counts == {
        "variants": 5,
        "completed": 2,
        "stopped": 1,
        "not_assembled": 2,
        "designs_solved": 5,
        "single_runs": 1,
    }


# ---------------------------------------------------------------- other mechanisms: Newton blocks, sliders


@pytest.mark.parametrize(
    ("file", "params"),
    [
        ("sixbar_stephenson3_output_driven.toml", {"joints.O6.x": None, "joints.D.y": None}),
        ("slider_crank_offset.toml", {"sliders.l4.offset": None, "sliders.l4.angle": None, "links.l3.length": None}),
        ("inverted_slider_crank.toml", {"joints.O4.y": None, "drivers.l2.theta0": None}),
    ],
)
def test_newton_and_slider_variants_equal_their_own_files(file, params):
    mech = vloop.load(ROOT / "mechanisms" / file)
    from vloop.core.variants import resolve

    tol = []
    for name in params:
        ref = resolve(mech, name, name)
        tol.append({"name": name, "tolerance": {"dist": "normal", "sigma": 2e-3 * ref.typical}})
    cols = [*[c for c in vloop.solve(mech).columns if not c.endswith(".theta")][:12], f"{mech.moving_links[-1]}.theta"]
    res = vloop.study(mech, tol, [f"{c}.series" for c in cols], samples=4, seed=3, sensitivity="none")
    assert res.table["completed"].all() and (res.table["solver"] == "batch").all()
    for i in range(len(res.table)):
        own = res.variant_mechanism(i)
        again = vloop.loads(vloop.dumps(own))  # a file of its own: it loads and closes its loops
        ref = vloop.solve(again, mech.times)
        for c in cols:
            got = np.asarray(res.table.loc[i, f"{c}.series"])
            diff = got - ref[c]
            if c.endswith(".theta"):
                diff = np.angle(np.exp(1j * diff))  # whole turns: the study counts them from the nominal's
            assert np.max(np.abs(diff)) <= 1e-11 * max(np.max(np.abs(ref[c])), 1e-9 * mech.scale), (i, c)


def _every_number(mech) -> list[str]:
    """Every variable number of a mechanism file: coordinates, binary lengths, slider axes and offsets, drivers."""
    names = [f"joints.{j}.{c}" for j in mech.joints for c in "xy"] + [f"points.{p}.x" for p in mech.points]
    names += [f"links.{n}.length" for n, lk in mech.links.items() if not lk.ground and len(lk.joints) == 2]
    names += [f"sliders.{s}.{f}" for s in mech.sliders for f in ("angle", "offset")]
    for d in mech.drivers:
        if d.profile is None:
            names += [f"drivers.{d.target}.{f}" for f in (("theta0", "omega") if d.kind == "crank" else ("s0", "v"))]
    return names


CATALOG = sorted((ROOT / "mechanisms").glob("*.toml"))
NEWTON = ["eightbar.toml", "jansen_pair.toml", "whitworth_quick_return.toml"]


@pytest.mark.parametrize(
    ("path", "method"),
    [(p, "auto") for p in CATALOG] + [(p, "newton") for p in CATALOG if p.name in NEWTON],
    ids=lambda x: x.stem if isinstance(x, Path) else x,
)
def test_catalog_variants_equal_their_own_files(path, method):
    """Every number of every catalog file varied at once (σ = 0.2 % of its size): each variant equals its own file
    solved by vloop.solve, on the closed-form path and (three files) the Newton path."""
    import dataclasses

    from vloop.core.variants import resolve

    mech = vloop.load(path)
    if method == "newton":
        mech = dataclasses.replace(mech, options={**mech.options, "method": "newton"})
    params = [{"name": n, "tolerance": {"dist": "normal", "sigma": 2e-3 * resolve(mech, n, n).typical}}
              for n in _every_number(mech)]  # fmt: skip
    cols = list(vloop.solve(mech, mech.times[:2]).columns)
    res = vloop.study(mech, params, [f"{c}.series" for c in cols], samples=3, seed=5, sensitivity="none")
    assert res.table["assembled"].all()
    for i in np.nonzero(res.table["completed"].to_numpy())[0]:
        ref = vloop.solve(vloop.loads(vloop.dumps(res.variant_mechanism(i))), mech.times)
        for c in cols:
            diff = np.asarray(res.table.loc[i, f"{c}.series"]) - ref[c]
            if c.endswith(".theta"):
                diff = np.angle(np.exp(1j * diff))
            assert np.max(np.abs(diff)) <= 1e-11 * max(np.max(np.abs(ref[c])), 1e-9 * mech.scale), (i, c)
    for i in np.nonzero(~res.table["completed"].to_numpy())[0]:  # a variant that stops: as its own file does
        with pytest.raises(MotionError) as exc:
            vloop.solve(vloop.loads(vloop.dumps(res.variant_mechanism(i))), mech.times)
        assert res.table.loc[i, "stopped_sample"] == exc.value.sample


# ---------------------------------------------------------------- scale-out: chunks and Dask


SMALL = dict(samples=300, seed=11, times=np.linspace(0.0, 0.25, 25))
SMALL_OUTPUTS = ["l4.theta.series", "l4.alpha.peak", "transmission_angle.min", "B.path", "grashof"]


def _assert_identical(a, b):
    pd.testing.assert_frame_equal(a.table, b.table, check_exact=True)
    for name in ("summary", "sensitivity", "bands"):
        pd.testing.assert_frame_equal(getattr(a, name), getattr(b, name), check_exact=True)


def test_chunking_never_changes_a_number(textbook):
    params = [*TOLERANCES[:2], {"name": "links.l4.length", "values": [79.0, 80.0, 81.0]}]
    one = vloop.study(textbook, params, SMALL_OUTPUTS, chunk=100_000, **SMALL)
    many = vloop.study(textbook, params, SMALL_OUTPUTS, chunk=7, **SMALL)
    assert len(one.table) == 900
    _assert_identical(one, many)


def test_dask_local_cluster_gives_the_in_process_numbers_bit_for_bit(textbook):
    pytest.importorskip("distributed")
    here = vloop.study(textbook, TOLERANCES, SMALL_OUTPUTS, **SMALL)
    there = vloop.study(textbook, TOLERANCES, SMALL_OUTPUTS, workers=2, chunk=60, **SMALL)
    _assert_identical(here, there)
    assert here.counts == there.counts


# ---------------------------------------------------------------- the study file and the command


STUDY = """mechanism = "{mech}"
samples = 50
seed = 2
[time]
start = 0.0
stop = 0.25
step = 0.005
[[parameters]]
name = "links.l3.length"
values = [119.0, 121.0]
tolerance = {{ dist = "uniform", half_width = 0.05 }}
[[outputs]]
quantity = "l4.theta"
stat = "series"
[[outputs]]
quantity = "l4.theta"
stat = "range"
name = "swing"
"""


def test_command_writes_parquet_tables_and_pictures(tmp_path):
    f = tmp_path / "s.toml"
    f.write_text(STUDY.format(mech=TEXTBOOK.as_posix()))
    out = tmp_path / "out"
    r = subprocess.run(
        [sys.executable, "-m", "vloop.cli", "study", str(f), "--out", str(out), "--plot"],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 0, r.stderr
    names = {p.name for p in out.iterdir()}
    assert {"variants.parquet", "summary.parquet", "sensitivity.parquet", "bands.parquet", "study.json"} <= names
    assert {"band_l4.theta.series.png", "hist_swing.png"} <= names
    table = pd.read_parquet(out / "variants.parquet")
    assert len(table) == 100 and set(table["grid"]) == {0, 1} and table["completed"].all()
    assert np.all(np.isfinite(table["swing"])) and len(table["l4.theta.series"].iloc[0]) == 51
    assert "swing" in r.stdout and "linearized σ" in r.stdout


def test_outputs_of_unfinished_variants_are_null_in_parquet(tmp_path, textbook):
    res = vloop.study(
        textbook, {"links.l3.length": [2.0, 120.0, 150.0]}, ["l4.theta.range", "l4.theta.series"], sensitivity="none"
    )
    res.write(tmp_path)
    import pyarrow.parquet as pq

    t = pq.read_table(tmp_path / "variants.parquet")
    swing = t.column("l4.theta.range")
    assert swing.null_count == 2 and t.column("stopped_at").null_count == 2
    assert np.all(np.isfinite(np.asarray(swing.drop_null())))


HOSTILE = [0, -0.0, 1e308, 5e-324, float("nan"), float("inf"), 10**400, "1.0", [[1.0]], True]


def _study(mech, **over):
    data = {"parameters": [{"name": "links.l3.length", "values": [120.0]}], "outputs": ["l4.theta.range"]}
    data.update(over)
    return studyfile.from_dict(data, mech, source="s.toml")


def _never_valid(where: str, v) -> bool:
    """Values a field can never take: not a number, a boolean, not finite, too large for a float, a count that is
    not a positive integer, a length or width that is not positive."""
    if isinstance(v, bool) or not isinstance(v, int | float):
        return True
    if where in ("samples", "chunk", "num", "seed"):
        return not isinstance(v, int) or v < (0 if where == "seed" else 1) or v > 10**7
    if abs(v) > 1.8e308 or not math.isfinite(v):
        return True
    return where in ("values", "half_width", "sigma") and not v > 0


@pytest.mark.parametrize("value", HOSTILE, ids=repr)
@pytest.mark.parametrize(
    ("where", "build"),
    [
        ("samples", lambda v: {"samples": v, "parameters": TOLERANCES[:1]}),
        ("seed", lambda v: {"seed": v}),
        ("chunk", lambda v: {"chunk": v}),
        ("num", lambda v: {"parameters": [{"name": "links.l3.length", "start": 100.0, "stop": 120.0, "num": v}]}),
        ("values", lambda v: {"parameters": [{"name": "links.l3.length", "values": [v]}]}),
        ("start", lambda v: {"parameters": [{"name": "joints.O4.x", "start": v, "stop": 1e308, "num": 3}]}),
        (
            "half_width",
            lambda v: {
                "samples": 3,
                "parameters": [{"name": "joints.O4.x", "tolerance": {"dist": "uniform", "half_width": v}}],
            },
        ),
        (
            "sigma",
            lambda v: {
                "samples": 3,
                "parameters": [{"name": "joints.O4.x", "tolerance": {"dist": "normal", "sigma": v}}],
            },
        ),
        ("quantity", lambda v: {"outputs": [{"quantity": v}]}),
        ("stat", lambda v: {"outputs": [{"quantity": "l4.theta", "stat": v}]}),
        ("name", lambda v: {"parameters": [{"name": v, "values": [1.0]}]}),
    ],
)
def test_hostile_values_are_refused_with_one_line_naming_the_entry(textbook, where, build, value):
    """A value a field can never take is refused in one line naming the entry; a value it can take (a huge or
    tiny length, a wide tolerance) runs, and every number the study reports is finite or null."""
    from vloop.studies.study import run

    try:
        spec = _study(textbook, **build(value))
        spec = spec.__class__(**{**spec.__dict__, "times": np.linspace(0.0, 0.05, 5)})
        res = run(spec)
    except MechanismError as exc:
        msg = str(exc)
        assert "\n" not in msg and msg.startswith("s.toml: [")
        assert exc.entry in ("study", "samples") or exc.entry.startswith(("parameters[", "outputs["))
        return
    assert not _never_valid(where, value), (where, value)
    assert where not in ("quantity", "stat", "name")
    num = res.table.select_dtypes("number").to_numpy(dtype=float)
    assert not np.any(np.isinf(num))
    for df in (res.summary, res.sensitivity, res.bands):
        if len(df):
            assert not np.any(np.isinf(df.select_dtypes("number").to_numpy(dtype=float)))


@pytest.mark.parametrize(
    ("data", "words"),
    [
        ({"parameters": [{"name": "links.l9.length", "values": [1.0]}]}, "no link 'l9'"),
        ({"parameters": [{"name": "links.ground.length", "values": [1.0]}]}, "the ground's dimensions"),
        ({"parameters": [{"name": "links.l3.mass", "values": [1.0]}]}, "no variable field"),
        ({"parameters": [{"name": "links.l3.length", "values": [1.0], "start": 1.0}]}, "not both"),
        ({"parameters": [{"name": "links.l3.length", "values": [-1.0]}]}, "must be positive"),
        ({"parameters": [{"name": "links.l3.length"}]}, "give values"),
        (
            {"parameters": [{"name": "links.l3.length", "tolerance": {"dist": "cauchy", "sigma": 1.0}}], "samples": 3},
            "'dist'",
        ),
        (
            {
                "parameters": [{"name": "links.l3.length", "tolerance": {"dist": "normal", "half_width": 1.0}}],
                "samples": 3,
            },
            "takes 'sigma'",
        ),
        (
            {"parameters": [{"name": "links.l3.length", "tolerance": {"dist": "normal", "sigma": 1.0}}]},
            "'samples' is needed",
        ),
        ({"samples": 10}, "no parameter has a tolerance"),
        ({"parameters": [{"name": "links.l3.length", "values": [1.0], "colour": 1}]}, "unknown key"),
        ({"outputs": [{"quantity": "l4.theta", "stat": "median"}]}, "'stat' of l4.theta"),
        ({"outputs": [{"quantity": "B.speed"}, {"quantity": "B.speed"}]}, "used twice"),
        ({"outputs": [{"quantity": "l4.theta", "name": "a b"}]}, "'name' may use only"),
        ({"outputs": [{"quantity": "grashof.7"}]}, None),
        ({"outputs": [{"quantity": "l4.theta", "name": "reason"}]}, "a column of the table already"),
        ({"outputs": [{"quantity": "l4.theta", "name": "links.l3.length"}]}, "a column of the table already"),
        (
            {"parameters": [{"name": "joints.O4.x", "tolerance": {"dist": "normal", "sigma": 1e308}}], "samples": 50},
            "overflow",
        ),
        ({"sensitivity": "maybe"}, "'sensitivity'"),
        ({"bogus": 1}, "unknown key"),
    ],
)
def test_bad_study_entries_say_what_and_where(textbook, data, words):
    from vloop.studies.study import run

    with pytest.raises(MechanismError) as exc:
        run(_study(textbook, **data))
    if words:
        assert words in str(exc.value)
    assert "\n" not in str(exc.value)


def test_bad_study_file_exits_2_with_one_line(tmp_path):
    f = tmp_path / "bad.toml"
    f.write_text(STUDY.format(mech=TEXTBOOK.as_posix()).replace("values = [119.0, 121.0]", "values = [119.0, nan]"))
    r = subprocess.run(
        [sys.executable, "-m", "vloop.cli", "study", str(f), "--out", str(tmp_path / "o")],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "parameters[0]" in r.stderr and "not finite" in r.stderr
    assert not (tmp_path / "o").exists()


def test_study_is_in_the_public_api(textbook):
    assert vloop.study is vloop.study  # lazy attribute
    from vloop.studies.study import study

    assert vloop.study is study
