"""What an identification writes: the ``model`` override file (``model=identified model.from=<file>``) and, beside
it, the fit report (``<stem>.report.md``: parameters with their intervals, replay residuals before and after, the
machine and code), the same as data (``<stem>.fit.json``) and mujoco.sysid's HTML report (``<stem>.sysid.html``)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from taslel_bench.identify.fit import CONFIDENCE, SIGNALS, SPECS, FitResult
from taslel_bench.record.run_files import atomic_write
from taslel_bench.util.machine import machine_info

IDENTIFIED_TO = 0.10  # a field whose interval half-width exceeds this share of its value is "not identified"


def companion(out: Path, suffix: str) -> Path:
    """The file beside ``out`` with ``suffix`` (``lossy.yaml`` -> ``lossy.report.md``)."""
    return out.with_name(out.stem + suffix)


def model_values(fit: FitResult) -> dict[str, Any]:
    """The fitted fields as ``model.*`` values (one number, or a list), and the plant's discrete damping step."""
    values: dict[str, Any] = {k: v[0] if len(v) == 1 and k != "trunk_com_shift_m" else list(v)
                              for k, v in fit.value.items()}
    values["implicit_damping_dt_s"] = fit.physics_dt_s
    return values


def _number(x: float) -> str:
    return f"{x:.9g}"


def _yaml_value(value: Any) -> str:
    return f"[{', '.join(_number(v) for v in value)}]" if isinstance(value, list) else _number(value)


def write_model_file(out: Path, fit: FitResult) -> None:
    """The override file: a ``model:`` mapping, one key a line with its unit and interval."""
    lines = ["# The controller's model identified with mujoco.sysid by python -m taslel_bench.identify from",
             *(f"#   {run}" for run in fit.runs),
             f"# Use it: python -m taslel_bench model=identified model.from={out}",
             f"# Fit report beside it: {companion(out, '.report.md').name}", "model:"]
    for key, value in model_values(fit).items():
        if key in SPECS:
            half = ", ".join(_number(h) for h in fit.interval[key])
            note = f"[{SPECS[key].unit}] +- {half} ({CONFIDENCE:.0%})"
        else:
            note = "[s] the plant's physics step: MuJoCo integrates joint damping implicitly (discrete model)"
        lines.append(f"  {key}: {_yaml_value(value)}  # {note}")
    atomic_write(out, lambda tmp: tmp.write_text("\n".join(lines) + "\n"))


def identified(value: list[float], half: list[float], scale: float) -> bool:
    """Every component's interval within :data:`IDENTIFIED_TO` of its value (of the field's typical scale where
    the value is smaller)."""
    return all(h <= IDENTIFIED_TO * max(abs(v), scale) for v, h in zip(value, half, strict=True))


def parameter_rows(fit: FitResult) -> list[str]:
    """The markdown table of the parameters."""
    rows = ["| field | unit | URDF | identified | 95 % half-width | plant (run config) | error | identified to 10 % |",
            "|---|---|---|---|---|---|---|---|"]
    for key, value in fit.value.items():
        spec, plant = SPECS[key], (fit.plant or {}).get(key)
        err = "n/a" if plant is None else ", ".join(_relative(v, p) for v, p in zip(value, plant, strict=True))
        rows.append(f"| {key} | {spec.unit} | {_list(fit.urdf[key])} | {_list(value)} | {_list(fit.interval[key])} "
                    f"| {'n/a' if plant is None else _list(plant)} | {err} "
                    f"| {'yes' if identified(value, fit.interval[key], spec.scale) else 'no'} |")
    return rows


def _relative(value: float, truth: float) -> str:
    """The error against the truth: relative where the truth is not 0, else absolute (in the field's unit)."""
    if truth != 0.0:
        return f"{(value - truth) / abs(truth):+.2%}"
    return f"{value - truth:+.2g} (abs)"


def _list(values: list[float]) -> str:
    return ", ".join(f"{v:.6g}" for v in values)


