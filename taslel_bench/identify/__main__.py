"""``python -m taslel_bench.identify RUN_FOLDER... --out FILE``: fit the controller model's joint damping, armature,
friction loss, trunk mass and centre of mass to recorded runs (mujoco.sysid) and write a ``model`` override file
that ``model=identified model.from=FILE`` loads, with its fit report beside it. Exit code 0 on success, 2 for bad
input (a folder that is not a run, an unreadable config, mujoco[sysid] not installed)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from taslel_bench.util.fields import ConfigError

EXIT_BAD_INPUT = 2


def parse(argv: list[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog="python -m taslel_bench.identify", description=(__doc__ or "").split("\n\n")[0])
    ap.add_argument("runs", type=Path, nargs="+", metavar="RUN_FOLDER", help="run folders (config.yaml, "
                    "steps.parquet); their walking parts, in this order, are the data")
    ap.add_argument("--out", type=Path, required=True, help="the model override file to write (YAML); the fit "
                    "report goes beside it (<stem>.report.md, .fit.json, .sysid.html)")
    ap.add_argument("--window", type=float, default=0.02, help="replay window [s] (default 0.02)")
    ap.add_argument("--max-walk", type=float, default=20.0, help="walking data used at most [s] (default 20)")
    ap.add_argument("--per-joint", action="store_true", help="12 values per joint field instead of one")
    ap.add_argument("--max-iters", type=int, default=50, help="optimizer iterations at most (default 50)")
    ap.add_argument("--threads", type=int, default=2, help="rollout threads (default 2)")
    ap.add_argument("--no-html", action="store_true", help="skip mujoco.sysid's HTML report")
    return ap.parse_args(argv)


def check(args: argparse.Namespace) -> None:
    """Refuse bad arguments naming them (:class:`ConfigError`)."""
    for flag, value, lo in (("--window", args.window, 0.0), ("--max-walk", args.max_walk, 0.0)):
        if not value > lo:
            raise ConfigError(f"{flag}={value}: must be > {lo:g} s")
    for flag, value in (("--max-iters", args.max_iters), ("--threads", args.threads)):
        if value < 1:
            raise ConfigError(f"{flag}={value}: must be >= 1")
    if args.out.suffix not in (".yaml", ".yml"):
        raise ConfigError(f"--out={args.out}: a YAML file (.yaml) for model.from")
    if not args.out.parent.is_dir():
        raise ConfigError(f"--out={args.out}: no folder {args.out.parent}")


def main(argv: list[str] | None = None) -> int:
    args = parse(argv)
    try:
        check(args)
        from mujoco import sysid

        if not hasattr(sysid, "optimize"):  # mujoco.sysid imports without its extra's packages, empty
            raise ConfigError('mujoco.sysid needs its extra: pip install "mujoco[sysid]" (or the project\'s '
                              '"[identify]" extra)')
        from taslel_bench.identify.fit import FitSettings, identify
        from taslel_bench.identify.output import write_model_file, write_report, write_sysid_report
        from taslel_bench.identify.runs import load_run

        runs = [load_run(path) for path in args.runs]
        settings = FitSettings(window_s=args.window, max_walk_s=args.max_walk, per_joint=args.per_joint,
                               max_iters=args.max_iters, threads=args.threads)
        fit = identify(runs, settings, output=sys.stderr)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    write_model_file(args.out, fit)
    report = write_report(args.out, fit)
    html = None if args.no_html else write_sysid_report(args.out, fit)
    print(Path(report).read_text().split("## Replay")[0].split("## Parameters")[1].strip())
    print(f"model file: {args.out}  (use: model=identified model.from={args.out})")
    print(f"fit report: {report}" + (f", {html}" if html else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
