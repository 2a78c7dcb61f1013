"""Every shipped robot under the paper's trot, from the sweeps of ``+experiment=robots``: per robot and controller
(nominal = the trot alone, paper = ``filter=id_cbf_qp``, terrain = ``filter=terrain``), seeds pooled, the falls,
unsafe runs, mean forward speed over the commanded one, the share of filtered ticks whose QP was solved, the
vertical contact-force error over every loaded contact (filter's planned vs the plant's, mean over runs), the
cone-edge share of loaded contacts (|f_t| >= 0.98 mu f_n in MuJoCo's contact frame) and the tick median
(median over runs; the runs ran two at a time). One row group per sweep folder given (its name in the first column).

    python -m studies.robots_table SWEEP_FOLDER [SWEEP_FOLDER ...] [--out FILE.md]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import pandas as pd

from studies.study_table import table_study

HEADER = ["| sweep | world | robot | controller | runs | falls | unsafe | speed / commanded | commanded [m/s] | QP "
          "solved | vertical GRF error [N] | cone-edge share | tick median [µs] |",
          "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
WORLD_COLUMNS = ("scenario", "friction_true")


def rows(args: argparse.Namespace) -> list[str]:
    frame = pd.concat([pd.read_parquet(Path(folder) / "summary.parquet").assign(sweep=Path(folder).name)
                       for folder in args.sweeps], ignore_index=True)
    out = []
    keys = ["sweep", "scenario", "friction_true", "robot", "filter_variant"]
    for (sweep, scenario, mu, robot, variant), g in frame.groupby(keys):
        speed = (g["mean_speed_mps"] / g["commanded_speed_mps"]).mean()
        filtered = g["qp_solves"].sum() if "qp_solves" in g else 0
        solved = f"{1.0 - g['qp_failed'].sum() / filtered:.4f}" if filtered else "—"
        grf = f"{g['grf_mae_z_n'].mean():.2f}" if g["grf_mae_z_n"].notna().any() else "—"
        unsafe = int((~g["safe"].astype(bool)).sum())
        out.append(f"| {sweep} | {scenario} mu={mu:g} | {robot} | {variant} | {len(g)} | {int(g['fell'].sum())} | "
                   f"{unsafe} | {speed:.2f} | {g['commanded_speed_mps'].iloc[0]:.3f} | {solved} | {grf} | "
                   f"{g['friction_cone_edge_rate'].mean():.3f} | {g['tick_us_median'].median():.0f} |")
    return out


def main(argv: list[str] | None = None) -> None:
    table_study("studies.robots_table", __doc__, HEADER, rows, argv,
                add_args=lambda ap: ap.add_argument("sweeps", nargs="+", type=Path, help="sweep folders"))


if __name__ == "__main__":
    main()
