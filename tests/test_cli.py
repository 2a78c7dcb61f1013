"""The command line: --help, did-you-mean, unread +key refusals, exit codes, the console's reasons, the GL hint."""

from __future__ import annotations

import itertools
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from taslel_bench import cli_help
from taslel_bench.cli_checks import CliError, check_overrides, group_options
from taslel_bench.gl_hint import hint
from taslel_bench.sim.console import print_summary, reason_lines

REPO = Path(__file__).resolve().parents[1]


def _cli(tmp_path: Path, *args: str, env: dict | None = None) -> subprocess.CompletedProcess:
    """``python -m taslel_bench args`` in an empty folder (so that nothing it creates goes unnoticed)."""
    return subprocess.run([sys.executable, "-m", "taslel_bench", *args], cwd=tmp_path, capture_output=True, check=False,
                          text=True, timeout=300, env={**os.environ, **(env or {}), "PYTHONPATH": str(REPO)})


def test_help_lists_groups_with_one_line_each_and_no_refused_names(tmp_path):
    out = _cli(tmp_path, "--help")
    assert out.returncode == 0, out.stderr
    for group in ("scenario:", "solver:", "estimator:", "filter:", "hydra/launcher:", "experiment:"):
        assert f"\n{group}" in out.stdout
    assert "  steps " in out.stdout and "  stress " in out.stdout and "  slip_fixed " in out.stdout
    assert "_persistent" not in out.stdout
    assert "Exit codes: 0" in out.stdout and "2 bad input" in out.stdout
    assert list(tmp_path.iterdir()) == []


def test_help_template_is_current():
    assert cli_help.HELP_FILE.read_text() == cli_help.template_yaml(), \
        "run: python -m taslel_bench.cli_help --write"


def test_renamed_solvers_hidden_from_help_but_still_refused_with_the_new_name():
    assert "osqp_persistent" in group_options()["solver"]
    assert "osqp_persistent" not in group_options(include_renamed=False)["solver"]


def test_unknown_option_gets_did_you_mean_and_exit_2(tmp_path):
    out = _cli(tmp_path, "scenario=stepz")
    assert out.returncode == 2
    assert "error: scenario=stepz: 'stepz' is not an option of the config group 'scenario'; did you mean steps?" \
        in out.stderr
    assert "Traceback" not in out.stderr and list(tmp_path.iterdir()) == []


def test_unknown_option_in_a_sweep_list_is_refused(tmp_path):
    with pytest.raises(CliError, match="'claribel' is not an option of the config group 'solver'; did you mean "
                                       "clarabel"):
        check_overrides(["-m", "solver=osqp,claribel"])


def test_unknown_key_gets_did_you_mean_and_exit_2(tmp_path):
    out = _cli(tmp_path, "controller.sped=0.3")
    assert out.returncode == 2
    assert "controller.sped=0.3: the config has no key 'controller.sped'; did you mean controller.speed" in out.stderr
    assert list(tmp_path.iterdir()) == []


def test_added_key_no_part_of_the_run_reads_is_refused(tmp_path):
    out = _cli(tmp_path, "+controller.sped=0.3")
    assert out.returncode == 2
    assert "+controller.sped=0.3: no part of the run reads 'controller.sped'" in out.stderr
    assert "did you mean controller.speed" in out.stderr
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("args", [
    ["+solver.eps_abs=1e-7"],                      # a native solver setting: the backend takes **settings
    ["+controller.terrain_following=true"],        # read with controller.get("terrain_following")
    ["+experiment=paper"],                         # a group appended
    ["-m", "solver=osqp,clarabel", "seed=0,1"],
])
def test_added_keys_that_the_run_reads_pass(args):
    check_overrides(args)  # raises CliError when refused


def test_hydra_level_mistake_exits_2(tmp_path):
    out = _cli(tmp_path, "--no-such-flag")
    assert out.returncode == 2 and "unrecognized arguments: --no-such-flag" in out.stderr
    bad = _cli(tmp_path, "seed=[0,")  # an override Hydra cannot parse
    assert bad.returncode == 2 and "no viable alternative at input '[0,'" in bad.stderr
    assert list(tmp_path.iterdir()) == []


def test_console_prints_every_reason_in_full(capsys, tmp_path):
    long = ("beyond_cone: filter_demand_beyond_cone_rate_worst_window=0.0312 > 0.01 (planned contact forces outside "
            "the true friction cone, worst 0.5 s); cone_edge: friction_cone_edge_rate_worst_window=0.41 > 0.25 "
            "(loaded contacts at the friction-cone edge (sliding), worst 0.5 s)")
    summary = {"status": "ok", "safe": False, "unsafe_reasons": long, "scenario": "flat"}
    assert reason_lines(summary) == [f"unsafe: {part}" for part in long.split("; ")]
    print_summary(summary, tmp_path)
    printed = capsys.readouterr().out
    for part in long.split("; "):
        assert f"unsafe: {part}" in printed


