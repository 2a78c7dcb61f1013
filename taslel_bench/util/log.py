"""Console logging for the command-line entry points: the package's INFO messages (status and progress of
library code, ``logging.getLogger(__name__)``) printed plainly on stderr, as the lines were before they were
logged. Library modules only log; the entry points call :func:`console_logging` once."""

from __future__ import annotations

import logging
import sys


class _StderrHandler(logging.StreamHandler):
    """Writes to the current ``sys.stderr`` (not the one at construction: a redirected or captured stderr
    gets the lines)."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self):  # type: ignore[override]
        return sys.stderr

    @stream.setter
    def stream(self, value) -> None:
        pass


def console_logging(level: int = logging.INFO) -> None:
    """The ``taslel_bench`` loggers' messages at ``level`` and above on stderr, message text only. Idempotent.
    They do not propagate to the root logger: Hydra's job logging (root at WARNING, its own format) neither
    hides nor repeats them."""
    log = logging.getLogger("taslel_bench")
    log.setLevel(level)
    if not any(isinstance(h, _StderrHandler) for h in log.handlers):
        handler = _StderrHandler()
        handler.setFormatter(logging.Formatter("%(message)s"))
        log.addHandler(handler)
    log.propagate = False
