"""Every table vloop writes: a run's results streamed to disk chunk by chunk (``results.{csv,parquet,npz}``,
``health.{...}``), and whole tables (a study's, a validation's comparisons: :func:`write_table`).

Every file is staged by an :class:`vloop.files.output.OutputSet` and published with the others when the
run ends (complete, or stopped by a limit position with its rows so far): nothing half-written ever
appears, and Ctrl-C leaves the previous complete set (or nothing).

* ``csv``: one row per sample, ``t`` then the columns, every number the shortest text that reads back
  to the same double (:func:`vloop.result.write_csv`; float32 health columns to the same float32).
* ``parquet`` (needs pyarrow, ``pip install vloop[parquet]``): one row group per chunk, float64
  columns; each field's unit in its metadata (``unit``) and all of them as JSON under the schema
  metadata key ``vloop.units``.
* ``npz``: one float64 array per column (``np.load(path)["l3.theta"]``), ``t`` included.

A whole table (:func:`write_table`, a pandas DataFrame) is Parquet or CSV. Parquet: as above, each field's
unit in its metadata. CSV: a header row, then a units row (``-`` where a column has no unit: a count, a
flag, text), then one row per record; numbers as the shortest text that reads back to the same double, list
cells (a series, a path) as JSON arrays, booleans ``true``/``false``. In both, a number that is not finite
(a motion that did not complete, a spread of fewer than two draws, an error that overflowed) is a null — an
empty cell — never NaN or inf.

Health is compact: one row per sample with ``t``, ``health.residual`` and ``health.cond`` as float32
(7 significant digits: they are diagnostics), ``health.branch`` (integer signature of the assembly
branches) and the flags ``health.ill_conditioned`` and ``health.change_point`` (0/1). It does not
repeat the results' columns.
"""

from __future__ import annotations

import json
import shutil
import zipfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np

from ..result import Result, arrow_array, column_units, write_csv
from .output import OutputError, OutputSet, atomic_write

FORMATS = ("csv", "parquet", "npz")
HEALTH = (("residual", np.float32), ("cond", np.float32), ("branch", np.int64))
FLAGS = ("ill_conditioned", "change_point")
CSV_BYTES = 24  # per value, an upper estimate of a full-precision decimal and its comma




def health_columns(res: Result) -> dict[str, np.ndarray]:
    """The compact health table of a chunk (see the module docstring)."""
    out: dict[str, np.ndarray] = {"t": res.t}
    n = len(res.t)
    for name, dtype in HEALTH:
        out[f"health.{name}"] = np.asarray(res.health.get(name, np.zeros(n)), dtype)
    for name in FLAGS:
        out[f"health.{name}"] = np.asarray(res.health.get(name, np.zeros(n)), np.int8)
    return out


class _Table:
    """One streamed table (results or health) in one format."""

    def __init__(self, outset: OutputSet, name: str, fmt: str, names: list[str], units_: dict[str, str], meta: dict):
        self.fmt, self.names, self.units, self.meta = fmt, names, units_, meta
        self.name = f"{name}.{fmt}"
        self.path = outset.path(self.name)
        self.rows = 0
        self._fh: IO[Any] | None = None
        self._pq: Any = None
        self._cols: list[IO[Any]] = []
        self._dtypes: list[np.dtype] = []
        try:
            if fmt == "csv":
                self._fh = open(self.path, "wb")  # closed in close()
                self._fh.write((",".join(names) + "\n").encode())
            elif fmt == "npz":
                raw = [self.path.with_name(f"{self.path.name}.{i}.raw") for i in range(len(names))]
                self._cols = [open(r, "wb") for r in raw]  # one file per column, assembled in close()
        except OSError as exc:
            raise OutputError(f"cannot write {outset.folder / self.name}: {exc.strerror}", entry="out") from None
        self.folder_name = outset.folder / self.name

    def write(self, cols: dict[str, np.ndarray]) -> None:
        try:
            getattr(self, f"_write_{self.fmt}")(cols)
        except OSError as exc:
            raise OutputError(f"cannot write {self.folder_name}: {exc.strerror}", entry="out") from None
        self.rows += len(cols["t"])

    def _write_csv(self, cols: dict[str, np.ndarray]) -> None:
        write_csv(self._fh, None, [cols[n] for n in self.names])

    def _write_parquet(self, cols: dict[str, np.ndarray]) -> None:
        import pyarrow as pa
        import pyarrow.parquet as pq

        arrays = [arrow_array(cols[n]) for n in self.names]
        if self._pq is None:
            fields = [
                pa.field(n, a.type, metadata={"unit": self.units[n]}) for n, a in zip(self.names, arrays, strict=True)
            ]
            self._pq = pq.ParquetWriter(self.path, pa.schema(fields, metadata=_metadata(self.units, self.meta)))
        self._pq.write_table(pa.Table.from_arrays(arrays, schema=self._pq.schema))

    def _write_npz(self, cols: dict[str, np.ndarray]) -> None:
        if not self._dtypes:
            self._dtypes = [cols[n].dtype for n in self.names]
        for fh, n in zip(self._cols, self.names, strict=True):
            np.ascontiguousarray(cols[n]).tofile(fh)

    def close(self) -> None:
        """Finish the file (Parquet footer; NPZ archive assembled from the column files)."""
        try:
            if self._fh is not None:
                self._fh.close()
            if self.fmt == "parquet":
                if self._pq is None:  # no row at all: an empty table with the schema
                    self._write_parquet({n: np.zeros(0) for n in self.names})
                self._pq.close()
            if self.fmt == "npz":
                self._assemble_npz()
        except OSError as exc:
            raise OutputError(f"cannot write {self.folder_name}: {exc.strerror}", entry="out") from None

    def _assemble_npz(self) -> None:
        for fh in self._cols:
            fh.close()
        dtypes = self._dtypes or [np.dtype(float)] * len(self.names)
        with zipfile.ZipFile(self.path, "w", zipfile.ZIP_STORED, allowZip64=True) as zf:
            for i, (n, dt) in enumerate(zip(self.names, dtypes, strict=True)):
                raw = self.path.with_name(f"{self.path.name}.{i}.raw")
                with zf.open(f"{n}.npy", "w", force_zip64=True) as out, open(raw, "rb") as src:
                    header = {"descr": np.lib.format.dtype_to_descr(dt), "fortran_order": False, "shape": (self.rows,)}
                    np.lib.format.write_array_header_2_0(out, header)
                    shutil.copyfileobj(src, out, 1 << 20)
                raw.unlink()


