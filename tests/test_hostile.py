"""Hostile inputs and hostile surroundings: never a wrong number with exit 0, never a traceback, never a
half-written or misplaced file. One test (or a few) per class of hostile input; the Ctrl-C, concurrent-run and
disk-limit tests run real `vloop` processes (subprocess, a signal, resource limits), not mocks."""

from __future__ import annotations

import math
import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import tomli_w

import vloop
from vloop.cli import main

FOURBAR = """
name = "fourbar"
[joints]
O2 = [0.0, 0.0]
O4 = [7.0, 0.0]
A = [0.0, 2.0]
B = [5.0, 4.0]
[links]
ground = { joints = ["O2", "O4"], ground = true }
crank = { joints = ["O2", "A"] }
coupler = { joints = ["A", "B"] }
rocker = { joints = ["O4", "B"] }
[[drivers]]
link = "crank"
omega = 1.0
[time]
start = 0.0
stop = 1.0
step = 0.1
"""


def run_cli(args: list[str], tmp: Path, **kw) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "vloop.cli", *args], cwd=tmp, capture_output=True, text=True, timeout=300, **kw
    )


def one_clean_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("vloop: error: ") or lines[0].startswith("vloop: interrupted"), err
    return lines[0]


def finite_csv(path: Path) -> np.ndarray:
    """The data rows of a written table; a run stopped before its first sample writes the header only (no rows)."""
    header, *data = path.read_text(encoding="utf-8").splitlines()
    rows = np.loadtxt(data, delimiter=",", ndmin=2) if data else np.empty((0, header.count(",") + 1))
    assert np.all(np.isfinite(rows)), f"{path} holds non-finite numbers"
    return rows


# ---------------------------------------------------------------- 1. wrong or non-finite numbers


@pytest.mark.parametrize("omega", ["1e200", "1e155", "-1e300"])
def test_overflowing_rates_are_an_error_not_data(omega, tmp_path, capsys):
    f = tmp_path / "m.toml"
    f.write_text(FOURBAR.replace("omega = 1.0", f"omega = {omega}"))
    assert main(["run", str(f), "--out", str(tmp_path / "o")]) == 2
    line = one_clean_line(capsys.readouterr().err)
    assert "not finite" in line or "too large to resolve" in line
    if (tmp_path / "o" / "results.csv").exists():
        finite_csv(tmp_path / "o" / "results.csv")


def test_huge_slider_axis_is_normalised_without_overflow():
    text = FOURBAR.replace('rocker = { joints = ["O4", "B"] }', "").replace(
        "[[drivers]]", '[sliders]\nblk = { joint = "B", guide = "ground", axis = [1.5e308, 1.5e308] }\n[[drivers]]'
    )
    mech = vloop.loads(text)
    assert mech.sliders["blk"].axis == pytest.approx((math.sqrt(0.5), math.sqrt(0.5)), abs=1e-15)
    tiny = vloop.loads(text.replace("[1.5e308, 1.5e308]", "[5e-324, 0.0]"))
    assert tiny.sliders["blk"].axis == (1.0, 0.0) or tiny is None  # a subnormal axis is refused or exact


def scaled(mech: vloop.Mechanism, factor: float) -> vloop.Mechanism:
    """The same mechanism with every coordinate and length multiplied by ``factor``."""
    data = vloop.mechanism.to_dict(mech)
    data["joints"] = {k: [v[0] * factor, v[1] * factor] for k, v in data["joints"].items()}
    for link in data["links"].values():
        if "length" in link:
            link["length"] *= factor
    return vloop.mechanism.from_dict(data, source=mech.source)  # read only: a size refused later, by the compiler


@pytest.mark.parametrize("factor", [1e-60, 1e-30, 1e30, 1e56])
def test_a_mechanism_at_any_solvable_size_gives_the_same_motion(factor):
    """Scaled by 1e-60…1e56 (sizes ~1.6e-58…1.6e58 of its units) the textbook four-bar moves the same: angles to
    1e-14 rad, positions to 1e-14 of their peak in the new units."""
    mech = vloop.load(Path(__file__).resolve().parents[1] / "mechanisms" / "fourbar_textbook_example.toml")
    ref, res = vloop.solve(mech), vloop.solve(scaled(mech, factor))
    assert np.max(np.abs(res["l3.theta"] - ref["l3.theta"])) < 1e-14
    assert np.max(np.abs(res["B.ay"] / factor - ref["B.ay"])) < 1e-14 * np.max(np.abs(ref["B.ay"]))


