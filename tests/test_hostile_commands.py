"""The newer commands (study, corpus, validate, view, and every option of run) as hard to break as `run`.

One group per class of failure: everything a command reads is checked before any work starts; every option is
parsed by the one parser the files and the environment use; no NaN or inf in any printed line or table; a viewer
page bounded by its bytes (tests/test_viewer.py); messages that name the real file, entry and column; Ctrl-C and
output sets (real processes and real signals, as tests/test_hostile.py); the validation's printed time; study and
comparison tables in CSV as well as Parquet, with units.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import vloop
from vloop.cli import main

from .conftest import MECHANISMS
from .test_bad_input import FOURBAR

ROOT = Path(__file__).resolve().parents[1]
TEXTBOOK = MECHANISMS / "fourbar_textbook_example.toml"
TOLERANCE_STUDY = """
mechanism = "{mechanism}"
samples = {samples}
seed = 1
[[parameters]]
name = "links.l3.length"
tolerance = {{ dist = "uniform", half_width = {half_width} }}
[[parameters]]
name = "joints.O4.x"
tolerance = {{ dist = "normal", sigma = {sigma} }}
[[outputs]]
quantity = "l4.theta"
stat = "range"
[[outputs]]
quantity = "l4.theta"
stat = "series"
"""


def cli(*args: str) -> tuple[int, str, str]:
    """``vloop ARGS`` in this process: (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def one_line(err: str) -> str:
    """The single line a refused command prints (no traceback, no usage block)."""
    lines = err.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in err, err
    assert lines[0].startswith("vloop: error: "), err
    return lines[0]


def no_non_finite(text: str) -> None:
    assert not re.search(r"\b(nan|inf|infinity)\b", text, re.IGNORECASE), text


def write(path: Path, text: str) -> Path:
    path.write_text(text, encoding="utf-8")
    return path


def tolerance_study(
    tmp_path: Path, samples: int = 200, mechanism: Path = TEXTBOOK, half_width: float = 0.5, sigma: float = 0.3
) -> Path:
    text = TOLERANCE_STUDY.format(mechanism=mechanism, samples=samples, half_width=half_width, sigma=sigma)
    return write(tmp_path / "tol.toml", text)


# ---------------------------------------------------------------- 16. everything read is checked before any work


def grid_study(tmp_path: Path, n: int) -> Path:
    mech = write(tmp_path / "fb.toml", FOURBAR)
    a = ", ".join(repr(float(x)) for x in np.linspace(4.5, 5.5, n))
    b = ", ".join(repr(float(x)) for x in np.linspace(5.5, 6.5, n))
    text = (
        f'mechanism = "{mech.name}"\nsensitivity = "none"\n'
        f'[[parameters]]\nname = "links.coupler.length"\nvalues = [{a}]\n'
        f'[[parameters]]\nname = "links.rocker.length"\nvalues = [{b}]\n'
        '[[outputs]]\nquantity = "rocker.theta"\nstat = "range"\n'
    )
    return write(tmp_path / f"grid{n}.toml", text)


def _refusal_peak(tmp_path: Path, n: int, budget: str) -> tuple[float, int, str]:
    """(seconds, peak bytes allocated, stderr) of `vloop study` on an n × n grid refused by its memory budget."""
    import tracemalloc

    f = grid_study(tmp_path, n)
    tracemalloc.start()
    try:
        t0 = time.perf_counter()
        code, _, err = cli("study", f, "--out", tmp_path / "o", "--memory-budget", budget)
        seconds = time.perf_counter() - t0
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert code == 2
    return seconds, peak, err


def test_a_7000_by_7000_grid_is_refused_by_its_estimate_before_it_is_built(tmp_path):
    """49,000,000 variants: refused from the sizes alone, the designs never built (they alone are 49e6 × 2 × 8 B =
    784 MB; building the grid took 4–5 GB): the peak allocation (tracemalloc counts numpy's arrays too) is that of
    a 70 × 70 grid refused the same way, within the longer file's text."""
    assert cli("study", grid_study(tmp_path, 3), "--out", tmp_path / "warm")[0] == 0  # imports outside the count
    _, small, _ = _refusal_peak(tmp_path, 70, "1K")
    seconds, peak, err = _refusal_peak(tmp_path, 7000, "4G")
    line = one_line(err)
    assert "the study's 49,000,000 designs to solve need about" in line
    assert "memory budget of 4 GB (--memory-budget)" in line
    assert peak < small + (8 << 20), (peak, small)
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())
    print(f"refused in {seconds:.2f} s (under tracemalloc), peak {peak / 2**20:.1f} MiB vs {small / 2**20:.1f} MiB")


@pytest.mark.parametrize(
    "setup",
    [
        {"values": [4.8, 5.0, 5.2]},
        {"values": [4.8, 5.2], "sensitivity": "each"},
        {"values": [4.8, 5.2], "sensitivity": "none"},
        {"tolerance": True},
        {"tolerance": True, "values": [4.8, 5.2]},
        {"tolerance": True, "sensitivity": "each"},
    ],
)
def test_the_estimate_counts_the_designs_the_plan_builds(setup):
    """design_count (from the sizes) equals the rows plan() builds, for grids, tolerances, both, each sensitivity."""
    from vloop.studies.study import design_count, plan
    from vloop.studies.studyfile import from_dict

    mech = vloop.loads(FOURBAR)
    p: dict = {"name": "links.coupler.length"}
    if "values" in setup:
        p["values"] = setup["values"]
    if setup.get("tolerance"):
        p["tolerance"] = {"dist": "normal", "sigma": 0.01}
    data = {"parameters": [p, {"name": "joints.O4.x", "values": [6.9, 7.0]}], "outputs": ["rocker.theta.range"]}
    if setup.get("tolerance"):
        data["samples"] = 7
    data["sensitivity"] = setup.get("sensitivity", "nominal")
    spec = from_dict(data, mech)
    built = plan(spec)
    assert design_count(spec) == (built.n_variants, len(built.values))


