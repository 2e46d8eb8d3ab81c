"""Long runs solved in chunks give the run in one piece, streamed outputs and memory budgets hold, and the
solver's faster evaluations give the direct ones: sums entry by entry or by products, condition numbers
against the SVD, Newton blocks on change points, parallelograms and redundant loops, the grid by one bound.

References are independent of vloop's loop equations: hand closed forms written out here or in
validators/analytic/*.py, and the run solved in one piece (a chunk border must change nothing).
"""

from __future__ import annotations

import dataclasses
import math
import os
import resource
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import vloop
from tests.conftest import MECHANISMS, mechanism_files
from tests.test_bad_input import ISOSCELES
from tests.test_change_points import parallelogram
from validators import analytic
from validators.analytic import fourbar as analytic_fourbar
from vloop.cli import main
from vloop.compare import assert_histories_close
from vloop.core import grid as sample_grid
from vloop.core import plans, solver
from vloop.core import sums as vector_sums
from vloop.files.budget import MemoryBudgetError, parse_size
from vloop.method.loops import LoopSystem, loop_jacobian

ROOT = Path(__file__).resolve().parents[1]


def solve_in_chunks(mech, times=None, chunk=37, **kw):
    """The run solved in chunks of ``chunk`` samples (the default chunk is larger than these runs)."""
    old = solver.CHUNK
    solver.CHUNK = chunk
    try:
        return vloop.solve(mech, times, **kw)
    finally:
        solver.CHUNK = old


def outcome(fn):
    try:
        return fn(), None
    except vloop.MotionError as exc:
        return exc.partial, exc


@pytest.mark.parametrize(
    ("name", "method"),
    [
        ("eightbar", "auto"),
        ("eightbar", "newton"),
        ("fivebar_two_cranks", "auto"),
        ("sixbar_stephenson3_output_driven", "auto"),
        ("jansen_pair", "newton"),
        ("fourbar_nongrashof_past_limit", "auto"),
        ("fourbar_nongrashof_past_limit", "newton"),
    ],
)
def test_chunk_borders_change_nothing(name, method):
    """Chunks of 37 samples against one piece: same rows, same failure, same health; values agree to the
    Newton tolerance (1e-12 per step, amplified by the condition number in accelerations: 1e-10 of peak)."""
    mech = vloop.load(MECHANISMS / f"{name}.toml")
    t = np.linspace(mech.times[0], mech.times[-1], 1001)
    one, e1 = outcome(lambda: vloop.solve(mech, t, method=method))
    many, e2 = outcome(lambda: solve_in_chunks(mech, t, method=method))
    assert len(one) == len(many) and (e1 is None) == (e2 is None)
    if e1 is not None:
        assert (e1.sample, e1.time, str(e1)) == (e2.sample, e2.time, str(e2))
        # bisected to 1e-12 of the driver's range (a chunk's range is smaller: located at least as tightly)
        span = np.ptp(vloop.drivers.evaluate_all(mech, t)[0], axis=0)
        assert np.all(np.abs(np.subtract(e1.limit_value, e2.limit_value)) <= 2e-12 * span)
    assert_histories_close(many, one, rtol=1e-10 if method == "newton" or name.startswith("six") else 1e-13)
    for k in ("branch", "ill_conditioned", "change_point"):
        assert np.array_equal(one.health[k], many.health[k]), k


