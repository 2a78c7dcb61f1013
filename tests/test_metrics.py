"""Safety metrics that can fail: every loaded contact counts, each foot is judged by its own friction,
physical obstacles register trips, falls are timed on the physics step, and a filter that fails does not
end ``ok``. Synthetic traces pin each definition; short real runs check it in the plant."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from taslel_bench.metrics.clearance import clearance_metrics
from taslel_bench.metrics.contacts import contact_metrics, touchdown_window
from taslel_bench.metrics.health import HealthLimits, assess
from taslel_bench.plant.contacts import measure_contact_friction
from taslel_bench.record.trace import EpisodeTrace
from taslel_bench.sim import episode as episode_module
from taslel_bench.sim.build import Built
from taslel_bench.sim.run import run
from tests.conftest import NeverSolves, compose_cfg

N = 10  # synthetic ticks, all walking (k0 = 0), dt = 1 ms


def set_contact(tr: EpisodeTrace, ticks, foot: int, fn: float, ft: float = 0.0, mu: float = 1.0,
                normal=(0.0, 0.0, 1.0), slip: float = 0.0, obstacle: bool = False, slot: int = 0) -> None:
    """One contact of ``foot`` on ``ticks`` in its contact frame (what plant.contact_frames records)."""
    tr.contact_fn_n[ticks, foot, slot] = fn
    tr.contact_ft_n[ticks, foot, slot] = ft
    tr.contact_mu[ticks, foot, slot] = mu
    tr.contact_normal_w[ticks, foot, slot] = np.asarray(normal, float) / np.linalg.norm(normal)
    tr.contact_slip_mps[ticks, foot, slot] = slip
    tr.contact_touching[ticks, foot, slot] = fn > 0.0 or obstacle
    tr.contact_on_obstacle[ticks, foot, slot] = obstacle


def clear_contact(tr: EpisodeTrace, ticks, foot: int) -> None:
    for a in (tr.contact_fn_n, tr.contact_ft_n, tr.contact_mu, tr.contact_slip_mps):
        a[ticks, foot] = 0.0
    tr.contact_normal_w[ticks, foot] = 0.0
    tr.contact_touching[ticks, foot] = False
    tr.contact_on_obstacle[ticks, foot] = False


def synthetic_trace(filter_on: bool = True, n: int = N) -> EpisodeTrace:
    """Four feet in the filter's stance set on flat ground (mu 1), each carrying 50 N, predicted exactly."""
    tr = EpisodeTrace(n, filter_on=filter_on, barrier_names=["clearance"] if filter_on else [])
    tr.n = n
    tr.in_stance[:] = True
    tr.in_contact = np.ones((n, 4), bool)
    tr.grf_plant_w = np.zeros((n, 4, 3))
    tr.grf_plant_w[..., 2] = 50.0
    for foot in range(4):
        set_contact(tr, slice(None), foot, 50.0)
    tr.grf_filter_w[:] = tr.grf_plant_w if filter_on else np.nan
    tr.mu_foot = np.ones((n, 4))
    tr.slip_w = np.zeros((n, 4, 2))
    tr.foot_pos_w = np.zeros((n, 4, 3))
    tr.clearance_m = np.full((n, 4), np.nan)
    tr.obstacle_clearance_m = np.full((n, 4), np.nan)
    tr.obstacle_contact = np.zeros((n, 4), bool)
    tr.qp_status[:n] = 0 if filter_on else -1
    return tr


def test_early_touchdown_counts_in_the_headline_not_in_the_stance_set():
    tr = synthetic_trace()
    # foot 2 touches down in its scheduled swing: the plant carries 120 N, the filter's lambda is 0 (swing)
    tr.in_stance[5:, 2] = False
    tr.grf_plant_w[5:, 2] = (20.0, 0.0, 120.0)
    tr.grf_filter_w[5:, 2] = 0.0
    set_contact(tr, slice(5, None), 2, 120.0, ft=20.0, slip=1.0)  # sliding at 1 m/s
    m = contact_metrics(tr, 0, 1e-3, 0.2)
    assert m["grf_mae_z_n_stance"] == 0.0 and m["slip_mps_mean_stance"] == 0.0  # the old definition
    assert m["contacts_loaded_outside_stance"] == 5
    assert m["grf_mae_z_n"] == pytest.approx(5 * 120.0 / 40)  # 5 of 40 loaded (tick, foot) pairs
    assert m["sliding_distance_m"] == pytest.approx(5 * 1e-3 * 1.0)
    assert m["slip_mps_mean"] == pytest.approx(5 / 40)


