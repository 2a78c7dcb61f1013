"""A run's identity comes from the content of what it uses, not from git: a rerun is skipped only when
nothing it depends on changed (the plant file MuJoCo really reads through nested includes, code added as
README's "Extending" says, a copy without ``.git``). Each test failed on the main of before."""

from __future__ import annotations

import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import mujoco
import pytest

from taslel_bench.plant.mjcf_files import mjcf_files
from taslel_bench.sim.run import config_sha256, run
from tests.conftest import compose_cfg

ROOT = Path(__file__).resolve().parent.parent
TINY = ["duration=0.2", "progress=false", "record.mcap=false"]
BODY = '<mujoco><worldbody><body name="{name}"><freejoint/><geom size="0.1" mass="1"/></body></worldbody></mujoco>\n'


def nested_include(folder: Path) -> Path:
    """``main.xml`` includes ``sub/wrap.xml``, which includes ``a1.xml``; both ``a1.xml`` and ``sub/a1.xml``
    exist with different bodies (``top`` / ``sub``)."""
    (folder / "sub").mkdir(parents=True)
    (folder / "main.xml").write_text('<mujoco><include file="sub/wrap.xml"/></mujoco>\n')
    (folder / "sub" / "wrap.xml").write_text('<mujoco><include file="a1.xml"/></mujoco>\n')
    (folder / "a1.xml").write_text(BODY.format(name="top"))
    (folder / "sub" / "a1.xml").write_text(BODY.format(name="sub"))
    return folder / "main.xml"


@pytest.mark.parametrize("keep", ["both", "top only", "sub only"])
def test_nested_include_is_the_file_mujoco_reads(tmp_path, keep):
    """The listed plant files hold the file MuJoCo compiled (checked against MuJoCo itself, whichever
    candidates exist), so an edit of the file MuJoCo reads changes the identity."""
    main = nested_include(tmp_path / "m")
    if keep == "top only":
        (tmp_path / "m" / "sub" / "a1.xml").unlink()
    elif keep == "sub only":
        (tmp_path / "m" / "a1.xml").unlink()
    read = mujoco.MjModel.from_xml_path(str(main)).body(1).name  # the body of the file MuJoCo read
    used = tmp_path / "m" / ("a1.xml" if read == "top" else "sub/a1.xml")
    assert used.resolve() in mjcf_files(main)
    assert (tmp_path / "m" / ("sub/a1.xml" if read == "top" else "a1.xml")).resolve() not in mjcf_files(main)


def test_edit_of_the_nested_included_file_mujoco_reads_changes_the_identity(tmp_path):
    from taslel_bench.plant.build import robot_spec

    folder = tmp_path / "m"
    (folder / "sub").mkdir(parents=True)
    (folder / "main.xml").write_text('<mujoco model="scene"><include file="sub/wrap.xml"/></mujoco>\n')
    (folder / "sub" / "wrap.xml").write_text('<mujoco><include file="a1.xml"/></mujoco>\n')
    (folder / "a1.xml").write_text(robot_spec().to_xml())
    (folder / "sub" / "a1.xml").write_text(robot_spec().to_xml())  # a stale copy MuJoCo does not read
    cfg = compose_cfg([f"robot.plant_mjcf={folder / 'main.xml'}", *TINY])
    before = config_sha256(cfg)
    (folder / "a1.xml").write_text((folder / "a1.xml").read_text().replace('mass="6.001"', 'mass="7"'))
    assert config_sha256(cfg) != before


def test_a_new_untracked_scenario_module_is_part_of_the_identity(tmp_path):
    """Code added as README's "Extending" says: a new file in ``scenarios/`` named by ``_target_``; editing
    it gives another identity (git's diff of tracked files does not see it)."""
    module = ROOT / "scenarios" / "_identity_probe_flat.py"
    assert not module.exists()
    module.write_text("from scenarios.flat import FlatGround\n\n\nclass ProbeFlat(FlatGround):\n    pass\n")
    try:
        cfg = compose_cfg(["scenario._target_=scenarios._identity_probe_flat.ProbeFlat", *TINY])
        before = config_sha256(cfg)
        module.write_text(module.read_text() + "\n\nSPEED_SCALE = 2.0  # an edit\n")
        assert config_sha256(cfg) != before
    finally:
        module.unlink(missing_ok=True)


def test_a_target_module_outside_the_project_is_hashed_with_what_it_imports(tmp_path, monkeypatch):
    from taslel_bench.sim.run import identity_of

    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "__init__.py").write_text("")
    (tmp_path / "mine" / "flat2.py").write_text("from scenarios.flat import FlatGround as Flat2\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    cfg = compose_cfg(["scenario._target_=mine.flat2.Flat2", *TINY])
    first = identity_of(cfg)
    assert {"mine.flat2", "scenarios.flat"} <= set(first.record()["code"])
    (tmp_path / "mine" / "flat2.py").write_text("from scenarios.flat import FlatGround as Flat2\nX = 1\n")
    assert identity_of(cfg).config_sha256 != first.config_sha256


def test_an_untracked_config_file_of_a_choice_is_hashed():
    from taslel_bench.sim.run import identity_of

    rec = identity_of(compose_cfg(TINY), (), {"scenario": "flat", "solver": "osqp"}).record()
    assert {"config.yaml", "scenario/flat.yaml", "solver/osqp.yaml"} <= set(rec["config"])


def test_a_copy_without_git_sees_its_code_edits(tmp_path):
    """A tarball or a non-editable install has no ``.git``: the identity still changes with the code."""
    copy = tmp_path / "copy"
    for name in ("taslel_bench", "scenarios", "solvers", "estimators", "hydra_plugins", "conf"):
        shutil.copytree(ROOT / name, copy / name, ignore=shutil.ignore_patterns("__pycache__"))
    probe = textwrap.dedent("""
        from hydra import compose, initialize_config_dir
        from taslel_bench.sim.run import config_sha256
        from taslel_bench.util.provenance import code_version
        with initialize_config_dir(config_dir=r"{conf}", version_base="1.3"):
            cfg = compose(config_name="config", overrides=["duration=0.2"])
        print(code_version()["git_commit"], config_sha256(cfg))
    """).format(conf=copy / "conf")

    def identity() -> tuple[str, str]:
        out = subprocess.run([sys.executable, "-c", probe], cwd=tmp_path, capture_output=True, text=True,
                             env={"PATH": "/usr/bin:/bin", "PYTHONPATH": str(copy), "HOME": str(tmp_path)},
                             check=True)  # fmt: skip
        commit, sha = out.stdout.split()[-2:]
        return commit, sha

    commit, before = identity()
    assert commit == "unknown"  # really no git here
    target = copy / "taslel_bench" / "filter" / "safety_filter.py"
    target.write_text(target.read_text() + "\n# an edit of the filter\n")
    assert identity()[1] != before


def test_summary_records_what_the_identity_hashed(tmp_path):
    summary = run(compose_cfg(TINY), tmp_path / "run", {"scenario": "flat", "solver": "daqp"})
    rec = summary["identity"]
    assert "taslel_bench.filter.safety_filter" in rec["code"] and "scenarios.flat" in rec["code"]
    assert "solver/daqp.yaml" in rec["config"] and len(rec["plant"]) == 1 and "mujoco" in rec["packages"]
    again = run(compose_cfg(TINY), tmp_path / "run", {"scenario": "flat", "solver": "daqp"})
    assert again.get("skipped") is True  # nothing changed: reused
