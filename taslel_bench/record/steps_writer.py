"""steps.parquet written chunk by chunk: each chunk of the episode's table is appended as a row group to a
temporary file in the run folder (``.steps.parquet.tmp-<pid>``, the name :func:`run_files.atomic_write`
uses), renamed to ``steps.parquet`` when the episode's files are written. A killed run leaves only the
temporary file, which the next run removes and names (:func:`taslel_bench.record.run_files.remove_stale`);
a half-written table never carries the final name.

Column statistics (min/max per row group) are written for the time column ``t_s`` only: pyarrow keeps every
row group's statistics in memory until the file is closed (measured: 125 MB after 720 row groups of 202
columns, 251 MB at close; none without them), so with them memory would grow with the episode's length.
No dictionary encoding either: with it the writer grew by 0.17-0.24 MB per row group of 5000 rows x 202
columns (measured: +29 MB after 120 row groups, +50 MB at close; +0.1 / +1.0 MB without), i.e. ~35 bytes
per control tick -- the native growth of the hour-long run."""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

STATISTICS_COLUMNS = ("t_s",)  # columns with per-row-group min/max (filters on time can skip row groups)


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
            stats = [c for c in STATISTICS_COLUMNS if c in table.schema.names]
            self._writer = pq.ParquetWriter(self.tmp, table.schema, write_statistics=stats or False,
                                            use_dictionary=False)
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