def test_each_foot_is_judged_against_the_friction_under_it():
    tr = synthetic_trace()
    tr.grf_plant_w[:, :, 0] = 10.0  # |f_t| / f_n = 0.2 on every foot
    tr.grf_filter_w[:] = tr.grf_plant_w
    for foot in range(4):  # front feet on a mu = 0.2 patch: at the cone edge; rear feet on mu = 1
        set_contact(tr, slice(None), foot, 50.0, ft=10.0, mu=0.2 if foot < 2 else 1.0)
    tr.mu_foot[:, :2] = 0.2
    m = contact_metrics(tr, 0, 1e-3, 0.2)
    assert m["friction_cone_edge_rate"] == pytest.approx(0.5)
    # the filter planned the same force: inside the true cone of the rear feet, on the edge of the front
    # ones (allowed), beyond it once mu under the front feet is 0.1
    assert m["filter_demand_beyond_cone_rate"] == 0.0
    tr.mu_foot[:, :2] = 0.1
    assert contact_metrics(tr, 0, 1e-3, 0.2)["filter_demand_beyond_cone_rate"] == pytest.approx(0.5)


def test_touchdown_window_takes_the_first_ticks_of_each_contact():
    loaded = np.array([1, 1, 0, 1, 1, 1, 1, 0, 0, 1, 1, 0], bool)[:, None]
    got = touchdown_window(loaded, 2)[:, 0].astype(int)
    np.testing.assert_array_equal(got, [0, 0, 0, 1, 1, 0, 0, 0, 0, 1, 1, 0])  # tick 0 is no touchdown


def test_virtual_clearance_counts_every_swing_tick_and_reports_loaded_ones_beside():
    tr = synthetic_trace()
    tr.in_stance[:, 0] = False  # foot 0 swings the whole time
    tr.swing_phase[:, 0] = np.linspace(0.05, 0.95, N)
    tr.clearance_m[:, 0] = [0.01, 0.0, -0.002, -0.004, -0.01, 0.02, 0.02, 0.02, -0.03, -0.03]
    clear_contact(tr, slice(None), 0)
    set_contact(tr, slice(8, None), 0, 40.0)  # an early touchdown: loaded, below the profile
    m = clearance_metrics(tr, 0)
    assert m["clearance_violation_rate"] == pytest.approx(5 / 10)  # the headline: every swing tick
    assert m["clearance_min_m"] == -0.03 and m["clearance_violation_depth_max_m"] == pytest.approx(0.03)
    assert m["clearance_violation_depth_p50_m"] == pytest.approx(0.01)
    assert m["clearance_violation_rate_unloaded"] == pytest.approx(3 / 8)
    assert m["clearance_violation_rate_early_touchdown"] == 1.0 and math.isnan(
        m["clearance_violation_rate_lift_off_lag"]
    )
    assert m["clearance_loaded_swing_rate"] == pytest.approx(0.2)


def test_trips_are_strikes_and_lift_scuffs_in_the_air_and_leg_link_contacts_not_late_landings():
    tr = synthetic_trace(n=40)
    tr.obstacle_clearance_m[:] = 0.05
    tr.in_stance[:, 1] = False
    tr.swing_phase[:, 1] = 0.3
    tr.swing_phase[20:, 1] = 0.8
    clear_contact(tr, slice(None), 1)
    set_contact(tr, [2, 3], 1, 5.0, obstacle=True, normal=(-1.0, 0.0, 0.5))  # foot 1 hits a log's flank in swing ...
    set_contact(tr, [30], 1, 5.0, obstacle=True)  # ... and lands early on its top later: a touchdown
    set_contact(tr, slice(None), 3, 50.0, obstacle=True)  # foot 3 stands on a log: nothing
    tr.obstacle_clearance_m[[2, 3, 30], 1] = -0.001
    tr.leg_link_obstacle_contact[[4, 5], 0] = True  # one knock of leg 0's calf, beside its foot
    m = clearance_metrics(tr, 0)
    assert (m["foot_trips"], m["shin_trips"], m["trips"]) == (1, 1, 2)
    assert (m["foot_trips_flank"], m["foot_trips_top"], m["touchdowns_early"]) == (1, 0, 1)
    assert (m["shin_trips_off_foot"], m["foot_trips_floor"], m["touchdowns_early_floor"]) == (0, 0, 0)
    assert m["obstacle_touch_swing_rate"] == pytest.approx(3 / 40)
    # the top contact in the first half of the swing: a scuff, a trip
    tr.swing_phase[30, 1] = 0.3
    tr.leg_link_obstacle_contact_off_foot[[4, 5], 0] = True  # the calf knock 4 cm or more from its foot
    m = clearance_metrics(tr, 0)
    assert (m["foot_trips_top"], m["touchdowns_early"], m["shin_trips_off_foot"], m["trips"]) == (1, 0, 1, 3)
    assert m["obstacle_clearance_min_m"] == pytest.approx(-0.001)


