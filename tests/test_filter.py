"""ID-CBF-QP filter on real states, solved by an independent tight reference (qpsolvers' clarabel at
1e-10 tolerances, called directly here so the core is tested without the solvers package)."""

from __future__ import annotations

import time

import mujoco
import numpy as np
import pinocchio as pin
import pytest
import qpsolvers

from taslel_bench.control.gait import GaitParams
from taslel_bench.control.nominal import NominalController, PDGains
from taslel_bench.filter.barriers.base import BarrierWorld
from taslel_bench.filter.barriers.obstacle import ObstacleClearance
from taslel_bench.filter.barriers.phase_profile import PhaseProfileClearance
from taslel_bench.filter.layout import LAM, VDOT, TickInputs, U
from taslel_bench.filter.safety_filter import FilterSettings, SafetyFilter
from taslel_bench.interfaces import ClearanceProfile, Plane, QPSolution, Terrain
from taslel_bench.plant.bridge import StateBridge
from taslel_bench.plant.build import PlantOptions, build_plant
from taslel_bench.robot import quadruped as quad
from taslel_bench.robot.description import load_robot
from taslel_bench.robot.model import RobotModel

A1 = load_robot("a1")


class TightReference:
    name = "clarabel-tight"

    def solve(self, p):
        t0 = time.perf_counter()
        x = qpsolvers.solve_qp(p.P, p.q, p.G, p.h, p.A, p.b, p.lb, p.ub, solver="clarabel",
                               tol_gap_abs=1e-10, tol_gap_rel=1e-10, tol_feas=1e-10)
        return QPSolution(x, "solved" if x is not None else "infeasible", time.perf_counter() - t0)

    def reset(self):
        pass

    def describe(self):
        return {"name": self.name}


class ActiveSetReference(TightReference):
    """quadprog (dual active set, exact up to rounding) -- to compare two formulations to 1e-6."""

    name = "quadprog"

    def solve(self, p):
        t0 = time.perf_counter()
        x = qpsolvers.solve_qp(p.P, p.q, p.G, p.h, p.A if p.A.size else None, p.b if p.b.size else None,
                               p.lb, p.ub, solver="quadprog")
        return QPSolution(x, "solved" if x is not None else "infeasible", time.perf_counter() - t0)


class Broken:
    name = "broken"

    def solve(self, p):
        raise RuntimeError("boom")

    def reset(self):
        pass

    def describe(self):
        return {}


BUMP = ClearanceProfile((0.0, 0.0, 1.28, -2.56, 1.28))  # 8 cm 4th-order bump


def world(terrain: Terrain | None = None, profile: ClearanceProfile | None = None) -> BarrierWorld:
    return BarrierWorld(terrain if terrain is not None else Terrain(), profile, 20.0, 20.0)


def clearance_rows(profile: ClearanceProfile = BUMP) -> list:
    """The paper's swing-foot clearance family on ``profile`` (the filter's barrier list)."""
    return [PhaseProfileClearance(world(profile=profile))]


def walking_states(n_states: int, t_start: float = 1.0, friction: float = 1.0):
    """(TickInputs-ready) plant states of the nominal trot after t_start, every 37 ms."""
    m = build_plant(PlantOptions(floor_friction=friction))
    d, br, pm = mujoco.MjData(m), StateBridge(m), RobotModel()
    ctl = NominalController(GaitParams(), PDGains())
    q0 = pin.neutral(pm.model)
    q0[2] = 0.27 + A1.foot_radius_m
    q0[7:] = ctl.stand_configuration()
    br.qpos_mj(q0, d.qpos)
    mujoco.mj_forward(m, d)
    out, k = [], 0
    while len(out) < n_states:
        t = k * 1e-3
        u = ctl.compute(t, d.qpos[br.joint_qadr], d.qvel[br.joint_dadr])
        if t >= t_start and k % 37 == 0:
            q, v = br.q_pin(d.qpos), br.v_pin(d.qpos, d.qvel)
            out.append((q, v, ctl.contact_plan(t), u.copy()))
        br.ctrl_mj(u, d.ctrl)
        mujoco.mj_step(m, d)
        k += 1
    return out, pm


def inputs_for(pm, state, mu):
    q, v, gs, _ = state
    pm.update(q, v)
    return TickInputs(pm, v, gs.in_stance, mu, gs.swing_phase, gs.swing_phase_rate)


@pytest.fixture(scope="module")
def states():
    return walking_states(12)


