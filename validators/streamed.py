"""summary.json, the comparison table and the pages' figures from the comparison dataset, in one streaming pass.

    night = Night(engines, head, previous=..., options=...)
    for path in files_in_task_order:
        night.add(dataset.read_entry(path))             # one entry in memory at a time
    summary = night.finish(out / "summary.json", table_path, fmt)

Each mechanism's full entry (every quantity's worst figures) is read from its dataset file's metadata and passed to
everyone who needs it, once: the counts (:class:`validators.harness.Tally`), the nightly flags
(:func:`validators.nightly.compare_summaries`, against the previous summary's index), the failures with their
reproduce commands, the corpus page's figures (:class:`reports.corpus.CorpusFigures`), the comparison table (rows per
quantity, written a block at a time) and summary.json (each comparison with its worst figures only). What stays in
memory: the counts, the failures, the entries a report shows (files that are not generated, generated failures up
to a bound) and one block of table rows.
"""

from __future__ import annotations

import json
import os
import re
import tempfile
from pathlib import Path
from typing import Any

from . import harness, nightly

TABLE_BLOCK = 10_000  # rows of the comparison table written at a time
SHOWN_FAILURES = 200  # generated failures kept for the printed table (all are in summary.json and corpus.html)
SMALL_CORPUS = 30  # up to this many generated mechanisms, the printed table has a row for each


def light(entry: dict[str, Any]) -> dict[str, Any]:
    """A summary entry as summary.json keeps it: each comparison's worst figures, not every quantity's."""
    comps = [{k: v for k, v in c.items() if k != "quantities"} for c in entry.get("comparisons", [])]
    return {**entry, "comparisons": comps}


def unstaged(text: str, folder: str) -> str:
    """Every path in ``text`` written inside a staging folder of ``folder`` (this run's or an interrupted one's), as
    it is once published."""
    return re.sub(re.escape(folder) + r"/\.vloop-stage-[^/\"]+", lambda _: folder, text)


class Night:
    """One pass over the entries; :meth:`finish` writes summary.json and the comparison table."""

    def __init__(
        self,
        head: dict[str, Any],
        folder: str,
        previous: dict[str, Any] | None = None,
        options: str = "",
        pages: tuple[Any, ...] = (),
    ) -> None:
        self.head, self.folder, self.options = head, folder, options
        self.engines = tuple(head["engines"])
        self.tally = harness.Tally(self.engines)
        self.previous = nightly.Previous(previous) if previous is not None else None
        self.flags: list[dict[str, Any]] = []
        self.failures: list[dict[str, Any]] = []
        self.shown: list[dict[str, Any]] = []
        self.pages = tuple(p for p in pages if p is not None)  # each gathers a page's figures: .add(entry)
        self.rows: list[dict[str, Any]] = []
        self._entries = tempfile.TemporaryFile("w+", encoding="utf-8")
        self._first = True
        self._blocks: list[Path] = []

    def add(self, entry: dict[str, Any]) -> None:
        text = json.dumps(entry)
        entry = json.loads(unstaged(text, self.folder)) if self.folder in text else entry
        self.tally.add(entry)
        if self.previous is not None:
            self.flags += self.previous.flags(entry)
        if entry.get("corpus") and not entry["passed"]:
            self.failures += nightly.corpus_failures({"mechanisms": [entry]}, self.engines, self.options)
        kept = light(entry)
        small = entry["passed"] and self.tally.generated <= SMALL_CORPUS  # a small corpus prints every row
        if not entry.get("corpus") or small or (not entry["passed"] and len(self.shown) < SHOWN_FAILURES):
            self.shown.append(kept)
        for page in self.pages:
            page.add(kept)
        self.rows += harness.comparison_rows({"mechanisms": [entry]})
        self._entries.write(("" if self._first else ",\n") + json.dumps(kept, allow_nan=False))
        self._first = False

    def block(self, folder: Path, fmt: str) -> None:
        """Write the table rows gathered so far as one block file (joined by :meth:`finish`)."""
        if not self.rows:
            return
        path = folder / f".block-{len(self._blocks):05d}.{fmt}"
        harness.write_table({"mechanisms": []}, path, fmt, rows=self.rows)
        self._blocks.append(path)
        self.rows = []

    def finish(self, summary_path: Path, table_path: Path | None, fmt: str, extra: dict[str, Any]) -> dict[str, Any]:
        """Write summary.json (head, every entry, the counts, ``extra``) and the comparison table; return the summary
        as the printed table and the pages read it: its mechanisms are those shown."""
        tail = self.tally.fields()
        tail["passed"], tail["red"] = self.tally.passed == self.tally.n, bool(tail["verdicts"]["red"])
        head = {**self.head, "passed": tail.pop("passed"), "red": tail.pop("red")}
        corpus = tail.pop("corpus", None)
        if corpus is not None:
            corpus.update(extra.pop("corpus", {}), failures=self.failures)
            tail["corpus"] = corpus
        if self.previous is not None or "nightly" in extra:
            extra.setdefault("nightly", {})["flags"] = self.flags
        tail.update(extra)
        self._write_summary(summary_path, head, tail)
        if table_path is not None:
            self.block(table_path.parent, fmt)
            _join(self._blocks, table_path, fmt)
        return {**head, "mechanisms": self.shown, **tail}

    def _write_summary(self, path: Path, head: dict[str, Any], tail: dict[str, Any]) -> None:
        """summary.json as json.dumps(indent=1) would lay it out at the top level, its entries one per line."""
        tmp = path.with_name(f".{path.name}.tmp")
        with open(tmp, "w", encoding="utf-8") as out:
            out.write("{\n")
            for k, v in head.items():
                out.write(f" {json.dumps(k)}: {json.dumps(v, allow_nan=False)},\n")
            out.write(' "mechanisms": [\n')
            self._entries.seek(0)
            while chunk := self._entries.read(1 << 20):
                out.write(chunk)
            out.write("\n ]")
            for k, v in tail.items():
                out.write(f",\n {json.dumps(k)}: {json.dumps(v, allow_nan=False)}")
            out.write("\n}\n")
        os.replace(tmp, path)
        self._entries.close()


def _join(blocks: list[Path], path: Path, fmt: str) -> None:
    """The block files as one table: Parquet row groups appended, or CSV without the blocks' repeated two header
    lines (names, units); the blocks removed."""
    if not blocks:
        harness.write_table({"mechanisms": []}, path, fmt)
        return
    tmp = path.with_name(f".{path.name}.tmp")
    if fmt == "parquet":
        import pyarrow.parquet as pq

        schema = pq.read_schema(blocks[0])
        with pq.ParquetWriter(tmp, schema) as writer:
            for b in blocks:  # a block whose column is all null is cast to the first block's type
                writer.write_table(pq.read_table(b).cast(schema))
    else:
        with open(tmp, "w", encoding="utf-8", newline="") as out:
            for k, b in enumerate(blocks):
                with open(b, encoding="utf-8", newline="") as fh:
                    if k:
                        fh.readline(), fh.readline()
                    while chunk := fh.read(1 << 20):
                        out.write(chunk)
    os.replace(tmp, path)
    for b in blocks:
        b.unlink()
