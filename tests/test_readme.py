"""The README works as written: its commands, its Python, its mechanism file and its links.

Every fenced ``sh`` block of README.md is split into commands (one a line; ``a && b`` is two) and each runs in
a fresh temporary folder holding copies of the catalog, the example studies and the documentation sources,
against this checkout: ``vloop`` and ``python`` on the PATH are this interpreter with this checkout first on
its path. The output files the README names (``out/...``, ``validation/...``, ``site/...``) must then exist.
Three set-up commands cannot run here and are checked instead:

- ``python3 -m venv .venv`` and ``. .venv/bin/activate`` make the environment these tests already run in;
- ``pip install -e ".[all]"`` needs the network: every requirement of the extra it names (and of the extras
  that one pulls in) must be installed here at a version it accepts;
- ``python -m pytest -q`` is the command running this test: `.ci/run` must run the README's set-up lines
  exactly as written.

Every ``python`` block runs as a script in the same folder; every ``toml`` block must load to the mechanism
of the catalog file the README names just before it (name and title aside).
"""

from __future__ import annotations

import os
import re
import shlex
import shutil
import stat
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

import vloop
from vloop.files.fileformat import to_dict

ROOT = Path(__file__).parents[1]
README = ROOT / "README.md"
COPIED = ("mechanisms", "studies", "docs", "mkdocs.yml")  # what the README's commands read
ENVIRONMENT = {"python3 -m venv .venv", ". .venv/bin/activate"}
TEST_COMMAND = "python -m pytest -q"


def _blocks(lang: str) -> list[tuple[int, str]]:
    """(offset, text) of each fenced block of the language."""
    text = README.read_text(encoding="utf-8")
    return [(m.start(), m.group(1)) for m in re.finditer(rf"^```{lang}\n(.*?)^```\n", text, re.S | re.M)]


def _shown_output(offset: int) -> str | None:
    """The ``text`` block right after the sh block at ``offset`` (what its last command prints), if any."""
    text = README.read_text(encoding="utf-8")
    lines = r"((?:(?!```)[^\n]*\n)*)"  # lines up to the closing fence
    block = re.compile(rf"```sh\n{lines}```\n\s*```text\n{lines}```").match(text, offset)
    return block.group(2) if block else None


NUMBER = r"[-+]?\d+(\.\d+)?(e[-+]?\d+)?"
ROUNDOFF = 1e-4  # a figure below it (a difference as a fraction of a tolerance) is round-off: machines differ
CLOSE = 0.10  # larger figures: the README's within 10 % of the printed ones


def _numbers_out(text: str) -> str:
    """The text with every number replaced by # (its layout)."""
    return re.sub(NUMBER, "#", text)


def _figures_agree(shown: str, printed: str) -> bool:
    """The README's figure against the printed one: both round-off (≤ ROUNDOFF), or within CLOSE of each other."""
    a, b = float(shown), float(printed)
    return (abs(a) <= ROUNDOFF and abs(b) <= ROUNDOFF) or abs(a - b) <= CLOSE * max(abs(a), abs(b))


def _shown_line_printed(line: str, printed: str) -> bool:
    """A line of the README's output is printed: a printed line of the same layout whose every number agrees."""
    numbers = [m.group(0) for m in re.finditer(NUMBER, line)]
    for candidate in printed.splitlines():
        if _numbers_out(candidate.strip()) == _numbers_out(line.strip()):
            got = [m.group(0) for m in re.finditer(NUMBER, candidate)]
            if all(_figures_agree(a, b) for a, b in zip(numbers, got, strict=True)):
                return True
    return False


def _lines(block: str | None = None) -> list[str]:
    """Every command line of one sh block (default: of them all), continuation lines joined."""
    lines = []
    for b in [block] if block is not None else [b for _, b in _blocks("sh")]:
        for line in b.replace("\\\n", " ").splitlines():
            if line.strip() and not line.lstrip().startswith("#"):
                lines.append(line.strip())
    return lines


def _commands(block: str | None = None) -> list[str]:
    return [part.strip() for line in _lines(block) for part in line.split(" && ")]


def _runnable(block: str | None = None) -> list[str]:
    skip = (*ENVIRONMENT, TEST_COMMAND)
    return [c for c in _commands(block) if c not in skip and not c.startswith("pip ")]


def _shims(folder: Path) -> dict[str, str]:
    """An environment whose `vloop` and `python` are this interpreter with this checkout first on its path."""
    folder.mkdir()
    for name, run in (("vloop", "-m vloop.cli"), ("python", ""), ("python3", "")):
        path = folder / name
        path.write_text(f'#!/bin/sh\nexec {shlex.quote(sys.executable)} {run} "$@"\n')
        path.chmod(path.stat().st_mode | stat.S_IXUSR)
    pythonpath = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH")) if p)
    # the site's notebooks are executed by tests/test_docs.py's build: this one builds it without running them
    return {
        **os.environ,
        "PATH": f"{folder}{os.pathsep}{os.environ['PATH']}",
        "PYTHONPATH": pythonpath,
        "VLOOP_DOCS_EXECUTE": "false",
    }


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> tuple[Path, dict[str, str]]:
    base = tmp_path_factory.mktemp("readme")
    work = base / "work"
    work.mkdir()
    for name in COPIED:
        src = ROOT / name
        (shutil.copytree if src.is_dir() else shutil.copy2)(src, work / name)
    return work, _shims(base / "bin")


def test_the_readme_has_its_set_up_and_tour():
    commands = _commands()
    assert any(c.startswith("pip install") for c in commands) and TEST_COMMAND in commands
    assert len(_runnable()) >= 5, _runnable()


