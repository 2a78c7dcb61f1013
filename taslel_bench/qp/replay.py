"""Replay a QP test set (:mod:`taslel_bench.record.qpset`) through QP backends: the exact solver comparison.

    python -m taslel_bench.replay <set.npz>                            # every conf/solver backend
    python -m taslel_bench.replay <set.npz> -m solver=osqp,clarabel    # Hydra multirun, one job per backend
    python -m taslel_bench.replay <set.npz> solver=daqp repeats=1 'profiles=[high_accuracy]'

(configuration: ``conf/replay.yaml``). For every backend, settings profile and mode, the QPs are solved run
by run in tick order (warm starts never cross runs), ``repeats`` passes:

* ``cold``: ``reset()`` before every QP (no initial guess, solver set up from scratch);
* ``warm``: the backend's previous answer as initial guess (``warm_start=true``; backends that cannot use a
  guess report the mode as unavailable);
* ``persistent``: ``solver=<name>``, set up once per layout and updated in place.

``cold`` and ``warm`` run the qpsolvers route of the solver (``solver=qpsolvers solver.name=<name>``).

Per QP and pass: the backend's status (success = ``"solved"``), correctness checked *here* (u within
``tolerances.u_nm`` of the tight reference ``conf/solver/reference.yaml``, primal residual, and dual
residual + duality gap when the backend returns duals -- a "solved" answer with a wrong u is wrong), the
wall time of the ``solve`` call, the backend's own split of it (native ``solve_time_s``, ``overhead_s``:
conversions + its answer check), the time of the replay's check, and the filter's build time recorded in
the run. Tables and figures: :mod:`taslel_bench.qp.replay_report`.

The core never imports the solver packages: backends are built from ``conf/solver/*.yaml`` ``_target_``
entries; one that cannot be built (package missing) is reported as unavailable and the others still run.
"""

from __future__ import annotations

import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from hydra.experimental.callback import Callback  # hydra-core >= 1.3.2 (a dependency) has it
from omegaconf import DictConfig, OmegaConf

from taslel_bench.config.compose import CONF_DIR
from taslel_bench.interfaces import SOLVED, QPBackend, QPProblem
from taslel_bench.qp.replay_report import JOB_INFO, QP_TABLE, write_report
from taslel_bench.record import qpset, run_files
from taslel_bench.util.fields import plain_dict

SOLVER_DIR = CONF_DIR / "solver"
MODES = ("cold", "warm", "persistent")


@dataclass(frozen=True)
class Tolerances:
    u_nm: float = 1e-3  # [N·m]
    primal: float = 1e-6
    dual: float = 1e-5
    gap: float = 1e-5  # [(N·m)²]


# ---------------------------------------------------------------------------------------- correctness


def kkt_residuals(p: QPProblem, x: np.ndarray, y, z, z_box) -> tuple[float, float, float]:
    """(primal, dual, gap) in the qpsolvers dual convention (P x + q + A'y + G'z + z_box = 0, z >= 0);
    dual and gap are NaN without duals. Identically-zero G rows are constants: their multiplier is ignored.
    (Computed here, independently of the backends' own checks.)"""
    primal = max(
        float(np.abs(p.A @ x - p.b).max()) if p.A.shape[0] else 0.0,
        float((p.G @ x - p.h).max()) if p.G.shape[0] else 0.0,
        float((p.lb - x).max()), float((x - p.ub).max()),
    )  # fmt: skip
    if y is None or z is None or z_box is None:
        return primal, float("nan"), float("nan")
    z = np.asarray(z) * p.G.any(axis=1)
    Px = p.P @ x
    dual = float(np.abs(Px + p.q + y @ p.A + z @ p.G + z_box).max())
    bound = np.where(z_box < 0.0, p.lb, p.ub)
    act = z_box != 0.0
    gap = abs(float(x @ Px + p.q @ x + p.b @ y + p.h @ z + bound[act] @ z_box[act]))
    return primal, dual, gap


