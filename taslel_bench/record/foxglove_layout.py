"""The Foxglove layout shipped with the harness (``conf/foxglove/layout.json``, built with
``foxglove.layouts`` of foxglove-sdk): a 3D panel following the trunk (the robot, terrain, force arrows and
barrier spheres of :mod:`taslel_bench.record.scene`) beside plots of the forward speed, the vertical ground
reaction force per foot (MuJoCo's and the filter's), the smallest barrier value h per foot, the QP solve
time, and mu with mu_hat; a log panel of the events below.

``python -m taslel_bench.record.foxglove_layout`` rewrites the shipped file (the tests check it is current).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import foxglove.layouts as fl

from taslel_bench.robot import quadruped as quad

LAYOUT_PATH = Path(__file__).resolve().parents[2] / "conf" / "foxglove" / "layout.json"
LEG_COLORS = {"FL": "#1f77b4", "FR": "#d62728", "RL": "#2ca02c", "RR": "#9467bd"}


def _plot(title: str, series: list[tuple[str, str]], y_label: str, **series_options) -> fl.PlotPanel:
    paths = [fl.PlotSeries(value=value, label=label, timestamp_method="receiveTime", **series_options)
             for value, label in series]  # fmt: skip
    return fl.PlotPanel(title=title, config=fl.PlotConfig(paths=paths, y_axis_label=y_label, show_legend=True,
                                                          legend_display="floating", is_synced=True))  # fmt: skip


def _three_d() -> fl.ThreeDeePanel:
    scene_topics: dict[str, fl.BaseRendererTopicSettings] = {
        topic: fl.BaseRendererSceneUpdateTopicSettings(visible=True)
        for topic in ("/scene/robot", "/scene/terrain", "/scene/contact")}  # fmt: skip
    return fl.ThreeDeePanel(title="robot (trunk followed; blue: MuJoCo contact force, orange: filter lambda)",
                            config=fl.ThreeDeeConfig(
                                follow_tf=quad.TRUNK_BODY, fixed_frame="world", follow_mode="follow-position",
                                camera_state=fl.ThreeDeeCameraState(distance=1.6, phi=65.0, theta_offset=135.0,
                                                                    perspective=True, target_offset=(0.0, 0.0, 0.0)),
                                topics=scene_topics,
                                layers={"grid": fl.BaseRendererGridLayerSettings(visible=True, frame_id="world")},
                            ))  # fmt: skip


def _plots() -> list[fl.PlotPanel]:
    grf = [(f"/contact_force.{leg}.plant_w_n.z", f"{leg} MuJoCo f_z [N]") for leg in quad.LEGS]
    grf += [(f"/contact_force.{leg}.filter_w_n.z", f"{leg} filter lambda_z [N]") for leg in quad.LEGS]
    return [
        _plot("Forward speed", [("/base_state.linvel_w_mps.x", "trunk v_x (world) [m/s]")], "m/s"),
        _plot("Vertical ground reaction force", grf, "N"),
        _plot("Barrier h per swing foot (smallest family)",
              [(f"/barrier.{leg}.h_m", f"{leg} h [m]") for leg in quad.LEGS], "m"),
        _plot("QP solve time", [("/qp.solve_us", "solve [µs]"), ("/qp.build_us", "build [µs]")], "µs"),
        _plot("Friction", [("/friction.mu_true", "mu under the trunk"), ("/friction.mu_hat", "mu_hat (filter)")]
              + [(f"/contact_force.{leg}.mu_foot", f"mu under {leg}") for leg in quad.LEGS], "-"),
    ]  # fmt: skip


def layout() -> fl.Layout:
    plots = fl.SplitContainer(direction="column", items=[fl.SplitItem(content=p) for p in _plots()])
    top = fl.SplitContainer(direction="row", items=[fl.SplitItem(proportion=3, content=_three_d()),
                                                    fl.SplitItem(proportion=2, content=plots)])  # fmt: skip
    logs = fl.LogPanel(title="Events (QP failures, falls, errors)", config=fl.LogConfig(topic_to_render="/log"))
    return fl.Layout(content=fl.SplitContainer(direction="column", items=[
        fl.SplitItem(proportion=5, content=top), fl.SplitItem(proportion=1, content=logs)]))  # fmt: skip


def layout_json() -> str:
    return json.dumps(json.loads(layout().to_json()), indent=1) + "\n"


def main(argv: list[str] | None = None) -> None:
    path = Path((argv or sys.argv[1:] or [str(LAYOUT_PATH)])[0])
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(layout_json())
    print(path)


if __name__ == "__main__":
    main()
