"""The layering is enforced: import-linter's contracts (pyproject.toml, [tool.importlinter]) must be kept.

One direction of flow — file → Mechanism → LoopSystem → Result → consumers → CLI — with no import
cycles between vloop's modules, validators and reports using vloop's public API only, and nothing in
vloop importing validators or reports except the CLI.
"""

from __future__ import annotations

import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).parents[1]


def test_import_contracts_are_kept():
    exe = shutil.which("lint-imports") or str(Path(sys.executable).with_name("lint-imports"))
    if not Path(exe).exists():
        pytest.skip("import-linter is not installed (pip install -e '.[dev]')")
    proc = subprocess.run([exe, "--no-cache"], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    n = len(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]["contracts"])
    assert "BROKEN" not in proc.stdout and f"Contracts: {n} kept, 0 broken." in proc.stdout


def test_the_package_shows_its_layers():
    """vloop/ holds a handful of modules; the rest live in subpackages that name their layer."""
    top = sorted(p.name for p in (ROOT / "vloop").glob("*.py"))
    packages = sorted(p.parent.name for p in (ROOT / "vloop").glob("*/__init__.py"))
    assert len(top) <= 15, top
    assert {"core", "method", "files", "views", "studies", "teaching"} <= set(packages), packages


def test_import_vloop_is_light():
    """`import vloop` loads neither the solver's heavy dependencies nor the optional engines."""
    code = (
        "import sys, vloop; heavy = [m for m in ('scipy', 'matplotlib', 'pandas', 'networkx', 'pinocchio', "
        "'exudyn', 'dask', 'pyarrow', 'jinja2') if m in sys.modules]; print(','.join(heavy))"
    )
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and out.stdout.strip() == "", out.stdout + out.stderr


def test_every_function_fits_on_a_screen():
    """No function or method in vloop/ runs past 60 lines: a long one is a sequence of named steps."""
    import ast

    long = []
    for path in sorted((ROOT / "vloop").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef) and node.end_lineno - node.lineno + 1 > 60:
                long.append(f"{path.relative_to(ROOT)}:{node.lineno} {node.name} ({node.end_lineno - node.lineno + 1})")
    assert long == [], long