def unfiltered_prediction(f: SafetyFilter, u: np.ndarray) -> np.ndarray:
    """(vdot, lambda) that the equality constraints give for a fixed u (square linear system)."""
    p = f.problem
    A_free = np.hstack([p.A[:, VDOT], p.A[:, LAM]])
    sol = np.linalg.solve(A_free, p.b - p.A[:, U] @ u)
    return np.concatenate([sol[:18], u, sol[18:]])


def test_filter_returns_u_nom_when_no_inequality_is_active(states):
    """Where u_nom's own contact forces satisfy every inequality, the filter must not intervene."""
    st, pm = states
    f = SafetyFilter(FilterSettings(regularization=1e-4, lambda_min_n=0.0), TightReference())
    checked = 0
    for s in st:
        x = inputs_for(pm, s, mu=1.0)
        f.build(x, s[3])
        x_nom = unfiltered_prediction(f, s[3])
        if np.all(f.problem.G @ x_nom - f.problem.h <= -1e-6):
            res = f.filter(x, s[3])
            assert res.status == "solved"
            assert np.abs(res.u - s[3]).max() < 1e-6
            checked += 1
    assert checked >= 3, "too few walking states with all inequalities slack"


def test_solution_satisfies_dynamics_and_cones(states):
    st, pm = states
    f = SafetyFilter(FilterSettings(lambda_min_n=2.0), TightReference(), clearance_rows())
    mu = 0.3
    for s in st:
        x = inputs_for(pm, s, mu)
        res = f.filter(x, s[3])
        assert res.status == "solved"
        lam = res.lam.reshape(4, 3)
        # equations of motion: M vdot + h = B u + sum J_i' lambda_i
        tau = np.concatenate([np.zeros(6), res.u]) + sum(pm.foot_jac_in_world[i].T @ lam[i] for i in range(4))
        assert np.abs(pm.M @ res.vdot + pm.h - tau).max() <= 1e-6
        mu_t = mu / np.sqrt(2.0)
        for i in range(4):
            if s[2].in_stance[i]:
                assert lam[i, 2] >= 2.0 - 1e-6
                assert abs(lam[i, 0]) <= mu_t * lam[i, 2] + 1e-6
                assert abs(lam[i, 1]) <= mu_t * lam[i, 2] + 1e-6
                # stance foot does not accelerate
                acc = pm.foot_jac_in_world[i] @ res.vdot + pm.foot_jdotv_in_world[i]
                assert np.abs(acc).max() < 1e-6
            else:
                assert np.abs(lam[i]).max() < 1e-8
        assert np.all(np.abs(res.u) <= A1.torque_limit_nm[0] + 1e-9)


def test_ecbf_rows_hold_at_the_solution(states):
    st, pm = states
    f = SafetyFilter(FilterSettings(), TightReference(), clearance_rows())
    active = 0
    for s in st:
        x = inputs_for(pm, s, 1.0)
        res = f.filter(x, s[3])
        p = f.problem
        rows = [i for i, lab in enumerate(p.row_labels) if lab.endswith("clearance")]
        xvec = np.concatenate([res.vdot, res.u, res.lam])
        slack = p.h[rows] - p.G[rows] @ xvec
        assert np.all(slack >= -1e-6)
        active += int(np.sum(np.abs(slack) < 1e-6))
        # the row is the paper's ECBF: a2 h_e + hdot_e >= 0 with hdot_e from the predicted foot acceleration
        for i in range(4):
            if not s[2].in_stance[i]:
                z, dz, ddz = BUMP(float(s[2].swing_phase[i]))
                sd = s[2].swing_phase_rate
                h = pm.foot_pos_in_world[i, 2] - A1.foot_radius_m - z
                hdot = pm.foot_vel_in_world[i, 2] - dz * sd
                acc_z = pm.foot_jac_in_world[i, 2] @ res.vdot + pm.foot_jdotv_in_world[i, 2]
                hddot = acc_z - ddz * sd**2
                al1, al2 = f.settings.ecbf_alpha1, f.settings.ecbf_alpha2
                assert al2 * (hdot + al1 * h) + hddot + al1 * hdot >= -1e-6
    assert active > 0, "the 8 cm bump should make the ECBF bind on some swing ticks"