def test_a_foot_dragged_from_lift_off_is_no_trip_but_its_drag_rate_counts_it():
    """A foot the plan lifts that keeps touching the floor is one continuing contact (no onset, no trip);
    ``foot_drag_rate_early_swing`` is the share of the first-half swing ticks it touched. Breaking the contact
    and touching again in the first half is a trip."""
    tr = synthetic_trace(n=40)
    tr.in_stance[:, 1] = False
    tr.swing_phase[:, 1] = 0.3
    tr.swing_phase[20:, 1] = 0.8  # second half: ticks 20-39 are not judged
    clear_contact(tr, slice(5, None), 1)  # dragged on ticks 0-4 (touching since before the walk), then lifted
    m = clearance_metrics(tr, 0)
    assert (m["trips"], m["foot_drag_rate_early_swing"]) == (0, pytest.approx(5 / 20))
    set_contact(tr, [16], 1, 5.0)  # a touch again after 11 ticks off (past the 10 ms re-arm), first half: a scuff
    m = clearance_metrics(tr, 0)
    assert (m["trips"], m["foot_trips_top"], m["foot_drag_rate_early_swing"]) == (1, 1, pytest.approx(6 / 20))


def test_a_late_touchdown_on_an_obstacle_top_is_a_landing_not_a_trip():
    """The contact estimate holds a foot whose planned stance has begun as swing until it is loaded (a late
    touchdown): its contact onset is where the plan means it to land, a stance contact; the same onset in the
    planned swing's second half is an early touchdown, no trip either."""
    tr = synthetic_trace(n=40)
    tr.obstacle_clearance_m[:] = 0.05
    tr.in_stance[:, 1] = False  # outside the filter's stance set throughout
    tr.swing_phase[:, 1] = 0.9
    clear_contact(tr, slice(None), 1)
    set_contact(tr, [30, 31], 1, 40.0, obstacle=True)
    tr.scheduled_stance[28:, 1] = True  # the plan's stance began two ticks before the onset
    m = clearance_metrics(tr, 0)
    assert (m["trips"], m["touchdowns_early"], m["stance_obstacle_contacts"]) == (0, 0, 1)
    tr.scheduled_stance[:, 1] = False  # the same onset in the planned swing
    m = clearance_metrics(tr, 0)
    assert (m["trips"], m["touchdowns_early"], m["stance_obstacle_contacts"]) == (0, 1, 0)


def test_negative_barrier_while_solved_degrades_the_run():
    tr = synthetic_trace()
    tr.in_stance[:, 0] = False
    tr.barriers["clearance"].h_m[:N, 0] = [0.01] * 8 + [-0.01, -0.02]  # the filter's own h < 0 on 2 of 10 swing ticks
    m = clearance_metrics(tr, 0)
    assert m["barrier_negative_rate"] == pytest.approx(0.2)
    status, why = assess({"status": "ok", **m}, HealthLimits(barrier_negative_rate_max=0.05))
    assert status == "degraded" and "barrier_negative_rate=0.2" in why
    tr.qp_status[8:N] = 1  # those ticks failed instead: counted by qp_failed_rate, not here
    assert clearance_metrics(tr, 0)["barrier_negative_rate"] == 0.0
    assert assess({"status": "ok", "qp_failed_rate": 1.0}, HealthLimits())[0] == "degraded"
    assert assess({"status": "error", "qp_failed_rate": 1.0}, HealthLimits())[0] == "error"
    assert assess({"status": "ok", "qp_failed_rate": 0.0}, HealthLimits()) == ("ok", "")


