"""Identified against true plant values, from the fit files ``python -m taslel_bench.identify`` writes
(``<model>.fit.json``): per plant and field, the plant's value (its run config), the identified value, the 95 %
interval half-width from mujoco.sysid's ``calculate_intervals``, the error (relative; absolute in the field's unit
where the true value is 0) and whether the value is within 10 % of the truth (within 10 % of the field's typical
scale where the truth is 0: 1 N·m·s/rad, 0.01 kg·m², 0.1 N·m, 1, 0.01 m). One row per field component.

    python -m studies.identify_fit_table FIT_JSON [FIT_JSON ...] [--out FILE.md]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from studies.study_table import table_study
from taslel_bench.identify.fit import SPECS

HEADER = ["| plant | field | unit | truth | identified | 95 % half-width | error | within 10 % | walking data | "
          "replay RMS joint velocity URDF -> identified [rad/s] |",
          "|---|---|---|---|---|---|---|---|---|---|"]
TOLERANCE = 0.10


def rows(args: argparse.Namespace) -> list[str]:
    out = []
    for path in args.fits:
        fit = json.loads(Path(path).read_text())
        plant = Path(path).name.removesuffix(".fit.json")
        data = f"{fit['walking_s']:.0f} s, {len(fit['runs'])} runs"
        rms = f"{fit['rms_before']['joint_velocity_radps']:.3g} -> {fit['rms_after']['joint_velocity_radps']:.2g}"
        for name, values in fit["value"].items():
            for i, value in enumerate(values):
                truth = fit["plant"][name][i] if fit["plant"] else None
                label = name if len(values) == 1 else f"{name}[{'xyz'[i] if len(values) == 3 else i}]"
                out.append(f"| {plant} | {label} | {SPECS[name].unit} | {_fmt(truth)} | {value:.6g} | "
                           f"{fit['interval'][name][i]:.2g} | {_error(value, truth)} | "
                           f"{_within(value, truth, SPECS[name].scale)} | {data} | {rms} |")
    return out


def _fmt(x: float | None) -> str:
    return "n/a" if x is None else f"{x:g}"


def _error(value: float, truth: float | None) -> str:
    if truth is None:
        return "n/a"
    return f"{(value - truth) / abs(truth):+.3%}" if truth != 0 else f"{value - truth:+.2g} (abs)"


def _within(value: float, truth: float | None, scale: float) -> str:
    if truth is None:
        return "n/a"
    return "yes" if abs(value - truth) <= TOLERANCE * (abs(truth) if truth != 0 else scale) else "no"


def main(argv: list[str] | None = None) -> None:
    table_study("studies.identify_fit_table", __doc__, HEADER, rows, argv,
                add_args=lambda ap: ap.add_argument("fits", nargs="+", type=Path, help="<model>.fit.json files"))


if __name__ == "__main__":
    main()