@pytest.mark.parametrize(
    ("name", "content", "what"),
    [
        ("empty", b"", "is empty"),
        ("blank", b"  \n", "is empty"),
        ("not-json", b'{"mechanisms": [', "is not JSON"),
        ("not-utf8", b'\xff\xfe{"mechanisms": []}', "is not UTF-8 text"),
        ("array", b"[1, 2]", "is not a vloop validation summary"),
        ("no-mechanisms", b'{"schema": 1}', "is not a vloop validation summary"),
        ("bad-quantity", b'{"mechanisms": [{"name": "x", "comparisons": [{"engine": "a", "reference": "b", '
         b'"quantities": [{"quantity": "q", "passed": true, "max_abs": "big", "allowed": 1}]}]}]}',
         "mechanisms[0].comparisons[0].quantities[0].max_abs"),
        ("huge-float", b'{"mechanisms": [], "seconds": 1e400}', "holds 1e400"),
        ("huge-int", b'{"mechanisms": [], "seconds": 1' + b"0" * 400 + b"}", "too large"),
        ("nan", b'{"mechanisms": [], "seconds": NaN}', "holds NaN"),
        ("deep", b"[" * 100_000 + b"]" * 100_000, "nested too deeply"),
        ("folder", None, "is a folder"),
        ("missing", "missing", "does not exist"),
    ],
)  # fmt: skip
def test_a_bad_previous_summary_is_one_line_before_any_engine_runs(tmp_path, monkeypatch, name, content, what):
    from validators import harness

    def no_run(*a, **k):
        raise AssertionError("validation ran before the previous summary was checked")

    monkeypatch.setattr(harness, "run", no_run)
    prev = tmp_path / f"{name}.json"
    if content is None:
        prev.mkdir()
    elif content != "missing":
        prev.write_bytes(content)
    out = tmp_path / "o"
    code, _, err = cli("validate", TEXTBOOK, "--engines", "vloop,analytic", "--out", out, "--previous", prev)
    assert code == 2
    line = one_line(err)
    assert f"previous summary {prev}: " in line and what in line
    assert not out.exists()


def test_a_bad_summary_found_by_a_nightly_run_is_refused_the_same_way(tmp_path, monkeypatch):
    from validators import harness

    monkeypatch.setattr(harness, "run", lambda *a, **k: pytest.fail("ran"))
    (tmp_path / "n" / "2020-01-01").mkdir(parents=True)
    (tmp_path / "n" / "2020-01-01" / "summary.json").write_bytes(b"\x00\xff")
    code, _, err = cli("validate", TEXTBOOK, "--engines", "vloop,analytic", "--out", tmp_path / "n", "--nightly")
    assert code == 2 and "2020-01-01/summary.json: is not UTF-8 text" in one_line(err)


@pytest.mark.parametrize("command", ["study", "view", "corpus", "validate"])
def test_an_output_folder_that_cannot_be_written_is_refused_before_the_work(tmp_path, monkeypatch, command):
    """--out naming a file: one line, exit 2, and the work (solving, generating, validating) never started."""
    import validators.corpus
    import vloop.views.view
    from validators import harness
    from vloop.studies import study

    for mod, fn in ((study, "run"), (vloop.views.view, "solve_for_view"), (harness, "run")):
        monkeypatch.setattr(mod, fn, lambda *a, **k: pytest.fail("work started"))
    monkeypatch.setattr(validators.corpus, "generate", lambda *a, **k: pytest.fail("work started"))
    blocked = write(tmp_path / "blocked", "a file")
    args = {
        "study": ["study", tolerance_study(tmp_path)],
        "view": ["view", TEXTBOOK],
        "corpus": ["corpus", "--n", "2"],
        "validate": ["validate", TEXTBOOK, "--engines", "vloop,analytic"],
    }[command]
    code, _, err = cli(*args, "--out", blocked)
    assert code == 2 and f"output folder {blocked}: exists and is not a folder" in one_line(err)


# ---------------------------------------------------------------- 17. one parser per option