def test_a_long_run_is_solved_in_chunks_written_in_place(monkeypatch):
    """solve() on more samples than one chunk takes (forced here: chunks of up to 16,384 for the Jansen pair's
    48,000) splits them evenly, three chunks of 16,000 written in place into the run's columns — the streamed
    run's numbers (chunks of 16,384, joined here by hand) to round-off (1e-13 of peak, as for any chunk borders:
    numpy rounds some operations differently on arrays of other lengths) and the same flags, every quantity within
    1e-12 of its peak of the hand closed form (validators.analytic), every column one contiguous array of the
    run's length."""
    assert solver._in_memory_chunk(48_000) == 48_000 and solver._in_memory_chunk(100_000) == 50_000
    monkeypatch.setattr(solver, "IN_MEMORY", 1)
    assert solver._in_memory_chunk(48_000) == 16_000
    mech = vloop.load(MECHANISMS / "jansen_pair.toml")
    system = vloop.compile(mech)
    t = np.linspace(mech.times[0], mech.times[-1], 48_000)
    sinks = []
    monkeypatch.setattr(solver, "_Sink", lambda *a, _Sink=solver._Sink: sinks.append(_Sink(*a)) or sinks[-1])
    res = vloop.solve(system, t)
    assert len(sinks) == 1  # the run's columns, every chunk written into them
    parts = list(solver.solve_iter(system, t))
    assert len(parts) == 3
    for name, col in res.columns.items():
        assert col.flags.c_contiguous and col.shape == (48_000,) and col.base is None, name
    assert_histories_close(res, solver.join(parts), rtol=1e-13, min_columns=len(res.columns))
    for name in ("branch", "ill_conditioned", "change_point"):
        assert np.array_equal(res.health[name], np.concatenate([p.health[name] for p in parts])), name
    assert_histories_close(res, analytic.solve(mech, res.t), rtol=1e-12, min_columns=10)


def points_by_definition(system: LoopSystem, res: vloop.Result) -> tuple[np.ndarray, ...]:
    """Every point's position, velocity and acceleration (rows, points) summed term by term from the Result's own
    angle and slider columns — the definition, not vloop's grouped sums: z = (r + s)·e^{j(θ + δ)},
    ż = ṡ·e + jω·z, z̈ = s̈·e + 2jωṡ·e + (jα − ω²)·z per term, P = Σ_t path[t, p]·z_t."""
    n, na, ns = len(res.t), system.n_angles, len(system.slider_names)
    th, w, al = np.zeros((n, na + 1)), np.zeros((n, na + 1)), np.zeros((n, na + 1))  # column na: the ground
    for name, a, offset in system.link_outputs:
        if a >= 0:
            th[:, a] = res.columns[f"{name}.theta"] - offset
            w[:, a], al[:, a] = res.columns[f"{name}.omega"], res.columns[f"{name}.alpha"]
    s, sd, sdd = np.zeros((n, ns + 1)), np.zeros((n, ns + 1)), np.zeros((n, ns + 1))  # column ns: no slider
    for i, name in enumerate(system.slider_names):
        s[:, i], sd[:, i], sdd[:, i] = (res.columns[f"{name}.{q}"] for q in ("s", "v", "a"))
    a, i = np.where(system.t_ang < 0, na, system.t_ang), np.where(system.t_sl < 0, ns, system.t_sl)
    e = np.exp(1j * (th[:, a] + system.t_delta))
    z = (system.t_r + s[:, i]) * e
    zd = sd[:, i] * e + 1j * w[:, a] * z
    zdd = sdd[:, i] * e + 2j * w[:, a] * sd[:, i] * e + (1j * al[:, a] - w[:, a] ** 2) * z
    return z @ system.path, zd @ system.path, zdd @ system.path


