"""What a synthesis shows and writes: errors named unit-free, why there are fewer candidates, distinct colours in
path.png, the targets shown at once on a candidate's page, bounds kept by the search, an output set that never
mixes two runs, outputs checked before the search, no warning on success.

References: the precision positions and error scales are computed here (Chebyshev x, log10, the closed form
validators/analytic/fourbar.py), the figure's artists read back from matplotlib, the page read by Chromium.
"""

from __future__ import annotations

import dataclasses
import math
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import vloop
import vloop.synthesis as syn
from validators.analytic import fourbar as analytic_fourbar
from vloop.cli import main

from .test_synthesis import MOTION_POSES, PATH_POINTS
from .test_viewer import browser, open_page  # noqa: F401  (fixtures)


@pytest.fixture(scope="module")
def two_paths():
    """A path synthesis's result without its search (seconds): two crank-rockers, each re-solved and checked as
    the search's candidates are; the targets are five points of the first one's coupler curve (closed form)."""
    from vloop.synthesis.candidates import Candidates, Task
    from vloop.synthesis.defects import Draft, assess
    from vloop.synthesis.linkages import FOURBAR

    times = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    first = {"O2": 0j, "A": 0.3 + 0.4j, "B": 1.2 + 1.1j, "O4": 1.3 + 0j, "P": 0.5 + 1.0j}
    second = {k: v * 1.1 + 0.05j for k, v in first.items()}
    truth = analytic_fourbar.solve(FOURBAR.mechanism(first, name="t", omega=1.0, times=times), times)
    points = truth["P.x"] + 1j * truth["P.y"]
    size = float(np.hypot(np.ptp(points.real), np.ptp(points.imag)))
    task = Task("path", size, False, points=points, scale="the points' size")
    req = syn.Requirements(full_rotation=True, tolerance=0.5)
    mechs = [FOURBAR.mechanism(z, name="path", omega=1.0, times=times[:1]) for z in (first, second)]
    cands = [assess(Draft("path", "path", FOURBAR, m, times, 2 * math.pi), task, req) for m in mechs]
    return Candidates(task, cands).keep("path")


LOG = {"x_range": (1.0, 2.0), "input_range": (0.5236, 2.0944), "output_range": (4.1888, 5.7596)}


def test_function_generators_error_is_a_fraction_of_the_output_range():
    """The log10 generator by least squares (5 Chebyshev points), with ground 1 and 1000: the same error figure,
    and it is the largest rocker-angle miss at the precision points (closed form at the stated instants) over the
    output range 1.5708 rad, with the structural error a fraction of the y range log10(2)."""
    out = [syn.function("log10(x)", **LOG, points=5, ground=g)[0] for g in (1.0, 1000.0)]
    assert out[0].error == pytest.approx(out[1].error, rel=1e-9) and out[0].error > 1e-4
    assert out[0].structural_error == pytest.approx(out[1].structural_error, rel=1e-9)
    c = out[1]
    x = 1.5 - 0.5 * np.cos((2 * np.arange(1, 6) - 1) * math.pi / 10)
    want = 4.1888 + np.log10(x) / math.log10(2) * (5.7596 - 4.1888)
    res = analytic_fourbar.solve(c.mechanism, np.sort(c.times))
    got = res["rocker.theta"][np.argsort(np.argsort(c.times))]
    flip = math.pi if "c < 0" in " ".join(c.notes) else 0.0
    miss = np.abs(np.angle(np.exp(1j * (got - want - flip))))
    assert c.error == pytest.approx(np.max(miss) / (5.7596 - 4.1888), rel=1e-6)
    assert c.structural_error <= 0.05 and c.structural_error >= np.max(miss) / (5.7596 - 4.1888) * math.log10(2) / 2