@pytest.mark.parametrize("value", ["abc", "-1", "0", "1e30", "nan", "inf", "5e-324", "1" + "0" * 400, "2 G B"])
def test_a_memory_budget_is_refused_alike_on_the_command_line_in_the_file_and_the_environment(
    tmp_path, monkeypatch, value
):
    """The same parser everywhere: the message names where the value came from and says what a size is."""
    f = write(tmp_path / "m.toml", FOURBAR)
    accepts = "must be a size such as 2G, 500M or a number of bytes (1 byte to 1 EiB)"
    for command in (["run", f], ["study", tolerance_study(tmp_path, 20)]):
        code, _, err = cli(*command, "--out", tmp_path / "o", f"--memory-budget={value}")
        assert code == 2 and f"argument --memory-budget: {accepts}" in one_line(err)
    monkeypatch.setenv("VLOOP_MEMORY_BUDGET", value)
    for command in (["run", f], ["info", f], ["view", f]):
        code, _, err = cli(*command, "--out", tmp_path / "o") if command[0] != "info" else cli(*command)
        assert code == 2 and f"VLOOP_MEMORY_BUDGET: {accepts}" in one_line(err)
    monkeypatch.delenv("VLOOP_MEMORY_BUDGET")
    g = write(tmp_path / "g.toml", FOURBAR + f'[solver]\nmemory_budget = "{value}"\n')
    code, _, err = cli("run", g, "--out", tmp_path / "o")
    assert code == 2 and f"[solver] memory_budget: {accepts}" in one_line(err)
    assert not (tmp_path / "o").exists()


def test_a_study_refused_by_its_own_memory_budget(tmp_path):
    code, _, err = cli("study", tolerance_study(tmp_path, 200), "--out", tmp_path / "o", "--memory-budget", "100K")
    assert code == 2 and "more than the memory budget of 100 kB (--memory-budget)" in one_line(err)


@pytest.mark.parametrize("command", ["study", "validate"])
@pytest.mark.parametrize(
    ("address", "what"),
    [
        ("localhost", "must be a Dask scheduler address such as tcp://host:8786 (with its port"),
        ("tcp://localhost", "with its port"),
        ("localhost:99999", "(with its port, 1 to 65535), got 'localhost:99999'"),
        ("localhost:1", "cannot reach a Dask scheduler at tcp://localhost:1 (connection refused"),
    ],
)
def test_a_scheduler_without_port_or_unreachable_is_one_quick_line(tmp_path, command, address, what):
    args = ["study", tolerance_study(tmp_path, 20)] if command == "study" else ["validate", TEXTBOOK]
    t0 = time.perf_counter()
    code, _, err = cli(*args, "--out", tmp_path / "o", "--scheduler", address)
    assert code == 2 and what in one_line(err)
    assert time.perf_counter() - t0 < 10.0  # a refused or closed port answers at once (was: a 60 s hang)
    assert not (tmp_path / "o").exists()


def test_a_port_that_is_not_a_dask_scheduler_is_refused_quickly(tmp_path):
    """A server that accepts the connection and says nothing (Dask's client waited for its handshake forever)."""
    import socket

    with socket.create_server(("127.0.0.1", 0)) as server:
        port = server.getsockname()[1]
        t0 = time.perf_counter()
        code, _, err = cli("study", tolerance_study(tmp_path, 20), "--out", tmp_path / "o", "--scheduler",
                           f"127.0.0.1:{port}")  # fmt: skip
    assert code == 2 and "accepts connections but is not a Dask scheduler (no handshake within 3 s)" in one_line(err)
    assert time.perf_counter() - t0 < 10.0


@pytest.mark.parametrize(
    ("engines", "what"),
    [
        ("", "argument --engines: must be a comma-separated list"),
        (",", "(none may be empty)"),
        ("vloop,,analytic", "(none may be empty)"),
        ("vloop,vloop", "(each once)"),
        ("vloop,warp-drive", "unknown 'warp-drive'"),
        ("vloop", "nothing to compare: --engines vloop makes no comparison on this file"),
        ("pinocchio", "nothing to compare"),
    ],
)
def test_a_validation_that_would_validate_nothing_is_refused(tmp_path, engines, what):
    """An empty --engines never ends "all passed" with no engine run: every engine list must make a comparison."""
    code, out, err = cli("validate", TEXTBOOK, f"--engines={engines}", "--out", tmp_path / "o")
    assert code == 2 and what in one_line(err) and "passed" not in out
    assert not (tmp_path / "o" / "summary.json").exists()


def test_engines_without_a_closed_form_compare_nothing_and_say_so(tmp_path):
    """analytic has no closed form for the Stephenson III driven at its output: vloop,analytic compares nothing."""
    f = MECHANISMS / "sixbar_stephenson3_output_driven.toml"
    code, _, err = cli("validate", f, "--engines", "vloop,analytic", "--out", tmp_path / "o")
    assert code == 2 and "analytic needs a closed form" in one_line(err)


# the options of every command, each with a cheap baseline (values are fuzzed one option at a time)
COMMANDS = {
    "run": (["run", "{fb}", "--out", "o"], ["--out", "--method", "--ma", "--format", "--memory-budget"]),
    "view": (["view", "{fb}", "--out", "o"], ["--out"]),
    "loops": (["loops", "{fb}"], []),
    "info": (["info", "{fb}"], []),
    "study": (
        ["study", "{study}", "--out", "o"],
        ["--out", "--format", "--memory-budget", "--scheduler", "--workers"],
    ),
    "corpus": (
        ["corpus", "--n", "1", "--out", "o"],
        ["--n", "--out", "--seed", "--start", "--families", "--limit-fraction"],
    ),
    "validate": (
        ["validate", "{textbook}", "--engines", "vloop,analytic", "--out", "o", "--no-report"],
        ["--engines", "--out", "--previous", "--format", "--scheduler", "--workers", "--timeout", "--corpus",
         "--seed", "--start", "--families", "--limit-fraction", "--minimize-tries"],
    ),
}  # fmt: skip
HOSTILE = [
    "", " ", "0", "-0", "1", "-1", "2", "1e308", "5e-324", "nan", "inf", "-inf", "1" + "0" * 400, "1e400",
    "abc", "[[1]]", "{}", "'", '"', "\\", "a,b", ",", "..", "x" * 300, "\x00", "é", "\n", "1G", "2.5",
]  # fmt: skip


