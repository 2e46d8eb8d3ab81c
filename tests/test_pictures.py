"""The PNG figures vloop writes, checked through their matplotlib artists (no pixels compared).

* Coincident curves are told apart: wherever two curves lie on each other to within half a line
  width, their (line style, marker) pairs differ and the later one's legend label names the earlier
  one. Which curves coincide is known independently of the plotting code: the eight-bar is symmetric
  about the x axis (paper, Fig. 1: C = (8, k), D = (8, −k)), so its sliders l6 and l8 move alike and
  the transmission angles at C and D are equal; a crank's angle does not depend on the coupler's
  length, so the Monte-Carlo percentiles of θ2 under a coupler tolerance all lie on the nominal curve.
* forces.png draws every pin reaction (or names the ones it leaves out) and its polar plot's labels
  do not overlap (text bounding boxes from the Agg renderer).
"""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from matplotlib.figure import Figure
from matplotlib.text import Text

import vloop
from vloop.teaching.report import transmission_figure
from vloop.views import forces_plot
from vloop.views.curves import TOLERANCE, distinguish
from vloop.views.forces_plot import forces_figure
from vloop.views.plots import figures

from .conftest import MECHANISMS


def _look(line) -> tuple[str, str]:
    return line.get_linestyle(), str(line.get_marker())


def _named_lines(ax) -> dict[str, object]:
    """The axes' lines by their name before any note: 'l8 (= l6)' → 'l8'."""
    return {str(ln.get_label()).split(" (= ")[0]: ln for ln in ax.get_lines()}


def _told_apart(ax, first: str, second: str) -> None:
    lines = _named_lines(ax)
    a, b = lines[first], lines[second]
    assert _look(a) != _look(b), f"{first} and {second} are drawn alike"
    assert f"= {first}" in str(b.get_label()), b.get_label()


def _texts_do_not_overlap(fig: Figure, texts: list[Text]) -> None:
    renderer = fig.canvas.get_renderer()
    fig.canvas.draw()
    boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in texts if t.get_visible() and t.get_text().strip()]
    for (ta, a), (tb, b) in itertools.combinations(boxes, 2):
        assert not a.overlaps(b), f"{ta!r} overlaps {tb!r}"


# ------------------------------------------------------------------ coincident curves


def test_curves_within_half_a_line_coincide_and_others_do_not() -> None:
    """Synthetic curves on a unit axis: 0.3 × TOLERANCE apart coincide, 3 × TOLERANCE apart do not."""
    fig = Figure()
    ax = fig.add_subplot()
    t = np.linspace(0.0, 1.0, 200)
    base = np.sin(2 * np.pi * t)
    span = 2.0 * 1.1  # the y axis spans the sine with matplotlib's 5 % margins
    ax.plot(t, base, label="a")
    ax.plot(t, base + 0.3 * TOLERANCE * span, label="b")
    ax.plot(t, base - 3.0 * TOLERANCE * span, label="c")
    ax.plot(t, base + np.where(t < 0.5, 0.0, 0.5), label="d")  # on a for half the run only
    changed = distinguish(ax)
    assert [str(ln.get_label()) for ln in changed] == ["b (= a)"]
    lines = _named_lines(ax)
    assert (
        _look(lines["a"]) == ("-", "None") and _look(lines["c"]) == ("-", "None") and _look(lines["d"]) == ("-", "None")
    )
    _told_apart(ax, "a", "b")


@pytest.fixture(scope="module")
def eightbar():
    mech = vloop.load(MECHANISMS / "eightbar.toml")
    return mech, vloop.solve(mech)


def test_eightbar_mirror_sliders_are_told_apart(eightbar) -> None:
    mech, res = eightbar
    for q in ("s", "v", "a"):  # the mirror image: the same numbers, independently of the figure
        assert np.allclose(res[f"l6.{q}"], res[f"l8.{q}"], rtol=0, atol=1e-9 * np.abs(res[f"l6.{q}"]).max())
    figs = figures(mech, res)
    axes = figs["sliders.png"].axes
    for ax in axes:
        _told_apart(ax, "l6", "l8")
        assert _look(_named_lines(ax)["l4"]) == ("-", "None")  # l4 is on its own
    for ax in axes[1:]:  # the lower panels say it in a legend of their own
        assert any("l8 (= l6)" == t.get_text() for t in ax.get_legend().get_texts())
    assert "l8 (= l6)" in [t.get_text() for t in axes[0].get_legend().get_texts()]
    links = figs["links.png"].axes[0]  # l5 and l7 are mirror images too, but their angles differ
    assert all(_look(ln) == ("-", "None") for ln in links.get_lines())


def test_eightbar_transmission_angles_at_c_and_d_are_told_apart(eightbar) -> None:
    mech, res = eightbar
    mu = {ta.dyad.label: np.degrees(ta.folded) for ta in vloop.transmission_angles(mech, res)}
    assert np.allclose(mu["C"], mu["D"], atol=1e-9) and not np.allclose(mu["B"], mu["C"], atol=1.0)
    ax = transmission_figure(mech, res).axes[0]
    lines = {str(ln.get_label()).split(" (")[0].removeprefix("μ at "): ln for ln in ax.get_lines()}
    assert _look(lines["C"]) != _look(lines["D"]) and "= μ at C" in str(lines["D"].get_label())
    assert _look(lines["B"]) == ("-", "None")
    assert any("= μ at C" in t.get_text() for t in ax.get_legend().get_texts())


