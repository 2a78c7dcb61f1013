"""The report's first table: per group of runs (seeds pooled), how many were unsafe and why — the run's
verdict (``safe``, ``unsafe_reasons``; :mod:`taslel_bench.metrics.verdict`), counted per reason tag, beside
the harness's own status counts."""

from __future__ import annotations

import pandas as pd

from taslel_bench.metrics.verdict import REASON_TAGS, reason_tags
from taslel_bench.util.tables import markdown_table


def verdict_table(frame: pd.DataFrame, group_cols: list[str]) -> pd.DataFrame:
    """One row per group: ``runs``, ``unsafe`` (k/n of judged runs), ``status_ok`` (runs the harness ended
    ``ok``), and per reason tag the number of runs with that reason (a run can have several)."""
    rows = []
    groups = frame.groupby(group_cols, dropna=False) if group_cols else [((), frame)]
    for keys, g in groups:
        keys = keys if isinstance(keys, tuple) else (keys,)
        row: dict[str, object] = dict(zip(group_cols, keys, strict=True))
        texts = g.get("unsafe_reasons", pd.Series([""] * len(g), index=g.index))
        typed = g.get("unsafe_reason_tags", pd.Series([None] * len(g), index=g.index))  # absent in older summaries
        tags = [reason_tags(r, t) for r, t in zip(texts, typed, strict=True)]
        judged = g["safe"].notna() if "safe" in g else pd.Series(False, index=g.index)
        unsafe = int((~g.loc[judged, "safe"].astype(bool)).sum()) if judged.any() else 0
        row["runs"] = len(g)
        row["unsafe"] = f"{unsafe}/{int(judged.sum())}" if judged.any() else "—"
        row["status_ok"] = int((g["status"] == "ok").sum()) if "status" in g else 0
        for tag in REASON_TAGS:
            row[tag] = sum(tag in t for t in tags)
        rows.append(row)
    return pd.DataFrame(rows)


def verdict_section(frame: pd.DataFrame, group_cols: list[str]) -> str:
    """Markdown: the table and how to read it (empty for an empty sweep)."""
    if frame.empty:
        return ""
    table = verdict_table(frame, [c for c in group_cols if c in frame])
    return ("## Unsafe runs per group (the verdict)\n\n"
            "`unsafe`: runs whose `safe` is false, of the judged runs; the same rules with the filter on or off "
            "(`safety.*` in the config: a fall, any trip, loaded contacts at the cone edge, swing ticks below "
            "the clearance profile, planned forces beyond the true cone; rates over the worst 0.5 s window). "
            "The next columns count runs per reason; `status_ok` counts runs the harness ended `ok` (its "
            "health: solver, model, barriers), which says nothing about the robot's safety.\n\n"
            + markdown_table(table))