def _metadata(units_: dict[str, str], meta: dict) -> dict[str, str]:
    """A Parquet file's schema metadata: every column's unit, and the table's own facts (JSON values)."""
    return {"vloop.units": json.dumps(units_), **{f"vloop.{k}": json.dumps(v) for k, v in meta.items()}}


TABLE_FORMATS = ("csv", "parquet")
CSV_ROWS = 65536
NO_UNIT = "-"


def write_table(
    df: Any, path: str | Path, fmt: str, units_: dict[str, str] | None = None, meta: dict | None = None
) -> Path:
    """Write a whole table (a pandas DataFrame) as ``fmt`` ("csv" or "parquet") to ``path`` (see the module
    docstring); ``units_`` maps a column to its unit (others: no unit). Non-finite numbers become nulls."""
    path = Path(path)
    df = finite_or_null(df)
    units_ = {c: (units_ or {}).get(c) or NO_UNIT for c in map(str, df.columns)}
    if fmt not in TABLE_FORMATS:
        raise OutputError(f"{path}: unknown table format {fmt!r} (csv or parquet)", entry="format")
    if fmt == "parquet":
        with atomic_write(path, "wb") as fh:
            _table_parquet(df, fh, path, units_, meta or {})
    else:
        with atomic_write(path) as fh:
            _table_csv(df, fh, units_)
    return path


def finite_or_null(df: Any) -> Any:
    """``df`` with its non-finite numbers (nan, ±inf; in list cells too) as nulls: ``df`` itself when it has none
    besides nulls already, else a copy (the caller's table is never changed)."""
    from pandas.api.types import infer_dtype

    fixed: dict[str, Any] = {}
    for col in df.columns:
        kind = df[col].dtype.kind
        if kind == "f":
            v = df[col].to_numpy(dtype=float, na_value=np.nan)
            if np.any(np.isinf(v)):
                fixed[col] = np.where(np.isfinite(v), v, np.nan)
        elif kind == "O" and infer_dtype(df[col], skipna=True) not in _NO_NUMBERS:  # cell by cell: 1 µs a cell
            cells = [_finite_cell(x) for x in df[col]]
            if any(a is not b for a, b in zip(cells, df[col], strict=True)):
                fixed[col] = cells
    if not fixed:
        return df
    df = df.copy()
    for col, values in fixed.items():
        df[col] = values
    return df


# object columns (infer_dtype) that cannot hold a non-finite number: text, flags, integers, nothing
_NO_NUMBERS = frozenset({"string", "bytes", "boolean", "integer", "empty"})


def _finite_cell(x: Any) -> Any:
    if isinstance(x, float) and not np.isfinite(x):
        return None
    if isinstance(x, list | tuple | np.ndarray) and len(x) and not np.all(np.isfinite(np.asarray(x, float))):
        return None  # a series with a gap is no series: the row's reason says why
    return x


def _table_parquet(df: Any, fh: IO[bytes], path: Path, units_: dict[str, str], meta: dict) -> None:
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        raise OutputError(
            f"{path}: writing Parquet needs pyarrow: pip install 'vloop[parquet]' (or use --format csv)", entry="format"
        ) from None
    table = pa.Table.from_pandas(df, preserve_index=False)
    fields = [f.with_metadata({"unit": units_[f.name]}) for f in table.schema]
    keep = {k.decode(): v.decode() for k, v in (table.schema.metadata or {}).items()}  # pandas' own (dtypes)
    pq.write_table(table.cast(pa.schema(fields, metadata={**keep, **_metadata(units_, meta)})), fh)


