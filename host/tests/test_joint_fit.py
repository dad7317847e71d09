"""What a fit varies of the joints is what the joint model declares, not a list of names."""

import numpy as np
import pytest

from eelhost.estimation.joint_fit import joint_fit
from eelsim.joints import JOINT_MODELS
from eelsim.robot import BUNDLED_ROBOTS, load_robot


@pytest.mark.parametrize("robot_file", BUNDLED_ROBOTS)
@pytest.mark.parametrize("model", sorted(JOINT_MODELS))
def test_a_fit_varies_the_parameters_its_joint_model_declares_fitted(robot_file, model):
    joints = JOINT_MODELS[model]
    fit = joint_fit(load_robot(robot_file), model)
    assert fit.model == model
    if joints.fitted_by_estimator:
        assert fit.names == joints.fit_names and fit.names
        assert np.array_equal(fit.bounds, joints.fit_bounds)
    else:
        assert fit.names == () and fit.bounds.shape == (0, 2)


def test_the_papers_pd_gains_are_kept_and_the_servo_line_is_fitted():
    # the paper's gains are the robot's own (docs/estimation.md, "The protocol"); the limited PD
    # inherits PD's law but declares its line fitted
    assert not JOINT_MODELS["pd"].fitted_by_estimator
    assert "fitted_by_estimator" in vars(type(JOINT_MODELS["pd_limited"]))
    assert joint_fit(load_robot(), "pd_limited").names == ("servo_max_torque_nm",
                                                           "servo_max_speed_rad_s")
