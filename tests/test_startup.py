"""Every seed starts: one initial state per run, built once, with a foot touching the floor, and the friction
check made on the state the episode starts from."""

from __future__ import annotations

import numpy as np
import pytest

from taslel_bench.sim.build import Built
from taslel_bench.sim.seed_scan import scan
from tests.conftest import compose_cfg

# seeds that could not start when the stand pose put every foot exactly tangent to the floor
ONCE_FAILING = [7, 32, 40, 58, 85, 94, 103]


def test_seeds_that_could_not_start_now_start_and_stand():
    rows = scan(ONCE_FAILING, [])
    assert [r["seed"] for r in rows if r["started"] and r["stood"]] == ONCE_FAILING


def test_no_initial_noise_starts():
    built = Built(compose_cfg(["robot.init_joint_noise_rad=0", "robot.init_base_vel_noise_mps=0",
                               "filter.enabled=false", "duration=0.1", "progress=false"]))
    assert len(built.friction_checked) == 4  # symmetric stand: all four feet touch
    res = built.episode.run()
    assert res.status == "ok" and not res.fell


def test_the_friction_check_sees_the_state_every_run_starts_from():
    built = Built(compose_cfg(["filter.enabled=false", "duration=0.05", "progress=false", "seed=32"]))
    checked_qpos = built.episode.d.qpos.copy()  # the state check_friction looked at
    np.testing.assert_array_equal(checked_qpos, built.episode.initial_qpos)
    first = built.episode.run().trace
    second = built.episode.run().trace  # no fresh noise: the same episode again
    np.testing.assert_array_equal(first.qpos_mj[: first.n], second.qpos_mj[: second.n])
    # the episode starts on the floor: after its first tick the trunk has not dropped (a start in the air
    # would fall ~0.5 mm per tick in free fall, then land)
    assert first.qpos_mj[0, 2] == pytest.approx(checked_qpos[2], abs=1e-4)


@pytest.mark.slow
def test_every_seed_of_2000_starts():
    rows = scan(range(2000), [], stand=False)
    assert [r["seed"] for r in rows if not r["started"]] == []
