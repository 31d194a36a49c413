"""A sweep's results on disk: one Parquet part per finished batch, a manifest, the whole table.

out/
  sweep.json            the study's name, file, fingerprint and run count (a resume checks it)
  parts/part-NNNNNN.parquet   the rows of one batch (written whole, then renamed into place)
  runs.parquet          every row in run order, when the sweep is complete (runs.csv with --csv)

An interrupted sweep leaves its finished parts; the next `gcs sweep` with the same study and
--out reads them and flies only the runs that have no row yet.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from gcs.config import ConfigError
from gcs.sweep.study import Study

MANIFEST, PARTS, TABLE, CSV = "sweep.json", "parts", "runs.parquet", "runs.csv"


def _type_of(values: Sequence[Any]) -> pa.DataType:
    known = [v for v in values if v is not None]
    if known and all(isinstance(v, bool) for v in known):
        return pa.bool_()
    if known and all(isinstance(v, int) and not isinstance(v, bool) for v in known):
        return pa.int64()
    if known and all(isinstance(v, int | float) and not isinstance(v, bool) for v in known):
        return pa.float64()
    return pa.string()


def rows_to_table(rows: Sequence[dict[str, Any]]) -> pa.Table:
    """Rows (dicts with the same keys, in the same order) as a table, one column a key."""
    if not rows:
        return pa.table({})
    names = list(rows[0])
    columns = {}
    for name in names:
        values = [r.get(name) for r in rows]
        kind = _type_of(values)
        if kind == pa.float64():
            values = [math.nan if v is None else float(v) for v in values]
        columns[name] = pa.array(values, type=kind)
    return pa.table(columns)


class ResultStore:
    """The out directory of one study (see the module's docstring)."""

    def __init__(self, out: Path, study: Study) -> None:
        self.out, self.study = Path(out), study
        self.parts = self.out / PARTS

    def open(self) -> set[int]:
        """Create or reopen the directory; returns the runs that already have rows. Refuses a
        directory that holds another study's (or another version's) results."""
        manifest = self.out / MANIFEST
        mine = {"study": self.study.name, "file": self.study.source,
                "fingerprint": self.study.fingerprint, "runs": self.study.runs}
        if manifest.is_file():
            theirs = json.loads(manifest.read_text())
            if theirs.get("fingerprint") != self.study.fingerprint:
                raise ConfigError(
                    self.study.source, "(file)",
                    f"{self.out} holds the results of another study or of another version of "
                    f"this one ({theirs.get('file')}, fingerprint "
                    f"{str(theirs.get('fingerprint'))[:12]}); give a new --out or remove it")
        self.parts.mkdir(parents=True, exist_ok=True)
        manifest.write_text(json.dumps(mine, indent=2) + "\n")
        return self.done_runs()

    def done_runs(self) -> set[int]:
        done: set[int] = set()
        for part in sorted(self.parts.glob("part-*.parquet")):
            done.update(pq.read_table(part, columns=["run"]).column("run").to_pylist())
        return done

    def add(self, rows: Sequence[dict[str, Any]]) -> None:
        """Write one batch's rows (atomically: a part is whole or absent)."""
        if not rows:
            return
        first = min(r["run"] for r in rows)
        final = self.parts / f"part-{first:07d}.parquet"
        tmp = final.with_suffix(".tmp")
        pq.write_table(rows_to_table(rows), tmp)
        os.replace(tmp, final)

    def table(self) -> pa.Table:
        """Every row written so far, in run order."""
        parts = [pq.read_table(p) for p in sorted(self.parts.glob("part-*.parquet"))]
        if not parts:
            return pa.table({})
        table = pa.concat_tables(parts, promote_options="permissive")
        return table.sort_by("run")

    def finish(self, csv: bool) -> list[Path]:
        table = self.table()
        written = [self.out / TABLE]
        pq.write_table(table, written[0])
        if csv:
            written.append(self.out / CSV)
            pacsv.write_csv(table, written[-1])
        return written


def batches(runs: Iterable[int], size: int) -> list[list[int]]:
    """The runs in order, cut into lists of at most `size`."""
    ordered = sorted(runs)
    return [ordered[k : k + size] for k in range(0, len(ordered), size)]