@pytest.mark.parametrize("entry_by_entry", [True, False], ids=["entry-by-entry", "dense-product"])
@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_point_outputs_are_their_terms_summed(path, entry_by_entry, monkeypatch):
    """The points' columns equal Σ path·z from the Result's angles and sliders, whether every sum (the blocks'
    too) is evaluated entry by entry or by the dense product (each forced here; vloop picks the cheaper per sum).
    Tolerance 1e-12 of each quantity's peak over the points: the definition recomputes e^{jθ} from the
    unwrapped θ (≈ |θ|·ε)."""
    monkeypatch.setattr(vector_sums.Entries, "pay", lambda self: self if entry_by_entry else None)
    system = vloop.compile(vloop.load(path))
    res, _ = outcome(lambda: vloop.solve(system, np.linspace(0.0, system.mechanism.times[-1], 240)))
    sums = [*plans.system_sums(system), *(s for p in plans.block_plans(system) for s in (p.total, p.known_sum))]
    assert all((s.entries is not None) == entry_by_entry for s in sums)
    for ref, (x, y) in zip(points_by_definition(system, res), (("x", "y"), ("vx", "vy"), ("ax", "ay")), strict=True):
        got = np.stack([res.columns[f"{p}.{x}"] + 1j * res.columns[f"{p}.{y}"] for p in system.point_names], axis=1)
        assert np.max(np.abs(got - ref)) <= 1e-12 * np.max(np.abs(ref)), (x, np.max(np.abs(got - ref)))


def variables_of(system: LoopSystem, res: vloop.Result) -> np.ndarray:
    """(rows, n_vars): every angle and slider variable per sample, from the Result's columns."""
    q = np.zeros((len(res.t), system.n_vars))
    for name, a, offset in system.link_outputs:
        if a >= 0:
            q[:, a] = res.columns[f"{name}.theta"] - offset
    for i, name in enumerate(system.slider_names):
        q[:, system.n_angles + i] = res.columns[f"{name}.s"]
    return q


@pytest.mark.parametrize(
    "name",
    [
        "eightbar",
        "fourbar_textbook_example",
        "slider_crank_offset",
        "jansen_pair",
        "whitworth_quick_return",
        "inverted_slider_crank",
        "fourbar_nongrashof_rocking",
        "fourbar_nongrashof_past_limit",
    ],
)
def test_closed_form_condition_numbers_are_the_svd_ones(name):
    """health.cond on the closed-form path is, per sample, the largest 2-norm condition number (numpy's SVD) of the
    blocks' Jacobians, angle columns divided by the mechanism size — each Jacobian built by loops.loop_jacobian from
    the Result's own angles and sliders, on every dyad kind and up to a toggle (cond ≈ 2e3). Relative tolerance
    1e-13 + 16·ε·cond: an exact formula for a 2×2 matrix against the SVD, both with ~cond·ε of round-off (measured
    ≤ 3.7·ε·cond)."""
    mech = vloop.load(MECHANISMS / f"{name}.toml")
    times = np.linspace(0.0, mech.times[-1], 157)
    if name == "fourbar_nongrashof_past_limit":  # up to the toggle: cond → ∞ (the run stops at cond ≈ 2e3)
        lim = math.acos((3.0**2 + 6.0**2 - 8.5**2) / (2 * 3.0 * 6.0))
        times = (lim - mech.drivers[0].x0) / mech.drivers[0].v0 - np.geomspace(1e-1, 1e-9, 300)
    system = vloop.compile(mech)
    assert all(b.kind in ("RRR", "RRP", "RPR") for b in system.blocks)
    res, _ = outcome(lambda: vloop.solve(system, times))
    q = variables_of(system, res)
    worst = np.zeros(len(q))
    for b in system.blocks:
        scale = np.where(np.array(b.unknowns) < system.n_angles, 1.0 / system.mechanism.scale, 1.0)
        J = np.array([loop_jacobian(system, row, list(b.loops), list(b.unknowns)) for row in q]) * scale
        worst = np.maximum(worst, np.linalg.cond(J))
    assert worst.max() > (1e3 if name == "fourbar_nongrashof_past_limit" else 1.8)
    # both sides carry ~cond·ε of relative round-off (the Jacobian's entries, the smallest singular value)
    assert np.all(np.abs(res.health["cond"] - worst) <= (1e-13 + 16 * np.finfo(float).eps * worst) * worst)


