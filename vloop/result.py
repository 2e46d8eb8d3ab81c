"""The Result every engine returns: time histories of links, joints/points and sliders.

Columns follow the output contract: ``t``; ``LINK.theta|omega|alpha`` [rad, rad/s,
rad/s²] (θ continuous, unwrapped); ``POINT.x|y|vx|vy|ax|ay``; ``SLIDER.s|v|a``.
An engine may leave out quantities it does not compute (e.g. a closed form that
only gives some links); comparison works on the columns two Results share.
"""

from __future__ import annotations

import html
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import IO, Any

import numpy as np

LINK_FIELDS = ("theta", "omega", "alpha")
POINT_FIELDS = ("x", "y", "vx", "vy", "ax", "ay")
SLIDER_FIELDS = ("s", "v", "a")
CSV_BLOCK = 65536  # rows formatted at a time by the fallback writer (bounds its memory)


def arrow_array(a: np.ndarray) -> Any:
    """A numpy column as an Arrow array over the same memory (pa.array would import pandas to inspect it)."""
    import pyarrow as pa

    a = np.ascontiguousarray(a)
    kind = {"f8": pa.float64(), "f4": pa.float32(), "i8": pa.int64(), "i1": pa.int8()}[a.dtype.str[1:]]
    return pa.Array.from_buffers(kind, len(a), [None, pa.py_buffer(a)])


def write_csv(fh: IO[bytes], names: list[str] | None, columns: list[np.ndarray]) -> None:
    """Write a header row (``names``, unless None) and one comma-separated row per sample to a binary file.

    Every number is the shortest text that reads back to the same value (``repr(float)`` semantics: 0.35,
    never 0.35000000000000003 for the double 0.35): float64 to the same double, float32 to the same float32,
    integers as integers. pyarrow formats them where installed (fast), else Python's float repr.
    """
    if names is not None:
        fh.write((",".join(names) + "\n").encode())
    columns = [c if c.dtype.isnative else c.astype(c.dtype.newbyteorder("=")) for c in map(np.asarray, columns)]
    if not columns or not len(columns[0]):
        return
    try:
        import pyarrow as pa
        import pyarrow.csv as pcsv
    except ImportError:
        for k in range(0, len(columns[0]), CSV_BLOCK):
            parts = [_texts(c[k : k + CSV_BLOCK]) for c in columns]
            fh.write(("\n".join(map(",".join, zip(*parts, strict=True))) + "\n").encode())
        return
    arrays = [arrow_array(c if c.dtype.str[1:] in ("f8", "f4", "i8", "i1") else c.astype(float)) for c in columns]
    table = pa.Table.from_arrays(arrays, names=[f"c{i}" for i in range(len(arrays))])
    pcsv.write_csv(table, fh, pcsv.WriteOptions(include_header=False))


def _texts(c: np.ndarray) -> list[str]:
    """The shortest round-trip text of each value of a column (the fallback of :func:`write_csv`)."""
    if c.dtype == np.float32:
        return c.astype(str).tolist()  # numpy's shortest text of a float32
    if np.issubdtype(c.dtype, np.integer):
        return list(map(str, c.tolist()))
    return list(map(repr, c.astype(float).tolist()))


UNIT_OF_FIELD = {
    "theta": "rad",
    "omega": "rad/s",
    "alpha": "rad/s^2",
    "x": "L",
    "y": "L",
    "s": "L",
    "vx": "L/s",
    "vy": "L/s",
    "v": "L/s",
    "ax": "L/s^2",
    "ay": "L/s^2",
    "a": "L/s^2",
}


LENGTH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001, "km": 1000.0, "in": 0.0254, "ft": 0.3048}  # metres per unit
LENGTH_FIELDS = frozenset(f for f, u in UNIT_OF_FIELD.items() if u.startswith("L"))  # lengths and their rates


def column_units(columns: list[str], length: str) -> dict[str, str]:
    """The unit of each output column: ``t`` s, angles rad (rates per s, s²), lengths ``length`` (the file's units;
    rates per s, s²); anything else "1"."""
    return {c: "s" if c == "t" else UNIT_OF_FIELD.get(c.rsplit(".", 1)[-1], "1").replace("L", length) for c in columns}


