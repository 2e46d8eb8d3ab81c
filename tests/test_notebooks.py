"""Notebooks: the example notebooks in docs/ run, and every result type shows itself in a notebook.

* docs/lecture_fourbar.ipynb, docs/design_study.ipynb and docs/dynamics.ipynb (the flywheel example of
  docs/dynamics.md: the textbook's ΔE by kinetostatics against the equation of motion) are stored without outputs and executed here by the
  command docs/notebooks.md gives (nbconvert, a real kernel); each asserts its own numbers against formulas
  written out in its cells (Norton's closed form, the velocity loop, the instant centre as a line intersection,
  the transmission angle by the law of cosines, the power balance, the crank-rocker's extreme transmission
  angles, Monte-Carlo against the linearized σ), so a notebook that runs is a notebook whose numbers were
  checked. The command that opens one (JupyterLab) is installed with the notebooks extra.
* ``_repr_html_`` of Mechanism, Result, ForceResult and StudyResult: an HTML table whose numbers are the data's
  (ranges against numpy's min and max, Gruebler's M of the paper's eight-bar), every name escaped.
* ``Result.to_pandas()``: the columns and their units (angles rad, lengths the file's).
"""

from __future__ import annotations

import importlib.util
import json
import re
import shlex
import subprocess
import sys
import time
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

import vloop

from .conftest import MECHANISMS, ROOT

NOTEBOOKS = sorted((ROOT / "docs").glob("*.ipynb"))


def test_the_three_notebooks_are_stored_without_outputs() -> None:
    assert {p.name for p in NOTEBOOKS} == {"lecture_fourbar.ipynb", "design_study.ipynb", "dynamics.ipynb"}
    for path in NOTEBOOKS:
        nb = json.loads(path.read_text(encoding="utf-8"))
        for cell in nb["cells"]:
            if cell["cell_type"] == "code":
                assert cell["outputs"] == [] and cell["execution_count"] is None, path.name
            assert "execution" not in cell.get("metadata", {}), path.name


def _documented_commands() -> tuple[list[str], list[str]]:
    """The two lines of docs/notebooks.md's shell block: (run the notebooks, open the lecture)."""
    page = (ROOT / "docs" / "notebooks.md").read_text(encoding="utf-8")
    blocks = re.findall(r"```sh\n(.*?)```", page, flags=re.S)
    assert len(blocks) == 1, "docs/notebooks.md: one shell block with the two commands"
    run, open_ = (shlex.split(line) for line in blocks[0].strip().splitlines())
    return run, open_


def test_the_documented_commands_run_the_notebooks_and_their_checks(tmp_path: Path) -> None:
    """docs/notebooks.md's first command (nbconvert, a real kernel) executes every notebook; each asserts its
    own numbers against formulas written out in its cells, so a notebook that runs is one whose numbers were
    checked. The outputs it writes hold what the cells print."""
    pytest.importorskip("nbconvert", reason="pip install -e '.[notebooks]'")
    pytest.importorskip("ipykernel", reason="pip install -e '.[notebooks]'")
    run, _ = _documented_commands()
    assert run[:4] == ["jupyter", "nbconvert", "--to", "notebook"] and run[-2:] == ["--output-dir", "out/notebooks"]
    assert sorted(run[5:-2]) == sorted(f"docs/{p.name}" for p in NOTEBOOKS)
    exe = Path(sys.executable).with_name("jupyter")
    start = time.perf_counter()
    proc = subprocess.run([str(exe), *run[1:-1], str(tmp_path)], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]  # a failing cell (its asserts included) is named here
    seconds = time.perf_counter() - start
    for path in NOTEBOOKS:
        nb = json.loads((tmp_path / path.name).read_text(encoding="utf-8"))
        outputs = [o for c in nb["cells"] for o in c.get("outputs", [])]
        text = "".join("".join(o.get("text", "")) for o in outputs if o["output_type"] == "stream")
        html = "".join("".join(o.get("data", {}).get("text/html", "")) for o in outputs if "data" in o)
        if path.stem == "lecture_fourbar":
            assert "by hand: θ3 = 20.2979°, θ4 = 57.3249°" in text and "power balance" in text
            assert 'sandbox="allow-scripts"' in html and "<b>Result</b>" in html and "<b>ForceResult</b>" in html
        elif path.stem == "dynamics":
            assert "ΔE = 1.6467" in text and "simulated: I = " in text
        else:
            assert "rocker swing: nominal" in text and "StudyResult(" in html
    print(f"the notebooks: {seconds:.1f} s")  # with the kernels' start