@pytest.mark.parametrize(
    ("factor", "named"), [(1e-70, "[joints] the mechanism spans"), (1e80, "[joints.O4] (1e+82, 0) is beyond ±1e+60 mm")]
)
def test_a_mechanism_too_large_or_too_small_for_double_precision_is_refused(factor, named, tmp_path, capsys):
    """Beyond 1e±60 of its units a dyad's discriminant (size⁴) over- or underflows: one line, exit 2, naming the
    size and what to do (not a wrong 'limit position' at t = 0). A length beyond 1e60 is refused as the file is read,
    by its key; a mechanism too small, by the compiler, from its span."""
    mech = vloop.load(Path(__file__).resolve().parents[1] / "mechanisms" / "fourbar_textbook_example.toml")
    data = vloop.mechanism.to_dict(mech)
    data["joints"] = {k: [v[0] * factor, v[1] * factor] for k, v in data["joints"].items()}
    for link in data["links"].values():
        if "length" in link:
            link["length"] *= factor
    f = tmp_path / "m.toml"
    f.write_text(tomli_w.dumps(data), encoding="utf-8")
    assert main(["run", str(f), "--out", str(tmp_path / "o")]) == 2
    line = one_clean_line(capsys.readouterr().err)
    assert named in line and ("larger units" if factor > 1 else "smaller units") in line
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_near_singular_samples_are_refused_by_the_error_they_imply():
    """A triple rocker driven at fine steps up to its limit: the samples whose condition number implies an
    error above rtol are refused (toggle), the kept ones within 1e-3 of rtol are flagged ill-conditioned."""
    from tests.conftest import MECHANISMS

    mech = vloop.load(MECHANISMS / "fourbar_nongrashof_past_limit.toml")
    lim = math.acos((3.0**2 + 6.0**2 - 8.5**2) / (2 * 3.0 * 6.0))
    d = mech.drivers[0]
    t_lim = (lim - d.x0) / d.v0
    times = t_lim - np.geomspace(1e-2, 1e-12, 60)  # ever closer to the limit, never past it
    with pytest.raises(vloop.MotionError) as info:
        vloop.solve(mech, times=times)
    err = info.value
    assert "toggle" in str(err) and "cond²·ε" in str(err)
    kept = err.partial
    eps = np.finfo(float).eps
    assert np.all(kept.health["cond"] ** 2 * eps <= 1e-9)  # every kept sample's velocities within rtol
    assert np.array_equal(kept.health["ill_conditioned"].astype(bool), kept.health["cond"] ** 3 * eps > 1e-12)
    assert kept.health["ill_conditioned"].sum() >= 1


# ---------------------------------------------------------------- 2. messages, not tracebacks


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (("omega = 1.0", "omega = " + "9" * 400), "too large"),
        (("step = 0.1", "step = 5e-324"), "[time]"),
        (("A = [0.0, 2.0]", "A = " + "[" * 5000 + "0" + "]" * 5000), "nested too deeply"),
        (("crank = {", '"cr\\u0000nk" = {'), "may use only letters"),
        (("crank = {", '"cr,ank" = {'), "may use only letters"),
        (("crank = {", '"cou\\"pler" = {'), "may use only letters"),
        (('name = "fourbar"', 'name = "a\\u0000b"'), "[name]"),
    ],
    ids=["int-10^400", "step-5e-324", "deep-nesting", "nul-in-name", "comma-in-name", "quote-in-name", "nul-name"],
)
def test_bad_values_end_in_one_line(edit, needle, tmp_path, capsys):
    f = tmp_path / "m.toml"
    f.write_text(FOURBAR.replace(*edit))
    assert main(["run", str(f), "--out", str(tmp_path / "o")]) == 2
    assert needle in one_clean_line(capsys.readouterr().err)
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


def test_byte_order_mark_is_accepted(tmp_path):
    f = tmp_path / "bom.toml"
    f.write_bytes(b"\xef\xbb\xbf" + FOURBAR.encode())
    assert len(vloop.solve(vloop.load(f))) == 11