def test_change_points_across_chunk_borders():
    """The parallelogram passes θ2 = kπ three times in 1.5 turns; with chunks of 7 samples the change points
    fall next to chunk borders: same events, and the parallelogram stays one (θ4 = θ2, θ3 = 0 by hand)."""
    mech = parallelogram(step=0.01)
    one = vloop.solve(mech)
    for chunk in (7, 8, 50):
        many = solve_in_chunks(mech, chunk=chunk)
        assert [round(c["time"], 9) for c in many.meta["change_points"]] == [
            round(c["time"], 9) for c in one.meta["change_points"]
        ]
        assert np.array_equal(one.health["change_point"], many.health["change_point"])
        assert np.max(np.abs(many["rocker.theta"] - many["crank.theta"])) < 1e-9
        assert np.max(np.abs(many["coupler.theta"])) < 1e-9


def test_late_start_in_chunks_keeps_the_turns():
    mech = vloop.load(MECHANISMS / "fourbar_crank_rocker_open.toml")
    t = 1000.0 + np.linspace(0.0, 3.0, 301)
    one = vloop.solve(mech, t)
    many = solve_in_chunks(mech, t, chunk=13)
    assert_histories_close(many, one, rtol=1e-12)


def test_newton_passes_a_change_point_on_the_smooth_branch():
    """The isosceles slider-crank (crank = rod = 1, no offset) under method = "newton": on the branch through
    the crank pivot s = 2·cos θ2, ṡ = −2ω·sin θ2 (by hand), straight through θ2 = π/2 where both branches meet."""
    mech = vloop.loads(ISOSCELES)
    res = vloop.solve(mech)
    assert mech.options["method"] == "newton" and len(res) == len(mech.times)
    th, w = res["crank.theta"], res["crank.omega"]
    assert np.max(np.abs(res["blk.s"] - 2 * np.cos(th))) < 1e-12
    assert np.max(np.abs(res["blk.v"] + 2 * w * np.sin(th))) < 1e-9
    (cp,) = res.meta["change_points"]
    assert cp["time"] == pytest.approx(1.0, abs=1e-9) and cp["continued"] == "smooth"
    assert res.health["change_point"][10] == 1


def test_newton_parallelogram_matches_the_closed_form_path():
    mech = parallelogram(step=0.01)
    auto = vloop.solve(mech)
    newton = vloop.solve(mech, method="newton")
    assert np.max(np.abs(newton["rocker.theta"] - newton["crank.theta"])) < 1e-9
    assert [round(c["time"], 6) for c in newton.meta["change_points"]] == [
        round(c["time"], 6) for c in auto.meta["change_points"]
    ]
    # the parallelogram by hand: the rocker turns with the crank, the coupler stays parallel to the ground
    w2, a2 = newton["crank.omega"], newton["crank.alpha"]
    assert np.max(np.abs(newton["rocker.omega"] - w2)) < 1e-8 * np.max(np.abs(w2))
    assert np.max(np.abs(newton["rocker.alpha"] - a2)) < 1e-7 * np.max(np.abs(a2))
    assert np.max(np.abs(newton["coupler.theta"])) < 1e-12 and np.max(np.abs(newton["coupler.omega"])) < 1e-9
    assert np.array_equal(newton.health["change_point"], auto.health["change_point"])


def test_rectangular_newton_block_by_least_squares():
    """A four-bar whose loop is written twice (4 equations, 2 unknowns: consistent, redundant) is solved by
    Gauss–Newton and least-squares rates, and matches the hand closed form (validators.analytic.fourbar)."""
    mech = vloop.load(MECHANISMS / "fourbar_crank_rocker_open.toml")
    sys0 = vloop.compile(mech)
    (lp,) = sys0.loops
    twice = dataclasses.replace(lp, index=1)
    block = dataclasses.replace(sys0.blocks[0], loops=(0, 1), kind="newton")
    sysr = dataclasses.replace(sys0, loops=(lp, twice), C=np.vstack([sys0.C, 2.0 * sys0.C]), blocks=(block,), cache={})
    res = vloop.solve(sysr)
    ref = analytic_fourbar.solve(mech, res.t)
    assert_histories_close(res, ref, rtol=1e-12, min_columns=10)
    assert res.health["residual"].max() < 1e-14


