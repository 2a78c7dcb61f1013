"""Which code produced a result: the git commit of the project's checkout and whether its tracked files had
uncommitted changes (every run summary, sweep report and results README records it). Changes under
``results/`` (reports being regenerated) do not count: they are outputs, not code."""

from __future__ import annotations

import subprocess
from functools import lru_cache
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]


def _git(*args: str) -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(REPO_ROOT), *args], capture_output=True, text=True, timeout=10,
                             check=True)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip()


@lru_cache(maxsize=1)
def code_version() -> dict[str, object]:
    """``{"git_commit": <sha or "unknown">, "git_dirty": <tracked files modified?>}`` (once per process;
    an installed copy without a git checkout reports "unknown" and dirty None)."""
    commit = _git("rev-parse", "HEAD")
    if not commit:
        return {"git_commit": "unknown", "git_dirty": None}
    status = _git("status", "--porcelain", "--untracked-files=no", "--", ".", ":(exclude)results")
    return {"git_commit": commit, "git_dirty": bool(status) if status is not None else None}


def describe() -> str:
    """``commit <sha12>`` plus `` (uncommitted changes)`` when dirty, for report headers."""
    v = code_version()
    sha = str(v["git_commit"])
    return f"commit {sha[:12] if sha != 'unknown' else sha}" + (" (uncommitted changes)" if v["git_dirty"] else "")