def test_the_summary_names_the_scale_and_never_prints_nan(tmp_path, capsys):
    """vloop synth's lines: "of the output's range"; a candidate that does not reach a position says which."""
    from vloop.cli import _synth_lines

    res = syn.function("log10(x)", **LOG)
    assert "largest error" in _synth_lines(res)[1] and "of the output's range" in _synth_lines(res)[1]
    cand = res[0]
    cand.errors = np.array([0.0, np.nan, 0.0])
    line = _synth_lines(res)[1]
    assert "position 2 not reached" in line and "nan" not in line


def test_fewer_candidates_than_asked_says_why(tmp_path, capsys):
    spec = tmp_path / "f.toml"
    spec.write_text(
        'method = "function"\ncandidates = 3\n[function]\nexpression = "log10(x)"\nx = [1, 2]\n'
        "input = [0.5236, 2.0944]\noutput = [4.1888, 5.7596]\n",
        encoding="utf-8",
    )
    assert main(["synth", str(spec), "--out", str(tmp_path / "o")]) == 0
    out = capsys.readouterr().out
    assert "1 candidate of the 3 asked: function generation's equation is linear" in out
    dyads = [{"fixed": (0.0, 0.0)}, {"fixed": (1.3, 0.0)}]
    given = syn.motion(MOTION_POSES, dyads=dyads, count=5)
    assert len(given) == 2 and given.note.endswith("the free choices given fix one four-bar (either dyad driving)")


