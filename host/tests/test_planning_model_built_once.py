"""The robot's model is built once per command and handed on (docs/architecture.md, "The planning room").

``eelbot run --plan`` and ``eelbot plan`` build ``SwimmerModel.from_robot`` for the robot the
planner swims once, at the command, and hand it to the planner, its twin and every batch the twin
runs, the search, the check, the executed swims and every replan's planner. What else may build a
model is the other side of the link: over ``sim://`` the virtual robot is the water (its own
robot file and coefficients, which a benchmark draws apart from the planner's) and the synthetic
camera films that robot's markers, so each builds its own, as they would stand apart from the
planner at the tank.
"""

from __future__ import annotations

import inspect
import json
from collections import Counter

import pytest

from eelhost.cli import main
from eelsim.batch import BatchSpec
from eelsim.closed_loop import LoopOptions
from eelsim.model import SwimmerModel
from eelsim.robot import load_robot
from eelsim.scenario import PATH_GAIT, Scenario

OPEN_WORLD = (
    'name = "open"\n[tank]\nsize_m = [3.0, 2.0]\n[start]\nposition_m = [0.6, 1.0]\n'
    "heading_deg = 0.0\n[goal]\nposition_m = [2.1, 1.0]\nradius_m = 0.2\n[current]\n"
    'speed_m_s = 0.0\ndirection_deg = 0.0\n[[obstacles]]\nkind = "circle"\n'
    "centre_m = [1.4, 0.25]\nradius_m = 0.1\n"
)

FITTED = {"fits": {"joint": {
    "coefficients": {"C_f": 0.008, "C_d": 0.7, "C_a": 0.6, "C_m": 0.007},
    "ambient_current": {"current_x_m_s": 0.01, "current_y_m_s": 0.0}}}}
"""A fitted model whose robot (the fit's coefficients) differs from the robot file's."""

PLANT_SIDE = ("eelhost.xil.", "eelhost.vision.")
"""Modules on the link's other side: the virtual robot (the water) and the synthetic camera."""


@pytest.fixture
def builds(monkeypatch):
    """Every SwimmerModel.from_robot call, counted by the eelhost or eelsim module that asked."""
    calls: Counter[str] = Counter()
    original = SwimmerModel.from_robot.__func__  # type: ignore[attr-defined]

    def counting(cls, robot, coefficients=None):  # noqa: ANN001, ANN202
        caller = inspect.stack(context=0)[1].frame.f_globals.get("__name__", "?")
        calls[caller] += 1
        return original(cls, robot, coefficients)

    monkeypatch.setattr(SwimmerModel, "from_robot", classmethod(counting))
    return calls


@pytest.mark.parametrize("fitted", [False, True], ids=["robot-file", "coefficients-file"])
def test_run_plan_builds_the_planners_model_once_for_planner_twin_search_check_and_replans(
        tmp_path, capsys, builds, fitted):
    world = tmp_path / "open.toml"
    world.write_text(OPEN_WORLD)
    extra = []
    if fitted:
        (tmp_path / "coefficients.json").write_text(json.dumps(FITTED))
        extra = ["--coefficients-file", str(tmp_path / "coefficients.json")]
    code = main(["run", "--link", "sim://?speed=0", "--plan", str(world), *extra,
                 "--duration", "1", "--camera", "synthetic:clean", "--no-view",
                 "--out", str(tmp_path / "take")])
    assert code == 0, capsys.readouterr().out
    planning = {k: v for k, v in builds.items() if not k.startswith(PLANT_SIDE)}
    plant = {k: v for k, v in builds.items() if k.startswith(PLANT_SIDE)}
    # one model for the planner's robot, built at the command (CoefficientModel.swimmer_for);
    # before, the planner, the search and every batch of the twin built their own (33 in all)
    assert planning == {"eelhost.planning.uncertainty": 1}, builds
    # the water's robot and the camera filming it: one each, never one per frame or step
    assert plant == {"eelhost.xil.virtual_robot": 1, "eelhost.vision.synthetic": 1}, builds


def test_plan_builds_the_robots_model_once_for_the_plan_its_check_and_the_coverage(
        tmp_path, capsys, builds):
    world = tmp_path / "open.toml"
    world.write_text(OPEN_WORLD)
    assert main(["plan", str(world), "--out", str(tmp_path / "plan")]) == 0
    assert "action coverage" in capsys.readouterr().out  # coverage's 8 twins ran too
    assert dict(builds) == {"eelhost.planning.uncertainty": 1}


def test_a_batch_uses_a_handed_model_only_when_it_is_the_robots_own(builds):
    robot = load_robot()
    scenario = Scenario.swimming(PATH_GAIT, name="s", waypoints_m=[(1.0, 0.0)], duration_s=1.0)
    own = SwimmerModel.from_robot(robot)
    other = SwimmerModel.from_robot(robot, type(robot.hydrodynamics).from_array(
        1.5 * robot.hydrodynamics.as_array()))
    builds.clear()
    built = BatchSpec.build(robot, scenario, options=LoopOptions())
    assert sum(builds.values()) == 1  # nothing handed: the batch builds the robot's own
    handed = BatchSpec.build(robot, scenario, options=LoopOptions(), models=own)
    assert sum(builds.values()) == 1  # the robot's own handed: used
    BatchSpec.build(robot, scenario, options=LoopOptions(), models=other)
    assert sum(builds.values()) == 2  # other coefficients: not the step check's, rebuilt
    for name in ("params", "initial_state", "coefficients", "half_length_m"):
        assert (getattr(handed, name) == getattr(built, name)).all(), name
    assert handed.blow_up_hints == built.blow_up_hints
    with pytest.raises(ValueError, match="2 models for 1 robots"):
        BatchSpec.build(robot, scenario, models=[own, own])


def test_planners_of_one_world_in_other_currents_share_its_clearance_field_and_water_draws():
    # the replanner builds a planner per current estimate: the clearance field (tank and
    # obstacles only) and the seeded water draws are the same, built once (docs/planning.md,
    # "The replan's deadline")
    import tomllib

    import numpy as np

    from eelhost.planning.field import ClearanceField, clearance_field
    from eelhost.planning.planner import Planner
    from eelhost.planning.tank import with_extra_current
    from eelhost.planning.uncertainty import default_model
    from eelhost.planning.world import parse_world

    robot = load_robot(None)
    model = default_model(robot)
    world = parse_world(tomllib.loads(OPEN_WORLD), "open")
    first = Planner(world, robot, model)
    moved = Planner(with_extra_current(world, np.array([0.01, -0.005])), robot, model)
    assert moved.clearance is first.clearance
    assert moved.water is first.water and moved.waters(1) is first.waters(1)
    # the same field as one built afresh, and read only, so no planner can change another's
    fresh = ClearanceField(world)
    np.testing.assert_array_equal(first.clearance.values, fresh.values)
    with pytest.raises(ValueError):
        first.clearance.values[0, 0] = 1.0
    # another geometry gets its own field; another model its own draws
    other = world.model_copy(update={"obstacles": []})
    assert clearance_field(other) is not first.clearance
    assert Planner(world, robot, default_model(robot)).water is not first.water