def _fuzz_case(tmp_path: Path, command: str, option: str | None, value: str) -> None:
    """One command with one option set to ``value``: exit 0 or 2 (1 only for a validation that failed), and on 2
    one clean line; never a traceback."""
    base, _ = COMMANDS[command]
    files = {"fb": tmp_path / "fb.toml", "study": tmp_path / "st.toml", "textbook": TEXTBOOK}
    argv = [a.format(**files) for a in base]
    if option is not None:
        if option in argv:
            i = argv.index(option)
            del argv[i : i + 2]
        argv.append(f"{option}={value}")
    else:
        argv.append(value)  # a stray positional or an unknown option
    code, out, err = cli(*argv)
    assert "Traceback" not in err and "Traceback" not in out, (argv, err)
    assert code in (0, 1, 2), (argv, code, err)
    if code == 2:
        one_line(err)
    if code == 1:
        assert command == "validate" and "RED: " in out, (argv, out, err)
    no_non_finite(out.replace(value, "") if value.strip() else out)  # a folder may be called "nan"


@pytest.fixture
def fuzz_dir(tmp_path, monkeypatch):
    """A working folder with the baseline files; anything expensive a valid value could start is stubbed to a
    one-line refusal (a Dask cluster, a scheduler connection, a corpus of a million files)."""
    import validators.corpus
    from vloop import runner
    from vloop.errors import VloopError

    write(tmp_path / "fb.toml", FOURBAR)
    write(tmp_path / "st.toml", TOLERANCE_STUDY.format(mechanism=TEXTBOOK, samples=20, half_width=0.5, sigma=0.3))
    monkeypatch.chdir(tmp_path)

    def no_cluster(*a, **k):
        raise runner.RunnerError("(test) no cluster", entry="runner")

    monkeypatch.setattr(runner, "_client", no_cluster)
    monkeypatch.setattr(runner, "check_scheduler", no_cluster)
    generate = validators.corpus.generate

    def small(n, *a, **k):
        if n > 3:
            raise VloopError("(test) corpus too large for a unit test", entry="n")
        return generate(n, *a, **k)

    monkeypatch.setattr(validators.corpus, "generate", small)
    return tmp_path


def _fuzz(fuzz_dir: Path, command: str, examples: int) -> None:
    from hypothesis import HealthCheck, given, settings
    from hypothesis import strategies as st

    _, options = COMMANDS[command]
    values = st.one_of(
        st.sampled_from(HOSTILE),
        st.text(max_size=12),
        st.integers(-(10**6), 10**6).map(str),
        st.floats(allow_nan=True, allow_infinity=True).map(repr),
    )
    safe_out = values.filter(lambda v: not v.startswith(("/", "~")) and ".." not in v)
    option = st.sampled_from([*options, None]) if options else st.just(None)

    @settings(max_examples=examples, deadline=None, suppress_health_check=list(HealthCheck), derandomize=True)
    @given(data=st.data())
    def check(data):
        opt = data.draw(option)
        value = data.draw(safe_out if opt in ("--out", None) else values)
        _fuzz_case(fuzz_dir, command, opt, value)

    check()


@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_option_of_every_command_takes_any_value_without_a_traceback(fuzz_dir, command):
    _fuzz(fuzz_dir, command, 12)


@pytest.mark.slow
@pytest.mark.parametrize("command", list(COMMANDS))
def test_every_option_of_every_command_many_values(fuzz_dir, command):
    _fuzz(fuzz_dir, command, 150)


@pytest.mark.parametrize("value", HOSTILE)
def test_every_option_parser_answers_a_value_or_an_option_error(value):
    """Each parser of vloop.files.options, on any text: a value, or an OptionError/VloopError — nothing else."""
    from vloop.errors import VloopError
    from vloop.files.options import OPTIONS, check_environment

    for name, opt in OPTIONS.items():
        try:
            opt.parse(value)
        except VloopError as exc:
            assert "\n" not in str(exc) and str(exc), name
    for env in ("VLOOP_MEMORY_BUDGET", "VLOOP_KEEP_HEAP"):
        with contextlib.suppress(VloopError):
            check_environment({env: value})


# ---------------------------------------------------------------- 18. no NaN or inf in any output


def test_a_tolerance_study_where_every_variant_fails_says_so(tmp_path):
    """Every variant of the non-Grashof four-bar driven past its limit stops: no "σ nan ± nan" with exit 0, but
    one line that no variant completed (exit 2, the rule for a motion that cannot be completed), the tables still
    written with each variant's reason, and no NaN or inf in any file."""
    f = tolerance_study(tmp_path, 30, MECHANISMS / "fourbar_nongrashof_past_limit.toml", 0.01, 0.005)
    for fmt in ("csv", "parquet"):
        out = tmp_path / fmt
        code, stdout, err = cli("study", f, "--out", out, "--format", fmt, "--plot")
        assert code == 2
        line = one_line(err)
        assert "no variant completed its motion (30 stopped, 0 not assembled of 30)" in line
        assert "the first: fourbar_nongrashof_past_limit: cannot assemble" in line
        no_non_finite(stdout + err)
        assert "0 completed" in stdout and "σ" not in stdout
        assert_tables_finite(out, fmt)


