"""episode.mcap for Foxglove: read back with the ``mcap`` reader, the foxglove protobuf schemas checked by
name and decoded with google.protobuf from the file's own descriptors, and the 3D content checked against
MuJoCo's numbers in steps.parquet (foot positions from the transforms, force arrows, the logs)."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from google.protobuf import descriptor_pb2, descriptor_pool, json_format, message_factory
from mcap.reader import make_reader

from taslel_bench.record import foxglove_layout, scene
from taslel_bench.record.mcap import FINAL_NAME
from taslel_bench.robot import quadruped as quad
from taslel_bench.sim.run import run
from tests.conftest import compose_cfg

FOXGLOVE_SCHEMAS = {"/tf": "foxglove.FrameTransforms", "/scene/robot": "foxglove.SceneUpdate",
                    "/scene/terrain": "foxglove.SceneUpdate", "/scene/contact": "foxglove.SceneUpdate",
                    "/log": "foxglove.Log"}  # fmt: skip


def _decoder(schema):
    pool = descriptor_pool.DescriptorPool()
    files = list(descriptor_pb2.FileDescriptorSet.FromString(schema.data).file)
    while files:
        for f in list(files):
            try:
                pool.Add(f)
                files.remove(f)
            except TypeError:  # a dependency is not in the pool yet
                continue
    cls = message_factory.GetMessageClass(pool.FindMessageTypeByName(schema.name))
    return lambda data: json_format.MessageToDict(cls.FromString(data), preserving_proto_field_name=True)


@pytest.fixture(scope="module")
def logs_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("logs_run")
    before = time.time_ns()
    summary = run(compose_cfg(["scenario=logs", "duration=0.3", "progress=false", "scenario.first_x_m=0.45"]), out,
                  {"scenario": "logs", "solver": "daqp"})  # fmt: skip
    messages: dict[str, list] = {}
    with open(out / FINAL_NAME, "rb") as f:
        reader = make_reader(f)
        decoders = {}
        for schema, channel, message in reader.iter_messages():
            if channel.message_encoding == "protobuf":
                decode = decoders.setdefault(schema.id, _decoder(schema))
                body = decode(message.data)
            else:
                body = json.loads(message.data)
            messages.setdefault(channel.topic, []).append((message.log_time, message.publish_time, body, schema.name))
        metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    return out, summary, messages, metadata, before


def test_foxglove_schemas_by_name_and_log_time_is_wall_clock(logs_run):
    out, _, messages, metadata, before = logs_run
    for topic, name in FOXGLOVE_SCHEMAS.items():
        assert topic in messages and {m[3] for m in messages[topic]} == {name}
    start = int(metadata["run"]["start_unix_ns"])
    assert before <= start <= time.time_ns()
    for topic, rows in messages.items():  # log time = wall-clock start + simulated time (= publish time)
        assert all(log == start + pub for log, pub, _, _ in rows), topic
    steps = pd.read_parquet(out / "steps.parquet")
    every = int(metadata["run"]["record_every_ticks"])
    assert every == 10  # record.mcap_rate_hz=100 at 1 kHz control
    assert len(messages["/tf"]) == len(messages["/contact_force"]) == -(-len(steps) // every)
    assert all("t_s" in body for _, _, body, _ in messages["/contact_force"])  # simulated time in every message


def test_metadata_holds_config_summary_and_versions(logs_run):
    out, _, _, metadata, _ = logs_run
    assert yaml.safe_load(metadata["config"]["config.yaml"]) == yaml.safe_load((out / "config.yaml").read_text())
    saved = json.loads((out / "summary.json").read_text())
    assert metadata["summary"]["status"] == saved["status"] and json.loads(metadata["summary"]["fell"]) == saved["fell"]
    assert metadata["versions"]["mujoco"] and metadata["versions"]["git_commit"] == saved["git_commit"]


def _compose(pos_a, quat_a, pos_b, quat_b):
    """Pose b (in a's frame) composed onto a (in the world): the child in the world."""
    return pos_a + scene.quat_rotate(quat_a, pos_b), scene.quat_multiply(quat_a, quat_b)


def test_transforms_put_each_foot_where_mujoco_measured_it(logs_run):
    """world -> trunk -> hip -> thigh -> calf from /tf, then the foot sphere's offset in the calf (0, 0,
    -0.2): the foot centre MuJoCo's sensor recorded in steps.parquet, to rounding. A row's state is the one
    at the end of its tick, its foot sensors are of the tick's last physics step's starting state: with
    physics at the control rate, the state of row k is the one the sensors of row k + 1 read."""
    out, _, messages, _, _ = logs_run
    steps = pd.read_parquet(out / "steps.parquet")
    by_time = {round(t, 6): i for i, t in enumerate(steps["t_s"])}
    checked = 0
    for _, pub, body, _ in messages["/tf"][:-1:7]:
        row = steps.iloc[by_time[round(pub * 1e-9, 6)] + 1]
        tf = {t["child_frame_id"]: t for t in body["transforms"]}
        assert tf["trunk"]["parent_frame_id"] == "world"
        for leg in quad.LEGS:
            pos, quat = np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
            for link in ("trunk", f"{leg}_hip", f"{leg}_thigh", f"{leg}_calf"):
                t = tf[link]["translation"]
                r = tf[link]["rotation"]
                p_b = np.array([t.get("x", 0.0), t.get("y", 0.0), t.get("z", 0.0)])
                q_b = np.array([r.get("w", 0.0), r.get("x", 0.0), r.get("y", 0.0), r.get("z", 0.0)])
                pos, quat = _compose(pos, quat, p_b, q_b)
            foot = pos + scene.quat_rotate(quat, np.array([0.0, 0.0, -0.2]))
            recorded = row[[f"{leg}_foot_{ax}_w_m" for ax in "xyz"]].to_numpy(float)
            np.testing.assert_allclose(foot, recorded, atol=1e-9)
            checked += 1
    assert checked >= 8


def test_contact_arrows_are_the_recorded_forces(logs_run):
    out, _, messages, _, _ = logs_run
    steps = pd.read_parquet(out / "steps.parquet")
    by_time = {round(t, 6): i for i, t in enumerate(steps["t_s"])}
    arrows = 0
    for _, pub, body, _ in messages["/scene/contact"]:
        row = steps.iloc[by_time[round(pub * 1e-9, 6)]]
        assert body["deletions"][0]["type"] == "ALL"
        for entity in body["entities"]:
            leg = entity["id"].removeprefix("foot_")
            force = row[[f"{leg}_grf_plant_{ax}_w_n" for ax in "xyz"]].to_numpy(float)
            if np.linalg.norm(force) < 1.0:
                continue
            arrow = entity["arrows"][0]  # the plant's arrow comes first
            o = arrow["pose"]["orientation"]
            q = np.array([o.get("w", 0.0), o.get("x", 0.0), o.get("y", 0.0), o.get("z", 0.0)])
            length = arrow["shaft_length"] + arrow["head_length"]
            along = scene.quat_rotate(q, np.array([1.0, 0.0, 0.0])) * length / scene.FORCE_SCALE_M_PER_N
            np.testing.assert_allclose(along, force, atol=1e-4 * max(1.0, np.linalg.norm(force)))
            arrows += 1
    assert arrows > 20


def test_terrain_entities_are_the_plant_logs(logs_run):
    """Each log is a cylinder along world y (plus two end spheres) where MuJoCo's capsule is, of its size."""
    out, _, messages, _, _ = logs_run
    from taslel_bench.record.video import plant_of_run

    m = plant_of_run(out)
    import mujoco

    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)
    entities = messages["/scene/terrain"][-1][2]["entities"]
    logs = [e for e in entities if {"key": "kind", "value": "Log"} in e["metadata"]]
    capsules = [g for g in range(m.ngeom) if m.geom_type[g] == mujoco.mjtGeom.mjGEOM_CAPSULE]
    assert len(logs) == len(capsules) > 0
    for entity, g in zip(logs, capsules, strict=True):
        cyl = entity["cylinders"][0]
        p = cyl["pose"]["position"]
        np.testing.assert_allclose([p.get("x", 0.0), p.get("y", 0.0), p.get("z", 0.0)], d.geom_xpos[g], atol=1e-12)
        assert cyl["size"]["x"] == pytest.approx(2 * m.geom_size[g, 0])
        assert cyl["size"]["z"] == pytest.approx(2 * m.geom_size[g, 1])
        o = cyl["pose"]["orientation"]
        q = np.array([o.get("w", 0.0), o.get("x", 0.0), o.get("y", 0.0), o.get("z", 0.0)])
        axis = scene.quat_rotate(q, np.array([0.0, 0.0, 1.0]))  # the capsule's axis, either way along it
        assert abs(float(axis @ d.geom_xmat[g].reshape(3, 3)[:, 2])) == pytest.approx(1.0, abs=1e-12)
    robot = {e["id"] for e in messages["/scene/robot"][0][2]["entities"]}
    assert {"trunk", "FL_calf"} <= robot


