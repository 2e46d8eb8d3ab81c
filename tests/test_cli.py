"""The command line on good input: run (CSV + plots), loops, info."""

from __future__ import annotations

import numpy as np

import vloop
from tests.conftest import MECHANISMS
from vloop.cli import main


def test_run_writes_csv_and_plots(tmp_path, capsys):
    assert main(["run", str(MECHANISMS / "eightbar.toml"), "--out", str(tmp_path), "--plot"]) == 0
    out = capsys.readouterr().out
    assert "eightbar: 48 samples" in out
    res = vloop.Result.read_csv(tmp_path / "results.csv")
    assert len(res) == 48 and res.t[-1] == 2.35
    assert res["l6.s"][0] == np.float64(vloop.solve(vloop.load(MECHANISMS / "eightbar.toml"))["l6.s"][0])
    header = (tmp_path / "results.csv").read_text().splitlines()[0].split(",")
    assert header[:4] == ["t", "l2.theta", "l2.omega", "l2.alpha"]
    assert {"l4.s", "l4.v", "l4.a", "C.ay", "l7.alpha"} <= set(header)
    import matplotlib.image as mpimg

    for name in ("links.png", "sliders.png", "paths.png"):
        img = mpimg.imread(tmp_path / name)
        assert img.shape[0] > 400 and img.shape[1] > 400
        assert img[..., :3].std() > 0.05  # not a blank canvas
    health = vloop.Result.read_csv(tmp_path / "health.csv")
    assert health.health["residual"].max() < 1e-14


def test_run_default_out_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["run", str(MECHANISMS / "slider_crank_offset.toml")]) == 0
    assert (tmp_path / "out" / "slider_crank_offset" / "results.csv").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # nothing written elsewhere


def test_loops_and_latex(capsys):
    assert main(["loops", str(MECHANISMS / "eightbar.toml")]) == 0
    text = capsys.readouterr().out
    assert "3 vector loops (J − L + 1 = 10 − 8 + 1), mobility M = 1, 6 unknowns" in text
    assert main(["loops", "--latex", str(MECHANISMS / "eightbar.toml")]) == 0
    latex = capsys.readouterr().out
    assert r"\begin{align*}" in latex and r"\end{align*}" in latex and latex.count("&= 0") == 3


def test_info_reports_mobility_pins_and_grashof(capsys):
    assert main(["info", str(MECHANISMS / "eightbar.toml")]) == 0
    text = capsys.readouterr().out
    assert "B        (4, 0)  pin of order 3 (l3, l5, l7, l4)" in text
    assert "Gruebler M = 3(L-1) - 2J = 3(8-1) - 2*10 = 1" in text
    assert "rank 6 of 6 unknowns" in text
    assert main(["info", str(MECHANISMS / "fourbar_crank_rocker_open.toml")]) == 0
    assert "Grashof crank-rocker (ground 7, links 2, 6, 5)" in capsys.readouterr().out
    assert main(["info", str(MECHANISMS / "fourbar_nongrashof_past_limit.toml")]) == 0
    assert "non-Grashof triple-rocker" in capsys.readouterr().out


def test_dataframe_and_named_access():
    res = vloop.solve(vloop.load(MECHANISMS / "eightbar.toml"))
    df = res.to_dataframe()
    assert list(df.columns[:2]) == ["t", "l2.theta"] and len(df) == 48
    assert np.array_equal(df["l3.omega"].to_numpy(), res.link("l3").omega)
    assert np.array_equal(res.slider("l4").a, res["l4.a"])
    assert np.array_equal(res.point("C").vy, res["C.vy"])
    assert res.names("slider") == ["l4", "l6", "l8"]
