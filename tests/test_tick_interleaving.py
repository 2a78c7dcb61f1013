"""studies.tick_interleaving: the replay redoes the loop's work (same QP answers, same plant states), and says
so when it does not."""

import numpy as np
import pytest

from studies import tick_interleaving as ti


@pytest.fixture(scope="module")
def recorded():
    return ti.record(["duration=1.0"], 30)


def test_replay_redoes_the_loops_ticks(recorded):
    built, rec = recorded
    alone, bare = ti.replay(built, rec)  # raises if an answer or a state differs from the loop's
    assert alone.shape == bare.shape == (30, len(ti.PARTS))
    assert np.all(alone > 0) and np.all(bare > 0)
    assert len(rec.solutions) == 30 and all(x is not None for x in rec.solutions)


def test_replay_fails_on_a_changed_record(recorded):
    built, rec = recorded
    kept = rec.solutions[7]
    rec.solutions[7] = kept + 1e-6
    try:
        with pytest.raises(RuntimeError, match="does not redo the loop's work"):
            ti.replay(built, rec)
    finally:
        rec.solutions[7] = kept