# ---------------------------------------------------------------- streamed output


@pytest.mark.parametrize("fmt", ["csv", "parquet", "npz"])
def test_run_streams_every_format(fmt, tmp_path, capsys, monkeypatch):
    pytest.importorskip("pyarrow") if fmt == "parquet" else None
    monkeypatch.setattr(solver, "CHUNK", 10)  # several chunks even for 48 samples
    assert main(["run", str(MECHANISMS / "eightbar.toml"), "--out", str(tmp_path), "--format", fmt]) == 0
    ref = vloop.solve(vloop.load(MECHANISMS / "eightbar.toml"))
    if fmt == "csv":
        got = vloop.Result.read_csv(tmp_path / "results.csv")
        cols = {"t": got.t, **got.columns}
        health = vloop.Result.read_csv(tmp_path / "health.csv").health
    elif fmt == "parquet":
        import pyarrow.parquet as pq

        table = pq.read_table(tmp_path / "results.parquet")
        cols = {n: table[n].to_numpy() for n in table.column_names}
        assert table.schema.field("l3.omega").metadata[b"unit"] == b"rad/s"
        assert table.schema.field("C.ay").metadata[b"unit"] == b"m/s^2"
        htable = pq.read_table(tmp_path / "health.parquet")
        health = {n.split(".", 1)[1]: htable[n].to_numpy() for n in htable.column_names if n != "t"}
        assert htable.schema.field("health.cond").type == "float"  # float32: diagnostics, compact
    else:
        with np.load(tmp_path / "results.npz") as z:
            cols = {k: z[k] for k in z.files}
        with np.load(tmp_path / "health.npz") as z:
            health = {k.split(".", 1)[1]: z[k] for k in z.files if k != "t"}
    assert list(cols) == ["t", *ref.columns]
    for k, v in ref.columns.items():
        assert np.array_equal(cols[k], v), k  # full precision, every chunk in order
    assert np.array_equal(cols["t"], ref.t)
    assert set(health) == {"residual", "cond", "branch", "ill_conditioned", "change_point"}
    assert np.allclose(health["cond"], ref.health["cond"], rtol=1e-6)
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([f"results.{fmt}", f"health.{fmt}"])


