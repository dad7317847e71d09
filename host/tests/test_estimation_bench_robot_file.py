"""``eelbot estimate-bench --tanks PLANT --robot FILE``: the same tank under either bundled file.

Issue 32 asks for the same chosen model from either bundled robot file on every test plant; the
benchmark measures it on one plant's recordings declared under each file (the plant is the tank,
the robot file only what a lab wrote), and the plant's own floor does not change with the file.
"""

import numpy as np

from eelhost.benchmarks.estimator_accuracy import _plant_itself, _tank
from eelhost.data.experiments import manifest_text, write_experiment, write_manifest
from eelhost.data.plants import PLANTS
from eelhost.data.virtual_tank import record_experiment
from eelsim.robot import SERVO_ROBOT, load_robot
from eelsim.scenario import load_scenario

GAITS = ["straight_A0.87_w3.9", "straight_A0.61_w2.7"]


def _small_plant_tank(folder, plant):
    """Two short straight gaits of ``plant`` from the paper robot (one to train, one held out)."""
    truths = plant.truths()
    for i, name in enumerate(GAITS):
        task = load_scenario(name).model_copy(update={"waypoints_m": [(0.3, 0.0)]})
        write_experiment(record_experiment(load_robot(), task, "straight", truths["straight"],
                                           plant.settings, seed=i), folder)
    described = {"fluid_law": plant.law, **plant.settings.describe()}
    write_manifest(folder, manifest_text(
        "paper_robot.toml", {"straight": {"train": GAITS[:1], "test": GAITS[1:]}}, [],
        {"straight": truths["straight"]}, f"plant {plant.name}", described))


def test_a_plants_tank_declared_under_the_servo_file_holds_the_same_recordings(tmp_path):
    plant = PLANTS["steady_current"]  # its joints are the robot's: the file must not change them
    _small_plant_tank(tmp_path / plant.name, plant)
    said = []
    pd = _tank(tmp_path, plant, 0, said.append)
    servo = _tank(tmp_path, plant, 0, said.append, SERVO_ROBOT)
    assert not said  # the recordings were there: nothing generated again
    assert pd.robot.joints.model_name == "pd" and servo.robot.joints.model_name == "servo"
    recordings = [ds.train["straight"] + ds.test["straight"] for ds in (pd, servo)]
    assert [e.name for e in recordings[0]] == [e.name for e in recordings[1]]
    for a, b in zip(*recordings, strict=True):
        np.testing.assert_array_equal(a.position_m, b.position_m)
    assert pd.truth == servo.truth and pd.plant == servo.plant
    assert servo.plant["stray_current_direction_deg"] == 120.0
    # the plant itself (the floor) swims the tank's own joints, whichever file is declared
    floors = [_plant_itself(ds, plant, ds.held_out, "reference") for ds in (pd, servo)]
    assert floors[0] == floors[1]
    assert 0 < floors[0]["straight"] < 0.05


def test_interval_coverage_on_stiff_servos_under_the_servo_file_judges_the_plants_own_joints():
    # the servo model fitted to stiff_servos contains the tank: its truth is the law's straight
    # row, the servo file's lag (1/K) and motor time constant, and still water
    from eelhost.benchmarks.estimator_coverage import coverage_truth
    from eelhost.estimation.space import ParameterSpace

    plant = PLANTS["stiff_servos"]
    space = ParameterSpace.for_robot(load_robot(SERVO_ROBOT), current=True)
    truth = space.as_dict(coverage_truth(space, plant, load_robot()))
    joints = load_robot(SERVO_ROBOT).joints
    assert truth["lag_s"] == 1.0 / joints.position_gain_1_s
    assert truth["motor_time_constant_s"] == joints.motor_time_constant_s
    assert truth["C_d"] == plant.truths()["straight"].C_d
    assert truth["current_x_m_s"] == truth["current_y_m_s"] == 0.0
    # a steady current is the nuisance's truth: 5 mm/s towards 120 deg
    steady = coverage_truth(ParameterSpace.for_robot(load_robot(), current=True),
                            PLANTS["steady_current"], load_robot())
    np.testing.assert_allclose(steady[-2:], 0.005 * np.array([-0.5, np.sqrt(3) / 2]))


def test_choose_without_bands_is_a_usage_error(capsys):
    from eelhost import cli

    assert cli.main(["estimate-bench", "--choose", "--tanks", "steady_current"]) == 2
    assert "--choose: goes with --bands" in capsys.readouterr().err


def test_the_bench_table_gives_a_one_set_models_fitness_in_every_motions_row():
    # a one-set model has a single fit under "joint"; its rows printed nan until session 20
    from types import SimpleNamespace

    from eelhost.benchmarks.estimator_accuracy import _fitness_text

    one_set = {"joint": SimpleNamespace(fitness=0.0123)}
    assert _fitness_text(one_set, "straight") == "0.0123 (one set)"
    assert _fitness_text(one_set, "path") == "0.0123 (one set)"
    separate = {"straight": SimpleNamespace(fitness=0.02), "turning": SimpleNamespace(fitness=0.03)}
    assert _fitness_text(separate, "turning") == "0.0300"
    assert _fitness_text(separate, "path") == "-"
