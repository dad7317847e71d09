"""The PD loop on the fitted torque-speed line (``pd_limited``): its numpy law against the loop's
own servo-line option, its batched form against its numpy law, and its fitted parameters
(docs/model.md section 4, "Joint models").
"""

import numpy as np
import pytest
from test_batch import assert_agrees
from test_joints import _run_joint_code

from eelsim.batch import run_batch
from eelsim.closed_loop import LoopOptions, servo_limited, simulate_closed_loop
from eelsim.joints import (
    JOINT_MODELS,
    PD,
    PD_LIMITED,
    PDLimitedJointParameters,
    default_grid_models,
    get_joint_model,
)
from eelsim.robot import load_robot
from eelsim.scenario import load_scenario

STALL_NM, NO_LOAD_RAD_S = 0.02, 6.0  # binds on the paper's soft joints at the fast gait


def limited(robot, stall=STALL_NM, no_load=NO_LOAD_RAD_S):
    table = PD_LIMITED.table_from(robot.joints)
    return robot.with_joints(PD_LIMITED.with_fit_values(table, [stall, no_load]))


def test_it_is_registered_but_offered_to_the_comparison_only_when_asked():
    assert get_joint_model("pd_limited") is PD_LIMITED
    assert "pd_limited" in JOINT_MODELS
    assert "pd_limited" not in default_grid_models("pd")
    assert "pd_limited" in default_grid_models("pd_limited")  # the robot file's own model
    assert {"pd", "servo"} <= set(default_grid_models())


def test_its_table_is_the_pd_tables_and_it_fits_the_line_within_its_bounds(robot):
    table = PD_LIMITED.table_from(robot.joints)
    assert isinstance(table, PDLimitedJointParameters)
    assert (table.kp_nm_per_rad, table.kd_nms_per_rad) == (robot.joints.kp_nm_per_rad,
                                                           robot.joints.kd_nms_per_rad)
    assert PD_LIMITED.table_from(load_robot("servo_robot.toml").joints) is None
    assert PD_LIMITED.fit_names == ("servo_max_torque_nm", "servo_max_speed_rad_s")
    bounds = PD_LIMITED.fit_bounds
    again = PD_LIMITED.with_fit_values(table, [STALL_NM, NO_LOAD_RAD_S])
    np.testing.assert_array_equal(PD_LIMITED.fit_values(again), [STALL_NM, NO_LOAD_RAD_S])
    assert np.all((bounds[:, 0] <= [STALL_NM, NO_LOAD_RAD_S])
                  & ([STALL_NM, NO_LOAD_RAD_S] <= bounds[:, 1]))
    assert again.kp_nm_per_rad == table.kp_nm_per_rad  # the gains are not fitted
    with pytest.raises(ValueError):
        PD_LIMITED.with_fit_values(table, [-0.01, NO_LOAD_RAD_S])


def test_its_law_is_the_pd_law_on_the_servo_line_and_its_kernel_code_computes_it(robot):
    rng = np.random.default_rng(5)
    spec = limited(robot).joints
    clipped = 0
    for plain in (True, False):  # the clip is this model's law: written even in plain blocks
        rows = PD_LIMITED.kernel_values(spec, servo_limits=False)
        for al, ald, ph, phd in rng.normal(0, [0.5, 2.0, 0.5, 9.0], (200, 4)):
            args = [np.array([v]) for v in (al, ald, ph, phd)]
            pd = PD.drive(spec, *args)
            want = PD_LIMITED.drive(spec, *args)
            assert want == pytest.approx(servo_limited(pd, args[3], STALL_NM, NO_LOAD_RAD_S))
            clipped += bool(want[0] != pd[0])
            got = _run_joint_code(PD_LIMITED, plain, rows, al, ald, ph, phd)
            assert got == pytest.approx(want[0], rel=1e-12, abs=1e-15)
    assert clipped > 100  # the line binds on most of these draws


@pytest.mark.slow
def test_it_swims_as_the_pd_robot_with_the_loops_servo_line_and_the_batch_agrees(robot):
    s = load_scenario("straight_A0.87_w3.9").model_copy(update={"duration_s": 3.0})
    small = robot.with_joints(robot.joints.model_copy(
        update={"servo_max_torque_nm": STALL_NM, "servo_max_speed_rad_s": NO_LOAD_RAD_S}))
    on_line = simulate_closed_loop(small, s, LoopOptions(servo_limits=True))
    free = simulate_closed_loop(small, s)
    own = simulate_closed_loop(limited(robot), s)  # the model's law, the loop's option off
    np.testing.assert_allclose(own.states, on_line.states, rtol=0, atol=1e-9)
    assert np.abs(free.states - on_line.states).max() > 0.01  # the line changes the swim
    assert own.saturated_steps == 0
    res = run_batch(limited(robot), s, sample_steps=np.arange(len(own.t_s) + 5), threads=1)
    assert_agrees(own, res)

