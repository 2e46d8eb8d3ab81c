"""vloop export --format mjcf|exudyn|pinocchio: models a user takes to another engine, checked against vloop.

References:

* MJCF: the written file loaded by MuJoCo itself (``MjModel.from_xml_path``), reset to its keyframe ``t0`` and
  simulated under its driver; its positions against ``vloop.solve``'s within the MuJoCo engine's stated
  tolerance (validators/tolerances.py: 1e-6 of the size for positions, 1e-6 rad for angles);
* the scripts: run as a user runs them (``python -I SCRIPT --out FILE.csv`` in a subprocess, so neither vloop nor
  validators is imported from this checkout), their CSV against ``vloop.solve`` within the validators' stated
  tolerances of Pinocchio (1e-9) and Exudyn's kinematic engine (1e-8), by ``vloop.compare``;
* the MuJoCo engine in the harness: ``vloop validate --engines vloop,mujoco`` on a run that stops at a limit
  position (MuJoCo stops at the sample vloop stops at).
"""

from __future__ import annotations

import inspect
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import vloop
from vloop.cli import main
from vloop.compare import compare

from .conftest import MECHANISMS, mechanism_files

mujoco = pytest.importorskip("mujoco", reason="MJCF export needs mujoco (pip install -e '.[models]')")

FEW = ["slider_crank_offset", "inverted_slider_crank"]  # a slider on the ground, a moving guide


def _export(stem: str, fmt: str, out: Path) -> Path:
    assert main(["export", str(MECHANISMS / f"{stem}.toml"), "--format", fmt, "--out", str(out)]) == 0
    (path,) = [p for p in out.iterdir() if p.suffix in (".xml", ".py")]
    return path


def _mjcf_against_vloop(stem: str, tmp_path: Path, samples: int | None) -> None:
    from validators.models.mjcf import build
    from validators.mujoco import simulate

    mech = vloop.load(MECHANISMS / f"{stem}.toml")
    try:
        ref = vloop.solve(mech)
    except vloop.MotionError as exc:  # a run that stops at a limit: compared where it runs
        ref = exc.partial
    t = ref.t if samples is None else ref.t[:samples]
    path = _export(stem, "mjcf", tmp_path)
    model = mujoco.MjModel.from_xml_path(str(path))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    _, layout = build(mech)  # the names the file was written with (the same construction)
    res = simulate(model, data, layout, mech, t)
    size = mech.scale
    for c in res.columns:
        if c.endswith((".x", ".y", ".s")):
            assert np.max(np.abs(res[c] - ref[c][: len(t)])) <= 1e-6 * size, c
        elif c.endswith(".theta"):
            assert np.max(np.abs(res[c] - ref[c][: len(t)])) <= 1e-6, c
    assert np.max(res.health["violation"]) <= 1e-6


@pytest.mark.parametrize("stem", FEW)
def test_mjcf_loads_and_follows_vloop(stem: str, tmp_path: Path) -> None:
    _mjcf_against_vloop(stem, tmp_path, 30)


@pytest.mark.slow
@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_mjcf_of_every_catalog_mechanism_follows_vloop(path: Path, tmp_path: Path) -> None:
    _mjcf_against_vloop(path.stem, tmp_path, None)


def test_mjcf_keyframe_is_assembled_and_a_constant_speed_input_runs_by_itself(tmp_path: Path) -> None:
    """With no controller at all, the keyframe's set point and ctrl turn the crank at the file's speed."""
    import dataclasses

    from validators.models import export
    from validators.models.mjcf import length_scale

    mech = vloop.load(MECHANISMS / "fourbar_crank_rocker_open.toml")
    drv = dataclasses.replace(mech.drivers[0], a0=0.0)  # the file's crank speeds up; this one turns steadily
    mech = dataclasses.replace(mech, drivers=(drv,))
    model = mujoco.MjModel.from_xml_path(str(export(mech, tmp_path, "mjcf")))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, 0)
    mujoco.mj_forward(model, data)
    eq = data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    assert np.max(np.abs(data.efc_pos[eq])) <= 1e-12 * mech.scale  # the cut pins closed at t = 0
    crank = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, drv.target)
    steps = 2000
    for _ in range(steps):
        mujoco.mj_step(model, data)
    t = steps * model.opt.timestep
    xm = data.xmat[crank]
    theta = np.arctan2(xm[3], xm[0])
    want = drv.x0 + drv.v0 * t
    assert abs((theta - want + np.pi) % (2 * np.pi) - np.pi) <= 1e-6
    ref = vloop.solve(mech, times=np.array([t]))
    for p in mech.joints:
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, f"{mech.body_of_point(p)}/{p}")
        got = data.site_xpos[site][:2] / length_scale(mech)  # the model is in metres
        assert np.hypot(*(got - [ref[f"{p}.x"][0], ref[f"{p}.y"][0]])) <= 1e-6 * mech.scale, p