def test_obstacle_rows_hold_and_follow_the_geometry(states):
    """A log 6 cm ahead of each state's first swing foot: the row is the ECBF of the foot sphere's Euclidean
    clearance, its hddot (n . a + curvature) matches a finite difference of the clearance along the
    predicted motion, and it holds (and binds on some states) at the tight reference's solution."""
    from taslel_bench.interfaces import Log

    st, pm = states
    active = 0
    for s in st:
        x = inputs_for(pm, s, 1.0)
        swing = [i for i in range(4) if not s[2].in_stance[i]]
        if not swing:
            continue
        i = swing[0]
        p0 = pm.foot_pos_in_world[i].copy()
        log = Log(x_m=float(p0[0] + 0.06 + 0.05), z_m=-0.02, radius_m=0.05)
        f = SafetyFilter(FilterSettings(), TightReference(), [ObstacleClearance(world(Terrain((Plane(), log))))])
        res = f.filter(x, s[3])
        assert res.status == "solved"
        p = f.problem
        row = p.row_labels.index(f"{quad.LEGS[i]}_obstacle")
        xvec = np.concatenate([res.vdot, res.u, res.lam])
        slack = p.h[row] - p.G[row] @ xvec
        assert slack >= -1e-6
        active += int(abs(slack) < 1e-6)
        v0 = pm.foot_vel_in_world[i]
        a0 = pm.foot_jac_in_world[i] @ res.vdot + pm.foot_jdotv_in_world[i]

        def clearance(t: float, p0=p0, v0=v0, a0=a0, log=log) -> float:
            pt = p0 + v0 * t + 0.5 * a0 * t * t
            return float(np.hypot(pt[0] - log.x_m, pt[2] - log.z_m) - log.radius_m - A1.foot_radius_m)

        dt = 1e-4
        h, hdot = clearance(0.0), (clearance(dt) - clearance(-dt)) / (2 * dt)
        hddot = (clearance(dt) - 2 * h + clearance(-dt)) / dt**2
        al1, al2 = f.settings.ecbf_alpha1, f.settings.ecbf_alpha2
        # what the kernel wrote: h, h_e = hdot + al1 h, and the row -G vdot = hddot - (J̇v-free part)
        h_e = f.barriers[0].h_e[i]
        hdot_row = h_e - al1 * f.barriers[0].h[i]
        hddot_row = -p.G[row, :18] @ res.vdot + p.h[row] - al2 * h_e - al1 * hdot_row
        assert f.barriers[0].h[i] == pytest.approx(h, abs=1e-12)
        assert hdot_row == pytest.approx(hdot, abs=1e-6)
        assert hddot_row == pytest.approx(hddot, abs=1e-3 * max(1.0, abs(hddot)))  # finite-difference accuracy
        assert al2 * (hdot + al1 * h) + hddot + al1 * hdot >= -1e-3 * max(1.0, abs(hddot))
    assert active > 0, "a log 6 cm ahead of a swinging foot should make the row bind"


def test_friction_pyramid_binds_on_low_mu(states):
    """On mu = 0.05 the pyramid rows bind and the filter moves u; the bound holds at the solution."""
    st, pm = states
    f = SafetyFilter(FilterSettings(), TightReference())
    binding, du = 0, []
    for s in st:
        res = f.filter(inputs_for(pm, s, 0.05), s[3])
        p = f.problem
        xvec = np.concatenate([res.vdot, res.u, res.lam])
        rows = [i for i, lab in enumerate(p.row_labels) if lab[-3:] in ("fx+", "fx-", "fy+", "fy-")]
        slack = p.h[rows] - p.G[rows] @ xvec
        assert np.all(slack >= -1e-6)
        binding += int(np.sum(slack < 1e-6))
        du.append(np.linalg.norm(res.u - s[3]))
    assert binding > 0 and np.mean(du) > 1.0


def test_friction_margin_alone_plans_inside_the_narrower_pyramid(states):
    """robust.friction_margin = 0.1 with the ECBF margins off (robust.enabled false): the same as planning with
    0.9 mu, and different from mu where the pyramid binds."""
    from taslel_bench.filter.robust import RobustSettings

    st, pm = states
    narrow = SafetyFilter(FilterSettings(robust=RobustSettings(enabled=False, friction_margin=0.1)), TightReference())
    plain = SafetyFilter(FilterSettings(), TightReference())
    moved = 0
    for s in st:
        a, b = narrow.filter(inputs_for(pm, s, 0.05), s[3]), plain.filter(inputs_for(pm, s, 0.045), s[3])
        np.testing.assert_allclose(a.u, b.u, atol=1e-6)
        moved += int(np.linalg.norm(a.u - plain.filter(inputs_for(pm, s, 0.05), s[3]).u) > 1e-3)
    assert moved > 0