@pytest.mark.parametrize("where", ["out-is-a-file", "cannot-create", "results-is-a-folder"])
def test_outputs_that_cannot_be_written(where, tmp_path, capsys):
    f = tmp_path / "m.toml"
    f.write_text(FOURBAR)
    out = tmp_path / "o"
    if where == "out-is-a-file":
        out.write_text("I am a file")
    elif where == "cannot-create":
        out = Path("/proc/vloop-cannot-be-here/o")
    else:
        (out / "results.csv").mkdir(parents=True)
    assert main(["run", str(f), "--out", str(out)]) == 2
    line = one_clean_line(capsys.readouterr().err)
    assert str(out) in line
    if where == "results-is-a-folder":
        assert (out / "results.csv").is_dir() and not (out / "health.csv").exists()  # nothing half-published


def test_disk_full_is_a_clean_error(tmp_path):
    """A file-size limit (RLIMIT_FSIZE) makes every write past 4 kB fail, as a full disk would."""
    f = tmp_path / "m.toml"
    f.write_text(FOURBAR.replace("step = 0.1", "step = 0.0005"))

    def limit() -> None:
        resource.setrlimit(resource.RLIMIT_FSIZE, (4096, 4096))

    proc = run_cli(["run", str(f), "--out", str(tmp_path / "o")], tmp_path, preexec_fn=limit)
    assert proc.returncode == 2
    line = one_clean_line(proc.stderr)
    assert "too large" in line.lower() or "no space" in line.lower()
    assert not (tmp_path / "o" / "results.csv").exists()


@pytest.mark.parametrize("kind", ["folder", "fifo", "dev-zero"])
def test_profiles_must_be_regular_files(kind, tmp_path, capsys):
    if kind == "folder":
        (tmp_path / "p.csv").mkdir()
        spec, extra = "p.csv", []
    elif kind == "fifo":
        os.mkfifo(tmp_path / "p.csv")
        spec, extra = "p.csv", []
    else:
        spec, extra = "/dev/zero", ["--allow-external-profiles"]
    f = tmp_path / "m.toml"
    f.write_text(FOURBAR.replace("omega = 1.0", f'profile = "{spec}"'))
    assert main(["run", str(f), "--out", str(tmp_path / "o"), *extra]) == 2  # returns at once: nothing read
    assert "not a regular file" in one_clean_line(capsys.readouterr().err)


def test_profiles_outside_the_folder_are_refused_and_never_echoed(tmp_path, capsys):
    secret = tmp_path / "secret.csv"
    secret.write_text("t,theta\nTOP-SECRET,1\n0.5,2\n")
    sub = tmp_path / "sub"
    sub.mkdir()
    f = sub / "m.toml"
    f.write_text(FOURBAR.replace("omega = 1.0", 'profile = "../secret.csv"'))
    assert main(["run", str(f), "--out", str(tmp_path / "o")]) == 2
    line = one_clean_line(capsys.readouterr().err)
    assert "outside the mechanism file's folder" in line and "TOP-SECRET" not in line
    assert main(["run", str(f), "--out", str(tmp_path / "o"), "--allow-external-profiles"]) == 2
    line = one_clean_line(capsys.readouterr().err)
    assert "every data row must be" in line and "TOP-SECRET" not in line


def _profile_case(tmp_path: Path, spec: str) -> Path:
    """A four-bar in tmp_path/m whose crank follows θ = π/2 + t [rad] from the profile ``spec``."""
    folder = tmp_path / "m"
    folder.mkdir(exist_ok=True)
    (folder / "p.csv").write_text(f"t,theta\n0,{math.pi / 2!r}\n1,{math.pi / 2 + 1!r}\n")
    f = folder / "m.toml"
    f.write_text(FOURBAR.replace("omega = 1.0", f"profile = {str(spec)!r}"))
    return f