def test_study_percentiles_that_coincide_are_told_apart() -> None:
    from vloop.studies.plot import band_figure

    mech = vloop.load(MECHANISMS / "fourbar_textbook_example.toml")
    tol = [{"name": "links.l3.length", "tolerance": {"dist": "uniform", "half_width": 0.5}}]
    res = vloop.study(
        mech, tol, ["l2.theta.series", "l4.theta.series"], times=np.linspace(0, 0.1, 11), samples=64, seed=3
    )
    outputs = {o.name: o for o in res.spec.outputs}
    crank = res.bands[res.bands["output"] == "l2.theta.series"]
    assert np.all(crank[["mc_p2.5", "mc_p50", "mc_p97.5"]].to_numpy() == crank[["nominal"]].to_numpy())
    lower = band_figure(res, outputs["l2.theta.series"]).axes[1]
    lines = {str(ln.get_label()).split(" (= ")[0].removeprefix("_"): ln for ln in lower.get_lines()}
    looks = [_look(lines[n]) for n in ("Monte-Carlo 2.5–97.5 %", "Monte-Carlo 97.5 %", "Monte-Carlo median")]
    assert len(set(looks)) == 3, looks
    assert any("(= Monte-Carlo 2.5–97.5 %" in t.get_text() for t in lower.get_legend().get_texts())
    rocker = band_figure(res, outputs["l4.theta.series"]).axes[1]  # the coupler moves θ4: a band, no note
    assert not any("(=" in str(ln.get_label()) for ln in rocker.get_lines())


# ------------------------------------------------------------------ forces.png


@pytest.fixture(scope="module", params=["eightbar_dynamics", "sixbar_watt2_dynamics", "fourbar_textbook_dynamics"])
def dynamics(request):
    mech = vloop.load(MECHANISMS / f"{request.param}.toml")
    res = vloop.solve(mech)
    return mech, vloop.solve_forces(mech, res)


def test_forces_figure_draws_every_reaction(dynamics) -> None:
    mech, forces = dynamics
    reactions = sorted(c[:-4] for c in forces.columns if c.endswith(".mag"))
    assert len(reactions) == len(vloop.forces.reaction_names(mech)) >= 3
    fig = forces_figure(mech, forces)
    pins = next(ax for ax in fig.axes if ax.get_ylabel() == "pin force |F| [N]")
    drawn = sorted(str(ln.get_label()).split(" (= ")[0] for ln in pins.get_lines())
    assert drawn == reactions
    assert len(pins.get_legend().get_texts()) == len(reactions)
    assert not any("not drawn" in t.get_text() for t in fig.texts)


def test_forces_figure_names_the_reactions_it_leaves_out(dynamics, monkeypatch) -> None:
    mech, forces = dynamics
    monkeypatch.setattr(forces_plot, "MAX_PINS", 2)
    peaks = {c[:-4]: float(np.max(forces[c])) for c in forces.columns if c.endswith(".mag")}
    by_size = sorted(peaks, key=lambda n: -peaks[n])
    fig = forces_figure(mech, forces)
    pins = next(ax for ax in fig.axes if ax.get_ylabel() == "pin force |F| [N]")
    assert sorted(str(ln.get_label()).split(" (= ")[0] for ln in pins.get_lines()) == sorted(by_size[:2])
    note = " ".join(t.get_text().replace("\n", " ") for t in fig.texts)
    assert f"not drawn ({len(peaks) - 2} of {len(peaks)}, the smallest" in note and "forces.csv" in note
    for name in by_size[2:]:
        assert name in note, name
    renderer = fig.canvas.get_renderer()
    for ax in fig.axes:  # the note stays clear of every panel, its tick labels and axis labels
        for t in fig.texts:
            assert not ax.get_tightbbox(renderer).overlaps(t.get_window_extent(renderer)), t.get_text()


def test_forces_polar_labels_do_not_overlap(dynamics) -> None:
    mech, forces = dynamics
    fig = forces_figure(mech, forces)
    polar = next(ax for ax in fig.axes if ax.name == "polar")
    radial = [t for t in polar.yaxis.get_ticklabels() if t.get_visible() and t.get_text()]
    assert len(radial) >= 2, "the radial scale must be labelled"
    _texts_do_not_overlap(fig, [*radial, *polar.xaxis.get_ticklabels(), polar.title])
    _texts_do_not_overlap(fig, _drawn_texts(fig))


def _drawn_texts(fig: Figure) -> list[Text]:
    """Every text the figure draws outside its legends: titles, axis labels, the tick labels of ticks
    inside the view (matplotlib keeps labels of ticks beyond it, undrawn), figure notes."""
    out = list(fig.texts)
    for ax in fig.axes:
        out += [ax.title, ax.xaxis.label, ax.yaxis.label]
        for axis in (ax.xaxis, ax.yaxis):
            lo, hi = sorted(axis.get_view_interval())
            out += [t.label1 for t in axis.get_major_ticks() if lo <= t.get_loc() <= hi and t.label1.get_visible()]
    return out
