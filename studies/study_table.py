"""The frame of a study that prints one markdown table row per case and can write it to a new file
(``--out``): the command, the code version and the study's module doc above the table."""

from __future__ import annotations

import argparse
import shlex
import sys
from collections.abc import Callable, Iterable
from pathlib import Path


def table_study(module: str, doc: str, header: list[str],
                rows: Iterable[str] | Callable[[argparse.Namespace], Iterable[str]], argv: list[str] | None,
                add_args: Callable[[argparse.ArgumentParser], None] | None = None) -> None:
    """Parse ``--out`` (and what ``add_args`` adds; ``rows`` is then a function of the parsed arguments), print
    ``header`` and each row of ``rows`` as it comes (rows are computed lazily: a long study shows progress),
    then write the table to ``--out`` (refused if the file exists: results are not overwritten) under the
    command ``python -m <module> ...``, the code version and ``doc``."""
    ap = argparse.ArgumentParser(description=doc.split("\n")[0])
    ap.add_argument("--out", type=Path, default=None, help="markdown table (a new file)")
    if add_args is not None:
        add_args(ap)
    a = ap.parse_args(argv)
    if callable(rows):
        rows = rows(a)
    if a.out is not None and a.out.exists():
        ap.error(f"--out: {a.out} exists; not overwritten")
    lines = list(header)
    print("\n".join(lines), flush=True)
    for row in rows:
        lines.append(row)
        print(row, flush=True)
    if a.out is not None:
        from taslel_bench.util.machine import machine_info

        args = sys.argv[1:] if argv is None else argv
        cmd = f"python -m {module} " + " ".join(shlex.quote(x) for x in args)
        a.out.write_text(f"`{cmd}` ({machine_info()['code']})\n\n{doc}\n" + "\n".join(lines) + "\n")