def write_report(out: Path, fit: FitResult) -> Path:
    """``<stem>.report.md`` and ``<stem>.fit.json`` beside ``out``; returns the report's path."""
    info = machine_info()
    lines = [f"# Identified model: {out.name}", "",
             f"Fitted with mujoco.sysid (`python -m taslel_bench.identify`) to {fit.walking_s:.1f} s of walking from "
             f"{len(fit.runs)} run(s), {fit.windows} replay windows of {fit.window_s * 1e3:.0f} ms (each replayed from "
             f"its recorded state under the recorded torques); {fit.iterations} optimizer iterations, "
             f"{fit.seconds:.1f} s.", "", *(f"- `{run}`" for run in fit.runs), "",
             f"## Parameters ({CONFIDENCE:.0%} intervals from the Jacobian and the residual variance)", "",
             *parameter_rows(fit), "",
             "## Replay residual (RMS, predicted minus recorded)", "",
             "| signal | URDF values | identified |", "|---|---|---|",
             *(f"| {k} | {fit.rms_before[k]:.4g} | {fit.rms_after[k]:.4g} |" for k in SIGNALS), "",
             *correlations(fit), "",
             f"mujoco.sysid's report: `{companion(out, '.sysid.html').name}`; the numbers: "
             f"`{companion(out, '.fit.json').name}`.", "",
             "## Machine", "", *(f"- {k}: {v}" for k, v in info.items()), ""]
    report = companion(out, ".report.md")
    atomic_write(report, lambda tmp: tmp.write_text("\n".join(lines)))
    data = {k: v for k, v in vars(fit).items() if k != "sysid"} | {"machine": info, "model": model_values(fit)}
    atomic_write(companion(out, ".fit.json"), lambda tmp: tmp.write_text(json.dumps(data, indent=1) + "\n"))
    return report


def correlations(fit: FitResult) -> list[str]:
    """The strongest parameter correlations of the fit's covariance (|r| > 0.5), as lines."""
    cov = np.asarray(fit.sysid.get("covariance", np.zeros((0, 0))))
    names = [f"{k}[{i}]" if len(v) > 1 else k for k, v in fit.value.items() for i in range(len(v))]
    if cov.size == 0:
        return []
    sd = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    corr = cov / np.outer(sd, sd)
    pairs = sorted(((abs(corr[i, j]), i, j) for i in range(len(sd)) for j in range(i)), reverse=True)
    strong = [f"- {names[i]} / {names[j]}: {corr[i, j]:+.2f}" for r, i, j in pairs if r > 0.5][:8]
    return ["## Correlations above 0.5", "", *(strong or ["none"])]


def write_sysid_report(out: Path, fit: FitResult) -> Path:
    """mujoco.sysid's HTML report (its sections: insights, parameters, parameter distribution with the intervals,
    covariance, optimization trace) beside ``out``; the report loads plotly from its CDN."""
    from mujoco.sysid.report.builder import ReportBuilder
    from mujoco.sysid.report.sections.covariance import Covariance
    from mujoco.sysid.report.sections.insights import AutomatedInsights
    from mujoco.sysid.report.sections.optimization_trace import OptimizationTrace
    from mujoco.sysid.report.sections.parameter_distribution import ParameterDistribution
    from mujoco.sysid.report.sections.parameters import ParametersTable

    s = fit.sysid
    initial, opt, result = s["initial"], s["opt"], s["result"]
    intervals = np.concatenate([np.asarray(v, float) for v in fit.interval.values()])
    rb = ReportBuilder(f"Identified model {out.name}")
    rb.add_section(AutomatedInsights("Automated Insights", opt))
    rb.add_section(ParametersTable("Parameters", opt, initial, anchor="parameters"))
    rb.add_section(ParameterDistribution("Parameter Distribution", opt, initial, confidence_intervals=intervals,
                                         anchor="param_dist"))
    rb.add_section(Covariance("Covariance and Correlation", s["covariance"], opt, anchor="cov"))
    extras = result.get("extras", {})
    if extras.get("objective"):
        rb.add_section(OptimizationTrace("Optimization Trace", extras["objective"], extras["candidate"],
                                         bounds=opt.get_bounds(), param_names=opt.get_non_frozen_parameter_names(),
                                         anchor="opt"))
    path = companion(out, ".sysid.html")
    html = rb.build()
    atomic_write(path, lambda tmp: tmp.write_text(html))
    return path