def test_run_stopped_by_a_limit_streams_the_rows_before_it(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(solver, "CHUNK", 50)
    path = MECHANISMS / "fourbar_nongrashof_past_limit.toml"
    assert main(["run", str(path), "--out", str(tmp_path), "--format", "npz"]) == 2
    err = capsys.readouterr().err
    assert "sample 173 of 301" in err and "wrote 173 rows" in err and err.count("\n") == 1
    with np.load(tmp_path / "results.npz") as z:
        assert len(z["t"]) == 173 and z["t"][-1] == pytest.approx(1.72)


# ---------------------------------------------------------------- memory budget


@pytest.mark.parametrize(
    ("text", "size"), [("2G", 2 << 30), ("500 MB", 500 << 20), ("1.5GiB", int(1.5 * (1 << 30))), (1000, 1000)]
)
def test_sizes(text, size):
    assert parse_size(text) == size


@pytest.mark.parametrize("bad", [0, -0.0, 1e308, 5e-324, math.nan, math.inf, 10**400, "fast", [[1]], True])
def test_bad_sizes(bad):
    with pytest.raises(ValueError, match="memory budget"):
        parse_size(bad)


def test_solve_refuses_what_does_not_fit():
    """10⁶ samples of the eight-bar keep 10⁶ × 61 columns (t; θ, ω, α of 7 links; 6 per each of 5 joints; s, v, a
    of 3 sliders) × 8 bytes × 2 copies ≈ 1 GB in memory."""
    mech = vloop.load(MECHANISMS / "eightbar.toml")
    with pytest.raises(MemoryBudgetError) as info:
        vloop.solve(mech, np.linspace(0, 2.35, 1_000_000), memory_budget="100M")
    msg = str(info.value)
    assert "1,000,000 samples × 61 columns × 8 bytes × 2 copies" in msg
    assert "memory budget of 100 MB (--memory-budget)" in msg and "vloop run" in msg
    assert info.value.partial is None


def test_budget_from_the_environment_and_the_file(tmp_path, capsys, monkeypatch):
    text = (MECHANISMS / "eightbar.toml").read_text() + '\n[solver]\nmemory_budget = "10K"\n'
    (tmp_path / "m.toml").write_text(text)
    assert main(["run", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "memory budget of 10 kB ([solver] memory_budget)" in capsys.readouterr().err
    monkeypatch.setenv("VLOOP_MEMORY_BUDGET", "20K")
    assert main(["run", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o")]) == 2
    assert "memory budget of 20 kB (VLOOP_MEMORY_BUDGET)" in capsys.readouterr().err
    assert main(["run", str(tmp_path / "m.toml"), "--out", str(tmp_path / "o"), "--memory-budget", "1G"]) == 0
    assert (
        not (tmp_path / "o" / "results.csv").exists()
        or len(vloop.Result.read_csv(tmp_path / "o" / "results.csv")) == 48
    )


def capped_run(cap: int, *args: str) -> subprocess.CompletedProcess:
    """A real `vloop` process under an address-space cap (ulimit -v)."""

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_AS, (cap, cap))

    exe = Path(sys.executable).with_name("vloop")
    env = {k: v for k, v in os.environ.items() if k != "VLOOP_MEMORY_BUDGET"}
    return subprocess.run(
        [str(exe), *args], preexec_fn=limit, capture_output=True, text=True, timeout=120, env=env, cwd=ROOT
    )


def test_under_a_memory_cap_a_run_finishes_or_refuses_cleanly(tmp_path):
    """Under a 1 GiB address-space cap: 200,000 samples stream to disk (exit 0); the same run kept in memory
    for plots, 3·10⁶ samples, is refused before it starts (exit 2, one line naming the budget); a time grid
    of 10⁹ samples is refused at load."""
    cap = 1 << 30
    text = (MECHANISMS / "fourbar_crank_rocker_open.toml").read_text()
    head = text.split("[time]")[0]
    ok = tmp_path / "ok.toml"
    ok.write_text(head + "[time]\nstart = 0.0\nstop = 20.0\nstep = 0.0001\n")
    r = capped_run(cap, "run", str(ok), "--out", str(tmp_path / "a"), "--format", "npz")
    assert r.returncode == 0, r.stderr
    with np.load(tmp_path / "a" / "results.npz") as z:
        assert len(z["t"]) == 200_001 and np.all(np.isfinite(z["l3.theta"]))
    big = tmp_path / "big.toml"
    big.write_text(head + "[time]\nstart = 0.0\nstop = 300.0\nstep = 0.0001\n")
    r = capped_run(cap, "run", str(big), "--out", str(tmp_path / "b"), "--plot")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert "more than the memory budget" in r.stderr and "half the memory available" in r.stderr
    huge = tmp_path / "huge.toml"
    huge.write_text(head + "[time]\nstart = 0.0\nstop = 1000000.0\nstep = 0.001\n")
    r = capped_run(cap, "run", str(huge), "--out", str(tmp_path / "c"))
    assert r.returncode == 2 and "the time grid alone needs" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "b" / "results.csv").exists() and not (tmp_path / "c" / "results.csv").exists()


# ---------------------------------------------------------------- the allocator

FAULTS = """
import resource, sys, numpy as np, vloop
mech = vloop.load(sys.argv[1])
system = vloop.compile(mech)
t = np.linspace(0.0, 2.0, 4800)
vloop.solve(system, t)
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(10):
    vloop.solve(system, t)
print((resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / 10)
"""


@pytest.mark.skipif(not hasattr(os, "confstr") or "glibc" not in (os.confstr("CS_GNU_LIBC_VERSION") or ""),
                    reason="glibc's allocator only")  # fmt: skip
def test_freed_temporaries_are_reused_not_page_faulted():
    """With vloop's allocator setting (the default) a 4,800-sample eight-bar solve takes (almost) no page faults
    once warm; with VLOOP_KEEP_HEAP=0 every solve faults its temporaries' pages in again (~1,000 measured)."""
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    faults = {}
    for keep in ("1", "0"):
        r = subprocess.run(
            [sys.executable, "-c", FAULTS, str(MECHANISMS / "eightbar.toml")],
            env={**env, "VLOOP_KEEP_HEAP": keep, "OPENBLAS_NUM_THREADS": "1"},
            capture_output=True,
            text=True,
            timeout=120,
        )
        assert r.returncode == 0, r.stderr
        faults[keep] = float(r.stdout.split()[-1])
    assert faults["1"] < 50 and faults["0"] > 200 + 10 * faults["1"], faults


@pytest.mark.parametrize("rtol", [1e-9, 2.0**-30, 1e-12, 3e-7, 1e-15, 0.5])
def test_a_crank_angle_too_large_to_resolve_is_refused_where_its_spacing_exceeds_rtol(rtol):
    """The refusal threshold (a power of two, compared without np.spacing) is where np.spacing(θ) first exceeds
    rtol: the largest angle accepted resolves to rtol, the next float does not."""
    mech = vloop.load(MECHANISMS / "fourbar_textbook_example.toml")
    system = vloop.compile(mech)
    X = np.zeros((3, 1))
    bound = 2.0 ** (math.floor(math.log2(rtol)) + 53)
    X[1, 0], X[2, 0] = np.nextafter(bound, 0), bound
    assert np.spacing(X[1, 0]) <= rtol < np.spacing(X[2, 0])
    failure = sample_grid.check_inputs(system, X, np.zeros_like(X), np.zeros_like(X), 0, rtol)
    assert failure is not None and failure.sample == 2 and "too large to resolve" in failure.why


@pytest.mark.parametrize("omega, alpha, steps", [(2.0, 0.0, 4800), (4.0, 1.0, 301), (30.0, -5.0, 40), (0.5, 80.0, 97)])
def test_one_bound_for_the_whole_grid_gives_the_row_by_row_grid(omega, alpha, steps, monkeypatch):
    """For drivers without a profile the grid is settled by one bound (max h · max|ẋ| ≤ 10°) where it holds; the
    internal grid and its inputs are then those of the row-by-row test, with and without a lead-in."""
    text = (MECHANISMS / "fourbar_textbook_example.toml").read_text().split("[time]")[0]
    text = text.replace("alpha = 15.0", f"alpha = {alpha}").replace("omega = 25.0", f"omega = {omega}")
    assert f"alpha = {alpha}" in text and f"omega = {omega}" in text
    system = vloop.compile(vloop.loads(text + "[time]\nstart = 0.0\nstop = 2.0\nstep = 0.5\n"))
    run, times = solver._prepare(system, np.linspace(0.0, 2.0, steps), None, None, None, None)
    for lead in (np.zeros(0), np.array([-0.3, -0.2, -0.1])):
        fast = sample_grid.internal_grid(run, lead, times)
        with monkeypatch.context() as m:
            m.setattr(sample_grid, "_within_one_step", lambda *a: False)
            slow = sample_grid.internal_grid(run, lead, times)
        assert np.array_equal(fast.t, slow.t) and np.array_equal(fast.out, slow.out)
        if fast.inputs is not None:
            for a, b in zip(fast.inputs, run.inputs(fast.t), strict=True):
                assert np.array_equal(a, b)
