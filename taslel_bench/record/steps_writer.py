"""steps.parquet written chunk by chunk: each chunk of the episode's table is appended as a row group to a
temporary file in the run folder (``.steps.parquet.tmp-<pid>``, the name :func:`run_files.atomic_write`
uses), renamed to ``steps.parquet`` when the episode's files are written. A killed run leaves only the
temporary file, which the next run removes and names (:func:`taslel_bench.record.run_files.remove_stale`);
a half-written table never carries the final name."""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq


class StepsWriter:
    """``append(frame)`` per chunk (the same columns every time), :meth:`finish` renames, :meth:`abandon`
    removes the temporary file."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.name}.tmp-{os.getpid()}")
        self._writer: pq.ParquetWriter | None = None
        self.rows = 0

    def append(self, frame: pd.DataFrame) -> None:
        table = pa.Table.from_pandas(frame, preserve_index=False)
        if self._writer is None:
            self._writer = pq.ParquetWriter(self.tmp, table.schema)
        self._writer.write_table(table)
        self.rows += len(frame)

    def finish(self) -> Path:
        """Close the file and give it its final name (atomic on POSIX)."""
        if self._writer is None:
            raise RuntimeError(f"{self.path}: no chunk was written")
        self._writer.close()
        os.replace(self.tmp, self.path)
        return self.path

    def abandon(self) -> None:
        if self._writer is not None:
            self._writer.close()
        self.tmp.unlink(missing_ok=True)
