"""The servo joint model's fit bounds stay inside what the twin can integrate."""

import numpy as np

from eelsim.joints import get_joint_model
from eelsim.model import SwimmerModel
from eelsim.robot import SERVO_ROBOT, load_robot
from eelsim.timing import LoopTiming


def test_every_lag_and_motor_time_constant_a_fit_may_try_is_stable_at_the_twins_step():
    # an estimator's fold may refit anywhere in the box; a point RK4 cannot integrate would
    # fail as ill-conditioned and disqualify the whole candidate model
    robot = load_robot(SERVO_ROBOT)
    servo = get_joint_model("servo")
    model = SwimmerModel.from_robot(robot, robot.hydrodynamics)
    (lag_lo, lag_hi), (tau_lo, tau_hi) = servo.fit_bounds
    dt_s = LoopTiming().dt_s
    steps = [
        servo.largest_stable_step_s(servo.with_fit_values(robot.joints, (lag, tau)), model)
        for lag in np.geomspace(lag_lo, lag_hi, 40)
        for tau in np.geomspace(tau_lo, tau_hi, 40)
    ]
    assert min(steps) > 1.2 * dt_s  # with a margin for the control jitter's shortened periods