def assert_tables_finite(folder: Path, fmt: str) -> None:
    """No NaN or inf in any table: CSV cells parse as finite numbers or are empty; Parquet floats null, not NaN."""
    tables = list(folder.glob(f"*.{fmt}"))
    assert tables
    for path in tables:
        if fmt == "csv":
            text = path.read_text()
            no_non_finite(text.replace("past a limit", ""))
            continue
        import pyarrow.compute as pc
        import pyarrow.parquet as pq

        t = pq.read_table(path)
        for name in t.column_names:
            col = t[name]
            if col.type in ("double", "float"):
                assert not pc.any(pc.is_nan(col)).as_py() and not pc.any(pc.is_inf(col)).as_py(), (path, name)


def test_a_study_with_some_variants_failing_prints_no_nan(tmp_path):
    """A grid where half the rocker lengths cannot close the loop: the printed lines and tables stay finite."""
    mech = write(tmp_path / "fb.toml", FOURBAR)
    study = write(
        tmp_path / "g.toml",
        f'mechanism = "{mech}"\n[[parameters]]\nname = "links.rocker.length"\nvalues = [1.0, 4.5, 5.0, 20.0]\n'
        '[[outputs]]\nquantity = "rocker.theta"\nstat = "range"\n',
    )
    code, out, err = cli("study", study, "--out", tmp_path / "o", "--format", "csv")
    assert code == 0, err
    no_non_finite(out + err)
    assert "over the completed variants" in out
    assert_tables_finite(tmp_path / "o", "csv")


def test_linearized_sigma_of_a_design_whose_neighbours_failed_is_null_not_zero():
    """σ_lin = √Σ(∂y/∂p·σ_p)²: where a derivative is unknown (NaN) the answer is unknown, never 0 (exact)."""
    from vloop.studies.study import _lin_sigma

    class P:
        sigma = np.array([0.1, 0.2])

    assert math.isnan(float(_lin_sigma(P, np.array([np.nan, 1.0]))))
    assert float(_lin_sigma(P, np.array([3.0, 4.0]))) == pytest.approx(math.hypot(0.3, 0.8), rel=1e-15)


def test_the_validation_table_says_not_finite_instead_of_inf():
    from validators.validate import _worst_text

    comp = {"engine": "pinocchio", "passed": False, "worst": {"max_abs": "inf", "allowed": 1e-9}}
    m = {"runs": {"pinocchio": {"status": "ok"}}, "comparisons": [comp]}
    assert _worst_text(m, "pinocchio") == "not finite fail"


def test_the_one_table_writer_writes_nulls_for_non_finite_numbers(tmp_path):
    pd = pytest.importorskip("pandas")
    from vloop.files.writers import write_table

    df = pd.DataFrame({"a": [1.0, math.inf, math.nan, 0.1], "s": [[1.0, math.nan], [2.0], None, [0.5]]})
    write_table(df, tmp_path / "t.csv", "csv", {"a": "m"})
    rows = (tmp_path / "t.csv").read_text().splitlines()
    assert rows == ["a,s", "m,-", "1.0,", ",[2.0]", ",", "0.1,[0.5]"]
    write_table(df, tmp_path / "t.parquet", "parquet", {"a": "m"})
    assert_tables_finite(tmp_path, "parquet")


# ---------------------------------------------------------------- 20. messages that name the real thing

MASSES = FOURBAR.replace(
    'coupler = { joints = ["A", "B"] }',
    'coupler = { joints = ["A", "B"], mass = 2.0, inertia = 0.3, com = [2.5, 3.0] }',
)


@pytest.mark.parametrize(
    ("csv", "load", "what"),
    [
        ("t,fx,fy\n0,1,2\n0.5,nan,2\n1,1,2\n", 'point = "B"',
         "profile 'load.csv' column 'fx' has a missing or non-finite value at data row 2"),
        ("t,fx,fy\n0,1,2\n0.5,1,inf\n1,1,2\n", 'point = "B"',
         "profile 'load.csv' column 'fy' has a missing or non-finite value at data row 2"),
        ("t,fx,fy\n0,1,2\n0.5,1,2\n1,1,\n", 'point = "B"', "every data row must be 3 numbers"),
        ("t,torque\n0,1\n0.5,-inf\n1,1\n", 'link = "rocker"',
         "profile 'load.csv' column 'torque' has a missing or non-finite value at data row 2"),
        ("t,fx,fy\n0,1,2\nnan,1,2\n1,1,2\n", 'point = "B"',
         "profile 'load.csv' column 't' has a missing or non-finite value at data row 2"),
    ],
)  # fmt: skip
def test_a_bad_value_in_a_load_profile_names_its_file_column_and_row(tmp_path, csv, load, what):
    (tmp_path / "load.csv").write_text(csv)
    f = write(tmp_path / "m.toml", MASSES + f'[[loads]]\n{load}\nprofile = "load.csv"\n')
    code, _, err = cli("run", f, "--out", tmp_path / "o")
    assert code == 2
    line = one_line(err)
    assert "[loads[0]]" in line and what in line and "column 'x'" not in line


