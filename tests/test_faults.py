"""Fault matrix: a bad value is refused before anything is simulated, and the error names the
field (dotted config path) and the value. ``Episode.run`` is replaced by a function that fails the test, and
the run folder must stay empty (no config.yaml, steps.parquet, summary.json)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from hydra.errors import ConfigCompositionException

from taslel_bench.cli_checks import CliError, check_overrides
from taslel_bench.config.validate import ConfigError
from taslel_bench.sim.episode import Episode
from taslel_bench.sim.run import record_job_error, run
from tests.conftest import compose_cfg

ROOT = Path(__file__).resolve().parent.parent
CHECKPOINTS = ROOT / "estimators" / "checkpoints"

# (overrides, field the message must name, value text the message must show)
FAULTS = [
    # the cases of the issue
    (["scenario=obstacle", "scenario.coefficients=[]"], "scenario.coefficients", "[]"),
    (["scenario=obstacle", "scenario.coefficients=[0,0,nan]"], "scenario.coefficients[2]", "nan"),
    (["estimator=mlp", "estimator.conservative_k=nan"], "estimator.conservative_k", "nan"),
    (["seed=abc"], "seed", "'abc'"),
    (["solver=qpsolvers", "solver.name=osqp", "+solver.settings.eps_abs=-1"], "solver.settings.eps_abs", "-1"),
    (["solver=osqp", "solver.settings.eps_abs=-1"], "solver.settings.eps_abs", "-1"),
    (["solver=osqp_persistent"], "solver", "renamed: solver=osqp"),
    (["solver=qpsolvers", "solver.name=gurobi_x"], "solver.name", "'gurobi_x'"),
    (["scenario=obstacle", "scenario.height_m=-1"], "scenario.height_m", "-1"),
    (["controller.speed=100"], "controller.speed", "100"),
    # top level and record.*
    (["seed=${oops}"], "seed", "${oops}"),
    (["duration=1e9"], "duration", "1000000000.0"),
    (["duration=3600", "record.chunk_ticks=null"], "duration", "3600"),  # the whole trace in memory
    (["record.chunk_ticks=0"], "record.chunk_ticks", "0"),
    (["filter.start_time=3600", "duration=0.5"], "filter.start_time", "3600"),
    (["record.qps=true", "filter.enabled=false"], "record.qps", "True"),
    (["max_memory_gb=0"], "max_memory_gb", "0"),
    (["physics_rate_hz=50", "control_rate_hz=50"], "physics_rate_hz", "50"),
    (["record.qps_every=0"], "record.qps_every", "0"),
    (["record.reference_every=-1"], "record.reference_every", "-1"),
    (["record.reference_tol_nm=0"], "record.reference_tol_nm", "0"),
    (["progress=maybe"], "progress", "'maybe'"),
    # controller, filter, robot
    (["controller.period=1e6"], "controller.period", "1000000.0"),
    (["controller.duty=0.999"], "controller.duty", "0.999"),
    (["controller.kp=1e9"], "controller.kp", "1000000000.0"),
    (["filter.enabled=maybe"], "filter.enabled", "'maybe'"),
    (["filter.regularization=1e6"], "filter.regularization", "1000000.0"),
    (["filter.lambda_min_n=1e6"], "filter.lambda_min_n", "1000000.0"),
    (["filter.contact_velocity_gain=1e9"], "filter.contact_velocity_gain", "1000000000.0"),
    (["filter.ecbf.alpha2=1e9"], "filter.ecbf.alpha2", "1000000000.0"),
    (["robot.torque_limit_nm=1e9"], "robot.torque_limit_nm", "1000000000.0"),
    (["robot.fall_height_m=5"], "robot.fall_height_m", "5"),
    (["robot.init_joint_noise_rad=10"], "robot.init_joint_noise_rad", "10"),
    # scenarios (checked by the scenario classes)
    (["scenario.friction=1e6"], "scenario.friction", "1000000.0"),
    (["scenario=obstacle", "scenario.coefficients=[0,0,100]"], "scenario.coefficients", "[0, 0, 100]"),
    (["scenario=friction_patch", "scenario.friction_after=abc"], "scenario.friction_after", "'abc'"),
    (["scenario=friction_patch", "scenario.change_at_m=nan"], "scenario.change_at_m", "nan"),
    (["scenario=perturbed", "scenario.trunk_com_shift_m=[5,0,0]"], "scenario.trunk_com_shift_m[0]", "5"),
    (
        ["scenario=perturbed", "scenario.motor_strength_scale=1e6"],
        "scenario.motor_strength_scale",
        "1000000.0",
    ),
    (
        ["scenario=perturbed", "scenario.actuator_delay_steps=1e9"],
        "scenario.actuator_delay_steps",
        "1000000000.0",
    ),
    (
        ["scenario=push", "scenario.pushes=[{t_s:1,force_n:[0,nan,0],duration_s:0.1}]"],
        "scenario.pushes[0].force_n[1]",
        "nan",
    ),
    (
        ["scenario=push", "scenario.pushes=[{t:1,force_n:[0,60,0],duration_s:0.1}]"],
        "scenario.pushes[0]",
        "'t': 1",
    ),
    # solvers (checked by the backends, then on a trivial QP)
    (["solver=proxqp", "solver.settings.max_iter=0"], "solver.settings.max_iter", "0"),
    (["solver=clarabel", "solver.settings.tol_feas=-1"], "solver.settings.tol_feas", "-1"),
    (["solver=daqp", "solver.check.primal=-1"], "solver.check.primal", "-1"),
    (["solver=reference", "solver.agree_u_nm=-1"], "solver.agree_u_nm", "-1"),
    (["solver=piqp", "solver.backend=gpu"], "solver.backend", "'gpu'"),
    (
        ["solver=osqp", "+solver.settings.no_such_setting=1"],
        "solver.settings",
        "'no_such_setting': 1",
    ),
    # estimators (checked by the estimator classes)
    (["estimator=fixed", "estimator.mu=1e6"], "estimator.mu", "1000000.0"),
    (["estimator=mlp", "estimator.conservative_k=-1"], "estimator.conservative_k", "-1"),
    (["estimator=mlp", "estimator.mu_min=-1"], "estimator.mu_min", "-1"),
    (["estimator=mlp", "estimator.threads=0"], "estimator.threads", "0"),
]


@pytest.fixture
def no_episode(monkeypatch: pytest.MonkeyPatch) -> None:
    """Fail the test if anything is simulated."""

    def simulated(self: Episode, *args: object, **kwargs: object) -> None:
        raise AssertionError("Episode.run was called: the bad value was simulated")

    monkeypatch.setattr(Episode, "run", simulated)


def assert_refused(overrides: list[str], out_dir: Path, *expected: str) -> str:
    """Run ``overrides`` into ``out_dir`` as the command line does (its checks, then the run): a refusal whose
    message holds every ``expected`` text, and an empty run folder. A value of the wrong type is refused by the
    command line's check (Hydra would refuse to compose it); a value out of range by the run's validation.
    Returns the message."""
    with pytest.raises((ConfigError, CliError)) as err:
        try:
            cfg = compose_cfg(overrides)
        except ConfigCompositionException:
            check_overrides(overrides)  # names the field and its range, where Hydra's type error does not
            raise
        run(cfg, out_dir)
    message = str(err.value)
    for text in expected:
        assert text in message, f"{text!r} not in {message!r}"
    assert not out_dir.exists() or sorted(p.name for p in out_dir.iterdir()) == []  # nothing written
    return message


@pytest.mark.parametrize(("overrides", "field", "value"), FAULTS, ids=[" ".join(f[0]) for f in FAULTS])
def test_bad_value_is_refused_naming_field_and_value(overrides, field, value, tmp_path, no_episode):
    message = assert_refused(overrides, tmp_path, f"{field}=", value)
    assert message.index(field) < message.index(value)  # "field=value: rule"


def test_range_errors_say_what_is_valid(tmp_path, no_episode):
    message = assert_refused(["scenario=obstacle", "scenario.height_m=-1"], tmp_path, "scenario.height_m")
    assert message == "scenario.height_m=-1: must be a finite number in [0, 0.2] [m]"
    message = assert_refused(["filter.fallback=pray"], tmp_path / "choice", "filter.fallback")
    assert message == "filter.fallback='pray': valid: nominal, hold_last"
    message = assert_refused(["controller.speed=100"], tmp_path / "speed", "controller.speed")
    assert "[0, 2.67395] [m/s]" in message  # stroke 2 sqrt(0.38² - 0.27²) over period x duty = 0.2 s


def _garbage_mjcf(tmp_path: Path) -> tuple[list[str], Path]:
    path = tmp_path / "robot.xml"
    path.write_bytes(b"\x8f this is not XML at all \x00\x01 <<<")
    return [f"robot.plant_mjcf={path}"], path


def _truncated_weights(tmp_path: Path) -> tuple[list[str], Path]:
    shutil.copy(CHECKPOINTS / "attention.json", tmp_path / "cut.json")
    (tmp_path / "cut.pt").write_bytes((CHECKPOINTS / "attention.pt").read_bytes()[:20_000])
    return ["estimator=attention", f"estimator.checkpoint={tmp_path / 'cut'}"], tmp_path / "cut.pt"


def _corrupt_metadata(tmp_path: Path) -> tuple[list[str], Path]:
    shutil.copy(CHECKPOINTS / "attention.pt", tmp_path / "bad.pt")
    (tmp_path / "bad.json").write_text((CHECKPOINTS / "attention.json").read_text()[:500])
    return ["estimator=attention", f"estimator.checkpoint={tmp_path / 'bad'}"], tmp_path / "bad.json"


@pytest.mark.parametrize(
    ("make", "field"),
    [
        (_garbage_mjcf, "robot.plant_mjcf"),
        (_truncated_weights, "estimator.checkpoint"),
        (_corrupt_metadata, "estimator.checkpoint"),
    ],
    ids=["random-text MJCF", "truncated checkpoint weights", "truncated checkpoint metadata"],
)
def test_unreadable_file_is_refused_naming_field_and_file(make, field, tmp_path, no_episode):
    overrides, path = make(tmp_path)
    assert_refused(overrides, tmp_path / "run", field, str(path))


def test_error_summary_of_a_job_with_an_invalid_seed(tmp_path):
    """In a sweep the job's error is recorded (seed -1), also when the seed itself cannot be read (a seed of the
    wrong type, seed=abc, is refused before: Hydra cannot compose it into the schema's int)."""
    cfg = compose_cfg(["seed=${oops}"])
    try:
        run(cfg, tmp_path / "run")
    except Exception as exc:  # what __main__ does in a multirun
        summary = record_job_error(tmp_path / "run", {"scenario": "flat"}, cfg, exc)
    assert summary["seed"] == -1 and summary["status"] == "error" and "seed" in summary["message"]


def test_single_run_with_a_bad_seed_exits_naming_the_field(tmp_path):
    """``python -m taslel_bench seed=abc``: non-zero exit, the field and value in stderr, no run files."""
    cmd = [sys.executable, "-m", "taslel_bench", "seed=abc", f"hydra.run.dir={tmp_path}"]
    out = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=120, check=False)
    assert out.returncode != 0
    assert out.returncode == 2 and "seed='abc': must be an integer in [0, " in out.stderr
    assert not (tmp_path / "summary.json").exists() and not (tmp_path / "steps.parquet").exists()