def test_every_command_runs_as_written(workdir):
    """Each command exits 0 without a traceback; where the README shows what a block prints, its last command
    prints those lines, every figure equal to the printed one where both are round-off (≤ 1e-4 of a tolerance)
    and within 10 % otherwise; the files the README names are written."""
    work, env = workdir
    for offset, block in _blocks("sh"):
        stdout = ""
        for command in _runnable(block):
            proc = subprocess.run(
                ["/bin/sh", "-c", command], cwd=work, env=env, capture_output=True, text=True, timeout=600
            )
            assert proc.returncode == 0, f"{command}\n{proc.stdout[-2000:]}\n{proc.stderr[-2000:]}"
            assert "Traceback" not in proc.stderr, f"{command}\n{proc.stderr[-2000:]}"
            stdout = proc.stdout
        shown = _shown_output(offset)
        if shown is not None and shown.strip() != "...":
            for line in shown.splitlines():
                if line.strip() and line.strip() != "...":
                    assert _shown_line_printed(line, stdout), f"{command} no longer prints\n{line}\n---\n{stdout}"
    text = README.read_text(encoding="utf-8")
    promised = set(re.findall(r"`((?:out|validation|site)/[^`\s]+)`", text))
    assert promised, "the README names no output file"
    missing = sorted(p for p in promised if not (work / p).exists())
    assert not missing, f"the README's commands did not write {missing}"


def _files(folder: Path) -> set[Path]:
    return {p.relative_to(folder) for p in folder.rglob("*") if p.is_file()}


def test_every_python_block_runs(workdir):
    """Each block runs, and writes only under out/ (which git ignores): nothing lands in the checkout's root."""
    work, env = workdir
    assert "out/" in (ROOT / ".gitignore").read_text(encoding="utf-8").splitlines()
    for i, (_, code) in enumerate(_blocks("python")):
        script = work / f"readme_{i}.py"
        script.write_text(code, encoding="utf-8")
        before = _files(work)
        proc = subprocess.run(
            [sys.executable, script.name], cwd=work, env=env, capture_output=True, text=True, timeout=300
        )
        assert proc.returncode == 0, f"{code}\n{proc.stderr[-3000:]}"
        written = _files(work) - before - {Path(script.name)}
        assert written and all(p.parts[0] == "out" for p in written), sorted(written)


def test_every_mechanism_file_is_the_catalogs():
    text = README.read_text(encoding="utf-8")
    blocks = _blocks("toml")
    assert blocks
    for offset, block in blocks:
        named = re.findall(r"`(mechanisms/[\w.-]+\.toml)`", text[:offset])
        assert named, "a TOML block of the README must follow the name of the catalog file it shows"
        shown, catalog = to_dict(vloop.loads(block)), to_dict(vloop.load(ROOT / named[-1]))
        for key in ("name", "title"):
            shown.pop(key, None), catalog.pop(key, None)
        assert shown == catalog, named[-1]


def _requirements(extra: str, project: dict) -> list[str]:
    """The requirements an install of `.[extra]` brings: the dependencies and the extra's, self-references
    (vloop[a,b]) expanded."""
    from packaging.requirements import Requirement

    out = list(project["dependencies"])
    todo, seen = [extra], set()
    while todo:
        name = todo.pop()
        if name in seen:
            continue
        seen.add(name)
        assert name in project["optional-dependencies"], f"the README installs an extra pyproject.toml lacks: {name}"
        for req in project["optional-dependencies"][name]:
            r = Requirement(req)
            if r.name == project["name"]:
                todo.extend(r.extras)
            else:
                out.append(req)
    return out


def test_the_install_command_gives_this_environment():
    """The README's install needs the network; what it would install is checked against this environment."""
    from packaging.requirements import Requirement

    installs = [c for c in _commands() if c.startswith("pip ")]
    assert len(installs) == 1, installs
    words = shlex.split(installs[0])
    assert words[:3] == ["pip", "install", "-e"] and len(words) == 4, words
    target = re.fullmatch(r"\.\[([\w,-]+)\]", words[3])
    assert target, words[3]
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    wrong = []
    for extra in target.group(1).split(","):
        for req in map(Requirement, _requirements(extra, project)):
            try:
                version = metadata.version(req.name)
            except metadata.PackageNotFoundError:
                wrong.append(f"{req} is not installed")
                continue
            if not req.specifier.contains(version, prereleases=True):
                wrong.append(f"{req}: {version} is installed")
    assert not wrong, "; ".join(wrong)


def test_ci_runs_the_set_up_as_written():
    """`.ci/run` runs each line of the README's set-up block unchanged, the test command last."""
    ci = [line.strip() for line in (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()]
    setup = [line for line in _lines() if line.startswith("python3 -m venv") or line == TEST_COMMAND]
    assert len(setup) == 2, setup
    for line in setup:
        assert line in ci, f".ci/run does not run the README's {line!r}"
    assert ci.index(setup[0]) < ci.index(TEST_COMMAND)


def test_every_link_resolves():
    text = README.read_text(encoding="utf-8")
    for target in re.findall(r"\]\(([^)\s]+)\)", text):
        if "://" in target:
            continue
        path = target.split("#")[0]
        assert (ROOT / path).exists(), target
        if "#" in target and path.endswith(".md"):
            heading = target.split("#")[1]
            headings = re.findall(r"^#+ (.+)$", (ROOT / path).read_text(encoding="utf-8"), re.M)
            slugs = {re.sub(r"[-\s]+", "-", re.sub(r"[^\w\s-]", "", h).strip().lower()) for h in headings}
            assert heading in slugs, target