def _table_csv(df: Any, fh: IO[str], units_: dict[str, str]) -> None:
    import csv

    import pandas as pd

    out = csv.writer(fh, lineterminator="\n")
    out.writerow(list(map(str, df.columns)))
    out.writerow([units_[str(c)] for c in df.columns])
    for lo in range(0, len(df), CSV_ROWS):  # a block of rows at a time: memory stays bounded
        part = df.iloc[lo : lo + CSV_ROWS]
        cells = [[_csv_cell(x, pd.NA) for x in part[c].tolist()] for c in part.columns]
        out.writerows(zip(*cells, strict=True))


def _csv_cell(x: Any, na: Any) -> str:
    """One cell: shortest round-trip numbers, JSON arrays for lists, true/false, empty for a null (``na``)."""
    if x is None or x is na or (isinstance(x, float) and x != x):
        return ""
    if isinstance(x, bool | np.bool_):
        return "true" if x else "false"
    if isinstance(x, float | np.floating):
        return repr(float(x))
    if isinstance(x, list | tuple | np.ndarray):
        return json.dumps([float(v) for v in x], allow_nan=False)
    return str(x)


@dataclass
class RunSummary:
    """What the run's summary line needs, gathered chunk by chunk."""

    rows: int = 0
    t_first: float = float("nan")
    t_last: float = float("nan")
    closure: float = 0.0
    cond: float = 1.0
    ill: int = 0
    meta: dict = field(default_factory=dict)

    def add(self, res: Result) -> None:
        if not len(res):
            self.meta = dict(res.meta) or self.meta
            return
        if not self.rows:
            self.t_first = float(res.t[0])
        self.rows += len(res)
        self.t_last = float(res.t[-1])
        self.closure = max(self.closure, float(np.max(res.health.get("residual", 0.0), initial=0.0)))
        self.cond = max(self.cond, float(np.max(res.health.get("cond", 1.0), initial=1.0)))
        self.ill += int(np.sum(res.health.get("ill_conditioned", 0)))
        self.meta = dict(res.meta)


def disk_need(samples: int, n_columns: int, fmt: str) -> int:
    """Bytes the files of a run take on disk, at most (npz: twice, while its columns are assembled)."""
    values = samples * (n_columns + 6)
    return values * (CSV_BYTES if fmt == "csv" else 8) * (2 if fmt == "npz" else 1)


def check_disk(folder: Path, samples: int, n_columns: int, fmt: str) -> None:
    """Refuse (OutputError) a run whose files would not fit on the output folder's disk."""
    need = disk_need(samples, n_columns, fmt)
    try:
        free = shutil.disk_usage(folder).free
    except OSError:
        return
    if need > free:
        from .budget import fmt_size

        raise OutputError(
            f"{folder}: the run's {fmt} files would take up to {fmt_size(need)}, more than the "
            f"{fmt_size(free)} free on that disk; use a larger [time] step, a shorter run, --format parquet "
            "or another --out",
            entry="out",
        )


def stream(
    outset: OutputSet, fmt: str, chunks: Iterator[Result], columns: list[str], length: str, mechanism: str,
    progress: Any = None, keep: bool = False,
) -> tuple[RunSummary, list[Result], list[Path], Exception | None]:  # fmt: skip
    """Write every chunk to results.FMT and health.FMT; returns (summary, the chunks if ``keep``, files,
    the error that stopped the run). An error with rows solved before it (a MotionError's ``partial``)
    has those rows written and is returned; any other is raised (nothing is to be published)."""
    if fmt == "parquet":
        try:
            import pyarrow  # noqa: F401
        except ImportError:
            raise OutputError(
                "--format parquet needs pyarrow: pip install 'vloop[parquet]' (or use --format csv or npz)", entry="out"
            ) from None
    names = ["t", *columns]
    hnames = ["t", *(f"health.{n}" for n, _ in HEALTH), *(f"health.{n}" for n in FLAGS)]
    meta = {"mechanism": mechanism}
    results = _Table(outset, "results", fmt, names, column_units(names, length), meta)
    health = _Table(outset, "health", fmt, hnames, {n: "s" if n == "t" else "1" for n in hnames}, meta)
    summary, kept = RunSummary(), []
    failure: Exception | None = None
    try:
        for part in chunks:
            _write(results, health, part)
            summary.add(part)
            if keep:
                kept.append(part)
            if progress is not None:
                progress.update(len(part))
    except Exception as exc:
        partial = getattr(exc, "partial", None)
        if partial is None:
            raise
        _write(results, health, partial)
        summary.add(partial)
        if keep:
            kept.append(partial)
        failure = exc
    results.close()
    health.close()
    files = [outset.folder / results.name, outset.folder / health.name]
    return summary, kept, files, failure


def _write(results: _Table, health: _Table, part: Result) -> None:
    results.write({"t": part.t, **part.columns})
    health.write(health_columns(part))