def length_conversion(source: str, target: str) -> float:
    """The factor that turns lengths in ``source`` units into ``target`` units (1 where the two are the same name);
    ValueError naming the unit where either is not in :data:`LENGTH_UNITS`."""
    if source.strip().lower() == target.strip().lower():
        return 1.0
    for unit in (source, target):
        if unit.strip().lower() not in LENGTH_UNITS:
            raise ValueError(
                f"cannot convert lengths from {source!r} to {target!r}: {unit!r} is not a length unit vloop knows "
                f"({', '.join(LENGTH_UNITS)})"
            )
    return LENGTH_UNITS[source.strip().lower()] / LENGTH_UNITS[target.strip().lower()]


def html_table(rows: list[list[Any]], header: list[str] | None = None, caption: str = "") -> str:
    """A small HTML table for notebooks (every cell escaped; numbers to 6 significant digits)."""

    def cell(x: Any) -> str:
        return html.escape(f"{x:.6g}" if isinstance(x, float) else str(x))

    head = "<tr>" + "".join(f"<th>{cell(h)}</th>" for h in header) + "</tr>" if header else ""
    body = "".join("<tr>" + "".join(f"<td>{cell(x)}</td>" for x in row) + "</tr>" for row in rows)
    cap = f"<caption style='text-align:left'>{cell(caption)}</caption>" if caption else ""
    return f"<table class='vloop'>{cap}<thead>{head}</thead><tbody>{body}</tbody></table>"


