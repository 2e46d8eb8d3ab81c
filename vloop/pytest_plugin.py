"""pytest plugin (entry point ``vloop``): tolerance checks over the mechanism catalog.

    def test_my_engine(vloop_mechanism_file, assert_histories_close):
        mech = vloop.load(vloop_mechanism_file)
        assert_histories_close(my_engine(mech), vloop.solve(mech), rtol=1e-9)

``vloop_mechanism_file`` is parametrized over every ``*.toml`` in the folder given by
``--vloop-mechanisms`` (default: ``mechanisms/`` of the working directory, else of vloop's
source tree). ``assert_histories_close`` fails with the quantity, the time and how far off.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from .compare import assert_histories_close as _assert_histories_close


def pytest_addoption(parser: pytest.Parser) -> None:
    parser.addoption(
        "--vloop-mechanisms", default=None, help="folder of mechanism files for the vloop_mechanism_file fixture"
    )


def catalog(folder: str | Path | None = None) -> list[Path]:
    """Mechanism files of ``folder`` (default: ./mechanisms, else vloop's source tree's)."""
    roots = (
        [Path(folder)] if folder else [Path.cwd() / "mechanisms", Path(__file__).resolve().parents[1] / "mechanisms"]
    )
    for root in roots:
        files = sorted(root.glob("*.toml"))
        if files:
            return files
    return []


def pytest_generate_tests(metafunc: pytest.Metafunc) -> None:
    if "vloop_mechanism_file" in metafunc.fixturenames:
        files = catalog(metafunc.config.getoption("--vloop-mechanisms"))
        metafunc.parametrize("vloop_mechanism_file", files, ids=[f.stem for f in files])


@pytest.fixture
def assert_histories_close():
    """vloop.compare.assert_histories_close(a, b, rtol, ...), as a fixture."""
    return _assert_histories_close
