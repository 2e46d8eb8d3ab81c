"""Many variants solved together by the core's own algorithms (vloop.core.batch).

* Each variant the batch takes gets the single run's numbers on that variant's own constants: bit for bit
  where its blocks are closed-form dyads (the same functions on the same numbers, row by row), to round-off
  where Newton blocks continue (the batch checks their steps against the nominal mechanism's size, the single
  run against the variant's own).
* How many variants are solved together never changes a number (Newton blocks and sliders on moving guides
  included: no product mixes the rows of two variants).
* A doubtful variant is solved again on its own, or reported as failed when the caller asks so.
* The state is one structure over variants × samples, readable per variant.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import vloop
from vloop.core import batch
from vloop.core.data import State
from vloop.core.solver import solve as solve_system
from vloop.core.variants import VariantModel, resolve

ROOT = Path(__file__).resolve().parents[1]
CATALOG = sorted((ROOT / "mechanisms").glob("*.toml"))
NEWTON = ["eightbar.toml", "jansen_pair.toml", "whitworth_quick_return.toml"]


def _model(mech: vloop.Mechanism, names: list[str]) -> VariantModel:
    return VariantModel.build(mech, vloop.compile(mech), tuple(resolve(mech, n, n) for n in names))


def _lengths(mech: vloop.Mechanism) -> list[str]:
    names = [f"links.{n}.length" for n, lk in mech.links.items() if not lk.ground and len(lk.joints) == 2][:3]
    return names or [f"joints.{j}.x" for j in list(mech.joints)[:2]]


@pytest.mark.parametrize(
    ("path", "method"),
    [(p, "auto") for p in CATALOG] + [(p, "newton") for p in CATALOG if p.name in NEWTON],
    ids=lambda x: x.stem if isinstance(x, Path) else x,
)
def test_each_variant_is_the_single_run_on_its_own_constants(path, method):
    mech = vloop.load(path)
    mech = dataclasses.replace(mech, options={**mech.options, "method": method})
    model = _model(mech, _lengths(mech))
    values = model.nominal_values()[None, :] * (1 + 1e-3 * np.random.default_rng(2).standard_normal((5, 1)))
    grid = batch.make_grid(model, model.designs(values), mech.times)
    names = batch.column_names(model.system)
    out = batch.solve(model, values, grid, names, doubtful="fail")
    d = model.designs(values)
    closed_forms = all(b.kind != "newton" for b in model.system.blocks)
    for v in np.nonzero(out.completed)[0]:
        _, own = batch.variant_system(model, values[v], d.take(slice(v, v + 1)), out.q0[v], out.positions[v])
        ref = solve_system(own, mech.times)
        for c in names:
            if closed_forms:
                assert np.array_equal(out.columns[c][v], ref[c]), (v, c)
            else:  # round-off of each quantity's peak (1e-15 measured), a hundredfold margin
                peak = max(float(np.max(np.abs(ref[c]))), 1e-9 * mech.scale)
                assert np.max(np.abs(out.columns[c][v] - ref[c])) <= 1e-13 * peak, (v, c)
    if path.name != "fourbar_nongrashof_past_limit.toml":  # (every variant of that one stops at its limit)
        assert out.completed.sum() >= 4


@pytest.mark.parametrize(
    "file", ["sixbar_stephenson3_output_driven.toml", "inverted_slider_crank.toml", "whitworth_quick_return.toml"]
)
def test_chunking_never_changes_a_number_on_newton_blocks_and_moving_guides(file):
    mech = vloop.load(ROOT / "mechanisms" / file)
    params = [{"name": n, "tolerance": {"dist": "normal", "sigma": 2e-3 * resolve(mech, n, n).typical}}
              for n in _lengths(mech)]  # fmt: skip
    outs = [f"{c}.series" for c in vloop.solve(mech, mech.times[:2]).columns][:8]
    kw = dict(samples=12, seed=4, sensitivity="none", times=mech.times[:60])
    one = vloop.study(mech, params, outs, chunk=1000, **kw)
    many = vloop.study(mech, params, outs, chunk=5, **kw)
    pd.testing.assert_frame_equal(one.table, many.table, check_exact=True)


def test_doubtful_variants_are_solved_again_or_reported_as_asked():
    mech = vloop.load(ROOT / "mechanisms" / "fourbar_textbook_example.toml")
    model = _model(mech, ["links.l3.length"])
    values = np.array([[120.0], [150.0], [110.0]])  # 150: non-Grashof, its motion stops at a limit
    grid = batch.make_grid(model, model.designs(values), mech.times)
    single = batch.solve(model, values, grid, ["l4.theta"])
    failed = batch.solve(model, values, grid, ["l4.theta"], doubtful="fail")
    assert list(single.completed) == list(failed.completed) == [True, False, True]
    assert failed.reason[1] == batch.DOUBTFUL and np.all(np.isnan(failed.columns["l4.theta"][1]))
    assert np.isnan(failed.stopped_at[1]) and failed.solver[1] == ""
    assert "cannot assemble" in single.reason[1] and single.solver[1] == "single"
    assert 0.0 < single.stopped_at[1] < mech.times[-1]
    assert np.array_equal(single.columns["l4.theta"][[0, 2]], failed.columns["l4.theta"][[0, 2]])
    with pytest.raises(ValueError, match="doubtful"):
        batch.solve(model, values, grid, ["l4.theta"], doubtful="maybe")


def test_solve_variants_gives_each_variant_files_motion():
    mech = vloop.load(ROOT / "mechanisms" / "fourbar_textbook_example.toml")
    values = np.array([[115.0], [125.0]])
    out = batch.solve_variants(vloop.compile(mech), ["links.l3.length"], values, ["l4.theta", "B.x"])
    assert out.completed.all() and out.columns["B.x"].shape == (2, len(mech.times))
    model = _model(mech, ["links.l3.length"])
    for v in range(2):
        positions = dict(zip(model.system.point_names, out.positions[v].tolist(), strict=True))
        own = vloop.loads(vloop.dumps(model.variant_mechanism(values[v], positions, out.q0[v])))
        ref = vloop.solve(own, mech.times)
        for c in ("l4.theta", "B.x"):  # its file's coordinates are rounded t = 0 positions: round-off of the peak
            assert np.max(np.abs(out.columns[c][v] - ref[c])) <= 1e-12 * np.max(np.abs(ref[c])), c


def test_the_state_is_one_structure_over_variants_and_samples():
    state = State(7, 3, 1, variants=4)
    assert state.e.shape == (28, 4) and state.theta.shape == (28, 3) and state.s_ddot.shape == (28, 2)
    view = state.per_variant("theta")
    assert view.shape == (4, 7, 3)
    view[2, 5, 1] = 1.25  # a view: variant 2's sample 5 is row 2·7 + 5
    assert state.theta[19, 1] == 1.25
    own = state.rows(slice(14, 21))  # variant 2 as a state of its own, writing through
    own.omega[5, 1] = -3.0
    assert state.per_variant("omega")[2, 5, 1] == -3.0 and np.all(state.e[:, -1] == 1.0)


def _dips_of_one(h: np.ndarray, tail: bool) -> list[tuple[int, int]]:
    """The single run's brackets, written out for one variant: sampled minima below 0.9 of their larger
    neighbour, a rise from the first sample, a fall into the last (below 0.9 of the next sample, or a V of √h
    with its vertex between the outer two samples possible at twice the slope beyond them)."""
    n, out = len(h), []

    def v_at_edge(h0: float, h1: float, h2: float) -> bool:
        r0, r1, r2 = (math.sqrt(x) if x >= 0 else math.nan for x in (h0, h1, h2))
        return h0 <= h1 and r0 + r1 <= 2 * (r2 - r1)

    for c in range(1, n - 1):
        if h[c] <= h[c - 1] and h[c] <= h[c + 1] and h[c] < 0.9 * max(h[c - 1], h[c + 1]):
            out.append((c - 1, c + 1))
    if n > 2 and (h[0] < 0.9 * h[1] or v_at_edge(*h[:3])) and h[1] <= h[2]:
        out.insert(0, (0, 1))
    if tail and n > 1 and (h[-1] < 0.9 * h[-2] or (n > 2 and v_at_edge(h[-1], h[-2], h[-3]))):
        out.append((n - 2, n - 1))
    return out


def test_candidate_minima_of_many_variants_are_each_ones_own():
    from vloop.core.changepoints import DIP, candidate_minima

    assert DIP == 0.9
    rng = np.random.default_rng(0)
    for _ in range(300):
        V, n = int(rng.integers(1, 6)), int(rng.integers(2, 12))
        h = rng.random((V, n))
        h[rng.random((V, n)) < 0.1] = np.nan  # NaN compares false, as in the single run
        for tail in (True, False):
            want = [[v, lo, hi] for v in range(V) for lo, hi in _dips_of_one(h[v], tail)]
            assert candidate_minima(h, tail).tolist() == want
