"""eelbot bench's engine comparison: each engine timed in a process of its own, ratios in rounds
(eelhost.benchmarks.engine_rounds). No timing is asserted: only that the processes measure what
they are asked and that the rounds are laid out as documented (docs/benchmarks.md)."""

import pytest

from eelhost.benchmarks import engine_rounds as er
from eelsim.robot import SERVO_ROBOT, load_robot


def test_a_kernel_is_timed_in_its_own_process_over_the_whole_batch():
    robot = load_robot()
    steps, walls = er.time_engine(er.EngineJob("kernel", robot, 8, 50, 1, repeats=2))
    assert steps == 8 * 50 and len(walls) == 2 and min(walls) > 0
    rate = er.time_engine_in_process(er.EngineJob("kernel", robot, 8, 50, 1, repeats=1))
    assert rate > 0


def test_a_failing_engine_process_is_reported_with_its_error():
    with pytest.raises(RuntimeError, match="timing warp in its own process failed.*warp"):
        er.time_engine_in_process(er.EngineJob("warp", load_robot(), 2, 5, 1))


def test_rounds_rotate_the_engines_and_cover_every_thread_count(monkeypatch):
    order = []

    def fake(job):
        order.append((job.engine, job.robot.joint_model.name, job.threads))
        return {"kernel": 10.0, "mujoco": 0.5}[job.engine] * (2 if job.threads > 1 else 1)

    monkeypatch.setattr(er, "time_engine_in_process", fake)
    pd, servo = load_robot(), load_robot(SERVO_ROBOT)
    rounds = er.engine_rounds(pd, servo, 4, 10, [1, 2], rounds=2)
    assert [r.threads for r in rounds] == [1, 2, 1, 2]
    assert order[0][:2] == ("kernel", "pd") and order[6][:2] == ("kernel", "servo")
    assert all(r.ratio("pd kernel") == pytest.approx(20.0) for r in rounds)
    assert {o for o in order if o[0] == "mujoco"} == {("mujoco", "pd", 1), ("mujoco", "pd", 2)}
    assert er.spread([20.0, 10.0, 40.0]) == "20.0 (10.0-40.0)"


def test_mujoco_is_timed_in_windows_of_a_fraction_of_the_runs():
    # the bench extra is installed by scripts/setup.sh; five windows of a fifth of the runs
    steps, walls = er.time_engine(er.EngineJob("mujoco", load_robot(), 10, 20, 1, repeats=5))
    assert steps == 2 * 20 and len(walls) == 5 and min(walls) > 0
