"""Launchers of conf/hydra/launcher/: each composes, a missing package names its pip extra, and a 2-job
sweep runs end to end on a local Ray instance and on submitit_local (subprocesses, tiny episodes)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
from hydra import compose, initialize_config_dir

from taslel_bench.sweep.launchers import LauncherNotInstalled, check_launcher_overrides
from tests.conftest import CONF_DIR

ROOT = Path(__file__).resolve().parent.parent
LAUNCHERS = sorted(p.stem for p in (ROOT / "conf" / "hydra" / "launcher").glob("*.yaml"))
TINY = ["duration=0.3", "progress=false", "record.mcap=false"]


def launcher_node(name: str) -> dict:
    with initialize_config_dir(config_dir=CONF_DIR, version_base="1.3"):
        cfg = compose(config_name="config", overrides=[f"hydra/launcher={name}"], return_hydra_config=True)
    return dict(cfg.hydra.launcher)


def test_launcher_options_are_the_documented_three():
    assert LAUNCHERS == ["local", "ray", "slurm"]


@pytest.mark.parametrize(
    ("name", "target_class", "key", "value"),
    [
        ("local", "RobustJoblibLauncher", "n_jobs", -1),  # -1: every core of the machine, not a fixed count
        ("ray", "RayLauncher", "address", "local"),  # a new local Ray instance, whatever runs on the node
        ("slurm", "SlurmLauncher", "timeout_min", 30),
    ],
)
def test_launcher_config_composes_to_a_hydra_plugin(name, target_class, key, value):
    node = launcher_node(name)
    assert node["_target_"].startswith("hydra_plugins.") and node["_target_"].endswith("." + target_class)
    assert node[key] == value


@pytest.mark.parametrize(
    ("launcher", "extra"), [("ray", "ray"), ("slurm", "slurm"), ("submitit_local", "slurm")]
)
def test_missing_launcher_package_names_the_pip_extra(launcher, extra):
    def nothing_installed(module):
        return False

    hint = rf'hydra/launcher={launcher} needs .*pip install -e "\.\[{extra}\]"'
    with pytest.raises(LauncherNotInstalled, match=hint):
        check_launcher_overrides(["-m", f"hydra/launcher={launcher}", "seed=0,1"], nothing_installed)
    check_launcher_overrides(["-m", "hydra/launcher=local"], nothing_installed)  # joblib: a core dependency


def test_slurm_without_submitit_exits_with_the_hint_before_running(tmp_path):
    """`python -m taslel_bench -m hydra/launcher=slurm` where hydra-submitit-launcher cannot be imported."""
    code = (
        "import runpy, sys; sys.modules['hydra_plugins.hydra_submitit_launcher'] = None; "
        f"sys.argv = ['taslel_bench', '-m', 'hydra/launcher=slurm', 'hydra.sweep.dir={tmp_path}']; "
        "runpy.run_module('taslel_bench', run_name='__main__')"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=120, check=False
    )
    assert out.returncode == 1
    assert "hydra/launcher=slurm needs hydra-submitit-launcher, which is not installed" in out.stderr
    assert 'pip install -e ".[slurm]"' in out.stderr
    assert not any(tmp_path.iterdir())  # nothing launched


@pytest.mark.parametrize(
    "launcher_args",
    [["hydra/launcher=ray", "hydra.launcher.num_cpus=2"], ["hydra/launcher=submitit_local"]],
    ids=["ray_local_instance", "submitit_local"],
)
def test_two_job_sweep_through_launcher(tmp_path, launcher_args):
    cmd = [sys.executable, "-m", "taslel_bench", "-m", *launcher_args, "seed=0,1", *TINY,
           f"hydra.sweep.dir={tmp_path}"]  # fmt: skip
    # a dead cluster address in the environment: the ray launcher must still start its own local instance
    env = {**os.environ, "RAY_ADDRESS": "127.0.0.1:1"}
    out = subprocess.run(cmd, cwd=ROOT, env=env, capture_output=True, text=True, timeout=600, check=False)
    assert out.returncode == 0, out.stderr[-3000:]
    summaries = sorted(tmp_path.glob("*/summary.json"))
    assert [p.parent.name for p in summaries] == ["duration=0.3,seed=0", "duration=0.3,seed=1"]
    table = pd.read_parquet(tmp_path / "summary.parquet")
    assert len(table) == 2 and sorted(table["seed"]) == [0, 1] and (table["status"] == "ok").all()
    assert "sweep: 2 runs (0 with errors)" in out.stdout