def test_signals_have_named_per_foot_fields(logs_run):
    out, _, messages, _, _ = logs_run
    steps = pd.read_parquet(out / "steps.parquet")
    _, _, body, _ = messages["/contact_force"][5]
    row = steps[np.isclose(steps["t_s"], body["t_s"])].iloc[0]
    assert set(body) == {"t_s", *quad.LEGS}
    assert body["RL"]["plant_w_n"]["z"] == pytest.approx(row["RL_grf_plant_z_w_n"])
    assert body["RL"]["stance"] == bool(row["RL_stance"])
    _, _, joints, _ = messages["/joint_state"][5]
    assert joints["position_rad"]["FR_calf"] == pytest.approx(row["q_FR_calf_rad"])
    _, _, barrier, _ = messages["/barrier"][5]
    # logs: the obstacle family
    assert {"h_m", "obstacle_h_m", "obstacle_h_e_mps", "obstacle_clearance_m"} <= set(barrier["FL"])


def test_the_shipped_layout_is_current_and_names_recorded_fields(logs_run):
    _, _, messages, _, _ = logs_run
    shipped = foxglove_layout.LAYOUT_PATH.read_text()
    assert shipped == foxglove_layout.layout_json()  # python -m taslel_bench.record.foxglove_layout rewrites it
    paths = [s["value"] for s in _panels(json.loads(shipped)) for s in s.get("config", {}).get("paths", [])]
    assert len(paths) >= 10
    for path in paths:  # every plotted path exists in the recorded messages
        topic, *fields = path.split(".")
        node = messages[topic][3][2]
        for f in fields:
            node = node[f]
        assert isinstance(node, (int, float)) or node is None


def _panels(node):
    if isinstance(node, dict):
        if node.get("type") == "panel":
            yield node
        for v in node.values():
            yield from _panels(v)
    elif isinstance(node, list):
        for v in node:
            yield from _panels(v)


def test_every_tick_when_the_rate_is_null(tmp_path):
    run(compose_cfg(["duration=0.1", "progress=false", "filter.enabled=false", "record.mcap_rate_hz=null"]), tmp_path)
    with open(Path(tmp_path) / FINAL_NAME, "rb") as f:
        summary = make_reader(f).get_summary()
    counts = {ch.topic: summary.statistics.channel_message_counts[ch.id] for ch in summary.channels.values()}
    steps = pd.read_parquet(tmp_path / "steps.parquet")
    assert counts["/tf"] == counts["/base_state"] == len(steps) == 600
