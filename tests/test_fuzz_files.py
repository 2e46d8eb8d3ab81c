"""Property-based fuzzing of every catalog file: any value replaced by 0, −0, ±1e308, 5e-324, nan, ±inf,
10**400, a string or a deeply nested array, a key removed, or a line duplicated. `vloop run` must end with
exit 0 or 2 and one line on stderr — never a traceback — and exit 0 means only finite numbers on disk.

The default budget is small for CI (VLOOP_FUZZ_EXAMPLES raises it for the nightly job).
"""

from __future__ import annotations

import math
import os
import tomllib
from pathlib import Path

import numpy as np
import tomli_w
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.conftest import MECHANISMS
from vloop.cli import main

FILES = sorted(MECHANISMS.glob("*.toml"))
NESTED: object = 0.0
for _ in range(300):
    NESTED = [NESTED]
VALUES = [0, -0.0, 1e308, -1e308, 5e-324, math.nan, math.inf, -math.inf, 10**400, "x", NESTED]
EXAMPLES = int(os.environ.get("VLOOP_FUZZ_EXAMPLES", "60"))


def leaves(node: object, path: tuple = ()) -> list[tuple]:
    """Paths to every value (and every table key) of a parsed TOML document."""
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append((*path, k))
            out += leaves(v, (*path, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out.append((*path, i))
            out += leaves(v, (*path, i))
    return out


def mutate(data: dict, path: tuple, how: str, value: object) -> None:
    node = data
    for p in path[:-1]:
        node = node[p]
    if how == "remove":
        del node[path[-1]]
    else:
        node[path[-1]] = value


@settings(
    max_examples=EXAMPLES,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.function_scoped_fixture],
)
@given(data=st.data())
def test_mutated_catalog_files_end_cleanly(data, tmp_path_factory, capsys):
    src = data.draw(st.sampled_from(FILES), label="file")
    text = src.read_text(encoding="utf-8")
    doc = tomllib.loads(text)
    kind = data.draw(st.sampled_from(["value", "value", "value", "remove", "duplicate"]), label="kind")
    tmp = tmp_path_factory.mktemp("fuzz")
    for extra in src.parent.glob(f"{src.stem}*.csv"):  # a profile beside the file
        (tmp / extra.name).write_bytes(extra.read_bytes())
    if kind == "duplicate":
        lines = text.splitlines()
        k = data.draw(st.integers(0, len(lines) - 1), label="line")
        mutated = "\n".join([*lines[: k + 1], lines[k], *lines[k + 1 :]])
    else:
        path = data.draw(st.sampled_from(leaves(doc)), label="path")
        value = data.draw(st.sampled_from(VALUES), label="value") if kind == "value" else None
        mutate(doc, path, "remove" if kind == "remove" else "set", value)
        try:
            mutated = tomli_w.dumps(doc)
        except (TypeError, ValueError, RecursionError):
            return  # not expressible as TOML: nothing for vloop to read
    f = tmp / src.name
    f.write_text(mutated, encoding="utf-8")
    out = tmp / "out"
    code = main(["run", str(f), "--out", str(out)])
    err = capsys.readouterr().err
    assert code in (0, 2), err
    assert "Traceback" not in err
    if code == 2:
        assert err.count("\n") == 1 and err.startswith("vloop: error: "), err
    if code == 0 or (out / "results.csv").exists():
        for name in ("results.csv", "health.csv"):
            # a run stopped before its first sample writes the header only: no rows
            header, *data = (out / name).read_text(encoding="utf-8").splitlines()
            rows = np.loadtxt(data, delimiter=",", ndmin=2) if data else np.empty((0, header.count(",") + 1))
            assert np.all(np.isfinite(rows)), f"{name} holds non-finite numbers after exit {code}"


def test_the_fuzzer_covers_every_catalog_file():
    assert len(FILES) >= 15 and all(leaves(tomllib.loads(f.read_text(encoding="utf-8"))) for f in FILES)
    assert Path(MECHANISMS).is_dir()