def test_labelled_progress_names_the_job(capsys):
    from taslel_bench.__main__ import _labelled_progress

    show = _labelled_progress("scenario=flat,solver=osqp")(10.5, True)
    for t in (0.0, 0.5, 1.0, 1.2, 2.0):
        show(t)
    err = capsys.readouterr().err.splitlines()
    assert err == [f"  [scenario=flat,solver=osqp] simulated {t:6.2f} / 10.50 s" for t in (0.0, 1.0, 2.0)]
    assert _labelled_progress("x")(1.0, False) is None


def test_gl_hint_is_one_line_naming_the_package():
    text = hint("osmesa", AttributeError("'NoneType' object has no attribute 'glGetError'"))
    assert "\n" not in text and "libosmesa6" in text and text.startswith("error: MUJOCO_GL=osmesa")


def test_unloadable_gl_library_gives_the_hint_not_a_traceback(tmp_path):
    out = _cli(tmp_path, "duration=0.1", env={"MUJOCO_GL": "no_such_gl"})
    assert out.returncode == 1
    assert (
        out.stderr.startswith("error: MUJOCO_GL=no_such_gl: MuJoCo could not load it") and "Traceback" not in out.stderr
    )


def test_added_barrier_family_passes():
    check_overrides(["+filter.barriers.mine={_target_: my.module.MyBarrier}"])  # the filter builds every entry


def test_report_opens_with_contents_and_verdicts_and_keeps_heading_order():
    import pandas as pd

    from taslel_bench.sweep.claims import paper_claims
    from taslel_bench.sweep.report import answers_section, contents

    frame = pd.DataFrame({"scenario": ["flat", "flat", "logs"], "solver": ["daqp"] * 3, "filter_enabled": [True] * 3,
                          "status": ["ok", "ok", "degraded"], "safe": [True, False, False],
                          "unsafe_reasons": ["", "fell: at 3.00 s (tilt)", "tripped: trips=2 > 0 (x)"]})
    text = answers_section(frame, None)
    assert text.startswith("## Verdicts")
    assert "2 of 3 judged runs are unsafe" in text
    assert "- scenario=flat, solver=daqp: 1/2 (fell 1) unsafe" in text
    assert "- scenario=logs, solver=daqp: 1/1 (tripped 1) unsafe" in text
    toc = contents(["## Verdicts\n", "## Solver verdict: which backend to ship\n"])
    assert "- [Solver verdict: which backend to ship](#solver-verdict-which-backend-to-ship)" in toc
    # a committed sweep's runs with the filter on only (no nominal runs): the sentence names what it has
    paper = pd.read_parquet(REPO / "results" / "paper" / "summary.parquet")
    claims = paper_claims(paper[paper["filter_enabled"].astype(bool)])
    assert "Claim by claim" in claims and "flat — nominal" not in claims and "(verdict) — nominal" not in claims
    assert re.search(r"unsafe runs of the judged ones: flat: \d+/\d+ .*filtered", claims)
    levels = [len(line) - len(line.lstrip("#")) for line in claims.splitlines() if line.startswith("#")]
    assert levels and all(b - a <= 1 for a, b in itertools.pairwise(levels))


def test_old_solver_name_is_refused_with_the_new_one_before_any_folder(tmp_path):
    out = _cli(tmp_path, "solver=osqp_persistent")
    assert out.returncode == 2
    assert "solver=osqp_persistent: 'osqp_persistent' is an old name, refused" in out.stderr
    assert "solver=osqp is now the persistent osqp" in out.stderr
    assert list(tmp_path.iterdir()) == []


def test_console_logging_prints_the_package_info_lines_plainly_on_stderr(capsys):
    """The entry points' console: a library module's INFO line appears as its bare text on the current stderr,
    once (not repeated by the root logger's handlers)."""
    import logging

    from taslel_bench.util.log import console_logging

    console_logging()
    console_logging()  # idempotent: one handler
    logging.getLogger("taslel_bench.sweep.stills").info("report: still strips and clips %d/%d", 0, 3)
    logging.getLogger("taslel_bench.sweep.stills").debug("not shown")
    captured = capsys.readouterr()
    assert captured.err == "report: still strips and clips 0/3\n" and captured.out == ""
