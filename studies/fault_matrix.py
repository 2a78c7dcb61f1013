"""The fault matrix: bad input, interruption, concurrency and corrupted files, each case tried on the
importable taslel_bench and judged "well" (refused naming the field/file, result kept, table complete, exit
code truthful) or "badly". Runs on any checkout (it only uses ``run``, ``config_sha256``, the CLIs and the
fault injector of tests/fault_injection/), so the same matrix measures the main of before and after:

    PYTHONPATH=<checkout> python studies/fault_matrix.py [--only substring]

Prints one line per case and the count; studies/notes/reliability.md records both checkouts' counts.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import re
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
INJECTOR = HERE.parent / "tests" / "fault_injection"  # this checkout's injector (the old one has none)
TINY = ["duration=0.2", "progress=false", "record.mcap=false"]
TETRA = "v 0 0 0\nv 0.1 0 0\nv 0 0.1 0\nv 0 0 0.1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"
CASES: list[tuple[str, str, Callable[[Path], tuple[bool, str]]]] = []


def case(klass: str, name: str):
    def add(fn):
        CASES.append((klass, name, fn))
        return fn

    return add


def root() -> Path:
    import taslel_bench

    return Path(taslel_bench.__file__).resolve().parent.parent


def cfg(overrides: list[str]):
    from hydra import compose, initialize_config_dir

    with initialize_config_dir(config_dir=str(root() / "conf"), version_base="1.3"):
        return compose(config_name="config", overrides=list(overrides))


def run(overrides: list[str], out: Path) -> dict:
    from taslel_bench.sim.run import run as run_one

    with contextlib.redirect_stderr(io.StringIO()):
        return run_one(cfg([*TINY, *overrides]), out)


def cli(*args: str, env: dict | None = None, module: str = "taslel_bench") -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", module, *args], cwd=root(), capture_output=True, text=True,
                          timeout=900, check=False, env={**os.environ, **(env or {})})  # fmt: skip


class Simulated(Exception):
    """The bad value reached the episode (it was not refused)."""


def refused(overrides: list[str], out: Path, *texts: str) -> tuple[bool, str]:
    """Refused before simulating, the message holding ``texts`` (the episode is replaced by one that
    raises :class:`Simulated`: an accepted ``duration=3600`` must not run for an hour here)."""
    from taslel_bench.sim.episode import Episode

    def simulated(self, *args, **kwargs):
        raise Simulated

    original, Episode.run = Episode.run, simulated
    try:
        run(overrides, out)
    except Simulated:
        return False, "accepted: it would have been simulated"
    except Exception as exc:  # any error is the case's answer: its message is checked
        msg = f"{type(exc).__name__}: {exc}"
        return all(t in msg for t in texts), msg.splitlines()[0][:160]
    finally:
        Episode.run = original
    return False, "accepted"


def scene(folder: Path) -> Path:
    from taslel_bench.plant.build import robot_spec

    (folder / "assets").mkdir(parents=True, exist_ok=True)
    (folder / "assets" / "tetra.obj").write_text(TETRA)
    xml = re.sub(r"<compiler ([^/]*)/>", r'<compiler \1 meshdir="assets"/>\n  <asset><mesh name="tetra" '
                                         r'file="tetra.obj"/></asset>',
                 robot_spec().to_xml(), count=1)
    xml = xml.replace('<site name="imu"/>', '<site name="imu"/>\n      <geom type="mesh" mesh="tetra" contype="0" '
                                            'conaffinity="0" density="0" group="3"/>', 1)  # fmt: skip
    (folder / "robot.xml").write_text(xml)
    (folder / "scene.xml").write_text('<mujoco model="scene">\n  <include file="robot.xml"/>\n</mujoco>\n')
    return folder / "scene.xml"


def sha(overrides: list[str], files=()) -> str:
    from taslel_bench.sim import run as run_module

    try:
        return run_module.config_sha256(cfg(overrides), files)
    except TypeError:  # an older signature without input files
        return run_module.config_sha256(cfg(overrides))


# ------------------------------------------------------------------------------------------------- stale


@case("stale", "included robot file changed -> another identity")
def _(tmp: Path):
    s = scene(tmp / "s")
    before = sha([f"robot.plant_mjcf={s}"])
    (tmp / "s" / "robot.xml").write_text((tmp / "s" / "robot.xml").read_text().replace('mass="6.001"', 'mass="7"'))
    return sha([f"robot.plant_mjcf={s}"]) != before, ""


@case("stale", "mesh of the plant changed -> another identity")
def _(tmp: Path):
    s = scene(tmp / "s")
    before = sha([f"robot.plant_mjcf={s}"])
    (tmp / "s" / "assets" / "tetra.obj").write_text(TETRA.replace("0.1 0 0", "0.3 0 0"))
    return sha([f"robot.plant_mjcf={s}"]) != before, ""


@case("stale", "changed included robot: rerun, not 'already complete'")
def _(tmp: Path):
    s = scene(tmp / "s")
    run([f"robot.plant_mjcf={s}"], tmp / "run")
    (tmp / "s" / "robot.xml").write_text((tmp / "s" / "robot.xml").read_text().replace('mass="6.001"', 'mass="7"'))
    again = run([f"robot.plant_mjcf={s}"], tmp / "run")
    return "skipped" not in again, "skipped" if "skipped" in again else "rerun"


def _ckpt(tmp: Path) -> Path:
    src = root() / "estimators" / "checkpoints"
    (tmp / "c").mkdir(parents=True, exist_ok=True)
    for suffix in (".pt", ".json"):
        shutil.copy(src / f"mlp{suffix}", tmp / "c" / f"mlp{suffix}")
    return tmp / "c" / "mlp"


@case("stale", "checkpoint with NaN weights refused")
def _(tmp: Path):
    import torch

    c = _ckpt(tmp)
    state = torch.load(c.with_suffix(".pt"), weights_only=True)
    key = next(k for k, v in state.items() if v.is_floating_point() and v.numel() > 1)
    state[key].view(-1)[0] = float("nan")
    torch.save(state, c.with_suffix(".pt"))
    return refused(["estimator=mlp", f"estimator.checkpoint={c}"], tmp / "run", "estimator.checkpoint")


@case("stale", "checkpoint content changed at the same path -> another identity")
def _(tmp: Path):
    from taslel_bench.sim.build import Built

    c = _ckpt(tmp)
    over = ["estimator=mlp", f"estimator.checkpoint={c}", *TINY]
    built = Built(cfg(over))
    files = list(built.estimator.input_files()) if hasattr(built.estimator, "input_files") else []
    before = sha(over, files)
    c.with_suffix(".json").write_text(c.with_suffix(".json").read_text().replace("{", '{"retrained": 1, ', 1))
    return sha(over, files) != before, ""


@case("stale", "code version in the identity")
def _(tmp: Path):
    probe = ("from hydra import compose, initialize_config_dir\nfrom taslel_bench.sim.run import config_sha256\n"
             f"with initialize_config_dir(config_dir=r'{root() / 'conf'}', version_base='1.3'):\n"
             "    print(config_sha256(compose(config_name='config', overrides=['duration=0.2'])))\n")  # fmt: skip

    def identity() -> str:
        out = subprocess.run([sys.executable, "-c", probe], cwd=tmp, capture_output=True, text=True, check=True)
        return out.stdout.split()[-1]

    source = root() / "scenarios" / "flat.py"  # a module every default run imports
    before, text = identity(), source.read_text()
    try:
        source.write_text(text + "\n# an edit\n")
        return identity() != before, ""
    finally:
        source.write_text(text)


def cli_probe(code: str) -> tuple[bool, str]:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=False)
    return out.stdout.strip() == "True", out.stdout.strip() or out.stderr.strip()[-100:]


@case("stale", "filter.start_time=3600 duration=0.5 refused")
def _(tmp: Path):
    return refused(["filter.start_time=3600", "duration=0.5"], tmp / "run", "filter.start_time")


@case("stale", "record.qps=true with filter.enabled=false refused")
def _(tmp: Path):
    return refused(["record.qps=true", "filter.enabled=false"], tmp / "run", "record.qps")


# ---------------------------------------------------------------------------------------------- writers


@case("writers", "-m seed=0,0 refused before start (exit 2, both named)")
def _(tmp: Path):
    out = cli("-m", "seed=0,0", *TINY, f"hydra.sweep.dir={tmp}")
    return out.returncode == 2 and "#1 (seed=0" in out.stderr, f"exit {out.returncode}"


@case("writers", "-m record.mcap=true,false refused before start")
def _(tmp: Path):
    out = cli("-m", "record.mcap=true,false", *TINY[:2], f"hydra.sweep.dir={tmp}")
    return out.returncode == 2, f"exit {out.returncode}"


@case("writers", "folder written by a live process: refused, its files untouched")
def _(tmp: Path):
    out = tmp / "run"
    out.mkdir()
    (out / "episode.partial.mcap").write_bytes(b"live")
    with _lock_holder(out):  # a live process that took the folder's lock
        ok, msg = refused([], out, "being written")
    return ok and (out / "episode.partial.mcap").is_file(), msg


@contextlib.contextmanager
def _lock_holder(folder: Path):
    """A live process holding ``folder``'s run lock (through the checkout's own RunLock) for the block."""
    holder = subprocess.Popen([sys.executable, "-c", ("import sys; from taslel_bench.record.run_lock import RunLock; "
                               f"l = RunLock(r'{folder}').acquire(); print('held', flush=True); sys.stdin.read()")],
                              cwd=root(), stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)  # fmt: skip
    try:
        holder.stdout.readline()
        yield holder
    finally:
        holder.kill()
        holder.wait()


@case("writers", "stale lock of a dead process taken over")
def _(tmp: Path):
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    out = tmp / "run"
    out.mkdir()
    (out / "run.lock").write_text(json.dumps({"pid": p.pid, "host": socket.gethostname(), "started": "x"}))
    s = run([], out)
    return s.get("status") == "ok", str(s.get("stale_lock_taken_over", ""))


# -------------------------------------------------------------------------------------------- superseded


def _rerun_keeps(tmp: Path, damage: Callable[[Path], None], overrides: list[str] = ()) -> tuple[bool, str]:
    out = tmp / "run"
    run(list(overrides), out)
    damage(out)
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    s = run(list(overrides), out)
    moved = out / str(s.get("superseded", "-"))
    kept = moved.is_dir() and all((moved / n).is_file() and (moved / n).read_bytes() == b for n, b in before.items())
    return kept, str(s.get("superseded", "overwritten"))


@case("superseded", "truncated summary.json kept under superseded/")
def _(tmp: Path):
    return _rerun_keeps(tmp, lambda out: (out / "summary.json").write_text((out / "summary.json").read_text()[:100]))


@case("superseded", "deleted steps.parquet: the rest kept under superseded/")
def _(tmp: Path):
    return _rerun_keeps(tmp, lambda out: (out / "steps.parquet").unlink())


@case("superseded", "truncated steps.parquet kept under superseded/")
def _(tmp: Path):
    def cut(out: Path) -> None:
        data = (out / "steps.parquet").read_bytes()
        (out / "steps.parquet").write_bytes(data[: len(data) // 2])

    return _rerun_keeps(tmp, cut)


@case("superseded", "killed after episode.mcap was final: kept under superseded/")
def _(tmp: Path):
    return _rerun_keeps(tmp, lambda out: (out / "summary.json").unlink(), ["record.mcap=true"])


@case("superseded", "old traceback.txt does not stay in a folder that is now ok")
def _(tmp: Path):
    from taslel_bench.sim.run import record_job_error

    out = tmp / "run"
    try:
        raise RuntimeError("first attempt")
    except RuntimeError as exc:
        record_job_error(out, {}, cfg(TINY), exc)
    run([], out)
    return not (out / "traceback.txt").exists(), ""


# -------------------------------------------------------------------------------------------- the table


def _three(tmp: Path) -> Path:
    for seed in (0, 1, 2):
        run([f"seed={seed}"], tmp / "sweep" / f"seed={seed}")
    return tmp / "sweep"


def _report(sweep: Path) -> tuple[bool, str]:
    out = cli(str(sweep), module="taslel_bench.report")
    tail = (out.stderr.strip().splitlines() or [""])[-1][:120]
    return out.returncode in (0, 1) and "Traceback" not in out.stderr and (sweep / "report.md").is_file(), tail


@case("table", "report with a truncated steps.parquet: error row, no crash")
def _(tmp: Path):
    sweep = _three(tmp)
    p = sweep / "seed=0" / "steps.parquet"
    p.write_bytes(p.read_bytes()[:5000])
    return _report(sweep)


@case("table", "report with a corrupt config.yaml: no crash")
def _(tmp: Path):
    sweep = _three(tmp)
    (sweep / "seed=1" / "config.yaml").write_text("scenario: [unclosed\n  : :")
    ok, msg = _report(sweep)
    return ok, msg


@case("table", "report with summary.json holding a JSON list: no crash")
def _(tmp: Path):
    sweep = _three(tmp)
    (sweep / "seed=2" / "summary.json").write_text("[1, 2]\n")
    return _report(sweep)


@case("table", "report of a sweep with an error run exits non-zero")
def _(tmp: Path):
    sweep = _three(tmp)
    s = json.loads((sweep / "seed=0" / "summary.json").read_text())
    s["status"] = "error"
    (sweep / "seed=0" / "summary.json").write_text(json.dumps(s))
    out = cli(str(sweep), module="taslel_bench.report")
    return out.returncode == 1, f"exit {out.returncode}"


def _sweep(tmp: Path, seeds: str, faults: str = "", extra: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    env = {"PYTHONPATH": os.pathsep.join([str(INJECTOR), str(root())]), "TASLEL_FAULTS": faults}
    return cli("-m", f"seed={seeds}", *TINY, *extra, f"hydra.sweep.dir={tmp / 'sweep'}", env=env)


def _table(tmp: Path):
    import pandas as pd

    p = tmp / "sweep" / "summary.parquet"
    return pd.read_parquet(p) if p.is_file() else None


@case("table", "a SIGKILLed worker: error row, the rest run, table, exit 1")
def _(tmp: Path):
    out = _sweep(tmp, "0,1,2", "kill=seed=1")
    t = _table(tmp)
    ok = t is not None and len(t) == 3 and (t["status"] == "ok").sum() == 2 and out.returncode == 1
    return ok, f"exit {out.returncode}, rows {None if t is None else len(t)}"


@case("table", "ENOSPC at one run's writer: error row, table, exit 1")
def _(tmp: Path):
    out = _sweep(tmp, "0,1", "enospc=seed=1")
    t = _table(tmp)
    ok = t is not None and len(t) == 2 and (t["status"] == "error").sum() == 1 and out.returncode == 1
    return ok, f"exit {out.returncode}, rows {None if t is None else len(t)}"


@case("table", "a sweep with a refused job exits 1 (table written)")
def _(tmp: Path):
    out = cli("-m", "controller.kp=100,-1", *TINY, f"hydra.sweep.dir={tmp / 'sweep'}")
    return out.returncode == 1 and _table(tmp) is not None, f"exit {out.returncode}"


@case("table", "failing report at the sweep's end: exit non-zero, one line")
def _(tmp: Path):
    sweep = _three(tmp)
    from omegaconf import OmegaConf

    from taslel_bench.sweep import callback

    def broken(*a, **k):
        raise RuntimeError("report failed")

    callback.write_report = broken
    err = io.StringIO()
    try:
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            callback.SweepCallback().on_multirun_end(OmegaConf.create({"hydra": {"sweep": {"dir": str(sweep)}}}))
    except Exception as exc:  # Hydra turns this into a UserWarning and exits 0
        return False, f"raised {type(exc).__name__} (Hydra: a warning, exit 0)"
    code = callback.exit_code() if hasattr(callback, "exit_code") else 0
    return code == 1 and "report failed" in err.getvalue(), f"exit code {code}"


@case("table", "single run refused: exit code 2")
def _(tmp: Path):
    out = cli("controller.kp=-1", f"hydra.run.dir={tmp}")
    return out.returncode == 2, f"exit {out.returncode}"


# --------------------------------------------------------------------------------------- sizing, messages


@case("messages", "duration=3600 accepted in chunks; with the whole trace in memory refused with an estimate")
def _(tmp: Path):
    chunked, said = refused(["duration=3600"], tmp / "run", "GB")
    whole, why = refused(["duration=3600", "record.chunk_ticks=null"], tmp / "whole", "GB", "record.chunk_ticks")
    return (not chunked and said.startswith("accepted") and whole), why


@case("messages", "missing mesh: error names robot.plant_mjcf and the file")
def _(tmp: Path):
    s = scene(tmp / "s")
    (tmp / "s" / "assets" / "tetra.obj").unlink()
    return refused([f"robot.plant_mjcf={s}"], tmp / "run", "robot.plant_mjcf", str((tmp / "s" / "assets").resolve()))


@case("messages", "massless body: error names robot.plant_mjcf")
def _(tmp: Path):
    s = scene(tmp / "s")
    robot = tmp / "s" / "robot.xml"
    robot.write_text(robot.read_text().replace('<site name="imu"/>', '<site name="imu"/><body name="x"><joint '
                                               'type="slide"/></body>', 1))  # fmt: skip
    return refused([f"robot.plant_mjcf={s}"], tmp / "run", "robot.plant_mjcf", "mjMINVAL")


@case("messages", "unnamed foot spheres: 'name these 4 spheres' hint")
def _(tmp: Path):
    from taslel_bench.plant.build import robot_spec
    from taslel_bench.robot import quadruped as quad

    spec = robot_spec()
    for e in list(spec.sensors) + list(spec.sites):
        spec.delete(e)
    for f in quad.FOOT_FRAMES:
        spec.geom(f).name = ""
    (tmp / "a1.xml").write_text(spec.to_xml())
    return refused([f"robot.plant_mjcf={tmp / 'a1.xml'}"], tmp / "run", "name these 4 spheres")


def _one_line(out: subprocess.CompletedProcess, name: str) -> tuple[bool, str]:
    lines = out.stderr.strip().splitlines()
    ok = out.returncode != 0 and len(lines) == 1 and name in lines[0] and "Traceback" not in out.stderr
    return ok, (lines[-1] if lines else "")[:140]


@case("messages", "qpset info of a non-npz file: one line naming it")
def _(tmp: Path):
    (tmp / "bad.npz").write_text("hello")
    return _one_line(cli("info", str(tmp / "bad.npz"), module="taslel_bench.qpset"), str(tmp / "bad.npz"))


@case("messages", "qpset info of a set missing an array: one line naming it")
def _(tmp: Path):
    good = root() / "tests" / "data" / "qps_episode.npz"
    with np.load(good) as d:
        np.savez(tmp / "cut.npz", **{k: d[k] for k in d.files if not k.startswith("g0__P")})
    return _one_line(cli("info", str(tmp / "cut.npz"), module="taslel_bench.qpset"), str(tmp / "cut.npz"))


@case("messages", "qpset info of a pickled npz: one line naming it")
def _(tmp: Path):
    np.savez(tmp / "p.npz", format=np.array([{"a": 1}], dtype=object))
    return _one_line(cli("info", str(tmp / "p.npz"), module="taslel_bench.qpset"), str(tmp / "p.npz"))


@case("messages", "qpset merge into a missing folder: names the output, not a temp file")
def _(tmp: Path):
    good = root() / "tests" / "data" / "qps_episode.npz"
    out = cli("merge", str(good), "-o", str(tmp / "nope" / "m.npz"), module="taslel_bench.qpset")
    return _one_line(out, str(tmp / "nope"))


@case("messages", "replay repeats=0 refused before any work")
def _(tmp: Path):
    good = root() / "tests" / "data" / "qps_episode.npz"
    out = cli(str(good), "solver=daqp", "repeats=0", f"hydra.run.dir={tmp}", module="taslel_bench.replay")
    return _one_line(out, "repeats")


@case("messages", "replay with an unknown mode refused before any work")
def _(tmp: Path):
    good = root() / "tests" / "data" / "qps_episode.npz"
    out = cli(str(good), "solver=daqp", "modes=[cold,hot]", "repeats=1", f"hydra.run.dir={tmp}",
              module="taslel_bench.replay")  # fmt: skip
    return _one_line(out, "modes")

# -------------------------------------------------------------------------------------- identity (content)


@case("identity", "nested include: the file MuJoCo reads changed -> another identity")
def _(tmp: Path):
    from taslel_bench.plant.build import robot_spec

    (tmp / "m" / "sub").mkdir(parents=True)
    (tmp / "m" / "main.xml").write_text('<mujoco model="scene"><include file="sub/wrap.xml"/></mujoco>\n')
    (tmp / "m" / "sub" / "wrap.xml").write_text('<mujoco><include file="a1.xml"/></mujoco>\n')
    for f in (tmp / "m" / "a1.xml", tmp / "m" / "sub" / "a1.xml"):
        f.write_text(robot_spec().to_xml())
    over = [f"robot.plant_mjcf={tmp / 'm' / 'main.xml'}"]
    before = sha(over)
    # MuJoCo looks in the main file's folder first (checked: tests/test_reliability_identity.py)
    read = tmp / "m" / "a1.xml"
    read.write_text(read.read_text().replace('mass="6.001"', 'mass="7"'))
    return sha(over) != before, ""


@case("identity", "new untracked scenario module edited -> another identity")
def _(tmp: Path):
    module = root() / "scenarios" / "_fault_matrix_probe.py"
    module.write_text("from scenarios.flat import FlatGround\n\n\nclass Probe(FlatGround):\n    pass\n")
    try:
        over = ["scenario._target_=scenarios._fault_matrix_probe.Probe"]
        before = sha(over)
        module.write_text(module.read_text() + "\nEDITED = True\n")
        return sha(over) != before, ""
    finally:
        module.unlink(missing_ok=True)


@case("identity", "copy without .git: a code edit -> another identity")
def _(tmp: Path):
    copy = tmp / "copy"
    for name in ("taslel_bench", "scenarios", "solvers", "estimators", "hydra_plugins", "conf"):
        shutil.copytree(root() / name, copy / name, ignore=shutil.ignore_patterns("__pycache__"))
    probe = ("from hydra import compose, initialize_config_dir\nfrom taslel_bench.sim.run import config_sha256\n"
             f"with initialize_config_dir(config_dir=r'{copy / 'conf'}', version_base='1.3'):\n"
             "    cfg = compose(config_name='config', overrides=['duration=0.2'])\nprint(config_sha256(cfg))\n")

    def identity() -> str:
        env = {"PATH": os.environ.get("PATH", ""), "PYTHONPATH": str(copy), "HOME": str(tmp)}
        return subprocess.run([sys.executable, "-c", probe], cwd=tmp, env=env, capture_output=True, text=True,
                              check=True).stdout.split()[-1]  # fmt: skip

    before = identity()
    target = copy / "taslel_bench" / "filter" / "safety_filter.py"
    target.write_text(target.read_text() + "\n# edited\n")
    return identity() != before, ""


# -------------------------------------------------------------------------------------------------- outcome


@case("outcome", "sweep job that cannot write its folder: error row, not the old summary; exit 1")
def _(tmp: Path):
    first = _sweep(tmp, "0")
    out = _sweep(tmp, "0", "eacces=seed=0")
    t = _table(tmp)
    ok = first.returncode == 0 and t is not None and (t["status"] == "error").all() and out.returncode == 1
    return ok, f"exit {out.returncode}, statuses {None if t is None else list(t['status'])}"


# ---------------------------------------------------------------------------------------------------- locks


@case("locks", "lock left by a killed pid-1 run (container) taken over")
def _(tmp: Path):
    out = tmp / "run"
    out.mkdir()
    (out / "run.lock").write_text(json.dumps({"pid": 1, "host": socket.gethostname(), "started": "x"}))
    try:
        s = run([], out)
    except Exception as exc:  # any error is the case's answer
        return False, f"{type(exc).__name__}: {str(exc)[:100]}"
    return s.get("status") == "ok", str(s.get("stale_lock_taken_over", ""))


@case("locks", "stale lock released to 4 processes at once: one holder (15 trials)")
def _(tmp: Path):
    race = [sys.executable, "-m", "studies.lock_race", str(tmp), "15"]  # 15 trials
    out = subprocess.run(race, cwd=root(), capture_output=True, text=True, timeout=600, check=False)
    over = out.stdout.strip()
    return over == "0", f"{over or out.stderr[-100:]} of 15 trials had more than one holder"




# ------------------------------------------------------------------------------------------------ launchers


@case("launchers", "submitit_local with one job killed: error row, table, exit 1")
def _(tmp: Path):
    out = _sweep(tmp, "0,1", "kill=seed=1", ("hydra/launcher=submitit_local",))
    t = _table(tmp)
    ok = t is not None and len(t) == 2 and (t["status"] == "ok").sum() == 1 and out.returncode == 1
    return ok, f"exit {out.returncode}, rows {None if t is None else len(t)}"


@case("launchers", "report killed between summary.parquet and report.md: a reader can tell")
def _(tmp: Path):
    run([], tmp / "sweep" / "seed=0")
    first = cli(str(tmp / "sweep"), module="taslel_bench.report")
    kill = ("import os, signal, taslel_bench.sweep.report as r\n"  # killed once summary.parquet is written
            "r.write_report = lambda *a, **k: os.kill(os.getpid(), signal.SIGKILL)\n"
            f"r.main([r'{tmp / 'sweep'}'])\n")  # fmt: skip
    killed = subprocess.run([sys.executable, "-c", kill], cwd=root(), capture_output=True, text=True, check=False)
    again = cli(str(tmp / "sweep"), module="taslel_bench.report")
    told = "table_set.json is missing" in again.stderr
    return first.returncode == 0 and killed.returncode != 0 and told, again.stderr.strip()[:140]


# --------------------------------------------------------------------------------------------- interruption


def _interrupted(tmp: Path, signum: int) -> tuple[subprocess.Popen, str]:
    run_dir = tmp / "run"
    proc = subprocess.Popen([sys.executable, "-m", "taslel_bench", "duration=30", "progress=false",
                             "record.chunk_ticks=500", f"hydra.run.dir={run_dir}"], cwd=root(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)  # fmt: skip
    deadline = time.monotonic() + 300
    while not list(run_dir.glob(".steps.parquet.tmp-*")) and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.2)
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=300)
    return proc, err


@case("interruption", "Ctrl-C mid-run: one line, summary interrupted with the time, readable files, exit 130")
def _(tmp: Path):
    proc, err = _interrupted(tmp, signal.SIGINT)
    lines = [line for line in err.splitlines() if line.strip()]
    summary = json.loads((tmp / "run" / "summary.json").read_text()) if (tmp / "run" / "summary.json").is_file() else {}
    readable = (tmp / "run" / "steps.parquet").is_file() and (tmp / "run" / "episode.mcap").is_file()
    ok = proc.returncode == 130 and len(lines) == 1 and summary.get("status") == "interrupted" and readable
    return ok, f"exit {proc.returncode}, {len(lines)} stderr lines, status {summary.get('status')}"


@case("interruption", "SIGTERM mid-run: summary interrupted, exit 143")
def _(tmp: Path):
    proc, _ = _interrupted(tmp, signal.SIGTERM)
    summary = json.loads((tmp / "run" / "summary.json").read_text()) if (tmp / "run" / "summary.json").is_file() else {}
    return proc.returncode == 143 and summary.get("status") == "interrupted", f"exit {proc.returncode}"


@case("interruption", "a refused value creates no run folder")
def _(tmp: Path):
    out = cli("controller.kp=-1", f"hydra.run.dir={tmp / 'r'}")
    return out.returncode == 2 and not (tmp / "r").exists(), f"exit {out.returncode}, folder {(tmp / 'r').exists()}"


@case("interruption", "report during a live sweep: a live job is running, not crashed")
def _(tmp: Path):
    from taslel_bench.sweep.aggregate import collect

    job = tmp / "seed=0"
    (job / ".hydra").mkdir(parents=True)
    (job / ".hydra" / "config.yaml").write_text("seed: 0\n")
    (job / ".hydra" / "overrides.yaml").write_text("- seed=0\n")
    with _lock_holder(job):
        row = collect(tmp).iloc[0]
    return row["status"] == "running", f"{row['status']}: {row['message']}"[:140]


# --------------------------------------------------------------------------------------------------- timing


@case("timing", "a run records its CPU share and each solve's thread CPU time")
def _(tmp: Path):
    import pandas as pd

    s = run(["solver=osqp"], tmp / "run")
    steps = pd.read_parquet(tmp / "run" / "steps.parquet")
    ok = "machine_cpu_share" in s and "machine_busy" in s and "qp_solve_cpu_us" in steps
    return ok, f"machine_cpu_share {s.get('machine_cpu_share')}"


@case("timing", "busy machine: verdict from thread CPU time, says it was busy")
def _(tmp: Path):
    import pandas as pd

    from taslel_bench.sweep.solver_verdict import solver_verdict

    rows = []
    for solver, cpu_us in (("osqp", 90.0), ("clarabel", 330.0)):
        (tmp / solver).mkdir()
        wall = np.full(1000, cpu_us)
        wall[::33] = 8500.0  # waited for a CPU
        pd.DataFrame({"qp_solve_us": wall, "qp_solve_cpu_us": np.full(1000, cpu_us), "qp_iterations": 10,
                      "qp_u_error_nm": np.where(np.arange(1000) % 10 == 0, 1e-6, np.nan),
                      "qp_status": 0}).to_parquet(tmp / solver / "steps.parquet")  # fmt: skip
        rows.append({"scenario": "flat", "solver": solver, "status": "ok", "run_dir": solver, "control_rate_hz": 1000.0,
                     "qp_reference_tol_nm": 1e-3, "machine_busy": True, "machine_cpu_share": 0.41})  # fmt: skip
    text, _ = solver_verdict(tmp, pd.DataFrame(rows), ["scenario", "solver"])
    line = next((x for x in text.splitlines() if x.startswith("**flat**")), "")
    return "machine busy: CPU share 0.41" in line and "ship **osqp**" in line, line[:140]


@case("timing", "bench tool refuses --out from a disturbed run unless --allow-busy")
def _(tmp: Path):
    code = ("import taslel_bench.qp.tick_bench as b\n"  # the watch reports a busy machine (CPU share 0.41)
            "from taslel_bench.util.machine import CpuShare, CpuWatch\n"
            "class Busy(CpuWatch):\n"
            "    def __exit__(self, *e): self.result = CpuShare(1.0, 0.41, 0.45, 3.0, 3.5, 0.0, 900.0)\n"
            "b.CpuWatch = Busy\nb.part_costs = lambda built, trace=None: {}\nb._print_table = lambda r, a: None\n"
            f"b.main(['--duration', '0.1', '--solvers', 'daqp', '--formulations', 'condensed', '--out', "
            f"r'{tmp / 't.md'}'])\n")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], cwd=root(), capture_output=True, text=True, check=False)
    ok = out.returncode == 1 and "machine busy" in out.stderr and not (tmp / "t.md").exists()
    return ok, (out.stderr.strip().splitlines() or [""])[-1][:140]

def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="run the cases whose name holds this text")
    ap.add_argument("--klass", default="", help="run the cases of this class (stale, writers, superseded, table, "
                                                "messages, identity, outcome, locks, launchers, interruption, timing)")
    args = ap.parse_args()
    print(f"taslel_bench from {root()}")
    good = tried = 0
    for klass, name, fn in CASES:
        if args.only not in name or args.klass not in klass:
            continue
        with tempfile.TemporaryDirectory() as tmp:
            try:
                ok, detail = fn(Path(tmp))
            except Exception as exc:  # a crash of the case is a bad behaviour
                ok, detail = (
                    False,
                    f"crashed: {type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"[:160],
                )
                if os.environ.get("FAULT_MATRIX_DEBUG"):
                    traceback.print_exc()
        tried += 1
        good += bool(ok)
        print(f"{'well ' if ok else 'BADLY'} [{klass}] {name}: {detail}", flush=True)
    print(f"{good}/{tried} cases behave well")


if __name__ == "__main__":
    main()