def _script_against_vloop(stem: str, fmt: str, tmp_path: Path) -> None:
    from validators.tolerances import tolerance

    pytest.importorskip("pinocchio" if fmt == "pinocchio" else "exudyn")
    script = _export(stem, fmt, tmp_path / "out")
    text = script.read_text(encoding="utf-8")
    assert "import vloop" not in text and "from vloop" not in text and "validators" not in text.split('"""')[2]
    run = subprocess.run(
        [sys.executable, "-I", str(script), "--out", "run.csv"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    mech = vloop.load(MECHANISMS / f"{stem}.toml")
    try:
        ref = vloop.solve(mech)
    except vloop.MotionError as exc:
        ref = exc.partial
    assert run.returncode in (0, 1), run.stderr
    got = vloop.Result.read_csv(tmp_path / "run.csv", mechanism=mech.name, engine=fmt)
    assert abs(len(got) - len(ref)) <= 1 and len(got) >= 0.9 * len(ref), (len(got), len(ref), run.stdout)
    n = min(len(got), len(ref))
    if n < len(ref):
        n = int(0.9 * n)  # next to a limit every engine's rates grow without bound (the harness's rule)
    assert set(ref.columns) - {c for c in ref.columns if c.startswith("health")} <= set(got.columns)
    tol = tolerance("pinocchio" if fmt == "pinocchio" else "exudyn-kinematic", "vloop")
    cmp = compare(got.head(n), ref.head(n), tol.rtol, floor=tol.floor)
    assert cmp.passed, cmp.message(limit=3)


@pytest.mark.parametrize(
    ("stem", "fmt"), [("fourbar_textbook_example", "pinocchio"), ("inverted_slider_crank", "exudyn")]
)
def test_scripts_run_as_a_user_would_and_match_vloop(stem: str, fmt: str, tmp_path: Path) -> None:
    _script_against_vloop(stem, fmt, tmp_path)


@pytest.mark.slow
@pytest.mark.parametrize("fmt", ["pinocchio", "exudyn"])
@pytest.mark.parametrize("path", mechanism_files(), ids=lambda p: p.stem)
def test_scripts_of_every_catalog_mechanism_match_vloop(path: Path, fmt: str, tmp_path: Path) -> None:
    _script_against_vloop(path.stem, fmt, tmp_path)


def test_scripts_carry_the_validators_construction_verbatim(tmp_path: Path) -> None:
    """One implementation: the model-building code in the script is the validators' own source."""
    from validators import exudyn, exudyn_model, pinocchio
    from validators.models import export

    mech = vloop.load(MECHANISMS / "sixbar_watt2.toml")
    pin_text = export(mech, tmp_path, "pinocchio").read_text(encoding="utf-8")
    exu_text = export(mech, tmp_path, "exudyn").read_text(encoding="utf-8")
    for fn in (pinocchio.plan_tree, pinocchio.build_model, pinocchio._Solver):
        assert inspect.getsource(fn) in pin_text
    for fn in (exudyn_model.build, exudyn_model.DriverInput, exudyn._Kinematics, exudyn.ConstraintEquations):
        assert inspect.getsource(fn) in exu_text


@pytest.mark.slow
def test_mujoco_engine_stops_where_vloop_stops_in_the_harness(tmp_path: Path, capsys) -> None:
    """A run into a limit position: MuJoCo's servo cannot turn the input past it, and the engine says so."""
    import json

    from validators.engines import ENGINES

    assert "mujoco" in ENGINES
    path = MECHANISMS / "fourbar_nongrashof_past_limit.toml"
    code = main(["validate", str(path), "--engines", "vloop,mujoco", "--out", str(tmp_path), "--no-report"])
    assert code == 0, capsys.readouterr().out
    summary = json.loads(next(tmp_path.rglob("summary.json")).read_text())
    text = json.dumps(summary)
    assert "mujoco" in text and '"passed": true' in text.replace(" ", "").replace('"passed":true', '"passed": true')


@pytest.mark.parametrize(
    "argv",
    [
        ["--format", "mjcf", "--at", "0.5"],
        ["--format", "pinocchio", "--kerf", "0.1"],
        ["--format", "svg"],
        ["--format", "dxf", "--at", "0.5", "--kerf", "abc"],
        ["--format", "dxf", "--at", "0.5", "--pin", "0"],
        ["--format", "dxf", "--at", "0.5", "--pin", "1", "--width", "0.5"],
        ["--format", "svg", "--at", "0.5", "--kerf", "0.1"],
        ["--format", "dxf", "--at", "0.5", "--dimensions"],
    ],
)
def test_export_options_for_another_format_are_one_line_and_exit_2(argv: list[str], tmp_path: Path, capsys) -> None:
    out = tmp_path / "o"
    assert main(["export", str(MECHANISMS / "eightbar.toml"), *argv, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err, err
    assert not out.exists() or not any(out.iterdir())


def test_the_files_masses_gravity_and_loads_go_into_every_model(tmp_path: Path) -> None:
    """MJCF: each body's mass, inertia and centre as the file states them (kg, kg·m², metres), gravity, one motor
    per load; the scripts: the same mass table the validators' force engines read, and the loads."""
    import runpy

    from validators.forces_common import mass_table
    from validators.models import export

    mech = vloop.load(MECHANISMS / "sixbar_watt2_dynamics.toml")
    model = mujoco.MjModel.from_xml_path(str(export(mech, tmp_path, "mjcf")))
    assert np.allclose(model.opt.gravity[:2], mech.gravity, rtol=0, atol=1e-15)
    for name, (mass, com, inertia) in mass_table(mech).items():
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, name)
        assert model.body_mass[b] == pytest.approx(mass, rel=1e-15)
        assert model.body_inertia[b][2] == pytest.approx(inertia, rel=1e-15)
        assert np.allclose(model.body_ipos[b][:2], com * 1.0, rtol=0, atol=1e-15)  # the file is in metres
    motors = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, i) for i in range(model.nu)]
    assert sum(m.startswith("load ") for m in motors) == len(mech.loads) >= 1
    for fmt in ("pinocchio", "exudyn"):
        ns = runpy.run_path(str(export(mech, tmp_path, fmt)), run_name="not_main")
        got = ns["MECHANISM"]
        assert got.gravity == mech.gravity and len(got.loads) == len(mech.loads)
        for name, (mass, com, inertia) in mass_table(mech).items():
            m2, c2, i2 = got.masses_table[name]
            assert (m2, i2) == (mass, inertia) and np.array_equal(c2, com)


def test_mujoco_stops_at_the_sample_vloop_stops_and_writes_nothing(tmp_path: Path, monkeypatch) -> None:
    """Into a limit position the servo cannot turn the input further: the engine stops there, with vloop, and
    keeps MuJoCo's instability warnings to itself (no MUJOCO_LOG.TXT in the working folder)."""
    from validators import mujoco as engine

    monkeypatch.chdir(tmp_path)
    mech = vloop.load(MECHANISMS / "fourbar_nongrashof_past_limit.toml")
    with pytest.raises(vloop.MotionError) as ours:
        vloop.solve(mech)
    with pytest.raises(vloop.MotionError) as theirs:
        engine.solve(mech)
    assert theirs.value.sample == ours.value.sample and "cannot follow the input" in str(theirs.value)
    assert list(tmp_path.iterdir()) == []