def test_the_documented_front_end_is_installed() -> None:
    """docs/notebooks.md's second command opens a notebook in JupyterLab: its front end and its command are
    installed with the notebooks extra (the server itself is not started here)."""
    if importlib.util.find_spec("jupyterlab") is None:
        pytest.skip("pip install -e '.[notebooks]'")
    _, open_ = _documented_commands()
    assert open_[:2] == ["jupyter", "lab"] and (ROOT / open_[2]).is_file()
    assert Path(sys.executable).with_name("jupyter-lab").is_file()  # what `jupyter lab` runs


# ---------------------------------------------------------------- rich display


class _Tags(HTMLParser):
    """Checks tags are balanced and collects the text of every cell."""

    VOID = frozenset({"br", "hr", "img", "meta", "input", "link"})

    def __init__(self) -> None:
        super().__init__()
        self.stack: list[str] = []
        self.cells: list[str] = []

    def handle_starttag(self, tag: str, attrs: list) -> None:
        if tag not in self.VOID:
            self.stack.append(tag)
        if tag in ("td", "th"):
            self.cells.append("")

    def handle_endtag(self, tag: str) -> None:
        assert self.stack and self.stack.pop() == tag, (tag, self.stack)

    def handle_data(self, data: str) -> None:
        if self.stack and self.stack[-1] in ("td", "th"):
            self.cells[-1] += data


def _parse(html: str) -> list[str]:
    tags = _Tags()
    tags.feed(html)
    tags.close()
    assert tags.stack == []
    return tags.cells


def test_a_mechanism_shows_its_bodies_and_mobility() -> None:
    mech = vloop.load(MECHANISMS / "eightbar.toml")
    html = mech._repr_html_()
    cells = _parse(html)
    assert "L = 8 bodies, J = 10 joints, Gruebler M = 1" in html  # the paper: L = 8, J = 10, M = 1
    assert {"l2", "l3", "l5", "l7", "l4", "l6", "l8"} <= set(cells) and "length 6.15" in cells
    watt = vloop.load(MECHANISMS / "sixbar_watt2_dimensions.toml")._repr_html_()
    assert "written from dimensions" in watt and "sides 4, 3, angle -2.26893 rad" in _parse(watt)


def test_a_result_shows_each_quantity_s_range() -> None:
    mech = vloop.load(MECHANISMS / "whitworth_quick_return.toml")
    res = vloop.solve(mech)
    cells = _parse(res._repr_html_())
    i = next(i for i in range(len(cells) - 1) if cells[i : i + 2] == ["l6", "slider"])  # (l6 is also a block's θ)
    s = res["l6.s"]
    assert cells[i + 2] == f"s {s.min():.4g} … {s.max():.4g} mm"
    w = res["l4.omega"]
    assert f"omega {w.min():.4g} … {w.max():.4g} rad/s" in cells
    speed = np.hypot(res["C.vx"], res["C.vy"]).max()
    assert f"|v| ≤ {speed:.4g} mm/s" in cells