def judge(p: QPProblem, sol, x_ref: np.ndarray, tol: Tolerances) -> dict[str, Any]:
    """Success (the backend says solved) and correctness (checked here) of one answer."""
    x = getattr(sol, "x", None)
    status = str(getattr(sol, "status", "no solution"))
    out = {"status": status, "success": status == SOLVED and x is not None, "correct": False,
           "du_nm": np.nan, "primal": np.nan, "dual": np.nan, "gap": np.nan}  # fmt: skip
    if x is None or not np.all(np.isfinite(x)):
        out["success"] = False
        return out
    u = p.layout.get("u", slice(None))
    out["du_nm"] = float(np.abs(x[u] - x_ref[u]).max()) if np.all(np.isfinite(x_ref)) else np.nan
    y, z, zb = (getattr(sol, k, None) for k in ("y", "z", "z_box"))
    out["primal"], out["dual"], out["gap"] = kkt_residuals(p, x, y, z, zb)
    ok = out["success"] and out["du_nm"] <= tol.u_nm and out["primal"] <= tol.primal
    ok = ok and not (out["dual"] > tol.dual) and not (out["gap"] > tol.gap)  # NaN (no duals) passes
    out["correct"] = bool(ok)
    return out


# --------------------------------------------------------------------------------------- backends


class Unavailable(Exception):
    """A backend (or mode) that cannot run here; the message says why."""


def solver_conf(name: str) -> DictConfig:
    path = SOLVER_DIR / f"{name}.yaml"
    if not path.is_file():
        raise Unavailable(f"no conf/solver/{name}.yaml")
    cfg = OmegaConf.load(path)
    if not isinstance(cfg, DictConfig):
        raise Unavailable(f"conf/solver/{name}.yaml: not a mapping")
    return cfg


def base_names() -> list[str]:
    """Backends a ``solver=all`` replay covers: the conf/solver files except the reference, the qpsolvers
    route (the cold and warm modes of every name) and the old names that only refuse."""
    stems = sorted(p.stem for p in SOLVER_DIR.glob("*.yaml"))
    return [s for s in stems if s not in ("reference", "qpsolvers") and not s.endswith("_persistent")]


def _per_call(cfg: DictConfig) -> bool:
    """A conf/solver entry of the qpsolvers route (set up on every call)."""
    return str(cfg.get("_target_", "")).startswith("solvers.qpsolvers_backend.")


def backend_conf(name: str, mode: str, overrides: dict[str, Any]) -> tuple[str, DictConfig]:
    """(conf name, config) of backend ``name`` in ``mode``, with a profile's ``overrides``
    (``{"all": {...}, "qpsolvers": {...}, "<conf name>": {...}}``, "qpsolvers" for every per-call backend)
    applied. ``persistent``: ``conf/solver/<name>.yaml``; ``cold`` and ``warm``: the qpsolvers route of the
    same solver (``conf/solver/qpsolvers.yaml`` with ``name``, conf name ``qpsolvers:<name>``)."""
    base = name.removeprefix("qpsolvers:")
    own = solver_conf(base)
    if mode == "persistent":
        if _per_call(own):
            raise Unavailable(f"no persistent backend (conf/solver/{base}.yaml is the qpsolvers route)")
        conf_name, cfg = base, own
    elif _per_call(own):
        conf_name, cfg = base, own
    else:
        conf_name, cfg = f"qpsolvers:{base}", solver_conf("qpsolvers")
        cfg["name"] = base
    keys = ("all", "qpsolvers", conf_name) if _per_call(cfg) else ("all", conf_name)
    for key in keys:
        for k, v in dict(overrides.get(key) or {}).items():
            cfg[k] = v
    if mode == "warm":
        cfg["warm_start"] = True
    return conf_name, cfg


def make_backend(cfg: DictConfig | dict) -> QPBackend:
    """Instantiate a ``_target_`` config; any failure becomes :class:`Unavailable`."""
    from hydra.utils import instantiate

    try:
        return instantiate(cfg)
    except Exception as exc:
        cause = exc
        while cause.__cause__ is not None:
            cause = cause.__cause__
        raise Unavailable(f"{type(cause).__name__}: {str(cause).splitlines()[0] if str(cause) else ''}") from exc


# ------------------------------------------------------------------------------------------ replay


def reference_solutions(qs: qpset.QPSet, reference: QPBackend | None = None) -> np.ndarray:
    """Fill the set's missing ``x_ref`` with the tight reference (``conf/solver/reference.yaml``); return a
    bool mask of the QPs that have one (the reference refuses when its two solvers disagree)."""
    have = np.array([np.all(np.isfinite(qs.x_ref_of(i))) for i in range(len(qs))], bool)
    if not have.all():
        reference = reference or make_backend(solver_conf("reference"))
        for i in np.flatnonzero(~have):
            sol = reference.solve(qs.problem(int(i)))
            ok = getattr(sol, "ok", False)
            qs.set_x_ref(int(i), sol.x if ok else None)
            have[i] = ok
    return have