def test_a_filter_that_fails_every_tick_ends_degraded(tmp_path, monkeypatch):
    """The run finishes on fallback torques (u_nom: intervention 0) and must say so, not end `ok`."""
    import taslel_bench.sim.build as run_module

    monkeypatch.setattr(run_module, "build_backend", lambda cfg: NeverSolves())
    summary = run(compose_cfg(["duration=0.3", "progress=false", "record.mcap=false"]), tmp_path)
    assert summary["qp_failed_rate"] == 1.0 and summary["intervention_nm_mean"] == 0.0
    assert summary["status"] == "degraded" and "qp_failed_rate=1 > 0.05" in summary["degraded_reasons"]


def test_front_feet_on_a_patch_get_the_patch_friction(tmp_path):
    """Trunk at x ~ 0 on the mu = 0.8 patch, front feet (x ~ +0.18 m) beyond the change at 0.05 m on 0.2."""
    cfg = compose_cfg(["scenario=friction_patch", "scenario.change_at_m=0.05", "filter.enabled=false",
                       "duration=0.001", "controller.stand_duration=0.3", "progress=false", "record.mcap=false"])
    built = Built(cfg)
    assert all(mu_plant == mu_cfg for _, mu_plant, mu_cfg in built.friction_checked)  # the lowest foot(s)
    res = built.episode.run()
    tr = res.trace
    assert np.all(tr.mu_true[: tr.n] == 0.8)
    np.testing.assert_array_equal(tr.mu_foot[:, :2], 0.2)  # FL, FR
    np.testing.assert_array_equal(tr.mu_foot[:, 2:], 0.8)  # RL, RR
    f = tr.grf_plant_w[50 : tr.n]  # after the first drop onto the floor
    loaded = f[..., 2] > 1.0
    ratio = np.hypot(f[..., 0], f[..., 1])[loaded] / f[..., 2][loaded]
    assert ratio.max() <= 0.8 + 1e-6
    front = np.hypot(f[:, :2, 0], f[:, :2, 1])[loaded[:, :2]] / f[:, :2, 2][loaded[:, :2]]
    assert front.max() <= 0.2 + 1e-6  # the plant's cone of the front feet is the patch's
    in_contact = dict(measure_contact_friction(built.mj_model, built.episode.d))
    assert in_contact == {"FL_foot": 0.2, "FR_foot": 0.2, "RL_foot": 0.8, "RR_foot": 0.8}


def test_trip_on_a_log_registers_and_tips_the_nominal_trot(tmp_path):
    """Nominal trot (no filter) into 6 cm logs: swing feet hit them (MuJoCo contacts), and seed 0 falls."""
    cfg = compose_cfg(["scenario=logs", "filter.enabled=false", "duration=7", "progress=false",
                       "record.mcap=false", "seed=0"])
    summary = run(cfg, tmp_path, {"scenario": "logs"})
    assert summary["foot_trips"] >= 5 and summary["obstacle_touch_swing_rate"] > 0.01
    assert summary["obstacle_clearance_min_m"] < 0.0
    assert summary["fell"] is True and "touched the terrain" in summary["fall_reason"]
    assert summary["distance_m"] < 0.7  # stuck at the first log (x = 0.6 m)


@pytest.mark.parametrize("control_rate", [1000, 250])
def test_fall_time_is_the_first_physics_step_past_the_threshold(monkeypatch, control_rate):
    """No gains: the robot collapses. The trunk height is logged after every mj_step independently; the
    reported fall time is the first state below the threshold, also between control ticks."""
    cfg = compose_cfg(["filter.enabled=false", "controller.kp=0", "controller.kd=0", "duration=2",
                       "robot.fall_height_m=0.2", f"control_rate_hz={control_rate}", "progress=false",
                       "record.mcap=false"])
    built = Built(cfg)
    log: list[tuple[float, float]] = []
    real_step = mujoco.mj_step

    def logged_step(m, d, *args):
        real_step(m, d, *args)
        log.append((d.time, float(d.qpos[2])))

    monkeypatch.setattr(episode_module.mujoco, "mj_step", logged_step)
    res = built.episode.run()
    assert res.fell and res.fall_reason.startswith("trunk height")
    times, heights = np.array(log).T
    first = int(np.flatnonzero(heights < 0.2)[0])
    assert res.time_to_fall_s == pytest.approx(times[first], abs=1e-9)
    assert heights[first - 1] >= 0.2
    assert len(log) == first + 1  # the episode stopped on that step
    assert math.isfinite(res.time_to_fall_s)