def test_forces_and_study_results_show_their_tables() -> None:
    mech = vloop.load(MECHANISMS / "fourbar_textbook_dynamics.toml")
    forces = vloop.solve_forces(mech, vloop.solve(mech))
    cells = _parse(forces._repr_html_())
    i = cells.index("l2.torque")
    assert cells[i + 1] == "N·m" and float(cells[i + 2]) == pytest.approx(forces["l2.torque"].min(), rel=1e-5)
    assert "O2:ground>l2.fx" in cells and cells[cells.index("O2:ground>l2.fx") + 1] == "N"
    study = vloop.study(
        mech,
        [{"name": "links.l3.length", "tolerance": {"dist": "uniform", "half_width": 0.5}}],
        ["l4.theta.range"],
        samples=8,
        seed=1,
        times=mech.times[:30],
    )
    cells = _parse(study._repr_html_())
    assert cells[cells.index("links.l3.length") + 1 : cells.index("links.l3.length") + 4] == [
        "mm",
        "120",
        "uniform ± 0.5",
    ]


def test_hostile_names_and_titles_stay_text() -> None:
    text = (MECHANISMS / "fourbar_textbook_example.toml").read_text(encoding="utf-8")
    text = re.sub(r'^title = ".*"$', 'title = "<script>alert(1)</script> & <b>"', text, flags=re.M)
    mech = vloop.loads(text, source="<x>")
    res = vloop.solve(mech, times=mech.times[:5])
    assert "&lt;script&gt;alert(1)&lt;/script&gt; &amp; &lt;b&gt;" in mech._repr_html_()
    for html in (mech._repr_html_(), res._repr_html_()):
        assert "<script>" not in html
        _parse(html)


def test_to_pandas_has_every_column_and_its_unit() -> None:
    mech = vloop.load(MECHANISMS / "whitworth_quick_return.toml")  # millimetres
    res = vloop.solve(mech, times=mech.times[:20])
    df = res.to_pandas()
    assert list(df.columns) == ["t", *res.columns] and np.array_equal(df["l6.v"].to_numpy(), res["l6.v"])
    units = df.attrs["units"]
    assert units["t"] == "s" and units["l4.theta"] == "rad" and units["l4.omega"] == "rad/s"
    assert units["l4.alpha"] == "rad/s^2" and units["C.x"] == "mm" and units["C.vy"] == "mm/s"
    assert units["C.ax"] == "mm/s^2" and units["l6.s"] == "mm" and units["l6.a"] == "mm/s^2"
    assert vloop.Result.to_dataframe is vloop.Result.to_pandas
    bare = vloop.Result("m", "csv", res.t, dict(res.columns))  # a Result that does not know its units
    assert bare.to_pandas().attrs["units"]["C.x"] == "L" and bare.to_pandas(length="in").attrs["units"]["C.x"] == "in"


def test_to_pandas_converts_lengths_and_leaves_angles() -> None:
    """A run in millimetres asked for metres: positions, velocities and accelerations × 0.001 (and back to mm
    × 1000, to inches ÷ 25.4), angles and their rates untouched; an unknown unit refused, naming it."""
    mech = vloop.load(MECHANISMS / "whitworth_quick_return.toml")  # millimetres
    res = vloop.solve(mech, times=mech.times[:20])
    metres, inches = res.to_pandas(length="m"), res.to_pandas(length="in")
    for col in ("C.x", "C.vy", "C.ax", "l6.s", "l6.v", "l6.a"):
        assert np.array_equal(metres[col].to_numpy(), res[col] * 0.001), col  # 1 mm = 0.001 m exactly as written
        assert np.allclose(inches[col].to_numpy(), res[col] / 25.4, rtol=1e-15, atol=0), col  # 1 in = 25.4 mm
    for col in ("t", "l4.theta", "l4.omega", "l4.alpha"):
        assert np.array_equal(metres[col].to_numpy(), res.t if col == "t" else res[col]), col
    assert metres.attrs["units"]["C.vy"] == "m/s" and metres.attrs["units"]["l4.omega"] == "rad/s"
    assert np.array_equal(res.to_pandas(length="mm")["C.x"].to_numpy(), res["C.x"])  # its own units: as they are
    with pytest.raises(ValueError, match="'furlong' is not a length unit vloop knows"):
        res.to_pandas(length="furlong")