def test_path_png_draws_each_candidate_in_its_own_colour(tmp_path, two_paths):
    """Two candidates: their paths and linkages in two colours, a legend naming both and the targets (black)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from vloop.synthesis import plot as plot_module

    res = two_paths
    seen = {}
    real_save = plot_module._save

    def keep(plt_, fig, path):
        ax = fig.axes[0]
        seen["lines"] = [(ln.get_label(), matplotlib.colors.to_hex(ln.get_color())) for ln in ax.get_lines()]
        seen["legend"] = [t.get_text() for t in ax.get_legend().get_texts()]
        return real_save(plt_, fig, path)

    plot_module._save = keep
    try:
        plot_module.plot_result(res, res.solutions, tmp_path)
    finally:
        plot_module._save = real_save
        plt.close("all")
    paths = [(lbl, col) for lbl, col in seen["lines"] if lbl.startswith("path_")]
    assert len(paths) == 2 and paths[0][1] != paths[1][1]
    assert sum(t.startswith("path_") for t in seen["legend"]) == 2 and "targets" in seen["legend"]
    assert ("targets", "#000000") in seen["lines"]


def test_bounds_are_kept_by_the_search():
    """pivots and links (Requirements) on a three-pose motion search: unbounded, its first candidate's pivots lie
    above y = 1.3; bounded, every candidate's ground pivots are in the box and every moving link's length (a
    plate's sides, read back from its written coordinates) in the range."""
    free = syn.motion(MOTION_POSES, grid=6, count=2)
    assert max(free[0].mechanism.joints[j][1] for j in ("O2", "O4")) > 1.3
    box, rng = (-0.5, -0.5, 1.5, 0.3), (0.3, 1.6)
    res = syn.motion(MOTION_POSES, grid=6, count=2, requirements=syn.Requirements(pivots=box, links=rng))
    assert res.solutions
    for c in res:
        for j in ("O2", "O4"):
            x, y = c.mechanism.joints[j]
            assert box[0] <= x <= box[2] and box[1] <= y <= box[3]
        moving = {k: v for k, v in c.dims.items() if not k.startswith("ground")}
        assert all(rng[0] <= v <= rng[1] for v in moving.values()), moving
    outside = syn.motion(MOTION_POSES, dyads=[{"fixed": (0.0, 0.0)}, {"fixed": (1.3, 0.0)}],
                         requirements=syn.Requirements(pivots=(0.5, -1.0, 2.0, 1.0)))  # fmt: skip
    assert all("bounds" in c.defects and not c.solution for c in outside)
    assert "ground pivot O2 at (0, 0) is outside pivots" in " ".join(outside[0].notes)


def test_a_synthesis_folder_never_mixes_two_runs(tmp_path, capsys):
    """A motion synthesis writes guide_1.toml and guide_2.toml; a function synthesis into the same folder leaves
    its own files only (the user's file beside them stays)."""
    from .test_synthesis import LOG_SPEC, MOTION_SPEC

    out = tmp_path / "out"
    (tmp_path / "m.toml").write_text(MOTION_SPEC, encoding="utf-8")
    (tmp_path / "f.toml").write_text(LOG_SPEC, encoding="utf-8")
    assert main(["synth", str(tmp_path / "m.toml"), "--out", str(out)]) == 0
    (out / "mine.toml").write_text("# the user's", encoding="utf-8")
    first = {p.name for p in out.iterdir() if not p.name.startswith(".")}
    assert {"guide_1.toml", "guide_2.toml", "candidates.csv"} <= first
    assert main(["synth", str(tmp_path / "f.toml"), "--out", str(out)]) == 0
    second = {p.name for p in out.iterdir() if not p.name.startswith(".")}
    assert second == {"candidates.csv", "candidates.parquet", "logx_1.toml", "mine.toml"} - (
        set() if (out / "candidates.parquet").exists() else {"candidates.parquet"}
    )


def test_an_output_that_cannot_be_written_is_refused_before_the_search(tmp_path, capfd):
    """--out naming an existing file: exit 2 at once (the search would take seconds), one line naming it."""
    spec = tmp_path / "p.toml"
    spec.write_text(
        f'method = "path"\n[path]\npoints = {PATH_POINTS}\ngenerations = 100000\nrestarts = 100\n', encoding="utf-8"
    )
    blocked = tmp_path / "file"
    blocked.write_text("x", encoding="utf-8")
    started = time.perf_counter()
    assert main(["synth", str(spec), "--out", str(blocked)]) == 2
    assert time.perf_counter() - started < 5
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and f"output folder {blocked}: exists and is not a folder" in err[0]


def test_no_warning_on_success(tmp_path, two_paths):
    """A synthesis with every picture and page, pairs without f (no structural curve), a unit the font lacks a
    glyph for and a "$": no Python warning."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        x = 1.5 - 0.5 * np.cos((2 * np.arange(1, 4) - 1) * math.pi / 6)
        pairs = np.stack([0.5236 + (x - 1) * 1.5708, 4.1888 + np.log10(x) / math.log10(2) * 1.5708], 1)
        res = syn.function(pairs=pairs.tolist(), units="mm😀$x$")
        syn.write(res, tmp_path / "f", plot=True, html=True)
        two_paths.task = dataclasses.replace(two_paths.task, units="µm😀")
        syn.write(two_paths, tmp_path / "p", plot=True, html=True)
        dyads = [{"fixed": (0.0, 0.0)}, {"fixed": (1.3, 0.0)}]
        syn.write(syn.motion(MOTION_POSES, dyads=dyads, units="😀"), tmp_path / "m", plot=True, html=True)
    assert (tmp_path / "f" / "structural_error.png").exists() and (tmp_path / "p" / "path.png").exists()
    assert (tmp_path / "m" / "poses.png").exists()


def test_targets_are_shown_when_the_page_opens(tmp_path, open_page, two_paths):  # noqa: F811
    """A written candidate's page in Chromium: the targets' crosses drawn and visible without a click."""
    res = two_paths
    page = next(p for p in syn.write(res, tmp_path / "p", html=True) if p.suffix == ".html")
    opened = open_page(Path(page))
    crosses = opened.page.locator("path.v-target")
    assert crosses.count() == len(PATH_POINTS)
    assert all(crosses.nth(k).is_visible() for k in range(crosses.count()))
    assert not opened.problems and not opened.requests
    assert vloop.load(Path(page).with_suffix(".toml")).name == res[0].name