def select(qs: qpset.QPSet, max_qps: int = 0) -> list[np.ndarray]:
    """The QP sequences to replay: per run, in tick order (first ``max_qps`` of each when > 0)."""
    return [s[:max_qps] if max_qps > 0 else s for s in qs.sequences()]


def replay_backend(
    qs: qpset.QPSet, factory: Callable[[], QPBackend], mode: str, sequences: list[np.ndarray], repeats: int,
    tol: Tolerances, labels: dict[str, Any],
) -> pd.DataFrame:  # fmt: skip
    """Solve every QP of ``sequences`` ``repeats`` times with a backend from ``factory``; one row per QP and
    pass. Building the problem from the set (values written into a preallocated QPProblem) is not timed."""
    backend = factory()
    scen = qs.scenario()
    rows = []
    perf = time.perf_counter
    for rep in range(repeats):
        for seq in sequences:
            backend.reset()
            for i in seq:
                p = qs.problem(int(i))
                if mode == "cold":
                    backend.reset()
                t0 = perf()
                sol = backend.solve(p)
                call = perf() - t0
                t1 = perf()
                row = judge(p, sol, qs.x_ref_of(int(i)), tol)
                row["check_s"] = perf() - t1
                row.update(
                    repeat=rep, qp=int(i), scenario=str(scen[i]), tick=int(qs.tick[i]), call_s=call,
                    solve_s=float(getattr(sol, "solve_time_s", np.nan)),
                    setup_s=float(getattr(sol, "setup_time_s", np.nan)),
                    overhead_s=float(getattr(sol, "overhead_s", np.nan)),
                    iterations=float(getattr(sol, "iterations", None) or np.nan),
                    build_s=float(qs.build_time_s[i]),
                )  # fmt: skip
                rows.append(row)
    frame = pd.DataFrame(rows)
    for k, v in labels.items():
        frame[k] = v
    return frame


def unavailable_row(labels: dict[str, Any], reason: str) -> pd.DataFrame:
    return pd.DataFrame([{**labels, "status": f"unavailable: {reason}", "success": False, "correct": False,
                          "qp": -1, "repeat": -1}])  # fmt: skip


def replay(
    qs: qpset.QPSet, names: list[str], modes: list[str], profiles: dict[str, dict], repeats: int,
    tol: Tolerances, max_qps: int = 0, log: Callable[[str], None] | None = None,
) -> pd.DataFrame:  # fmt: skip
    """Every backend x profile x mode (see module doc); unavailable combinations give one row saying why."""
    have_ref = reference_solutions(qs)
    seqs = [s[have_ref[s]] for s in select(qs, max_qps)]
    frames = []
    for name in names:
        for profile, overrides in profiles.items():
            for mode in modes:
                labels = {"solver": name, "profile": profile, "mode": mode}
                try:
                    if mode not in MODES:
                        raise Unavailable(f"unknown mode {mode!r}; valid: {', '.join(MODES)}")
                    conf_name, cfg = backend_conf(name, mode, overrides)
                    labels["backend"] = conf_name
                    probe = make_backend(cfg)
                    if mode == "warm" and not getattr(probe, "supports_warm_start", False):
                        raise Unavailable("the solver ignores initial guesses")
                    labels["settings"] = str(probe.describe())
                except Unavailable as exc:
                    frames.append(unavailable_row(labels, str(exc)))
                    if log:
                        log(f"  {name:<18} {profile:<13} {mode:<10} unavailable: {exc}")
                    continue
                t0 = time.perf_counter()
                try:
                    f = replay_backend(qs, lambda c=cfg: make_backend(c), mode, seqs, repeats, tol, labels)
                except Exception as exc:  # a backend bug must not stop the others
                    frames.append(unavailable_row(labels, f"crashed: {type(exc).__name__}: {exc}"))
                    traceback.print_exc()
                    continue
                frames.append(f)
                if log:
                    first = f[f["repeat"] == 0]
                    log(f"  {name:<18} {profile:<13} {mode:<10} success {first.success.mean():6.1%} correct "
                        f"{first.correct.mean():6.1%}  median {np.median(f.solve_s) * 1e6:7.1f} µs "
                        f"({time.perf_counter() - t0:.0f} s)")  # fmt: skip
    out = pd.concat(frames, ignore_index=True)
    out["n_without_reference"] = int((~have_ref).sum())
    return out


def profiles_from(cfg: DictConfig) -> dict[str, dict]:
    all_over = plain_dict(cfg.profile_overrides, "profile_overrides")
    return {p: dict(all_over.get(p) or {}) for p in cfg.profiles}


