"""The evaluator scores through the backend object it is given (estimation/runs.py's interface)."""

import numpy as np

from eelhost.data.virtual_tank import TABLE3, TankSettings, record_experiment
from eelhost.estimation.evaluate import Evaluator
from eelhost.estimation.reference_backend import ReferenceBackend
from eelhost.estimation.space import ParameterSpace
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

TRUTH = TABLE3["straight"]


class RecordingBackend:
    """The reference backend, noting what each call was given and each ``fresh`` it made."""

    def __init__(self) -> None:
        self.inner = ReferenceBackend(workers=1)
        self.calls: list[tuple[int, int, ParameterSpace]] = []
        self.made_fresh: list[RecordingBackend] = []

    def simulate(self, robots, prepared, parameters, space):
        self.calls.append((len(robots), len(prepared), space))
        return self.inner.simulate(robots, prepared, parameters, space)

    def fresh(self) -> "RecordingBackend":
        self.made_fresh.append(RecordingBackend())
        return self.made_fresh[-1]


def test_an_evaluator_scores_through_the_backend_object_it_is_given_as_through_the_named_one():
    robot = load_robot()
    scenario = load_scenario("straight_A0.87_w3.9").model_copy(update={"waypoints_m": [(0.3, 0.0)]})
    exp = record_experiment(robot, scenario, "straight", TRUTH,
                            TankSettings(timestamp_jitter_s=0.0), seed=0)
    candidates = np.array([TRUTH.as_array(), [0.02, 1.3, 0.3, 0.05]])
    backend = RecordingBackend()
    given = Evaluator(robot, [exp], backend=backend)
    named = Evaluator(robot, [exp], backend="reference", workers=1)
    assert np.array_equal(given.errors(candidates), named.errors(candidates))
    assert backend.calls == [(2, 1, given.space)]  # every candidate's robot, one call
    assert given.simulations == 2
    # another space of the same robot gets a backend that has learned nothing of this one's runs
    other = given.with_space(ParameterSpace.for_robot(robot, current=True))
    assert other.backend is backend.made_fresh[0] and given.backend is backend