@dataclass
class Result:
    """Histories of one run. ``columns`` maps ``NAME.field`` to an array over ``t``.

    ``health`` holds per-sample diagnostics when the engine keeps them
    (vloop: ``residual`` — loop-closure residual relative to the mechanism size,
    ``cond`` — Jacobian condition number, ``branch`` — assembly-branch signature).
    """

    mechanism: str
    engine: str
    t: np.ndarray
    columns: dict[str, np.ndarray]
    health: dict[str, np.ndarray] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)

    # ----- construction helpers
    @classmethod
    def from_arrays(
        cls,
        mechanism: str,
        engine: str,
        t: np.ndarray,
        *,
        links: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None,
        points: dict[str, tuple[np.ndarray, ...]] | None = None,
        sliders: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]] | None = None,
        **kw: Any,
    ) -> Result:
        """Build from per-entity tuples: links (θ, ω, α); points (x, y, vx, vy, ax, ay); sliders (s, v, a)."""
        cols: dict[str, np.ndarray] = {}
        for group, names in ((links, LINK_FIELDS), (points, POINT_FIELDS), (sliders, SLIDER_FIELDS)):
            for ent, arrays in (group or {}).items():
                for f, a in zip(names, arrays, strict=True):
                    cols[f"{ent}.{f}"] = np.asarray(a, float)
        return cls(mechanism, engine, np.asarray(t, float), cols, **kw)

    # ----- access
    def __len__(self) -> int:
        return len(self.t)

    def __getitem__(self, key: str) -> np.ndarray:
        if key == "t":
            return self.t
        return self.columns[key]

    def __contains__(self, key: str) -> bool:
        return key == "t" or key in self.columns

    def _group(self, name: str, fields: tuple[str, ...], kind: str) -> SimpleNamespace:
        if f"{name}.{fields[0]}" not in self.columns:
            raise KeyError(f"no {kind} '{name}' in this result")
        return SimpleNamespace(**{f: self.columns[f"{name}.{f}"] for f in fields})

    def link(self, name: str) -> SimpleNamespace:
        """θ, ω, α of a link or slider block (``.theta``, ``.omega``, ``.alpha``)."""
        return self._group(name, LINK_FIELDS, "link")

    def point(self, name: str) -> SimpleNamespace:
        """Position, velocity, acceleration of a joint or tracer point (``.x .y .vx .vy .ax .ay``)."""
        return self._group(name, POINT_FIELDS, "joint or point")

    joint = point

    def slider(self, name: str) -> SimpleNamespace:
        """s, v, a of a slider along its axis."""
        return self._group(name, SLIDER_FIELDS, "slider")

    def names(self, kind: str) -> list[str]:
        """Entity names of a kind: ``"link"``, ``"point"`` or ``"slider"``, in column order."""
        first = {"link": "theta", "point": "x", "slider": "s"}[kind]
        return [c.rsplit(".", 1)[0] for c in self.columns if c.rsplit(".", 1)[1] == first]

    def head(self, n: int) -> Result:
        """The first ``n`` samples (used to keep the rows solved before a failure)."""
        return Result(
            self.mechanism,
            self.engine,
            self.t[:n],
            {k: v[:n] for k, v in self.columns.items()},
            {k: v[:n] for k, v in self.health.items()},
            dict(self.meta),
        )

    # ----- export
    def to_csv(self, path: str | Path, *, health: bool = False) -> None:
        """Write one row per sample: ``t`` then the columns, each number the shortest text that reads back to
        the same double (:func:`write_csv`)."""
        names = ["t", *self.columns]
        data = [self.t, *self.columns.values()]
        if health:
            names += [f"health.{k}" for k in self.health]
            data += list(self.health.values())
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb") as fh:
            write_csv(fh, names, [np.asarray(c, float) for c in data])

    def to_pandas(self, length: str | None = None) -> Any:
        """A pandas DataFrame, one row per sample: ``t`` [s] first, then every column; ``df.attrs["units"]`` maps
        each column to its unit (angles rad, rad/s, rad/s^2, never converted; lengths in the file's units —
        ``meta["units"]``, which vloop's runs record — or in ``length``: positions, velocities and accelerations
        converted by :data:`LENGTH_UNITS`' factors; ValueError where either unit is not one of them). A Result that
        does not know its units takes ``length`` as their name ("L" without it)."""
        import pandas as pd

        own = self.meta.get("units")
        factor = 1.0 if length is None or own is None else length_conversion(own, length)
        cols = {
            k: v * factor if factor != 1.0 and k.rsplit(".", 1)[-1] in LENGTH_FIELDS else v
            for k, v in self.columns.items()
        }
        df = pd.DataFrame({"t": self.t, **cols})
        df.attrs["units"] = column_units(list(df.columns), length or own or "L")
        return df

    to_dataframe = to_pandas  # the name the file-format contract gives it

    def _repr_html_(self) -> str:
        """A notebook's summary: the run, then per link, slider and point the range of each quantity (units)."""
        n = len(self.t)
        span = f"t = {self.t[0]:g} … {self.t[-1]:g} s" if n else "no sample"
        who = html.escape(f"{self.mechanism} by {self.engine}")
        head = f"<p><b>Result</b> of {who}: {n:,} samples, {span}</p>"
        if not n:
            return head
        length = self.meta.get("units", "L")
        rows = [self._html_row(name, kind, length) for kind in ("link", "slider", "point") for name in self.names(kind)]
        table = html_table(rows, ["name", "kind", "position", "velocity", "acceleration"], "ranges over the run")
        notes = [f"{k}: max {float(np.max(v)):.3g}" for k, v in self.health.items() if k in ("residual", "cond")]
        return head.replace("</p>", f"{'; ' + '; '.join(notes) if notes else ''}</p>") + table

    def _html_row(self, name: str, kind: str, length: str) -> list[str]:
        def span(col: str) -> str:
            x = self.columns[f"{name}.{col}"]
            unit = UNIT_OF_FIELD[col].replace("L", length)
            return f"{col} {float(np.min(x)):.4g} … {float(np.max(x)):.4g} {unit}"

        if kind == "point":
            speed = float(np.max(np.hypot(self.columns[f"{name}.vx"], self.columns[f"{name}.vy"])))
            acc = float(np.max(np.hypot(self.columns[f"{name}.ax"], self.columns[f"{name}.ay"])))
            return [
                name,
                kind,
                f"{span('x')}; {span('y')}",
                f"|v| ≤ {speed:.4g} {length}/s",
                f"|a| ≤ {acc:.4g} {length}/s^2",
            ]
        return [name, kind, *(span(f) for f in (LINK_FIELDS if kind == "link" else SLIDER_FIELDS))]

    @classmethod
    def read_csv(cls, path: str | Path, *, mechanism: str = "", engine: str = "csv") -> Result:
        """Read a CSV written by :meth:`to_csv` (health columns go back to ``health``)."""
        with open(path, encoding="utf-8") as fh:
            header = fh.readline().strip().split(",")
        arr = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)
        cols = {h: arr[:, i] for i, h in enumerate(header)}
        t = cols.pop("t")
        health = {k[7:]: cols.pop(k) for k in list(cols) if k.startswith("health.")}
        return cls(mechanism, engine, t, cols, health)