def test_a_bad_value_in_a_driver_profile_names_its_column(tmp_path):
    (tmp_path / "p.csv").write_text("t,theta,omega\n0,0,1\n0.5,0.5,nan\n1,1,1\n")
    f = write(tmp_path / "m.toml", FOURBAR.replace("omega = 1.0", 'profile = "p.csv"'))
    code, _, err = cli("run", f, "--out", tmp_path / "o")
    assert code == 2 and "[drivers[0]" in (line := one_line(err))
    assert "profile 'p.csv' column 'omega' has a missing or non-finite value at data row 2" in line


@pytest.mark.parametrize(
    ("edit", "entry", "what"),
    [
        (("com = [2.5, 3.0]", "com = [1e20, 3.0]"), "[links.coupler]", "'com' = [1e+20, 3] lies 1.2e+19 times"),
        (("com = [2.5, 3.0]", "com = [2.5, -1e300]"), "[links.coupler]", "'com' = [2.5, -1e+300] lies"),
        (("[[drivers]]", '[points]\nP = { link = "coupler", at = [1e20, 0.0] }\n[[drivers]]'), "[points.P]",
         "'at' = [1e+20, 0] lies 1.2e+19 times the linkage's size away from it (8.06226 m, the span of its joints)"),
        (('coupler = { joints = ["A", "B"]', 'coupler = { joints = ["A", "B"], length = 1e20'), "[links.coupler]",
         "'length' = 1e+20 is 1.2e+19 times the linkage's size"),
        (("omega = 1.0", "theta0 = 1e20\nomega = 1.0"), "[drivers[0]", "'theta0' = 1e+20 rad cannot be resolved"),
    ],
)  # fmt: skip
def test_a_magnitude_that_cannot_be_solved_is_refused_by_its_entry(tmp_path, edit, entry, what):
    """A centre of mass at 1e20 was reported as "more freedom than its drivers fix", a tracer point at 1e20 as
    every link having zero length: each is now named, with its size against the linkage's (its joints' span)."""
    f = write(tmp_path / "m.toml", MASSES.replace(*edit))
    code, _, err = cli("run", f, "--out", tmp_path / "o")
    assert code == 2
    line = one_line(err)
    assert entry in line and what in line
    assert "freedom" not in line and "zero-length" not in line


def test_a_centre_of_mass_far_but_inside_the_limit_still_balances_the_power(tmp_path):
    """At 1e5 of the linkage's size (the limit) the force balance still closes the power balance to 1e-9 of peak
    (the independent check of tests/test_forces.py: Σ τ·ω = dT/dt)."""
    from tests.test_forces import powers
    from vloop.files.fileformat import FAR, joint_span
    from vloop.forces import solve_forces

    mech = vloop.loads(MASSES)
    span, (cx, _) = joint_span(mech)
    far = vloop.loads(MASSES.replace("com = [2.5, 3.0]", f"com = [{cx + 0.99 * FAR * span!r}, 3.0]"))
    res = vloop.solve(far)
    power, rhs = powers(far, res, solve_forces(far, res))
    assert np.max(np.abs(power - rhs)) <= 1e-9 * np.max(np.abs(power))


# ---------------------------------------------------------------- 21. Ctrl-C and output sets


def _ctrl_c(argv: list[str], delay: float, cwd: Path, out: Path) -> subprocess.CompletedProcess:
    """Run ``vloop ARGV`` in its own process group and, ``delay`` seconds after the command has started its work
    (its staging folder appeared in ``out``: Python and vloop are imported, the options parsed), send SIGINT to the
    whole group, as a terminal does on Ctrl-C."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "vloop.cli", *map(str, argv)],
        cwd=cwd,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    deadline = time.monotonic() + 60
    while proc.poll() is None and time.monotonic() < deadline and not list(out.glob(".vloop-stage-*")):
        time.sleep(0.02)
    time.sleep(delay)
    with contextlib.suppress(ProcessLookupError):
        os.killpg(proc.pid, signal.SIGINT)
    out, err = proc.communicate(timeout=180)
    return subprocess.CompletedProcess(argv, proc.returncode, out, err)


def _interrupted_study(tmp_path: Path, delays: list[float]) -> None:
    f = tolerance_study(tmp_path, 200_000)
    for k, delay in enumerate(delays):
        out = tmp_path / f"o{k}"
        r = _ctrl_c(["study", f, "--out", out, "--workers", "2"], delay, tmp_path, out)
        assert r.returncode == 130, (delay, r.stderr[-3000:])
        assert r.stderr.strip() == "vloop: interrupted (nothing half-written was left behind)", (delay, r.stderr)
        assert not out.exists() or [p.name for p in out.iterdir()] == []


def test_ctrl_c_during_a_study_on_two_workers_is_one_line(tmp_path):
    """SIGINT to the process group while the Dask workers start and run: no traceback from any worker process."""
    _interrupted_study(tmp_path, [6.0])


@pytest.mark.slow
def test_ctrl_c_during_a_study_on_two_workers_many_times(tmp_path):
    _interrupted_study(tmp_path, [0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5, 9.0, 11.0])


def _names(folder: Path) -> tuple[set, set, set]:
    """The mechanisms named by summary.json, comparisons.parquet and report.html of one folder."""
    import pyarrow.parquet as pq

    summary = {m["name"] for m in json.loads((folder / "summary.json").read_text())["mechanisms"]}
    table = set(pq.read_table(folder / "comparisons.parquet")["mechanism"].to_pylist())
    report = (folder / "report.html").read_text()
    shown = {n for n in ("fourbar_textbook_example", "slider_crank_offset") if n in report}
    return summary, table, shown


def _interrupted_validation(tmp_path: Path, delays: list[float]) -> None:
    """Yesterday's set is the textbook four-bar's; today's run (the offset slider-crank) is interrupted at several
    moments, some while it writes: the folder always holds one run's summary, table and report — never a mix."""
    out = tmp_path / "v"
    base = ["validate", "--engines", "vloop,analytic", "--out", out]
    assert main([*map(str, base), str(TEXTBOOK)]) == 0
    old = _names(out)
    assert old == ({"fourbar_textbook_example"},) * 3
    new_file = MECHANISMS / "slider_crank_offset.toml"
    seen = set()
    for delay in delays:
        r = _ctrl_c([*base, new_file], delay, tmp_path, out)
        # -2: the signal came after main() returned, as Python shuts down (a shell reports 128 + 2 = 130 too)
        assert r.returncode in (0, 130, -signal.SIGINT), r.stderr[-2000:]
        assert "Traceback" not in r.stderr, r.stderr
        if r.returncode == 130:
            assert r.stderr.strip().splitlines()[-1].startswith("vloop: interrupted"), r.stderr
            assert "Traceback" not in r.stderr, r.stderr
        now = _names(out)
        assert now in (old, ({"slider_crank_offset"},) * 3), (delay, now)
        assert not [p for p in out.iterdir() if p.name.startswith(".vloop-stage-")]
        seen.add(r.returncode)
        if now != old:
            main([*map(str, base), str(TEXTBOOK)])  # back to yesterday for the next try
    print(f"exit codes seen: {sorted(seen)}")