def test_backend_exception_falls_back_and_is_recorded(states):
    st, pm = states
    f = SafetyFilter(FilterSettings(fallback="nominal"), Broken())
    res = f.filter(inputs_for(pm, st[0], 1.0), st[0][3])
    assert res.used_fallback and res.status.startswith("error: RuntimeError")
    assert np.array_equal(res.u, st[0][3]) and np.all(np.isnan(res.lam))


def test_hold_last_fallback(states):
    st, pm = states
    f = SafetyFilter(FilterSettings(fallback="hold_last"), TightReference())
    good = f.filter(inputs_for(pm, st[0], 0.3), st[0][3])
    f.backend = Broken()
    res = f.filter(inputs_for(pm, st[1], 0.3), st[1][3])
    assert res.used_fallback and np.array_equal(res.u, good.u)


def test_bad_fallback_name():
    with pytest.raises(ValueError, match="valid: nominal, hold_last"):
        SafetyFilter(FilterSettings(fallback="pray"), TightReference())


def test_layout_is_fixed(states):
    st, pm = states
    f = SafetyFilter(FilterSettings(), TightReference(), clearance_rows())
    p = f.problem
    assert p.n == 42 and p.A.shape == (30, 42) and p.G.shape == (24, 42)
    assert (p.layout["vdot"], p.layout["u"], p.layout["lambda"]) == (VDOT, U, LAM)
    for s in st:
        f.build(inputs_for(pm, s, 0.5), s[3])
        assert not np.any(p.A[~p.A_pattern]) and not np.any(p.G[~p.G_pattern])


def test_zero_regularization_target_is_biased(states):
    """Documents why the default regularises towards the nominal prediction (safety_filter docstring)."""
    st, pm = states
    f = SafetyFilter(FilterSettings(regularization=1e-4, lambda_min_n=0.0, regularization_target="zero"),
                     TightReference())
    du = [np.abs(f.filter(inputs_for(pm, s, 10.0), s[3]).u - s[3]).max() for s in st]
    assert max(du) > 1e-2


@pytest.mark.parametrize("target", ["nominal", "zero"])
def test_condensed_formulation_has_the_same_minimiser(states, target):
    """formulation=condensed (equalities eliminated, backend sees u only) returns the full QP's solution,
    with binding friction and ECBF rows, for both regularisation targets."""
    st, pm = states
    kw = {"regularization": 1e-4, "regularization_target": target}
    full = SafetyFilter(FilterSettings(**kw), ActiveSetReference(), clearance_rows())
    cond = SafetyFilter(FilterSettings(formulation="condensed", **kw), ActiveSetReference(), clearance_rows())
    assert cond.condensed.n == quad.N_JOINTS and cond.condensed.A.shape[0] == 0
    moved = 0
    for s in st:
        for mu in (0.05, 1.0):
            a, b = full.filter(inputs_for(pm, s, mu), s[3]), cond.filter(inputs_for(pm, s, mu), s[3])
            assert a.status == b.status == "solved"
            assert np.abs(a.u - b.u).max() < 1e-6
            assert np.abs(a.lam - b.lam).max() < 1e-5 and np.abs(a.vdot - b.vdot).max() < 1e-4
            moved += int(np.abs(a.u - s[3]).max() > 1e-3)
    assert moved >= 3, "the comparison must include ticks where constraints change u"


def test_bad_formulation_name():
    with pytest.raises(ValueError, match="valid: full, condensed"):
        SafetyFilter(FilterSettings(formulation="sparse"), TightReference())


def test_api_builds_the_configured_filter(states):
    """taslel_bench.api (what axis packages use): the filter from the project config, with its backend."""
    from taslel_bench import api

    st, pm = states
    f = api.build_safety_filter(api.compose(["solver=quadprog", "filter.formulation=condensed"]), profile=BUMP)
    assert f.settings.formulation == "condensed" and [b.name for b in f.barriers] == ["clearance"]
    res = f.filter(inputs_for(pm, st[0], 0.3), st[0][3])
    assert res.status == "solved" and res.u.shape == (12,)
    with pytest.raises(ValueError, match="filter.enabled is false"):
        api.build_safety_filter(api.compose(["filter.enabled=false"]))


