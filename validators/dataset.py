"""The comparison dataset: one Parquet file per task (one mechanism), written by the worker that ran it, read by
streaming.

    DATASET/family=fourbar/000123.parquet         # task 123: every comparison of one mechanism, sample by sample

Rows: one per comparison and sample — ``task``, ``mechanism``, ``engine``, ``reference``, ``sample``, ``t`` [s], and
per quantity group ``err_<group>``: the largest |a − b| of the group's quantities at that sample over the group's
peak over the run (float32; angles modulo 2π; null where the comparison has no quantity of the group). Each file's
key-value metadata holds the mechanism's summary entry (``vloop.entry``: JSON, every quantity's worst figures, its
runs and verdict) and, when the report will show it, nothing more: the Results stay with the worker.

A file appears complete or not at all: written under a hidden name in its folder (which the dataset readers skip)
and renamed into place. A task is done exactly when its file exists, so a resumed run skips it, and a task that
runs again (its worker was lost) replaces it under the same name: every mechanism is in the dataset once.
Read with :func:`entries` (one entry at a time, in task order) or :func:`table` (pyarrow.dataset, by columns).
"""

from __future__ import annotations

import json
import os
import uuid
from collections.abc import Iterable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

from vloop.compare import error_series, group_of

GROUPS = ("angle", "angular velocity", "angular acceleration", "position", "velocity", "acceleration")
GROUPS += ("force", "moment")
ENTRY_KEY = b"vloop.entry"
TASK_DIGITS = 6


def column(group: str) -> str:
    """The dataset's column for a quantity group: ``err_angular_velocity``."""
    return "err_" + group.replace(" ", "_")


def schema() -> Any:
    import pyarrow as pa

    fields = [
        ("task", pa.int64()),
        ("mechanism", pa.string()),
        ("engine", pa.string()),
        ("reference", pa.string()),
        ("sample", pa.int32()),
        ("t", pa.float64()),
    ]
    return pa.schema(fields + [(column(g), pa.float32()) for g in GROUPS])


def task_path(root: Path, task: int, family: str) -> Path:
    """Where task ``task``'s file goes: ``root/family=FAMILY/000123.parquet``."""
    safe = "".join(ch if ch.isalnum() or ch in "-_" else "-" for ch in family) or "catalog"
    return Path(root) / f"family={safe}" / f"{task:0{TASK_DIGITS}d}.parquet"


def sample_columns(task: int, name: str, pairs: Iterable[tuple[str, str, Any, Any, int]]) -> dict[str, np.ndarray]:
    """The rows of one mechanism as columns: for each (engine, reference, Result a, Result b, n) compared on its
    first n samples, one row per sample with each group's largest |a − b| over the group's peak."""
    cols: dict[str, list[np.ndarray]] = {k: [] for k in schema().names}
    for engine, reference, a, b, n in pairs:
        shared = [c for c in b.columns if c in a.columns and _group(c) in GROUPS]
        errs = {g: np.full(n, np.nan) for g in GROUPS}
        peaks = dict.fromkeys(GROUPS, 0.0)
        for c in shared:
            g = _group(c)
            peaks[g] = max(peaks[g], float(np.max(np.abs(np.asarray(b[c][:n], float)), initial=0.0)))
        for c in shared:
            g = _group(c)
            e = error_series(a, b, c, n) / (peaks[g] if peaks[g] > 0 else 1.0)
            errs[g] = np.fmax(errs[g], np.where(np.isfinite(e), e, np.inf))
        cols["task"].append(np.full(n, task, np.int64))
        cols["mechanism"].append(np.full(n, name, object))
        cols["engine"].append(np.full(n, engine, object))
        cols["reference"].append(np.full(n, reference, object))
        cols["sample"].append(np.arange(n, dtype=np.int32))
        cols["t"].append(np.asarray(b.t[:n], float))
        for g in GROUPS:
            cols[column(g)].append(errs[g].astype(np.float32))
    return {k: (np.concatenate(v) if v else np.zeros(0)) for k, v in cols.items()}


def _group(col: str) -> str:
    try:
        return group_of(col)
    except (KeyError, ValueError):
        return ""


def write_task(root: Path, task: int, family: str, columns: dict[str, np.ndarray], entry: dict[str, Any]) -> Path:
    """Write one task's file atomically (hidden name, then renamed into place); returns its path."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    path = task_path(root, task, family)
    path.parent.mkdir(parents=True, exist_ok=True)
    sch = schema().with_metadata({ENTRY_KEY: json.dumps(entry, allow_nan=False).encode()})
    arrays = [pa.array(columns[f.name], type=f.type, from_pandas=True) for f in schema()]
    tmp = path.parent / f".{path.stem}-{uuid.uuid4().hex[:8]}.tmp"
    try:
        pq.write_table(pa.Table.from_arrays(arrays, schema=sch), tmp, compression="zstd")
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def done(root: Path) -> dict[int, Path]:
    """The tasks whose files are on disk (a resumed run skips them): task number -> file."""
    root = Path(root)
    if not root.is_dir():
        return {}
    out = {}
    for path in root.glob("family=*/*.parquet"):
        if path.stem.isdigit():
            out[int(path.stem)] = path
    return out


def read_entry(path: Path) -> dict[str, Any]:
    """A task's summary entry, from its file's metadata (the rows are not read)."""
    import pyarrow.parquet as pq

    meta = pq.read_schema(path).metadata or {}
    return json.loads(meta[ENTRY_KEY])


def entries(files: Iterable[Path]) -> Iterator[dict[str, Any]]:
    """The entries of ``files`` one at a time (memory: one entry)."""
    for path in files:
        yield read_entry(path)


def table(root: Path, columns: list[str] | None = None, filter: Any = None) -> Any:
    """The rows (those of ``filter``, a pyarrow.dataset expression) as one Arrow table, by streaming over the files."""

    return dataset(root).to_table(columns=columns, filter=filter)


def dataset(root: Path) -> Any:
    """The files under ``root`` as one pyarrow dataset (hive partitioning by family; hidden files skipped)."""
    import pyarrow.dataset as ds

    return ds.dataset(str(root), format="parquet", partitioning="hive", schema=_with_family())


def _with_family() -> Any:
    import pyarrow as pa

    return schema().append(pa.field("family", pa.string()))
