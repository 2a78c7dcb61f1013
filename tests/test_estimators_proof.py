"""The legs' own weight in the slip detector's force (against MuJoCo) and the friction proofs of holding feet."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest

from estimators.simple import FixedEstimator
from estimators.slip import FootState, LegGravity
from estimators.slip_bound import SlipBoundEstimator
from estimators.stance_proof import ProofSettings, StanceProof
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.plant.build import build_plant
from taslel_bench.robot import quadruped as quad


def test_leg_gravity_matches_mujoco_bias_forces() -> None:
    """At zero velocity MuJoCo's bias force on the joint rows is the gravity torque of the links beyond each joint;
    LegGravity (Pinocchio on the URDF) gives the same at random joint angles and trunk attitudes."""
    m = build_plant()
    d, br = mujoco.MjData(m), StateBridge(m)
    grav, rng = LegGravity(), np.random.default_rng(1)
    worst = 0.0
    for _ in range(10):
        quat = rng.normal(size=4)
        quat /= np.linalg.norm(quat)
        q = np.zeros(quad.NQ)
        q[3:7] = quat[[1, 2, 3, 0]]  # Pinocchio's xyzw
        q[7:] = rng.uniform(-0.8, 0.8, 12)
        q[9::3] = rng.uniform(-2.6, -1.0, 4)
        br.qpos_mj(q, d.qpos)
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)
        # T maps Pinocchio's velocity to MuJoCo's (joints permuted): the bias in Pinocchio's order is T' qfrc_bias
        T = np.column_stack([_mj_velocity(br, q, i) for i in range(quad.NV)])
        tau_mj = (T.T @ d.qfrc_bias)[6:]
        worst = max(worst, float(np.abs(grav.torques(q[7:], quat) - tau_mj).max()))
    assert worst < 1e-9


def _mj_velocity(br: StateBridge, q: np.ndarray, i: int) -> np.ndarray:
    out = np.zeros(quad.NV)
    br.qvel_mj(q, np.eye(quad.NV)[i], out)
    return out


def _feet(xy, ratio, loaded=(True,) * 4, slipping=(False,) * 4) -> FootState:
    w = np.zeros((4, 3))
    w[:, :2] = xy
    return FootState(np.asarray(loaded), np.asarray(slipping), np.zeros(4), np.asarray(ratio, float), w,
                     np.array([1.0, 0.0]))


XY = [[0.2, 0.1], [0.2, -0.1], [-0.2, 0.1], [-0.2, -0.1]]


def test_a_foot_proves_the_smallest_ratio_it_held_over_the_window() -> None:
    """hold_ticks 3, settle 0, bias 0.01: FL holds 0.30, 0.32, 0.31, 0.40 -> proofs 0.29 after three ticks,
    0.30 after four (min of 0.32, 0.31, 0.40 less the bias); the other feet (unloaded) prove nothing. The proof
    reaches feet within reach_m of FL's place only."""
    p = StanceProof(ProofSettings(step=0.05, bias=0.01, hold_ticks=3, settle_s=0.0, reach_m=0.15))
    unloaded = (True, False, False, False)
    for k, r in enumerate([0.30, 0.32, 0.31]):
        p.update(0.001 * k, _feet(XY, [r, np.nan, np.nan, np.nan], unloaded))
    assert p.proven(np.array(XY, float)) == pytest.approx([0.29, 0.0, 0.0, 0.0])
    p.update(0.003, _feet(XY, [0.40, np.nan, np.nan, np.nan], unloaded))
    assert p.proven(np.array(XY, float))[0] == pytest.approx(0.30)
    near = np.array([[0.3, 0.1], [0.2, 0.0], [0.0, 0.1], [5.0, 5.0]])  # 0.1, 0.1, 0.2 and far from FL's place
    assert p.proven(near) == pytest.approx([0.30, 0.30, 0.0, 0.0])


def test_a_slip_ends_the_proof_and_forget_erases_it() -> None:
    """A slipping tick resets the window (no proof from it); forget_near drops proofs near a slip's place."""
    p = StanceProof(ProofSettings(bias=0.0, hold_ticks=2, settle_s=0.0, reach_m=0.1))
    p.update(0.0, _feet(XY, [0.3] * 4))
    p.update(0.001, _feet(XY, [0.3] * 4, slipping=(True, False, False, False)))
    assert p.proven(np.array(XY, float)) == pytest.approx([0.0, 0.3, 0.3, 0.3])
    p.forget_near(np.array([0.2, -0.1]))  # FR's place: only FR's proof is within 0.1 m
    assert p.proven(np.array(XY, float)) == pytest.approx([0.0, 0.0, 0.3, 0.3])


def test_slip_bound_plans_a_step_above_the_proof_and_a_slip_takes_it_back() -> None:
    """Base 0.2, proofs on: once every foot proved 0.35 the estimate is 0.40; a slip of FL caps FL at the floor
    and erases the proofs near it."""
    est = SlipBoundEstimator(FixedEstimator(0.2), floor_mu=0.1, rise_per_s=0.0,
                             proof={"step": 0.05, "bias": 0.0, "hold_ticks": 2, "settle_s": 0.0, "reach_m": 0.1})
    est.proof.update(0.0, _feet(XY, [0.35] * 4))
    est.proof.update(0.001, _feet(XY, [0.35] * 4))
    proven = est.proof.proven(np.array(XY, float))
    assert np.minimum(np.maximum(0.2, proven + 0.05), 1.0) == pytest.approx([0.4] * 4)
    est._add(0, np.array(XY[0], float), 0.002)
    assert est.proof.proven(np.array(XY, float)) == pytest.approx([0.0, 0.35, 0.35, 0.35])
