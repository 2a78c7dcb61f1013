"""The one markdown (pipe) table writer of the reports: ``markdown_table(frame)`` or ``markdown_table(rows,
columns)``; cells are formatted by ``fmt`` (default: :func:`cell`)."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence

import pandas as pd


def cell(value: object, digits: int = 3) -> str:
    """A number with ``digits`` significant digits, "—" for nan/inf (not measured), anything else as text."""
    if isinstance(value, float):
        return "—" if not math.isfinite(value) else f"{value:.{digits}g}"
    return str(value)


def markdown_table(table: pd.DataFrame | Iterable[Sequence[object]], columns: Sequence[str] | None = None,
                   fmt: Callable[[object], str] = cell) -> str:
    """A pipe table (header, separator, one line per row; ends with a newline)."""
    if isinstance(table, pd.DataFrame):
        columns = [str(c) for c in table.columns] if columns is None else list(columns)
        rows: Iterable[Sequence[object]] = table.itertuples(index=False)
    else:
        if columns is None:
            raise ValueError("markdown_table: give the columns of plain rows")
        rows = table
    head = "| " + " | ".join(columns) + " |\n|" + "---|" * len(columns) + "\n"
    return head + "".join("| " + " | ".join(fmt(v) for v in row) + " |\n" for row in rows)
