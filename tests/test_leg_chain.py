"""The vectorised leg chain (taslel_bench.robot.leg_chain) on every shipped robot: the same feet as the scalar
LegKinematics and as Pinocchio, a Jacobian that is the derivative of its feet, and the same numbers from each
backend (numpy, torch in the estimators' features, the compiled kernel the slip detector reads)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pinocchio as pin
import pytest

from taslel_bench.robot import leg_chain
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import load_robot
from taslel_bench.robot.kinematics import LegKinematics
from taslel_bench.robot.model import RobotModel

SHIPPED = ("a1", "go1", "anymal_c", "solo12")
TOL = 1e-10
N_POSES = 20


def _joint_angles(robot, rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 12) [rad] random joint angles, knees bent the robot's way."""
    q = rng.uniform(-0.8, 0.8, (n, quad.N_LEGS, 3))
    for leg, g in enumerate(robot.legs):
        q[:, leg, 2] = g.knee_sign * g.axis_signs[2] * rng.uniform(0.3, 2.4, n)
    return q.reshape(n, quad.N_JOINTS)


@pytest.mark.parametrize("name", SHIPPED)
def test_feet_and_jacobians_match_leg_kinematics_and_pinocchio(name: str) -> None:
    """All poses in one call: feet equal LegKinematics.leg_fk + the hips, feet and leg Jacobians equal Pinocchio's
    (trunk at the identity, so world = trunk axes), to 1e-10."""
    robot = load_robot(name)
    q = _joint_angles(robot, np.random.default_rng(0), N_POSES)
    feet, jac = leg_chain.feet_and_jacobians(leg_chain.chain_table(robot), q)
    assert feet.shape == (N_POSES, 4, 3) and jac.shape == (N_POSES, 4, 3, 3)
    kin, pm = LegKinematics(robot), RobotModel(robot)
    full = pin.neutral(pm.model)
    worst = {"leg_fk": 0.0, "pinocchio_feet": 0.0, "pinocchio_jacobians": 0.0}
    for k in range(N_POSES):
        full[7:] = q[k]
        pm.update(full, np.zeros(quad.NV))
        for leg in range(quad.N_LEGS):
            fk = kin.leg_fk(leg, q[k, 3 * leg : 3 * leg + 3]) + robot.hip_positions_in_trunk[leg]
            leg_cols = pm.foot_jac_in_world[leg][:, 6 + 3 * leg : 9 + 3 * leg]
            worst["leg_fk"] = max(worst["leg_fk"], np.abs(feet[k, leg] - fk).max())
            feet_error = np.abs(feet[k, leg] - pm.foot_pos_in_world[leg]).max()
            worst["pinocchio_feet"] = max(worst["pinocchio_feet"], feet_error)
            worst["pinocchio_jacobians"] = max(worst["pinocchio_jacobians"], np.abs(jac[k, leg] - leg_cols).max())
    assert max(worst.values()) < TOL, (name, worst)


def _mirrored_axes(robot):
    """The robot with every joint axis reversed: the same legs driven by the negated angles."""
    return replace(robot, legs=tuple(replace(g, axis_signs=(-g.axis_signs[0], -g.axis_signs[1], -g.axis_signs[2]))
                                     for g in robot.legs))


@pytest.mark.parametrize("name", SHIPPED)
def test_jacobian_is_the_derivative_of_the_feet(name: str) -> None:
    """J equals the central finite difference of the feet, for the robot and for it with reversed joint axes
    (which no shipped robot has; its feet at q are the robot's at -q)."""
    robot = load_robot(name)
    q = _joint_angles(robot, np.random.default_rng(1), 5)
    h = 1e-6
    for table in (leg_chain.chain_table(robot), leg_chain.chain_table(_mirrored_axes(robot))):
        _, jac = leg_chain.feet_and_jacobians(table, q)
        for j in range(quad.N_JOINTS):
            dq = np.zeros(quad.N_JOINTS)
            dq[j] = h
            d_feet = (leg_chain.feet_in_trunk(table, q + dq) - leg_chain.feet_in_trunk(table, q - dq)) / (2 * h)
            leg, col = divmod(j, 3)
            np.testing.assert_allclose(jac[:, leg, :, col], d_feet[:, leg], atol=1e-8)
            assert not np.delete(d_feet, leg, axis=1).any()  # a joint moves its own foot only
    mirrored = leg_chain.feet_in_trunk(leg_chain.chain_table(_mirrored_axes(robot)), q)
    np.testing.assert_array_equal(mirrored, leg_chain.feet_in_trunk(leg_chain.chain_table(robot), -q))


@pytest.mark.parametrize("name", SHIPPED)
def test_velocities_compiled_kernel_and_torch_match_numpy(name: str) -> None:
    """feet_and_velocities = (feet, J qd); the compiled feet_and_jacobians_into and the torch features
    (estimators.models.foot_kinematics, float64 and float32) give the numpy chain's numbers."""
    torch = pytest.importorskip("torch")
    from estimators.models import foot_kinematics

    robot = load_robot(name)
    table = leg_chain.chain_table(robot)
    rng = np.random.default_rng(2)
    q, qd = _joint_angles(robot, rng, N_POSES), rng.normal(0.0, 3.0, (N_POSES, quad.N_JOINTS))
    feet, jac = leg_chain.feet_and_jacobians(table, q)
    vel = np.einsum("nlrc,nlc->nlr", jac, qd.reshape(N_POSES, 4, 3))
    p_np, v_np = leg_chain.feet_and_velocities(table.T, q, qd)
    np.testing.assert_array_equal(p_np, feet)
    np.testing.assert_allclose(v_np, vel, rtol=0, atol=1e-12)

    p_k, jac_k = np.empty((4, 3)), np.empty((4, 3, 3))
    for k in range(N_POSES):
        leg_chain.feet_and_jacobians_into(table, q[k], p_k, jac_k)
        np.testing.assert_allclose(p_k, feet[k], rtol=0, atol=1e-12)
        np.testing.assert_allclose(jac_k, jac[k], rtol=0, atol=1e-12)

    x = torch.from_numpy(np.concatenate([q, qd, np.zeros_like(q)], axis=1)).reshape(4, 5, 36)
    for dtype, atol in ((torch.float64, 1e-12), (torch.float32, 2e-5)):
        out = foot_kinematics(x.to(dtype), robot).reshape(N_POSES, 24).double().numpy()
        np.testing.assert_allclose(out[:, :12], feet.reshape(N_POSES, 12), rtol=0, atol=atol)
        np.testing.assert_allclose(out[:, 12:], vel.reshape(N_POSES, 12), rtol=0, atol=atol)


def test_one_joint_vector_and_a_batch_agree() -> None:
    """A (12,) joint vector gives the (4, 3) / (4, 3, 3) row of the batch it belongs to."""
    table = leg_chain.chain_table(load_robot("anymal_c"))
    q = _joint_angles(load_robot("anymal_c"), np.random.default_rng(3), 6).reshape(2, 3, 12)
    feet, jac = leg_chain.feet_and_jacobians(table, q)
    one_feet, one_jac = leg_chain.feet_and_jacobians(table, q[1, 2])
    np.testing.assert_array_equal(one_feet, feet[1, 2])
    np.testing.assert_array_equal(one_jac, jac[1, 2])
    np.testing.assert_array_equal(leg_chain.feet_in_trunk(table, q), feet)
