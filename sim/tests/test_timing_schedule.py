"""The control update schedule: the loop without jitter is every period exactly, as drawn one by one."""

from __future__ import annotations

import numpy as np
import pytest

from eelsim.timing import LoopTiming


def schedule_drawn_one_by_one(timing, total_steps, rng):
    """The schedule as the definition reads: each update a period plus a drawn jitter later."""
    steps = [0]
    while True:
        jitter = timing.jitter_steps
        nxt = steps[-1] + timing.period_steps + (int(rng.integers(-jitter, jitter + 1))
                                                  if jitter else 0)
        if nxt > total_steps:
            return np.array(steps, dtype=np.int64)
        steps.append(nxt)


@pytest.mark.parametrize("total_steps", [0, 1, 29, 30, 31, 60, 61, 4321])
@pytest.mark.parametrize("jitter_s", [0.0, 0.05])
def test_the_update_schedule_is_the_one_drawn_update_by_update(total_steps, jitter_s):
    timing = LoopTiming(jitter_s=jitter_s)
    fast, slow = np.random.default_rng(7), np.random.default_rng(7)
    got = timing.update_steps(total_steps, fast)
    want = schedule_drawn_one_by_one(timing, total_steps, slow)
    assert got.dtype == np.int64 and np.array_equal(got, want)
    # the generator is left where the definition leaves it (the camera noise is drawn next)
    assert fast.random() == slow.random()