class ReplayInputError(ValueError):
    """A replay setting or test set that cannot work (the message names the field or the file)."""


def check_settings(cfg: DictConfig) -> None:
    """Refuse bad replay settings before any QP is solved: ``repeats`` >= 1, ``max_qps`` >= 0, known
    ``modes`` and ``profiles``, positive tolerances."""
    def integer(key: str, lo: int) -> None:
        v = cfg.get(key)
        if isinstance(v, bool) or not isinstance(v, int) or v < lo:
            raise ReplayInputError(f"{key}={v!r}: must be an integer >= {lo}")

    integer("repeats", 1)
    integer("max_qps", 0)
    modes = list(cfg.get("modes") or [])
    bad = [m for m in modes if m not in MODES]
    if not modes or bad:
        raise ReplayInputError(f"modes={modes}: valid modes: {', '.join(MODES)} (unknown: {', '.join(map(str, bad))})")
    known = set(cfg.get("profile_overrides") or {})
    profiles = list(cfg.get("profiles") or [])
    bad = [p for p in profiles if p not in known]
    if not profiles or bad:
        raise ReplayInputError(f"profiles={profiles}: valid profiles (profile_overrides): {', '.join(sorted(known))}")
    for key, v in (cfg.get("tolerances") or {}).items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not v > 0:
            raise ReplayInputError(f"tolerances.{key}={v!r}: must be a positive number")


def run_job(cfg: DictConfig, out_dir: Path, solver: str | None = None) -> pd.DataFrame:
    """One replay job (one conf/solver name, or every one when ``solver`` is None): writes
    ``replay_qps.parquet`` into ``out_dir``. Settings and the test set are checked first
    (:class:`ReplayInputError`, :class:`taslel_bench.record.qpset.QPSetError`)."""
    check_settings(cfg)
    qs = qpset.load(cfg.testset)
    out_dir.mkdir(parents=True, exist_ok=True)
    names = base_names() if solver is None else [solver]
    tol = Tolerances(**plain_dict(cfg.tolerances, "tolerances"))
    print(f"replay {cfg.testset}: {len(qs)} QPs, {len(qs.runs)} runs; {', '.join(names)}", file=sys.stderr)
    frame = replay(qs, names, list(cfg.modes), profiles_from(cfg), int(cfg.repeats), tol, int(cfg.max_qps),
                   log=lambda s: print(s, file=sys.stderr, flush=True))  # fmt: skip
    run_files.write_parquet(out_dir / QP_TABLE, frame)
    info = {"testset": str(Path(cfg.testset).resolve()), "n_qps": len(qs), "runs": qs.runs,
            "config": OmegaConf.to_container(cfg, resolve=True)}  # fmt: skip
    run_files.write_json(out_dir / JOB_INFO, info)
    return frame


# -------------------------------------------------------------------------------------------- CLI


class ReplayCallback(Callback):
    """At the end of a replay multirun: one report over every job's table in the sweep folder."""

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        out = Path(config.out) if config.get("out") else sweep_dir
        print(f"replay report: {write_report(sweep_dir, out)}")


def _hydra_main(cfg: DictConfig) -> None:
    from hydra.core.hydra_config import HydraConfig

    hc = HydraConfig.get()
    job_dir = Path(hc.runtime.output_dir)
    try:
        run_job(cfg, job_dir, hc.runtime.choices.get("solver"))  # the solver group option (None: all)
    except (ReplayInputError, qpset.QPSetError) as exc:  # one line, before any QP is solved
        print(f"error: {exc}", file=sys.stderr)
        raise SystemExit(2) from None
    if str(hc.mode) != "RunMode.MULTIRUN":
        out = Path(cfg.out) if cfg.get("out") else job_dir
        print(f"replay report: {write_report(job_dir, out)}")


def main() -> None:
    """``python -m taslel_bench.replay <set> [overrides]``: the first plain argument is the test set."""
    import hydra

    args = sys.argv[1:]
    for k, a in enumerate(args):
        if not a.startswith("-") and "=" not in a and (k == 0 or args[k - 1] not in ("--config-name", "-cn",
                                                                                       "--config-path", "-cp")):
            args = [*args[:k], *args[k + 1 :], f"testset={Path(a).resolve()}"]  # overrides go after flags
            break
    sys.argv = [sys.argv[0], *args]
    hydra.main(config_path=str(CONF_DIR), config_name="replay", version_base="1.3")(_hydra_main)()


if __name__ == "__main__":
    main()