def test_ctrl_c_while_validate_writes_leaves_one_complete_set(tmp_path):
    _interrupted_validation(tmp_path, [0.5, 2.0])


@pytest.mark.slow
def test_ctrl_c_while_validate_writes_many_times(tmp_path):
    _interrupted_validation(tmp_path, [0.0, 0.2, 0.4, 0.6, 0.8, 1.0, 1.3, 1.6, 2.0, 2.5, 3.0, 4.0])


def test_ctrl_c_during_publishing_is_held_until_the_set_is_complete(tmp_path, monkeypatch):
    """A SIGINT that arrives while the staged files are renamed into place is raised after the last rename."""
    from vloop.files import output

    with output.OutputSet(tmp_path) as first:
        for name in ("a.txt", "b.txt", "c.txt"):
            first.write_text(name, "old")
    real = os.replace
    calls = []

    def replace(src, dst):
        calls.append(dst)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGINT)  # Ctrl-C after the first of three renames
        return real(src, dst)

    monkeypatch.setattr(output.os, "replace", replace)
    with pytest.raises(KeyboardInterrupt), output.OutputSet(tmp_path) as second:
        for name in ("a.txt", "b.txt", "c.txt"):
            second.write_text(name, "new")
    assert {p.read_text() for p in tmp_path.glob("*.txt")} == {"new"}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt", "c.txt"]


def test_a_new_set_replaces_the_previous_sets_files_it_does_not_have(tmp_path):
    """validate with a report, then --no-report --format csv: no old report.html, viewer/ or comparisons.parquet
    is left beside the new summary.json."""
    out = tmp_path / "v"
    assert main(["validate", str(TEXTBOOK), "--engines", "vloop,analytic", "--out", str(out)]) == 0
    assert {"summary.json", "comparisons.parquet", "report.html", "viewer"} <= {p.name for p in out.iterdir()}
    args = ["validate", str(TEXTBOOK), "--engines", "vloop,analytic", "--out", str(out), "--no-report"]
    assert main([*args, "--format", "csv"]) == 0
    assert sorted(p.name for p in out.iterdir()) == ["comparisons", "comparisons.csv", "summary.json"]


# ---------------------------------------------------------------- 14. the validation's printed time


def test_the_printed_time_covers_the_whole_command(tmp_path, monkeypatch):
    """The report is written after the engines: its time is in the verdict's, which covers the whole command."""
    import reports.html

    real = reports.html.write_report

    def slow_report(*a, **k):
        time.sleep(1.0)
        return real(*a, **k)

    monkeypatch.setattr(reports.html, "write_report", slow_report)
    t0 = time.perf_counter()
    code, out, _ = cli("validate", TEXTBOOK, "--engines", "vloop,analytic", "--out", tmp_path / "v")
    wall = time.perf_counter() - t0
    assert code == 0
    m = re.search(r"^all passed in ([0-9.]+) s \(engines ([0-9.]+) s; summary, tables and pages ([0-9.]+) s\)$", out,
                  re.MULTILINE)  # fmt: skip
    assert m, out
    total, engines, pages = map(float, m.groups())
    summary = json.loads((tmp_path / "v" / "summary.json").read_text())
    assert engines == pytest.approx(round(summary["seconds"], 1), abs=0.051)
    assert pages >= 1.0 and total >= engines + pages - 0.1 and total <= wall + 0.05
    assert out.strip().splitlines()[-1] == m.group(0)  # the last line: nothing is written after it