def test_profiles_are_resolved_alike_absolute_or_relative_and_links_out_are_refused(tmp_path, capsys):
    """An absolute path into the mechanism's folder is read like the relative one (the crank then follows the
    profile: θ(1 s) = π/2 + 1); what really lies outside — by an absolute path or a symbolic link inside the
    folder that points out — is refused with one line naming the file and the entry."""
    inside = [str(tmp_path / "m" / "p.csv"), "p.csv", "./sub/../p.csv", str(tmp_path / "m" / "." / "p.csv")]
    (tmp_path / "m" / "sub").mkdir(parents=True)
    for spec in inside:
        mech = vloop.load(_profile_case(tmp_path, spec))
        assert abs(vloop.solve(mech, times=np.array([0.0, 1.0]))["crank.theta"][1] - (math.pi / 2 + 1)) <= 1e-12
    os.symlink(tmp_path / "m", tmp_path / "link_to_m")  # the folder reached through a link: still inside
    mech = vloop.load(tmp_path / "link_to_m" / _profile_case(tmp_path, str(tmp_path / "m" / "p.csv")).name)
    assert mech.drivers[0].profile is not None
    (tmp_path / "outside.csv").write_text("t,theta\n0,1\n1,2\n")
    os.symlink(tmp_path / "outside.csv", tmp_path / "m" / "escape.csv")
    for spec in (str(tmp_path / "outside.csv"), "escape.csv", "../outside.csv"):
        f = _profile_case(tmp_path, spec)
        assert main(["run", str(f), "--out", str(tmp_path / "o")]) == 2
        line = one_clean_line(capsys.readouterr().err)
        assert line.startswith(f"vloop: error: {f}: [drivers[0] (link 'crank')] profile ")
        assert "is outside the mechanism file's folder" in line and "(allow others with --allow-external" in line
        assert not (tmp_path / "o").exists()


# ---------------------------------------------------------------- 4. output safety


@pytest.mark.parametrize("name", ["../../x", "/tmp/absolute", "a\\u0000b", "..", "."])
def test_default_folder_stays_inside_out(name, tmp_path, capsys):
    f = tmp_path / "m.toml"
    f.write_text(FOURBAR.replace('name = "fourbar"', f'name = "{name}"'))
    cwd = Path.cwd()
    os.chdir(tmp_path)
    try:
        code = main(["run", str(f)])
    finally:
        os.chdir(cwd)
    err = capsys.readouterr()
    if code == 2:  # a NUL in a name is refused outright
        assert "[name]" in one_clean_line(err.err)
        return
    assert code == 0
    written = [p for p in tmp_path.rglob("results.csv")]
    assert len(written) == 1 and written[0].parent.parent == tmp_path / "out"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.toml", "out"]


LONG = FOURBAR.replace("step = 0.1", "step = 2e-7")  # 5 million samples: several seconds


def test_ctrl_c_leaves_nothing_half_written(tmp_path):
    f = tmp_path / "m.toml"
    f.write_text(LONG)
    out = tmp_path / "o"
    proc = subprocess.Popen(
        [sys.executable, "-m", "vloop.cli", "run", str(f), "--out", str(out)],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    time.sleep(2.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    if proc.returncode == 0:  # the machine was fast enough to finish: then the files are whole
        finite_csv(out / "results.csv")
        return
    assert proc.returncode == 130
    assert one_clean_line(err).startswith("vloop: interrupted")
    assert not out.exists() or [p.name for p in out.iterdir()] == []  # no stage, no half file


def test_two_runs_into_one_folder_leave_one_runs_files(tmp_path):
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    a.write_text(FOURBAR.replace("step = 0.1", "step = 0.00005"))  # 20,001 rows
    b.write_text(FOURBAR.replace("step = 0.1", "step = 0.0001"))  # 10,001 rows
    out = tmp_path / "o"
    procs = [
        subprocess.Popen([sys.executable, "-m", "vloop.cli", "run", str(m), "--out", str(out)], cwd=tmp_path)
        for m in (a, b, a, b)
    ]
    assert [p.wait(timeout=300) for p in procs] == [0, 0, 0, 0]
    results = finite_csv(out / "results.csv")
    health = np.loadtxt(out / "health.csv", delimiter=",", skiprows=1, ndmin=2)
    assert len(results) in (20001, 10001) and len(health) == len(results)
    assert np.array_equal(health[:, 0], results[:, 0])  # the same run's two files
    assert sorted(p.name for p in out.iterdir()) == ["health.csv", "results.csv"]


# ---------------------------------------------------------------- 3. compile stays near-linear


def test_a_chain_of_200_dyads_compiles_and_solves():
    sys.path.insert(0, str(Path(__file__).parents[1] / "benchmarks"))
    from bench_compile import dyad_chain

    mech = dyad_chain(200)
    system = vloop.compile(mech)
    assert len(system.loops) == 200 and all(b.kind == "RRR" for b in system.blocks)
    res = vloop.solve(system)
    assert res.health["residual"].max() < 1e-12


def test_published_files_follow_the_umask(tmp_path):
    from vloop.files.output import write_text

    old = os.umask(0o022)
    try:
        p = write_text(tmp_path / "x.txt", "hi")
    finally:
        os.umask(old)
    assert (p.stat().st_mode & 0o777) == 0o644
