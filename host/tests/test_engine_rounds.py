"""eelbot bench's engine comparison: each engine in a worker process of its own, one window of
each per round (eelhost.benchmarks.engine_rounds). No timing is asserted: only that the workers
measure what they are asked and that the rounds are laid out as documented (docs/benchmarks.md)."""

import pytest

from eelhost.benchmarks import engine_rounds as er
from eelsim.robot import SERVO_ROBOT, load_robot


def test_a_kernel_window_is_the_whole_batch_timed_in_a_worker_process():
    robot = load_robot()
    steps, walls = er.time_engine(er.EngineJob("kernel", robot, 8, 50, 1), windows=2)
    assert steps == 8 * 50 and len(walls) == 2 and min(walls) > 0
    worker = er.EngineProcess(er.EngineJob("kernel", robot, 8, 50, 1))
    try:
        rates = [worker.rate(), worker.rate()]  # the same worker answers window after window
    finally:
        worker.close()
    assert min(rates) > 0


def test_a_failing_engine_process_is_reported_with_its_error():
    with pytest.raises(RuntimeError, match="timing warp in its own process failed.*warp"):
        er.EngineProcess(er.EngineJob("warp", load_robot(), 2, 5, 1))


def test_rounds_rotate_the_engines_and_cover_every_thread_count(monkeypatch):
    started, timed = [], []

    class FakeProcess:
        def __init__(self, job):
            self.job = job
            started.append((job.engine, job.robot.joint_model.name, job.threads))

        def rate(self):
            timed.append((self.job.engine, self.job.robot.joint_model.name))
            return {"kernel": 10.0, "mujoco": 0.5}[self.job.engine] * self.job.threads

        def close(self):
            started.remove((self.job.engine, self.job.robot.joint_model.name, self.job.threads))

    monkeypatch.setattr(er, "EngineProcess", FakeProcess)
    pd, servo = load_robot(), load_robot(SERVO_ROBOT)
    rounds = er.engine_rounds(pd, servo, 4, 10, [1, 2], rounds=3)
    assert [r.threads for r in rounds] == [1, 1, 1, 2, 2, 2]
    # one window of each engine per round, the first engine rotating: pd, servo, MuJoCo
    assert [timed[3 * i][:2] for i in range(3)] == [("kernel", "pd"), ("kernel", "servo"),
                                                    ("mujoco", "pd")]
    assert all(r.ratio("pd kernel") == pytest.approx(20.0) for r in rounds)
    assert started == []  # every worker closed
    assert er.spread([20.0, 10.0, 40.0]) == "20.0 (10.0-40.0)"
    assert er.quartiles([1.0, 2.0, 3.0, 4.0, 5.0]) == "3.0 (2.0-4.0)"


def test_a_mujoco_window_is_a_fraction_of_the_runs_with_two_per_thread_at_least():
    # the bench extra is installed by scripts/setup.sh
    assert er.mujoco_window_runs(600, 2) == 600 // er.MUJOCO_WINDOW_FRACTION
    assert er.mujoco_window_runs(10, 1) == 2
    steps, walls = er.time_engine(er.EngineJob("mujoco", load_robot(), 10, 20, 1), windows=3)
    assert steps == 2 * 20 and len(walls) == 3 and min(walls) > 0