def test_no_report_does_not_mention_the_corpus_page(tmp_path):
    args = ["validate", "--corpus", "2", "--seed", "5", "--engines", "vloop,analytic", "--out", tmp_path / "v"]
    code, out, _ = cli(*args, "--no-report", "--minimize-tries", "0")
    assert code in (0, 1) and "2 of 2 mechanisms pass every comparison" in out and "corpus.html" not in out
    assert not (tmp_path / "v" / "corpus.html").exists()
    code, out, _ = cli(*args, "--minimize-tries", "0")
    assert "(per family: corpus.html)" in out and (tmp_path / "v" / "corpus.html").exists()


# ---------------------------------------------------------------- tables: CSV as well as Parquet, with units


def test_study_tables_in_csv_hold_the_parquet_numbers_with_a_units_row(tmp_path):
    pd = pytest.importorskip("pandas")
    f = tolerance_study(tmp_path, 50)
    for fmt in ("csv", "parquet"):
        assert cli("study", f, "--out", tmp_path / fmt, "--format", fmt)[0] == 0
    for name in ("variants", "summary", "sensitivity", "bands"):
        with open(tmp_path / "csv" / f"{name}.csv") as fh:
            header, units = fh.readline().strip().split(","), fh.readline().strip().split(",")
        pq = pd.read_parquet(tmp_path / "parquet" / f"{name}.parquet")
        assert header == list(pq.columns)
        csv = pd.read_csv(tmp_path / "csv" / f"{name}.csv", skiprows=[1])
        for col in pq.columns:
            if pq[col].dtype.kind == "f":
                assert np.array_equal(csv[col].to_numpy(float), pq[col].to_numpy(float), equal_nan=True), (name, col)
        unit = dict(zip(header, units, strict=True))
        if name == "variants":
            assert unit["links.l3.length"] == "mm" and unit["l4.theta.range"] == "rad" and unit["stopped_at"] == "s"
            series = json.loads(csv["l4.theta.series"][0])
            assert np.array_equal(series, pq["l4.theta.series"][0])
        if name in ("summary", "bands"):
            assert unit["nominal"] == "[unit]" and set(csv["unit"]) == {"rad"}


def test_study_json_names_half_width_and_sigma_and_units(tmp_path):
    f = tolerance_study(tmp_path, 20)
    assert cli("study", f, "--out", tmp_path / "o")[0] == 0
    params = json.loads((tmp_path / "o" / "study.json").read_text())["parameters"]
    assert params[0]["tolerance"] == {"dist": "uniform", "half_width": 0.5} and params[0]["unit"] == "mm"
    assert params[1]["tolerance"] == {"dist": "normal", "sigma": 0.3}
    assert not any("width" in p["tolerance"] for p in params)


def test_the_printed_study_summary_is_in_the_plots_units_and_says_so(tmp_path):
    """Angles in degrees (as the plots), said on a line of its own; the numbers are the table's radians × 180/π."""
    pd = pytest.importorskip("pandas")
    f = tolerance_study(tmp_path, 100)
    code, out, _ = cli("study", f, "--out", tmp_path / "o")
    assert code == 0 and "(angles in degrees, as in the plots; the tables keep radians)" in out
    m = re.search(r"l4\.theta\.range \[deg\]: nominal ([0-9.e+-]+), linearized σ ([0-9.e+-]+)", out)
    row = pd.read_parquet(tmp_path / "o" / "summary.parquet").iloc[0]
    assert float(m.group(1)) == pytest.approx(math.degrees(row["nominal"]), rel=1e-5)
    assert float(m.group(2)) == pytest.approx(math.degrees(row["linearized_sigma"]), rel=1e-3)


def test_map_axes_carry_their_units(tmp_path, monkeypatch):
    from vloop.studies import plot

    labels = []
    save = plot._save

    def keep(fig, path):
        labels.extend((path.name, ax.get_xlabel(), ax.get_ylabel()) for ax in fig.axes)
        return save(fig, path)

    monkeypatch.setattr(plot, "_save", keep)
    mech = write(tmp_path / "fb.toml", FOURBAR)
    study = write(
        tmp_path / "g.toml",
        f'mechanism = "{mech}"\n[[parameters]]\nname = "links.coupler.length"\nvalues = [4.9, 5.0, 5.1]\n'
        '[[parameters]]\nname = "drivers.crank.omega"\nvalues = [1.0, 2.0]\n'
        '[[outputs]]\nquantity = "rocker.theta"\nstat = "range"\n',
    )
    assert cli("study", study, "--out", tmp_path / "o", "--plot")[0] == 0
    maps = [x for x in labels if x[0].startswith("map_")]
    assert maps and maps[0][1] == "links.coupler.length [m]" and maps[0][2] == "drivers.crank.omega [rad/s]"


def test_validate_comparison_table_in_csv(tmp_path):
    pd = pytest.importorskip("pandas")
    from validators import harness

    code, _, _ = cli("validate", TEXTBOOK, "--engines", "vloop,analytic", "--out", tmp_path, "--no-report",
                     "--format", "csv")  # fmt: skip
    assert code == 0
    csv = pd.read_csv(tmp_path / "comparisons.csv", skiprows=[1])
    assert list(csv.columns) == list(harness.TABLE_COLUMNS) and len(csv) > 10
    units = (tmp_path / "comparisons.csv").read_text().splitlines()[1].split(",")
    unit = dict(zip(csv.columns, units, strict=True))
    assert unit["t_at_max"] == "s" and unit["ratio"] == "1" and unit["max_abs"] == "the quantity's"
    assert np.allclose(csv["ratio"], csv["max_abs"] / csv["allowed"])
