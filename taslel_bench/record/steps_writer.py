"""steps.parquet written chunk by chunk: the episode's table is appended, in row groups, to a temporary file
in the run folder (``.steps.parquet.tmp-<pid>``, the name :func:`run_files.atomic_write` uses), renamed to
``steps.parquet`` when the episode's files are written. A killed run leaves only the temporary file, which the
next run removes and names (:func:`taslel_bench.record.run_files.remove_stale`); a half-written table never
carries the final name.

Memory. pyarrow's ParquetWriter keeps per row group state until the footer is written at close, so what it
holds grows with the number of row groups; three measures keep it small (each measured on the hour-long run
or on the real table shape, 202 columns):
- column statistics (min/max per row group) for the time column ``t_s`` only: with them on every column,
  +125 MB after 720 row groups, +251 MB at close;
- no dictionary encoding: with it, the hour's peak was 0.78 GB instead of 0.67 GB;
- row groups of at least ``ROW_GROUP_BYTES`` (chunks are buffered until then): each row group's column-chunk
  metadata costs ~0.86 kB per column whatever its rows (+172 kB per row group of 200 columns, released at
  close), i.e. ~35 bytes per tick with one row group per 5000-tick chunk. With 64 MB row groups (~45 000 ticks
  of the default table) it is ~4 bytes per tick, for a buffer of at most ``ROW_GROUP_BYTES`` plus one chunk.
A single Parquet file cannot do better: its footer holds every row group's metadata and is written at once."""

from __future__ import annotations

import os
from pathlib import Path

import pandas as pd
import pyarrow as pa
import pyarrow.parquet as pq

STATISTICS_COLUMNS = ("t_s",)  # columns with per-row-group min/max (filters on time can skip row groups)
ROW_GROUP_BYTES = 64 * 1024**2  # [bytes] of Arrow data buffered before a row group is written


class StepsWriter:
    """``append(frame)`` per chunk (the same columns every time), :meth:`finish` writes what is buffered and
    renames, :meth:`abandon` removes the temporary file. ``row_group_bytes``: see ``ROW_GROUP_BYTES``."""

    def __init__(self, path: Path, row_group_bytes: int = ROW_GROUP_BYTES) -> None:
        self.path = Path(path)
        self.tmp = self.path.with_name(f".{self.path.name}.tmp-{os.getpid()}")
        self.row_group_bytes = int(row_group_bytes)
        self._writer: pq.ParquetWriter | None = None
        self._buffer: list[pa.Table] = []  # chunks not yet written (one row group once they reach the size)
        self._buffered_bytes = 0
        self.rows = 0  # rows appended (buffered or written)

    def append(self, frame: pd.DataFrame) -> None:
        table = pa.Table.from_pandas(frame, preserve_index=False)
        if self._writer is None:  # the file exists from the first chunk on (a kill leaves it, named temporary)
            stats = [c for c in STATISTICS_COLUMNS if c in table.schema.names]
            self._writer = pq.ParquetWriter(self.tmp, table.schema,
                                            write_statistics=stats or False,  # pyright: ignore[reportArgumentType] pyarrow is unannotated: bool inferred from the default; it takes a bool or a list of columns
                                            use_dictionary=False)
        self._buffer.append(table)
        self._buffered_bytes += table.nbytes
        self.rows += len(frame)
        if self._buffered_bytes >= self.row_group_bytes:
            self._flush()

    def _flush(self) -> None:
        """The buffered chunks as one row group."""
        if not self._buffer:
            return
        table = pa.concat_tables(self._buffer)
        assert self._writer is not None  # made by the first append (the buffer is not empty)
        self._writer.write_table(table, row_group_size=max(1, table.num_rows))
        self._buffer, self._buffered_bytes = [], 0

    def finish(self) -> Path:
        """Write the last row group, close the file and give it its final name (atomic on POSIX)."""
        if self._writer is None:
            raise RuntimeError(f"{self.path}: no chunk was written")
        self._flush()
        self._writer.close()
        os.replace(self.tmp, self.path)
        return self.path

    def abandon(self) -> None:
        self._buffer, self._buffered_bytes = [], 0
        if self._writer is not None:
            self._writer.close()
        self.tmp.unlink(missing_ok=True)