def test_tree_solve_of_the_equality_rows_equals_the_dense_lu(states):
    """The leg-by-leg elimination of the (vdot, lambda) block and the dense pivoted LU give the same
    [z0, Z] on walking states (stance and swing feet, 13 right-hand sides), and a stretched stance leg (a
    singular leg block) falls back to the dense LU instead of failing."""
    from taslel_bench.filter.equality_solve import FreeBlockSolver, solve_dense, solve_tree

    sts, pm = states
    filt = SafetyFilter(FilterSettings(), TightReference())
    qp = filt.problem
    sv = FreeBlockSolver(13, filt.eq_families[0].start, filt.eq_families[1].start)
    K, piv, W, V, S, T, pivS, A_free, piv_dense = sv.workspace
    rng = np.random.default_rng(0)
    worst = 0.0
    for st in sts:
        filt.build(inputs_for(pm, st, 0.6), st[3])
        rhs = rng.normal(size=(qp.A.shape[0], 13))
        tree, dense = rhs.copy(), rhs.copy()
        assert solve_tree(qp.A, tree, 0, quad.NV, K, piv, W, V, S, T, pivS)
        assert solve_dense(qp.A, dense, A_free, piv_dense)
        worst = max(worst, np.abs(tree - dense).max() / np.abs(dense).max())
        A_free_np = np.hstack([qp.A[:, VDOT], qp.A[:, LAM]])
        np.testing.assert_allclose(A_free_np @ tree, rhs, atol=1e-9 * np.abs(rhs).max() * 1e3)
    assert worst < 1e-10
    # a singular leg block: foot 0 in stance with a zero Jacobian on its own joints
    A = qp.A.copy()
    A[:] = 0.0
    A[: quad.NV, : quad.NV] = np.eye(quad.NV)
    A[quad.NV : quad.NV + 3, :3] = np.eye(3)  # foot 0's contact rows use only base columns
    for i in range(1, 4):
        A[quad.NV + 3 * i : quad.NV + 3 * i + 3, 30 + 3 * i : 33 + 3 * i] = np.eye(3)  # swing feet
    A[:3, 30:33] = -np.eye(3)
    rhs = rng.normal(size=(qp.A.shape[0], 1))
    assert not solve_tree(A, rhs.copy(), 0, quad.NV, K, piv, W, V, S, T, pivS)
    from taslel_bench.filter.equality_solve import solve_free

    y = rhs.copy()
    assert solve_free(A, y, sv.rows, sv.workspace)
    np.testing.assert_allclose(np.hstack([A[:, VDOT], A[:, LAM]]) @ y, rhs, atol=1e-12)


def test_persistent_osqp_leaves_out_vacuous_rows_and_keeps_its_setup(states):
    """On condensed filter QPs of a walk (stance changes included) the persistent OSQP, which leaves the
    identically-zero G rows out, gives DAQP's u to 1e-5 N·m, reports zero multipliers for the left-out rows
    and is set up once: the kept rows' pattern does not change with the stance set."""
    from solvers.registry import make_backend

    sts, pm = states
    osqp_b, daqp_b = make_backend("osqp"), make_backend("daqp")
    f = SafetyFilter(FilterSettings(formulation="condensed"), TightReference(), clearance_rows())
    stance_sets = set()
    for st in sts:
        f.build(inputs_for(pm, st, 0.5), st[3])
        qp = f.condensed
        a, b = osqp_b.solve(qp), daqp_b.solve(qp)
        assert a.ok and b.ok, (a.status, b.status)
        assert np.abs(a.x - b.x).max() <= 1e-5
        vacuous = ~qp.G.any(axis=1)
        assert vacuous.sum() >= 4 and np.all(a.z[vacuous] == 0.0)
        stance_sets.add(st[2].in_stance.tobytes())
    assert len(stance_sets) >= 2 and osqp_b.setups == 1


@pytest.mark.parametrize("formulation", ["full", "condensed"])
def test_contact_velocity_gain_brakes_stance_feet(states, formulation):
    """filter.contact_velocity_gain k_v: at the solution a stance foot's centre accelerates as
    J vdot + J̇v = -k_v J v (both formulations), and the equations of motion still hold."""
    st, pm = states
    kv = 50.0
    f = SafetyFilter(
        FilterSettings(contact_velocity_gain=kv, formulation=formulation), TightReference(), clearance_rows()
    )
    for s in st:
        res = f.filter(inputs_for(pm, s, 0.6), s[3])
        assert res.status == "solved"
        for i in range(4):
            if s[2].in_stance[i]:
                acc = pm.foot_jac_in_world[i] @ res.vdot + pm.foot_jdotv_in_world[i]
                np.testing.assert_allclose(acc, -kv * pm.foot_vel_in_world[i], atol=1e-6)
        lam = res.lam.reshape(4, 3)
        tau = np.concatenate([np.zeros(6), res.u]) + sum(pm.foot_jac_in_world[i].T @ lam[i] for i in range(4))
        assert np.abs(pm.M @ res.vdot + pm.h - tau).max() <= 1e-6
