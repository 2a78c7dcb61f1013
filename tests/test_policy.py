"""controller=policy: the contract (terms, joint order, action), the ONNX checks at load, the config's errors."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from taslel_bench.config.compose import compose
from taslel_bench.config.validate import validate
from taslel_bench.control.policy import OnnxPolicy
from taslel_bench.control.policy_contract import (
    TERMS,
    ObservationBuilder,
    PolicyState,
    action_to_targets,
    contract_from_mapping,
    contract_to_mapping,
    file_sha256,
    projected_gravity,
)
from taslel_bench.robot import quadruped as quad
from taslel_bench.util.fields import ConfigError


def _mapping(**changes) -> dict:
    node = {
        "name": "test_policy", "robot": "a1", "onnx": "policy.onnx", "rate_hz": 50,
        "observations": [{"term": "projected_gravity"}, {"term": "joint_pos", "history": 3},
                         {"term": "velocity_command", "scale": [2.0, 2.0, 0.25]}],
        "action": {"kind": "joint_position", "scale": 0.25, "kp": 20.0, "kd": 0.5},
        "default_pose": [0.1 * i for i in range(12)],
    }  # fmt: skip
    node.update(changes)
    return node


def _state(n: int = 1, q: float = 0.0) -> PolicyState:
    z3, z12 = np.zeros((n, 3)), np.zeros((n, 12))
    return PolicyState(z3, z3, np.tile([0.0, 0.0, -1.0], (n, 1)), z12 + q, z12, z12, np.tile([0.5, 0.0, 0.1], (n, 1)))


def test_contract_round_trip_and_sizes():
    c = contract_from_mapping(_mapping(), "test")
    assert c.obs_size == 3 + 12 * 3 + 3
    assert contract_from_mapping(contract_to_mapping(c), "again") == c
    assert c.privileged_terms == []
    assert contract_from_mapping(_mapping(observations=[{"term": "base_lin_vel"}]), "t").privileged_terms == [
        "base_lin_vel"]


@pytest.mark.parametrize(("changes", "message"), [
    ({"observations": [{"term": "foot_height"}]}, "term='foot_height': unknown; valid terms: base_lin_vel"),
    ({"observations": [{"term": "velocity_command", "scale": [1.0, 2.0]}]}, "scale has 2 values; needs 1 or 3"),
    ({"default_pose": [0.0] * 11}, "default_pose has 11 values; needs 12"),
    ({"joint_order": list(quad.JOINT_NAMES[:11]) + ["FL_hip_joint"]}, "must name each of the core joints once"),
    ({"action": {"kind": "joint_velocity"}}, "kind='joint_velocity': unknown; valid: joint_position, joint_torque"),
    ({"rate_hz": 0}, "rate_hz=0.0: must be in (0, 1000] [Hz]"),
])  # fmt: skip
def test_contract_errors_name_the_key_and_what_is_valid(changes, message):
    with pytest.raises(ConfigError) as err:
        contract_from_mapping(_mapping(**changes), "conf/policy/test_policy.yaml")
    assert message in str(err.value)
    assert "conf/policy/test_policy.yaml" in str(err.value)


def test_observation_history_is_oldest_first_and_starts_full():
    c = contract_from_mapping(_mapping(), "test")
    b = ObservationBuilder(c, 1)
    pose = np.asarray(c.default_pose)
    first = b.build(_state(q=0.0))
    cols = dict(c.layout())["joint_pos"]
    np.testing.assert_allclose(first[0, cols], np.tile(-pose, 3), atol=1e-6)  # the first fills the history
    second = b.build(_state(q=1.0))
    np.testing.assert_allclose(second[0, cols], np.concatenate([-pose, -pose, 1.0 - pose]), atol=1e-6)
    np.testing.assert_allclose(second[0, -3:], [1.0, 0.0, 0.025])  # the command, scaled
    b.reset()
    np.testing.assert_allclose(b.build(_state(q=2.0))[0, cols], np.tile(2.0 - pose, 3), atol=1e-6)


def test_joint_order_maps_policy_vectors_to_the_core_order():
    order = list(reversed(quad.JOINT_NAMES))
    c = contract_from_mapping(_mapping(joint_order=order), "test")
    action = np.arange(12.0)[None, :]
    targets = action_to_targets(c, action)  # core order
    for core_index, name in enumerate(quad.JOINT_NAMES):
        i = order.index(name)
        assert targets[0, core_index] == pytest.approx(c.default_pose[i] + 0.25 * action[0, i])
    b = ObservationBuilder(c, 1)
    state = _state()
    state.q_joints = np.arange(12.0)[None, :]  # core order
    cols = dict(c.layout())["joint_pos"]
    obs = b.build(state)[0, cols][-12:]
    np.testing.assert_allclose(obs, np.arange(12.0)[::-1] - np.asarray(c.default_pose), atol=1e-6)


def test_projected_gravity_of_a_rolled_trunk():
    roll = np.radians(30.0)
    quat_wxyz = np.array([[np.cos(roll / 2), np.sin(roll / 2), 0.0, 0.0]])
    np.testing.assert_allclose(projected_gravity(quat_wxyz)[0], [0.0, -np.sin(roll), -np.cos(roll)], atol=1e-12)


def _onnx(tmp_path, n_in: int, n_out: int = 12):
    path = tmp_path / f"p{n_in}x{n_out}.onnx"
    model = torch.nn.Linear(n_in, n_out).eval()
    torch.onnx.export(model, (torch.zeros(1, n_in),), str(path), input_names=["obs"], output_names=["actions"],
                      external_data=False, verbose=False)
    return path


def test_onnx_sizes_and_hash_are_checked_at_load(tmp_path):
    c = contract_from_mapping(_mapping(), "test")
    good = _onnx(tmp_path, c.obs_size)
    assert OnnxPolicy(contract_from_mapping(_mapping(onnx=str(good)), "t"), "t")(np.zeros(c.obs_size)).shape == (12,)
    wrong_in = _onnx(tmp_path, 45)
    with pytest.raises(ConfigError) as err:
        OnnxPolicy(contract_from_mapping(_mapping(onnx=str(wrong_in)), "t"), "conf/policy/x.yaml")
    text = str(err.value)
    assert str(wrong_in) in text and "has 45 values" in text and "have 42" in text and "joint_pos 36" in text
    wrong_out = _onnx(tmp_path, c.obs_size, 8)
    with pytest.raises(ConfigError, match="has 8 values; the action needs 12"):
        OnnxPolicy(contract_from_mapping(_mapping(onnx=str(wrong_out)), "t"), "t")
    with pytest.raises(ConfigError, match="the file changed since the contract was written"):
        OnnxPolicy(contract_from_mapping(_mapping(onnx=str(good), onnx_sha256="0" * 64), "t"), "t")
    assert OnnxPolicy(contract_from_mapping(_mapping(onnx=str(good), onnx_sha256=file_sha256(good)), "t"), "t")
    with pytest.raises(ConfigError, match="no such file"):
        OnnxPolicy(contract_from_mapping(_mapping(onnx=str(tmp_path / "missing.onnx")), "t"), "t")


def test_controller_policy_without_a_policy_names_the_shipped_ones():
    with pytest.raises(ConfigError) as err:
        validate(compose(["controller=policy"]))
    assert "controller=policy needs a policy: policy=<name>" in str(err.value)


def test_every_term_has_a_meaning_and_a_size():
    for name, spec in TERMS.items():
        assert spec.size in (3, 12) and spec.meaning, name
